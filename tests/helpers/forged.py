"""Adversarial but well-encoded messages on every key of a team: values out of their domains,
robots out of the team or on another robot's key, ticks far from the receiver's clock. Every
one must be rejected."""

from __future__ import annotations

import random
import struct

from agent.platform.protocol import (
    Command,
    Control,
    Estimates,
    Keys,
    Measurement,
    Phase,
    Share,
    Status,
    encode,
)

TEAM = "fuzz"
KEYS = Keys(TEAM)


def forged_messages(rng: random.Random, n: int, tick: int) -> list[tuple[str, bytes]]:
    """One adversarial but well-encoded message for each kind of key of a team of ``n``:
    values out of their domains, robots out of the team or on another robot's key, ticks far
    from the receiver's clock. Every one must be rejected."""
    i = rng.randint(1, n)
    other = i % n + 1
    far = tick + rng.randint(1000, 2**40 - tick)
    huge = rng.choice([1e6, -1e9, 3e300])
    out = [
        (KEYS.velocity(i), encode(Measurement(i, 2**62, 0.0, (0.0, 0.0), (0.0, 0.0)))),
        (KEYS.velocity(i), encode(Measurement(other, tick, 0.0, (0.1, 0.0), (0.0, 0.0)))),
        (KEYS.velocity(i), encode(Measurement(i, far, 0.0, (0.0, 0.0), (0.0, 0.0)))),
        (KEYS.velocity(i), encode(Measurement(i, tick, 0.0, (huge, 0.0), (0.0, 0.0)))),
        (KEYS.force(i), encode(Command(i, 2**62, (10.0, 0.0)))),
        (KEYS.force(i), encode(Command(i, far, (10.0, 0.0)))),
        (KEYS.force(i), encode(Command(other, tick, (10.0, 0.0)))),
        (KEYS.force(i), encode(Command(i, tick, (huge, 0.0)))),
        (KEYS.share(i), share_with_phase(Share(i, tick + 20, (0.0, 0.0), 1), 200)),
        (KEYS.share(i), encode(Share(i, tick, (huge, 0.0), 1))),
        (KEYS.share(i), encode(Share(i, tick, (0.0, 0.0), 0))),
        (KEYS.share(i), encode(Share(i, tick, (0.0, 0.0), 1, instant=tick))),
        (KEYS.share(i), encode(Share(n + 1 + rng.randint(0, 9), tick, (0.0, 0.0), 1))),
        (KEYS.control(), encode(Control("launch"))),
        (KEYS.estimate(i), encode(Estimates(n + 5, tick, Phase.DONE))),
        (KEYS.estimate(i), encode(Estimates(i, far, Phase.DONE))),
        (KEYS.status(i), encode(Status(0, tick, Phase.HALTED))),
        (KEYS.truth(), encode(Control())),
    ]
    return out


def share_with_phase(share: Share, phase: int) -> bytes:
    """``share`` encoded, its phase byte then set to ``phase`` (which may name no phase)."""
    payload = bytearray(encode(share))
    at = 3 + struct.calcsize("<Hq2dHq")  # the phase byte: after sender ... instant
    assert payload[at] == share.barrier.phase  # (fails if the layout moves it)
    payload[at] = phase
    return bytes(payload)
