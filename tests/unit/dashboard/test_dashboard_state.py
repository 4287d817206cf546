"""The dashboard's state (dashboard/state.py) and channels (dashboard/channels.py), alone: fed
the messages of a real run of the paper's scenario (in one process), it holds charts that
converge to the truth, finds the same final instant and estimates as the run, and stays
bounded and wary of bad input."""

from __future__ import annotations

import copy
import dataclasses
import json
import math

import pytest

from agent.platform.protocol import (
    KINDS,
    Barrier,
    BridgeStatus,
    Clock,
    Command,
    Control,
    DecodeError,
    Estimates,
    Keys,
    LoadGeometry,
    LogLine,
    Measurement,
    Phase,
    PlantStatus,
    Share,
    Status,
    Truth,
    encode,
)
from agent.platform.team import ConsensusState
from dashboard import channels
from dashboard.quantities import SCALARS
from dashboard.state import KEEP_TICKS, MAX_SEGMENTS, TeamState
from tests.helpers.paths import PAPER

SCALAR_KEYS = [s.key for s in SCALARS]


@pytest.fixture(scope="module")
def paper_run():
    """The paper's scenario in one process: its recorded instants (truth and every robot's
    estimates, every 5 ticks, then the final instant)."""
    from simulator.inprocess import run_inprocess
    from simulator.scenario import load_scenario

    scenario = load_scenario(PAPER)
    outcome = run_inprocess(scenario)
    assert outcome.converged
    return scenario, outcome


def feed(state: TeamState, outcome) -> None:
    """The run's instants into ``state``, as a display would hear them (10 ms apart)."""
    for sample in [*outcome.history, outcome.final]:
        now = sample.truth.time_s
        state.ingest(sample.truth, now)
        for est in sample.estimates.values():
            state.ingest(est, now)


def test_the_charts_converge_to_the_truth_and_the_final_table_is_the_runs(paper_run) -> None:
    from simulator.results import robot_errors

    scenario, outcome = paper_run
    state = TeamState("paper", scenario.load_geometry())
    feed(state, outcome)
    series = state.all_series()
    for i in range(1, 5):
        masses = series[f"mass/{i}"]
        assert abs(masses[-1][1] - 5.0) < 1e-3  # m̂ converged to the true 5 kg
        assert abs(series[f"moment/{i}"][-1][1] - 12.3795) / 12.3795 < 1e-3
        assert [t for t, _ in masses] == sorted(t for t, _ in masses)
    assert series["mass/truth"][-1][1] == 5.0
    for (i, j), truth in zip(
        scenario.edges, ("edge/1-2/truth", "edge/2-3/truth", "edge/3-4/truth")
    ):
        estimated = series[f"edge/{min(i, j)}-{max(i, j)}"][-1][1]
        assert abs(estimated - series[truth][-1][1]) < 1e-3
    # The final instant and table are the run's own.
    final = state.final
    assert final is not None and final["final"]
    assert final["tick"] == outcome.final.truth.tick
    for i, est in outcome.final.estimates.items():
        row = final["robots"][str(i)]
        assert row["mass"] == est.mass and row["moment"] == est.moment
        assert tuple(row["contact_to_com"]) == est.contact_to_com
        assert row["errors"]["mass_rel"] < 1e-4 and row["errors"]["contact_to_com_m"] < 1e-3
        assert row["errors"] == robot_errors(outcome, i)  # the results' own figures
    assert state.done and not state.halted
    # The phase timeline: every robot went through the four phases in order, the team
    # switched together, and the charts' time axis is simulated seconds.
    scene = state.scene(now=100.0)
    for view in scene["robots"].values():
        assert [label for label, _ in view["segments"]] == ["excite", "inertia", "push", "done"]
    switches = scene["switches"]
    assert switches["excite"] < switches["inertia"] < switches["push"] < switches["done"]
    assert switches["done"] == pytest.approx(outcome.sim_time_s, abs=0.02)
    assert scene["alarms"] == []
    top = scene["top"]
    assert top["source"] == "truth" and len(top["outline"]) == len(scenario.body.polygon)
    for robot, com in top["com_estimates"].items():
        assert math.dist(com, top["com"]) < 1e-3, robot


