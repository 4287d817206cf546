"""The contract between a robot's agent and everything around it.

Every message that crosses a process or a machine is defined here, and nowhere else:

- :class:`Measurement` — what a robot senses at one sensor tick (plant or AGV → agent),
- :class:`Command` — the force the agent asks its robot to apply until the next tick
  (agent → plant or AGV),
- :class:`Share` — what an agent tells its graph neighbours each tick (agent → neighbours),
- :class:`Estimates` — the agent's current estimates, for logs, results and displays.

All vectors are planar, ``(x, y)`` tuples in SI units, in the common world frame ``W`` of the
paper (Sec. II). Robot ids are ``1..n``. A *tick* is the index of a sensor sample; every robot's
sample ``k`` is taken at the same instant ``t_k`` (the robots' clocks are synchronised), and a
message stamped ``k`` was produced after sample ``k`` and before sample ``k + 1``.
"""

from __future__ import annotations

import json as _json
import math as _math
import struct as _struct
from dataclasses import dataclass, field

Vec2 = tuple[float, float]


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
class Share:
    """What agent ``sender`` sends its neighbours after its step at ``tick``.

    ``velocity`` is the sender's sample of ``tick``. The consensus states refer to the
    sender's *estimation instant* ``instant`` (the newest instant for which it had its
    neighbours' velocities: ``tick - 1`` unless messages were late; ``-1`` before any);
    vectors are in ``W`` at that instant.

    - ``degree``: the sender's number of neighbours (Metropolis consensus weights).
    - ``centroid``: the sender's centroid iterate ``x_i`` (Aragues et al. [10]) or ``None``.
    - ``spread``: the sender's average-consensus state ``ξ_i`` for ``w = Σ‖z_i‖²`` (eq. 16).
    - ``flows``: ``(j, F_x, F_y, F_s)`` per neighbour ``j``: the sender's outflows of both
      iterations on edge ``(sender, j)`` (see :mod:`agent.estimation.flows`).
    - ``phase``, ``ready``, ``switch_at``: the team's phase barrier (see
      :mod:`agent.coordination`): the sender's phase, the bitmask of robots known to be ready
      to leave it, and the agreed tick of the switch (``-1`` while none is agreed).
    """

    sender: int
    tick: int
    velocity: Vec2
    degree: int
    centroid: Vec2 | None = None
    spread: float = 0.0
    phase: int = 0
    ready: int = 0
    switch_at: int = -1
    flows: tuple[tuple[int, float, float, float], ...] = ()
    instant: int = -1


@dataclass(frozen=True, slots=True)
class Estimates:
    """An agent's estimates at its estimation instant ``tick`` (vectors in ``W`` then).

    ``None`` marks a quantity not estimated yet. ``relative_positions[j]`` is
    ``z_ij = p_Ci - p_Cj``; ``centroid_offset`` is ``z_i = p_Ci - p_G``; ``com_offset`` is
    ``z_C = p_G - p_C``; ``contact_to_com`` is ``p_C - p_Ci = -(z_i + z_C)``.
    ``spread`` is ``w = Σ_i ‖z_i‖²`` as the robot knows it by consensus (eq. 16).
    ``com_observer`` is observer (24)'s ``ẑ_C`` (run beside the team's estimate).
    ``started`` maps a paper step (1..7) to the tick at which the robot began it, ``settled`` to
    the tick at which its estimate first settled.
    """

    robot: int
    tick: int
    phase: str
    omega: float | None = None
    relative_positions: dict[int, Vec2] = field(default_factory=dict)
    centroid_offset: Vec2 | None = None
    spread: float | None = None
    moment: float | None = None
    com_offset: Vec2 | None = None
    com_observer: Vec2 | None = None
    com_velocity: Vec2 | None = None
    mass: float | None = None
    contact_to_com: Vec2 | None = None
    started: dict[int, int] = field(default_factory=dict)
    settled: dict[int, int] = field(default_factory=dict)


# ====================================================================== on the wire
# Key expressions: every process of one team lives under ``heft/<team>/``.
#
#   heft/<team>/robot/<id>/velocity   Measurement   plant or AGV bridge → agent <id>
#   heft/<team>/robot/<id>/force      Command       agent <id> → plant or AGV bridge
#   heft/<team>/robot/<id>/share      Share         agent <id> → its graph neighbours
#   heft/<team>/robot/<id>/estimate   Estimates     agent <id> → launcher, displays
#   heft/<team>/robot/<id>/status     Status        agent <id> → launcher, displays
#   heft/<team>/robot/<id>/alive      (liveliness token of agent <id>)
#   heft/<team>/plant/clock           Clock         plant → everyone (lockstep and real time)
#   heft/<team>/plant/truth           Truth         plant → launcher, displays (evaluation only)
#   heft/<team>/plant/status          plant_status  plant → launcher (counters, latencies)
#   heft/<team>/control               Control       launcher → everyone (stop)
#
# Payloads start with a 3-byte header: magic ``b"H"``, :data:`WIRE_VERSION`, and a kind byte.
# The per-tick messages (measurement, command, share, clock) are packed with :mod:`struct`
# (little-endian, fixed size); the occasional ones (estimate, status, truth, control) are UTF-8
# JSON. :func:`decode` checks everything it can and raises :class:`DecodeError` — callers count
# and log those, never crash on them.

