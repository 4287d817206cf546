"""``heft bench can``: one AGV bridge's latency, throughput and CPU on a real kernel CAN bus.

What runs (:class:`~bridge.devtools.rig.BridgeRig`): a Zenoh router, robot 1's ``heft bridge`` on a
SocketCAN channel (``vcan8`` by default) and a stand-in agent (:mod:`bridge.devtools.echo_agent`)
that answers every measurement at once with a command echoing the force it reports. This
process plays AGV node 1's driver and the bus's sync master: a tick is ``Sync(k)``, then
``Odometry`` and ``AppliedForce`` with ``Counter = k mod 16``, plus a ``Heartbeat`` every
100 ms, all encoded by :class:`~bridge.codec.AgvCodec` before a phase starts. Each tick's
velocity and applied force encode ``k`` (:func:`tick_values`), so the ``ForceCommand`` that
comes back names the tick it answers, whatever its 4-bit counter says.

What is measured:

1. **Round trip** at the sensor period (``--period-ms``, 10 ms) for ``--seconds``: odometry
   frame on CAN → bridge → Zenoh → agent → Zenoh → bridge → force frame on CAN. A second
   socket of this process reads the driver's own frames and the bridge's ``ForceCommand``
   with their kernel receive timestamps (``SO_TIMESTAMPNS``, python-can's
   ``Message.timestamp``); a tick's latency is the ``ForceCommand``'s timestamp minus the
   later of its ``Odometry`` and ``AppliedForce`` (the frame that completed the measurement).
   Reported: p50, p99 (linear interpolation,
   :func:`~agent.platform.statistics.percentile`), max, count, and the round trips lost (no
   command back within a drain time after the last tick). Its goal (:data:`GOALS`): p99
   below :data:`GOAL_P99_MS`.
2. **Forwarding rate**: steps of ticks sent as fast as a rate asks (:class:`RateSearch`:
   doubling from 50 ticks/s, then two bisections between the fastest clean rate and the
   slowest lossy one), each ``step_seconds`` long. A step is clean when the bridge read every
   frame sent (its ``BridgeStatus.frames_in`` grew by exactly what was sent: none dropped by
   its socket), counted no missed tick, and every tick's command came back on the bus (a
   bridge that falls more than 15 ticks behind has its commands refused as too old, so a
   growing backlog shows as loss). The figure is the fastest clean step's achieved rate,
   in ticks/s and frames/s read (3 per tick + heartbeats) and written (1 per tick). If this
   process cannot send faster while the bridge still keeps up, the figure is a lower bound
   and the report says so.
3. **CPU share**: the bridge process's user + system time (``/proc/<pid>/stat``) over the
   round-trip phase, as a percentage of one CPU; the router's, the agent's and this
   process's beside it, and the bridge's for each rate step.
4. **Where**: natively, or in User-Mode Linux (``/proc/cpuinfo`` names it), where every
   process shares the guest's one CPU and each system call costs about 100 µs, so the
   figures there are far below a robot computer's.
"""

from __future__ import annotations

import math
import os
import statistics
import sys
import tempfile
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import can

from agent.platform.goals import Goal, Sense
from agent.platform.process import in_user_mode_linux
from agent.platform.statistics import percentile
from bridge.codec import (
    AgvCodec,
    AppliedForce,
    ForceCommand,
    FrameError,
    Heartbeat,
    Odometry,
    Sync,
    Vec2,
)
from bridge.config import CanSettings
from bridge.dbc import APPLIED_FORCE_BASE, FORCE_COMMAND_BASE
from bridge.devtools.rig import BridgeRig, RigError, cpu_seconds
from bridge.node import open_bus

