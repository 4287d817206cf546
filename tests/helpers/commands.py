"""``heft`` command lines where people read them: found in shell text, Markdown code blocks and
unit files, and checked against the real parser (every option one its ``--help`` lists, the
whole line one argparse accepts), and the commands the packages register."""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import shlex
from importlib import metadata
from pathlib import Path

import pytest

from agent.platform.heft import BENCH_GROUP, GROUP


def registered(group: str) -> set[str]:
    """The subcommands the packages of the entry-point group ``group`` register."""
    names: set[str] = set()
    for entry in metadata.entry_points(group=group):
        commands = argparse.ArgumentParser().add_subparsers()
        entry.load()(commands)
        names.update(commands.choices)
    return names


def registered_commands() -> set[str]:
    """Every ``heft`` command: the packages' and ``heft bench`` (the heft program's own)."""
    return registered(GROUP) | {"bench"}


def registered_benchmarks() -> set[str]:
    """Every ``heft bench`` benchmark the packages register."""
    return registered(BENCH_GROUP)


def split_commands(words: list[str]) -> list[list[str]]:
    """``words`` of a shell line cut at ``&&``, ``||``, ``;``, ``|``, each command without a
    leading ``sudo`` (and its options) or environment assignments."""
    commands, current = [], []
    for word in [*words, ";"]:
        if word in ("&&", "||", ";", "|", "&"):
            if current:
                commands.append(current)
            current = []
        else:
            current.append(word)
    stripped = []
    for command in commands:
        while command and re.match(r"^[A-Za-z_][A-Za-z0-9_]*=", command[0]):
            command = command[1:]
        if command and command[0] == "sudo":
            command = command[1:]
            while command and command[0].startswith("-"):
                command = command[2:] if command[0] in ("-u", "-g") else command[1:]
        stripped.append(command)
    return stripped


def shell_words(line: str) -> list[str]:
    lexer = shlex.shlex(line, posix=True, punctuation_chars=";&|")
    lexer.whitespace_split = True
    lexer.commenters = "#"
    return list(lexer)


def heft_command_lines(text: str) -> list[list[str]]:
    """The arguments of every ``heft`` (or ``/opt/heft/.venv/bin/heft``) command in shell
    text or ``ExecStart=`` lines (backslash continuations joined)."""
    found = []
    for line in re.sub(r"\\\n", " ", text).splitlines():
        line = re.sub(r"^\s*ExecStart=[-@:+!]*", "", line)
        for command in split_commands(shell_words(line)):
            if command and Path(command[0]).name == "heft":
                found.append(command[1:])
    return found


def code_blocks(markdown: str, language: str = "[a-z0-9]*") -> list[str]:
    """The fenced code blocks of ``markdown`` (of ``language`` only, a regular expression)."""
    return re.findall(rf"^```{language}\n(.*?)^```", markdown, flags=re.S | re.M)


def prose(markdown: str) -> str:
    return re.sub(r"^```[a-z0-9]*\n.*?^```", "", markdown, flags=re.S | re.M)


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def leaf(heft: argparse.ArgumentParser, argv: list[str]) -> tuple[str, argparse.ArgumentParser]:
    """The (sub)subcommand ``argv`` names, as ``"deploy certs"`` or ``"bench calibrate
    arc-correlation"``, and its parser; a placeholder in capitals (``heft bench BENCHMARK``)
    names the command above it."""
    commands = subcommands(heft)
    assert argv and argv[0] in commands, f"heft {' '.join(argv)}: no such command"
    name, parser = argv[0], commands[argv[0]]
    for word in argv[1:]:
        nested = subcommands(parser)
        if not nested or word.isupper() or word.startswith("-"):
            break
        assert word in nested, f"heft {' '.join(argv)}: no such command"
        name, parser = f"{name} {word}", nested[word]
    return name, parser


def assert_options_listed(heft, argv: list[str], where: str) -> None:
    """Every option in ``argv`` is written out in its command's ``--help`` (no abbreviation,
    nothing the help does not list)."""
    name, parser = leaf(heft, argv)
    text = parser.format_help()
    for word in argv:
        if word == "--":
            break
        if word.startswith("-") and len(word) > 1:
            option = word.split("=", 1)[0]
            listed = re.search(rf"(?<![\w-]){re.escape(option)}(?![\w-])", text)
            assert listed, f"{where}: heft {name} has no option {option}: {' '.join(argv)}"


def assert_parses(heft, argv: list[str], where: str) -> argparse.Namespace:
    """``heft ARGV`` is a complete, valid command line (as argparse would run it)."""
    assert_options_listed(heft, argv, where)
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            args = heft.parse_args(argv)
    except SystemExit:
        pytest.fail(f"{where}: heft {' '.join(argv)}: {err.getvalue().strip()}")
    assert getattr(args, "handler", None) is not None, f"{where}: heft {' '.join(argv)}"
    return args
