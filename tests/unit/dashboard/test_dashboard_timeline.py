"""Each message's own instant (dashboard/timeline.py) as a recording's ``log_time``: a plant's
team on the plant's clock to the nanosecond however its messages arrive, a team without a plant
on its robots' ticks anchored once on the wall clock, one clock per recording whatever is heard
first; and a recorder's file with ``log_time`` the instant and ``publish_time`` the arrival.
A real lockstep run's recording is checked in tests/integration/test_recording_over_zenoh.py."""

from __future__ import annotations

import random
from pathlib import Path

from mcap.reader import make_reader

from agent.platform.protocol import (
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
    Status,
    Truth,
)
from dashboard.channels import ROBOT_KINDS, TEAM_KINDS, decode_on
from dashboard.recorder import Recorder
from dashboard.timeline import Timeline
from dashboard.topics import HOLD_S, Topics
from tests.helpers.forged import KEYS, forged_messages
from tests.helpers.foxglove import decoder

PERIOD = 0.01
WALL = 1_800_000_000_000_000_000
"""A wall clock (ns since the epoch) at which the tests' teams start."""
GEOMETRY = LoadGeometry(2, ((-1.0, -0.5), (1.0, -0.5), (0.0, 1.0)), ((1, 2),), PERIOD)


def truth(k: int) -> Truth:
    zero = (0.0, 0.0)
    return Truth(
        k, k * PERIOD, zero, 0.0, zero, 0.0, (zero, zero), (zero, zero), (zero, zero), 1, 1
    )


def tick_traffic(k: int, plant: bool = True) -> list[object]:
    """What two robots' team publishes at tick ``k``, in a lockstep plant's order: the samples
    and the clock, each robot's command, estimates (every 5 ticks: of the tick before) and
    status, and the truth of ``t_k``; without a plant, the bridges' samples and statuses."""
    messages: list[object] = [Measurement(i, k, k * PERIOD, (0.1, 0.0), (1.0, 0.0)) for i in (1, 2)]
    if plant:
        messages.append(Clock(k, k * PERIOD))
    for i in (1, 2):
        messages.append(Command(i, k, (1.0, 0.0)))
        if k % 5 == 0:
            messages.append(Estimates(i, k - 1, Phase.EXCITE))
        messages.append(Status(i, k, Phase.EXCITE))
        if not plant:
            messages.append(BridgeStatus(i, k))
    if plant:
        messages.append(truth(k))
        if k % 50 == 0:
            messages += [PlantStatus(k, k * PERIOD, "lockstep"), GEOMETRY]
    return messages


def stamped(messages: list[object], arrivals: list[int]) -> list[tuple[object, int]]:
    """Each message's ``log_time``, held as :class:`Topics` holds it while the clock is not
    known (then released, before the message that makes it known, at that one's instant)."""
    timeline = Timeline()
    out: list[tuple[object, int]] = []
    held: list[tuple[object, int]] = []
    for message, at in zip(messages, arrivals):
        log_time = timeline.log_time_ns(message, at)
        if log_time is None:
            held.append((message, at))
            continue
        out += [(m, timeline.log_time_ns(m, a)) for m, a in held] + [(message, log_time)]
        held = []
    return out


def arrivals(count: int, step_ns: int, seed: int = 1) -> list[int]:
    """Arrival times (ns since the epoch), ``step_ns`` apart on average, batches sharing one."""
    rng = random.Random(seed)
    times, now = [], WALL
    for _ in range(count):
        if rng.random() < 0.7:  # most messages arrive in the same batch as the one before
            now += rng.randrange(0, 2 * step_ns)
        times.append(now)
    return times


def test_a_plants_team_is_on_the_plants_clock_to_the_nanosecond() -> None:
    """Lockstep: 1 ms of wall clock per 10 ms tick, messages in batches. Every message with a
    ``time_s`` has it as ``log_time`` exactly; every tick-stamped message its tick's Clock's;
    the estimates of the tick before the first sample, the geometry and the stop what came
    before them."""
    messages: list[object] = [GEOMETRY]
    for k in range(300):
        messages += tick_traffic(k)
    messages.append(Control())
    stamps = stamped(messages, arrivals(len(messages), 100_000))
    clock = {m.tick: t for m, t in stamps if isinstance(m, Clock)}
    newest = 0
    for message, log_time in stamps:
        if hasattr(message, "time_s"):
            assert log_time == round(message.time_s * 1e9), message
        elif getattr(message, "tick", -1) >= 0:
            assert log_time == clock[message.tick], message
        else:  # the geometry, the estimates of tick -1, the stop
            assert log_time == newest, message
        newest = max(newest, log_time)
    assert len({t for _, t in stamps}) == 300
    assert stamps[-1][1] == clock[299]


