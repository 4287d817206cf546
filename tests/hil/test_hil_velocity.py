"""Hardware-in-the-loop of the AGV protocol's velocity profile on real kernel CAN (vcan):
velocity-commanded bases behind bridges that close the admittance loop. What is checked is the
plumbing (frames, ticks, stops), not how well the loop tracks its force (``heft bench can
--profile velocity`` measures that). Like tests/hil/test_hil.py, these need vcan (``make
hil``)."""

from __future__ import annotations

import contextlib
import threading
import time
from pathlib import Path

import pytest

from agent.platform.protocol import Command, Keys, encode
from agent.platform.zenoh_session import tick_publisher
from bridge.codec import (
    AgvCodec,
    AppliedForce,
    ForceCommand,
    ForceTorque,
    MotionCommand,
    MotionFeedback,
    Odometry,
    Sync,
)
from bridge.dbc import FORCE_TORQUE_BASE, MOTION_COMMAND_BASE, SENSOR_STATUS_BITS, SYNC_ID
from tests.helpers.hil import (
    AGENT_SILENT,
    ATTEMPTS,
    LATE_TRIP_MS,
    RIG_TEAM,
    SENSOR_STALE,
    STALL_MS,
    STOPS_SEEN,
    WATCHDOG_MS,
    DriverRig,
    assert_within_watchdog,
    decoded_kinds,
    lockstep_over_vcan,
)
from tests.helpers.paths import ROOT

pytestmark = [pytest.mark.hil, pytest.mark.usefixtures("vcan")]

PAPER_VELOCITY = ROOT / "simulator" / "scenarios" / "paper-velocity.toml"
RIG_CHANNEL = "vcan0"
"""The spare interface: the force profile's rig and ``heft bench can`` use vcan8."""
VELOCITY_PERIOD = 0.02
"""s: the rig's tick, a velocity base's command period (AgileX's motion command frame comes
every 20 ms). At the force rig's 10 ms the bridge took two thirds of a User-Mode Linux guest's
CPU at real-time priority, the rig's driver, the router and the echo agent the rest: the
driver's ticks, and the agent's commands, then came 30-80 ms apart now and then."""
PUSH_N = 5.0
"""N: the echo agent's pushes (``--push``)."""
UNLOADED = (0.5, -0.25)
"""N: the sensor's raw reading, its bias alone (nothing presses on it)."""
AGENT_BACK = "commands are back"
"""What the bridge logs when its agent's watchdog clears (it trips: ``AGENT_SILENT``)."""
FAULT = 1 << next(bit for bit, name in SENSOR_STATUS_BITS.items() if name == "FAULT")


# ------------------------------------------------------------------------------ whole runs
def test_lockstep_over_can_reproduces_the_inprocess_can_run_on_velocity_commanded_agvs(
    tmp_path: Path,
) -> None:
    """``heft run paper-velocity.toml --can`` for :data:`~tests.helpers.hil.HIL_RUN_S`: every
    robot's estimates equal the in-process ``link="can"`` run's to 1e-9, the bridges' counters
    clean (:func:`~tests.helpers.hil.lockstep_over_vcan`), every bridge of the velocity
    profile and never stopped (a stop forgets the admittance loop's state, which the run in one
    process does not); robot 1's bus, logged in candump's format, decodes with cantools
    against ``bridge/agv-velocity.dbc``, a frame of each kind per tick."""
    log = tmp_path / "vcan1.log"
    there = lockstep_over_vcan(PAPER_VELOCITY, log)
    for status in there.transport["bridges"].values():
        assert status["profile"] == "velocity"
        assert status["watchdog_trips"] == 0 and status["sensor_stale_trips"] == 0
    kinds = decoded_kinds(log, ROOT / "bridge/agv-velocity.dbc")
    for kind in ("Sync", "MotionFeedback_1", "ForceTorque_1", "MotionCommand_1"):
        assert kinds[kind] >= there.ticks, (kind, kinds)
    assert kinds["Heartbeat_1"] > 0
    assert not {"Odometry_1", "AppliedForce_1", "ForceCommand_1"} & set(kinds)


# ------------------------------------------------------------------------------ one bridge
def commands(frames: list, drive: bool) -> list[float]:
    """The kernel timestamps of the bridge's ``MotionCommand`` frames among ``(timestamp,
    frame)``: those in mode VELOCITY (``drive``) or STOP."""
    return [t for t, f in frames if isinstance(f, MotionCommand) and f.drive == drive]


def last_sample(frames: list) -> float:
    """The kernel timestamp of the last usable ``ForceTorque`` among ``frames``."""
    return max(t for t, f in frames if isinstance(f, ForceTorque) and f.status == 0)


