"""Light modules stay light: a fresh interpreter that imports the protocol and the Zenoh session,
or builds the ``heft`` parser, loads none of the plant's, the estimators' or the plots'
libraries. (The rest of the layout is tests/unit/test_layout.py.)"""

from __future__ import annotations

import json
import subprocess
import sys

from tests.helpers.paths import ROOT

HEAVY = ("pymunk", "matplotlib", "numpy")


# ------------------------------------------------------------------------------ import weight
def modules_loaded_by(code: str) -> list[str]:
    """The modules a fresh interpreter has loaded after running ``code``."""
    ran = subprocess.run(
        [sys.executable, "-c", f"{code}\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert ran.returncode == 0, ran.stderr
    return json.loads(ran.stdout.splitlines()[-1])


def test_the_protocol_and_the_zenoh_session_load_nothing_heavy() -> None:
    """A bridge or a display reads the team's messages without the plant, the estimator's
    numerics or a plotting library."""
    loaded = modules_loaded_by("import agent.platform.protocol, agent.platform.zenoh_session")
    assert "agent.platform.protocol" in loaded and "agent.platform.zenoh_session" in loaded
    heavy = [name for name in loaded if name.split(".")[0] in (*HEAVY, "simulator")]
    assert heavy == []


def test_building_the_heft_parser_loads_nothing_heavy() -> None:
    """``heft agent`` on a robot does not pay for the simulator's libraries."""
    loaded = modules_loaded_by("from agent.platform.heft import build_parser\nbuild_parser()")
    assert "simulator.cli" in loaded and "agent.cli" in loaded
    assert [name for name in loaded if name.split(".")[0] in HEAVY] == []
