"""The ``heft`` command line: ``heft run`` on the paper's scenario end to end (exit status,
results JSON, plots), bad input, every subcommand's ``--help``, and the heft program
(agent/platform/heft.py) that gathers the packages' commands."""

from __future__ import annotations

import contextlib
import io
import json
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import pytest

from agent.platform.heft import BENCH_GROUP, GROUP, build_parser, main
from tests.helpers.paths import PAPER

PLOTS = ("relative_positions.png", "inertia_mass.png", "com_observer.png")
BOUNDS = {
    "mass_rel": 0.005,
    "moment_rel": 0.005,
    "contact_to_com_m": 0.005,
    "relative_positions_m": 0.005,
}


@dataclass
class Invocation:
    """What one call of ``main`` returned and printed."""

    code: int
    stdout: str
    stderr: str


def invoke(*argv: str) -> Invocation:
    """Call ``heft`` with ``argv``, capturing its output (usable in module-scoped fixtures)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return Invocation(code, out.getvalue(), err.getvalue())


PaperRun = tuple[Invocation, dict[str, Any], Path]


@pytest.fixture(scope="module")
def paper(tmp_path_factory: pytest.TempPathFactory) -> PaperRun:
    """``heft run paper.toml --out ... --plot ...``, once for the module."""
    tmp = tmp_path_factory.mktemp("paper")
    out, plots = tmp / "results.json", tmp / "plots"
    ran = invoke("run", str(PAPER), "--out", str(out), "--plot", str(plots))
    return ran, json.loads(out.read_text(encoding="utf-8")), plots


def _is_pair(value: Any) -> bool:
    return isinstance(value, list) and len(value) == 2 and all(isinstance(v, float) for v in value)


def test_run_paper_exits_zero_and_prints_the_table(paper: PaperRun) -> None:
    ran, _, _ = paper
    assert ran.code == 0, ran.stderr
    assert "truth" in ran.stdout and "moment of inertia J" in ran.stdout
    assert max(len(line) for line in ran.stdout.splitlines()) <= 100
    assert "t =" in ran.stderr  # progress lines


def test_run_paper_results_json_has_the_documented_shape(paper: PaperRun) -> None:
    _, results, _ = paper
    assert results["scenario"] == "paper" and results["converged"] is True
    assert results["sim_time_s"] > 0 and results["wall_time_s"] > 0
    assert [p["step"] for p in results["phases"]] == [1, 2, 3, 4, 5, 6, 7]
    for phase in results["phases"]:
        assert 0.0 <= phase["start_s"] <= phase["end_s"] <= results["sim_time_s"]
    assert sorted(results["robots"]) == ["1", "2", "3", "4"]
    neighbours = {"1": ["2"], "2": ["1", "3"], "3": ["2", "4"], "4": ["3"]}
    truth = results["truth"]
    for i, robot in results["robots"].items():
        assert isinstance(robot["mass"], float) and isinstance(robot["moment"], float)
        assert isinstance(robot["omega"], float)
        for key in ("contact_to_com", "centroid_offset", "com_offset", "com_observer"):
            assert _is_pair(robot[key]), key
        assert sorted(robot["relative_positions"]) == neighbours[i]
        assert all(_is_pair(z) for z in robot["relative_positions"].values())
        true_robot = truth["robots"][i]
        assert _is_pair(true_robot["contact_to_com"]) and _is_pair(true_robot["centroid_offset"])
        assert sorted(true_robot["relative_positions"]) == neighbours[i]
    assert truth["mass"] == 5.0 and truth["moment"] == 12.3795
    assert isinstance(truth["omega"], float) and _is_pair(truth["com_offset"])


def test_run_paper_errors_are_within_the_bounds(paper: PaperRun) -> None:
    _, results, _ = paper
    for key, bound in BOUNDS.items():
        value = results["errors"][key]
        assert value is not None and value <= bound, (key, value)


def test_run_paper_writes_non_empty_plots(paper: PaperRun) -> None:
    _, _, plots = paper
    for name in PLOTS:
        path = plots / name
        assert path.is_file() and path.stat().st_size > 10_000, name


BAD_SCENARIOS = {
    "invalid": 'name = "broken"\n[body]\npolygon = [[0, 0], [1, 0]]\nmass = 1.0\n',
    "not-toml": 'name = "broken\n',
    "missing": None,
}


def test_bad_scenario_exits_two_with_one_line(tmp_path: Path) -> None:
    for case, content in BAD_SCENARIOS.items():
        path = tmp_path / f"{case}.toml"
        if content is not None:
            path.write_text(content, encoding="utf-8")
        ran = invoke("run", str(path), "--quiet")
        assert ran.code == 2, case
        assert ran.stderr.startswith("heft: error: ") and str(path) in ran.stderr, case
        assert ran.stderr.count("\n") == 1 and "Traceback" not in ran.stderr, case
        assert ran.stdout == "", case


@pytest.mark.parametrize("port", ["70000", "-1"])
def test_demo_refuses_a_dashboard_port_out_of_range_before_it_starts(port: str) -> None:
    ran = invoke("demo", "--dashboard-port", port, "--no-wait")
    assert ran.code == 2
    assert ran.stderr == f"heft: error: --dashboard-port: expected 0 to 65535, got {port}\n"
    assert ran.stdout == ""


def test_help_works_for_every_command(capsys: pytest.CaptureFixture[str]) -> None:
    commands = (["run"], ["scenario"], ["scenario", "generate"], ["bench"], ["demo"], ["sim"])
    commands += tuple(["bench", name] for name in ("accuracy", "noise", "can", "dashboard"))
    for argv in ([], *commands, ["agent"], ["router"]):
        with pytest.raises(SystemExit) as exit_info:
            main([*argv, "--help"])
        assert exit_info.value.code == 0, argv
        assert "usage: heft" in capsys.readouterr().out, argv


def test_scenario_generate_writes_a_loadable_scenario(tmp_path: Path) -> None:
    from simulator.scenario import load_scenario

    path = tmp_path / "generated.toml"
    ran = invoke("scenario", "generate", "7", "-o", str(path))
    assert ran.code == 0, ran.stderr
    assert load_scenario(path).name == "generated-7"


def test_bench_help_shows_the_benchmark_default(capsys: pytest.CaptureFixture[str]) -> None:
    from simulator.bench.accuracy import DEFAULT_REPEAT

    with pytest.raises(SystemExit):
        main(["bench", "accuracy", "--help"])
    assert f"number of runs with each family (default: {DEFAULT_REPEAT})" in capsys.readouterr().out
    assert build_parser().parse_args(["bench", "accuracy"]).repeat == DEFAULT_REPEAT


def test_no_command_prints_the_help_and_exits_two(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith("usage: heft") and "commands:" in err


def with_broken_entry(monkeypatch: pytest.MonkeyPatch, broken_group: str) -> None:
    """The installed entry points, plus one of ``broken_group`` whose module is not there."""
    entry_points = metadata.entry_points
    broken = metadata.EntryPoint(
        name="broken", value="no_such_package.cli:register", group=broken_group
    )

    def with_broken(group: str):
        installed = list(entry_points(group=group))
        return [*installed, broken] if group == broken_group else installed

    monkeypatch.setattr(metadata, "entry_points", with_broken)


def test_a_package_whose_commands_cannot_be_imported_is_left_out(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    with_broken_entry(monkeypatch, GROUP)
    with pytest.raises(SystemExit) as exited:
        main(["--help"])
    assert exited.value.code == 0
    out, err = capsys.readouterr()
    assert "heft: warning: the broken commands are unavailable" in err
    assert "no_such_package" in err and err.count("\n") == 1
    assert "    run " in out and "    agent " in out


def test_a_package_whose_benchmarks_cannot_be_imported_is_left_out(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    with_broken_entry(monkeypatch, BENCH_GROUP)
    with pytest.raises(SystemExit) as exited:
        main(["bench", "--help"])
    assert exited.value.code == 0
    out, err = capsys.readouterr()
    assert "heft: warning: the broken benchmarks are unavailable" in err
    assert "no_such_package" in err and err.count("\n") == 1
    assert "    accuracy " in out and "    can " in out


# ------------------------------------------------------------------------------ heft bench
BENCH_OPTIONS = {
    "accuracy": {"--repeat": "2"},
    "generated": {"--count": "2"},
    "zenoh": {"--sizes": "4"},
    "noise": {"--seeds": "2", "--first-seed": "2", "--generated": "2", "--ideal-drives": None},
    "sweep": {
        "--seeds": "2",
        "--first-seed": "2",
        "--generated": "2",
        "--ideal-drives": None,
        "--plot": "plots",
    },
    "changes": {"--seeds": "2", "--first-seed": "2"},
    "can": {"--channel": "vcan1", "--seconds": "2", "--period-ms": "5"},
    "dashboard": {},
}
"""Each benchmark's options, and a value each accepts (None: a flag)."""