def test_a_tick_heard_before_its_clock_is_placed_by_the_period() -> None:
    """Estimates of a tick whose Clock is not heard yet (crossing on the way): ``t_c + (k - c)
    T`` from the latest tick heard, the plant's period."""
    timeline = Timeline()
    assert timeline.log_time_ns(GEOMETRY, WALL) == 0
    assert timeline.log_time_ns(Clock(10, 0.1), WALL + 1) == 100_000_000
    assert timeline.log_time_ns(Estimates(1, 12, Phase.EXCITE), WALL + 2) == 120_000_000
    assert timeline.log_time_ns(Status(1, 7, Phase.EXCITE), WALL + 3) == 70_000_000


def test_a_team_without_a_plant_is_on_its_ticks_anchored_once_on_the_wall_clock() -> None:
    """Real robots: the bridges' statuses before the first sample wait for it and take its
    instant; from the first sample on, tick ``k`` is at ``a + k T`` (``a`` the wall clock of
    tick 0, fixed once, ``T`` from the samples' ``time_s / tick``) however late each message
    arrives."""
    before = [BridgeStatus(1, -1), BridgeStatus(2, -1), Control("stop")]
    messages = before + [m for k in range(1000, 1200) for m in tick_traffic(k, plant=False)]
    at = arrivals(len(messages), 3_000_000)
    stamps = stamped(messages, at)
    first = stamps[3]
    assert [t for _, t in stamps[:4]] == [at[3]] * 4
    assert isinstance(first[0], Measurement) and first[1] == at[3]
    origin = at[3] - round(first[0].time_s * 1e9)
    for message, log_time in stamps[3:]:
        assert abs(log_time - (origin + round(message.tick * PERIOD * 1e9))) <= 1, message
    for message, log_time in stamps[3:]:
        if isinstance(message, Measurement):
            assert log_time == origin + round(message.time_s * 1e9)


def test_a_recorder_that_hears_a_robot_first_keeps_one_clock() -> None:
    """Joining a simulated team late, the first message a robot's sample: the plant's clock is
    anchored on the wall clock from it, and stays so once the plant is heard: every stamp on
    one clock, ``log_time - time_s`` the same for every message that has one."""
    messages = [m for k in range(500, 600) for m in tick_traffic(k)][1:]
    stamps = stamped(messages, arrivals(len(messages), 100_000))
    offsets = {t - round(m.time_s * 1e9) for m, t in stamps if hasattr(m, "time_s")}
    assert len(offsets) == 1 and offsets.pop() > WALL - 10**10


def test_a_recording_carries_the_instant_as_log_time_and_the_arrival_as_publish_time(
    tmp_path: Path,
) -> None:
    keys = Keys("clock")
    messages = [GEOMETRY] + [m for k in range(20) for m in tick_traffic(k)]
    at = arrivals(len(messages), 100_000)
    path = tmp_path / "clock.mcap"
    with Recorder(path, "clock") as recorder:
        expected = stamped(messages, at)
        for message, received in zip(messages, at):
            recorder.write(_key(keys, message), message, received)
    with open(path, "rb") as stream:
        read = [
            (m.log_time, m.publish_time)
            for schema, _, m in make_reader(stream).iter_messages()
            if schema.name.startswith("heft.")
        ]
    assert sorted(read) == sorted((t, r) for (_, t), r in zip(expected, at))
    with open(path, "rb") as stream:  # what Foxglove draws: at the instant of its message
        drawn = [
            (m.log_time, m.publish_time)
            for schema, _, m in make_reader(stream).iter_messages()
            if schema.name.startswith("foxglove.")
        ]
    assert drawn and set(drawn) <= set(read)


def test_topics_stamp_every_message_with_its_own_instant() -> None:
    topics = Topics("clock")
    keys = Keys("clock")
    out = [topics.of(keys.geometry(), GEOMETRY, WALL)]
    out.append(topics.of(keys.truth(), truth(3), WALL + 5))
    out.append(topics.of(keys.force(1), Command(1, 3, (0.0, 0.0)), WALL + 5))
    out.append(topics.of(keys.control(), Control(), WALL + 9))
    assert [{o.log_time_ns for o in items} for items in out] == [{0}, *[{30_000_000}] * 3]
    assert len(out[1]) == 3  # the truth's record, the load frame and the scene


def _key(keys: Keys, message: object) -> str:
    robot = getattr(message, "robot", None)
    if robot is not None:
        return ROBOT_KINDS[type(message)](keys, robot)
    return TEAM_KINDS[type(message)](keys)


