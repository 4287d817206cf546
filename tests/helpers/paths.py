"""The repository's root, the paper's scenario file and the tests' recorded fixtures."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "simulator" / "scenarios" / "paper.toml"
FIXTURES = ROOT / "tests" / "fixtures"
