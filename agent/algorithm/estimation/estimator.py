"""The one shape of every estimator of the seven steps.

Conventions (paper Sec. II and the notes): vectors are planar ``(x, y)`` tuples in the world
frame ``W`` at the instant they refer to; ``Q = [[0, -1], [1, 0]]``, ``v⊥ = Q v``, and the planar
cross product is ``a × b = (a⊥)ᵀ b``. For any two points of the rigid load ``ż_ij = ω z_ij⊥``
(``ω`` counter-clockwise positive), and the torque of ``f_i`` applied at ``C_i`` is
``τ_i = (p_Ci − p_C)⊥ᵀ f_i``.

Time is sampled: an estimator is fed once per sampling interval, at its end, with what was
measured then and the interval's length ``dt`` (s), always the last argument; between calls
nothing changes. The estimators built on the filtered regression (the Appendix, eq. 26) start
their filters on the first sample, with no transient, so that call's ``dt`` is not used.

The estimators and what they estimate, shared by every family:

- :class:`~agent.algorithm.estimation.team_consensus.TeamConsensus`: Step 2, ``z_i``, with
  ``w / n`` (eq. 16) and the team's other means;
- :class:`~agent.algorithm.estimation.com_observer.ComObserver`: Step 5, ``z_C`` by observer
  (24);

and each family's own, of Steps 1, 4, 5 and 7 (:mod:`agent.algorithm.paper`,
:mod:`agent.algorithm.robust`).
"""

from __future__ import annotations

from typing import Any, Protocol, TypeVar, runtime_checkable

Covariance = tuple[tuple[float, ...], ...]
"""A symmetric matrix, row by row, in the units of the estimate squared."""


E_co = TypeVar("E_co", covariant=True)


@runtime_checkable
class Estimator(Protocol[E_co]):
    """``update(<measured inputs>, dt)``, ``estimate`` and ``covariance``."""

    def update(self, *measured: Any) -> None:
        """Feed the inputs measured at the end of a sampling interval; the last argument is
        the interval's length ``dt`` (s)."""

    @property
    def estimate(self) -> E_co | None:
        """The current estimate, or ``None`` before the data determine it."""

    @property
    def covariance(self) -> Covariance | None:
        """The estimate's covariance; ``None``: not estimated (the paper assumes no noise)."""
