"""The docs as a newcomer meets them: a README of at most 200 lines whose first screen gives
exactly two commands, ``make demo`` and ``make test``; every relative link of the README, the
changelog, the deployment guide and docs/ pointing at a file that exists (and at a heading of
it, for an anchor), and every document a message, a comment or a unit names existing; no
README but the top one and the deployment guide; docs/cli.md with a
section for every ``heft`` command the packages register; and every ``heft`` command line the
docs show one the command's parser accepts. (The limits are checked against the code in
tests/unit/agent/test_input_bounds.py, the deployment guide's commands and files in
tests/unit/agent/test_deploy_files.py.)"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

from tests.helpers.commands import (
    assert_options_listed,
    assert_parses,
    code_blocks,
    heft_command_lines,
    prose,
    registered_benchmarks,
    registered_commands,
)
from tests.helpers.paths import ROOT

README = ROOT / "README.md"
DEPLOY_GUIDE = ROOT / "deploy" / "README.md"
DOCS = sorted((ROOT / "docs").glob("*.md"))
PAGES = [README, ROOT / "CHANGELOG.md", DEPLOY_GUIDE, *DOCS]
MAX_README_LINES = 200
FIRST_SCREEN = 40
"""Lines a newcomer sees before scrolling."""
COMMAND_WORDS = r"(make|heft|sudo|apt-get|apt|bash|sh|python3?|pip|npm|git|cd)"
"""The first word of what a reader would take for a command to type."""
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
"""A Markdown link or image, ``[text](target)``."""
SKIPPED_FOLDERS = {"node_modules", "out", "__pycache__"}
"""Folders of the working tree that are not the repository's (besides hidden and egg-info)."""