def test_the_papers_estimators_publish_no_uncertainty_and_get_no_band(paper_run) -> None:
    scenario, outcome = paper_run
    state = TeamState("paper", scenario.load_geometry())
    feed(state, outcome)
    assert {len(p) for points in state.all_series().values() for p in points} == {2}
    for row in state.final["robots"].values():
        assert set(row["intervals"]) == {*SCALAR_KEYS, "contact_to_com", "relative_positions"}
        assert all(interval == [None, None] for interval in row["intervals"].values())
    assert state.top_view()["com_ellipses"] == {}
    page = state.page_scene(100.0)["table"]["robots"]
    assert all(row["intervals"] == {} for row in page.values())


def test_the_pages_scene_is_the_scene_less_what_the_page_does_not_draw(paper_run) -> None:
    scenario, outcome = paper_run
    state = TeamState("paper", scenario.load_geometry())
    feed(state, outcome)
    final = copy.deepcopy(state.final)
    scene, page = state.scene(200.0), state.page_scene(200.0)
    assert state.final == final  # the final table is read, never trimmed in place
    assert len(json.dumps(page)) < len(json.dumps(scene)) / 2
    for key in ("truth", "plant", "received", "rejected"):
        assert key in scene and key not in page
    for key in ("top", "links", "alarms", "switches", "phases", "n", "t", "team"):
        assert page[key] == scene[key]
    for i in ("1", "2", "3", "4"):
        full, drawn = scene["robots"][i], page["robots"][i]
        assert drawn == {k: full[k] for k in ("phase", "tick", "segments", "alive")}
        row = page["table"]["robots"][i]
        errors = final["robots"][i]["errors"]
        drawn = (*(s.error for s in SCALARS), "contact_to_com_m", "relative_positions_m")
        assert row["errors"] == {key: errors[key] for key in drawn}
        assert errors["friction_torque_nm"] is None  # the paper's estimators: no friction
        assert (row["mass"], row["moment"]) == (
            final["robots"][i]["mass"],
            final["robots"][i]["moment"],
        )
    assert page["table"]["final"] and page["table"]["t"] == final["t"]
    assert page["table"]["truth"] == {
        "mass": 5.0,
        "moment": final["truth"]["moment"],
        "friction_torque": 0.0,  # a frictionless floor: μ m g c = 0
        "coulomb": 0.0,
    }
    assert SCALAR_KEYS == ["mass", "moment", "friction_torque", "coulomb"]


def test_a_lost_message_of_the_final_instant_moves_it_to_the_next_complete_one(paper_run) -> None:
    """As the launcher does: the first complete instant once the team is done; and the done
    instant itself if its messages arrive late."""
    scenario, outcome = paper_run
    final = outcome.final
    state = TeamState("paper", scenario.load_geometry())
    for sample in outcome.history:
        if sample.truth.tick < final.truth.tick:
            state.ingest(sample.truth, sample.time_s)
            for est in sample.estimates.values():
                state.ingest(est, sample.time_s)
    later = [dataclasses.replace(e, tick=e.tick + 1) for e in final.estimates.values()]
    truth = dataclasses.replace(final.truth, tick=final.truth.tick + 1)
    for est in final.estimates.values():  # robot 3's estimate of the done instant is lost
        if est.robot != 3:
            state.ingest(est, 9.0)
    state.ingest(final.truth, 9.0)
    assert state.final is None
    for est in later:
        state.ingest(est, 9.01)
    state.ingest(truth, 9.01)
    assert state.final["tick"] == final.truth.tick + 1
    state.ingest(final.estimates[3], 9.02)  # it was only late
    assert state.final["tick"] == final.truth.tick
    assert state.final["robots"]["3"]["mass"] == final.estimates[3].mass


