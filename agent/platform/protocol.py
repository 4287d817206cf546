"""The contract between a robot's agent and everything around it.

Every message that crosses a process or a machine is defined here, and nowhere else:

- :class:`Measurement` — what a robot senses at one sensor tick (plant or AGV bridge → agent),
- :class:`Command` — the force the agent asks its robot to apply until the next tick
  (agent → plant or AGV bridge),
- :class:`Share` — what an agent tells its graph neighbours each tick (agent → neighbours),
- :class:`Estimates` and :class:`Status` — an agent's estimates and health (agent → launcher,
  displays),
- :class:`Clock`, :class:`Truth`, :class:`LoadGeometry` and :class:`PlantStatus` — the
  simulated plant's tick, its ground truth (evaluation only: no agent subscribes to it), the
  load's outline and the graph (for displays) and its counters,
- :class:`BridgeStatus` — an AGV bridge's health,
- :class:`LogLine` — a line of an agent's own log (agent → displays),
- :class:`Control` — what the launcher tells every process of a team (stop).

All vectors are planar, ``(x, y)`` tuples in SI units, in the common world frame ``W`` of the
paper (Sec. II). Robot ids are ``1..n``. A *tick* is the index of a sensor sample; every robot's
sample ``k`` is taken at the same instant ``t_k`` (the robots' clocks are synchronised), and a
message stamped ``k`` was produced after sample ``k`` and before sample ``k + 1``.

This module imports nothing of the project but the typed-table reader :mod:`agent.platform.config`
and ``Vec2``, and of third-party packages only ``orjson``: a bridge or a display reads the team's
messages without the plant, the estimator or a plotting library.
"""

from __future__ import annotations

import dataclasses as _dataclasses
import functools as _functools
import json as _json
import math as _math
import re as _re
import struct as _struct
from dataclasses import dataclass, field
from enum import IntEnum

import orjson as _orjson

from agent.platform import team as _team
from agent.platform.config import MAX_ROBOTS, ConfigError, from_table
from agent.platform.geometry import Vec2
from agent.platform.team import ConsensusState

Cov2 = tuple[float, float, float]
"""A 2×2 covariance ``(xx, xy, yy)``."""
GRAVITY = 9.81
"""m/s²: ``g``. A load of mass ``m`` weighs ``m g``; friction coefficients are fractions of it."""


class Phase(IntEnum):
    """The team's force regime (see :mod:`agent.algorithm.phase_machine`); later phases compare
    greater.

    ======== =========================================================================
    excite    kick, then the geometry-free spin-up: Steps 1-3 and ``w`` settle
    inertia   ``f_i = ±k z_i⊥`` (eq. 14): Step 4 settles
    push      a common ``f`` (eq. 17): Steps 5-7 settle
    done      zero force: the load coasts
    halted    zero force: a robot was lost, the team stopped
    ======== =========================================================================
    """

    EXCITE = 0
    INERTIA = 1
    PUSH = 2
    DONE = 3
    HALTED = 4

    @property
    def label(self) -> str:
        """The phase's name as logs, tables and JSON write it (``"excite"``)."""
        return self.name.lower()


STEPS = tuple(range(1, 8))
"""The paper's seven steps."""
STEP_NAMES = {
    1: "relative positions z_ij",
    2: "centroid offsets z_i",
    3: "angular velocity omega",
    4: "moment of inertia J",
    5: "COM offset z_C",
    6: "COM velocity",
    7: "mass m",
}


@dataclass(frozen=True, slots=True)
class Measurement:
    """Robot ``robot``'s sample at ``tick``: its contact point's velocity ``ṗ_Ci`` and the
    force it measures itself applying (both in ``W``)."""

    robot: int
    tick: int
    time_s: float
    velocity: Vec2
    force: Vec2


@dataclass(frozen=True, slots=True)
class Command:
    """The force robot ``robot`` applies at its contact point from ``tick`` until the next."""

    robot: int
    tick: int
    force: Vec2


@dataclass(frozen=True, slots=True)
class Barrier:
    """The sender's view of the team's phase barrier (:mod:`agent.algorithm.coordination`)."""

    phase: Phase = Phase.EXCITE
    ready: int = 0
    """Bitmask of the robots known to be ready to leave ``phase`` (robot ``i`` is bit
    ``i − 1``)."""
    switch_at: int = -1
    """The agreed tick of the switch (``-1`` while none is agreed)."""
    load_changes: int = 0
    """How many times the team has restarted at Step 4 for a changed load."""
    rejoins: int = 0
    """How many times the team has begun again from Step 1 after a halt (every robot back);
    its ticks count from then on as from the start."""
    levels: tuple[int, int] = (0, 0)
    """The levels the team sizes Step 4's torque and the push's force by, in steps of a quarter
    doubling of their settings, 0 to :data:`HELD_LEVEL` (the floor holds the load; one byte
    each on the wire), the largest any
    robot asked for when it became ready to leave Step 1 (:mod:`agent.algorithm.coordination`)."""


@dataclass(frozen=True, slots=True)
class Share:
    """What agent ``sender`` sends its neighbours after its step at ``tick``.

    ``velocity`` is the sender's sample of ``tick``; ``degree`` its number of neighbours
    (Metropolis consensus weights); ``barrier`` its view of the team's phase barrier.
    ``consensus`` holds its states of the team's quantities (:data:`agent.platform.team.
    TEAM_QUANTITIES`, declared there once), which refer to the sender's *estimation instant*
    ``instant`` (the newest instant for which it had its neighbours' velocities: ``tick - 1``
    unless messages were late; ``-1`` before any); vectors are in ``W`` at that instant.
    ``flows`` holds, per neighbour ``j``, ``(j, F…)``: the sender's outflows on edge
    ``(sender, j)`` of the quantities averaged in flow form, in declaration order
    (:mod:`agent.algorithm.estimation.team_consensus`).
    """

    sender: int
    tick: int
    velocity: Vec2
    degree: int
    instant: int = -1
    barrier: Barrier = Barrier()
    consensus: ConsensusState = ConsensusState()
    flows: tuple[tuple[int | float, ...], ...] = ()


