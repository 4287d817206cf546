"""A Foxglove layout for a team's recordings and live feed, built with the Foxglove SDK's
:mod:`foxglove.layouts`::

    python -m dashboard.layout [--team T] [--robots N] -o FILE
    python -m dashboard.layout --recording RUN.mcap -o FILE

writes the layout of team ``T`` (default ``paper``) of ``N`` robots (default 4), or of the
team a recording holds, to ``FILE``. :data:`COMMITTED` is the repository's layout of the paper's
team (the deployed robots' ``team = "paper"``, and ``heft demo``'s: a simulated run's team is
named after its scenario), which a test keeps equal to what this writes with
``-o deploy/foxglove/heft-layout.json``; ``--recording`` makes the layout of another scenario's
or team's recording. Import it in
Foxglove (Layouts, Import from file) and open a recording (``heft record``, ``heft run
--transport zenoh``, ``heft demo``). It shows:

- the 3D panel: the load's scene (:mod:`dashboard.scene`) seen from above in the world frame,
  following the load frame's position;
- plots of each robot's ``m̂`` and ``Ĵ`` with the truth, and of its ``ω`` with the truth's;
- a state-transitions panel of each robot's phase, in the page's phase colours;
- the log panel of the team's news.

Its message paths name the recorded topics as they are, without a leading slash (a topic of
letters, digits, ``_`` and ``/`` only is written as it is; any other in double quotes,
:func:`message_path`), so the paths of a recording of ``heft/paper/…`` are
``heft/paper/robot/1/estimate.mass``.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import foxglove.layouts as fl

from agent.platform.config import MAX_ROBOTS
from agent.platform.protocol import Estimates, Keys, LoadGeometry, Phase
from dashboard.scene import (
    LOAD,
    PHASE_COLOURS,
    TRUTH_COLOUR,
    WORLD,
    SceneTopics,
    robot_colour,
)

COMMITTED = Path(__file__).resolve().parent.parent / "deploy" / "foxglove" / "heft-layout.json"
"""The repository's layout: team ``paper``, 4 robots."""
DEFAULT_TEAM = "paper"
DEFAULT_ROBOTS = 4
_PLAIN_TOPIC = re.compile(r"[A-Za-z0-9_/]+")


def message_path(topic: str, field: str) -> str:
    """Foxglove's message path of ``field`` of the messages on ``topic``: the topic as it is
    when Foxglove's grammar takes it bare (letters, digits, ``_``, ``/``), else in double
    quotes (``"`` and ``\\`` escaped)."""
    if not _PLAIN_TOPIC.fullmatch(topic):
        topic = '"' + topic.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return f"{topic}.{field}"


def layout(team: str = DEFAULT_TEAM, robots: int = DEFAULT_ROBOTS) -> fl.Layout:
    """The layout of team ``team`` of ``robots`` robots (see the module docstring)."""
    keys, drawn = Keys(team), SceneTopics(team)
    ids = range(1, robots + 1)

    def plot(title: str, field: str, symbol: str, truth: str, unit: str) -> fl.PlotPanel:
        """Each robot's estimate of ``field`` and the truth's ``field``."""
        series = [
            fl.PlotSeries(
                value=message_path(keys.estimate(i), field),
                label=f"{symbol} robot {i}",
                color=robot_colour(i),
            )
            for i in ids
        ]
        series.append(
            fl.PlotSeries(
                value=message_path(keys.truth(), field),
                label=f"{truth} (truth)",
                color=TRUTH_COLOUR,
                line_style="dashed",
            )
        )
        config = fl.PlotConfig(paths=series, y_axis_label=unit, is_synced=True)
        return fl.PlotPanel(title=title, config=config)

    phases = fl.StateTransitionsDiscreteCustomStates(
        states=[
            fl.StateTransitionsDiscreteCustomState(
                value=p.label, label=p.label, color=PHASE_COLOURS[p.label]
            )
            for p in Phase
        ]
    )
    timeline = fl.StateTransitionsPanel(
        title="phase",
        config=fl.StateTransitionsConfig(
            paths=[
                fl.StateTransitionsSeries(
                    value=message_path(keys.estimate(i), "phase"),
                    label=f"robot {i}",
                    custom_states=phases,
                )
                for i in ids
            ],
            is_synced=True,
        ),
    )
    scene = fl.ThreeDeePanel(
        title="the load, world frame",
        config=fl.ThreeDeeConfig(
            fixed_frame=WORLD,
            follow_tf=LOAD,
            follow_mode="follow-position",
            camera_state=fl.ThreeDeeCameraState(perspective=False, distance=12.0),
            topics={
                drawn.scene: fl.BaseRendererSceneUpdateTopicSettings(visible=True),
            },
            layers={
                "grid": fl.BaseRendererGridLayerSettings(
                    frame_id=WORLD, size=40.0, divisions=40, color="#3a3f4b"
                )
            },
        ),
    )
    news = fl.LogPanel(title="the team's news", config=fl.LogConfig(topic_to_render=drawn.log))
    left = fl.SplitContainer(
        direction="column",
        items=[fl.SplitItem(proportion=3, content=scene), fl.SplitItem(content=news)],
    )
    right = fl.SplitContainer(
        direction="column",
        items=[
            fl.SplitItem(content=plot("mass m̂", "mass", "m̂", "m", "kg")),
            fl.SplitItem(content=plot("moment of inertia Ĵ", "moment", "Ĵ", "J", "kg m²")),
            fl.SplitItem(content=plot("rotation rate ω", "omega", "ω̂", "ω", "rad/s")),
            fl.SplitItem(content=timeline),
        ],
    )
    return fl.Layout(
        content=fl.SplitContainer(
            direction="row",
            items=[fl.SplitItem(content=left), fl.SplitItem(content=right)],
        )
    )


