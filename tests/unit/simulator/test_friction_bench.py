"""The noise benchmarks on a floor: ``heft bench noise --coulomb``/``--coulomb-range`` and
``heft bench friction``. Each seed's μ drawn from its own stream, the supports the load rests on
(its own, its whole area, or the cells of it that bear it), the options' checks, the friction
estimates judged against the truth, and the friction sweep's table, plot and goals from known
results (no run is long: the commands run on stand-ins for the benchmark)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from agent.platform.goals import judge
from agent.platform.heft import main
from agent.platform.protocol import GRAVITY, Estimates, Phase, Truth
from simulator.bench import friction, noise
from simulator.bench.floor import FRICTION_STREAM, STATIC_RATIO, FloorSettings, on_floor
from simulator.bench.noise import friction_errors, friction_inside
from simulator.generate import generate_scenario
from simulator.scenario import (
    DEFAULT_SUPPORT_CELLS,
    MAX_FRICTION,
    ScenarioError,
    load_scenario,
    parse_scenario,
)
from tests.helpers.bad_input import paper
from tests.helpers.noise_results import seed_result
from tests.helpers.paths import PAPER

PAPER_FLOOR = PAPER.with_name("paper-floor.toml")
PARTLY_RESTING = 1
"""A generated load whose COM is too far from its area's centroid to rest on all of it."""


# ------------------------------------------------------------------------------ the μ draw
def test_each_seeds_mu_is_drawn_from_its_own_stream_in_the_range() -> None:
    floor = FloorSettings((0.005, 0.03))
    drawn = [floor.draw(seed) for seed in range(400)]
    mus = np.array([mu for mu, _ in drawn])
    assert mus.min() >= 0.005 and mus.max() <= 0.03
    assert mus.min() < 0.0075 and mus.max() > 0.0275  # the whole range, not a corner of it
    assert abs(mus.mean() - 0.0175) < 0.0015  # uniform: the mean within 4 standard errors
    assert len(set(mus)) == 400
    assert drawn[7] == floor.draw(7)  # the same seed, the same floor, in every benchmark
    expected = np.random.default_rng((7, FRICTION_STREAM)).uniform(0.005, 0.03)
    assert drawn[7] == (expected, STATIC_RATIO * expected)


def test_one_mu_for_every_seed_and_the_static_coefficient() -> None:
    assert FloorSettings((0.02, 0.02)).draw(3) == (0.02, STATIC_RATIO * 0.02)
    assert FloorSettings((0.02, 0.02), static=0.05).draw(3) == (0.02, 0.05)
    assert FloorSettings((1.9, 1.9)).draw(0) == (1.9, MAX_FRICTION)  # μ_s within its range
    mu, static = FloorSettings((0.01, 0.02), static=0.04).draw(11)
    assert 0.01 <= mu <= 0.02 and static == 0.04


# ------------------------------------------------------------------------------ supports
def test_a_scenario_with_its_own_floor_keeps_its_supports() -> None:
    scenario, dropped = on_floor(load_scenario(PAPER_FLOOR), 0.01, 0.015)
    assert dropped == 0 and scenario.ground.supports_given
    assert scenario.ground.supports == ((-1.8, -0.8), (1.8, -0.8), (1.8, 0.8), (-1.8, 0.8))
    assert (scenario.ground.coulomb, scenario.ground.static) == (0.01, 0.015)


def test_without_a_floor_the_load_rests_on_its_whole_area_as_the_plant_would_put_it() -> None:
    scenario, dropped = on_floor(load_scenario(PAPER), 0.02, 0.03)
    by_the_plant = parse_scenario({**paper(), "ground": {"coulomb": 0.02, "static": 0.03}})
    assert dropped == 0 and scenario.ground == by_the_plant.ground
    assert DEFAULT_SUPPORT_CELLS <= len(scenario.ground.supports)


def test_no_friction_is_no_floor() -> None:
    assert on_floor(load_scenario(PAPER_FLOOR), 0.0, 0.0)[0].ground is None
    assert on_floor(load_scenario(PAPER), 0.0, 0.0)[0].ground is None


def test_a_load_that_cannot_rest_on_its_whole_area_rests_on_the_cells_that_bear_it() -> None:
    """The plant refuses the whole area under a COM this far from its centroid (the floor
    would pull); the benchmark drops the cells it would pull at, and the rest hold the load
    in statics, none pulling."""
    generated = generate_scenario(PARTLY_RESTING)
    with pytest.raises(ScenarioError, match="give ground.supports"):
        parse_scenario({**_tables(generated), "ground": {"coulomb": 0.02}})
    scenario, dropped = on_floor(generated, 0.02, 0.03)
    ground, body = scenario.ground, scenario.body
    assert dropped > 0 and len(ground.supports) >= DEFAULT_SUPPORT_CELLS // 2
    normal = np.array(ground.loads(body.mass, body.com).normal)
    assert normal.min() >= 0.0
    assert normal.sum() == pytest.approx(body.mass * GRAVITY, rel=1e-12)
    centre = normal.dot(np.array(ground.supports)) / normal.sum()
    assert centre == pytest.approx(body.com, abs=1e-9)