def test_frames_carry_each_point_once_and_charts_are_sparse(paper_run) -> None:
    _, outcome = paper_run
    state = TeamState("paper")
    samples = [*outcome.history, outcome.final]
    half = len(samples) // 2
    seen: dict[str, list] = {}
    for part in (samples[:half], samples[half:]):
        for sample in part:
            state.ingest(sample.truth, sample.time_s)
            for est in sample.estimates.values():
                state.ingest(est, sample.time_s)
        for trace, points in state.frame(now=0.0)["points"].items():
            seen.setdefault(trace, []).extend(points)
    assert state.frame(now=0.0)["points"] == {}
    assert seen == state.all_series()
    # A point per 0.05 s of simulated time, whatever the report rate (and one at each phase
    # change and at the final instant).
    ts = [t for t, _ in seen["omega/1"]]
    assert len(ts) <= outcome.sim_time_s / 0.05 + 1 + 4
    assert state.period == pytest.approx(0.01)  # learned from the truth


def test_memory_is_bounded_whatever_the_length_of_the_run() -> None:
    state = TeamState("t", capacity=50)
    for k in range(20_000):
        phase = Phase.DONE if k % 2 else Phase.PUSH  # a phase flapping forever
        state.ingest(Estimates(1, k, phase, phase_since=k, mass=1.0 + k), now=k * 0.01)
        state.ingest(Share(1, k, (0.0, 0.0), 1), now=k * 0.01)
        truth = Truth(
            k,
            k * 0.01,
            (0, 0),
            0,
            (0, 0),
            0.1,
            ((0, 0), (1, 0)),
            ((0, 0),) * 2,
            ((0, 0),) * 2,
            1,
            1,
        )
        state.ingest(truth, now=k * 0.01)
    view = state.robots[1]
    assert all(len(points) <= 50 for points in state.series.values())
    assert len(view.segments) <= MAX_SEGMENTS
    assert len(view.done_estimates) <= KEEP_TICKS and len(state.truths) <= KEEP_TICKS
    assert len(view.shares) <= 1000
    assert state.series["mass/1"][-1][1] == 20_000.0


def test_messages_outside_the_team_or_window_are_counted_and_dropped() -> None:
    geometry = LoadGeometry(4, ((0, 0), (1, 0), (0, 1)), ((1, 2), (2, 3), (3, 4)), 0.01)
    state = TeamState("t", geometry)
    assert state.ingest(Status(2, 10, Phase.EXCITE), now=0.0)
    assert not state.ingest(Status(5, 10, Phase.EXCITE), now=0.0)  # robot 5 of 4
    assert not state.ingest(Estimates(1, 10 + 5000, Phase.EXCITE), now=0.0)  # far ahead
    wrong = Truth(1, 0.01, (0, 0), 0, (0, 0), 0, ((0, 0),) * 3, ((0, 0),) * 3, ((0, 0),) * 3, 1, 1)
    assert not state.ingest(wrong, now=0.0)  # three contacts: not this load
    assert state.rejected == {
        ("Status", "not in the team"): 1,
        ("Estimates", "tick out of window"): 1,
        ("Truth", "not the team's load"): 1,
    }
    assert set(state.robots) == {2}
    assert state.truth is None
    assert {"level": "warning", "text": "3 message(s) rejected"} in state.alarms(now=0.0)


