"""``heft bench generated``: its goals and the exit status they give, on real runs of the
default estimators on the paper's load and on the load of the generated scenario of seed 0,
their estimates of m, J and ``contact_to_com`` made exact (the goals' arithmetic, not the
estimators' accuracy, which the benchmark itself reports), and on copies of them that did not
converge or missed an accuracy goal."""

from __future__ import annotations

import dataclasses

import pytest

from agent.algorithm.tuning import AgentTuning, Estimators
from agent.platform.goals import judge
from agent.platform.heft import build_parser, main
from simulator.bench import generated


def _exact(outcome: generated.RunOutcome) -> generated.RunOutcome:
    """``outcome`` with every robot's m, J and ``contact_to_com`` those of the truth."""
    truth = outcome.final.truth
    exact = {
        i: dataclasses.replace(
            e, mass=truth.mass, moment=truth.moment, contact_to_com=truth.contact_to_com[i - 1]
        )
        for i, e in outcome.final.estimates.items()
    }
    return dataclasses.replace(outcome, final=dataclasses.replace(outcome.final, estimates=exact))


@pytest.fixture(scope="module")
def seed_0() -> generated.RunOutcome:
    (outcome,) = generated.run_generated(1)
    assert outcome.converged and outcome.scenario.name == "generated-0"
    assert outcome.scenario.agent == AgentTuning()  # the defaults, not the scenario's reference
    return _exact(outcome)


@pytest.fixture(scope="module")
def paper() -> generated.RunOutcome:
    outcome = generated.run_paper()
    assert outcome.converged and outcome.scenario.agent.estimator is Estimators.ROBUST
    return _exact(outcome)


@pytest.mark.parametrize("failed, status", [(0, 0), (1, 1)])
def test_bench_generated_exits_1_when_a_run_did_not_converge(
    monkeypatch, capsys, seed_0, paper, failed, status
) -> None:
    outcomes = [seed_0, dataclasses.replace(seed_0, converged=not failed)]
    asked = []

    def run(count: int, on_run) -> list[generated.RunOutcome]:
        asked.append(count)
        return outcomes

    monkeypatch.setattr(generated, "run_generated", run)
    monkeypatch.setattr(generated, "run_paper", lambda: paper)
    assert main(["bench", "generated", "-n", "2"]) == status
    out = capsys.readouterr().out
    assert asked == [2]
    assert f"generated loads: seeds 0..1, converged {2 - failed}/2, on their floor 2/2" in out
    verdict = "NOT met" if failed else "met"
    share = "66.7 %" if failed else "100 %"  # of the three runs, the paper's load's among them
    (line,) = [row for row in out.splitlines() if row.startswith("  runs converged ")]
    assert line.endswith(f" {share}  (at least 100 %): {verdict}")
    assert out.endswith(f"goals: {verdict}\n")


def test_the_accuracy_goals_are_the_default_estimators_noise_free_ones(seed_0, paper) -> None:
    """On the paper's load m within 0.01 %, J within 0.05 % and ``contact_to_com`` within
    1 mm; the generated loads' medians within 0.1 %, 0.1 % and 2 mm: met by exact estimates,
    and missed by a run whose J is 10 % off."""
    found = generated.figures(paper, [seed_0])
    verdicts = {v.goal.key: v.met for v in judge(generated.GOALS, found)}
    assert all(verdicts.values()), found
    bounds = {g.key: (g.bound, g.unit) for g in generated.GOALS}
    assert bounds["paper mass_rel"] == (0.01, "%") and bounds["paper moment_rel"] == (0.05, "%")
    assert bounds["paper contact_to_com_m"] == (1.0, "mm")
    assert bounds["median mass_rel"] == bounds["median moment_rel"] == (0.1, "%")
    assert bounds["median contact_to_com_m"] == (2.0, "mm")
    truth = paper.final.truth
    off = {
        i: dataclasses.replace(e, moment=1.1 * truth.moment)
        for i, e in paper.final.estimates.items()
    }
    wrong = dataclasses.replace(paper, final=dataclasses.replace(paper.final, estimates=off))
    found = generated.figures(wrong, [seed_0])
    assert found["paper moment_rel"] == pytest.approx(10.0)
    missed = [v.goal.key for v in judge(generated.GOALS, found) if not v.met]
    assert missed == ["paper moment_rel"]


def test_the_default_count_is_the_helps(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["bench", "generated", "--help"])
    assert f"(default: {generated.DEFAULT_COUNT})" in capsys.readouterr().out
    assert build_parser().parse_args(["bench", "generated"]).count == generated.DEFAULT_COUNT