@dataclass(frozen=True, slots=True)
class Estimates:
    """An agent's estimates at its estimation instant ``tick`` (vectors in ``W`` then).

    ``None`` marks a quantity not estimated yet. ``relative_positions[j]`` is
    ``z_ij = p_Ci - p_Cj``; ``centroid_offset`` is ``z_i = p_Ci - p_G``; ``com_offset`` is
    ``z_C = p_G - p_C``; ``contact_to_com`` is ``p_C - p_Ci = -(z_i + z_C)``.
    ``w`` is ``Σ_i ‖z_i‖²`` as the robot knows it by consensus (eq. 16).
    ``com_observer`` is observer (24)'s ``ẑ_C`` (run beside the team's estimate).
    ``phase_since`` is the tick at which the robot entered ``phase`` (the team's agreed switch
    tick, unless the robot caught up late). ``started`` maps a paper step (1..7) to the tick at
    which the robot began it, ``settled`` to the tick at which its estimate first settled.

    Uncertainty (the robust estimators give it; ``None`` or empty otherwise): ``mass_std`` and
    ``moment_std`` are standard deviations (kg, kg m²); ``contact_to_com_cov`` and each
    ``relative_positions_cov[j]`` are covariances ``(xx, xy, yy)`` (m²) of those vectors.
    ``drive_gain`` is the robot's estimate of its own drive's gain (applied over commanded
    force, :mod:`agent.algorithm.robust.drive_gain`), ``drive_gain_std`` its standard deviation.
    ``friction_torque`` (N m) is the floor's friction torque about the COM while the load turns
    and ``coulomb`` its kinetic friction coefficient ``μ`` (the force ``−μ m g`` against the COM's
    motion while the load translates), each with its standard deviation (docs/estimator.md,
    "Friction"). ``stuck_torque`` (N m), when given, says the floor holds the load and the robot
    estimates nothing more: the torque the team applied in Step 4 without turning it, the most
    it could apply within ``max_force`` where that falls short of what the floor's friction
    torque asks (robust Step 4), or 0 where Step 1's kick at ``max_force`` did not move it.

    ``load_changes`` counts the team's restarts at Step 4 for a changed load and ``rejoins`` its
    new beginnings from Step 1 after a halt (:mod:`agent.algorithm.coordination`);
    ``change_score`` is the last probe's test of the load against the estimates, in standard
    deviations (:mod:`agent.algorithm.robust.load_change`; ``None`` before the first probe
    ends).
    """

    robot: int
    tick: int
    phase: Phase
    phase_since: int = 0
    omega: float | None = None
    relative_positions: dict[int, Vec2] = field(default_factory=dict)
    centroid_offset: Vec2 | None = None
    w: float | None = None
    moment: float | None = None
    com_offset: Vec2 | None = None
    com_observer: Vec2 | None = None
    com_velocity: Vec2 | None = None
    mass: float | None = None
    contact_to_com: Vec2 | None = None
    started: dict[int, int] = field(default_factory=dict)
    settled: dict[int, int] = field(default_factory=dict)
    mass_std: float | None = None
    moment_std: float | None = None
    contact_to_com_cov: Cov2 | None = None
    relative_positions_cov: dict[int, Cov2] = field(default_factory=dict)
    drive_gain: float | None = None
    drive_gain_std: float | None = None
    load_changes: int = 0
    change_score: float | None = None
    rejoins: int = 0
    friction_torque: float | None = None
    friction_torque_std: float | None = None
    coulomb: float | None = None
    coulomb_std: float | None = None
    stuck_torque: float | None = None


@dataclass(frozen=True, slots=True)
class Status:
    """How an agent is doing: for logs, the launcher and displays."""

    robot: int
    tick: int
    phase: Phase
    rejected: int = 0
    decode_errors: int = 0
    late: int = 0
    lost_neighbours: tuple[int, ...] = ()
    rejoins: int = 0
    """How many times the team has begun again after a halt
    (:mod:`agent.algorithm.coordination`)."""


@dataclass(frozen=True, slots=True)
class Clock:
    """The plant's tick: sample ``tick`` was taken at ``time_s`` (simulated or wall clock)."""

    tick: int
    time_s: float


@dataclass(frozen=True, slots=True)
class Truth:
    """The load's ground truth at ``tick`` (vectors in ``W``). For evaluation and display
    only: never given to agents.

    The load's excursion so far, tracked by the plant at every tick ``k = 0 … tick`` (a
    receiver that misses some of the plant's messages still gets the whole of it):
    ``largest_travel = max_k ‖p_C(t_k) − p_C(t_0)‖`` (m), ``largest_speed = max_k ‖ṗ_C(t_k)‖``
    (m/s) and ``largest_omega = max_k |ω(t_k)|`` (rad/s)."""

    tick: int
    time_s: float
    com_position: Vec2
    """``p_C``."""
    angle: float
    """Angle of the load frame in ``W`` (rad)."""
    com_velocity: Vec2
    """``ṗ_C``."""
    omega: float
    """``ω``."""
    contacts: tuple[Vec2, ...]
    """``p_Ci``, robot ``1..n`` order."""
    contact_velocities: tuple[Vec2, ...]
    """``ṗ_Ci``."""
    contact_to_com: tuple[Vec2, ...]
    """``p_C - p_Ci``."""
    mass: float
    moment: float
    """Moment of inertia about the COM."""
    largest_travel: float = 0.0
    largest_speed: float = 0.0
    largest_omega: float = 0.0
    ground_coulomb: float = 0.0
    """``μ``: the floor's kinetic friction, a fraction of the weight ``m g`` (0: no friction)."""
    ground_static: float = 0.0
    """``μ_s ≥ μ``: its breakaway friction."""
    ground_viscous: float = 0.0
    """``b``: its viscous drag on the whole load (N s/m)."""
    friction_radius: float = 0.0
    """``c = Σ_k N_k ‖r_k‖ / (m g)`` (m), ``N_k`` the normal load on support ``k`` and ``r_k``
    its arm from the COM: a pure spin about the COM meets the friction torque ``μ m g c``."""
    viscous_radius2: float = 0.0
    """``ρ² = Σ_k N_k ‖r_k‖² / (m g)`` (m²): a spin meets the viscous torque ``b ρ² ω``."""
    friction_force: Vec2 = (0.0, 0.0)
    """The floor's force on the load (Coulomb and viscous), averaged over the period that
    ended at ``tick`` (N; zero at tick 0 and without friction)."""
    friction_torque: float = 0.0
    """Its torque about the COM, averaged likewise (N m)."""

    @property
    def coulomb_torque(self) -> float:
        """``τ_c = μ m g c`` (N m): the floor's Coulomb friction torque on a spin about the COM,
        what the robust estimators' ``friction_torque`` estimates."""
        return self.ground_coulomb * self.mass * GRAVITY * self.friction_radius

    @property
    def centroid(self) -> Vec2:
        """``p_G``, the centroid of the contact points."""
        n = len(self.contacts)
        return (
            _math.fsum(p[0] for p in self.contacts) / n,
            _math.fsum(p[1] for p in self.contacts) / n,
        )

    @property
    def centroid_offsets(self) -> tuple[Vec2, ...]:
        """``z_i = p_Ci - p_G``."""
        gx, gy = self.centroid
        return tuple((x - gx, y - gy) for x, y in self.contacts)

    @property
    def com_offset(self) -> Vec2:
        """``z_C = p_G - p_C``."""
        gx, gy = self.centroid
        return (gx - self.com_position[0], gy - self.com_position[1])


