"""A load that changes: the scenario's events, the plant, the probes' test, the team's restart,
and end to end under noise (a heavier load, a moved COM, and no change without a false alarm)."""

from __future__ import annotations

import dataclasses
import math
import random
import tomllib
from pathlib import Path

import pytest

from agent.algorithm.coordination import PhaseBarrier
from agent.algorithm.robust.load_change import ProbeFit
from agent.platform.protocol import Barrier, Phase, Share, decode, encode
from dashboard.state import TeamState
from simulator.inprocess import run_inprocess
from simulator.plant import Plant
from simulator.results import format_table, load_changes, results_dict
from simulator.scenario import (
    LoadChange,
    ScenarioError,
    load_scenario,
    parse_scenario,
    scenario_to_toml,
)
from tests.helpers.paths import PAPER

NOISY = PAPER.with_name("paper-noisy.toml")


def _table(path: Path) -> dict:
    with open(path, "rb") as f:
        return tomllib.load(f)


# ------------------------------------------------------------------------------ the scenario
def test_events_are_read_checked_and_written_back() -> None:
    data = _table(PAPER)
    data["events"] = [{"at_s": 30.0, "mass": 6.0}, {"at_s": 40.0, "com": [0.1, -0.1]}]
    data["run"]["hold_s"] = 8.0
    scenario = parse_scenario(data)
    assert scenario.events == (
        LoadChange(at_s=30.0, mass=6.0),
        LoadChange(at_s=40.0, com=(0.1, -0.1)),
    )
    assert scenario.end_s == 48.0 and scenario.end_tick == 4800
    after_first = scenario.events[0].applied_to(scenario.body)
    assert after_first.mass == 6.0 and after_first.com == scenario.body.com
    assert scenario.events[1].applied_to(after_first).com == (0.1, -0.1)
    assert parse_scenario(tomllib.loads(scenario_to_toml(scenario))) == scenario


@pytest.mark.parametrize(
    ("events", "message"),
    [
        ([{"at_s": 30.0}], "events[0]: expected at least one of mass, moment, com"),
        ([{"at_s": 70.0, "mass": 1.0}], "events[0].at_s: expected a time before run.max_time_s"),
        ([{"at_s": 30.0, "mass": -1.0}], "events[0].mass: expected a number in [0.01, 10000]"),
        ([{"at_s": 30.0, "com": [50.0, 0.0]}], "events[0]: body.com: expected a point within"),
        ([{"at_s": 30.0, "mass": 6.0, "x": 1}], "events[0].x: unknown key"),
        ([{"at_s": 30.0, "mass": 6.0}, {"at_s": 20.0, "mass": 5.0}], "events[1].at_s"),
        ({"at_s": 30.0}, "events: expected an array of tables"),
        ([{"at_s": 30.0, "moment": 1e5}], "events[0]: body.moment: expected a number in"),
    ],
)
def test_bad_events_are_refused_by_key(events, message: str) -> None:
    data = _table(PAPER)
    data["events"] = events
    with pytest.raises(ScenarioError) as err:
        parse_scenario(data)
    assert message in str(err.value)


def test_the_plant_changes_the_load_and_keeps_every_contact_moving_as_it_was() -> None:
    plant = Plant(load_scenario(PAPER))
    for i in range(4):
        plant.command(i + 1, (1.0, 0.5 * i))
    for _ in range(50):
        plant.advance()
    before = plant.truth()
    plant.change_load(6.0, 10.0, (0.3, 0.1))
    after = plant.truth()
    assert (after.mass, after.moment) == (6.0, 10.0)
    assert after.contacts == before.contacts and after.angle == before.angle
    for v, w in zip(before.contact_velocities, after.contact_velocities, strict=True):
        assert math.dist(v, w) < 1e-12
    # The COM is now (0.3, 0.1) of the load frame: its offset from contact 1, turned back.
    c, s = math.cos(after.angle), math.sin(after.angle)
    dx, dy = 0.3 - (-2.0), 0.1 - 0.4
    assert math.dist(after.contact_to_com[0], (c * dx - s * dy, s * dx + c * dy)) < 1e-12


