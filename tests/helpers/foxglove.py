"""Foxglove's own JSON-schema parser (from the npm package ``@foxglove/studio-base``, installed
by ``make``), run in node over a recording's schemas (tests/helpers/foxglove_parser.cjs)."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

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
