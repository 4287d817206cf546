"""The repository's root, the paper's scenario file (and the paper's scenario at half pace)
and the tests' recorded fixtures."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from simulator.scenario import Scenario, load_scenario

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "simulator" / "scenarios" / "paper.toml"
FIXTURES = ROOT / "tests" / "fixtures"


def paper_at_half_pace() -> Scenario:
    """The paper's scenario on the wall clock at half of real time (``run.real_time_factor``
    0.5, 20 ms a tick), for the real-time tests of the paper's estimators: fewer commands come
    late, and their Step 5 can wait long for a second of commands all on time
    (docs/estimator.md; on a fresh clone, at full pace, one forged-messages run's load travelled
    5.5 m, off its floor)."""
    scenario = load_scenario(PAPER)
    return dataclasses.replace(
        scenario, run=dataclasses.replace(scenario.run, real_time_factor=0.5)
    )
