"""The AGV CAN protocol, built as cantools databases and written to ``bridge/agv.dbc`` (the
force profile) and ``bridge/agv-velocity.dbc`` (the velocity profile).

The DBC files are what the bridge loads at run time and what ``cantools dump bridge/agv.dbc``,
``cantools decode`` and bus monitors read; this module is where their frames are declared once
(run ``python -m bridge.dbc`` after changing them: a test checks the files are up to date).

Two profiles, for two kinds of AGV driver (``[can] profile`` in ``robot.toml``):

- ``force``: the paper's robot. The driver takes a force command and reports the contact
  point's velocity and the force it applied;
- ``velocity``: a base that takes velocity commands, as most real drivers do (AgileX's motion
  command, CiA 402's velocity modes), with a force/torque sensor at the contact. The bridge
  closes an admittance loop (:mod:`bridge.admittance`) from the sensor's force to the base's
  velocity command.

The two share ``Sync`` and ``Heartbeat``; every other frame belongs to one profile, on
identifiers of its own, so a frame of the other profile is recognised and refused.

Classic CAN, 11-bit identifiers, every frame 8 bytes. Identifiers follow CANopen's function
codes, so a frame's id says what it is and whose it is: ``id = base + node`` with the robot's
node id ``node`` in 1..32 (robot ``i`` is node ``i``), and several robots can share one bus:

========================  ======  ========  ==================  ===================================
frame                     base    profile   sender              period
========================  ======  ========  ==================  ===================================
``Sync``                  0x080   both      bus master (plant)  one per tick (opens the tick)
``Odometry_<n>``          0x180   force     AGV driver n        one per tick, after ``Sync``
``ForceCommand_<n>``      0x200   force     bridge n            one per tick; zero on the watchdog
``AppliedForce_<n>``      0x280   force     AGV driver n        one per tick, after ``Sync``
``MotionCommand_<n>``     0x300   velocity  bridge n            one per tick; STOP on the watchdog
``MotionFeedback_<n>``    0x380   velocity  AGV driver n        one per tick, after ``Sync``
``ForceTorque_<n>``       0x480   velocity  F/T sensor n        one per tick, after ``Sync``
``Heartbeat_<n>``         0x700   both      AGV driver n        100 ms
========================  ======  ========  ==================  ===================================

``MotionCommand`` is the base's velocity (m/s, world frame, as every vector here) with a mode:
STOP brakes to standstill (the bridge's watchdog, a stale sensor), VELOCITY drives at it.
``MotionFeedback`` is the base's measured velocity, which the bridge reports as its contact
point's (the contact's compression changes slowly, see :mod:`bridge.admittance`).
``ForceTorque`` is the force the sensor at the contact measures, raw (its bias is the
bridge's to tare), with status bits (:data:`SENSOR_STATUS_BITS`).

Every frame ends with the same two fields: ``Counter`` (bits 52–55) and ``Checksum`` (byte 7).
For the per-tick frames the counter is the tick modulo 16 (the sample's tick for ``Odometry``,
``AppliedForce`` and ``Sync``, the command's tick for ``ForceCommand``): a gap is a lost frame,
a repeat a stale one, and it ties a sample to the ``Sync`` that opened its tick. The heartbeat's
counter counts heartbeats. The checksum is CRC-8 (SAE J1850) over the identifier's two bytes
(little-endian) and data bytes 0–6, so a frame with a corrupted payload or sent on the wrong id
is rejected (end-to-end protection as in AUTOSAR E2E; the bus's own CRC only covers the wire).

Resolutions are finer than real AGVs need because the paper's estimators assume exact
measurements: velocities at 1 µm/s (25-bit signed fields) and forces at 0.1 mN in ±500 N
(24-bit signed fields) keep the quantisation far below the estimators' tolerances (0.1 mm/s
quantisation alone already stops Step 1 from settling). The velocity range, ±16 m/s, is wider
than any AGV's because the paper's scenario is not an AGV's: its final push drives the contact
points to 6.1 m/s (``heft run simulator/scenarios/paper.toml`` ends at 9.19 s with one axis at
6.09 m/s), and a real-time run may push on a little longer than the lockstep one.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from cantools.database.can import Database, Message, Node, Signal
from cantools.database.conversion import BaseConversion

Profile = Literal["force", "velocity"]
PROFILES: tuple[Profile, ...] = ("force", "velocity")
"""The AGV protocol's profiles (see the module docstring)."""
DBC_PATHS: dict[str, Path] = {
    "force": Path(__file__).with_name("agv.dbc"),
    "velocity": Path(__file__).with_name("agv-velocity.dbc"),
}
"""The generated file of each profile, which the bridge and the plant load."""
DBC_PATH = DBC_PATHS["force"]

MAX_NODE = 32
"""Node ids are 1..MAX_NODE (the team's robot ids)."""

