"""A noise benchmark's seed as its report and goals see it, with known errors: what the noise
benchmark's and the friction sweep's tests judge."""

from __future__ import annotations

from simulator.bench.noise import SeedResult

ERRORS = {
    "mass_rel": 0.001,
    "moment_rel": 0.004,
    "contact_to_com_m": 0.004,
    "relative_positions_m": 0.002,
}
"""The centralized fit's errors; the robust estimators' are these times ``scale``."""
FRICTION = {"friction_torque_rel": 0.05, "coulomb": 0.001}
"""The robust estimators' friction errors (the fit has none)."""


def seed_result(
    seed: int,
    scale: float,
    done: float = 12.0,
    inside: bool = True,
    travel: float = 0.5,
    mu: float = 0.0,
) -> SeedResult:
    """Seed ``seed``: the robust errors ``scale`` times the fit's (:data:`ERRORS`), done at
    ``done`` s simulated (not done at 60), every robot's intervals holding the truth or none
    (``inside``), the load's largest travel ``travel`` (m; its floor 3 m), on a floor of
    ``mu``; the paper's estimators without estimates."""
    return SeedResult(
        seed=seed,
        robust={**{k: scale * v for k, v in ERRORS.items()}, **FRICTION},
        paper=dict.fromkeys(ERRORS),
        baseline={**ERRORS, **dict.fromkeys(FRICTION)},
        robust_time_s=done,
        robust_done=done < 60.0,
        paper_done=False,
        inside={k: [inside] * 4 for k in (*ERRORS, *FRICTION)},
        floor={"travel_m": travel, "speed": 1.0, "omega": 1.0, "within": travel <= 3.0},
        coulomb=mu,
    )
