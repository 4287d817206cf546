"""Estimator families as strategies: chosen once, each behind one interface, each with its own
tuning table; the phase machine and the pipeline read each other only through
``agent/algorithm/interfaces.py``."""

from __future__ import annotations

import ast
import typing
from pathlib import Path

import pytest

from agent.algorithm import interfaces
from agent.algorithm.agent import Agent
from agent.algorithm.paper.phases import PaperPhases
from agent.algorithm.paper.pipeline import PaperPipeline
from agent.algorithm.robust.phases import RobustPhases
from agent.algorithm.robust.pipeline import RobustPipeline
from agent.algorithm.tuning import AgentConfig, AgentTuning, Estimators
from agent.platform.config import ConfigError, from_table
from simulator.scenario import ScenarioError, load_scenario
from tests.helpers.paths import ROOT

ALGORITHM = ROOT / "agent" / "algorithm"


def agent_of(estimator: Estimators) -> Agent:
    tuning = AgentTuning(estimator=estimator)
    return Agent(AgentConfig(robot=1, n=3, neighbours=(2,), period_s=0.01, tuning=tuning))


def test_each_estimator_value_chooses_its_familys_pipeline_and_phases() -> None:
    paper, robust = agent_of(Estimators.PAPER), agent_of(Estimators.ROBUST)
    assert (type(paper.pipeline), type(paper.phase_machine)) == (PaperPipeline, PaperPhases)
    assert (type(robust.pipeline), type(robust.phase_machine)) == (RobustPipeline, RobustPhases)


def test_no_module_asks_which_family_it_runs() -> None:
    """Only the registry and the tuning name a family: nothing branches on it."""
    naming = {
        path.relative_to(ROOT).as_posix()
        for path in ALGORITHM.rglob("*.py")
        if "Estimators." in path.read_text(encoding="utf-8")
        or ".estimator ==" in path.read_text(encoding="utf-8")
        or "robust" in _names(path)
    }
    assert naming == {"agent/algorithm/families.py", "agent/algorithm/tuning.py"}, naming


def _names(path: Path) -> set[str]:
    """The attribute and variable names ``path`` uses (``self.robust`` gives ``robust``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and node.attr == "robust":
            if not (isinstance(node.value, ast.Attribute) and node.value.attr == "tuning"):
                names.add("robust")
        elif isinstance(node, ast.Name) and node.id == "robust":
            names.add("robust")
    if path.name == "tuning.py" or path.parent.name in ("robust",):
        names.discard("robust")  # the family's own table, read by the family
    return names


def _attributes_read(path: Path, variable: str) -> set[str]:
    """Every ``variable.attr`` in the module at ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return {
        node.attr
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute)
        and isinstance(node.value, ast.Name)
        and node.value.id == variable
    }


def _members(protocol: type) -> set[str]:
    own = {n for n in vars(protocol) if not n.startswith("_")}
    return (
        own
        | set(typing.get_type_hints(protocol))
        | {n for base in protocol.__mro__[1:] for n in vars(base) if not n.startswith("_")}
    )


@pytest.mark.parametrize(
    ("modules", "variable", "protocol"),
    [
        (["phase_machine.py", "paper/phases.py", "robust/phases.py"], "own", "OwnEstimates"),
        (["pipeline.py", "paper/pipeline.py", "robust/pipeline.py"], "schedule", "ProbeSchedule"),
    ],
)
def test_the_phase_machine_and_the_pipeline_read_each_other_only_through_the_interfaces(
    modules: list[str], variable: str, protocol: str
) -> None:
    allowed = _members(getattr(interfaces, protocol))
    for module in modules:
        read = _attributes_read(ALGORITHM / module, variable)
        assert read <= allowed, (module, sorted(read - allowed))


@pytest.mark.parametrize(
    ("table", "message"),
    [
        (
            {"push_force": 2.0},
            r"agent\.push_force: this key lives in the 'robust' table now: "
            r"agent\.robust\.push_force",
        ),
        ({"filter_gain": 5.0}, r"agent\.paper\.filter_gain"),
        ({"settle_uncertainty": 0.01}, r"agent\.robust\.settle_uncertainty"),
        ({"robust": {"push_force": 2000.0}}, r"agent\.robust\.push_force: expected a positive"),
        (
            {"robust": {"push_force": 20.0}},
            r"agent\.robust\.push_force: expected at most max_force",
        ),
        ({"paper": {"push_min_force": 20.0}}, r"agent\.paper\.push_min_force: expected at most"),
        ({"paper": {"push_force": 2.0}}, r"agent\.paper\.push_force: unknown key"),
    ],
)
def test_a_familys_keys_live_in_its_own_table(table: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        from_table(AgentTuning, table, "agent")


def test_a_scenario_with_an_old_key_is_refused_naming_its_new_place(tmp_path: Path) -> None:
    text = (ROOT / "simulator" / "scenarios" / "paper.toml").read_text(encoding="utf-8")
    old = tmp_path / "old.toml"
    old.write_text(text.replace('estimator = "paper"', 'estimator = "robust"\npush_force = 2.0'))
    with pytest.raises(ScenarioError, match=r"agent\.robust\.push_force"):
        load_scenario(old)
    new = tmp_path / "new.toml"
    new.write_text(text.replace("[agent]", "[agent.robust]\npush_force = 2.5\n\n[agent]"))
    assert load_scenario(new).agent.robust.push_force == 2.5


def test_a_familys_durations_are_checked_against_the_sensor_period() -> None:
    tuning = from_table(AgentTuning, {"robust": {"probe_s": 0.02}}, "agent")
    with pytest.raises(ConfigError, match=r"agent\.robust\.probe_s: .*at least 4 ticks"):
        tuning.check_period("agent", 0.01, "sensors.rate_hz = 100")
