"""Bad input for the ``heft`` command: scenario and robot files with chosen values, and the one
``heft: error:`` line they must get."""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Any

from agent.platform.config import toml_value
from agent.platform.heft import main
from tests.helpers.paths import PAPER


def paper() -> dict[str, Any]:
    """The paper's scenario file as TOML tables."""
    return tomllib.loads(PAPER.read_text(encoding="utf-8"))


def with_values(data: dict[str, Any], values: dict[str, Any]) -> dict[str, Any]:
    """``data`` with ``{"table.key": value}`` set (``None`` removes the key)."""
    data = copy.deepcopy(data)
    for dotted, value in values.items():
        *tables, key = dotted.split(".")
        table = data
        for name in tables:
            table = table.setdefault(name, {})
        if value is None:
            table.pop(key, None)
        else:
            table[key] = value
    return data


def write_toml(path: Path, data: dict[str, Any]) -> Path:
    """``data`` (two levels of tables at most) written to ``path`` as TOML."""
    lines = [f"{k} = {toml_value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    for name, table in data.items():
        if isinstance(table, dict):
            lines += ["", f"[{name}]"]
            lines += [f"{k} = {toml_value(v)}" for k, v in table.items() if not isinstance(v, dict)]
            for sub, inner in table.items():
                if isinstance(inner, dict):
                    lines += ["", f"[{name}.{sub}]"]
                    lines += [f"{k} = {toml_value(v)}" for k, v in inner.items()]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def scenario_file(tmp_path: Path, values: dict[str, Any], base: dict | None = None) -> Path:
    """The paper's scenario (or ``base``) with ``values`` set, as a file in ``tmp_path``."""
    return write_toml(tmp_path / "s.toml", with_values(paper() if base is None else base, values))


ROBOT = {"robot": 1, "n": 2, "neighbours": [2]}


def robot_file(tmp_path: Path, values: dict[str, Any]) -> Path:
    """A minimal robot.toml with ``values`` set, as a file in ``tmp_path``."""
    return write_toml(tmp_path / "robot.toml", with_values(ROBOT, values))


def one_error_line(capsys, *words: str) -> str:
    """The one ``heft: error:`` line on stderr, which names each of ``words``."""
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err, err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("heft: error: "), err
    for word in words:
        assert word in lines[0], (word, lines[0])
    return lines[0]


def refused(capsys, argv: list[str], *words: str, status: int = 2) -> str:
    """``heft argv`` in this process exits ``status`` with one error line naming ``words``."""
    assert main(argv) == status
    return one_error_line(capsys, *words)