FRAME_LENGTH = 8
COUNTER_START, COUNTER_BITS = 52, 4
CHECKSUM_START = 56

SYNC_ID = 0x080
ODOMETRY_BASE = 0x180
FORCE_COMMAND_BASE = 0x200
APPLIED_FORCE_BASE = 0x280
MOTION_COMMAND_BASE = 0x300
MOTION_FEEDBACK_BASE = 0x380
FORCE_TORQUE_BASE = 0x480
HEARTBEAT_BASE = 0x700

MAX_SPEED = 16.0
"""m/s: the range of each odometry axis (25-bit fields)."""
SPEED_BITS = 25
SPEED_RESOLUTION = 1e-6
"""m/s per bit of odometry."""
MAX_FORCE = 500.0
"""N: the range of each force axis (commanded and applied)."""
FORCE_RESOLUTION = 1e-4
"""N per bit of force."""
FORCE_BITS = 24
MAX_COMMAND_SPEED = 8.0
"""m/s: the range of each axis of a velocity command (24-bit fields at
:data:`SPEED_RESOLUTION`)."""
COMMAND_SPEED_BITS = 24
HEARTBEAT_PERIOD_MS = 100

COMMAND_MODES = {0: "ZERO", 1: "FORCE"}
"""``ForceCommand.Mode``: ZERO holds no force (the bridge's watchdog), FORCE applies Fx, Fy."""
MOTION_MODES = {0: "STOP", 1: "VELOCITY"}
"""``MotionCommand.Mode``: STOP brakes the base to standstill (the bridge's watchdog, a stale
sensor), VELOCITY drives it at Vx, Vy."""
SENSOR_STATUS_BITS = {0: "OVERRANGE", 1: "FAULT"}
"""``ForceTorque.Status``: bit number → condition; a sample with any bit set is not used."""
DRIVER_MODES = {0: "BOOT", 1: "READY", 2: "ACTIVE", 3: "ZERO_FORCE", 4: "FAULT"}
"""``Heartbeat.Mode``: what the AGV driver is doing."""
FAULT_BITS = {
    0: "ESTOP",
    1: "OVERCURRENT",
    2: "MOTOR",
    3: "ODOMETRY",
    4: "COMMAND_TIMEOUT",
    5: "UNDERVOLTAGE",
}
"""``Heartbeat.Faults``: bit number → fault."""


@dataclass(frozen=True)
class _Field:
    name: str
    start: int
    length: int
    signed: bool = False
    scale: float = 1.0
    minimum: float | None = None
    maximum: float | None = None
    unit: str | None = None
    choices: dict[int, str] | None = None
    comment: str | None = None


def _vector(
    prefix: str, what: str, bits: int, scale: float, bound: float, unit: str
) -> list[_Field]:
    """Two signed ``bits``-bit fields, x at bit 0 and y right after it."""
    return [
        _Field(
            f"{prefix}{axis}", start, bits, True, scale, -bound, bound, unit, None, f"{what} {axis}"
        )
        for axis, start in (("x", 0), ("y", bits))
    ]


def _tail(counter: str) -> list[_Field]:
    return [
        _Field("Counter", COUNTER_START, COUNTER_BITS, comment=counter),
        _Field("Checksum", CHECKSUM_START, 8, comment="CRC-8 SAE J1850 of id and bytes 0-6"),
    ]


TICK_COUNTER = "tick modulo 16"


def _signal(field: _Field) -> Signal:
    bits = field.length - 1 if field.signed else field.length
    low = -(2**bits) if field.signed else 0
    high = 2**bits - 1
    return Signal(
        name=field.name,
        start=field.start,
        length=field.length,
        byte_order="little_endian",
        is_signed=field.signed,
        conversion=BaseConversion.factory(scale=field.scale, offset=0, choices=field.choices),
        minimum=field.minimum if field.minimum is not None else low * field.scale,
        maximum=field.maximum if field.maximum is not None else high * field.scale,
        unit=field.unit,
        comment=field.comment,
    )


def _message(
    frame_id: int, name: str, sender: str, fields: list[_Field], cycle_ms: int | None, comment: str
) -> Message:
    return Message(
        frame_id=frame_id,
        name=name,
        length=FRAME_LENGTH,
        signals=[_signal(f) for f in fields],
        senders=[sender],
        cycle_time=cycle_ms,
        comment=comment,
    )


