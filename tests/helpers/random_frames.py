"""Random CAN frames that the AGV protocol must refuse, each with the reason it must give.

Ids are drawn mostly from the codec's profile's own (every kind, any node) so that the checks past
the id are reached too (length, checksum, ranges), then from anywhere in the 11-bit and
29-bit spaces; lengths 0 to 8; payloads random; some error and remote frames. A drawn frame
that happens to be valid (a checksum matched by chance) is drawn again, so the expected
counts are exact.
"""

from __future__ import annotations

import random
from collections import Counter

import can

from bridge.codec import AgvCodec, FrameError
from bridge.dbc import (
    APPLIED_FORCE_BASE,
    FORCE_COMMAND_BASE,
    FORCE_TORQUE_BASE,
    HEARTBEAT_BASE,
    MOTION_COMMAND_BASE,
    MOTION_FEEDBACK_BASE,
    ODOMETRY_BASE,
    SYNC_ID,
)

BASES = {
    "force": (SYNC_ID, ODOMETRY_BASE, FORCE_COMMAND_BASE, APPLIED_FORCE_BASE, HEARTBEAT_BASE),
    "velocity": (
        SYNC_ID,
        MOTION_FEEDBACK_BASE,
        MOTION_COMMAND_BASE,
        FORCE_TORQUE_BASE,
        HEARTBEAT_BASE,
    ),
}
"""Each profile's frames' ids (``SYNC_ID``) and bases (the others, plus a node)."""


def _draw(rng: random.Random, bases: tuple[int, ...]) -> can.Message:
    roll = rng.random()
    dlc = 8 if rng.random() < 0.6 else rng.randint(0, 8)
    data = bytes(rng.getrandbits(8) for _ in range(dlc))
    if roll < 0.05:
        return can.Message(
            arbitration_id=rng.getrandbits(29),
            is_error_frame=True,
            dlc=8,
            data=bytes(8),
            is_extended_id=True,
        )
    if roll < 0.08:
        return can.Message(
            arbitration_id=rng.getrandbits(11), is_remote_frame=True, dlc=dlc, is_extended_id=False
        )
    if roll < 0.15:
        return can.Message(arbitration_id=rng.getrandbits(29), data=data, is_extended_id=True)
    if roll < 0.3:
        return can.Message(arbitration_id=rng.getrandbits(11), data=data, is_extended_id=False)
    base = rng.choice(bases)
    frame_id = base if base == SYNC_ID else base + rng.randint(1, 127)
    return can.Message(arbitration_id=frame_id, data=data, is_extended_id=False)


def random_frames(count: int, seed: int, codec: AgvCodec) -> tuple[list[can.Message], Counter]:
    """``count`` frames ``codec`` refuses, and how many it refuses for each reason (the
    other profile's frames among them, as ``wrong profile``: random 11-bit ids hit them)."""
    rng = random.Random(seed)
    frames: list[can.Message] = []
    reasons: Counter[str] = Counter()
    while len(frames) < count:
        message = _draw(rng, BASES[codec.profile])
        try:
            codec.decode(message)
        except FrameError as err:
            frames.append(message)
            reasons[err.reason] += 1
    return frames, reasons
