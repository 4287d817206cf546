"""Foxglove's readers in the tests: its own JSON-schema parser (from the npm package
``@foxglove/studio-base``, installed by ``make``), run in node over a recording's schemas
(tests/helpers/foxglove_parser.cjs), and its protobuf messages read back with the schema each
channel carries (a FileDescriptorSet, as the SDK's ``get_schema()`` gives it), their poses
taken to the world frame."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from agent.platform.geometry import rotate

NODE = shutil.which("node")
"""The node executable, None if it is not installed (the parser's tests are then skipped)."""
HARNESS = Path(__file__).with_name("foxglove_parser.cjs")
TOLERANCE = 1e-9
"""How far a point drawn may be from where the messages put it (m, rad): rounding only."""


def foxglove_parse(schemas: dict[str, dict]) -> dict[str, dict]:
    """Each of ``schemas`` (by name) as Foxglove's parser takes it: ``{"ok": True,
    "datatypes": {type: [field, ...]}}`` (the message definitions Foxglove's panels use) or
    ``{"ok": False, "error": why}``."""
    if NODE is None:
        raise RuntimeError("node is not installed")
    done = subprocess.run(
        [NODE, str(HARNESS)],
        input=json.dumps(schemas),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    if done.returncode != 0:
        raise RuntimeError(f"Foxglove's parser did not run (run `make`): {done.stderr.strip()}")
    return json.loads(done.stdout)["results"]


def decoder(schema_name: str, data: bytes):
    """The protobuf message class of ``schema_name`` (``foxglove.SceneUpdate``) built from
    its FileDescriptorSet ``data``."""
    pool = descriptor_pool.DescriptorPool()
    for file in descriptor_pb2.FileDescriptorSet.FromString(data).file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))


def turn(q) -> float:
    """The turn about ``z`` of a quaternion that is one (a decoded ``foxglove.Quaternion``)."""
    assert abs(q.x) < TOLERANCE and abs(q.y) < TOLERANCE
    return 2.0 * math.atan2(q.z, q.w)


def in_world(frame, pose, x: float = 0.0, y: float = 0.0) -> tuple[float, float]:
    """Point ``(x, y)`` of ``pose`` (a decoded ``foxglove.Pose`` in the load frame) in the
    world frame, through ``frame`` (a decoded ``foxglove.FrameTransform`` world → load)."""
    local = rotate((x, y), turn(pose.orientation))
    local = (local[0] + pose.position.x, local[1] + pose.position.y)
    turned = rotate(local, turn(frame.rotation))
    return (turned[0] + frame.translation.x, turned[1] + frame.translation.y)


def close(a, b, tol: float = TOLERANCE) -> bool:
    """Whether points ``a`` and ``b`` agree to ``tol`` in every coordinate."""
    return all(abs(p - q) <= tol for p, q in zip(a, b, strict=True))


def check_recording(path: str | Path) -> list[dict]:
    """Each channel of the MCAP recording at ``path`` as Foxglove reads it: its topic, schema,
    encoding, whether Foxglove takes the schema (JSON schemas through its own parser,
    protobuf through the FileDescriptorSet the channel carries), and how many of its messages
    decode (JSON objects; protobuf messages of the schema)."""
    from mcap.reader import make_reader

    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        rows = {}
        for channel_id, channel in sorted(summary.channels.items()):
            schema = summary.schemas[channel.schema_id]
            rows[channel_id] = {
                "topic": channel.topic,
                "schema": schema.name,
                "encoding": schema.encoding,
                "messages": 0,
                "decoded": 0,
                "data": schema.data,
            }
        json_schemas = {
            row["schema"]: json.loads(row["data"])
            for row in rows.values()
            if row["encoding"] == "jsonschema"
        }
        parsed = foxglove_parse(json_schemas) if json_schemas else {}
        classes = {}
        for row in rows.values():
            if row["encoding"] == "jsonschema":
                row["schema_ok"] = parsed[row["schema"]]["ok"]
            else:
                try:
                    classes[row["schema"]] = decoder(row["schema"], row["data"])
                    row["schema_ok"] = True
                except Exception:  # noqa: BLE001 - a schema protobuf cannot read
                    row["schema_ok"] = False
        for _, channel, message in reader.iter_messages():
            row = rows[channel.id]
            row["messages"] += 1
            if not row["schema_ok"]:
                continue
            try:
                if row["encoding"] == "jsonschema":
                    ok = isinstance(json.loads(message.data), dict)
                else:
                    classes[row["schema"]].FromString(message.data)
                    ok = True
            except Exception:  # noqa: BLE001 - a message that does not decode
                ok = False
            row["decoded"] += ok
    return [{k: v for k, v in row.items() if k != "data"} for row in rows.values()]


def main(argv: list[str] | None = None) -> int:
    """``python -m tests.helpers.foxglove FILE...``: each recording's topics as Foxglove reads
    them, a line per topic; exit status 1 if any schema or message does not decode."""
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m tests.helpers.foxglove",
        description="Each topic of MCAP recordings as Foxglove reads it (run `make` first).",
    )
    parser.add_argument("files", nargs="+", metavar="FILE")
    args = parser.parse_args(argv)
    failed = False
    for name in args.files:
        rows = check_recording(name)
        print(f"{name}: {len(rows)} topics")
        for row in rows:
            verdict = "ok" if row["schema_ok"] else "SCHEMA REFUSED"
            print(
                f"  {row['topic']:<36} {row['schema']:<24} {verdict:<14}"
                f" {row['decoded']:>6} / {row['messages']:<6} decoded"
            )
            failed |= not row["schema_ok"] or row["decoded"] != row["messages"]
        topics_ok = sum(r["schema_ok"] and r["decoded"] == r["messages"] for r in rows)
        total = sum(r["messages"] for r in rows)
        decoded = sum(r["decoded"] for r in rows)
        print(f"  {topics_ok} of {len(rows)} topics decode; {decoded} of {total} messages")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
