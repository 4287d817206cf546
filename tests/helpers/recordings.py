"""A run made in one process, written as the recording of a run over Zenoh would be."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from agent.platform.protocol import Command, Keys
from dashboard.recorder import Recorder

if TYPE_CHECKING:
    from simulator.inprocess import RunOutcome
    from simulator.scenario import Scenario


def record_run(path: Path, scenario: Scenario, outcome: RunOutcome, team: str = "paper") -> None:
    """The run's recorded instants as a recording, 10 ms of simulated time apart, after the
    load's geometry (as the plant publishes it when it comes up)."""
    keys = Keys(team)
    start = 1_700_000_000_000_000_000
    with Recorder(path, team) as recorder:
        recorder.write(keys.geometry(), scenario.load_geometry(), start)
        for sample in [*outcome.history, outcome.final]:
            stamp = start + round(sample.truth.time_s * 1e9)
            recorder.write(keys.truth(), sample.truth, stamp)
            for i, est in sample.estimates.items():
                recorder.write(keys.estimate(i), est, stamp)
                recorder.write(keys.force(i), Command(i, sample.truth.tick, (1.0, 0.0)), stamp)