@dataclass(frozen=True, slots=True)
class LoadGeometry:
    """What the team's messages do not say but a display wants: the load's polygon about its
    COM and the communication graph. The simulated plant publishes it when it starts and with
    each of its statuses (a display that joins late has it within a status period)."""

    n: int
    outline: tuple[Vec2, ...]
    """Polygon vertices minus the COM, in the load frame: at truth pose ``(p_C, θ)`` vertex
    ``v`` is at ``p_C + R(θ) v`` in ``W``."""
    edges: tuple[tuple[int, int], ...]
    """Undirected edges ``(i, j)``, ``i < j``."""
    period_s: float
    """The sensor period: tick ``k`` is at ``k · period_s``."""
    end_tick: int = 0
    """The first tick at which the run may end (the scenario's load changes and hold); the
    final instant is not before it."""

    def world_outline(self, com: Vec2, angle: float) -> list[Vec2]:
        """The polygon in ``W`` with the COM at ``com`` and the load frame at ``angle``."""
        c, s = _math.cos(angle), _math.sin(angle)
        return [(com[0] + c * x - s * y, com[1] + s * x + c * y) for x, y in self.outline]


@dataclass(frozen=True, slots=True)
class PlantStatus:
    """The simulated plant's counters; latencies (ms, from publishing a tick to receiving a
    command for it) are ``None`` before any was measured."""

    tick: int
    time_s: float
    clock: str
    late_commands: int = 0
    missing_commands: int = 0
    overruns: int = 0
    resent: int = 0
    decode_errors: int = 0
    lost: tuple[int, ...] = ()
    latency_ms_p50: float | None = None
    latency_ms_p99: float | None = None
    latency_ms_mean: float | None = None
    latency_samples: int = 0


@dataclass(frozen=True, slots=True)
class BridgeStatus:
    """An AGV bridge's health (see :mod:`bridge.bridge`): frames each way, frames rejected
    by the codec (``decode_errors``), sequence (repeated frames, counter jumps and the frames
    they lost, ticks without a measurement), commands clamped or refused, error frames, bus
    reopenings, its command watchdog (``watchdog`` true while it commands zero force, or
    standstill, because the agent fell silent) and the driver's last heartbeat
    (``driver_mode`` -1: none yet).

    ``profile`` is the AGV protocol's (:data:`AGV_PROFILES`). With ``velocity`` the bridge
    closes an admittance loop: ``force_error_rms`` and ``force_error_p95`` (N) are its
    force-tracking error ``‖f_cmd − f_meas‖`` over its last 100 steps, and ``sensor_stale``
    is true while the base stands still because the force/torque sensor fell silent or
    reports a fault (``sensor_stale_trips`` times so far), and ``overload_stops`` counts the
    ticks the loop commanded standstill for a contact force beyond its limit; all zero with
    ``force``. ``wrong_profile`` counts the frames of the other profile among the
    ``decode_errors``."""

    robot: int
    tick: int
    watchdog: bool = False
    watchdog_trips: int = 0
    frames_in: int = 0
    frames_out: int = 0
    missed_ticks: int = 0
    decode_errors: int = 0
    repeats: int = 0
    counter_jumps: int = 0
    lost_frames: int = 0
    clamped: int = 0
    rejected_commands: int = 0
    bus_errors: int = 0
    reopens: int = 0
    driver_mode: int = -1
    driver_faults: int = 0
    profile: str = "force"
    force_error_rms: float = 0.0
    force_error_p95: float = 0.0
    sensor_stale: bool = False
    sensor_stale_trips: int = 0
    overload_stops: int = 0
    wrong_profile: int = 0


@dataclass(frozen=True, slots=True)
class Control:
    """An order to every process of a team; ``stop`` is the only one."""

    command: str = "stop"


@dataclass(frozen=True, slots=True)
class LogLine:
    """A line of robot ``robot``'s agent's own log, at ``level`` (:data:`LOG_LEVELS`: ``info``
    and above), logged while ``tick`` was its latest step (``-1`` before its first). ``text``
    is at most :data:`MAX_LOG_TEXT` characters without control characters but tab and newline
    (:func:`log_text` makes any text so). An agent publishes at most a few a second
    (:mod:`agent.platform.log_lines`)."""

    robot: int
    tick: int
    level: str
    text: str


CONTROL_COMMANDS = ("stop",)
CLOCKS = ("lockstep", "realtime")
"""How the plant and the agents keep time (see :mod:`agent.node` and :mod:`simulator.node`)."""
AGV_PROFILES = ("force", "velocity")
"""The AGV protocol's profiles a bridge speaks (``bridge.dbc.PROFILES``): a driver that takes
force commands, or a velocity-commanded base with a force/torque sensor."""
LOG_LEVELS = ("info", "warning", "error", "critical")
"""The levels of a :class:`LogLine`: Python's ``logging`` levels from INFO up, by name."""
MAX_LOG_TEXT = 1000
"""Characters of a :class:`LogLine`'s text."""
_NOT_LOG_TEXT = _re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\ud800-\udfff]")
"""What a log line's text may not hold: control characters (but tab and newline), and lone
surrogates (no UTF-8 for them)."""


