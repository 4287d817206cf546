"""The AGV CAN protocol, built as a cantools database and written to ``bridge/agv.dbc``.

The DBC file is what the bridge loads at run time and what ``cantools dump bridge/agv.dbc``,
``cantools decode`` and bus monitors read; this module is where its frames are declared once
(run ``python -m bridge.dbc`` after changing them: a test checks the file is up to date).

Classic CAN, 11-bit identifiers, every frame 8 bytes. Identifiers follow CANopen's function
codes, so a frame's id says what it is and whose it is: ``id = base + node`` with the robot's
node id ``node`` in 1..32 (robot ``i`` is node ``i``), and several robots can share one bus:

========================  ======  ==================  ===========================================
frame                     base    sender              period
========================  ======  ==================  ===========================================
``Sync``                  0x080   bus master (plant)  one per tick (opens the tick)
``Odometry_<n>``          0x180   AGV driver n        one per tick, after the tick's ``Sync``
``ForceCommand_<n>``      0x200   bridge n            one per tick; zero force on the watchdog
``AppliedForce_<n>``      0x280   AGV driver n        one per tick, after the tick's ``Sync``
``Heartbeat_<n>``         0x700   AGV driver n        100 ms
========================  ======  ==================  ===========================================

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

from cantools.database.can import Database, Message, Node, Signal
from cantools.database.conversion import BaseConversion

DBC_PATH = Path(__file__).with_name("agv.dbc")
"""The generated file the bridge and the plant load."""

MAX_NODE = 32
"""Node ids are 1..MAX_NODE (the team's robot ids)."""

FRAME_LENGTH = 8
COUNTER_START, COUNTER_BITS = 52, 4
CHECKSUM_START = 56

SYNC_ID = 0x080
ODOMETRY_BASE = 0x180
FORCE_COMMAND_BASE = 0x200
APPLIED_FORCE_BASE = 0x280
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
HEARTBEAT_PERIOD_MS = 100

COMMAND_MODES = {0: "ZERO", 1: "FORCE"}
"""``ForceCommand.Mode``: ZERO holds no force (the bridge's watchdog), FORCE applies Fx, Fy."""
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


def build() -> Database:
    """The AGV protocol for nodes 1..:data:`MAX_NODE` (see the module docstring)."""
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
        driver, bridge = f"AGV_{n}", f"Bridge_{n}"
        nodes += [Node(driver), Node(bridge)]
        velocity = _vector(
            "V", "contact point velocity", SPEED_BITS, SPEED_RESOLUTION, MAX_SPEED, "m/s"
        )
        force = _vector(
            "F", "force at the contact point", FORCE_BITS, FORCE_RESOLUTION, MAX_FORCE, "N"
        )
        messages += [
            _message(
                ODOMETRY_BASE + n,
                f"Odometry_{n}",
                driver,
                velocity + _tail(TICK_COUNTER),
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
            _message(
                HEARTBEAT_BASE + n,
                f"Heartbeat_{n}",
                driver,
                [
                    _Field("Mode", 0, 4, choices=DRIVER_MODES, comment="driver state"),
                    _Field(
                        "Faults",
                        8,
                        8,
                        comment="bit field: "
                        + ", ".join(f"{bit} {name}" for bit, name in FAULT_BITS.items()),
                    ),
                ]
                + _tail("heartbeat count modulo 16"),
                HEARTBEAT_PERIOD_MS,
                "The driver's state and faults.",
            ),
        ]
    return Database(messages=messages, nodes=nodes, version="1")


def main(argv: list[str] | None = None) -> int:
    """``python -m bridge.dbc [FILE]``: write the DBC (to ``bridge/agv.dbc`` by default)."""
    argv = sys.argv[1:] if argv is None else argv
    path = Path(argv[0]) if argv else DBC_PATH
    path.write_text(build().as_dbc_string())
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
