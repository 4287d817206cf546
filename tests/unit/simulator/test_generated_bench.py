"""``heft bench generated``: its goal (every run converged) and the exit status it gives, on one
real run of the generated scenario of seed 0 and a copy of it that did not converge."""

from __future__ import annotations

import dataclasses

import pytest

from agent.platform.heft import build_parser, main
from simulator.bench import generated


@pytest.fixture(scope="module")
def seed_0() -> generated.RunOutcome:
    (outcome,) = generated.run_generated(1)
    assert outcome.converged and outcome.scenario.name == "generated-0"
    return outcome


@pytest.mark.parametrize("failed, status", [(0, 0), (1, 1)])
def test_bench_generated_exits_1_when_a_run_did_not_converge(
    monkeypatch, capsys, seed_0, failed, status
) -> None:
    outcomes = [seed_0, dataclasses.replace(seed_0, converged=not failed)]
    asked = []

    def run(count: int, on_run) -> list[generated.RunOutcome]:
        asked.append(count)
        return outcomes

    monkeypatch.setattr(generated, "run_generated", run)
    assert main(["bench", "generated", "-n", "2"]) == status
    out = capsys.readouterr().out
    assert asked == [2]
    assert out.startswith(f"heft bench generated: seeds 0..1, converged {2 - failed}/2")
    verdict = "NOT met" if failed else "met"
    share = "50 %" if failed else "100 %"
    assert f"runs converged  {share}  (at least 100 %): {verdict}\ngoals: {verdict}\n" in out


def test_the_default_count_is_the_helps(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["bench", "generated", "--help"])
    assert f"(default: {generated.DEFAULT_COUNT})" in capsys.readouterr().out
    assert build_parser().parse_args(["bench", "generated"]).count == generated.DEFAULT_COUNT