def log_text(text: str) -> str:
    """``text`` as a :class:`LogLine` may carry it: each character it may not hold replaced by
    ``?``, cut to :data:`MAX_LOG_TEXT` characters (the last one ``…`` if it was cut)."""
    text = _NOT_LOG_TEXT.sub("?", text)
    if len(text) > MAX_LOG_TEXT:
        text = text[: MAX_LOG_TEXT - 1] + "…"
    return text


# ====================================================================== key expressions
class Keys:
    """The key expressions of one team: every process of a team lives under ``heft/<team>/``.

    ==================================== ================ ===================================
    key                                   message          from → to
    ==================================== ================ ===================================
    ``heft/<team>/robot/<id>/velocity``   Measurement      plant or AGV bridge → agent
    ``heft/<team>/robot/<id>/force``      Command          agent → plant or AGV bridge
    ``heft/<team>/robot/<id>/share``      Share            agent → its graph neighbours
    ``heft/<team>/robot/<id>/estimate``   Estimates        agent → launcher, displays
    ``heft/<team>/robot/<id>/status``     Status           agent → launcher, displays
    ``heft/<team>/robot/<id>/bridge``     BridgeStatus     AGV bridge → launcher, displays
    ``heft/<team>/robot/<id>/log``        LogLine          agent → displays, recorders
    ``heft/<team>/robot/<id>/alive``      (liveliness)     agent
    ``heft/<team>/robot/<id>/bridge/alive`` (liveliness)   AGV bridge
    ``heft/<team>/plant/clock``           Clock            plant → everyone
    ``heft/<team>/plant/truth``           Truth            plant → launcher, displays
    ``heft/<team>/plant/geometry``        LoadGeometry     plant → displays
    ``heft/<team>/plant/status``          PlantStatus      plant → launcher, displays
    ``heft/<team>/control``               Control          launcher → everyone
    ==================================== ================ ===================================

    A method per key takes the robot id; its ``all_…`` twin is the wildcard a subscriber to
    every robot of the team uses.
    """

    def __init__(self, team: str):
        if not team or any(c in team for c in "/*$?#"):
            raise ValueError(f"team name {team!r} must be non-empty without / * $ ? #")
        self.team = team
        self.root = f"heft/{team}"

    def _robot(self, robot: int, topic: str) -> str:
        if isinstance(robot, bool) or not isinstance(robot, int) or robot < 1:
            raise ValueError(f"robot ids are integers >= 1, got {robot!r}")
        return f"{self.root}/robot/{robot}/{topic}"

    def velocity(self, robot: int) -> str:
        return self._robot(robot, "velocity")

    def force(self, robot: int) -> str:
        return self._robot(robot, "force")

    def share(self, robot: int) -> str:
        return self._robot(robot, "share")

    def estimate(self, robot: int) -> str:
        return self._robot(robot, "estimate")

    def status(self, robot: int) -> str:
        return self._robot(robot, "status")

    def bridge(self, robot: int) -> str:
        return self._robot(robot, "bridge")

    def log(self, robot: int) -> str:
        return self._robot(robot, "log")

    def alive(self, robot: int) -> str:
        return self._robot(robot, "alive")

    def bridge_alive(self, robot: int) -> str:
        return self._robot(robot, "bridge/alive")

    def all_forces(self) -> str:
        return f"{self.root}/robot/*/force"

    def all_estimates(self) -> str:
        return f"{self.root}/robot/*/estimate"

    def all_statuses(self) -> str:
        return f"{self.root}/robot/*/status"

    def all_bridges(self) -> str:
        return f"{self.root}/robot/*/bridge"

    def all_logs(self) -> str:
        return f"{self.root}/robot/*/log"

    def all_alive(self) -> str:
        return f"{self.root}/robot/*/alive"

    def clock(self) -> str:
        return f"{self.root}/plant/clock"

    def truth(self) -> str:
        return f"{self.root}/plant/truth"

    def geometry(self) -> str:
        return f"{self.root}/plant/geometry"

    def plant_status(self) -> str:
        return f"{self.root}/plant/status"

    def control(self) -> str:
        return f"{self.root}/control"

    def of(self, message: object) -> str:
        """The key ``message`` is published on."""
        if isinstance(message, Measurement):
            return self.velocity(message.robot)
        if isinstance(message, Command):
            return self.force(message.robot)
        if isinstance(message, Share):
            return self.share(message.sender)
        if isinstance(message, Estimates):
            return self.estimate(message.robot)
        if isinstance(message, Status):
            return self.status(message.robot)
        if isinstance(message, BridgeStatus):
            return self.bridge(message.robot)
        if isinstance(message, LogLine):
            return self.log(message.robot)
        if isinstance(message, Clock):
            return self.clock()
        if isinstance(message, Truth):
            return self.truth()
        if isinstance(message, LoadGeometry):
            return self.geometry()
        if isinstance(message, PlantStatus):
            return self.plant_status()
        if isinstance(message, Control):
            return self.control()
        raise TypeError(f"not a protocol message: {type(message).__name__}")

    @staticmethod
    def robot_of(key: str) -> int:
        """The robot id in a ``heft/<team>/robot/<id>/…`` key (``DecodeError`` if none)."""
        parts = key.split("/")
        if (
            len(parts) < 4
            or parts[0] != "heft"
            or parts[2] != "robot"
            or not (parts[3].isascii() and parts[3].isdigit() and len(parts[3]) < 10)
        ):
            raise DecodeError(f"no robot id in key {key!r}")
        return int(parts[3])


# ====================================================================== on the wire
# Payloads start with a 3-byte header: magic ``b"H"``, :data:`WIRE_VERSION`, and a kind byte.
# The per-tick messages (measurement, command, share, clock, estimates) are packed with
# :mod:`struct` (little-endian: a fixed part, then counted repeats); the occasional ones are
# UTF-8 JSON objects with every field of the dataclass (pairs as arrays, phases by name).
# :func:`decode` checks everything it can and raises :class:`DecodeError` — callers count and
# log those, never crash on them.

WIRE_VERSION = 13
_MAGIC = 0x48
_HEADER = _struct.Struct("<BBB")


class DecodeError(ValueError):
    """A payload that is not a valid message of the expected kind and version."""


