"""A plant's truth on a floor with friction, for tests that judge the friction estimates."""

from __future__ import annotations

from agent.platform.protocol import Truth

FLOOR = Truth(
    10,
    0.1,
    (1.0, 0.0),
    0.0,
    (0.0, 0.0),
    0.0,
    ((0.0, 0.0), (2.0, 0.0)),
    ((0.0, 0.0),) * 2,
    ((1.0, 0.0), (-1.0, 0.0)),
    5.0,
    2.0,
    ground_coulomb=0.02,
    ground_static=0.03,
    friction_radius=1.5,
    viscous_radius2=2.5,
)
"""Two robots on a 5 kg load at rest, at tick 10 (0.1 s), on a floor of μ = 2 % whose supports
are 1.5 m from the COM on average: a spin meets ``μ m g c`` = 1.4715 N m."""
