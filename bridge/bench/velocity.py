"""``heft bench can --profile velocity``: one bridge's admittance loop against a simulated
velocity-commanded base on a real kernel CAN bus: force tracking, round trip, CPU.

What runs (:class:`~bridge.devtools.rig.BridgeRig`): a Zenoh router, robot 1's ``heft bridge``
with ``[can] profile = "velocity"`` on a SocketCAN channel (``vcan8`` by default), and the echo
agent pushing (:func:`~bridge.devtools.echo_agent.push`: cycles of a 0.5 s rest, a 1 s push of
:data:`PUSH_N` newtons and a 1 s push back, along x then y). This process plays the bus master,
the base and its force/torque sensor (:class:`~bridge.bench.contact.ContactModel`, stiffness
``--stiffness``), in lockstep as the plant does over CAN: tick ``k`` is ``Sync(k)``, then
``MotionFeedback`` and ``ForceTorque`` with ``Counter = k mod 16`` (the base's velocity and the
sensor's reading at ``t_k``); it then waits for the bridge's ``MotionCommand`` for tick ``k``
(at most :data:`COMMAND_WAIT_S`) and drives the model over ``[t_k, t_{k+1})`` with it; ticks
go out at the period on an absolute schedule (a late tick goes at once).

What is measured, over ``--seconds`` after a warm-up (until the bridge answers, then one cycle,
which tares the sensor):

1. **Force tracking**: at every tick in a push that has held for :data:`SETTLE_S` (the push's
   transient left out), ``‖f − u‖ / ‖u‖`` with ``f`` the contact force averaged over the tick
   (the model's, without the sensor's bias and noise) and ``u`` the force commanded for it.
   Reported: RMS and p95, and the bridge's own figure (``BridgeStatus.force_error_rms`` and
   ``_p95``, N, from the measured force over its last 100 steps). Goal (:data:`GOALS`): p95
   at most :data:`GOAL_TRACKING_P95` of the commanded force.
2. **Round trip**: ``ForceTorque`` on CAN → bridge → Zenoh → agent → Zenoh → bridge →
   ``MotionCommand`` on CAN, by kernel timestamps (as for the force profile); p50, p99, max,
   and the ticks whose command did not come back in time. Goal: p99 below 5 ms.
3. **CPU share** of the bridge, router, agent and this process over the phase.
"""

from __future__ import annotations

import math
import statistics
import tempfile
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import can

from agent.platform.goals import Goal, Sense
from agent.platform.statistics import percentile
from bridge.admittance import AdmittanceSettings
from bridge.bench.can import (
    DEFAULT_CHANNEL,
    DRIVER_MODE_ACTIVE,
    GOAL_P99_MS,
    GUEST_NOTE,
    HEARTBEAT_S,
    NODE,
    BenchError,
    Say,
    cpu_now,
    cpu_percent,
    say_on_stderr,
    where_measured,
)
from bridge.bench.contact import ContactModel, ContactSettings
from bridge.codec import (
    COUNTER_MODULO,
    AgvCodec,
    ForceTorque,
    FrameError,
    Heartbeat,
    MotionCommand,
    MotionFeedback,
    Sync,
    Vec2,
)
from bridge.config import CanSettings
from bridge.dbc import FORCE_TORQUE_BASE, MOTION_COMMAND_BASE
from bridge.devtools.echo_agent import CYCLE_S, push
from bridge.devtools.rig import BridgeRig, RigError
from bridge.node import open_bus

PUSH_N = 5.0
"""N: the pushes' force."""
SETTLE_S = 0.25
"""A push's first this-long is its transient, left out of the tracking figures."""
COMMAND_WAIT_S = 0.25
"""How long a tick waits for its command before the next goes out (it is then lost)."""
GOAL_TRACKING_P95 = 0.05
GOALS = (
    Goal("tracking_p95", "force tracking p95", 100 * GOAL_TRACKING_P95, Sense.AT_MOST, "%"),
    Goal("p99_ms", "round trip p99", GOAL_P99_MS, Sense.BELOW, "ms"),
)
"""What the velocity profile's benchmark checks, on the figures of :func:`figures`."""