def layout_json(team: str = DEFAULT_TEAM, robots: int = DEFAULT_ROBOTS) -> str:
    """:func:`layout` as the file Foxglove imports (indented, one trailing newline)."""
    return (
        json.dumps(json.loads(layout(team, robots).to_json()), indent=2, ensure_ascii=False) + "\n"
    )


def recorded_team(path: Path) -> tuple[str, int]:
    """The team a recording holds and how many robots it has (the load geometry's ``n``, else
    the highest robot id with estimates); :class:`~dashboard.replay.RecordingError` if it is
    not a team's recording."""
    from dashboard.replay import Recording

    recording = Recording(path)
    team = recording.header()
    robots = 0
    for recorded in recording.messages({LoadGeometry, Estimates}):
        if isinstance(recorded.message, LoadGeometry):
            return team, recorded.message.n
        robots = max(robots, recorded.message.robot)
    return team, robots or DEFAULT_ROBOTS


class _Usage(Exception):
    """Bad input: one line, exit status 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):
        raise _Usage(message)


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="python -m dashboard.layout",
        description="Write the Foxglove layout of a team's recordings and live feed.",
    )
    parser.add_argument("--team", help="the team (default: paper)")
    parser.add_argument(
        "--robots", help=f"how many robots, 1 to {MAX_ROBOTS} (default: {DEFAULT_ROBOTS})"
    )
    parser.add_argument(
        "--recording",
        type=Path,
        metavar="RUN.mcap",
        help="the team and robots of this recording (instead of --team and --robots)",
    )
    parser.add_argument(
        "-o",
        "--output",
        type=Path,
        required=True,
        metavar="FILE",
        help="where to write it (the repository's: deploy/foxglove/heft-layout.json)",
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    """``python -m dashboard.layout``: write the layout; exit status 2 with one line on bad
    input."""
    parser = _parser()
    try:
        args = parser.parse_args(sys.argv[1:] if argv is None else argv)
        if args.recording is not None:
            if args.team is not None or args.robots is not None:
                raise _Usage("--recording names the team and its robots: not with --team, --robots")
            from dashboard.replay import RecordingError

            try:
                team, robots = recorded_team(args.recording)
            except RecordingError as err:
                raise _Usage(f"--recording: {err}") from None
        else:
            team = DEFAULT_TEAM if args.team is None else args.team
            robots = str(DEFAULT_ROBOTS) if args.robots is None else args.robots
            try:
                Keys(team)
            except ValueError as err:
                raise _Usage(f"--team: {err}") from None
            if not (robots.isdecimal() and 1 <= int(robots) <= MAX_ROBOTS):
                raise _Usage(f"--robots: expected 1 to {MAX_ROBOTS}, got {robots!r}")
            robots = int(robots)
        text = layout_json(team, robots)
        try:
            args.output.parent.mkdir(parents=True, exist_ok=True)
            args.output.write_text(text, encoding="utf-8")
        except OSError as err:
            raise _Usage(f"{args.output}: cannot write ({err.strerror or err})") from None
    except _Usage as err:
        print(f"{parser.prog}: error: {err}", file=sys.stderr)
        return 2
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