def page_id(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


# ------------------------------------------------------------------------------ the README
def test_the_readme_is_at_most_200_lines() -> None:
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= MAX_README_LINES, len(lines)


def test_the_readmes_first_screen_gives_exactly_make_demo_and_make_test() -> None:
    screen = "\n".join(README.read_text(encoding="utf-8").splitlines()[:FIRST_SCREEN])
    assert screen.count("```") % 2 == 0, "a code block runs past the first screen"
    typed = [
        line.split("#", 1)[0].strip()
        for block in code_blocks(screen)
        for line in block.splitlines()
        if line.split("#", 1)[0].strip()
    ]
    assert typed == ["make demo", "make test"], typed
    inline = [
        span for span in re.findall(r"`([^`\n]+)`", prose(screen)) if re.match(COMMAND_WORDS, span)
    ]
    assert inline == [], f"other commands in the first screen: {inline}"


def test_there_is_no_readme_but_the_top_one_and_the_deployment_guide() -> None:
    found = []
    for folder, subfolders, files in os.walk(ROOT):
        subfolders[:] = [
            name
            for name in subfolders
            if not name.startswith(".")
            and not name.endswith(".egg-info")
            and name not in SKIPPED_FOLDERS
        ]
        found += [page_id(Path(folder) / name) for name in files if name.startswith("README")]
    assert sorted(found) == ["README.md", "deploy/README.md"]


# ------------------------------------------------------------------------------ links
def slugs(markdown: str) -> set[str]:
    """The anchors of ``markdown``'s headings, as GitHub makes them: lower case, punctuation
    dropped, spaces as hyphens, a repeated one numbered."""
    seen: dict[str, int] = {}
    anchors = set()
    for heading in re.findall(r"^#{1,6} +(.+?) *$", prose(markdown), flags=re.M):
        slug = re.sub(r"[^\w\- ]", "", heading.lower()).replace(" ", "-")
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        anchors.add(slug if count == 0 else f"{slug}-{count}")
    return anchors


def test_slugs_are_githubs() -> None:
    text = "# Heft\n## 6. Bench test: `heft sim` stands in\n## A, b\n## A, b\n```sh\n# no\n```\n"
    assert slugs(text) == {"heft", "6-bench-test-heft-sim-stands-in", "a-b", "a-b-1"}


@pytest.mark.parametrize("page", PAGES, ids=page_id)
def test_every_relative_link_points_at_a_file_and_heading_that_exist(page: Path) -> None:
    links = LINK.findall(prose(page.read_text(encoding="utf-8")))
    assert links or page.name == "CHANGELOG.md", f"{page_id(page)} links to nothing"
    for target in links:
        if re.match(r"^[a-z]+:", target):  # https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        linked = (page.parent / path).resolve() if path else page
        assert linked.exists(), f"{page_id(page)}: {target}: no such file"
        assert ROOT in linked.parents or linked == ROOT, f"{page_id(page)}: {target}"
        if anchor:
            headings = slugs(linked.read_text(encoding="utf-8"))
            assert anchor in headings, f"{page_id(page)}: {target}: no such heading"


def test_every_document_the_code_and_the_deployed_files_name_exists() -> None:
    """``deploy/README.md`` in an error message, ``docs/can-bridge.md`` in a robot's file or a
    unit's ``Documentation=file:///opt/heft/...``: each is a path from the repository's root."""
    named = 0
    for folder in ("agent", "bridge", "simulator", "dashboard", "deploy"):
        for path in (ROOT / folder).rglob("*"):
            if "node_modules" in path.parts or path.suffix == ".md" or not path.is_file():
                continue
            if path.suffix not in (".py", ".toml", ".service", ".json5", ".sh", ".dbc"):
                continue
            text = path.read_text(encoding="utf-8")
            for name in re.findall(r"(?:/opt/heft/|(?<![\w./-]))((?:[\w-]+/)*[\w-]+\.md)\b", text):
                named += 1
                assert (ROOT / name).is_file(), f"{page_id(path)} names {name}"
    assert named >= 10, named


def test_the_readme_links_every_page_of_docs() -> None:
    linked = {target.partition("#")[0] for target in LINK.findall(README.read_text("utf-8"))}
    assert {page_id(page) for page in DOCS} <= linked


# ------------------------------------------------------------------------------ commands
def test_the_cli_reference_has_a_section_for_every_command() -> None:
    text = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    sections = set(re.findall(r"^### heft (\S+)", text, flags=re.M))
    assert sections == registered_commands()


def test_the_cli_reference_has_a_row_for_every_benchmark() -> None:
    text = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    rows = set(re.findall(r"^\| `heft bench ([a-z-]+)", text, flags=re.M))
    assert rows == registered_benchmarks()


def heft_lines(page: Path) -> list[list[str]]:
    """Every ``heft`` command line of ``page``'s shell blocks, and every one run after ``--``
    by another (``heft vcan -- heft run …``)."""
    found = []
    for block in code_blocks(page.read_text(encoding="utf-8"), "sh"):
        for argv in heft_command_lines(block):
            found.append(argv)
            if "--" in argv and argv[argv.index("--") + 1 :][:1] == ["heft"]:
                found.append(argv[argv.index("--") + 2 :])
    return found


@pytest.mark.parametrize("page", [README, *DOCS], ids=page_id)
def test_every_heft_command_the_docs_show_is_one_heft_accepts(page: Path, heft) -> None:
    """Command lines in shell blocks parse whole; a ``heft`` command in the text names a real
    command and only options its ``--help`` lists."""
    registered = registered_commands()
    for argv in heft_lines(page):
        if argv and argv[0].startswith("-"):  # heft --help, heft --version
            continue
        assert argv and argv[0] in registered, f"{page_id(page)}: heft {' '.join(argv)}"
        assert_parses(heft, argv, page_id(page))
    for span in re.findall(r"`(heft [^`]+)`", prose(page.read_text(encoding="utf-8"))):
        argv = span.split()[1:]
        if not re.fullmatch(r"[a-z][a-z-]*", argv[0]):  # heft COMMAND, heft --help
            continue
        assert argv[0] in registered, f"{page_id(page)}: `{span}`: no such command"
        if len(argv) > 1:
            assert_options_listed(heft, argv, page_id(page))