_MEASUREMENT = _struct.Struct("<Hqd4d")
_COMMAND = _struct.Struct("<Hq2d")
_CLOCK = _struct.Struct("<qd")
_ESTIMATES = _struct.Struct("<HqBqIBBBBHH")
"""robot, tick, phase, phase_since, which optional values follow (bit per
:data:`_OPTIONAL_ESTIMATES` entry), how many relative positions, their covariances,
started and settled steps follow them, then the load changes and the rejoins."""
_NEIGHBOUR = _struct.Struct("<H2d")
_NEIGHBOUR_COV = _struct.Struct("<H3d")
_STEP = _struct.Struct("<Bq")
_OPTIONAL_ESTIMATES: tuple[tuple[str, int], ...] = (
    ("omega", 1),
    ("centroid_offset", 2),
    ("w", 1),
    ("moment", 1),
    ("com_offset", 2),
    ("com_observer", 2),
    ("com_velocity", 2),
    ("mass", 1),
    ("contact_to_com", 2),
    ("mass_std", 1),
    ("moment_std", 1),
    ("contact_to_com_cov", 3),
    ("drive_gain", 1),
    ("drive_gain_std", 1),
    ("change_score", 1),
    ("friction_torque", 1),
    ("friction_torque_std", 1),
    ("coulomb", 1),
    ("coulomb_std", 1),
    ("stuck_torque", 1),
)
"""The :class:`Estimates` fields that may be ``None``, and how many numbers each one is."""
KINDS: dict[type, int] = {
    Measurement: 1,
    Command: 2,
    Share: 3,
    Clock: 4,
    Estimates: 5,
    Status: 6,
    Truth: 7,
    Control: 8,
    PlantStatus: 9,
    BridgeStatus: 10,
    LoadGeometry: 11,
    LogLine: 12,
}
"""Every message class and its kind byte."""


def _finite(*values: float) -> bool:
    return all(map(_math.isfinite, values))


def _json_value(value):
    if isinstance(value, Phase):
        return value.label
    if isinstance(value, dict):
        return {str(k): _json_value(v) for k, v in value.items()}
    if isinstance(value, (tuple, list)):
        return [_json_value(v) for v in value]
    return value


def encode(message: object) -> bytes:
    """The wire form of a protocol message."""
    kind = KINDS.get(type(message))
    if kind is None:
        raise TypeError(f"not a protocol message: {type(message).__name__}")
    head = _HEADER.pack(_MAGIC, WIRE_VERSION, kind)
    m = message
    if kind == 1:
        return head + _MEASUREMENT.pack(m.robot, m.tick, m.time_s, *m.velocity, *m.force)
    if kind == 2:
        return head + _COMMAND.pack(m.robot, m.tick, *m.force)
    if kind == 3:
        return head + SHARE_WIRE.pack(m)
    if kind == 4:
        return head + _CLOCK.pack(m.tick, m.time_s)
    if kind == 5:
        return head + _encode_estimates(m)
    body = {f.name: _json_value(getattr(m, f.name)) for f in _dataclasses.fields(m)}
    return head + _json.dumps(body, allow_nan=False, separators=(",", ":")).encode()


def _encode_estimates(m: Estimates) -> bytes:
    present, values = 0, []
    for bit, (name, width) in enumerate(_OPTIONAL_ESTIMATES):
        value = getattr(m, name)
        if value is not None:
            present |= 1 << bit
            values.extend((value,) if width == 1 else value)
    fixed = _ESTIMATES.pack(
        m.robot,
        m.tick,
        m.phase,
        m.phase_since,
        present,
        len(m.relative_positions),
        len(m.relative_positions_cov),
        len(m.started),
        len(m.settled),
        m.load_changes,
        m.rejoins,
    )
    return b"".join(
        (
            fixed,
            _struct.pack(f"<{len(values)}d", *values),
            *(_NEIGHBOUR.pack(j, *z) for j, z in m.relative_positions.items()),
            *(_NEIGHBOUR_COV.pack(j, *c) for j, c in m.relative_positions_cov.items()),
            *(_STEP.pack(step, tick) for step, tick in m.started.items()),
            *(_STEP.pack(step, tick) for step, tick in m.settled.items()),
        )
    )


@_functools.cache
def _optional_layout(present: int) -> tuple[_struct.Struct, tuple[tuple[str, int], ...]]:
    """The numbers that follow an :class:`Estimates`' fixed part whose presence bits are
    ``present``, and the fields they fill."""
    fields = tuple(f for bit, f in enumerate(_OPTIONAL_ESTIMATES) if present >> bit & 1)
    return _struct.Struct(f"<{sum(width for _, width in fields)}d"), fields


@_functools.cache
def _repeats(layout: _struct.Struct, count: int) -> _struct.Struct:
    """``count`` of ``layout`` back to back, as one flat tuple."""
    return _struct.Struct("<" + layout.format[1:] * count)


def _decode_estimates(body: memoryview) -> Estimates:
    if len(body) < _ESTIMATES.size:
        raise DecodeError(f"estimates: {len(body)} bytes, expected at least {_ESTIMATES.size}")
    robot, tick, phase, since, present, neighbours, covs, started, settled, changes, rejoins = (
        _ESTIMATES.unpack_from(body)
    )
    if present >> len(_OPTIONAL_ESTIMATES):
        raise DecodeError(f"estimates: presence bits 0x{present:04x} name no field")
    numbers, fields = _optional_layout(present)
    expected = (
        _ESTIMATES.size
        + numbers.size
        + neighbours * _NEIGHBOUR.size
        + covs * _NEIGHBOUR_COV.size
        + (started + settled) * _STEP.size
    )
    if len(body) != expected:
        raise DecodeError(f"estimates: {len(body)} bytes, expected {expected}")
    at = _ESTIMATES.size
    values = numbers.unpack_from(body, at)
    if not _finite(*values):
        raise DecodeError("estimates: non-finite number")
    optional, i = {}, 0
    for name, width in fields:
        optional[name] = values[i] if width == 1 else values[i : i + width]
        i += width
    at += numbers.size
    flat = _repeats(_NEIGHBOUR, neighbours).unpack_from(body, at)
    if not _finite(*flat[1::3], *flat[2::3]):
        raise DecodeError("estimates: non-finite relative position")
    relative = dict(zip(flat[0::3], zip(flat[1::3], flat[2::3], strict=True), strict=True))
    at += neighbours * _NEIGHBOUR.size
    flat = _repeats(_NEIGHBOUR_COV, covs).unpack_from(body, at)
    if not _finite(*flat[1::4], *flat[2::4], *flat[3::4]):
        raise DecodeError("estimates: non-finite relative position covariance")
    relative_cov = dict(zip(flat[0::4], zip(flat[1::4], flat[2::4], flat[3::4]), strict=True))
    at += covs * _NEIGHBOUR_COV.size
    flat = _repeats(_STEP, started + settled).unpack_from(body, at)
    steps = dict(zip(flat[0 : 2 * started : 2], flat[1 : 2 * started : 2], strict=True))
    done = dict(zip(flat[2 * started :: 2], flat[2 * started + 1 :: 2], strict=True))
    if (len(relative), len(relative_cov), len(steps), len(done)) != (
        neighbours,
        covs,
        started,
        settled,
    ):
        raise DecodeError("estimates: a neighbour or a step repeated")
    return Estimates(
        robot,
        tick,
        _phase(phase, "estimates"),
        since,
        relative_positions=relative,
        started=steps,
        settled=done,
        relative_positions_cov=relative_cov,
        load_changes=changes,
        rejoins=rejoins,
        **optional,
    )