@dataclass(frozen=True)
class VelocityBenchSettings:
    """What :func:`run_velocity_benchmark` measures (the ``heft bench can --profile velocity``
    options)."""

    channel: str = DEFAULT_CHANNEL
    seconds: float = 20.0
    period_s: float = 0.01
    stiffness: float = 3000.0
    """N/m, the contact's."""
    admittance: AdmittanceSettings = AdmittanceSettings()
    """The bridge's loop."""
    startup_timeout_s: float = 120.0


@dataclass
class VelocityBenchReport:
    """What :func:`run_velocity_benchmark` measured."""

    settings: VelocityBenchSettings
    where: str
    errors: list[float]
    """``‖f − u‖ / ‖u‖`` at each tick of the pushes' steady parts."""
    latencies_ms: list[float]
    sent: int
    lost: int
    seconds: float
    cpu_percent: dict[str, float | None] = field(default_factory=dict)
    bridge_rms_n: float | None = None
    bridge_p95_n: float | None = None
    sensor: ContactSettings = ContactSettings()

    def tracking(self, q: float) -> float | None:
        """The ``q``-th percentile of the tracking errors (a fraction); None without any."""
        return percentile(self.errors, q) if self.errors else None

    @property
    def tracking_rms(self) -> float | None:
        if not self.errors:
            return None
        return math.sqrt(statistics.fmean(e * e for e in self.errors))

    def p(self, q: float) -> float | None:
        return percentile(self.latencies_ms, q) if self.latencies_ms else None


def steady_push(time_s: float) -> Vec2 | None:
    """The force commanded at ``time_s`` if it is a push that has held for
    :data:`SETTLE_S`, else None."""
    u = push(time_s, PUSH_N)
    if u == (0.0, 0.0) or push(time_s - SETTLE_S, PUSH_N) != u:
        return None
    return u


def tracking_error(force: Vec2, commanded: Vec2) -> float:
    """``‖force − commanded‖ / ‖commanded‖``."""
    return math.hypot(force[0] - commanded[0], force[1] - commanded[1]) / math.hypot(*commanded)


