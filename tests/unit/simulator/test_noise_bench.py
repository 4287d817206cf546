"""``heft bench noise``, ``sweep`` and ``changes``: their reports and goals from known results,
one real seed, and the commands' exit status from the goals' verdicts."""

from __future__ import annotations

import dataclasses
import math

import pytest

from agent.platform.evaluation import RelativePositionSplit
from agent.platform.goals import exit_status, judge
from agent.platform.heft import main
from simulator.bench import changes, noise
from simulator.bench.calibrate import published_variance
from simulator.bench.noise import (
    GOALS,
    NoiseSettings,
    coverage,
    figures,
    format_noise_report,
    format_sweep,
    median,
    plot_sweep,
    run_seed,
)
from simulator.scenario import load_scenario
from tests.helpers.noise_results import seed_result
from tests.helpers.paths import PAPER

NAMES = ("m", "J", "contact_to_com", "z_ij")
JUDGED = (*NAMES, "tau_c", "mu")


def unmet(results) -> list[str]:
    """The goals of the noise benchmark ``results`` do not meet, by what they measure."""
    return [v.goal.measured for v in judge(GOALS, figures(results)) if not v.met]


def test_the_report_and_each_goals_verdict() -> None:
    good = [seed_result(s, 1.2, inside=s != 0) for s in range(20)]  # 76 of 80 inside: 95 %
    assert median(good, "robust", "mass_rel") == pytest.approx(0.0012)
    assert median(good, "paper", "mass_rel") is None  # some run has none: unbounded
    assert coverage(good, "moment_rel") == (76, 80)
    report = format_noise_report(good, NoiseSettings(), "scenario 'paper'", 10.0)
    assert "m (%)" in report and "1.20" in report and "95 % of 80" in report
    assert figures(good)["ratio mass_rel"] == pytest.approx(1.2)
    assert figures(good)["inside moment_rel"] == pytest.approx(95.0)
    assert unmet(good) == [] and exit_status(judge(GOALS, figures(good))) == 0
    # the friction estimates' medians and coverage are reported, the fit's none
    lines = {line.split()[0]: line.split() for line in report.splitlines() if line.strip()}
    assert lines["tau_c"][2:5] == ["5", "-", "-"] and lines["mu"][3:6] == ["0.1", "-", "-"]
    assert lines["tau_c"][6:9] == ["95", "%", "of"]
    # at least 95 % of the runs done within 30 s: 19 of 20 are, 18 are not enough
    slow = [*good[:-1], seed_result(19, 1.2, done=31.0)]
    assert "19/20" in format_noise_report(slow, NoiseSettings(), "x", 1.0)
    assert figures(slow)["done"] == 95.0 and unmet(slow) == []
    slower = [*good[:-2], seed_result(18, 1.2, done=31.0), seed_result(19, 1.2, done=45.0)]
    assert unmet(slower) == ["robust runs done within 30 s simulated"]
    assert unmet([*good[:-1], seed_result(19, 1.2, done=29.9)]) == []
    worse = [seed_result(s, 2.0, inside=s != 0) for s in range(20)]
    assert unmet(worse) == [f"{q}: robust median / baseline's (runs done)" for q in NAMES]
    # a run that ended with a verdict has no estimates: the ratios are those of the runs done
    held = [*good[:-1], dataclasses.replace(seed_result(19, 9.0), robust_done=False)]
    assert figures(held)["ratio mass_rel"] == pytest.approx(1.2) and unmet(held) == []
    off_the_floor = [*good[:-1], seed_result(19, 1.2, travel=3.5)]
    report = format_noise_report(off_the_floor, NoiseSettings(), "x", 1.0)
    assert "on its floor: 19/20 (largest travel 3.50 m" in report
    assert unmet(off_the_floor) == ["robust runs that kept the load on its floor"]
    overconfident = [seed_result(s, 1.0, inside=s % 2 == 0) for s in range(20)]  # 50 % inside
    assert unmet(overconfident) == [f"{q}: truth inside the 95 % intervals" for q in JUDGED]
    always = [seed_result(s, 1.0) for s in range(20)]  # 100 %: the intervals are too wide
    assert len(unmet(always)) == 6 and exit_status(judge(GOALS, figures(always))) == 1
    # the friction intervals are judged as the others: too narrow on mu alone fails its goal
    narrow_mu = [seed_result(s, 1.2, inside=s != 0) for s in range(20)]
    for r in narrow_mu[:10]:
        r.inside["coulomb"] = [False] * 4
    assert unmet(narrow_mu) == ["mu: truth inside the 95 % intervals"]


