"""The hardware-in-the-loop tests' fixture: real vcan interfaces."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

VCAN_HELP = (
    "no vcan here: run `make hil` (heft vcan -- pytest tests/hil); to enable: sudo modprobe vcan"
    " (or deploy/vcan-setup.sh), or apt-get install user-mode-linux kmod"
)


@pytest.fixture(scope="session")
def vcan() -> None:
    """For hardware-in-the-loop tests: vcan1... exist (inside ``heft vcan``, or a kernel that
    has them); otherwise a skip saying how to get them, or a failure where CI requires them
    (``HEFT_REQUIRE_VCAN=1``)."""
    if os.environ.get("HEFT_VCAN") == "1" or Path("/sys/class/net/vcan1").exists():
        return
    if os.environ.get("HEFT_REQUIRE_VCAN") == "1":
        pytest.fail(f"vcan unavailable but HEFT_REQUIRE_VCAN=1: {VCAN_HELP}")
    pytest.skip(VCAN_HELP)