# ------------------------------------------------------------------------------ the bus side
class Base:
    """This process as the bus master, AGV node :data:`NODE`'s base and its sensor, and the
    reader of the bridge's ``MotionCommand`` frames (and of its own ``ForceTorque``, for their
    kernel timestamps) on a second socket."""

    def __init__(self, channel: str, model: ContactModel) -> None:
        self.codec = AgvCodec("velocity")
        self.model = model
        self.bus = open_bus(CanSettings(channel=channel))
        self.bus.set_filters([{"can_id": 0x7FF, "can_mask": 0x7FF, "extended": False}])
        self.reader = open_bus(CanSettings(channel=channel))
        ids = (FORCE_TORQUE_BASE + NODE, MOTION_COMMAND_BASE + NODE)
        self.reader.set_filters([{"can_id": i, "can_mask": 0x7FF, "extended": False} for i in ids])
        self.tick = 0
        self.velocity: Vec2 = (0.0, 0.0)
        """The velocity the base was last told to drive at."""
        self.beats = 0
        self._next_beat = 0.0
        self._read: deque[can.Message] = deque()
        self._arrived = threading.Event()
        self._stop = threading.Event()
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._listen, name="can-listen", daemon=True)
        self.thread.start()

    def _listen(self) -> None:
        try:
            while not self._stop.is_set():
                message = self.reader.recv(0.1)
                if message is not None:
                    self._read.append(message)
                    self._arrived.set()
        except (can.CanError, OSError, ValueError) as err:
            self.error = err
            self._arrived.set()

    def send_tick(self) -> None:
        """Tick :attr:`tick`: ``Sync``, the base's velocity and the sensor's reading (and a
        heartbeat every :data:`HEARTBEAT_S`)."""
        k, counter = self.tick, self.tick % COUNTER_MODULO
        frames = [
            Sync(k),
            MotionFeedback(NODE, counter, self.model.v),
            ForceTorque(NODE, counter, self.model.sensed()),
        ]
        now = time.monotonic()
        if now >= self._next_beat:
            frames.append(Heartbeat(NODE, self.beats % COUNTER_MODULO, DRIVER_MODE_ACTIVE))
            self.beats += 1
            self._next_beat = now + HEARTBEAT_S
        for frame in frames:
            self.bus.send(self.codec.encode(frame), timeout=1.0)

    def answer(self, timeout_s: float) -> tuple[MotionCommand, float | None] | None:
        """The bridge's ``MotionCommand`` for :attr:`tick` and its round trip (ms, from the
        tick's ``ForceTorque``), or None after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        counter = self.tick % COUNTER_MODULO
        sensed_at = None
        while True:
            while self._read:
                message = self._read.popleft()
                try:
                    frame = self.codec.decode(message)
                except FrameError:
                    continue
                if isinstance(frame, ForceTorque) and frame.counter == counter:
                    sensed_at = message.timestamp
                elif isinstance(frame, MotionCommand) and frame.counter == counter:
                    trip = None if sensed_at is None else (message.timestamp - sensed_at) * 1e3
                    return frame, trip
            if self.error is not None:
                raise BenchError(f"reading {self.reader.channel_info} failed: {self.error}")
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            self._arrived.clear()
            if not self._read:
                self._arrived.wait(min(left, 0.05))

    def step(self, timeout_s: float) -> tuple[bool, float | None]:
        """One tick: send it, wait for its command, drive the model with it over the period
        (standstill with STOP; the last command kept if none came); whether one came, and
        its round trip (ms)."""
        self.send_tick()
        answered = self.answer(timeout_s)
        trip = None
        if answered is not None:
            command, trip = answered
            self.velocity = command.velocity if command.drive else (0.0, 0.0)
        self.model.advance(self.velocity)
        self.tick += 1
        return answered is not None, trip

    def close(self) -> None:
        self._stop.set()
        self.thread.join(2.0)
        self.reader.shutdown()
        self.bus.shutdown()


# ------------------------------------------------------------------------------ the run
def _play(
    base: Base, period_s: float, count: int, errors: list[float] | None = None
) -> tuple[list[float], int]:
    """``count`` ticks at ``period_s`` on an absolute schedule; the round trips (ms) and the
    ticks unanswered. With ``errors``, the tracking error of every steady push is added."""
    start = time.monotonic()
    trips, lost = [], 0
    for i in range(count):
        delay = start + i * period_s - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        commanded = steady_push(base.tick * period_s)
        answered, trip = base.step(max(COMMAND_WAIT_S, 5 * period_s))
        if not answered:
            lost += 1
        elif trip is not None:
            trips.append(trip)
        if errors is not None and commanded is not None:
            errors.append(tracking_error(base.model.force, commanded))
    return trips, lost


def run_velocity_benchmark(
    settings: VelocityBenchSettings, say: Say = say_on_stderr
) -> VelocityBenchReport:
    """Bring up the rig with a velocity-profile bridge on ``settings.channel``, measure (see the
    module docstring), stop it. :class:`BenchError` if it cannot measure."""
    where = where_measured()
    sensor = ContactSettings(stiffness=settings.stiffness)
    with tempfile.TemporaryDirectory(prefix="heft-bench-can-") as folder:
        rig = BridgeRig(
            settings.channel,
            Path(folder),
            settings.period_s,
            profile="velocity",
            admittance=settings.admittance,
            push_n=PUSH_N,
        )
        base = None
        try:
            say(
                f"starting a router, a velocity-profile bridge on {settings.channel} and a pushing"
                f" agent ({where})"
            )
            started = time.monotonic()
            rig.start(settings.startup_timeout_s)
            base = Base(settings.channel, ContactModel(sensor, settings.period_s))
            deadline = time.monotonic() + settings.startup_timeout_s
            while not base.step(settings.period_s)[0]:
                rig.check()
                if time.monotonic() > deadline:
                    raise BenchError(
                        f"no MotionCommand came back within {settings.startup_timeout_s:.0f} s;"
                        f" the bridge's log ends:\n{rig.children['bridge'].tail()}"
                    )
            _play(base, settings.period_s, round(CYCLE_S / settings.period_s))
            say(f"up, answering and tared after {time.monotonic() - started:.1f} s")
            count = max(1, round(settings.seconds / settings.period_s))
            say(
                f"{settings.seconds:g} s of pushes at {settings.period_s * 1e3:g} ms, contact"
                f" stiffness {settings.stiffness:g} N/m"
            )
            errors: list[float] = []
            before, begun = cpu_now(rig), time.monotonic()
            trips, lost = _play(base, settings.period_s, count, errors)
            seconds = time.monotonic() - begun
            shares = cpu_percent(before, cpu_now(rig), seconds)
            status = rig.wait_status(lambda s: s.tick >= base.tick - 1, 5.0, "the last status")
        except RigError as err:
            raise BenchError(str(err)) from None
        finally:
            if base is not None:
                base.close()
            rig.close()
    return VelocityBenchReport(
        settings,
        where,
        errors,
        trips,
        count,
        lost,
        seconds,
        shares,
        status.force_error_rms,
        status.force_error_p95,
        sensor,
    )


# ------------------------------------------------------------------------------ the report
def figures(report: VelocityBenchReport) -> dict[str, float | None]:
    """The figures :data:`GOALS` bound: the tracking p95 (% of the commanded force) and the
    round trip's p99 (ms); None where nothing was measured."""
    p95 = report.tracking(95)
    return {"tracking_p95": None if p95 is None else 100 * p95, "p99_ms": report.p(99)}