def test_alarms_lost_robot_halt_bridge_watchdog_and_silence() -> None:
    state = TeamState("t")
    for i in (1, 2, 3):
        state.ingest(Estimates(i, 5, Phase.EXCITE, relative_positions={i % 3 + 1: (1, 0)}), 0.0)
        state.liveliness(i, True, 0.0)
    assert state.alarms(now=0.5) == []
    state.liveliness(3, False, 1.0)
    state.ingest(BridgeStatus(1, 6, watchdog=True), 1.0)
    texts = [a["text"] for a in state.alarms(now=1.0)]
    assert "robot(s) [3] lost" in texts
    assert "robot 1's bridge watchdog: zero force (its agent fell silent)" in texts
    assert not any("sensor" in t for t in texts)
    velocity = BridgeStatus(
        2, 6, watchdog=True, profile="velocity", sensor_stale=True, overload_stops=3
    )
    state.ingest(velocity, 1.0)
    texts = [a["text"] for a in state.alarms(now=1.0)]
    assert "robot 2's bridge watchdog: standstill (its agent fell silent)" in texts
    assert "robot 2's force/torque sensor is stale: standstill" in texts
    assert "robot 2's contact force went beyond max_contact_force: 3 protective stop(s)" in texts
    state.ingest(Status(2, 7, Phase.HALTED, lost_neighbours=(3,)), 1.0)
    texts = [a["text"] for a in state.alarms(now=1.0)]
    assert any(t.startswith("team halted") for t in texts)
    assert any(
        t.startswith("no message from the team") for t in (a["text"] for a in state.alarms(now=9.0))
    )
    # Once the launcher has told the team to stop, robots leaving are no news.
    state.ingest(Control("stop"), 9.0)
    texts = [a["text"] for a in state.alarms(now=9.5)]
    assert not any(t.startswith("robot(s)") for t in texts)
    assert any(t.startswith("team halted") for t in texts)  # that stays: it is the outcome


def test_link_health_from_the_shares_age_and_rate() -> None:
    geometry = LoadGeometry(3, ((0, 0), (1, 0), (0, 1)), ((1, 2), (2, 3)), 0.01)
    state = TeamState("t", geometry)
    for k in range(100):  # robots 1 and 2 at 100 Hz for a second, robot 3 silent since 0.2 s
        state.ingest(Share(1, k, (0, 0), 1), k * 0.01)
        state.ingest(Share(2, k, (0, 0), 2), k * 0.01)
        if k < 20:
            state.ingest(Share(3, k, (0, 0), 1), k * 0.01)
    links = {tuple(link["edge"]): link for link in state.links(now=0.995)}
    assert links[1, 2]["health"] == "ok" and links[1, 2]["rate_hz"] == 100
    assert links[2, 3]["health"] == "late" and links[2, 3]["age_s"] == pytest.approx(0.805)
    assert {link["health"] for link in state.links(now=3.0)} == {"silent"}
    state.liveliness(3, False, 3.0)
    assert {tuple(link["edge"]): link["health"] for link in state.links(now=3.0)}[2, 3] == "lost"


def test_without_truth_the_top_view_is_the_teams_own_geometry() -> None:
    state = TeamState("t")
    state.ingest(Estimates(1, 3, Phase.PUSH, centroid_offset=(-1.0, 0.0), com_offset=(0.1, 0)), 0)
    state.ingest(Estimates(2, 3, Phase.PUSH, centroid_offset=(1.0, 0.0)), 0)
    state.ingest(Command(1, 3, (2.0, 0.5)), 0)
    top = state.top_view()
    assert top["source"] == "estimates"
    assert top["contacts"] == [[-1.0, 0.0], [1.0, 0.0]]
    assert top["com_estimates"] == {"1": [-0.1, 0.0]}  # p_C = p_G − z_C, p_G at the origin
    assert top["forces"] == {"1": [2.0, 0.5]}
    assert top["outline"] is None and top["com"] is None