def stops_after(frames: list, since: float) -> list[float]:
    """The timestamps of the STOP frames among ``frames`` that follow the instant ``since``."""
    return [t for t in commands(frames, drive=False) if t > since]


def frames_before(frames: list, until: float, span_s: float = 0.15) -> str:
    """The ``frames`` in the ``span_s`` up to the instant ``until``, one a line: ms before it,
    the frame."""
    return "\n".join(
        f"{(t - until) * 1e3:8.1f} ms {f}"
        for t, f in sorted(frames, key=lambda frame: frame[0])
        if until - span_s <= t <= until
    )


def assert_stopped(frames: list, stops: list[float], delay_ms: float, stalled_ms: float) -> None:
    """The base is stopped: the first of the ``stops`` (the STOP frames' timestamps) came
    ``delay_ms`` after what stops it, within the watchdog plus or minus one frame period, plus
    the ``stalled_ms`` the host stood the machine still meanwhile
    (:func:`~tests.helpers.hil.assert_within_watchdog`), then one a tick (the tests read
    :data:`STOPS_SEEN` of them) and no MotionCommand in mode VELOCITY among the ``frames``.
    If not, the frames up to the first stop are told (:func:`frames_before`)."""
    try:
        assert_within_watchdog(delay_ms, stalled_ms, VELOCITY_PERIOD)
    except AssertionError as err:
        raise AssertionError(
            f"{err}; the frames before the stop:\n{frames_before(frames, stops[0])}"
        ) from None
    assert len(stops) >= STOPS_SEEN
    assert not commands([(t, f) for t, f in frames if t > stops[0]], drive=True)


class VelocityRig(DriverRig):
    """A :class:`~tests.helpers.hil.DriverRig` of the velocity profile on :data:`RIG_CHANNEL`,
    its echo agent pushing :data:`PUSH_N` newtons: the driver's tick is ``Sync``, the base's
    ``MotionFeedback`` and its force/torque sensor's ``ForceTorque`` (:attr:`sensor`:
    ``"ok"``, ``"silent"``: no ``ForceTorque``, or ``"fault"``: its FAULT bit set); what is
    read is ``Sync``, ``ForceTorque`` and the bridge's ``MotionCommand``."""

    def __init__(self, folder: Path) -> None:
        self.sensor = "ok"
        listened = (SYNC_ID, FORCE_TORQUE_BASE + 1, MOTION_COMMAND_BASE + 1)
        super().__init__(
            folder, RIG_CHANNEL, listened, "velocity", push_n=PUSH_N, period=VELOCITY_PERIOD
        )
        self.playing = threading.Event()
        # One publisher for the rig's life, declared before any episode plays through it.
        self.player = tick_publisher(self.rig.session, Keys(RIG_TEAM).force(1))
        self.playing_thread = threading.Thread(target=self._play, daemon=True)
        self.playing_thread.start()

    def tick_frames(self, k: int) -> list:
        frames = [Sync(k), MotionFeedback(1, k % 16, (0.1, 0.2))]
        if self.sensor != "silent":
            status = FAULT if self.sensor == "fault" else 0
            frames.append(ForceTorque(1, k % 16, UNLOADED, status))
        return frames

    def set_sensor(self, state: str) -> None:
        with self.ticking:  # from the next tick on
            self.sensor = state

    def _play(self) -> None:
        while not self.stop.wait(self.period):
            if self.playing.is_set():
                self.player.put(encode(Command(1, self.tick - 1, (0.0, 0.0))))

    @contextlib.contextmanager
    def agent_heard(self):
        """Meanwhile, commands for the bus's newest tick every period, as an agent's that
        keeps answering (the bridge hears them, so its watchdog holds off, and refuses them
        when that tick has no sample yet)."""
        self.playing.set()
        try:
            yield
        finally:
            self.playing.clear()

    def close(self) -> None:
        self.stop.set()
        self.playing_thread.join(5)
        self.player.undeclare()
        super().close()

    def drives_again(self, since: int) -> None:
        """Wait until neither stop holds and the bridge's frames after ``frames[since]``
        include a ``MotionCommand`` in mode VELOCITY."""
        self.wait(lambda s: not s.watchdog and not s.sensor_stale, 30, "both stops clear")
        deadline = time.monotonic() + 30
        while not commands(self.frames[since:], drive=True):
            self.rig.check()
            assert time.monotonic() < deadline, "no MotionCommand in mode VELOCITY within 30 s"
            time.sleep(0.02)

    def agent_stopped_first(self, since: int) -> bool:
        """Whether the agent's watchdog held the base before the sensor's stop, by the
        bridge's log from its byte ``since`` on: it was tripped then (its last trip or clear
        before that is a trip), or it trips before the log says the sensor is stale."""
        log = self.log.read_bytes()
        told = [
            line
            for line in log[:since].decode(errors="replace").splitlines()
            if AGENT_SILENT in line or AGENT_BACK in line
        ]
        return bool(told and AGENT_SILENT in told[-1]) or self.told_before(
            AGENT_SILENT, SENSOR_STALE, since
        )


