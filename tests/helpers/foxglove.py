"""Foxglove's readers in the tests: its own JSON-schema parser (from the npm package
``@foxglove/studio-base``, installed by ``make``), run in node over a recording's schemas
(tests/helpers/foxglove_parser.cjs), and its protobuf messages read back with the schema each
channel carries (a FileDescriptorSet, as the SDK's ``get_schema()`` gives it)."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

NODE = shutil.which("node")
"""The node executable, None if it is not installed (the parser's tests are then skipped)."""
HARNESS = Path(__file__).with_name("foxglove_parser.cjs")


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
