"""A misbehaving robot for the multi-host tests: ``python -m tests.multihost.forger``.

It connects with a robot's own certificate (authenticated, so the router lets it publish on
that robot's keys) and sends ``--count`` malformed or adversarial payloads on each of the
robot's keys, ``--rate`` a second on each, and tries the keys of others too (which the
router's access control drops).
Every payload it sends on an allowed key is one that its receivers must reject: bytes that
are no message, messages of another kind, and well-encoded messages whose fields are out of
their domains or name another robot. It prints one JSON line: how many it sent, by key.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import struct
import sys
import time

from agent.platform.protocol import (
    WIRE_VERSION,
    Barrier,
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
from agent.platform.zenoh_session import ZenohSettings, open_session, tick_publisher

FAR = 2**40 - 1


def _noise(rng: random.Random) -> bytes:
    """Bytes that are no message: random, or a valid header with garbage after it."""
    body = rng.randbytes(rng.randint(0, 120))
    if rng.random() < 0.5:
        return bytes([0x48, WIRE_VERSION, rng.randint(0, 255)]) + body
    return body


def _adversarial(rng: random.Random, topic: str, robot: int, n: int) -> bytes:
    """A payload the receivers of ``topic`` (robot ``robot``'s) must reject."""
    other = robot % n + 1
    huge = rng.choice([1e6, -1e9, 3e300])
    choices = {
        "velocity": [
            Measurement(robot, FAR, 0.0, (0.0, 0.0), (0.0, 0.0)),
            Measurement(other, 10, 0.1, (0.1, 0.0), (0.0, 0.0)),
            Measurement(robot, 10, 0.1, (huge, 0.0), (0.0, 0.0)),
            Command(robot, 10, (1.0, 0.0)),
        ],
        "force": [
            Command(robot, FAR, (10.0, 0.0)),
            Command(other, 10, (1.0, 0.0)),
            Command(robot, 10, (huge, 0.0)),
            Measurement(robot, 10, 0.1, (0.0, 0.0), (0.0, 0.0)),
        ],
        "share": [
            Share(robot, 10, (huge, 0.0), 1),
            Share(robot, 10, (0.0, 0.0), 0),
            Share(robot, 10, (0.0, 0.0), 1, instant=10),
            Share(n + 7, 10, (0.0, 0.0), 1),
            Share(robot, 10, (0.0, 0.0), 1, barrier=Barrier(rejoins=60000)),
        ],
        "estimate": [
            Estimates(n + 5, 10, Phase.DONE),
            Estimates(robot, FAR, Phase.DONE),
            Status(robot, 10, Phase.DONE),
        ],
        "status": [Status(0, 10, Phase.HALTED), Status(robot, FAR, Phase.HALTED)],
        "bridge": [Control("stop"), Status(robot, 10, Phase.DONE)],
    }
    if rng.random() < 0.3:
        return _noise(rng)
    payload = encode(rng.choice(choices[topic]))
    if rng.random() < 0.2:  # cut short
        return payload[: rng.randint(0, len(payload) - 1)]
    return payload


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--team", required=True)
    parser.add_argument("--robot", type=int, required=True)
    parser.add_argument("--n", type=int, default=4)
    parser.add_argument("--count", type=int, default=10_000)
    parser.add_argument("--rate", type=float, default=1000.0, help="payloads a second, a key")
    parser.add_argument("--connect", required=True)
    parser.add_argument("--tls", nargs=3, metavar=("CA", "CERT", "KEY"), required=True)
    args = parser.parse_args()
    os.nice(10)  # a misbehaving robot's computer, not a faster one: the team's share of the CPU
    keys = Keys(args.team)
    robot, other = args.robot, args.robot % args.n + 1
    ca, cert, key = args.tls
    settings = ZenohSettings(
        mode="client", connect=(args.connect,), root_ca=ca, certificate=cert, private_key=key
    )
    rng = random.Random(robot)
    allowed = ["velocity", "force", "share", "estimate", "status", "bridge"]
    sent: dict[str, int] = {}
    with open_session(settings) as session:
        publishers = {t: tick_publisher(session, f"{keys.root}/robot/{robot}/{t}") for t in allowed}
        # Others' keys: the router drops these (access control), so nobody counts them.
        denied = {
            keys.force(other): encode(Command(other, 10, (10.0, 0.0))),
            keys.share(other): encode(Share(other, 10, (0.0, 0.0), 1)),
            keys.control(): encode(Control("stop")),
            keys.truth(): struct.pack("<d", 1.0),
        }
        started = time.monotonic()
        for i in range(args.count):
            ahead = started + i / args.rate - time.monotonic()
            if ahead > 0:
                time.sleep(ahead)
            for topic, publisher in publishers.items():
                publisher.put(_adversarial(rng, topic, robot, args.n))
            if i % 100 == 0:
                for k, payload in denied.items():
                    session.put(k, payload)
                    sent[k] = sent.get(k, 0) + 1
        for topic in allowed:
            sent[keys.root + f"/robot/{robot}/{topic}"] = args.count
    print(json.dumps(sent), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