@pytest.fixture(scope="module")
def rig(tmp_path_factory, vcan) -> VelocityRig:
    rig = VelocityRig(tmp_path_factory.mktemp("velocity-rig"))
    yield rig
    rig.close()


def test_the_other_profiles_frames_are_refused_and_counted(rig: VelocityRig) -> None:
    """The force profile's frames for node 1 (Odometry, AppliedForce and ForceCommand, valid
    ones) on the velocity bridge's bus, the driver paused: the bridge reads every one and
    refuses every one, counted among its decode errors and as ``wrong_profile``, and says
    why in its log."""
    rig.drives_again(0)
    rig.paused.set()
    with rig.ticking:  # the tick being sent is out
        pass
    before = rig.rig.settled_status(1 << 62, timeout_s=60.0)  # every frame so far read
    force = AgvCodec("force")
    junk = []
    for k in range(20):
        junk += [
            force.encode(Odometry(1, k % 16, (0.1, 0.2))),
            force.encode(AppliedForce(1, k % 16, (1.0, 2.0))),
            force.encode(ForceCommand(1, k % 16, (1.0, 2.0))),
        ]
    for message in junk:
        rig.send(message)
    rig.heartbeat()  # valid: it dates the status that counts it
    frames_in = before.frames_in + len(junk) + 1
    after = rig.wait(lambda s: s.frames_in >= frames_in, 60, "the bridge reads the frames")
    rig.paused.clear()
    print(f"\n{len(junk)} force-profile frames: {before} -> {after}")
    assert after.frames_in == frames_in
    assert after.decode_errors - before.decode_errors == len(junk)
    assert after.wrong_profile - before.wrong_profile == len(junk)
    assert after.counter_jumps == before.counter_jumps and after.repeats == before.repeats
    assert "(wrong profile): wrong profile: ForceCommand_1 is not a velocity frame" in (
        rig.bridge_log()
    )
    rig.drives_again(len(rig.frames))


def test_the_base_is_stopped_when_the_agent_is_killed(rig: VelocityRig) -> None:
    """kill -9 the agent: the first MotionCommand in mode STOP follows the last one in mode
    VELOCITY within the watchdog plus or minus one frame period, by the frames' kernel
    timestamps, plus however long the host stalled the machine meanwhile
    (:func:`assert_stopped`), then one a tick; the base drives again once the agent is back. An
    episode in which the host stalled it for more than :data:`~tests.helpers.hil.STALL_MS`, or
    held the rig's driver until the sensor's stop came first, is measured again
    (:meth:`~tests.helpers.hil.DriverRig.stop_when_killed`)."""

    def pushing() -> None:  # the agent pushes: the loop commands a velocity
        rig.drives_again(len(rig.frames))
        deadline = time.monotonic() + 30
        while not any(
            f.velocity != (0.0, 0.0) for _, f in rig.frames if isinstance(f, MotionCommand)
        ):
            assert time.monotonic() < deadline, "every MotionCommand at standstill for 30 s"
            time.sleep(0.05)

    def stopped(frames: list) -> tuple[float | None, list[float]]:
        drives = commands(frames, drive=True)
        return (max(drives), stops_after(frames, max(drives))) if drives else (None, [])

    tripped, frames, last_drive, stops, stalled = rig.stop_when_killed(
        stopped, f"{STOPS_SEEN} STOP frames after the last VELOCITY", ready=pushing
    )
    delay_ms = (stops[0] - last_drive) * 1e3
    print(
        f"\nagent killed: first STOP {delay_ms:.1f} ms after the last VELOCITY command"
        f" (watchdog {WATCHDOG_MS} ms, period {VELOCITY_PERIOD * 1e3:.0f} ms; the host stalled it"
        f" {stalled:.1f} ms meanwhile); {len(stops)} STOP frames in the next"
        f" {(stops[-1] - stops[0]) * 1e3:.0f} ms"
    )
    assert_stopped(frames, stops, delay_ms, stalled)
    # The agent's watchdog stopped it (how many times a slow host's echo agent tripped it
    # before the kill is not this test's: each trip counted once is a unit test's).
    assert tripped.watchdog and not tripped.sensor_stale
    rig.drives_again(len(rig.frames))