def test_each_benchmark_takes_its_own_options_and_refuses_the_others(capsys) -> None:
    parser = build_parser()
    everyone = {option: value for own in BENCH_OPTIONS.values() for option, value in own.items()}
    for benchmark, own in BENCH_OPTIONS.items():
        for option, value in everyone.items():
            argv = ["bench", benchmark, option] + ([] if value is None else [value])
            if option in own:
                args = parser.parse_args(argv)
                assert args.benchmark == benchmark and callable(args.handler)
                continue
            with pytest.raises(SystemExit) as exited:
                parser.parse_args(argv)
            assert exited.value.code == 2, argv
            err = capsys.readouterr().err
            assert f"heft bench {benchmark}: error: unrecognized arguments: {option}" in err, err


def test_noise_takes_a_scenario_or_the_generated_ones_not_both(capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        build_parser().parse_args(["bench", "noise", "--generated", "3", str(PAPER)])
    assert exited.value.code == 2
    assert "not allowed with argument --generated" in capsys.readouterr().err


@pytest.mark.parametrize("old", ["--noise", "--can", "--dashboard", "--generated", "--transport"])
def test_the_old_bench_flags_are_refused(old: str, capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["bench", old])
    assert exited.value.code == 2
    assert f"heft bench: error: unrecognized arguments: {old}" in capsys.readouterr().err