def _check_header(payload: bytes, expected: int) -> memoryview:
    if len(payload) < _HEADER.size:
        raise DecodeError(f"payload of {len(payload)} bytes is shorter than the header")
    magic, version, kind = _HEADER.unpack_from(payload)
    if magic != _MAGIC:
        raise DecodeError(f"bad magic byte 0x{magic:02x}")
    if version != WIRE_VERSION:
        raise DecodeError(f"wire version {version}, this program speaks {WIRE_VERSION}")
    if kind != expected:
        raise DecodeError(f"message kind {kind}, expected {expected}")
    return memoryview(payload)[_HEADER.size :]


def _unpack(layout: _struct.Struct, body: memoryview, name: str) -> tuple:
    if len(body) != layout.size:
        raise DecodeError(f"{name}: {len(body)} bytes, expected {layout.size}")
    values = layout.unpack(body)
    if not _finite(*(v for v in values if isinstance(v, float))):
        raise DecodeError(f"{name}: non-finite number")
    return values


@_functools.cache
def _field_names(cls: type) -> frozenset[str]:
    return frozenset(f.name for f in _dataclasses.fields(cls))


def _json_message(cls: type, body: memoryview):
    name = cls.__name__
    try:
        data = _orjson.loads(body)
    except (_orjson.JSONDecodeError, RecursionError) as err:
        raise DecodeError(f"{name}: not JSON ({type(err).__name__}: {err})") from None
    if not isinstance(data, dict):
        raise DecodeError(f"{name}: expected a JSON object")
    if data.keys() != _field_names(cls):
        raise DecodeError(f"{name}: keys {sorted(data)} are not those of {name}")
    try:
        return from_table(cls, data, name)
    except (ConfigError, RecursionError) as err:
        raise DecodeError(str(err)) from None


# ====================================================================== domains
# A message that decodes is still checked field by field before it reaches an estimator, the
# plant or a display: ids, ticks and phases within their domains, vectors within physical
# bounds (generous: they reject garbage and clocks gone wrong, not unusual runs). What a
# receiver alone can check — a robot id within its team, a tick near its own clock — it checks
# itself (see :mod:`agent.node`, :mod:`simulator.node`).

MAX_ROBOT_ID = 0xFFFF
MAX_TICK = 2**40
"""About 35 years of ticks at 1 kHz."""
MAX_TIME_S = 1e9
MAX_SPEED = 500.0
"""m/s, a contact point's velocity."""
MAX_FORCE = 10_000.0
"""N, a commanded or measured force."""
MAX_DISTANCE = _team.MAX_DISTANCE
MAX_FLOW = _team.MAX_FLOW
MAX_GAIN = _team.MAX_GAIN
MAX_LOAD_CHANGES = 10_000
"""The team's restarts for a changed load in one run (one a second for almost three hours)."""
MAX_REJOINS = 10_000
"""The team's new beginnings after a halt in one run."""
HELD_LEVEL = 255
"""A barrier's level that says the floor holds the load beyond the team's forces
(:attr:`Barrier.levels`); the levels that size forces are below it."""
MAX_VERTICES = 1000
"""Of the load's outline."""
MAX_COORDINATE = 1000.0
"""m, an outline vertex's coordinates."""


def _within(name: str, value: float, low: float, high: float) -> None:
    if not low <= value <= high:
        raise DecodeError(f"{name} = {value!r} is outside [{low:g}, {high:g}]")


def _bounded(name: str, v: tuple[float, float], bound: float) -> None:
    if _math.hypot(v[0], v[1]) > bound:
        raise DecodeError(f"{name} = {v!r} is longer than {bound:g}")


def _robot_id(name: str, value: int) -> None:
    _within(name, value, 1, MAX_ROBOT_ID)


def _measurement(m: Measurement) -> None:
    _robot_id("measurement.robot", m.robot)
    _within("measurement.tick", m.tick, 0, MAX_TICK)
    _within("measurement.time_s", m.time_s, 0.0, MAX_TIME_S)
    _bounded("measurement.velocity", m.velocity, MAX_SPEED)
    _bounded("measurement.force", m.force, MAX_FORCE)


def _command(m: Command) -> None:
    _robot_id("command.robot", m.robot)
    _within("command.tick", m.tick, 0, MAX_TICK)
    _bounded("command.force", m.force, MAX_FORCE)


def _clock(m: Clock) -> None:
    _within("clock.tick", m.tick, 0, MAX_TICK)
    _within("clock.time_s", m.time_s, 0.0, MAX_TIME_S)