def test_the_report_gives_the_medians_over_the_runs_done_beside_them() -> None:
    """A run not done has no mass: the medians over all runs are unbounded, and those over
    the runs done follow."""
    results = [seed_result(s, 1.2) for s in range(4)]
    robust = {**results[2].robust, "mass_rel": None}
    results[2] = dataclasses.replace(
        results[2], robust=robust, robust_done=False, robust_time_s=60.0
    )
    report = format_noise_report(results, NoiseSettings(), "x", 1.0)
    every, done = report.split("over the 3 robust runs done (seeds 0, 1, 3):")
    assert [line.split()[2] for line in every.splitlines() if line.startswith("m (%)")] == ["-"]
    row = next(line.split() for line in done.splitlines() if line.startswith("m (%)"))
    assert row[2] == "0.12" and row[5] == "1.20"
    assert "over the" not in format_noise_report(results[:2], NoiseSettings(), "x", 1.0)


@pytest.mark.parametrize("late, status", [(False, 0), (True, 1)])
def test_bench_noise_exits_with_its_goals_verdict(monkeypatch, capsys, late, status) -> None:
    """The command's exit status is the goals' verdict: seeds 3 and 7 done after 30 s fail
    one (at least 95 % of the runs must be done by then)."""
    finished = {3: 35.0 if late else 12.0, 7: 31.0 if late else 29.0}
    results = [seed_result(s, 1.2, inside=s != 0, done=finished.get(s, 12.0)) for s in range(20)]
    seen = []

    def run(scenarios, settings, on_seed):
        seen.append(settings.seeds)
        return results

    monkeypatch.setattr(noise, "run_noise_bench", run)
    assert main(["bench", "noise", "--seeds", "20"]) == status
    out = capsys.readouterr().out
    assert seen == [20] and out.startswith("heft bench noise: scenario 'paper', 20 seeds")
    assert out.rstrip().endswith("goals: NOT met" if late else "goals: met")
    goals = out.split("\ngoals:\n", 1)[1].splitlines()
    line = next(line for line in goals if "runs done within 30 s" in line)
    assert line.endswith("(at least 95 %): NOT met" if late else "(at least 95 %): met")


def test_the_sweep_table_and_plot(tmp_path) -> None:
    found = {0.0: [seed_result(0, 1.0)], 0.01: [seed_result(0, 1.5)]}
    table = format_sweep(found, "scenario 'paper'")
    assert "| 0.01 | 0.5 |" in table and "0.15 / - / 0.1" in table
    path = plot_sweep(found, tmp_path / "sweep.png", "scenario 'paper'")
    assert path.stat().st_size > 10_000


def test_one_seed_against_the_centralized_fit() -> None:
    """One real seed: the robust run ends, the baseline fits its measurements, and both are
    close to the truth; the paper's estimators do not finish."""
    settings = NoiseSettings(seeds=1, max_time_s=25.0)
    result = run_seed(load_scenario(PAPER), dataclasses.replace(settings), 1)
    assert result.robust_done and not result.paper_done
    assert result.robust["mass_rel"] < 0.03 and result.baseline["mass_rel"] < 0.02
    assert result.baseline["relative_positions_m"] < 0.005
    # the plant's floor is frictionless: the baseline finds none, within its uncertainty
    friction = result.baseline_friction
    for key in ("friction_torque", "spin_drag", "sliding_friction"):
        if friction[key] is not None:  # F_s: fitted if the load slid
            assert abs(friction[key]) < 4 * friction[key + "_std"]
    assert result.baseline["friction_torque_Nm"] == abs(friction["friction_torque"])
    # Every robot's published estimates are kept, and at the current factors the calibration
    # counts inside exactly what the benchmark does.
    found = result.intervals
    assert len(found["moment"]) == len(found["own_mass"]) == 4
    assert all(s.fit_std is not None and s.fit_std > 0.0 for s in found["moment"])
    # Step 5's offsets, before Step 7 refined them (what STEP5_COM_VARIANCE is calibrated on)
    assert len(found["push_offset"]) == 4
    for s in found["push_offset"]:
        assert math.hypot(*s.error) < 0.05 and s.covariance[0] > 0.0 and s.covariance[2] > 0.0
    mass, moment, offset, _, robots, *floor = published_variance([result])
    # the floor's friction, published by every robot (frictionless here: its truth is 0)
    assert [f.quantity for f in floor] == ['tau_c ("friction_torque")', 'mu ("coulomb")']
    assert all(len(f.needed) == 4 for f in floor)
    for factor, key in (
        (mass, "mass_rel"),
        (moment, "moment_rel"),
        (offset, "contact_to_com_m"),
        (robots, "relative_positions_m"),
    ):
        inside, published = coverage([result], key)
        assert len(factor.needed) == published
        assert sum(k <= factor.factor for k in factor.needed) == inside
    assert result.robust["relative_positions_m"] < 0.01
    assert result.paper["mass_rel"] is None
    assert all(len(flags) == 4 for flags in result.inside.values())
    # on the paper's frictionless floor the friction intervals are judged against μ = 0: no
    # torque to take a relative error of, and the fit models none
    assert {"friction_torque_rel", "coulomb"} <= set(result.inside) and result.coulomb == 0.0
    assert result.robust["friction_torque_rel"] is None and result.robust["coulomb"] is not None
    assert result.baseline["coulomb"] is None
    assert result.floor["within"], result.floor