WIRE_VERSION = 1
CLOCKS = ("lockstep", "realtime")
"""How the plant and the agents keep time (see :mod:`agent.node` and :mod:`simulator.node`)."""
_MAGIC = 0x48
_HEADER = _struct.Struct("<BBB")


class DecodeError(ValueError):
    """A payload that is not a valid message of the expected kind and version."""


class Keys:
    """The key expressions of one team."""

    def __init__(self, team: str):
        if not team or any(c in team for c in "/*$?#"):
            raise ValueError(f"team name {team!r} must be non-empty without / * $ ? #")
        self.team = team
        self.root = f"heft/{team}"

    def robot(self, robot: int, topic: str) -> str:
        """``heft/<team>/robot/<id>/<topic>``; ``robot=0`` gives the wildcard ``*``."""
        return f"{self.root}/robot/{robot if robot else '*'}/{topic}"

    def plant(self, topic: str) -> str:
        return f"{self.root}/plant/{topic}"

    @property
    def control(self) -> str:
        return f"{self.root}/control"

    @staticmethod
    def robot_of(key: str) -> int:
        """The robot id in a ``heft/<team>/robot/<id>/…`` key (``DecodeError`` if none)."""
        parts = key.split("/")
        if (
            len(parts) < 4
            or parts[0] != "heft"
            or parts[2] != "robot"
            or not (parts[3].isascii() and parts[3].isdigit())
        ):
            raise DecodeError(f"no robot id in key {key!r}")
        return int(parts[3])


@dataclass(frozen=True, slots=True)
class Clock:
    """The plant's tick: sample ``tick`` was taken at ``time_s`` (simulated or wall clock)."""

    tick: int
    time_s: float


@dataclass(frozen=True, slots=True)
class Status:
    """How an agent is doing: for logs, the launcher and displays."""

    robot: int
    tick: int
    phase: str
    rejected: int = 0
    decode_errors: int = 0
    late: int = 0
    lost_neighbours: tuple[int, ...] = ()


# kind byte → (type, struct of the body)
_MEASUREMENT = _struct.Struct("<Hqd4d")
_COMMAND = _struct.Struct("<Hq2d")
_SHARE = _struct.Struct("<Hq2dHB2ddBQqqB")
_FLOW = _struct.Struct("<H3d")
_CLOCK = _struct.Struct("<qd")
_KIND = {Measurement: 1, Command: 2, Share: 3, Clock: 4, Estimates: 5, Status: 6}
_JSON_KINDS = {7: "truth", 8: "control", 9: "plant_status"}


def _finite(*values: float) -> bool:
    return all(_math.isfinite(v) for v in values)


def encode(message: object) -> bytes:
    """The wire form of a protocol message."""
    kind = _KIND.get(type(message))
    if kind is None:
        raise TypeError(f"not a protocol message: {type(message).__name__}")
    head = _HEADER.pack(_MAGIC, WIRE_VERSION, kind)
    m = message
    if kind == 1:
        return head + _MEASUREMENT.pack(m.robot, m.tick, m.time_s, *m.velocity, *m.force)
    if kind == 2:
        return head + _COMMAND.pack(m.robot, m.tick, *m.force)
    if kind == 3:
        has = m.centroid is not None
        cx, cy = m.centroid if has else (0.0, 0.0)
        fixed = _SHARE.pack(
            m.sender,
            m.tick,
            *m.velocity,
            m.degree,
            has,
            cx,
            cy,
            m.spread,
            m.phase,
            m.ready,
            m.switch_at,
            m.instant,
            len(m.flows),
        )
        return head + fixed + b"".join(_FLOW.pack(*f) for f in m.flows)
    if kind == 4:
        return head + _CLOCK.pack(m.tick, m.time_s)
    body = {k: getattr(m, k) for k in m.__dataclass_fields__}
    if kind == 5:
        body["relative_positions"] = {str(j): v for j, v in m.relative_positions.items()}
        body["started"] = {str(s): t for s, t in m.started.items()}
        body["settled"] = {str(s): t for s, t in m.settled.items()}
    return head + _json.dumps(body, allow_nan=False, separators=(",", ":")).encode()


def encode_json(kind: str, body: dict) -> bytes:
    """The wire form of a JSON message of ``kind`` ``"truth"``, ``"control"`` or
    ``"plant_status"``."""
    code = {v: k for k, v in _JSON_KINDS.items()}[kind]
    return (
        _HEADER.pack(_MAGIC, WIRE_VERSION, code)
        + _json.dumps(body, allow_nan=False, separators=(",", ":")).encode()
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


def _no_constants(name: str):
    raise ValueError(f"{name} is not a number this protocol accepts")


def _json_body(body: memoryview, name: str) -> dict:
    try:
        data = _json.loads(bytes(body), parse_constant=_no_constants)
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        raise DecodeError(f"{name}: not JSON ({type(err).__name__}: {err})") from None
    if not isinstance(data, dict):
        raise DecodeError(f"{name}: expected a JSON object")
    return data


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v) -> bool:
    return (isinstance(v, (int, float)) and not isinstance(v, bool)) and _math.isfinite(v)