DEFAULT_CHANNEL = "vcan8"
"""The hardware-in-the-loop tests' one-bridge channel (robots 1..7 of a run use vcan1..)."""
NODE = 1
TICK_BASE = 10_000
"""A tick is written into a pair of signal values as ``(k mod B, (k div B) mod B)``."""
VELOCITY_STEP = 1e-3
"""m/s per unit of an ``Odometry`` value carrying a tick (at most 9.999 m/s)."""
FORCE_STEP = 1e-2
"""N per unit of an ``AppliedForce`` value carrying a tick (at most 99.99 N)."""
HEARTBEAT_S = 0.1
DRIVER_MODE_ACTIVE = 2
GOAL_P99_MS = 5.0
"""ms: the round trip's p99 is below this on a robot computer."""
GOALS = (Goal("p99_ms", "round trip p99", GOAL_P99_MS, Sense.BELOW, "ms"),)
"""What the benchmark checks, on the figures of :func:`figures`."""
SENDER_SLACK = 0.9
"""A step whose achieved rate is below this fraction of the asked one was limited by this
process, not by the bridge."""
MIN_STEP_TICKS = 100
COMMAND_QUIET_S = 0.5
"""After a step's last tick: how long without a new command ends the wait for the rest."""
COMMAND_WAIT_S = 5.0
"""After a step's last tick: the longest wait for its commands."""
STDERR_PREFIX = "heft bench can"


class BenchError(Exception):
    """The benchmark could not measure; ``str()`` says why (with the end of a log)."""


