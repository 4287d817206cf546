"""Real sensors are noisy; the paper's estimators are not made for it ("the noisy case will be
the subject of a future work"). These end-to-end runs hold the paper's scenario with wheel
odometry noise of 1 cm/s and force noise of 0.5 N, run with ``[agent] estimator = "robust"``
and Step 1 spun up to 1 m/s, to the bounds of the noise issue: within 1.5 times a centralized
batch fit of the same kind of data (m 0.44 %, J 1.2 %, ``contact_to_com`` 12 mm, the issue's
reference figures), with margin, and done within 30 s simulated (the real floor's issue: the
robust push runs in stages, Step 5's, then Step 7's); ``z_ij`` within 10 mm (the
issue's 1.5 × 2.1 mm is not reached yet). The paper's estimators, on the same runs, do not get
past Step 1.

The robust estimators also keep the noise-free results: within a few times today's paper
figures (m 0.0003 %, J 0.013 %, 0.15 mm), but for ``contact_to_com`` and ``z_ij``, within
1.5 mm: Step 7's stage stops the load's turn, and the team's tracked angle loses about
0.5 mrad while it does (1 mm at the contacts' 2 m)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from agent.algorithm.tuning import Estimators
from agent.platform.heft import main
from agent.platform.protocol import Phase
from simulator.inprocess import run_inprocess
from simulator.results import format_table, intervals, results_dict
from simulator.scenario import load_scenario
from tests.helpers.accuracy import worst_errors
from tests.helpers.paths import PAPER

SIGMA_V = 0.01  # m/s per axis
SIGMA_F = 0.5  # N per axis


def _scenario(seed: int, estimator: Estimators, noise: bool = True, max_time_s: float = 30.0):
    paper = load_scenario(PAPER)
    return dataclasses.replace(
        paper,
        sensors=dataclasses.replace(
            paper.sensors,
            velocity_noise_std=SIGMA_V if noise else 0.0,
            force_noise_std=SIGMA_F if noise else 0.0,
        ),
        run=dataclasses.replace(paper.run, seed=seed, max_time_s=max_time_s),
        agent=dataclasses.replace(
            paper.agent,
            estimator=estimator,
            spin_speed=1.0,
            spin_gain=10.0,
            push_flip_s=2.0,
            robust=dataclasses.replace(
                paper.agent.robust, push_force=2.0, push_damping=0.0, inertia_brake_s=0.0
            ),
        ),
    )


@pytest.mark.parametrize("seed", [1, 2])
def test_the_paper_scenario_with_real_sensor_noise(seed: int) -> None:
    outcome = run_inprocess(_scenario(seed, Estimators.ROBUST), record_every=1000)
    assert outcome.converged, f"not done within {outcome.scenario.run.max_time_s:g} s simulated"
    worst = worst_errors(outcome)
    assert worst["mass"] <= 0.01, worst
    assert worst["moment"] <= 0.025, worst
    assert worst["contact_to_com"] <= 0.025, worst
    # z_ij: not yet within 1.5 times the fit's (3.2 mm): the robust median is 4 mm, the
    # paper's 30 mm (heft bench noise); this bounds what is reached.
    assert worst["relative"] <= 0.01, worst
    # Every robot published its uncertainty with its estimates.
    for i in range(1, outcome.scenario.n + 1):
        est = outcome.final.estimates[i]
        assert est.mass_std > 0 and est.moment_std > 0 and est.contact_to_com_cov is not None
        # Ideal drives here: each robot finds its gain 1, to within its uncertainty.
        assert 0 < est.drive_gain_std < 0.02 and abs(est.drive_gain - 1.0) < 4 * est.drive_gain_std
        assert set(est.relative_positions_cov) == set(outcome.scenario.neighbours(i))
        row = intervals(outcome, i)
        assert row["mass"][0] > 0 and row["contact_to_com"][0] > 0
    # ... and the results file and table carry it.
    document = results_dict(outcome)
    robot = document["robots"]["1"]
    assert robot["mass_std"] > 0 and len(robot["contact_to_com_cov"]) == 3
    assert robot["drive_gain"] == outcome.final.estimates[1].drive_gain
    assert set(robot["relative_positions_cov"]) == {"2"}
    assert set(document["intervals"]["1"]) == {
        "mass",
        "moment",
        "contact_to_com",
        "relative_positions",
    }
    assert "95 % intervals" in format_table(outcome)
    # The load stayed on its floor (3 m, 2 m/s, 2 rad/s) all the while.
    assert document["floor"]["within"], document["floor"]


def test_the_paper_estimators_do_not_get_past_step_1_on_the_same_run() -> None:
    outcome = run_inprocess(_scenario(1, Estimators.PAPER), record_every=1000)
    assert not outcome.converged
    assert all(e.phase == Phase.EXCITE for e in outcome.final.estimates.values())
    assert all(e.mass is None and e.mass_std is None for e in outcome.final.estimates.values())
    assert results_dict(outcome)["intervals"] == dict.fromkeys(("1", "2", "3", "4"))
    assert "95 % intervals" not in format_table(outcome)


def test_the_robust_estimators_without_noise() -> None:
    outcome = run_inprocess(_scenario(1, Estimators.ROBUST, noise=False), record_every=1000)
    assert outcome.converged
    worst = worst_errors(outcome)
    assert worst["mass"] <= 2e-4, worst
    assert worst["moment"] <= 3e-4, worst
    assert worst["contact_to_com"] <= 1.5e-3, worst
    assert worst["relative"] <= 1.5e-3, worst


def test_a_scenario_without_an_agent_table_works_with_real_sensors_and_drives(
    tmp_path: Path, capsys
) -> None:
    """The defaults are for real robots: the paper's load with the sensors' noise and the
    drives of ``paper-noisy.toml`` (1 cm/s, 0.5 N, a 20 ms lag, 2 % gain errors) and no
    ``[agent]`` table, run by ``heft run``, is done within 30 s simulated and on its floor;
    every robot's m, J and ``contact_to_com`` hold the truth within their published 95 %
    intervals, and its ``z_ij`` are within 1 cm."""
    text = (PAPER.parent / "paper-noisy.toml").read_text(encoding="utf-8")
    text = text[: text.index("# Agent gains and limits")]
    assert "[agent" not in text and "[actuators]" in text
    path, out = tmp_path / "noisy.toml", tmp_path / "results.json"
    path.write_text(text, encoding="utf-8")
    assert load_scenario(path).agent.estimator is Estimators.ROBUST  # the default
    assert main(["run", str(path), "--out", str(out)]) == 0
    capsys.readouterr()
    results = json.loads(out.read_text(encoding="utf-8"))
    assert results["converged"] and results["sim_time_s"] <= 30.0, results["sim_time_s"]
    assert results["floor"]["within"], results["floor"]
    for robot, rows in results["intervals"].items():
        for name in ("mass", "moment", "contact_to_com"):
            half_width, inside = rows[name]
            assert half_width is not None and inside, (robot, name, rows)
        assert rows["relative_positions"][0] is not None  # published
    assert results["errors"]["relative_positions_m"] <= 0.01, results["errors"]
