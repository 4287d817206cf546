"""How sure each robot is, as the dashboard streams it (dashboard/state.py,
dashboard/quantities.py): fed a robust run of the noisy paper scenario (in one process), every
chart point of an estimate that has a published uncertainty carries its 95 % half-width, the
table's intervals are ``heft run``'s, and an uncertainty that cannot be one is dropped, never
drawn and never a crash."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest

from agent.platform.evaluation import ERROR_KEYS, PLANAR_95, SCALAR_95
from agent.platform.geometry import largest_std
from agent.platform.protocol import Estimates, Phase, Truth
from dashboard.app import to_json
from dashboard.hub import Hub
from dashboard.quantities import DECLARATIONS, SCALARS
from dashboard.state import TeamState
from tests.helpers.paths import ROOT

NOISY = ROOT / "simulator" / "scenarios" / "paper-noisy.toml"


@pytest.fixture(scope="module")
def noisy_run():
    """The noisy paper scenario with the robust estimators, in one process."""
    from simulator.inprocess import run_inprocess
    from simulator.scenario import load_scenario

    scenario = load_scenario(NOISY)
    outcome = run_inprocess(scenario)
    assert outcome.converged
    return scenario, outcome


def fed(scenario, outcome) -> TeamState:
    state = TeamState(scenario.name, scenario.load_geometry())
    for sample in [*outcome.history, outcome.final]:
        state.ingest(sample.truth, sample.truth.time_s)
        for est in sample.estimates.values():
            state.ingest(est, sample.truth.time_s)
    return state


def along(v, cov) -> float:
    """``1.96 σ`` of ``‖v‖``: ``σ² = ûᵀ C û``."""
    norm = math.hypot(*v)
    ux, uy = v[0] / norm, v[1] / norm
    xx, xy, yy = cov
    return SCALAR_95 * math.sqrt(ux * ux * xx + 2 * ux * uy * xy + uy * uy * yy)


def test_every_point_with_an_uncertainty_carries_its_95_percent_half_width(noisy_run) -> None:
    scenario, outcome = noisy_run
    state = fed(scenario, outcome)
    series = state.all_series()
    final = outcome.final.estimates
    for i, est in final.items():
        # The charts end with the final estimates, each with 1.96 σ.
        assert series[f"mass/{i}"][-1] == [
            state.t(est.tick),
            round(est.mass, 9),
            round(SCALAR_95 * est.mass_std, 9),
        ]
        assert series[f"moment/{i}"][-1][2] == round(SCALAR_95 * est.moment_std, 9)
        ctc = series[f"ctc/{i}"][-1]
        assert ctc[1] == round(math.hypot(*est.contact_to_com), 9)
        assert ctc[2] == pytest.approx(along(est.contact_to_com, est.contact_to_com_cov))
        for j, cov in est.relative_positions_cov.items():
            if j > i:
                edge = series[f"edge/{i}-{j}"][-1]
                assert edge[2] == pytest.approx(along(est.relative_positions[j], cov))
        # Before the push, no mass and no interval; Ĵ's interval comes with Ĵ.
        assert all(len(point) == 3 for point in series[f"moment/{i}"])
        assert series[f"ctc/{i}/truth"][-1][1] == pytest.approx(
            math.hypot(*outcome.final.truth.contact_to_com[i - 1])
        )
    # The truth has no interval, ω none published.
    for trace, points in series.items():
        if trace.endswith("truth") or trace.startswith("omega/"):
            assert {len(point) for point in points} == {2}, trace
    # Early on, the band is wider than at the end.
    masses = series["mass/1"]
    assert masses[0][2] > 3 * masses[-1][2]


def test_the_tables_intervals_are_heft_runs(noisy_run) -> None:
    from simulator.results import intervals

    scenario, outcome = noisy_run
    state = fed(scenario, outcome)
    assert state.final is not None and state.final["tick"] == outcome.final.truth.tick
    page = state.page_scene(100.0)["table"]
    for i in range(1, scenario.n + 1):
        robot = str(i)
        row = state.final["robots"][robot]
        assert row["intervals"] == intervals(outcome, i)  # the "95 % intervals" table's
        assert page["robots"][robot]["intervals"] == row["intervals"]
        # Here every truth lies inside (heft run's table says so too).
        assert all(inside for _, inside in row["intervals"].values())
    # The snapshot carries what each robot published.
    robots = state.scene(100.0)["robots"]
    for i, est in outcome.final.estimates.items():
        view = robots[str(i)]
        assert view["mass_std"] == est.mass_std and view["moment_std"] == est.moment_std
        assert view["contact_to_com_cov"] == est.contact_to_com_cov
        assert view["relative_positions_cov"] == {
            str(j): c for j, c in est.relative_positions_cov.items()
        }


def test_the_top_view_draws_each_robots_95_percent_com_ellipse(noisy_run) -> None:
    scenario, outcome = noisy_run
    top = fed(scenario, outcome).top_view()
    assert set(top["com_ellipses"]) == set(top["com_estimates"]) == {"1", "2", "3", "4"}
    for robot, (major, minor, angle) in top["com_ellipses"].items():
        cov = outcome.final.estimates[int(robot)].contact_to_com_cov
        assert major == pytest.approx(math.sqrt(PLANAR_95) * largest_std(*cov), abs=1e-6)
        assert 0 <= minor <= major and abs(angle) <= math.pi / 2
        # The ellipse's own axis: C's eigenvector of the larger eigenvalue.
        xx, xy, yy = cov
        c, s = math.cos(angle), math.sin(angle)
        assert c * c * xx + 2 * c * s * xy + s * s * yy == pytest.approx(
            largest_std(*cov) ** 2, rel=1e-3
        )


def test_the_page_is_told_the_scalars_it_charts() -> None:
    hello = Hub("t").hello()
    assert [s["key"] for s in hello["scalars"]] == ["mass", "moment"]
    assert hello["scalars"][0] == {
        "key": "mass",
        "symbol": "m̂",
        "unit": "kg",
        "title": "mass",
        "digits": 4,
        "error": "mass_rel",
        "relative": True,
    }
    assert json.loads(to_json(DECLARATIONS)) == DECLARATIONS
    # Each declaration names what the messages and the errors have.
    estimates = {f.name for f in dataclasses.fields(Estimates)}
    truth = {f.name for f in dataclasses.fields(Truth)}
    for scalar in SCALARS:
        assert {scalar.key, scalar.std} <= estimates and scalar.truth in truth
        assert scalar.error is None or scalar.error in ERROR_KEYS


BAD_STDS = [math.nan, math.inf, -1.0, 1e308]
"""Not a standard deviation (1e308: finite, but 1.96 σ is not)."""
BAD_COVS = [(1.0, 2.0, 1.0), (-1e-4, 0.0, 1e-4), (math.nan, 0.0, 1e-4), (math.inf, 0.0, 1.0)]
"""Not a covariance: not positive semi-definite, or not finite."""


@pytest.mark.parametrize(("std", "cov"), list(zip(BAD_STDS, BAD_COVS, strict=True)), ids=str)
def test_an_uncertainty_that_cannot_be_one_is_dropped(std, cov) -> None:
    """As if it came over the network unchecked: no band, no interval, no ellipse; the
    estimates themselves are drawn and every frame is still JSON."""
    state = TeamState("t")
    contacts = ((0.0, 0.0), (2.0, 0.0))
    truth = Truth(10, 0.1, (1, 0), 0, (0, 0), 0, contacts, ((0, 0),) * 2, ((1, 0), (-1, 0)), 5, 2)
    state.ingest(truth, 0.1)
    bad = Estimates(
        1,
        10,
        Phase.PUSH,
        relative_positions={2: (-2.0, 0.0)},
        moment=2.0,
        mass=5.0,
        contact_to_com=(1.0, 0.0),
        mass_std=std,
        moment_std=std,
        contact_to_com_cov=cov,
        relative_positions_cov={2: cov},
    )
    good = dataclasses.replace(
        bad,
        robot=2,
        relative_positions={1: (2.0, 0.0)},
        contact_to_com=(-1.0, 0.0),
        mass_std=0.1,
        moment_std=0.1,
        contact_to_com_cov=(1e-4, 0.0, 1e-4),
        relative_positions_cov={1: (1e-4, 0.0, 1e-4)},
    )
    state.ingest(bad, 0.1)
    state.ingest(good, 0.1)
    frame = json.loads(to_json(state.frame(0.2)))
    points = frame["points"]
    for trace in ("mass/1", "moment/1", "ctc/1", "edge/1-2"):
        assert points[trace] == [[0.1, points[trace][0][1]]], trace  # the estimate, no band
    for trace in ("mass/2", "moment/2", "ctc/2"):
        assert len(points[trace][0]) == 3, trace
    rows = frame["scene"]["table"]["robots"]
    assert rows["1"]["intervals"] == {}  # the page is sent only those published
    assert rows["2"]["intervals"]["mass"] == [pytest.approx(SCALAR_95 * 0.1), True]
    assert set(rows["2"]["intervals"]) == {"mass", "moment", "contact_to_com", "relative_positions"}
    assert set(frame["scene"]["top"]["com_ellipses"]) == {"2"}
    scene = state.scene(0.2)
    intervals = scene["table"]["robots"]["1"]["intervals"]
    assert set(intervals) == set(rows["2"]["intervals"])
    assert all(interval == [None, None] for interval in intervals.values())
    view = scene["robots"]["1"]
    # As published when it can be a standard deviation (1e308 can, its interval cannot).
    assert view["mass_std"] == (std if math.isfinite(std) and std >= 0 else None)
    assert view["contact_to_com_cov"] is None
    assert view["relative_positions_cov"] == {"2": None}
