"""The product's layout: its top-level packages and nothing else, its packages in layers that
import only downwards (function-level and ``TYPE_CHECKING`` imports included), no import cycle
between its modules, and one ``heft`` command listing every package's commands. (Light modules
that stay light, in fresh interpreters: tests/integration/test_import_weight.py.)"""

from __future__ import annotations

import ast
import re
import tomllib
from pathlib import Path

import pytest

from agent.platform.heft import BENCH_GROUP, GROUP, main
from tests.helpers.commands import registered
from tests.helpers.paths import ROOT

PRODUCT_PACKAGES = ("agent", "simulator", "bridge", "dashboard")
"""The packages the product ships (bridge and dashboard once they exist)."""
TOP_LEVEL = {*PRODUCT_PACKAGES, "tests", "deploy"}
COMMANDS = {"run", "scenario", "bench", "agent", "sim", "router", "demo", "deploy"}
BENCHMARKS = {"accuracy", "generated", "zenoh", "noise", "sweep", "changes", "can", "dashboard"}
LAYERS: tuple[tuple[str, ...], ...] = (
    ("agent.platform",),
    ("agent.security", "agent.algorithm"),
    ("agent",),
    ("bridge", "dashboard"),
    ("simulator",),
)
"""The product's units, lowest first: a module imports only from its own unit and from units
of lower layers; the units of one layer do not import each other. A unit is a package less
its sub-packages that are units of their own (``agent`` is ``agent.node``, ``agent.cli`` and
``agent.__main__``). The platform (protocol, config, Zenoh, processes) stands on nothing of
the project; security (certificates, access control) and the robot's algorithm on the
platform; the agent's process and commands on both; the AGV bridge and the dashboard beside
each other on the agent; the simulator, which runs the others (plant, launcher, benchmarks,
the run's recording and dashboard), on top. ``heft`` finds each package's commands and
benchmarks through entry points (``agent.platform.heft``), not imports."""


# ------------------------------------------------------------------------------ the tree
def test_the_top_level_tree_has_only_the_products_packages() -> None:
    directories = [p for p in ROOT.iterdir() if p.is_dir() and not p.name.startswith(".")]
    with_python = {p.name for p in directories if next(p.rglob("*.py"), None) is not None}
    assert with_python <= TOP_LEVEL - {"deploy"}, sorted(with_python - TOP_LEVEL)
    packages = {p.name for p in directories if (p / "__init__.py").is_file()}
    assert {"agent", "simulator", "tests"} <= packages
    assert packages <= set(PRODUCT_PACKAGES) | {"tests"}, sorted(packages)
    assert (ROOT / "deploy").is_dir() and "deploy" not in packages
    assert sorted(p.name for p in ROOT.glob("*.py")) == []  # no top-level module


def test_the_distribution_ships_only_the_products_packages() -> None:
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    include = pyproject["tool"]["setuptools"]["packages"]["find"]["include"]
    assert {pattern.rstrip("*") for pattern in include} <= set(PRODUCT_PACKAGES), include
    assert pyproject["project"]["scripts"] == {"heft": "agent.platform.heft:main"}
    declared = pyproject["project"]["entry-points"][GROUP]
    assert set(declared) <= set(PRODUCT_PACKAGES), declared
    for package, target in declared.items():
        assert target == f"{package}.cli:register", (package, target)
    benchmarks = pyproject["project"]["entry-points"][BENCH_GROUP]
    assert set(benchmarks) == {"simulator", "bridge", "dashboard"}, benchmarks
    for package, target in benchmarks.items():
        assert target == f"{package}.bench.cli:register", (package, target)


# ------------------------------------------------------------------------------ import graph
def project_modules(
    root: Path = ROOT, packages: tuple[str, ...] = PRODUCT_PACKAGES
) -> dict[str, Path]:
    """Every module of ``packages`` under ``root``, by dotted name (a package by its own
    name)."""
    modules = {}
    for package in packages:
        if not (root / package / "__init__.py").is_file():
            continue
        for path in sorted((root / package).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join(parts)] = path
    return modules


def imported_names(path: Path, module: str) -> set[str]:
    """Every name ``path`` imports, anywhere in it (functions and ``TYPE_CHECKING`` included):
    ``import a.b`` gives ``a.b``; ``from a.b import c`` gives ``a.b`` and ``a.b.c``."""
    is_package = path.name == "__init__.py"
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                here = module.split(".") if is_package else module.split(".")[:-1]
                base = ".".join(here[: len(here) - node.level + 1] + [node.module or ""])
                base = base.strip(".")
            else:
                base = node.module or ""
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)
    return names