def _fraction(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.2f} %"


def _value(value: float | None, unit: str, digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f} {unit}"


def format_velocity_report(report: VelocityBenchReport) -> str:
    """The plain-text report of ``heft bench can --profile velocity`` (the goals' verdicts
    follow it: :data:`GOALS`)."""
    s, c, a = report.settings, report.sensor, report.settings.admittance
    cpu = report.cpu_percent
    lines = [
        f"heft bench can --profile velocity: one AGV bridge on {s.channel} (SocketCAN),"
        f" measured {report.where}",
        "",
        f"the base: speed loop {c.time_constant_s:g} s, contact {s.stiffness:g} N/m and"
        f" {c.damping:g} N s/m, load share {c.load_mass:g} kg (drag {c.drag:g} N s/m),"
        f" sensor noise {c.noise_std:g} N",
        f"the bridge's loop: M {a.mass:g} kg, D {a.damping:g} N s/m, integral"
        f" {a.integral_time_s:g} s, deadzone {a.deadzone_n:g} N, max {a.max_speed:g} m/s and"
        f" {a.max_accel:g} m/s²",
        f"pushes of {PUSH_N:g} N for 1 s each way, a tick every {s.period_s * 1e3:g} ms for"
        f" {report.seconds:.1f} s in lockstep",
        "",
        f"force tracking: |f - u| / |u| from {SETTLE_S:g} s after each change of the command",
        f"  {'samples':<18} {len(report.errors)}",
        f"  {'rms':<18} {_fraction(report.tracking_rms)}",
        f"  {'p95':<18} {_fraction(report.tracking(95))}",
        f"  {'max':<18} {_fraction(report.tracking(100))}",
        f"  {'bridge status':<18} rms {_value(report.bridge_rms_n, 'N')},"
        f" p95 {_value(report.bridge_p95_n, 'N')} (measured force, last 100 steps)",
        "",
        "round trip: ForceTorque frame on CAN -> bridge -> Zenoh -> agent -> Zenoh -> bridge ->",
        "MotionCommand frame on CAN, by kernel timestamps",
        f"  {'round trips':<18} {len(report.latencies_ms)} measured, {report.lost} lost",
        f"  {'p50':<18} {_value(report.p(50), 'ms')}",
        f"  {'p99':<18} {_value(report.p(99), 'ms')}",
        f"  {'max':<18} {_value(report.p(100), 'ms')}",
        f"  {'bridge CPU':<18} {_value(cpu.get('bridge'), '%', 1)} of one CPU"
        f" (router {_value(cpu.get('router'), '%', 1)}, agent"
        f" {_value(cpu.get('echo agent'), '%', 1)}, base {_value(cpu.get('driver'), '%', 1)})",
    ]
    if report.where != "natively":
        lines += GUEST_NOTE
    return "\n".join(lines)
