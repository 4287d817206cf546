"""The floor's friction in a run's results (simulator/results.py): each robot's ``τ̂_c`` and
``μ̂`` with their standard deviations in the JSON, their 95 % intervals judged against the
truth's ``μ m g c`` and ``μ``, and the table's friction block and interval columns, which a
run where no robot estimated friction (the paper's estimators) does not print.

The paper's run (in one process, noise-free) is put on a floor of known friction and given
friction estimates of known errors, so that every figure is known beforehand."""

from __future__ import annotations

import dataclasses

import pytest

from agent.platform.evaluation import SCALAR_95
from agent.platform.protocol import GRAVITY
from simulator.inprocess import RunOutcome, run_inprocess
from simulator.results import format_table, intervals, results_dict
from simulator.scenario import load_scenario
from tests.helpers.paths import PAPER

MU, RADIUS = 0.02, 2.0
"""The floor: μ and the supports' mean distance from the COM ``c`` (m)."""
FRICTION = {
    1: {"friction_torque": 1.97, "friction_torque_std": 0.01, "coulomb": 0.021},
    2: {"friction_torque": 1.95, "coulomb": 0.02, "coulomb_std": 2e-4},
    3: {"friction_torque": 1.90, "friction_torque_std": 0.01, "coulomb": 0.0195},
    4: {"friction_torque": 1.962, "coulomb": 0.0205, "coulomb_std": 1e-4},
}
"""Each robot's friction estimates (``coulomb_std`` of robot 1 and 3 added below)."""


@pytest.fixture(scope="module")
def paper_run() -> RunOutcome:
    return run_inprocess(load_scenario(PAPER))


def on_floor(outcome: RunOutcome) -> RunOutcome:
    """``outcome`` on a floor of ``μ`` = :data:`MU` and ``c`` = :data:`RADIUS`, every robot with
    its :data:`FRICTION` and a mass uncertainty (robot 1 and 3 also ``σ_μ = 1e-4``)."""
    final = outcome.final
    truth = dataclasses.replace(
        final.truth, ground_coulomb=MU, ground_static=MU, friction_radius=RADIUS
    )
    estimates = {
        i: dataclasses.replace(
            est, mass_std=0.01, **FRICTION[i], **({"coulomb_std": 1e-4} if i in (1, 3) else {})
        )
        for i, est in final.estimates.items()
    }
    return dataclasses.replace(
        outcome, final=dataclasses.replace(final, truth=truth, estimates=estimates)
    )


def test_the_results_carry_each_robots_friction_against_the_truth(paper_run) -> None:
    outcome = on_floor(paper_run)
    torque = MU * 5.0 * GRAVITY * RADIUS  # μ m g c: 1.962 N m
    assert outcome.final.truth.coulomb_torque == pytest.approx(torque)
    document = results_dict(outcome)
    assert document["truth"]["ground"]["coulomb_torque"] == pytest.approx(torque)
    assert document["truth"]["ground"]["coulomb"] == MU
    robot = document["robots"]["1"]
    assert (robot["friction_torque"], robot["friction_torque_std"]) == (1.97, 0.01)
    assert (robot["coulomb"], robot["coulomb_std"]) == (0.021, 1e-4)
    assert document["robots"]["2"]["friction_torque_std"] is None
    # The worst errors, absolute: robot 3's torque, robot 1's μ.
    assert document["errors"]["friction_torque_nm"] == pytest.approx(torque - 1.90)
    assert document["errors"]["coulomb"] == pytest.approx(0.001)
    # 1.96 σ about each estimate, and whether the truth lies inside.
    found = document["intervals"]
    assert found["1"]["friction_torque"] == [pytest.approx(SCALAR_95 * 0.01), True]
    assert found["1"]["coulomb"] == [pytest.approx(SCALAR_95 * 1e-4), False]  # 0.001 off
    assert found["2"]["friction_torque"] == [None, None]  # no σ published
    assert found["2"]["coulomb"] == [pytest.approx(SCALAR_95 * 2e-4), True]
    assert found["3"]["friction_torque"] == [pytest.approx(SCALAR_95 * 0.01), False]
    assert found["4"]["coulomb"] == [pytest.approx(SCALAR_95 * 1e-4), False]  # 5e-4 off
    assert found["1"] == intervals(outcome, 1)


def test_the_table_gives_the_friction_and_its_intervals(paper_run) -> None:
    lines = format_table(on_floor(paper_run)).splitlines()
    start = lines.index(
        "tau_c: friction torque on a spin about the COM (truth mu m g c); mu: kinetic coefficient"
    )
    assert lines[start + 1 : start + 9] == [
        "robot tau_c [N m]        mu tau_c err N m    mu err",
        "-" * 51,
        "    1     1.97000  0.021000       0.00800  0.001000",
        "    2     1.95000  0.020000       0.01200  0.000000",
        "    3     1.90000  0.019500       0.06200  0.000500",
        "    4     1.96200  0.020500       0.00000  0.000500",
        "truth     1.96200  0.020000             -         -",
        "worst           -         -       0.06200  0.001000",
    ]
    assert lines[start - 1] == "" and lines[start - 2].startswith("worst")  # after the estimates
    start = lines.index(
        "95 % intervals     m ±%     J ±%   ctc ±mm  z_ij ±mm  tau_c ±N m      mu ±   truth inside"
    )
    assert lines[start + 1 : start + 5] == [
        "robot 1           0.392        -         -         -     0.01960  0.000196   m tau_c",
        "robot 2           0.392        -         -         -           -  0.000392   m mu",
        "robot 3           0.392        -         -         -     0.01960  0.000196   m",
        "robot 4           0.392        -         -         -           -  0.000196   m",
    ]
    assert max(map(len, lines)) < 100


def test_a_run_without_friction_estimates_prints_no_friction(paper_run) -> None:
    """The paper's estimators estimate no friction: no friction block, and the intervals'
    columns are those without friction."""
    table = format_table(paper_run)
    assert "tau_c" not in table and "friction" not in table
    published = dataclasses.replace(
        paper_run,
        final=dataclasses.replace(
            paper_run.final,
            estimates={
                i: dataclasses.replace(est, mass_std=0.01)
                for i, est in paper_run.final.estimates.items()
            },
        ),
    )
    lines = format_table(published).splitlines()
    assert "tau_c" not in "\n".join(lines)
    header = lines.index("95 % intervals     m ±%     J ±%   ctc ±mm  z_ij ±mm   truth inside")
    assert lines[header + 1] == "robot 1           0.392        -         -         -   m"
    assert results_dict(paper_run)["robots"]["1"]["coulomb"] is None