def _estimates(m: Estimates) -> None:
    """Telemetry: ids and ticks; values only finite (early estimates may be far off)."""
    _robot_id("estimates.robot", m.robot)
    _within("estimates.tick", m.tick, -1, MAX_TICK)
    _within("estimates.phase_since", m.phase_since, 0, MAX_TICK)
    _within("estimates.load_changes", m.load_changes, 0, MAX_LOAD_CHANGES)
    _within("estimates.rejoins", m.rejoins, 0, MAX_REJOINS)
    for j in m.relative_positions:
        _robot_id("estimates.relative_positions", j)
    for step in (*m.started, *m.settled):
        _within("estimates step", step, 1, 7)
    for j, cov in m.relative_positions_cov.items():
        _robot_id("estimates.relative_positions_cov", j)
        _covariance("estimates.relative_positions_cov", cov)
    if m.contact_to_com_cov is not None:
        _covariance("estimates.contact_to_com_cov", m.contact_to_com_cov)
    for name in (
        "mass_std",
        "moment_std",
        "drive_gain_std",
        "change_score",
        "friction_torque_std",
        "coulomb_std",
        "stuck_torque",
    ):
        value = getattr(m, name)
        if value is not None:
            _within(f"estimates.{name}", value, 0.0, _math.inf)
    if m.drive_gain is not None:
        _within("estimates.drive_gain", m.drive_gain, 0.0, MAX_GAIN)


def _covariance(name: str, cov: tuple[float, float, float]) -> None:
    """A 2×2 covariance ``(xx, xy, yy)``: positive semi-definite (to rounding)."""
    xx, xy, yy = cov
    if not (xx >= 0.0 and yy >= 0.0 and xy * xy <= xx * yy * (1.0 + 1e-9) + 1e-300):
        raise DecodeError(f"{name} = {cov!r} is not a covariance")


def _status(m: Status) -> None:
    _robot_id("status.robot", m.robot)
    _within("status.tick", m.tick, -1, MAX_TICK)
    for j in m.lost_neighbours:
        _robot_id("status.lost_neighbours", j)
    _within("status.rejoins", m.rejoins, 0, MAX_REJOINS)


def _truth(m: Truth) -> None:
    _within("truth.tick", m.tick, 0, MAX_TICK)
    _within("truth.time_s", m.time_s, 0.0, MAX_TIME_S)
    if not len(m.contacts) == len(m.contact_velocities) == len(m.contact_to_com) >= 1:
        raise DecodeError("truth: contacts, contact_velocities, contact_to_com differ in length")
    if not (m.mass > 0 and m.moment > 0):
        raise DecodeError("truth: mass and moment must be positive")
    for name in (
        "largest_travel",
        "largest_speed",
        "largest_omega",
        "ground_coulomb",
        "ground_viscous",
        "friction_radius",
        "viscous_radius2",
    ):
        value = getattr(m, name)
        if not (_math.isfinite(value) and value >= 0.0):
            raise DecodeError(f"truth.{name} = {value!r} is not a finite number >= 0")
    if not m.ground_static >= m.ground_coulomb:
        raise DecodeError(
            f"truth.ground_static = {m.ground_static!r} is below ground_coulomb"
            f" = {m.ground_coulomb!r}"
        )
    if not m.friction_radius**2 <= m.viscous_radius2 * (1.0 + 1e-9) + 1e-300:
        raise DecodeError(
            f"truth: friction_radius² = {m.friction_radius**2!r} exceeds viscous_radius2"
            f" = {m.viscous_radius2!r} (a mean radius above its root mean square)"
        )


def _load_geometry(m: LoadGeometry) -> None:
    _within("load_geometry.n", m.n, 2, MAX_ROBOTS)
    if not 3 <= len(m.outline) <= MAX_VERTICES or not all(
        abs(v) <= MAX_COORDINATE for p in m.outline for v in p
    ):
        raise DecodeError(
            f"load_geometry.outline: not a polygon of 3 to {MAX_VERTICES} vertices within"
            f" {MAX_COORDINATE:g} m"
        )
    pairs = m.n * (m.n - 1) // 2
    if not all(1 <= i < j <= m.n for i, j in m.edges) or len(set(m.edges)) != len(m.edges):
        raise DecodeError(f"load_geometry.edges: not edges i < j of robots 1..{m.n}, each once")
    if len(m.edges) > pairs:
        raise DecodeError(f"load_geometry.edges: more than {pairs}")
    _within("load_geometry.period_s", m.period_s, 1e-4, 1.0)
    _within("load_geometry.end_tick", m.end_tick, 0, MAX_TICK)


def _plant_status(m: PlantStatus) -> None:
    _within("plant_status.tick", m.tick, 0, MAX_TICK)
    if m.clock not in CLOCKS:
        raise DecodeError(f"plant_status.clock {m.clock!r} is not one of {CLOCKS}")
    for j in m.lost:
        _robot_id("plant_status.lost", j)


def _bridge_status(m: BridgeStatus) -> None:
    _robot_id("bridge_status.robot", m.robot)
    _within("bridge_status.tick", m.tick, -1, MAX_TICK)
    for name in _BRIDGE_COUNTERS:
        _within(f"bridge_status.{name}", getattr(m, name), 0, MAX_TICK)
    _within("bridge_status.driver_mode", m.driver_mode, -1, 15)
    _within("bridge_status.driver_faults", m.driver_faults, 0, 255)
    if m.profile not in AGV_PROFILES:
        raise DecodeError(f"bridge_status.profile {m.profile!r} is not one of {AGV_PROFILES}")
    _within("bridge_status.force_error_rms", m.force_error_rms, 0.0, MAX_FORCE)
    _within("bridge_status.force_error_p95", m.force_error_p95, 0.0, MAX_FORCE)


_BRIDGE_COUNTERS = (
    "watchdog_trips",
    "frames_in",
    "frames_out",
    "missed_ticks",
    "decode_errors",
    "repeats",
    "counter_jumps",
    "lost_frames",
    "clamped",
    "rejected_commands",
    "bus_errors",
    "reopens",
    "sensor_stale_trips",
    "overload_stops",
    "wrong_profile",
)


def _log_line(m: LogLine) -> None:
    _robot_id("log_line.robot", m.robot)
    _within("log_line.tick", m.tick, -1, MAX_TICK)
    if m.level not in LOG_LEVELS:
        raise DecodeError(f"log_line.level {m.level!r} is not one of {LOG_LEVELS}")
    if len(m.text) > MAX_LOG_TEXT:
        raise DecodeError(f"log_line.text: {len(m.text)} characters, at most {MAX_LOG_TEXT}")
    bad = _NOT_LOG_TEXT.search(m.text)
    if bad is not None:
        raise DecodeError(f"log_line.text: character {bad.group()!r} at {bad.start()}")


def _control(m: Control) -> None:
    if m.command not in CONTROL_COMMANDS:
        raise DecodeError(f"control.command {m.command!r} is not one of {CONTROL_COMMANDS}")