def import_graph(
    root: Path = ROOT, packages: tuple[str, ...] = PRODUCT_PACKAGES
) -> dict[str, set[str]]:
    """Module -> the modules of ``packages`` it imports."""
    modules = project_modules(root, packages)
    return {
        name: {other for other in imported_names(path, name) if other in modules} - {name}
        for name, path in modules.items()
    }


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as ``[a, b, ..., a]``, or None (depth-first, no recursion)."""
    state: dict[str, str] = {}  # "open" while on the current path, then "done"
    for start in sorted(graph):
        if start in state:
            continue
        path, stack = [start], [iter(sorted(graph[start]))]
        state[start] = "open"
        while stack:
            nxt = next(stack[-1], None)
            if nxt is None:
                stack.pop()
                state[path.pop()] = "done"
            elif state.get(nxt) == "open":
                return path[path.index(nxt) :] + [nxt]
            elif nxt not in state:
                state[nxt] = "open"
                path.append(nxt)
                stack.append(iter(sorted(graph.get(nxt, ()))))
    return None


def unit_of(module: str, layers: tuple[tuple[str, ...], ...]) -> str | None:
    """The unit of ``layers`` that ``module`` belongs to (the longest that prefixes it)."""
    units = [u for layer in layers for u in layer if module == u or module.startswith(u + ".")]
    return max(units, key=len, default=None)


def upward_imports(
    graph: dict[str, set[str]], layers: tuple[tuple[str, ...], ...]
) -> list[tuple[str, str]]:
    """Every ``(importer, imported)`` of ``graph`` that does not go to the importer's own unit
    or to a lower layer (an import within a layer, between two units, is one too); a module
    in no unit imports ``None``."""
    rank = {unit: i for i, layer in enumerate(layers) for unit in layer}
    wrong = []
    for module, imported in sorted(graph.items()):
        here = unit_of(module, layers)
        if here is None:
            wrong.append((module, None))
            continue
        for other in sorted(imported):
            there = unit_of(other, layers)
            if there != here and (there is None or rank[there] >= rank[here]):
                wrong.append((module, other))
    return wrong


def test_upward_imports_are_found_wherever_they_are(tmp_path: Path) -> None:
    files = {
        "low/__init__.py": "",
        "low/base.py": "def f():\n    from high import top\n",  # upwards, in a function
        "low/sub/__init__.py": "from low import base\n",
        "high/__init__.py": "",
        "high/top.py": "import low.base\nfrom low.sub import thing\n",  # downwards
        "side/__init__.py": "",
        "side/x.py": (
            "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from high.top import T\n"
        ),
        "loose/__init__.py": "",
    }
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text, encoding="utf-8")
    graph = import_graph(tmp_path, ("low", "high", "side", "loose"))
    layers = (("low",), ("high", "side"))
    assert upward_imports(graph, layers) == [
        ("loose", None),
        ("low.base", "high"),
        ("low.base", "high.top"),
        ("side.x", "high.top"),  # a unit of the same layer
    ]
    assert upward_imports(graph, (("low.sub",), ("low",), ("high", "side", "loose"))) == [
        ("low.base", "high"),
        ("low.base", "high.top"),
        ("low.sub", "low"),  # a sub-package that is a unit of its own, below its parent
        ("low.sub", "low.base"),
        ("side.x", "high.top"),
    ]


def test_every_import_goes_down_the_layers() -> None:
    graph = import_graph()
    assert "dashboard.cli" in graph and "simulator.baseline" in graph
    assert "agent.platform.heft" in graph["simulator.cli"]  # a function-level import
    assert upward_imports(graph, LAYERS) == []


def test_find_cycle() -> None:
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"b"}}) == ["b", "c", "b"]


def test_imported_names_sees_every_import(tmp_path: Path) -> None:
    path = tmp_path / "mod.py"
    path.write_text(
        "from typing import TYPE_CHECKING\n"
        "import agent.platform.protocol\n"
        "if TYPE_CHECKING:\n"
        "    from simulator.inprocess import RunOutcome\n"
        "def f():\n"
        "    from . import results\n"
        "    from .plots import write_plots\n",
        encoding="utf-8",
    )
    names = imported_names(path, "simulator.cli")
    assert {"agent.platform.protocol", "simulator.inprocess", "simulator.results"} <= names
    assert {"simulator.plots", "simulator.plots.write_plots"} <= names


def test_no_import_cycle_between_the_products_modules() -> None:
    graph = import_graph()
    assert "agent.platform.heft" in graph and "simulator.cli" in graph
    assert "simulator.inprocess" in graph["simulator.cli"]  # a function-level import
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


# ------------------------------------------------------------------------------ heft --help
def listed(help_text: str, title: str, metavar: str) -> list[str]:
    """The subcommands a help text lists under ``title``, asserting one line each."""
    block = help_text.split(f"\n{title}:\n", 1)[1].split("\n\n", 1)[0].splitlines()
    assert block[0].strip() == metavar, block
    found = [re.match(r"^    (\S+) +\S", line) for line in block[1:]]
    assert all(found), block  # no continuation line: one line per subcommand
    return sorted(m.group(1) for m in found if m)


def test_heft_help_lists_every_registered_command_on_one_line(capsys, monkeypatch) -> None:
    monkeypatch.setenv("COLUMNS", "80")
    commands = registered(GROUP) | {"bench"}  # heft bench: the heft program's own
    assert commands >= COMMANDS
    with pytest.raises(SystemExit) as exited:
        main(["--help"])
    assert exited.value.code == 0
    assert listed(capsys.readouterr().out, "commands", "COMMAND") == sorted(commands)


def test_heft_bench_help_lists_every_registered_benchmark_on_one_line(capsys, monkeypatch) -> None:
    monkeypatch.setenv("COLUMNS", "80")
    benchmarks = registered(BENCH_GROUP)
    assert benchmarks >= BENCHMARKS
    with pytest.raises(SystemExit) as exited:
        main(["bench", "--help"])
    assert exited.value.code == 0
    assert listed(capsys.readouterr().out, "benchmarks", "BENCHMARK") == sorted(benchmarks)


def test_heft_bench_without_a_benchmark_prints_its_help_and_exits_two(capsys) -> None:
    assert main(["bench"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith("usage: heft bench")
    assert listed(err, "benchmarks", "BENCHMARK") == sorted(registered(BENCH_GROUP))