# ------------------------------------------------------------------------------ channels
EXAMPLES = [
    Measurement(2, 7, 0.07, (0.1, -0.2), (1.0, 2.0)),
    Command(2, 7, (1.5, -0.5)),
    Share(
        2,
        7,
        (0.1, 0.2),
        2,
        6,
        Barrier(Phase.INERTIA, 3, 9, levels=(3, 5)),
        ConsensusState(centroid_offset=(1.0, 2.0), mean_square_offset=3.0),
        (
            (
                1,
                1.0,
                2.0,
                3.0,
                0.1,
                0.2,
                0.3,
                0.4,
                2.0,
                10.0,
                1.6,
                2.6,
                0.5,
                4.0,
                1.0,
                0.2,
                -0.3,
                1e-6,
            ),
        ),
    ),
    Clock(7, 0.07),
    Estimates(2, 7, Phase.PUSH, 5, 0.4, {1: (1.0, 2.0)}, (0.5, 0.5), 2.0, 12.0, mass=5.0),
    Status(2, 7, Phase.DONE, 1, 2, 3, (4,)),
    Truth(7, 0.07, (1, 2), 0.3, (0, 1), 0.4, ((0, 0), (1, 1)), ((0, 0),) * 2, ((1, 1),) * 2, 5, 12),
    Control("stop"),
    PlantStatus(7, 0.07, "realtime", 1, 2, 0, 0, 0, (3,), 1.5, 2.5, 1.6, 10),
    BridgeStatus(2, 7, watchdog=True, frames_in=5),
    LoadGeometry(2, ((-1.0, -1.0), (1.0, -1.0), (0.0, 1.0)), ((1, 2),), 0.01, 300),
    LogLine(2, 7, "warning", "robot 2: lost neighbour 1; halting the team"),
]


def test_every_message_kind_has_its_key_and_survives_a_record_round_trip() -> None:
    assert {type(m) for m in EXAMPLES} == set(KINDS)
    keys = Keys("team")
    for message in EXAMPLES:
        key = keys.of(message)
        assert channels.kind_of(keys, key) is type(message)
        assert channels.decode_on(keys, key, encode(message)) == message
        assert channels.from_record(type(message), channels.record_bytes(message)) == message
        schema = channels.json_schema(type(message))
        record = channels.to_record(message)
        assert set(schema["required"]) <= set(record) <= set(schema["properties"])
        assert set(schema["properties"]) == {f.name for f in dataclasses.fields(message)}
    assert channels.kind_of(keys, keys.alive(1)) is None
    assert channels.kind_of(keys, "heft/other/plant/truth") is None
    assert channels.kind_of(keys, "heft/team/robot/x/force") is None


def test_a_message_on_another_robots_key_or_out_of_its_domain_is_refused() -> None:
    keys = Keys("team")
    with pytest.raises(DecodeError, match="on key"):
        channels.decode_on(keys, keys.force(3), encode(Command(2, 7, (0, 0))))
    with pytest.raises(DecodeError):
        channels.decode_on(keys, keys.force(2), b"\x48\x02\x02garbage")
    for data in (b"{", b"[]", b'{"robot": 0, "tick": 1, "force": [0, 0]}', b'{"robot": 1}'):
        with pytest.raises(DecodeError):
            channels.from_record(Command, data)
    bad = dataclasses.replace(EXAMPLES[1], force=(1e9, 0.0))
    with pytest.raises(DecodeError):
        channels.from_record(Command, channels.record_bytes(bad))


def test_the_load_geometry_is_heard_from_the_plant_as_any_message(paper_run) -> None:
    scenario, outcome = paper_run
    geometry = scenario.load_geometry()
    assert math.dist(geometry.world_outline((0.0, 0.0), 0.0)[0], (-2.0, -1.0 + 0.138889)) < 1e-5
    assert geometry.end_tick == scenario.end_tick and geometry.edges == ((1, 2), (2, 3), (3, 4))
    state = TeamState("paper")  # as a display that joins a team knowing nothing of its load
    state.ingest(outcome.history[0].truth, 0.0)
    assert state.top_view()["outline"] is None
    assert state.ingest(geometry, 0.5)
    assert state.geometry == geometry and state.period_s == scenario.period_s
    truth = outcome.history[0].truth
    assert state.top_view()["outline"] == [
        list(p) for p in geometry.world_outline(truth.com_position, truth.angle)
    ]
    three = dataclasses.replace(geometry, n=3, edges=((1, 2), (2, 3)))
    assert not state.ingest(three, 1.0)  # the truth has four contacts: not this team's load
    assert state.geometry == geometry
    assert state.rejected == {("LoadGeometry", "not the team's load"): 1}
