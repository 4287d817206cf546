"""Typed AGV frames ↔ python-can messages, through the DBC file (no hand-packed bytes).

:class:`AgvCodec` loads ``bridge/agv.dbc`` (see :mod:`bridge.dbc` for the frames) and turns a
:class:`Sync`, :class:`Odometry`, :class:`ForceCommand`, :class:`AppliedForce` or
:class:`Heartbeat` into a ``can.Message`` and back. Decoding trusts nothing: a frame is
rejected with a :class:`FrameError` whose ``reason`` (one of :data:`REASONS`) is what the
bridge counts, unless it is a data frame with a standard id of the protocol, 8 bytes, a
matching checksum and every signal within its DBC range.

What the codec does not judge is sequence (counters, ticks, watchdogs): that needs state, and
lives in :mod:`bridge.bridge` and :mod:`bridge.timing`.

Values cross the bus quantised to the DBC's resolution. :meth:`AgvCodec.quantize_velocity` and
:meth:`AgvCodec.quantize_force` give exactly what a receiver decodes, so an in-process run can
reproduce a run over CAN bit for bit.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from pathlib import Path

import can
import cantools
from crc import Calculator, Crc8

from bridge.dbc import (
    APPLIED_FORCE_BASE,
    DBC_PATHS,
    FORCE_COMMAND_BASE,
    FORCE_TORQUE_BASE,
    FRAME_LENGTH,
    HEARTBEAT_BASE,
    MAX_COMMAND_SPEED,
    MAX_FORCE,
    MAX_NODE,
    MOTION_COMMAND_BASE,
    MOTION_FEEDBACK_BASE,
    ODOMETRY_BASE,
    PROFILES,
    SYNC_ID,
)

Vec2 = tuple[float, float]

COUNTER_MODULO = 16
"""Every frame's ``Counter`` counts modulo 16 (4 bits)."""

REASONS = (
    "error frame",
    "remote frame",
    "extended id",
    "unknown id",
    "wrong length",
    "checksum",
    "out of range",
    "wrong profile",
)
"""Why :meth:`AgvCodec.decode` rejects a frame (the bridge's counter keys)."""


class FrameError(ValueError):
    """A frame that is not a valid protocol frame; ``reason`` is one of :data:`REASONS`."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason


@dataclass(frozen=True, slots=True)
class Sync:
    """The bus master opens ``tick`` (``counter = tick % 16``)."""

    tick: int

    @property
    def counter(self) -> int:
        return self.tick % COUNTER_MODULO


@dataclass(frozen=True, slots=True)
class Odometry:
    """AGV ``node``'s contact-point velocity (m/s, world frame) sampled at the tick whose
    counter is ``counter``."""

    node: int
    counter: int
    velocity: Vec2


@dataclass(frozen=True, slots=True)
class ForceCommand:
    """The force (N, world frame) AGV ``node`` applies from the tick whose counter is
    ``counter``; ``apply`` false is the watchdog's ZERO mode (no force, whatever ``force``
    says)."""

    node: int
    counter: int
    force: Vec2
    apply: bool = True


@dataclass(frozen=True, slots=True)
class AppliedForce:
    """The force (N, world frame) AGV ``node`` measured itself applying over the period that
    ended at the tick whose counter is ``counter``."""

    node: int
    counter: int
    force: Vec2


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """AGV ``node``'s driver state: ``mode`` (see :data:`bridge.dbc.DRIVER_MODES`) and fault
    bits (:data:`bridge.dbc.FAULT_BITS`); ``counter`` counts heartbeats."""

    node: int
    counter: int
    mode: int
    faults: int = 0


@dataclass(frozen=True, slots=True)
class MotionCommand:
    """The velocity (m/s, world frame) AGV ``node``'s base drives at from the tick whose
    counter is ``counter`` (velocity profile); ``drive`` false is STOP (brake to standstill,
    whatever ``velocity`` says)."""

    node: int
    counter: int
    velocity: Vec2
    drive: bool = True


@dataclass(frozen=True, slots=True)
class MotionFeedback:
    """AGV ``node``'s measured base velocity (m/s, world frame) at the tick whose counter is
    ``counter`` (velocity profile)."""

    node: int
    counter: int
    velocity: Vec2


@dataclass(frozen=True, slots=True)
class ForceTorque:
    """The raw force (N, world frame) the sensor at AGV ``node``'s contact measured at the tick
    whose counter is ``counter`` (velocity profile), and its ``status`` bits
    (:data:`bridge.dbc.SENSOR_STATUS_BITS`)."""

    node: int
    counter: int
    force: Vec2
    status: int = 0


Frame = (
    Sync
    | Odometry
    | ForceCommand
    | AppliedForce
    | MotionCommand
    | MotionFeedback
    | ForceTorque
    | Heartbeat
)

_BASES = {
    ODOMETRY_BASE: Odometry,
    FORCE_COMMAND_BASE: ForceCommand,
    APPLIED_FORCE_BASE: AppliedForce,
    MOTION_COMMAND_BASE: MotionCommand,
    MOTION_FEEDBACK_BASE: MotionFeedback,
    FORCE_TORQUE_BASE: ForceTorque,
    HEARTBEAT_BASE: Heartbeat,
}
_BASE_OF = {kind: base for base, kind in _BASES.items()}
_CALCULATORS = threading.local()
"""One CRC calculator per thread: a ``crc.Calculator`` keeps its register between calls, so
two threads sharing one corrupt each other's checksums."""


