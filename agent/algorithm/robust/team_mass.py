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
"""

from __future__ import annotations

import math

from agent.platform.geometry import Vec2

MAX_MASS_INFORMATION = 1e4
"""A mass fit's information at most this many times that of a 1 % standard deviation (0.01 %):
more is not believed, and it bounds the consensus states and flows."""


def mass_input(mass: float | None, std: float | None) -> tuple[float, float]:
    """``(ι_i, ι_i m_i)`` for a robot's own mass fit ``mass`` with standard deviation ``std``
    (``(0, 0)``: no fit yet)."""
    if mass is None or std is None or mass <= 0.0:
        return (0.0, 0.0)
    information = MAX_MASS_INFORMATION if std <= 0.0 else (0.01 * mass / std) ** 2
    information = min(information, MAX_MASS_INFORMATION)
    return (information, information * mass)


def inputs(
    x: Vec2, gain: float, mass: tuple[float, float], torque: float
) -> tuple[float, float, float, float, float, float, float, float]:
    """A robot's inputs of the team's means, in declaration order
    (:data:`agent.platform.team.TEAM_QUANTITIES`): ``‖x_i‖²`` (→ ``w / n``), ``g_i``,
    ``g_i x_i``, ``g_i ‖x_i‖²``, ``ι_i``, ``ι_i m_i`` and ``τ_i``, for its offsets iterate ``x``,
    its drive's gain, its mass input (:func:`mass_input`) and its torque in Step 1's spin-up
    (:attr:`~agent.algorithm.robust.phases.RobustPhases.spin_torque`)."""
    norm2 = x[0] * x[0] + x[1] * x[1]
    return (norm2, gain, gain * x[0], gain * x[1], gain * norm2, mass[0], mass[1], torque)


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
    return (mass, 0.01 / math.sqrt(information))
