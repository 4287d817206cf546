"""``heft bench accuracy``: each family of estimators on the same load, the speed figures and
their goal (the robust estimators' wall-clock time per simulated second at most 1.5 times the
paper's), on one real run of each family of the paper's scenario."""

from __future__ import annotations

import dataclasses

import pytest

from agent.algorithm.tuning import Estimators
from agent.platform.heft import main
from simulator.bench import accuracy
from simulator.scenario import load_scenario
from tests.helpers.paths import PAPER


@pytest.fixture(scope="module")
def report() -> accuracy.BenchReport:
    return accuracy.run_benchmark(load_scenario(PAPER), repeat=1, source=str(PAPER))


def test_each_family_runs_on_the_same_load(report) -> None:
    scenario = load_scenario(PAPER)
    for family in accuracy.FAMILIES:
        (outcome,) = report.runs[family]
        assert outcome.converged
        assert outcome.scenario.agent.estimator == family
        assert outcome.scenario == accuracy.with_estimators(scenario, family)
    assert report.outcomes == report.runs[Estimators.PAPER]  # paper.toml's own estimators


def test_each_agents_step_time_is_its_share_of_the_run(report) -> None:
    for family in accuracy.FAMILIES:
        (outcome,) = report.runs[family]
        assert sorted(outcome.step_s) == [1, 2, 3, 4]
        assert all(s > 0.0 for s in outcome.step_s.values())
        assert sum(outcome.step_s.values()) < outcome.wall_s  # the plant's time is not in it
        per_robot = report.step_per_simulated_s(family)
        assert per_robot == {i: s / outcome.sim_time_s for i, s in outcome.step_s.items()}


def test_the_ratio_is_robust_over_paper_wall_time_per_simulated_second(report) -> None:
    (robust,), (paper,) = report.runs[Estimators.ROBUST], report.runs[Estimators.PAPER]
    expected = (robust.wall_s / robust.sim_time_s) / (paper.wall_s / paper.sim_time_s)
    assert report.speed_ratio == pytest.approx(expected, rel=1e-12)
    assert accuracy.figures(report) == {"speed_ratio": report.speed_ratio}
    text = accuracy.format_report(report)
    assert f"robust / paper, wall per simulated second: {report.speed_ratio:.2f} (" in text
    assert "accuracy, paper estimators" in text and "paper steps" in text


def test_the_ratio_is_the_median_of_the_rounds_printed_with_their_range(report) -> None:
    (robust,), (paper,) = report.runs[Estimators.ROBUST], report.runs[Estimators.PAPER]
    per_s = paper.wall_s / paper.sim_time_s
    rounds = [  # the robust run slowed to these ratios, the paper's run as it was
        dataclasses.replace(robust, wall_s=ratio * per_s * robust.sim_time_s)
        for ratio in (1.3, 1.9, 1.45)
    ]
    slowed = dataclasses.replace(
        report, runs={Estimators.ROBUST: rounds, Estimators.PAPER: [paper] * 3}
    )
    assert slowed.round_ratios == pytest.approx([1.3, 1.9, 1.45], rel=1e-12)
    assert slowed.speed_ratio == pytest.approx(1.45, rel=1e-12)
    text = accuracy.format_report(slowed)
    assert "1.45 (median of the 3 rounds' ratios, 1.30 to 1.90)" in text


def test_the_families_take_turns(monkeypatch, report) -> None:
    ran = []

    def run(scenario):
        ran.append(scenario.agent.estimator)
        return report.runs[scenario.agent.estimator][0]

    monkeypatch.setattr(accuracy, "run_inprocess", run)
    heard = []
    found = accuracy.run_benchmark(
        load_scenario(PAPER), 3, on_run=lambda k, family, _: heard.append((k, family))
    )
    robust, paper = Estimators.ROBUST, Estimators.PAPER
    assert ran == [robust, paper, paper, robust, robust, paper]
    assert heard == [(1, robust), (1, paper), (2, paper), (2, robust), (3, robust), (3, paper)]
    assert [len(found.runs[f]) for f in accuracy.FAMILIES] == [3, 3]
    with pytest.raises(ValueError):
        accuracy.run_benchmark(load_scenario(PAPER), 0)


@pytest.mark.parametrize("slower, status", [(1.4, 0), (1.6, 1)])
def test_bench_accuracy_exits_1_when_the_robust_estimators_are_too_slow(
    monkeypatch, capsys, report, slower, status
) -> None:
    (robust,), (paper,) = report.runs[Estimators.ROBUST], report.runs[Estimators.PAPER]
    wall = slower * paper.wall_s / paper.sim_time_s * robust.sim_time_s
    timed = dataclasses.replace(
        report,
        runs={
            Estimators.ROBUST: [dataclasses.replace(robust, wall_s=wall)],
            Estimators.PAPER: [paper],
        },
    )
    monkeypatch.setattr(accuracy, "run_benchmark", lambda *args, **kwargs: timed)
    assert main(["bench", "accuracy", "-n", "1"]) == status
    out = capsys.readouterr().out
    verdict = "NOT met" if status else "met"
    assert f"wall-clock time per simulated second  {slower:.2f}  (at most 1.5): {verdict}" in out


def test_the_ratio_pairs_the_runs_of_each_round(report) -> None:
    (robust,), (paper,) = report.runs[Estimators.ROBUST], report.runs[Estimators.PAPER]

    def timed(outcome, per_simulated_s):
        return dataclasses.replace(outcome, wall_s=per_simulated_s * outcome.sim_time_s)

    # Rounds of 1.2, 1.4 and 2.0: a busy machine slowed the last round's runs both.
    rounds = [(0.012, 0.010), (0.014, 0.010), (0.060, 0.030)]
    paired = dataclasses.replace(
        report,
        runs={
            Estimators.ROBUST: [timed(robust, r) for r, _ in rounds],
            Estimators.PAPER: [timed(paper, p) for _, p in rounds],
        },
    )
    assert paired.speed_ratio == pytest.approx(1.4)
    assert paired.wall_per_simulated_s(Estimators.ROBUST) == pytest.approx(0.014)