@pytest.mark.parametrize("state", ["silent", "fault"])
def test_the_base_is_stopped_when_the_force_torque_sensor_is_stale(
    rig: VelocityRig, state: str
) -> None:
    """The sensor falls silent (no ``ForceTorque``; ``Sync`` and ``MotionFeedback`` go on), or
    reports FAULT: the first MotionCommand in mode STOP follows the last usable sample by the
    watchdog plus or minus one frame period, by kernel timestamps, plus however long the host
    stalled the machine meanwhile (:func:`assert_stopped`); the status says the sensor
    is stale, the bridge's log says why; the base drives again once the sensor is back.

    Without a sample there is no measurement, so the agent stops answering and its watchdog
    would stop the base too, about as soon: here the agent's commands are played for the
    bus's newest tick (:meth:`VelocityRig.agent_heard`) so that the sensor's stop is the one
    measured. Some episodes are not the one to judge, and are measured again:
    - the host stalled the machine for more than :data:`~tests.helpers.hil.STALL_MS` between
      the last sample and the first STOP (:meth:`~tests.helpers.hil.DriverRig.stall_ms`);
    - the rig's driver opened the first tick without a sample more than half the watchdog
      after the last sample: the bridge then gives the sample that long from that tick
      (:meth:`bridge.bridge.Bridge._sensor_deadline`), as it should;
    - the commands played stalled and the agent's watchdog held the base before the sensor's
      stop (:meth:`VelocityRig.agent_stopped_first`). They are played from 0.3 s before the
      episode until the sensor is back, so that the agent, which has no samples to answer
      meanwhile, does not trip the watchdog as the episode starts or ends;
    - the bridge tripped more than :data:`~tests.helpers.hil.LATE_TRIP_MS` after its deadline
      by its own log (:meth:`~tests.helpers.hil.DriverRig.trip_silence_ms`): the machine held
      its loop."""
    for attempt in range(1, ATTEMPTS + 1):
        rig.drives_again(len(rig.frames))
        rig.frames.clear()
        with rig.agent_heard():  # from before the episode until the agent hears samples again
            time.sleep(0.3)
            logged = rig.log_size()
            try:
                rig.set_sensor(state)
                stale = rig.wait(lambda s: s.sensor_stale, 10, "the sensor is stale")
                frames = rig.frames_when(
                    lambda got: len(stops_after(got, last_sample(got))) >= STOPS_SEEN,
                    f"{STOPS_SEEN} STOP frames after the last usable sample",
                )
            finally:  # the next tests need the sensor, whatever this one found
                since = len(rig.frames)
                rig.set_sensor("ok")
                rig.wait(lambda s: not s.sensor_stale, 10, "the sensor is back")
        sampled = last_sample(frames)
        stops = stops_after(frames, sampled)
        owed = min(t for t, f in frames if isinstance(f, Sync) and t > sampled)
        owed_ms = (owed - sampled) * 1e3
        stalled = rig.stall_ms(sampled, stops[0])
        agent_first = rig.agent_stopped_first(logged)
        due_ms = max(WATCHDOG_MS, owed_ms + WATCHDOG_MS / 2)  # Bridge._sensor_deadline
        late_ms = rig.trip_silence_ms(SENSOR_STALE, logged) - due_ms if not agent_first else 0.0
        if (
            stalled <= STALL_MS
            and owed_ms <= WATCHDOG_MS / 2
            and not agent_first
            and late_ms <= LATE_TRIP_MS
        ):
            break
        print(
            f"\nattempt {attempt}: the host stalled the rig for {stalled:.0f} ms; the next tick"
            f" came {owed_ms:.0f} ms after the last sample; the agent's watchdog"
            f" {'held' if agent_first else 'did not hold'} the base first; the bridge tripped"
            f" {late_ms:.0f} ms after its deadline: again"
        )
        rig.drives_again(since)
    else:
        pytest.fail(f"the host disturbed the rig in each of {ATTEMPTS} attempts")
    delay_ms = (stops[0] - sampled) * 1e3
    print(
        f"\nsensor {state}: first STOP {delay_ms:.1f} ms after the last usable sample,"
        f" {(stops[0] - owed) * 1e3:.1f} ms after the first tick without one (watchdog"
        f" {WATCHDOG_MS} ms, period {VELOCITY_PERIOD * 1e3:.0f} ms; the host stalled it"
        f" {stalled:.1f} ms meanwhile); {len(stops)} STOP frames; {stale}"
    )
    assert_stopped(frames, stops, delay_ms, stalled)
    assert stale.sensor_stale and stale.sensor_stale_trips >= 1
    why = "it reports FAULT" if state == "fault" else "no ForceTorque frame"
    assert f"({why})" in rig.bridge_log()
    rig.drives_again(since)