def test_what_comes_before_the_plant_waits_for_its_clock() -> None:
    """An agent's log line and a bridge's status of tick -1 heard before the plant: held, then
    recorded at the plant's first instant (0), before the plant's first message; a lockstep
    recording has no wall-clock stamp."""
    topics = Topics("clock")
    keys = Keys("clock")
    early = [
        (keys.log(1), LogLine(1, -1, "info", "robot 1: waiting for the plant"), WALL),
        (keys.bridge(2), BridgeStatus(2, -1), WALL + 1_000_000),
    ]
    assert [topics.of(key, m, at) for key, m, at in early] == [[], []]
    out = topics.of(keys.clock(), Clock(0, 0.0), WALL + 2_000_000)
    assert [(o.topic, o.log_time_ns) for o in out][:3] == [
        (keys.log(1), 0),
        ("heft/clock/log", 0),
        (keys.bridge(2), 0),
    ]
    assert out[-1].topic == keys.clock() and {o.log_time_ns for o in out} == {0}


def test_without_a_clock_what_is_held_goes_out_at_its_arrival() -> None:
    """Nothing with an instant within HOLD_S (a team whose bridges wait for their bus): the held
    messages go out at their arrival, and so does what follows until an instant is heard."""
    topics = Topics("clock")
    keys = Keys("clock")
    statuses = [BridgeStatus(1, -1)] * 3
    at = [WALL, WALL + 10**9, WALL + int(HOLD_S * 1e9)]
    out = [topics.of(keys.bridge(1), m, t) for m, t in zip(statuses, at)]
    assert out[:2] == [[], []]
    assert [o.log_time_ns for o in out[2]] == at
    later = topics.of(keys.bridge(1), BridgeStatus(1, -1), WALL + 5 * 10**9)
    assert [o.log_time_ns for o in later] == [WALL + 5 * 10**9]


def test_a_recorder_closing_writes_what_it_held(tmp_path: Path) -> None:
    path = tmp_path / "held.mcap"
    keys = Keys("clock")
    with Recorder(path, "clock") as recorder:
        recorder.write(keys.control(), Control(), WALL)
    with open(path, "rb") as stream:
        read = [(c.topic, m.log_time) for _, c, m in make_reader(stream).iter_messages()]
    assert read == [(keys.control(), WALL)]


def test_messages_from_far_ahead_are_recorded_but_move_neither_clock_nor_scene(
    tmp_path: Path,
) -> None:
    """A robot's certificate in a forger's hands: every forged message that decodes (ticks far
    ahead, 2**62 among them) is recorded, stamped with the newest instant; the team's own
    messages around them keep their instants, nothing of theirs is lost, and the scene still
    draws the team's own commands."""
    rng = random.Random(7)
    keys = KEYS
    path = tmp_path / "forged.mcap"
    sent, forged = [], 0
    with Recorder(path, keys.team) as recorder:
        recorder.write(keys.geometry(), GEOMETRY, WALL)
        for k in range(200):
            for message in tick_traffic(k):
                recorder.write(_key(keys, message), message, WALL + k)
                sent.append(message)
            if k >= 20:
                for key, payload in forged_messages(rng, 2, k):
                    try:
                        message = decode_on(keys, key, payload)
                    except DecodeError:
                        continue
                    recorder.write(key, message, WALL + k)
                    forged += 1
    assert forged > 100
    assert recorder.topics.failures == 0
    with open(path, "rb") as stream:
        read = [
            (c.topic, m.log_time, m.data, s.name)
            for s, c, m in make_reader(stream).iter_messages(log_time_order=False)
        ]
    records = [r for r in read if r[3].startswith("heft.")]
    assert len(records) == 1 + len(sent) + forged  # nothing lost, nothing dropped
    assert max(t for _, t, _, _ in read) == round(199 * PERIOD * 1e9)  # never ahead of the team
    scenes = [r for r in read if r[3] == "foxglove.SceneUpdate"]
    last = decoder("foxglove.SceneUpdate", _schema(path, "foxglove.SceneUpdate")).FromString(
        scenes[-1][2]
    )
    arrows = [e for e in last.entities if e.id.startswith("force/")]
    forces = [float({m.key: m.value for m in a.metadata}["x"]) for a in arrows]
    assert forces == [1.0, 1.0]  # the team's commands, not the forged 10 N of far-ahead ticks


def _schema(path: Path, name: str) -> bytes:
    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    return next(s.data for s in summary.schemas.values() if s.name == name)
