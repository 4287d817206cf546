"""The team's means that the robust estimators add to Step 2: the drives' gains and the mass.

Drives' gains. Steps 4, 5 and 7 assume every robot applies its command; a drive of gain ``g_i``
(:mod:`agent.algorithm.robust.drive_gain`) applies ``g_i`` times it. With the team's means
``ḡ`` (``mean_gain``), ``h = Σ g_i z_i / n`` (``mean_gain_offset``, a vector of the load, turned
with it like ``x_i``) and ``q = Σ g_i ‖z_i‖² / n`` (``mean_gain_square_offset``), the team's
torque in Step 4 is ``±k n q`` (not ``±k w``), its force in Steps 5–7 is ``n ḡ f`` and the
torque of that force about the COM is ``n (h + ḡ z_C) × f``. Each robot's inputs are ``g_i``,
``g_i x_i`` and ``g_i ‖x_i‖²`` (:func:`inputs`), averaged like ``w / n``
(:mod:`agent.algorithm.estimation.team_consensus`).

The team's mass (Step 7) is a consensus on information rather than on point estimates: each
robot's own fit ``m_i`` with relative standard deviation ``ρ_i`` enters as the inputs
``ι_i = (ρ₀ / ρ_i)²`` (its information, in units of ``ρ₀ = 1 %``, at most
:data:`MAX_MASS_INFORMATION`) and ``ι_i m_i``; their averages (``mean_mass_information``,
``mean_weighted_mass``) give the information-weighted mean ``m̂ = μ / ι = Σ ι_i m_i / Σ ι_i``.
Its relative standard deviation is published as ``ρ₀ / √ι`` (``ι`` the mean information): that
of a robot of average information, as if the robots' errors were fully correlated. They are
partly: the fits share the forces, the angle and the gains, while each robot's own velocity
noise averages out.

The robots' fits may also be further apart than their standard deviations say: each fit's
model leaves out what the floor, the drives and the other estimates add. The team measures
it, with two more averages, of ``ι_i ln m_i`` (``λ``) and ``ι_i (ln m_i)²`` (``ψ``): the
fits' weighted spread ``s² = ψ/ι − (λ/ι)²`` (relative), and their chi-square about their
weighted mean ``χ² = Σ ι_i (ln m_i − λ/ι)² / ρ₀² = n ι s² / ρ₀²``. Where ``χ²/(n − 1) > 1``
the published standard deviation is scaled by ``S = √(χ²/(n − 1))`` (:func:`disagreement`,
the scale factor of a weighted mean of inconsistent measurements, as particle physicists'
tables of averages apply it): fits that disagree widen the team's interval by as much as they
disagree, never narrow it.
"""

from __future__ import annotations

import math

from agent.platform.geometry import Vec2

RHO0 = 0.01
"""``ρ₀``: the relative standard deviation of one unit of a mass fit's information."""
MAX_MASS_INFORMATION = 1e4
"""A mass fit's information at most this many times that of a 1 % standard deviation (0.01 %):
more is not believed, and it bounds the consensus states and flows."""


def mass_input(mass: float | None, std: float | None) -> tuple[float, float, float, float]:
    """``(ι_i, ι_i m_i, ι_i ln m_i, ι_i (ln m_i)²)`` for a robot's own mass fit ``mass`` (kg)
    with standard deviation ``std`` (zeros: no fit yet)."""
    if mass is None or std is None or mass <= 0.0:
        return (0.0, 0.0, 0.0, 0.0)
    information = MAX_MASS_INFORMATION if std <= 0.0 else (RHO0 * mass / std) ** 2
    information = min(information, MAX_MASS_INFORMATION)
    log = math.log(mass)
    return (information, information * mass, information * log, information * log * log)


def inputs(
    x: Vec2,
    gain: float,
    mass: tuple[float, float, float, float],
    torque: float,
    kick: float,
    com: Vec2 | None,
    turn_variance: float,
) -> tuple[float, ...]:
    """A robot's inputs of the team's means, in declaration order
    (:data:`agent.platform.team.TEAM_QUANTITIES`): ``‖x_i‖²`` (→ ``w / n``), ``g_i``,
    ``g_i x_i``, ``g_i ‖x_i‖²``, ``ι_i``, ``ι_i m_i``, ``ι_i ln m_i``, ``ι_i (ln m_i)²``,
    ``τ_i``, ``A_i``, ``ζ_i``, ``ζ_i ẑ_C`` and ``Var(δ_i)``, for its offsets iterate ``x``,
    its drive's gain, its mass input (:func:`mass_input`), its torque in Step 1's spin-up
    (:attr:`~agent.algorithm.robust.phases.RobustPhases.spin_torque`), its kick's size
    (:attr:`~agent.algorithm.robust.phases.RobustPhases.kick_level`), its own ``ẑ_C``
    (``None``: none yet, ``ζ_i = 0``) and its own turn's variance
    (:func:`~agent.algorithm.robust.rotation.own_variance`)."""
    norm2 = x[0] * x[0] + x[1] * x[1]
    held = (0.0, 0.0, 0.0) if com is None else (1.0, com[0], com[1])
    return (
        norm2,
        gain,
        gain * x[0],
        gain * x[1],
        gain * norm2,
        *mass,
        torque,
        kick,
        *held,
        turn_variance,
    )


def team_mass(information: float, weighted: float, own: float) -> tuple[float, float] | None:
    """``(m̂, ρ)``: the team's mass ``μ / ι`` and its relative standard deviation ``ρ₀ / √ι``,
    from the consensus states ``ι`` (``information``) and ``μ`` (``weighted``); ``None`` while
    ``ι`` is not positive or ``m̂`` is not within a factor of 2 of this robot's ``own`` fit (the
    states of a consensus whose inputs have just appeared or gone, as at a restart, are not yet
    a weighted mean)."""
    if information <= 0.0 or own <= 0.0:
        return None
    mass = weighted / information
    if not 0.5 * own <= mass <= 2.0 * own:
        return None
    return (mass, RHO0 / math.sqrt(information))


def disagreement(
    information: float, weighted_log: float, weighted_square_log: float, n: int
) -> float:
    """``S = max(1, √(χ²/(n − 1)))``, ``χ² = n ι s² / ρ₀²`` with ``s² = ψ/ι − (λ/ι)²``, from the
    consensus states ``ι``, ``λ`` (``weighted_log``) and ``ψ`` (``weighted_square_log``): the
    factor on the team's mass's standard deviation for fits further apart than their own
    standard deviations say (1 for a lone robot, or before any robot has a fit)."""
    if n < 2 or not information > 0.0:
        return 1.0
    mean = weighted_log / information
    spread = weighted_square_log / information - mean * mean
    chi2 = n * information * max(spread, 0.0) / RHO0**2
    return max(1.0, math.sqrt(chi2 / (n - 1)))
