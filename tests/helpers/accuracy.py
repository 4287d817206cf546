"""How close a run's estimates are to the ground truth, and to another run's."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from simulator.inprocess import RunOutcome


def worst_errors(outcome: RunOutcome) -> dict[str, float]:
    """The largest error over robots of each estimate, against truth at the same instant."""
    truth = outcome.final.truth
    worst = {"mass": 0.0, "moment": 0.0, "contact_to_com": 0.0, "relative": 0.0}
    for i, est in outcome.final.estimates.items():
        assert est.mass is not None and est.moment is not None, f"robot {i} has no m or J"
        assert est.contact_to_com is not None, f"robot {i} has no contact_to_com"
        worst["mass"] = max(worst["mass"], abs(est.mass - truth.mass) / truth.mass)
        worst["moment"] = max(worst["moment"], abs(est.moment - truth.moment) / truth.moment)
        err = math.dist(est.contact_to_com, truth.contact_to_com[i - 1])
        worst["contact_to_com"] = max(worst["contact_to_com"], err)
        pi = truth.contacts[i - 1]
        for j, z in est.relative_positions.items():
            pj = truth.contacts[j - 1]
            err = math.dist(z, (pi[0] - pj[0], pi[1] - pj[1]))
            worst["relative"] = max(worst["relative"], err)
    return worst


ESTIMATED = (
    "omega",
    "w",
    "moment",
    "mass",
    "centroid_offset",
    "com_offset",
    "com_observer",
    "com_velocity",
    "contact_to_com",
)


def assert_same_estimates(a: RunOutcome, b: RunOutcome, tol: float = 1e-9) -> None:
    """Every robot's every estimate at the same final instant, to ``tol`` (relative)."""
    assert a.ticks == b.ticks and a.sim_time_s == b.sim_time_s
    assert a.final.estimates.keys() == b.final.estimates.keys()
    for i, x in a.final.estimates.items():
        y = b.final.estimates[i]
        assert (x.tick, x.phase, x.phase_since) == (y.tick, y.phase, y.phase_since)
        for name in ESTIMATED:
            u, v = getattr(x, name), getattr(y, name)
            assert (u is None) == (v is None), name
            if u is not None:
                u, v = (u, v) if isinstance(u, tuple) else ((u,), (v,))
                assert math.dist(u, v) <= tol * max(1.0, math.hypot(*u)), (i, name, u, v)
        assert x.relative_positions.keys() == y.relative_positions.keys()
        for j, z in x.relative_positions.items():
            assert math.dist(z, y.relative_positions[j]) <= tol * max(1.0, math.hypot(*z))
        assert (x.started, x.settled) == (y.started, y.settled)


def assert_within(outcome: RunOutcome, rel: float, metres: float) -> None:
    """The run converged within 60 s simulated, every robot's m and J within ``rel`` and its
    offsets within ``metres`` of the truth, and the load stayed on the scenario's floor."""
    from simulator.results import floor_check

    assert outcome.converged, f"not converged in {outcome.sim_time_s:.1f} s"
    floor = floor_check(outcome)
    assert floor["within"], floor
    assert outcome.sim_time_s < 60.0
    worst = worst_errors(outcome)
    assert worst["mass"] <= rel, worst
    assert worst["moment"] <= rel, worst
    assert worst["contact_to_com"] <= metres, worst
    assert worst["relative"] <= metres, worst
    assert len(outcome.final.estimates[1].relative_positions) > 0
