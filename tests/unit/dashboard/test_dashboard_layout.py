"""The Foxglove layout (dashboard/layout.py): the committed file is what the command writes, and
every topic, field and frame it names is in a recording of the team."""

from __future__ import annotations

import json
from pathlib import Path

import orjson
import pytest
from mcap.reader import make_reader

from dashboard.layout import COMMITTED, layout_json, main, message_path
from tests.helpers.foxglove import NODE, check_recording, decoder
from tests.helpers.recordings import record_run


def test_the_committed_layout_is_what_the_command_writes(tmp_path: Path, capsys) -> None:
    written = tmp_path / "layout.json"
    assert main(["-o", str(written)]) == 0
    assert capsys.readouterr().out == f"wrote {written}\n"
    assert COMMITTED.read_text(encoding="utf-8") == written.read_text(encoding="utf-8"), (
        f"{COMMITTED} is out of date: run python -m dashboard.layout -o {COMMITTED}"
    )
    assert written.read_text(encoding="utf-8") == layout_json("paper", 4)


def _panels(node: dict):
    """Every panel of a layout's content tree."""
    if node.get("type") == "panel":
        yield node
    for item in node.get("items", []):
        yield from _panels(item["content"])


def _split(path: str) -> tuple[str, str]:
    """A message path ``topic.field`` (the topic bare or in double quotes) as its parts."""
    if path.startswith('"'):
        end = path.index('"', 1)
        return path[1:end], path[end + 2 :]
    topic, _, field = path.partition(".")
    return topic, field


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    """A recording of the paper's team (an in-process run, recorded as the plant and agents
    publish it)."""
    from simulator.inprocess import run_inprocess
    from simulator.scenario import load_scenario
    from tests.helpers.paths import PAPER

    scenario = load_scenario(PAPER)
    path = tmp_path_factory.mktemp("layout") / "paper.mcap"
    record_run(path, scenario, run_inprocess(scenario))
    return path


@pytest.fixture(scope="module")
def recording(recorded: Path) -> tuple[dict[str, str], dict[str, set[str]], set[str]]:
    """The recording's topics: each one's schema, the fields its records have, and the frames
    its transforms name."""
    schemas: dict[str, str] = {}
    fields: dict[str, set[str]] = {}
    frames: set[str] = set()
    with open(recorded, "rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            schemas[channel.topic] = schema.name
            if channel.message_encoding == "json":
                fields.setdefault(channel.topic, set()).update(orjson.loads(message.data))
            elif schema.name == "foxglove.FrameTransform":
                frame = decoder(schema.name, schema.data).FromString(message.data)
                frames |= {frame.parent_frame_id, frame.child_frame_id}
    return schemas, fields, frames


@pytest.mark.skipif(NODE is None, reason="node is not installed (Foxglove's parser runs in it)")
def test_every_topic_of_a_recording_decodes_as_foxglove_reads_it(recorded: Path) -> None:
    """Every channel of a run's recording as Foxglove takes it: its JSON schema through
    Foxglove's own parser, its protobuf schema as a FileDescriptorSet, and every message."""
    rows = check_recording(recorded)
    assert {r["schema"] for r in rows} >= {
        "heft.Truth",
        "heft.Estimates",
        "heft.Command",
        "heft.LoadGeometry",
        "foxglove.SceneUpdate",
        "foxglove.FrameTransform",
        "foxglove.Log",
    }
    refused = [r for r in rows if not r["schema_ok"] or r["decoded"] != r["messages"]]
    assert not refused, refused
    assert all(r["messages"] > 0 for r in rows)


def test_every_path_of_the_layout_is_in_a_recording(recording) -> None:
    schemas, fields, frames = recording
    panels = list(_panels(json.loads(COMMITTED.read_text(encoding="utf-8"))["content"]))
    kinds = [p["panelType"] for p in panels]
    assert sorted(kinds) == ["Log", "Plot", "Plot", "Plot", "StateTransitions", "ThreeDee"]
    paths = [s["value"] for p in panels for s in p["config"].get("paths", [])]
    assert len(paths) == 3 * (4 + 1) + 4  # each robot's m, J and ω and the truth's; phases
    for path in paths:
        topic, field = _split(path)
        assert field in fields.get(topic, ()), f"{path}: no field {field!r} on {topic!r}"
    assert {_split(p)[1] for p in paths} == {"mass", "moment", "omega", "phase"}
    three_d = next(p for p in panels if p["panelType"] == "ThreeDee")["config"]
    assert {three_d["fixedFrame"], three_d["followTf"]} == frames == {"world", "load"}
    assert [schemas[t] for t in three_d["topics"]] == ["foxglove.SceneUpdate"]
    log = next(p for p in panels if p["panelType"] == "Log")["config"]
    assert schemas[log["topicToRender"]] == "foxglove.Log"


def test_a_topic_outside_foxgloves_bare_names_is_quoted() -> None:
    assert message_path("heft/paper/robot/1/estimate", "mass") == (
        "heft/paper/robot/1/estimate.mass"
    )
    assert message_path("heft/lab-2/plant/truth", "omega") == '"heft/lab-2/plant/truth".omega'
    assert message_path('heft/a"b\\c/x', "m") == '"heft/a\\"b\\\\c/x".m'


def test_another_team_gets_its_own_topics(tmp_path: Path) -> None:
    out = tmp_path / "lab.json"
    assert main(["--team", "lab.2", "--robots", "6", "-o", str(out)]) == 0
    panels = list(_panels(json.loads(out.read_text(encoding="utf-8"))["content"]))
    plot = next(p for p in panels if p["panelType"] == "Plot")
    assert [s["value"] for s in plot["config"]["paths"]] == [
        *(f'"heft/lab.2/robot/{i}/estimate".mass' for i in range(1, 7)),
        '"heft/lab.2/plant/truth".mass',
    ]
    three_d = next(p for p in panels if p["panelType"] == "ThreeDee")["config"]
    assert list(three_d["topics"]) == ["heft/lab.2/scene"]


def test_a_recordings_layout_names_its_team_and_robots(tmp_path: Path, capsys) -> None:
    from simulator.inprocess import run_inprocess
    from simulator.scenario import load_scenario
    from tests.helpers.paths import PAPER

    scenario = load_scenario(PAPER)
    path = tmp_path / "run.mcap"
    record_run(path, scenario, run_inprocess(scenario), team="paper-4242")
    out = tmp_path / "run-layout.json"
    assert main(["--recording", str(path), "-o", str(out)]) == 0
    assert out.read_text(encoding="utf-8") == layout_json("paper-4242", 4)
    assert main(["--recording", str(tmp_path / "none.mcap"), "-o", str(out)]) == 2
    assert "--recording: " in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (
            ["--recording", "x.mcap", "--team", "lab"],
            "--recording names the team and its robots: not with --team, --robots",
        ),
        (["--robots", "0"], "--robots: expected 1 to 32, got '0'"),
        (["--robots", "x"], "--robots: expected 1 to 32, got 'x'"),
        (["--team", "a/b"], "--team: team name 'a/b' must be non-empty without / * $ ? #"),
        (["--bogus"], "unrecognized arguments: --bogus"),
    ],
)
def test_bad_input_is_one_line_and_exit_status_2(argv, says, tmp_path: Path, capsys) -> None:
    assert main([*argv, "-o", str(tmp_path / "x.json")]) == 2
    captured = capsys.readouterr()
    assert captured.err == f"python -m dashboard.layout: error: {says}\n"
    assert captured.out == "" and not (tmp_path / "x.json").exists()