class ShareWire:
    """:class:`Share`'s wire layout and domain checks, derived from the team quantities'
    declarations (:mod:`agent.platform.team`): one number per component of each quantity's state
    and of each flow. The fixed part: sender, tick, velocity, degree, instant; the barrier
    (phase, ready, switch_at, load_changes, rejoins, the two levels); the quantities' layout code
    (:func:`~agent.platform.team.layout_code`) and states; how many flows follow, each the
    neighbour's id and the flow-form quantities' outflows, in declaration order."""

    def __init__(
        self, quantities: tuple[_team.TeamQuantity, ...] = _team.TEAM_QUANTITIES, state_type=None
    ):
        self.quantities = tuple(quantities)
        self.state_type = state_type or _team.consensus_state_type(self.quantities)
        self.fixed = _struct.Struct(f"<Hq2dHqBQqHHBBH{_team.width(self.quantities)}dB")
        self.flow = _struct.Struct(f"<H{_team.flow_width(self.quantities)}d")
        self.flow_fields = 1 + _team.flow_width(self.quantities)
        """A flow's numbers: the neighbour, then the outflows."""
        self.layout = _team.layout_code(self.quantities)

    def pack(self, m: Share) -> bytes:
        """The body of ``m`` (after the header)."""
        b = m.barrier
        fixed = self.fixed.pack(
            m.sender,
            m.tick,
            *m.velocity,
            m.degree,
            m.instant,
            b.phase,
            b.ready,
            b.switch_at,
            b.load_changes,
            b.rejoins,
            *b.levels,
            self.layout,
            *_team.flatten(m.consensus, self.quantities),
            len(m.flows),
        )
        return fixed + b"".join(self.flow.pack(*f) for f in m.flows)

    def unpack(self, body: memoryview | bytes) -> Share:
        """The share of ``body``; :class:`DecodeError` unless it is one of this layout."""
        body = memoryview(body)
        fixed, flow = self.fixed, self.flow
        values = _unpack(fixed, body[: fixed.size], "share")
        sender, tick, vx, vy, degree, instant, phase, ready, switch_at, changes, rejoins = values[
            :11
        ]
        levels, layout, count = values[11:13], values[13], values[-1]
        if layout != self.layout:
            raise DecodeError(
                f"share: team quantities of layout 0x{layout:04x}, this program's"
                f" 0x{self.layout:04x}"
            )
        rest = body[fixed.size :]
        if len(rest) != count * flow.size:
            raise DecodeError(f"share: {len(rest)} bytes of flows, expected {count * flow.size}")
        flows = tuple(
            _unpack(flow, rest[i : i + flow.size], "share flow")
            for i in range(0, len(rest), flow.size)
        )
        barrier = Barrier(_phase(phase, "share"), ready, switch_at, changes, rejoins, levels)
        consensus = self.state_type(*_team.grouped(values[14:-1], self.quantities))
        return Share(sender, tick, (vx, vy), degree, instant, barrier, consensus, flows)

    def check(self, m: Share) -> None:
        """:class:`DecodeError` naming the field unless every field is within its domain."""
        _robot_id("share.sender", m.sender)
        _within("share.tick", m.tick, 0, MAX_TICK)
        _bounded("share.velocity", m.velocity, MAX_SPEED)
        _within("share.degree", m.degree, 1, MAX_ROBOT_ID)
        _within("share.instant", m.instant, -1, m.tick - 1)
        b = m.barrier
        _within("share.barrier.switch_at", b.switch_at, -1, MAX_TICK)
        _within("share.barrier.load_changes", b.load_changes, 0, MAX_LOAD_CHANGES)
        _within("share.barrier.rejoins", b.rejoins, 0, MAX_REJOINS)
        if len(m.consensus) != len(self.quantities):
            raise DecodeError(
                f"share.consensus: {len(m.consensus)} quantities, expected {len(self.quantities)}"
            )
        outside = _team.check_state(m.consensus, self.quantities, "share.consensus")
        if outside is not None:
            raise DecodeError(outside)
        _within("share.flows (how many)", len(m.flows), 0, m.degree)
        for flow in m.flows:
            if len(flow) != self.flow_fields:
                raise DecodeError(
                    f"share.flows: expected {self.flow_fields} numbers a flow, got {flow!r}"
                )
            _robot_id("share.flows.robot", flow[0])
            for f in flow[1:]:
                _within("share.flows", f, -MAX_FLOW, MAX_FLOW)


SHARE_WIRE = ShareWire(_team.TEAM_QUANTITIES, ConsensusState)
"""The wire of :class:`Share` for the team's quantities."""


DOMAINS = {
    Measurement: _measurement,
    Command: _command,
    Share: lambda m: SHARE_WIRE.check(m),
    Clock: _clock,
    Estimates: _estimates,
    Status: _status,
    Truth: _truth,
    PlantStatus: _plant_status,
    LoadGeometry: _load_geometry,
    BridgeStatus: _bridge_status,
    Control: _control,
    LogLine: _log_line,
}
"""Each message class's domain check: raises :class:`DecodeError` naming the field."""


def _phase(value: int, name: str) -> Phase:
    try:
        return Phase(value)
    except ValueError:
        raise DecodeError(f"{name}: phase {value} is not one of 0..{max(Phase)}") from None


def decode(kind: type, payload: bytes):
    """Decode ``payload`` as a message of class ``kind`` and check every field's domain;
    :class:`DecodeError` if it is not one."""
    message = _decode(kind, payload)
    DOMAINS[kind](message)
    return message


def _decode(kind: type, payload: bytes):
    code = KINDS.get(kind)
    if code is None:
        raise TypeError(f"not a protocol message class: {kind!r}")
    body = _check_header(payload, code)
    if kind is Measurement:
        r, t, ts, vx, vy, fx, fy = _unpack(_MEASUREMENT, body, "measurement")
        return Measurement(r, t, ts, (vx, vy), (fx, fy))
    if kind is Command:
        r, t, fx, fy = _unpack(_COMMAND, body, "command")
        return Command(r, t, (fx, fy))
    if kind is Share:
        return SHARE_WIRE.unpack(body)
    if kind is Clock:
        return Clock(*_unpack(_CLOCK, body, "clock"))
    if kind is Estimates:
        return _decode_estimates(body)
    return _json_message(kind, body)