def test_the_plant_applies_a_scenario_event_at_its_time() -> None:
    data = _table(PAPER)
    data["events"] = [{"at_s": 0.5, "mass": 7.0}]
    plant = Plant(parse_scenario(data))
    for _ in range(50):
        plant.advance()
    assert plant.truth().mass == 5.0  # the tick at 0.5 s is not integrated yet
    plant.advance()
    assert plant.truth().mass == 7.0


# ------------------------------------------------------------------------------ the probe's test
def _probe_rows(probe: ProbeFit, delta: tuple[float, float], kappa: float, rng=None) -> None:
    """Feed ``probe`` the velocities of a load turning at 0.5 rad/s whose estimated COM is
    ``delta`` off and whose acceleration is ``kappa`` times the estimated one."""
    omega, dt, sigma = 0.5, 0.01, 0.0 if rng is None else 0.01
    velocity, once = [0.1, -0.05], 0.0
    ax, ay = probe.acceleration
    for k in range(201):
        sign = 0.0 if k == 0 else (1.0 if k <= 50 or k > 150 else -1.0)
        once += sign * dt
        turn = omega * k * dt
        c, s = math.cos(turn), math.sin(turn)
        dx, dy = c * delta[0] - s * delta[1], s * delta[0] + c * delta[1]
        v = (
            velocity[0] + kappa * ax * once - omega * dy,
            velocity[1] + kappa * ay * once + omega * dx,
        )
        if rng is not None:
            v = (v[0] + rng.gauss(0, sigma), v[1] + rng.gauss(0, sigma))
        probe.update(v, omega, probe.angle0 + turn, sign, dt if k else 0.0)


def test_the_probe_fit_finds_the_mass_ratio_and_the_com_offset_exactly() -> None:
    probe = ProbeFit(4, 5.0, (0.0, 2.0), 0.0, 0.3)
    _probe_rows(probe, (0.07, -0.02), 5.0 / 6.0)
    fit = probe.solve()
    assert fit is not None
    _, _, kappa, dx, dy = fit.estimate
    assert kappa == pytest.approx(5.0 / 6.0, abs=1e-9)
    assert (dx, dy) == pytest.approx((0.07, -0.02), abs=1e-9)


def test_the_probe_scores_a_change_far_above_the_noise_and_no_change_below_it() -> None:
    rng = random.Random(3)
    published = (0.005, (1e-4, 0.0, 1e-4))  # m̂ to 0.5 %, the offset to 1 cm per axis
    quiet = ProbeFit(4, 5.0, (0.0, 2.0), 0.0, 0.0)
    _probe_rows(quiet, (0.0, 0.0), 1.0, rng)
    d_m, d_c = quiet.score(*published)
    assert d_m < 3.0 and d_c < 3.0
    heavier = ProbeFit(4, 5.0, (0.0, 2.0), 0.0, 0.0)
    _probe_rows(heavier, (0.0, 0.0), 1 / 1.2, rng)
    assert heavier.score(*published)[0] > 20.0
    moved = ProbeFit(4, 5.0, (0.0, 2.0), 0.0, 0.0)
    _probe_rows(moved, (0.1, 0.0), 1.0, rng)
    assert moved.score(*published)[1] > 6.0


# ------------------------------------------------------------------------------ the restart
def test_one_robot_restarts_the_team_and_every_robot_restarts_at_the_same_tick() -> None:
    n = 3
    barriers = {i: PhaseBarrier(i, n, 2) for i in range(1, n + 1)}
    for b in barriers.values():
        b.phase = Phase.DONE
    heard: dict[int, list[Share]] = {i: [] for i in barriers}
    switched: dict[int, int] = {}
    for tick in range(20):
        sent = []
        for i, b in barriers.items():
            if (
                b.step(tick, i == 3 and tick >= 4, [s.barrier for s in heard[i]])
                and b.phase == Phase.INERTIA
            ):
                switched[i] = tick
            sent.append(
                Share(
                    i,
                    tick,
                    (0.0, 0.0),
                    1,
                    barrier=Barrier(
                        phase=b.phase, switch_at=b.switch_at, load_changes=b.load_changes
                    ),
                )
            )
        # the line 1 - 2 - 3: each hears its neighbours' last messages
        heard = {i: [s for s in sent if abs(s.sender - i) == 1] for i in barriers}
    assert set(switched) == {1, 2, 3} and len(set(switched.values())) == 1
    assert all(b.load_changes == 1 and b.phase == Phase.INERTIA for b in barriers.values())