def _clamp(v: Vec2, bound: float) -> tuple[Vec2, bool]:
    x = min(max(v[0], -bound), bound)
    y = min(max(v[1], -bound), bound)
    return (x, y), (x, y) != (v[0], v[1])


def clamp_force(force: Vec2) -> tuple[Vec2, bool]:
    """``force`` with each axis clamped to ±:data:`~bridge.dbc.MAX_FORCE`, and whether it had
    to be (the bridge counts clamps). Non-finite values are the caller's to reject."""
    return _clamp(force, MAX_FORCE)


def clamp_command_velocity(velocity: Vec2) -> tuple[Vec2, bool]:
    """``velocity`` with each axis clamped to ±:data:`~bridge.dbc.MAX_COMMAND_SPEED` (a
    ``MotionCommand``'s range), and whether it had to be."""
    return _clamp(velocity, MAX_COMMAND_SPEED)


def checksum(frame_id: int, data: bytes) -> int:
    """CRC-8 (SAE J1850) of the id's two bytes (little-endian) and data bytes 0–6."""
    calculator = getattr(_CALCULATORS, "crc8", None)
    if calculator is None:
        calculator = _CALCULATORS.crc8 = Calculator(Crc8.SAEJ1850, optimized=True)
    return calculator.checksum(frame_id.to_bytes(2, "little") + bytes(data[:7]))