def _tables(scenario) -> dict:
    """``scenario``'s tables as a file would give them."""
    import tomllib

    from simulator.scenario import scenario_to_toml

    return tomllib.loads(scenario_to_toml(scenario))


# ------------------------------------------------------------------------------ options
def _seen_settings(monkeypatch, argv: list[str]) -> list[noise.NoiseSettings]:
    """The settings ``heft bench noise ARGV`` runs with (the benchmark itself stood in for)."""
    seen: list[noise.NoiseSettings] = []

    def run(scenarios, settings, on_seed):
        seen.append(settings)
        return [seed_result(0, 1.0)]

    monkeypatch.setattr(noise, "run_noise_bench", run)
    main(["bench", "noise", *argv])
    return seen


def test_the_floor_options_give_the_benchmarks_floor(monkeypatch, capsys) -> None:
    (plain,) = _seen_settings(monkeypatch, ["--seeds", "1"])
    assert plain.floor is None and plain.paper_estimators
    (one,) = _seen_settings(monkeypatch, ["--seeds", "1", "--coulomb", "0.02"])
    assert one.floor == FloorSettings((0.02, 0.02))
    argv = ["--generated", "2", "--coulomb-range", "0.005", "0.03", "--static", "0.05"]
    (drawn,) = _seen_settings(monkeypatch, argv)
    assert drawn.floor == FloorSettings((0.005, 0.03), 0.05) and drawn.seeds == 2
    assert "floor: mu 0.5-3 % per seed, mu_s 5 %" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--static", "0.1"], "--static: needs --coulomb or --coulomb-range"),
        (["--coulomb", "3"], "--coulomb: expected a non-negative number in [0, 2], got 3.0"),
        (["--coulomb", "-0.01"], "--coulomb: expected a non-negative number in [0, 2]"),
        (["--coulomb-range", "0.03", "0.01"], "--coulomb-range HI: expected a number in [0.03, 2]"),
        (["--coulomb-range", "0.01", "nan"], "--coulomb-range HI"),
        (["--coulomb", "0.02", "--static", "0.01"], "--static: expected a number in [0.02, 2]"),
        (["--coulomb-range", "0", "0.03", "--static", "0.02"], "--static: expected a number in"),
    ],
)
def test_a_bad_floor_is_one_line_and_exit_2(monkeypatch, capsys, argv, message) -> None:
    monkeypatch.setattr(noise, "run_noise_bench", pytest.fail)
    assert main(["bench", "noise", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_one_mu_or_a_range_not_both(capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["bench", "noise", "--coulomb", "0.01", "--coulomb-range", "0", "0.02"])
    assert exit_.value.code == 2
    assert "not allowed with argument --coulomb" in capsys.readouterr().err


# ------------------------------------------------------------------------------ friction judged
def _truth(mu: float, radius: float = 1.5) -> Truth:
    """Two contacts about a 4 kg load's COM, on a floor of ``mu`` and friction radius
    ``radius``."""
    contacts = ((1.0, 0.0), (-1.0, 0.0))
    still = ((0.0, 0.0),) * 2
    return Truth(
        100,
        1.0,
        (0, 0),
        0,
        (0, 0),
        0,
        contacts,
        still,
        ((-1, 0), (1, 0)),
        4.0,
        2.0,
        ground_coulomb=mu,
        ground_static=1.5 * mu,
        friction_radius=radius,
    )


def test_the_friction_estimates_against_the_truths_torque_and_mu() -> None:
    """τ_c = μ m g c = 0.02 · 4 · 9.81 · 1.5 = 1.177 N m; robot 1 within its intervals, robot
    2's τ̂_c 10 % high with a σ of 1 % (outside) and its μ̂ right; robot 3 publishes none."""
    truth = _truth(0.02)
    torque = truth.coulomb_torque
    assert torque == pytest.approx(0.02 * 4.0 * GRAVITY * 1.5)

    def est(robot, tau, tau_std, mu, mu_std):
        return Estimates(
            robot=robot,
            tick=100,
            phase=Phase.DONE,
            friction_torque=tau,
            friction_torque_std=tau_std,
            coulomb=mu,
            coulomb_std=mu_std,
        )

    estimates = {
        1: est(1, 1.01 * torque, 0.01 * torque, 0.021, 0.001),
        2: est(2, 1.10 * torque, 0.01 * torque, 0.02, 0.001),
        3: est(3, None, None, None, None),
    }
    outcome = SimpleNamespace(final=SimpleNamespace(truth=truth, estimates=estimates))
    assert friction_inside(outcome) == {
        "friction_torque_rel": [True, False],
        "coulomb": [True, True],
    }
    found = friction_errors({"friction_torque_nm": 0.1 * torque, "coulomb": 0.001}, truth)
    assert found["friction_torque_rel"] == pytest.approx(0.1) and found["coulomb"] == 0.001
    # without friction the torque's error has no relative size; a fit without it has none
    assert friction_errors({"friction_torque_nm": 0.01}, _truth(0.0))["friction_torque_rel"] is None
    assert friction_errors({"friction_torque_nm": None}, truth)["friction_torque_rel"] is None


# ------------------------------------------------------------------------------ the sweep
def _sweep() -> friction.Sweep:
    """Four seeds at each μ of the sweep, 1.2 times the fit; at μ of 1 % and less the first
    seed's intervals exclude the truth (12 of 16 inside), above it every one holds it."""
    return {
        mu: [seed_result(s, 1.2, inside=s != 0 or mu > 0.01) for s in range(4)]
        for mu in friction.FRICTION_SWEEP
    }


def unmet(found: friction.Sweep) -> list[str]:
    return [v.goal.measured for v in judge(friction.GOALS, friction.figures(found)) if not v.met]


def test_the_sweeps_goals_are_the_worst_mu() -> None:
    good = _sweep()
    assert friction.figures(good) == {"ratio mass_rel": pytest.approx(1.2), "inside": 75.0}
    assert unmet(good) == ["truth inside the 95 % intervals, least over mu and quantities"]
    covered = _sweep()
    covered.update({mu: [seed_result(s, 1.2) for s in range(4)] for mu in (0.0, 0.005, 0.01)})
    assert friction.figures(covered)["inside"] == 100.0 and unmet(covered) == []
    # one μ at which m is 1.6 times the fit's is enough to miss the goal
    covered[0.03] = [seed_result(s, 1.6) for s in range(4)]
    assert friction.figures(covered)["ratio mass_rel"] == pytest.approx(1.6)
    assert unmet(covered) == ["m: robust median / baseline's, worst over mu"]
    # a μ at which a run has no mass: unbounded, not met
    never = [seed_result(0, 1.2, done=60.0), *(seed_result(s, 1.2) for s in range(1, 4))]
    never[0].robust["mass_rel"] = None
    covered[0.03] = never
    assert friction.figures(covered)["ratio mass_rel"] is None
    assert "m: robust median / baseline's, worst over mu" in unmet(covered)


def test_the_sweeps_table_and_plot(tmp_path) -> None:
    found = _sweep()
    late = [seed_result(s, 1.2, done=35.0) for s in range(1, 4)]
    found[0.05] = [seed_result(0, 1.2, done=60.0), *late]
    table = friction.format_friction_sweep(found, "scenario 'paper-floor'")
    rows = {line.split(" | ")[0]: line.split(" | ") for line in table.splitlines()[4:]}
    assert list(rows) == ["| 0", "| 0.5", "| 1", "| 2", "| 3", "| 5"]
    # μ = 2 %: m 0.12 % against the fit's 0.1 %, ratios 1.2, τ_c 5 %, μ 0.1 points, all inside
    assert rows["| 2"][1:5] == ["0.12 / 0.1", "0.48 / 0.4", "4.8 / 4", "2.4 / 2"]
    assert rows["| 2"][5:8] == ["1.2 / 1.2 / 1.2 / 1.2", "5", "0.1"]
    assert rows["| 2"][8] == "100 / 100 / 100 / 100 / 100 / 100"
    assert rows["| 0"][8] == "75 / 75 / 75 / 75 / 75 / 75"
    assert rows["| 2"][9:] == ["4 / 4 / 4", "12.0 / 12.0", "4 / 4 |"]
    assert rows["| 5"][9:11] == ["0 / 3 / 4", "35.0 / 35.0"]  # three done after 30 s, one never
    path = friction.plot_friction_sweep(found, tmp_path / "friction.png", "paper-floor")
    assert path.stat().st_size > 10_000


def test_bench_friction_runs_each_mu_on_the_paper_floor(monkeypatch, capsys, tmp_path) -> None:
    """The sweep's runs: each μ with μ_s = 1.5 μ, the robust estimators alone, by default on
    the paper's load on its four casters; the table, the plot, the goals' verdict."""
    seen: list[tuple[str, noise.NoiseSettings]] = []

    def run(scenarios, settings, on_seed=None):
        seen.append((scenarios(0).name, settings))
        return [seed_result(s, 1.2) for s in range(settings.seeds)]

    monkeypatch.setattr(friction, "run_noise_bench", run)
    plot = tmp_path / "docs" / "friction.png"
    assert main(["bench", "friction", "--seeds", "2", "--plot", str(plot)]) == 0
    assert [s.floor for _, s in seen] == [FloorSettings((mu, mu)) for mu in friction.FRICTION_SWEEP]
    assert {name for name, _ in seen} == {"paper-floor"}
    assert all(s.seeds == 2 and not s.paper_estimators for _, s in seen)
    out = capsys.readouterr().out
    assert "medians over 2 seeds" in out and out.rstrip().endswith("goals: met")
    assert plot.stat().st_size > 10_000
    seen.clear()
    assert main(["bench", "friction", "--generated", "3"]) == 0
    assert {name for name, _ in seen} == {"generated-0"} and seen[0][1].push_damping == 2.0