def _is_pair(v) -> bool:
    return isinstance(v, list) and len(v) == 2 and all(_is_number(x) for x in v)


def _check(ok: bool, name: str, key: str) -> None:
    if not ok:
        raise DecodeError(f"{name}: {key} has the wrong type")


def _int_keys(d, name: str, key: str, value_ok) -> dict:
    _check(isinstance(d, dict), name, key)
    out = {}
    for k, v in d.items():
        _check(k.isascii() and k.isdigit() and value_ok(v), name, key)
        out[int(k)] = tuple(v) if isinstance(v, list) else v
    return out


_ESTIMATE_NUMBERS = ("omega", "spread", "moment", "mass")
_ESTIMATE_PAIRS = (
    "centroid_offset",
    "com_offset",
    "com_observer",
    "com_velocity",
    "contact_to_com",
)


def _estimates(data: dict) -> Estimates:
    name = "estimates"
    if set(data) != set(Estimates.__dataclass_fields__):
        raise DecodeError(f"{name}: keys {sorted(data)} are not those of estimates")
    _check(_is_int(data["robot"]) and _is_int(data["tick"]), name, "robot/tick")
    _check(isinstance(data["phase"], str), name, "phase")
    for key in _ESTIMATE_NUMBERS:
        _check(data[key] is None or _is_number(data[key]), name, key)
    for key in _ESTIMATE_PAIRS:
        _check(data[key] is None or _is_pair(data[key]), name, key)
        if data[key] is not None:
            data[key] = tuple(data[key])
    data["relative_positions"] = _int_keys(
        data["relative_positions"], name, "relative_positions", _is_pair
    )
    data["started"] = _int_keys(data["started"], name, "started", _is_int)
    data["settled"] = _int_keys(data["settled"], name, "settled", _is_int)
    return Estimates(**data)


def _status(data: dict) -> Status:
    name = "status"
    known = set(Status.__dataclass_fields__)
    if not {"robot", "tick", "phase"} <= set(data) <= known:
        raise DecodeError(f"{name}: keys {sorted(data)} are not those of status")
    for key in ("rejected", "decode_errors", "late"):
        data.setdefault(key, 0)
    data.setdefault("lost_neighbours", [])
    for key in ("robot", "tick", "rejected", "decode_errors", "late"):
        _check(_is_int(data[key]), name, key)
    _check(isinstance(data["phase"], str), name, "phase")
    lost = data["lost_neighbours"]
    _check(isinstance(lost, list) and all(_is_int(j) for j in lost), name, "lost_neighbours")
    data["lost_neighbours"] = tuple(lost)
    return Status(**data)


def decode(kind: type | str, payload: bytes):
    """Decode ``payload`` as a message of ``kind`` (a message class, or ``"truth"`` /
    ``"control"`` for the JSON dictionaries); :class:`DecodeError` if it is not one."""
    if isinstance(kind, str):
        code = {v: k for k, v in _JSON_KINDS.items()}.get(kind)
        if code is None:
            raise ValueError(f"unknown message kind {kind!r}")
        return _json_body(_check_header(payload, code), kind)
    code = _KIND[kind]
    body = _check_header(payload, code)
    if kind is Measurement:
        r, t, ts, vx, vy, fx, fy = _unpack(_MEASUREMENT, body, "measurement")
        return Measurement(r, t, ts, (vx, vy), (fx, fy))
    if kind is Command:
        r, t, fx, fy = _unpack(_COMMAND, body, "command")
        return Command(r, t, (fx, fy))
    if kind is Share:
        fixed = body[: _SHARE.size]
        s, t, vx, vy, deg, has, cx, cy, spread, phase, ready, switch_at, instant, count = _unpack(
            _SHARE, fixed, "share"
        )
        rest = body[_SHARE.size :]
        if len(rest) != count * _FLOW.size:
            raise DecodeError(f"share: {len(rest)} bytes of flows, expected {count * _FLOW.size}")
        flows = tuple(
            _unpack(_FLOW, rest[i : i + _FLOW.size], "share flow")
            for i in range(0, len(rest), _FLOW.size)
        )
        return Share(
            s,
            t,
            (vx, vy),
            deg,
            (cx, cy) if has else None,
            spread,
            phase,
            ready,
            switch_at,
            flows,
            instant,
        )
    if kind is Clock:
        return Clock(*_unpack(_CLOCK, body, "clock"))
    data = _json_body(body, kind.__name__.lower())
    return _estimates(data) if kind is Estimates else _status(data)