def test_more_load_changes_are_caught_up_with_and_halted_beats_any_number() -> None:
    b = PhaseBarrier(1, 2, 0)
    b.phase = Phase.DONE
    b.step(10, False, [Barrier(phase=Phase.EXCITE, load_changes=2)])
    assert (b.phase, b.load_changes) == (Phase.EXCITE, 2)
    b.step(11, False, [Barrier(phase=Phase.DONE, load_changes=1)])
    assert (b.phase, b.load_changes) == (Phase.EXCITE, 2)  # fewer load changes: not gone back
    b.step(12, False, [Barrier(phase=Phase.HALTED, load_changes=0)])
    assert b.phase == Phase.HALTED


def test_the_load_changes_cross_the_wire_and_are_domain_checked() -> None:
    share = Share(1, 5, (0.0, 0.0), 1, barrier=Barrier(load_changes=7))
    assert decode(Share, encode(share)).barrier.load_changes == 7
    with pytest.raises(ValueError, match="share.barrier.load_changes"):
        decode(Share, encode(dataclasses.replace(share, barrier=Barrier(load_changes=60_000))))


# ------------------------------------------------------------------------------ end to end
def _noisy(seed: int, **run) -> dict:
    data = _table(NOISY)
    data["run"].update(seed=seed, max_time_s=90.0, **run)
    return data


@pytest.mark.parametrize(
    ("seed", "change"),
    [(3, {"mass": 6.0}), (4, {"com": [0.1, -0.138889]})],
    ids=["mass+20%", "com+10cm"],
)
def test_a_changed_load_is_noticed_within_5_s_and_estimated_again(seed, change) -> None:
    data = _noisy(seed, hold_s=12.0)
    data["events"] = [{"at_s": 25.0, **change}]
    outcome = run_inprocess(parse_scenario(data), record_every=10)
    found = load_changes(outcome)
    (event,) = found["changes"]
    assert event["latency_s"] is not None and 0.0 < event["latency_s"] <= 5.0
    assert found["false_alarms"] == 0
    assert outcome.converged and outcome.final.time_s >= 37.0
    truth = outcome.final.truth
    assert truth.mass == pytest.approx(change.get("mass", 5.0))
    for est in outcome.final.estimates.values():
        assert est.load_changes == 1
        assert abs(est.mass / truth.mass - 1.0) < 0.03
        assert abs(est.moment / truth.moment - 1.0) < 0.05
        assert math.dist(est.contact_to_com, truth.contact_to_com[est.robot - 1]) < 0.04
    assert results_dict(outcome)["floor"]["within"]
    assert "restarted" in format_table(outcome)
    # The dashboard, fed the run, ends on the same final instant: the one after the restart.
    state = TeamState("changing", outcome.scenario.load_geometry())
    for sample in [*outcome.history, outcome.final]:
        state.ingest(sample.truth, sample.truth.time_s)
        for est in sample.estimates.values():
            state.ingest(est, sample.truth.time_s)
    assert state.final is not None and state.final["tick"] == outcome.final.truth.tick
    assert {row["load_changes"] for row in state.final["robots"].values()} == {1}


def test_an_unchanged_load_raises_no_alarm_while_it_is_watched() -> None:
    outcome = run_inprocess(parse_scenario(_noisy(5, hold_s=40.0)), record_every=10)
    found = load_changes(outcome)
    assert found == {"changes": [], "restarts_s": [], "false_alarms": 0}
    assert outcome.converged and outcome.final.time_s >= 40.0
    scores = [e.change_score for e in outcome.final.estimates.values()]
    assert all(s is not None and s < 6.0 for s in scores)  # the probes ran, and passed
    assert results_dict(outcome)["floor"]["within"]