def change(seed: int, case: str, mass: float = 0.006, **odd) -> changes.ChangeResult:
    fields = dict(
        seed=seed,
        case=case,
        latency_s=None if case == "none" else 1.5,
        false_alarms=0,
        errors={"mass_rel": mass, "moment_rel": 0.005, "contact_to_com_m": 0.006},
        converged=True,
        on_floor=True,
        baseline={}
        if case == "none"
        else {"mass_rel": 0.004, "moment_rel": 0.01, "contact_to_com_m": 0.012},
    )
    return changes.ChangeResult(**{**fields, **odd})


def test_the_change_report_sets_the_re_estimated_load_beside_its_fit() -> None:
    results = [change(s, c, 0.006 + 0.001 * s) for s in range(3) for c in changes.CASES]
    report = changes.format_change_report(results)
    lines = {line.split()[0]: line for line in report.splitlines() if line.strip()}
    # Median re-estimated mass 0.7 % against the fit's 0.4 %: 1.75; J 0.5; ctc 0.5.
    assert lines["mass"].endswith("1.75 / 0.50 / 0.50")
    assert "0.40%" in lines["com"] and "12.0mm" in lines["com"]
    verdicts = judge(changes.GOALS, changes.figures(results))
    assert all(v.met for v in verdicts) and len(verdicts) == 4


@pytest.mark.parametrize(
    "odd, unmet",
    [
        (dict(case="mass", latency_s=5.5), "changes noticed within 5 s"),
        (dict(case="com", latency_s=None), "changes noticed within 5 s"),
        (dict(case="none", false_alarms=1), "false alarms"),
        (dict(case="none", converged=False), "runs done"),
        (dict(case="com", on_floor=False), "runs that kept the load on its floor"),
    ],
)
def test_each_change_goal_fails_on_its_own(monkeypatch, capsys, odd, unmet) -> None:
    results = [change(s, c) for s in range(2) for c in changes.CASES]
    results.append(change(2, **odd))
    verdicts = judge(changes.GOALS, changes.figures(results))
    assert [v.goal.measured for v in verdicts if not v.met] == [unmet]
    monkeypatch.setattr(changes, "run_change_bench", lambda scenario, settings, say: results)
    assert main(["bench", "changes", "--seeds", "2"]) == 1
    assert capsys.readouterr().out.rstrip().endswith("goals: NOT met")


def test_the_seeds_run_start_at_first_seed(monkeypatch) -> None:
    import simulator.bench.noise as bench

    seen = []
    monkeypatch.setattr(bench, "run_seed", lambda scenario, settings, seed: seen.append(seed))
    bench.run_noise_bench(lambda seed: None, NoiseSettings(seeds=3, first_seed=20))
    assert seen == [20, 21, 22]
    two = [seed_result(20, 1.0), seed_result(21, 1.0)]
    report = format_noise_report(two, NoiseSettings(), "x", 1.0)
    assert "2 seeds (20-21)" in report.splitlines()[0]


def test_the_commands_default_seeds_are_the_settings_default() -> None:
    """``heft bench noise|sweep|changes`` state their default seeds without importing the
    benchmark (numpy): the same number as :class:`NoiseSettings`'s."""
    from simulator.bench.cli import NOISE_SEEDS

    assert NOISE_SEEDS == NoiseSettings().seeds


def test_the_report_splits_the_relative_positions_errors() -> None:
    """The ``z_ij`` split's medians, robust / baseline, over the runs where both have one (a
    run without the baseline's is left out); no line when no run has both."""

    def split(turn: float, length: float, own: float) -> RelativePositionSplit:
        return RelativePositionSplit(common_turn=turn, worst_length=length, worst_own=own)

    runs = [seed_result(s, 1.2) for s in range(4)]
    for r, turn in zip(runs, (-1e-3, 2e-3, 3e-3, 9e-3)):
        r.split = {"robust": split(turn, 2e-3, 1e-3), "baseline": split(5e-4, 1e-3, 5e-4)}
    runs[3].split["baseline"] = None  # its fit failed: left out
    report = format_noise_report(runs, NoiseSettings(), "x", 1.0)
    line = next(line for line in report.splitlines() if line.startswith("z_ij split"))
    assert line == (
        "z_ij split, robust / baseline (medians over 3 runs): common turn 2 / 0.5 mrad; worst"
        " length 2 / 1 mm; worst without the common turn 1 / 0.5 mm"
    )
    bare = [seed_result(s, 1.2) for s in range(4)]
    assert "z_ij split" not in format_noise_report(bare, NoiseSettings(), "x", 1.0)
