"""Average consensus (eq. 16), sampled, with Metropolis weights and input tracking.

The paper's ``ξ̇_i = Σ_{j∈N_i} (ξ_j − ξ_i)`` is run in discrete time as

    ξ_i ← ξ_i + Σ_{j∈N_i} a_ij (ξ_j − ξ_i) + (r_i⁺ − r_i),

where ``r_i`` is the robot's own input (``‖z_i‖²`` for Step 4's ``w = Σ‖z_i‖²``) and
``a_ij = 1 / (1 + max(d_i, d_j))`` are the Metropolis weights: symmetric, and
``Σ_j a_ij < 1``, so the iteration converges on any connected graph using only the
neighbours' degrees. The last term lets the input change while consensus runs: ``Σ ξ_i = Σ r_i``
at every step, so once the inputs settle every ``ξ_i`` converges to their average ``w / n``.
:class:`~agent.algorithm.estimation.team_consensus.TeamConsensus` runs it beside Step 2, in flow
form, which keeps that sum when messages are lost.
"""

from __future__ import annotations

import functools
import math


def metropolis_weight(degree_i: int, degree_j: int) -> float:
    """``a_ij = 1 / (1 + max(d_i, d_j))``."""
    return 1.0 / (1.0 + max(degree_i, degree_j))


@functools.cache
def delay_factor(delay: int) -> float:
    """``ρ_d = sin(π / (2 (2d + 1)))``, the factor on ``a_ij`` for a neighbour's state ``d ≥ 0``
    instants older than the previous instant (the load's rotation,
    :mod:`agent.algorithm.robust.rotation`). ``x ← x − c x(k−d)`` is stable for ``c < 2 ρ_d``,
    and a Metropolis graph's ``c`` (an eigenvalue of ``I − A``) is below 2: so the consensus
    stays stable however late the states (``ρ_0 = 1``: on time, the plain weights)."""
    return math.sin(math.pi / (2.0 * (2.0 * max(delay, 0) + 1.0)))