def build(profile: str = "force") -> Database:
    """The AGV protocol's ``profile`` for nodes 1..:data:`MAX_NODE` (see the module
    docstring)."""
    if profile not in PROFILES:
        raise ValueError(f"profile must be one of {', '.join(PROFILES)}, got {profile!r}")
    messages = [
        _message(
            SYNC_ID,
            "Sync",
            "BusMaster",
            [_Field("Tick", 0, 32, comment="the tick this frame opens (modulo 2^32)")]
            + _tail(TICK_COUNTER),
            None,
            "Opens a tick: every driver samples, then sends Odometry and AppliedForce.",
        )
    ]
    nodes = [Node("BusMaster", comment="the plant in tests; a sync master on robots")]
    for n in range(1, MAX_NODE + 1):
        driver, bridge, sensor = f"AGV_{n}", f"Bridge_{n}", f"FTSensor_{n}"
        nodes += [Node(driver), Node(bridge)]
        if profile == "force":
            messages += _force_frames(n, driver, bridge)
        else:
            nodes.append(Node(sensor, comment=f"the force/torque sensor at AGV {n}'s contact"))
            messages += _velocity_frames(n, driver, bridge, sensor)
        messages.append(_heartbeat(n, driver))
    return Database(messages=messages, nodes=nodes, version="1")


def _velocities(what: str, bits: int = SPEED_BITS, bound: float = MAX_SPEED) -> list[_Field]:
    return _vector("V", what, bits, SPEED_RESOLUTION, bound, "m/s")


def _forces(what: str) -> list[_Field]:
    return _vector("F", what, FORCE_BITS, FORCE_RESOLUTION, MAX_FORCE, "N")


def _bits(names: dict[int, str]) -> str:
    return "bit field: " + ", ".join(f"{bit} {name}" for bit, name in names.items())


def _force_frames(n: int, driver: str, bridge: str) -> list[Message]:
    """The force profile's frames of node ``n``."""
    force = _forces("force at the contact point")
    return [
        _message(
            ODOMETRY_BASE + n,
            f"Odometry_{n}",
            driver,
            _velocities("contact point velocity") + _tail(TICK_COUNTER),
            None,
            "The contact point's velocity in the world frame at the tick's Sync.",
        ),
        _message(
            FORCE_COMMAND_BASE + n,
            f"ForceCommand_{n}",
            bridge,
            force
            + [_Field("Mode", 48, 4, choices=COMMAND_MODES, comment="ZERO or FORCE")]
            + _tail("tick modulo 16 of the command"),
            None,
            "The force to apply from the tick on (Mode ZERO: none, the bridge's watchdog).",
        ),
        _message(
            APPLIED_FORCE_BASE + n,
            f"AppliedForce_{n}",
            driver,
            force + _tail(TICK_COUNTER),
            None,
            "The force the driver measured itself applying over the last period.",
        ),
    ]


def _velocity_frames(n: int, driver: str, bridge: str, sensor: str) -> list[Message]:
    """The velocity profile's frames of node ``n``."""
    return [
        _message(
            MOTION_COMMAND_BASE + n,
            f"MotionCommand_{n}",
            bridge,
            _velocities("base velocity command", COMMAND_SPEED_BITS, MAX_COMMAND_SPEED)
            + [_Field("Mode", 48, 4, choices=MOTION_MODES, comment="STOP or VELOCITY")]
            + _tail("tick modulo 16 of the command"),
            None,
            "The base's velocity from the tick on (Mode STOP: brake to standstill).",
        ),
        _message(
            MOTION_FEEDBACK_BASE + n,
            f"MotionFeedback_{n}",
            driver,
            _velocities("measured base velocity") + _tail(TICK_COUNTER),
            None,
            "The base's measured velocity in the world frame at the tick's Sync.",
        ),
        _message(
            FORCE_TORQUE_BASE + n,
            f"ForceTorque_{n}",
            sensor,
            _forces("force measured at the contact (raw, with the sensor's bias)")
            + [_Field("Status", 48, 4, comment=_bits(SENSOR_STATUS_BITS))]
            + _tail(TICK_COUNTER),
            None,
            "The force the sensor at the contact measured at the tick's Sync.",
        ),
    ]


def _heartbeat(n: int, driver: str) -> Message:
    """Node ``n``'s heartbeat (both profiles)."""
    return _message(
        HEARTBEAT_BASE + n,
        f"Heartbeat_{n}",
        driver,
        [
            _Field("Mode", 0, 4, choices=DRIVER_MODES, comment="driver state"),
            _Field("Faults", 8, 8, comment=_bits(FAULT_BITS)),
        ]
        + _tail("heartbeat count modulo 16"),
        HEARTBEAT_PERIOD_MS,
        "The driver's state and faults.",
    )


def main(argv: list[str] | None = None) -> int:
    """``python -m bridge.dbc``: write every profile's DBC (:data:`DBC_PATHS`)."""
    argv = sys.argv[1:] if argv is None else argv
    if argv:
        print("usage: python -m bridge.dbc (writes bridge/agv.dbc and bridge/agv-velocity.dbc)")
        return 2
    for profile, path in DBC_PATHS.items():
        path.write_text(build(profile).as_dbc_string())
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