class AgvCodec:
    """Encodes the frames of both profiles; decodes those of ``profile`` (``force``: the
    frames of ``bridge/agv.dbc``, ``velocity``: of ``bridge/agv-velocity.dbc``) and refuses
    the other's as ``wrong profile``."""

    def __init__(self, profile: str = "force", paths: dict[str, Path] | None = None):
        if profile not in PROFILES:
            raise ValueError(f"profile must be one of {', '.join(PROFILES)}, got {profile!r}")
        paths = paths or DBC_PATHS
        self.profile = profile
        self.database = cantools.database.load_file(str(paths[profile]), strict=True)
        self._messages = {}
        for other in PROFILES:
            database = cantools.database.load_file(str(paths[other]), strict=True)
            self._messages.update({m.frame_id: m for m in database.messages})
        self._own = frozenset(m.frame_id for m in self.database.messages)

    # ------------------------------------------------------------------ encoding
    def encode(self, frame: Frame, timestamp: float = 0.0) -> can.Message:
        """A ``can.Message`` for ``frame``; ``ValueError`` if a value is not finite, outside
        its range or not one of its signal's choices (clamp forces first with
        :func:`clamp_force`)."""
        frame_id, values = self._values(frame)
        message = self._messages[frame_id]
        for name, value in values.items():
            if not math.isfinite(value):
                raise ValueError(f"{message.name}: {name} is {value!r}, not a finite number")
            choices = message.get_signal_by_name(name).choices
            if choices is not None and value not in choices:
                raise ValueError(
                    f"{message.name}: {name} is {value!r}, not one of {sorted(choices)}"
                )
        values["Checksum"] = 0
        try:
            data = message.encode(values, scaling=True, strict=True)
            values["Checksum"] = checksum(frame_id, data)
            data = message.encode(values, scaling=True, strict=True)
        except cantools.database.EncodeError as err:
            raise ValueError(f"{message.name}: {err}") from None
        return can.Message(
            arbitration_id=frame_id,
            is_extended_id=False,
            dlc=FRAME_LENGTH,
            data=data,
            timestamp=timestamp,
        )

    @staticmethod
    def _values(frame: Frame) -> tuple[int, dict[str, float]]:
        if isinstance(frame, Sync):
            return SYNC_ID, {"Tick": frame.tick % 2**32, "Counter": frame.counter}
        node = frame.node
        if not 1 <= node <= MAX_NODE:
            raise ValueError(f"node id must be in 1..{MAX_NODE}, got {node!r}")
        frame_id = _BASE_OF[type(frame)] + node
        if isinstance(frame, Odometry):
            vx, vy = frame.velocity
            return frame_id, {"Vx": vx, "Vy": vy, "Counter": frame.counter}
        if isinstance(frame, ForceCommand):
            fx, fy = frame.force if frame.apply else (0.0, 0.0)
            mode = 1 if frame.apply else 0
            return frame_id, {"Fx": fx, "Fy": fy, "Mode": mode, "Counter": frame.counter}
        if isinstance(frame, AppliedForce):
            fx, fy = frame.force
            return frame_id, {"Fx": fx, "Fy": fy, "Counter": frame.counter}
        if isinstance(frame, MotionCommand):
            vx, vy = frame.velocity if frame.drive else (0.0, 0.0)
            mode = 1 if frame.drive else 0
            return frame_id, {"Vx": vx, "Vy": vy, "Mode": mode, "Counter": frame.counter}
        if isinstance(frame, MotionFeedback):
            vx, vy = frame.velocity
            return frame_id, {"Vx": vx, "Vy": vy, "Counter": frame.counter}
        if isinstance(frame, ForceTorque):
            fx, fy = frame.force
            values = {"Fx": fx, "Fy": fy, "Status": frame.status, "Counter": frame.counter}
            return frame_id, values
        return frame_id, {"Mode": frame.mode, "Faults": frame.faults, "Counter": frame.counter}

    # ------------------------------------------------------------------ decoding
    def decode(self, msg: can.Message) -> Frame:
        """The frame ``msg`` carries; :class:`FrameError` if it is not a valid one."""
        if msg.is_error_frame:
            raise FrameError("error frame", f"error frame (id 0x{msg.arbitration_id:x})")
        if msg.is_remote_frame:
            raise FrameError("remote frame", f"remote frame on id 0x{msg.arbitration_id:x}")
        if msg.is_extended_id:
            raise FrameError("extended id", f"extended id 0x{msg.arbitration_id:x}")
        frame_id = msg.arbitration_id
        message = self._messages.get(frame_id)
        if message is None:
            raise FrameError("unknown id", f"id 0x{frame_id:x}")
        if frame_id not in self._own:
            raise FrameError("wrong profile", f"{message.name} is not a {self.profile} frame")
        data = bytes(msg.data)
        if msg.dlc != FRAME_LENGTH or len(data) != FRAME_LENGTH:
            raise FrameError("wrong length", f"{message.name}: {len(data)} bytes, expected 8")
        if data[7] != checksum(frame_id, data):
            raise FrameError("checksum", f"{message.name}: checksum 0x{data[7]:02x}")
        values = message.decode(data, decode_choices=False, scaling=True)
        for signal in message.signals:
            value = values[signal.name]
            low, high = signal.minimum, signal.maximum
            if (
                not math.isfinite(value)
                or (low is not None and value < low)
                or (high is not None and value > high)
            ):
                raise FrameError("out of range", f"{message.name}.{signal.name} = {value!r}")
            if signal.choices is not None and int(value) not in signal.choices:
                raise FrameError("out of range", f"{message.name}.{signal.name} = {value!r}")
        counter = int(values["Counter"])
        if frame_id == SYNC_ID:
            tick = int(values["Tick"])
            if tick % COUNTER_MODULO != counter:
                raise FrameError("out of range", f"Sync: counter {counter} for tick {tick}")
            return Sync(tick)
        base, node = frame_id & ~0x7F, frame_id & 0x7F
        kind = _BASES[base]
        if kind is Odometry:
            return Odometry(node, counter, (values["Vx"], values["Vy"]))
        if kind is ForceCommand:
            apply = int(values["Mode"]) == 1
            force = (values["Fx"], values["Fy"]) if apply else (0.0, 0.0)
            return ForceCommand(node, counter, force, apply)
        if kind is AppliedForce:
            return AppliedForce(node, counter, (values["Fx"], values["Fy"]))
        if kind is MotionCommand:
            drive = int(values["Mode"]) == 1
            velocity = (values["Vx"], values["Vy"]) if drive else (0.0, 0.0)
            return MotionCommand(node, counter, velocity, drive)
        if kind is MotionFeedback:
            return MotionFeedback(node, counter, (values["Vx"], values["Vy"]))
        if kind is ForceTorque:
            force = (values["Fx"], values["Fy"])
            return ForceTorque(node, counter, force, int(values["Status"]))
        return Heartbeat(node, counter, int(values["Mode"]), int(values["Faults"]))

    # ------------------------------------------------------------------ quantisation
    def quantize_velocity(self, velocity: Vec2) -> Vec2:
        """``velocity`` as a receiver decodes it from the profile's odometry frame
        (:class:`Odometry` or :class:`MotionFeedback`, the same resolution)."""
        kind = Odometry if self.profile == "force" else MotionFeedback
        return self.decode(self.encode(kind(1, 0, velocity))).velocity

    def quantize_force(self, force: Vec2) -> Vec2:
        """``force`` (within range) as a receiver decodes it from the profile's measured-force
        frame (:class:`AppliedForce` or :class:`ForceTorque`, the same resolution)."""
        if self.profile == "force":
            return self.decode(self.encode(AppliedForce(1, 0, force))).force
        return self.decode(self.encode(ForceTorque(1, 0, force))).force

    def quantize_command_velocity(self, velocity: Vec2) -> Vec2:
        """A velocity command (within ±:data:`~bridge.dbc.MAX_COMMAND_SPEED`) as the driver
        decodes it from a :class:`MotionCommand` (velocity profile only)."""
        return self.decode(self.encode(MotionCommand(1, 0, velocity))).velocity