# ------------------------------------------------------------------------------ pure helpers
def tick_values(tick: int, step: float) -> Vec2:
    """Tick ``tick`` (0 ≤ tick < B²) as a pair of signal values, ``step`` per unit."""
    if not 0 <= tick < TICK_BASE**2:
        raise ValueError(f"tick {tick} outside 0..{TICK_BASE**2 - 1}")
    return ((tick % TICK_BASE) * step, (tick // TICK_BASE) * step)


def tick_of(values: Vec2, step: float) -> int:
    """The tick :func:`tick_values` wrote into ``values`` (as a receiver decodes them)."""
    return round(values[0] / step) + TICK_BASE * round(values[1] / step)


def where_measured(cpuinfo: str | None = None) -> str:
    """``"in User-Mode Linux"`` if this kernel is one (its ``/proc/cpuinfo`` says so), else
    ``"natively"``."""
    return "in User-Mode Linux" if in_user_mode_linux(cpuinfo) else "natively"


def vcan_problem(channel: str, sys_class_net: Path = Path("/sys/class/net")) -> str | None:
    """Why ``channel`` cannot be benchmarked here, or None if it can."""
    from bridge.devtools.vcan import socketcan_available

    if not socketcan_available():
        return "this kernel has no SocketCAN"
    if not (sys_class_net / channel).exists():
        return f"there is no interface {channel}"
    return None


class RateSearch:
    """The rates (ticks/s) to try: ``start``, doubling while every step is clean (up to
    ``limit``); after the first lossy one, ``refine`` bisections between the fastest clean
    rate and the slowest lossy one (or halvings, if even ``start`` was lossy). Give each
    outcome to :meth:`record`; :meth:`next` is None when done."""

    def __init__(self, start: float = 50.0, limit: float = 12_800.0, refine: int = 2) -> None:
        if not 0 < start <= limit:
            raise ValueError(f"rates: need 0 < start <= limit, got {start}, {limit}")
        self.start = start
        self.limit = limit
        self.refine = refine
        self.best: float | None = None
        """The fastest clean rate so far."""
        self.worst: float | None = None
        """The slowest lossy rate so far."""
        self._next: float | None = start
        self._bisections = 0

    def next(self) -> float | None:
        return self._next

    def stop(self) -> None:
        """No more rates (e.g. the sender could not go faster)."""
        self._next = None

    def record(self, rate: float, clean: bool) -> None:
        if clean:
            self.best = rate if self.best is None else max(self.best, rate)
        else:
            self.worst = rate if self.worst is None else min(self.worst, rate)
        if self.worst is None:
            doubled = rate * 2
            self._next = doubled if doubled <= self.limit else None
            return
        if self._bisections >= self.refine:
            self._next = None
            return
        self._bisections += 1
        low = self.best if self.best is not None else 0.0
        self._next = (low + self.worst) / 2


# ------------------------------------------------------------------------------ results
@dataclass(frozen=True)
class CanBenchSettings:
    """What :func:`run_can_benchmark` measures (the ``heft bench can`` options)."""

    channel: str = DEFAULT_CHANNEL
    seconds: float = 20.0
    """Length of the round-trip phase."""
    period_s: float = 0.01
    """Sensor period of the round-trip phase (and of the bridge's config)."""
    step_seconds: float = 2.0
    """Length of each step of the rate search (at least ``min_step_ticks`` ticks)."""
    min_step_ticks: int = MIN_STEP_TICKS
    start_rate: float = 50.0
    max_rate: float = 12_800.0
    refine: int = 2
    startup_timeout_s: float = 120.0
    """How long the processes may take to come up and answer a first tick."""


@dataclass
class RoundTrips:
    """The round-trip phase: latencies (ms) of the ticks answered, ticks sent, CPU shares."""

    latencies_ms: list[float]
    sent: int
    lost: int
    unmatched: int
    """Ticks answered whose own frames this process did not read (no latency for them)."""
    seconds: float
    cpu_percent: dict[str, float | None] = field(default_factory=dict)
    """Percent of one CPU over the phase: ``bridge``, ``router``, ``echo agent``, ``driver``."""

    @property
    def count(self) -> int:
        return len(self.latencies_ms)

    def p(self, q: float) -> float | None:
        """The ``q``-th percentile of the latencies (ms); None without any."""
        return percentile(self.latencies_ms, q) if self.latencies_ms else None

    @property
    def mean(self) -> float | None:
        return statistics.fmean(self.latencies_ms) if self.latencies_ms else None

    @property
    def bridge_cpu_percent(self) -> float | None:
        return self.cpu_percent.get("bridge")


@dataclass
class RateStep:
    """One step of the rate search."""

    asked: float
    """Ticks per second asked for."""
    ticks: int
    frames_sent: int
    send_failures: int
    seconds: float
    """From the first tick sent to the last."""
    frames_read: int
    """The bridge's ``frames_in`` over the step."""
    missed_ticks: int
    answered: int
    """Ticks of the step whose command came back on the bus."""
    bridge_cpu_percent: float | None
    latencies_ms: list[float] = field(default_factory=list)
    """Round trips (ms) of the ticks answered."""

    @property
    def achieved(self) -> float:
        """Ticks per second sent."""
        return self.ticks / self.seconds if self.seconds > 0 else math.inf

    @property
    def frames_in_per_s(self) -> float:
        return self.frames_sent / self.seconds if self.seconds > 0 else math.inf

    @property
    def frames_out_per_s(self) -> float:
        return self.answered / self.seconds if self.seconds > 0 else math.inf

    @property
    def dropped(self) -> int:
        """Frames sent that the bridge never read."""
        return max(0, self.frames_sent - self.send_failures - self.frames_read)

    def p(self, q: float) -> float | None:
        """The ``q``-th percentile of the step's round trips (ms); None without any."""
        return percentile(self.latencies_ms, q) if self.latencies_ms else None

    @property
    def unanswered(self) -> int:
        return self.ticks - self.answered

    @property
    def clean(self) -> bool:
        return (
            self.send_failures == 0
            and self.dropped == 0
            and self.missed_ticks == 0
            and self.unanswered == 0
        )

    @property
    def sender_limited(self) -> bool:
        return self.achieved < SENDER_SLACK * self.asked


@dataclass
class CanBenchReport:
    """What :func:`run_can_benchmark` measured."""

    settings: CanBenchSettings
    where: str
    round_trips: RoundTrips
    steps: list[RateStep]
    sender_limited: bool
    """The search stopped because this process could not send faster (the bridge kept up)."""

    @property
    def fastest_clean(self) -> RateStep | None:
        clean = [s for s in self.steps if s.clean]
        return max(clean, key=lambda s: s.achieved) if clean else None


# ------------------------------------------------------------------------------ the bus side
class Driver:
    """This process as AGV node :data:`NODE`'s driver and the bus's sync master."""

    def __init__(self, channel: str, codec: AgvCodec) -> None:
        self.codec = codec
        self.bus = open_bus(CanSettings(channel=channel))
        # It reads nothing: an id no frame has keeps its socket's queue empty.
        self.bus.set_filters([{"can_id": 0x7FF, "can_mask": 0x7FF, "extended": False}])
        self.tick = 0
        self.beats = 0
        self.sent = 0
        self.failures = 0
        self._next_beat = 0.0

    def encode(self, count: int) -> list[list[can.Message]]:
        """The frames of the next ``count`` ticks (``Sync``, ``Odometry``, ``AppliedForce``)."""
        ticks = []
        for k in range(self.tick, self.tick + count):
            counter = k % 16
            ticks.append(
                [
                    self.codec.encode(Sync(k)),
                    self.codec.encode(Odometry(NODE, counter, tick_values(k, VELOCITY_STEP))),
                    self.codec.encode(AppliedForce(NODE, counter, tick_values(k, FORCE_STEP))),
                ]
            )
        self.tick += count
        return ticks

    def _send(self, message: can.Message) -> None:
        try:
            self.bus.send(message, timeout=1.0)
            self.sent += 1
        except (can.CanError, OSError):
            self.failures += 1

    def play(self, ticks: list[list[can.Message]], rate: float) -> tuple[float, float]:
        """Send ``ticks`` at ``rate`` ticks/s on an absolute schedule (late ticks go at
        once), a heartbeat every :data:`HEARTBEAT_S`; the monotonic times of the first and
        the last tick sent."""
        start = time.monotonic()
        last = start
        for i, frames in enumerate(ticks):
            delay = start + i / rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            last = time.monotonic()
            for message in frames:
                self._send(message)
            if last >= self._next_beat:
                beat = Heartbeat(NODE, self.beats % 16, DRIVER_MODE_ACTIVE)
                self._send(self.codec.encode(beat))
                self.beats += 1
                self._next_beat = last + HEARTBEAT_S
        return start, last

    def close(self) -> None:
        self.bus.shutdown()


class Listener:
    """Reads, on a socket of its own, the driver's ``AppliedForce`` and the bridge's
    ``ForceCommand`` frames with their kernel timestamps. Its thread only queues what it
    reads (this process shares the CPU with the bridge); :meth:`absorb`, in the caller's
    thread, decodes them into :attr:`completed` and :attr:`answered`, by tick."""

    IDS = (APPLIED_FORCE_BASE + NODE, FORCE_COMMAND_BASE + NODE)
    """The driver sends a tick's ``AppliedForce`` after its ``Odometry``, on one socket: it is
    the frame that completes the bridge's measurement, so ``Odometry`` is not read here."""

    def __init__(self, channel: str) -> None:
        self.codec = AgvCodec()
        self.bus = open_bus(CanSettings(channel=channel))
        self.bus.set_filters(
            [{"can_id": i, "can_mask": 0x7FF, "extended": False} for i in self.IDS]
        )
        self.completed: dict[int, float] = {}
        """Tick → the kernel timestamp of its AppliedForce (the frame that completed it)."""
        self.answered: dict[int, float] = {}
        """Tick → the kernel timestamp of the first ForceCommand answering it."""
        self.last_answer = 0.0
        """The kernel timestamp (Unix time) of the newest answer."""
        self._read: deque[can.Message] = deque()
        self._stop = threading.Event()
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="can-listen", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        read = self._read.append
        try:
            while not self._stop.is_set():
                message = self.bus.recv(0.1)
                if message is not None:
                    read(message)
        except (can.CanError, OSError, ValueError) as err:
            self.error = err

    def absorb(self) -> None:
        """Decode what was read so far; :class:`BenchError` if reading failed."""
        if self.error is not None:
            raise BenchError(f"reading {self.bus.channel_info} failed: {self.error}")
        while self._read:
            message = self._read.popleft()
            try:
                frame = self.codec.decode(message)
            except FrameError:
                continue
            if isinstance(frame, ForceCommand):
                if frame.apply:  # not the watchdog's zero force
                    self.answered.setdefault(tick_of(frame.force, FORCE_STEP), message.timestamp)
                    self.last_answer = max(self.last_answer, message.timestamp)
            elif isinstance(frame, AppliedForce):
                self.completed.setdefault(tick_of(frame.force, FORCE_STEP), message.timestamp)

    def wait_answers(self, ticks: range, quiet_s: float, timeout_s: float) -> None:
        """Until every tick of ``ticks`` is answered, or none was for ``quiet_s`` (by the
        frames' timestamps), or ``timeout_s`` passed."""
        deadline = time.monotonic() + timeout_s
        while True:
            self.absorb()
            if all(k in self.answered for k in ticks):
                return
            if time.time() - self.last_answer > quiet_s or time.monotonic() > deadline:
                return
            time.sleep(0.02)

    def latencies_ms(self, ticks: range) -> tuple[list[float], int, int]:
        """For ``ticks``: the round trips (ms) of those answered, how many were not, and how
        many were answered but their own frame was not read."""
        self.absorb()
        latencies, lost, unmatched = [], 0, 0
        for k in ticks:
            answered, completed = self.answered.get(k), self.completed.get(k)
            if answered is None:
                lost += 1
            elif completed is None:
                unmatched += 1
            else:
                latencies.append((answered - completed) * 1e3)
        return latencies, lost, unmatched

    def forget(self) -> None:
        """Drop what was read so far."""
        self.absorb()
        self.completed.clear()
        self.answered.clear()

    def close(self) -> None:
        self._stop.set()
        self.thread.join(2.0)
        self.bus.shutdown()


# ------------------------------------------------------------------------------ the phases
Say = Callable[[str], None]


def say_on_stderr(message: str) -> None:
    print(f"{STDERR_PREFIX}: {message}", file=sys.stderr, flush=True)


def _warm_up(driver: Driver, listener: Listener, rig: BridgeRig, settings: CanBenchSettings):
    """Ticks at the period until a first command comes back, then half a second more."""
    deadline = time.monotonic() + settings.startup_timeout_s
    rate = 1.0 / settings.period_s
    while True:
        listener.absorb()
        if listener.answered:
            break
        rig.check()
        if time.monotonic() > deadline:
            raise BenchError(
                f"no ForceCommand came back within {settings.startup_timeout_s:.0f} s;"
                f" the bridge's log ends:\n{rig.children['bridge'].tail()}"
            )
        driver.play(driver.encode(10), rate)
    driver.play(driver.encode(max(10, round(0.5 * rate))), rate)


def cpu_now(rig: BridgeRig) -> dict[str, float | None]:
    """CPU seconds used so far by each process of the rig, and by this one (``driver``)."""
    return {**rig.cpu_seconds(), "driver": cpu_seconds(os.getpid())}


def cpu_percent(before: dict, after: dict, seconds: float) -> dict[str, float | None]:
    """Each process's CPU time between ``before`` and ``after`` as % of ``seconds``."""
    shares: dict[str, float | None] = {}
    for name, start in before.items():
        end = after.get(name)
        usable = start is not None and end is not None and seconds > 0
        shares[name] = 100 * (end - start) / seconds if usable else None
    return shares


def measure_round_trips(
    driver: Driver, listener: Listener, rig: BridgeRig, settings: CanBenchSettings
) -> RoundTrips:
    """The round-trip phase (see the module docstring)."""
    count = max(1, round(settings.seconds / settings.period_s))
    ticks = driver.encode(count)
    window = range(driver.tick - count, driver.tick)
    listener.forget()
    cpu_before = cpu_now(rig)
    start, _ = driver.play(ticks, 1.0 / settings.period_s)
    seconds = time.monotonic() - start
    cpu_after = cpu_now(rig)
    listener.wait_answers(window, max(1.0, 50 * settings.period_s), COMMAND_WAIT_S)
    latencies, lost, unmatched = listener.latencies_ms(window)
    return RoundTrips(
        latencies_ms=latencies,
        sent=count,
        lost=lost,
        unmatched=unmatched,
        seconds=seconds,
        cpu_percent=cpu_percent(cpu_before, cpu_after, seconds),
    )


def measure_rate(
    driver: Driver,
    listener: Listener,
    rig: BridgeRig,
    rate: float,
    step_seconds: float,
    min_ticks: int = MIN_STEP_TICKS,
) -> RateStep:
    """One step of the rate search at ``rate`` ticks/s."""
    count = max(min_ticks, round(rate * step_seconds))
    ticks = driver.encode(count)
    window = range(driver.tick - count, driver.tick)
    listener.forget()
    before = rig.settled_status(frames_in=1 << 62)
    sent, failures = driver.sent, driver.failures
    cpu_before = cpu_now(rig)
    start, last = driver.play(ticks, rate)
    frames, failed = driver.sent - sent, driver.failures - failures
    listener.wait_answers(window, COMMAND_QUIET_S, COMMAND_WAIT_S)
    busy = time.monotonic() - start
    cpu = cpu_percent(cpu_before, cpu_now(rig), busy)["bridge"]
    after = rig.settled_status(frames_in=before.frames_in + frames)
    latencies, lost, _ = listener.latencies_ms(window)
    return RateStep(
        asked=rate,
        ticks=count,
        frames_sent=frames + failed,
        send_failures=failed,
        seconds=max(last - start, 1e-9) * count / max(count - 1, 1),
        frames_read=after.frames_in - before.frames_in,
        missed_ticks=after.missed_ticks - before.missed_ticks,
        answered=count - lost,
        bridge_cpu_percent=cpu,
        latencies_ms=latencies,
    )


def search_rate(
    driver: Driver,
    listener: Listener,
    rig: BridgeRig,
    settings: CanBenchSettings,
    say: Say = say_on_stderr,
) -> tuple[list[RateStep], bool]:
    """The rate search's steps, and whether it stopped because this process could not send
    faster while the bridge kept up."""
    search = RateSearch(settings.start_rate, settings.max_rate, settings.refine)
    steps: list[RateStep] = []
    limited = False
    while (rate := search.next()) is not None:
        step = measure_rate(
            driver, listener, rig, rate, settings.step_seconds, settings.min_step_ticks
        )
        steps.append(step)
        say(
            f"rate {rate:.0f} ticks/s asked, {step.achieved:.0f} sent:"
            f" {'clean' if step.clean else 'LOSS'} (dropped {step.dropped}, missed"
            f" {step.missed_ticks}, no command {step.unanswered})"
        )
        search.record(rate, step.clean)
        if step.clean and step.sender_limited:
            limited = True
            search.stop()
    return steps, limited


def run_can_benchmark(settings: CanBenchSettings, say: Say = say_on_stderr) -> CanBenchReport:
    """Bring up the rig on ``settings.channel``, measure (see the module docstring), stop
    it. :class:`BenchError` if it cannot measure."""
    where = where_measured()
    with tempfile.TemporaryDirectory(prefix="heft-bench-can-") as folder:
        rig = BridgeRig(settings.channel, Path(folder), settings.period_s)
        driver = listener = None
        try:
            say(f"starting a router, a bridge on {settings.channel} and an echo agent ({where})")
            started = time.monotonic()
            rig.start(settings.startup_timeout_s)
            driver = Driver(settings.channel, AgvCodec())
            listener = Listener(settings.channel)
            _warm_up(driver, listener, rig, settings)
            say(f"up and answering after {time.monotonic() - started:.1f} s")
            say(
                f"round trips: {settings.seconds:g} s at {settings.period_s * 1e3:g} ms"
                f" ({round(settings.seconds / settings.period_s)} ticks)"
            )
            trips = measure_round_trips(driver, listener, rig, settings)
            say(f"round trips: {trips.count} measured, {trips.lost} lost")
            steps, limited = search_rate(driver, listener, rig, settings, say)
        except RigError as err:
            raise BenchError(str(err)) from None
        finally:
            if listener is not None:
                listener.close()
            if driver is not None:
                driver.close()
            rig.close()
    return CanBenchReport(settings, where, trips, steps, limited)


# ------------------------------------------------------------------------------ the report
GUEST_NOTE = [
    "",
    "(in User-Mode Linux the guest's one CPU runs the bridge, the router, the agent and",
    " this process, and every system call costs about 100 us)",
]
"""The lines a report ends with when it was measured in User-Mode Linux."""


def _ms(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f} ms"


def _number(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def _percent(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f} %"


def figures(report: CanBenchReport) -> dict[str, float | None]:
    """The figures :data:`GOALS` bound: the round trip's p99 (ms; None without any)."""
    return {"p99_ms": report.round_trips.p(99)}


def format_can_report(report: CanBenchReport) -> str:
    """The plain-text report of ``heft bench can`` (the goals' verdicts follow it:
    :data:`GOALS`)."""
    s, trips = report.settings, report.round_trips
    cpu = trips.cpu_percent
    lines = [
        f"heft bench can: one AGV bridge on {s.channel} (SocketCAN), measured {report.where}",
        "",
        "round trip: odometry frame on CAN -> bridge -> Zenoh -> agent -> Zenoh -> bridge ->",
        "force frame on CAN, by kernel timestamps; a tick every"
        f" {s.period_s * 1e3:g} ms for {trips.seconds:.1f} s",
        f"  {'round trips':<18} {trips.count} measured, {trips.lost} lost"
        + (f", {trips.unmatched} unmatched" if trips.unmatched else ""),
        f"  {'p50':<18} {_ms(trips.p(50))}",
        f"  {'p99':<18} {_ms(trips.p(99))}",
        f"  {'max':<18} {_ms(trips.p(100))}",
        f"  {'mean':<18} {_ms(trips.mean)}",
        f"  {'bridge CPU':<18} {_percent(cpu.get('bridge'))} of one CPU"
        f" (router {_percent(cpu.get('router'))}, echo agent {_percent(cpu.get('echo agent'))},"
        f" driver {_percent(cpu.get('driver'))})",
        "",
        f"forwarding rate: steps of {s.step_seconds:g} s (at least {s.min_step_ticks} ticks) of"
        " Sync + Odometry + AppliedForce;",
        "clean = the bridge read every frame, missed no tick, and every tick's ForceCommand came",
        "back on the bus; frames/s read include the heartbeats; round trips as above",
        f"  {'asked':>7} {'sent':>7} {'frames/s':>8} {'frames/s':>8} {'dropped':>7}"
        f" {'missed':>6} {'no cmd':>6} {'p50':>8} {'p99':>8} {'bridge':>7}  result",
        f"  {'ticks/s':>7} {'ticks/s':>7} {'read':>8} {'written':>8} {'frames':>7}"
        f" {'ticks':>6} {'ticks':>6} {'ms':>8} {'ms':>8} {'CPU':>7}",
    ]
    for step in report.steps:
        lines.append(
            f"  {step.asked:7.0f} {step.achieved:7.0f} {step.frames_in_per_s:8.0f}"
            f" {step.frames_out_per_s:8.0f} {step.dropped:7d} {step.missed_ticks:6d}"
            f" {step.unanswered:6d} {_number(step.p(50)):>8} {_number(step.p(99)):>8}"
            f" {_percent(step.bridge_cpu_percent):>7}  {'clean' if step.clean else 'loss'}"
        )
    best = report.fastest_clean
    if best is None:
        slowest = min((step.asked for step in report.steps), default=s.start_rate)
        lines.append(f"  no step without loss, down to {slowest:g} ticks/s")
    else:
        bound = "at least " if report.sender_limited else ""
        lines.append(
            f"  fastest without loss: {bound}{best.achieved:.0f} ticks/s ="
            f" {best.frames_in_per_s:.0f} frames/s read + {best.frames_out_per_s:.0f}"
            " frames/s written"
            + (" (this process could not send faster)" if report.sender_limited else "")
        )
    if report.where != "natively":
        lines += GUEST_NOTE
    return "\n".join(lines)
