"""The default estimators on a real floor, end to end over Zenoh: the noisy paper load on four
casters (``paper-floor.toml``: μ = 2 %, μ_s = 3 %, 1 cm/s and 0.5 N of sensor noise, lagging
drives) with no ``[agent]`` table at all, one process per robot. In lockstep the run is the
in-process one, estimate for estimate; in real time it converges too; in both every robot's m,
J, ``contact_to_com`` and friction torque hold the truth within their published 95 %
intervals."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from agent.algorithm.tuning import AgentTuning
from simulator.inprocess import run_inprocess
from simulator.launcher import run_zenoh
from simulator.results import intervals
from simulator.scenario import load_scenario
from tests.helpers.accuracy import assert_same_estimates
from tests.helpers.paths import PAPER


@pytest.fixture(scope="module")
def floor(tmp_path_factory) -> Path:
    text = (PAPER.parent / "paper-floor.toml").read_text(encoding="utf-8")
    text = text[: text.index("[agent")]
    path = tmp_path_factory.mktemp("floor") / "floor.toml"
    path.write_text(text, encoding="utf-8")
    scenario = load_scenario(path)
    assert scenario.agent == AgentTuning() and scenario.ground.coulomb == 0.02
    return path


def _inside(outcome) -> None:
    assert outcome.converged, outcome.detail
    for robot in outcome.final.estimates:
        rows = intervals(outcome, robot)
        for name in ("mass", "moment", "contact_to_com", "friction_torque"):
            half_width, inside = rows[name]
            assert half_width is not None and inside, (robot, name, rows)


@pytest.mark.slow
@pytest.mark.parametrize("clock", ["lockstep", "realtime"])
def test_the_default_estimators_on_a_floor_over_zenoh(floor: Path, clock: str) -> None:
    scenario = load_scenario(floor)
    there = run_zenoh(scenario, clock=clock, log_stream=io.StringIO())
    _inside(there)
    if clock == "lockstep":
        assert_same_estimates(there, run_inprocess(scenario))
