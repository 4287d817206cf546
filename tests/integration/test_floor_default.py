"""The default estimators on a real floor, end to end over Zenoh: the noisy paper load on four
casters (``paper-floor.toml``: μ = 2 %, μ_s = 3 %, 1 cm/s and 0.5 N of sensor noise, lagging
drives) with no ``[agent]`` table at all, one process per robot. In lockstep the run is the
in-process one, estimate for estimate, and every robot's m, J, ``contact_to_com`` and friction
torque hold the truth within their published 95 % intervals; in real time, whose messages
arrive as they do (one run, not a coverage), it converges with m within 2 %, J within 3 %,
``contact_to_com`` within 3 cm and the friction torque within 10 % of the truth."""

from __future__ import annotations

import io
import math
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
def test_the_default_estimators_on_a_floor_over_zenoh_in_lockstep(floor: Path) -> None:
    scenario = load_scenario(floor)
    there = run_zenoh(scenario, clock="lockstep", log_stream=io.StringIO())
    _inside(there)
    assert_same_estimates(there, run_inprocess(scenario))


@pytest.mark.slow
def test_the_default_estimators_on_a_floor_over_zenoh_in_real_time(floor: Path) -> None:
    there = run_zenoh(load_scenario(floor), clock="realtime", log_stream=io.StringIO())
    assert there.converged, there.detail
    truth = there.final.truth
    for est in there.final.estimates.values():
        assert abs(est.mass / truth.mass - 1.0) < 0.02, est.mass
        assert abs(est.moment / truth.moment - 1.0) < 0.03, est.moment
        assert math.dist(est.contact_to_com, truth.contact_to_com[est.robot - 1]) < 0.03
        assert abs(est.friction_torque / truth.coulomb_torque - 1.0) < 0.1
