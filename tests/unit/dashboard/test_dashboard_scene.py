"""What Foxglove draws of a team (dashboard/scene.py, through dashboard/topics.py): one instant
of a lockstep run's scene and frame, decoded with protobuf from the SDK's own schemas, drawn
where the truth and the commands put them (and rendered to docs/images/foxglove-scene.png for
docs/dashboard.md); the team's news said once each; the colours the page's."""

from __future__ import annotations

import math
import re
from dataclasses import replace

import pytest

from agent.platform.protocol import (
    Command,
    Estimates,
    Keys,
    Phase,
    Status,
    Truth,
)
from agent.platform.transport import InMemoryTransport
from dashboard.scene import ARROW_FRACTION, SCENE_EVERY_S, Scene, SceneTopics
from dashboard.topics import Outgoing, Topics
from simulator.inprocess import make_agents
from simulator.plant import Plant
from simulator.scenario import load_scenario
from tests.helpers.foxglove import TOLERANCE, close, decoder, in_world, turn
from tests.helpers.paths import PAPER, ROOT

PICTURE = ROOT / "docs" / "images" / "foxglove-scene.png"
INSTANT_S = 6.5
"""The instant drawn: the paper's team pushing, every estimate there."""


# ------------------------------------------------------------------------------ decoding
def decode(out: Outgoing):
    """An outgoing item of Foxglove's, decoded with its own schema."""
    assert out.schema.encoding == "protobuf" and out.message_encoding == "protobuf"
    return decoder(out.schema.name, out.schema.data).FromString(out.data)


def decode_message(message):
    """A Foxglove SDK message, decoded with its class's schema."""
    schema = type(message).get_schema()
    return decoder(schema.name, schema.data).FromString(message.encode())


def _heading(frame, pose) -> float:
    return turn(frame.rotation) + turn(pose.orientation)


# ------------------------------------------------------------------------------ the run
@pytest.fixture(scope="module")
def recorded():
    """A lockstep run of the paper's team to :data:`INSTANT_S` (robots, plant, in-memory
    transport), every message through :class:`Topics` as a recorder takes them: the geometry,
    then each tick the robots' commands, their estimates and the truth, stamped with their
    instants. Returns the outgoing items, the truths and each tick's commands and estimates."""
    scenario = load_scenario(PAPER)
    plant, agents = Plant(scenario), make_agents(scenario)
    transport = InMemoryTransport(scenario.n, scenario.edges)
    keys, topics = Keys("paper"), Topics("paper")
    period_ns = round(scenario.period_s * 1e9)
    outgoing = list(topics.of(keys.geometry(), scenario.load_geometry(), 0))
    truths: dict[int, Truth] = {}
    commands: dict[int, dict[int, Command]] = {}
    estimates: dict[int, dict[int, Estimates]] = {}
    for k in range(round(INSTANT_S / scenario.period_s) + 1):
        shares = []
        commands[k] = {}
        for agent, measurement in zip(agents, plant.measure()):
            command, share = agent.step(measurement, transport.receive(agent.robot))
            plant.command(agent.robot, command.force)
            commands[k][agent.robot] = command
            shares.append(share)
        for share in shares:
            transport.send(share)
        for command in commands[k].values():
            outgoing += topics.of(keys.force(command.robot), command, k * period_ns)
        estimates[k] = {a.robot: a.estimates() for a in agents}
        for est in estimates[k].values():
            outgoing += topics.of(keys.estimate(est.robot), est, max(est.tick, 0) * period_ns)
        truths[k] = plant.truth()
        outgoing += topics.of(keys.truth(), truths[k], k * period_ns)
        plant.advance()
    return scenario, outgoing, truths, commands, estimates


def test_one_instants_scene_and_frame_are_the_truths_and_the_commands(recorded) -> None:
    scenario, outgoing, truths, commands, estimates = recorded
    drawn = SceneTopics("paper")
    instant_ns = round(INSTANT_S * 1e9)
    at = [out for out in outgoing if out.log_time_ns == instant_ns]
    by_topic = {out.topic: out for out in at}
    assert {out.schema.name for out in at if out.topic in (drawn.scene, drawn.transforms)} == {
        "foxglove.SceneUpdate",
        "foxglove.FrameTransform",
    }
    k = round(INSTANT_S / scenario.period_s)
    truth, forces, ests = truths[k], commands[k], estimates[k]
    assert truth.tick == k and all(est.contact_to_com is not None for est in ests.values())
    frame = decode(by_topic[drawn.transforms])
    update = decode(by_topic[drawn.scene])

    # The frame: world → load at the truth's pose, stamped with the instant.
    assert (frame.parent_frame_id, frame.child_frame_id) == ("world", "load")
    assert close((frame.translation.x, frame.translation.y), truth.com_position)
    assert abs(math.remainder(turn(frame.rotation) - truth.angle, 2 * math.pi)) < TOLERANCE
    assert frame.timestamp.seconds * 10**9 + frame.timestamp.nanos == instant_ns

    # The update replaces the whole scene; every entity is in the load frame, locked to it.
    assert [d.type for d in update.deletions] == [1]  # All
    entities = {e.id: e for e in update.entities}
    n = scenario.n
    assert set(entities) == {
        "load",
        "com",
        *(f"{what}/{i}" for what in ("contact", "force", "com_estimate", "geometry")
          for i in range(1, n + 1)),
    }  # fmt: skip
    assert all(e.frame_id == "load" and e.frame_locked for e in entities.values())
    assert all(
        e.timestamp.seconds * 10**9 + e.timestamp.nanos == instant_ns for e in update.entities
    )

    # The outline's vertices, taken to W by the frame, are where the truth puts the polygon.
    outline = entities["load"].lines[0]
    world = [in_world(frame, outline.pose, p.x, p.y) for p in outline.points]
    expected = scenario.load_geometry().world_outline(truth.com_position, truth.angle)
    assert len(world) == len(expected) >= 3
    assert all(close(p, q) for p, q in zip(world, expected))

    # The COM and the contacts.
    assert close(in_world(frame, entities["com"].spheres[0].pose), truth.com_position)
    for i, contact in enumerate(truth.contacts, start=1):
        assert close(in_world(frame, entities[f"contact/{i}"].spheres[0].pose), contact)
        assert entities[f"contact/{i}"].texts[0].text == str(i)

    # The arrows: from each contact along its robot's command, in proportion to it, the
    # largest a quarter of the load's size; their metadata give the commands in newtons.
    corners = scenario.load_geometry().outline  # the load's size: its outline's box
    size = max(max(v[c] for v in corners) - min(v[c] for v in corners) for c in (0, 1))
    largest = max(math.hypot(*c.force) for c in forces.values())
    assert largest > 0.0
    for i, command in forces.items():
        arrow = entities[f"force/{i}"].arrows[0]
        assert close(in_world(frame, arrow.pose), truth.contacts[i - 1])
        heading = _heading(frame, arrow.pose)
        assert abs(math.remainder(heading - math.atan2(*command.force[::-1]), 2 * math.pi)) < 1e-9
        length = arrow.shaft_length + arrow.head_length
        expected_length = ARROW_FRACTION * size * math.hypot(*command.force) / largest
        assert abs(length - expected_length) < 1e-9
        meta = {kv.key: kv.value for kv in entities[f"force/{i}"].metadata}
        assert (float(meta["x"]), float(meta["y"])) == command.force

    # Each robot's estimated COM (the ring's centre) and its estimated geometry of the team.
    for i, est in ests.items():
        contact = truth.contacts[i - 1]
        ring = entities[f"com_estimate/{i}"].lines[0]
        points = [in_world(frame, ring.pose, p.x, p.y) for p in ring.points]
        centre = tuple(sum(c) / len(points) for c in zip(*points))
        expected_com = (contact[0] + est.contact_to_com[0], contact[1] + est.contact_to_com[1])
        assert close(centre, expected_com, 1e-9)
        spheres = entities[f"geometry/{i}"].spheres
        placed = [in_world(frame, s.pose) for s in spheres]
        wanted = [
            (contact[0] - z[0], contact[1] - z[1])
            for _, z in sorted(est.relative_positions.items())
        ]
        assert len(placed) == len(wanted) == len(est.relative_positions) >= 1  # its neighbours
        assert all(close(p, q, 1e-9) for p, q in zip(placed, wanted))
        cross = entities[f"geometry/{i}"].lines[0]
        ends = [in_world(frame, cross.pose, p.x, p.y) for p in cross.points]
        centre = tuple(sum(c) / len(ends) for c in zip(*ends))
        g = est.centroid_offset
        assert close(centre, (contact[0] - g[0], contact[1] - g[1]), 1e-9)
        # The estimates are good by now: each robot's COM within 5 cm of the truth.
        assert math.dist(expected_com, truth.com_position) < 0.05

    _render(update, frame, truth, INSTANT_S)


def test_the_scene_goes_out_every_50_ms_the_frame_with_every_truth(recorded) -> None:
    scenario, outgoing, truths, _, _ = recorded
    drawn = SceneTopics("paper")
    scenes = [out.log_time_ns for out in outgoing if out.topic == drawn.scene]
    frames = [out.log_time_ns for out in outgoing if out.topic == drawn.transforms]
    period_ns = round(scenario.period_s * 1e9)
    assert frames == [k * period_ns for k in sorted(truths)]
    every = round(SCENE_EVERY_S * 1e9)
    assert scenes[0] == 0 and all(b - a == every for a, b in zip(scenes, scenes[1:]))
    assert len(scenes) == len(truths) // 5 + 1
    # Each record comes first, then what is drawn of it, at its instant.
    truth_key = Keys("paper").truth()
    for a, b in zip(outgoing, outgoing[1:]):
        if b.topic in (drawn.scene, drawn.transforms):
            assert a.topic in (truth_key, drawn.transforms) and a.log_time_ns == b.log_time_ns


def test_the_log_says_each_robots_phases_and_steps_once(recorded) -> None:
    _, outgoing, _, _, _ = recorded
    logs = [decode(out) for out in outgoing if out.topic == SceneTopics("paper").log]
    texts = [log.message for log in logs]
    for i in range(1, 5):
        mine = [t for t in texts if t.startswith(f"robot {i}:")]
        assert [t.split(":")[1].split()[0] for t in mine if " from tick " in t] == [
            "excite",
            "inertia",
            "push",
        ]
        assert len([t for t in mine if "settled" in t]) == len(
            set(t for t in mine if "settled" in t)
        )
        assert any("Step 4 (moment of inertia J) settled" in t for t in mine)
    assert {log.name for log in logs} == {f"robot {i}" for i in range(1, 5)}
    assert all(log.level == 2 for log in logs)  # Info: nothing went wrong


# ------------------------------------------------------------------------------ the news
def _news(scene: Scene, message, tick: int) -> list[str]:
    return [decode_message(m).message for _, m in scene.of(message, tick * 10_000_000)]


def test_news_is_said_once_and_an_older_message_does_not_take_it_back() -> None:
    scene = Scene("t")
    est = Estimates(robot=2, tick=10, phase=Phase.EXCITE, phase_since=0)
    assert _news(scene, est, 10) == [
        "robot 2: excite from tick 0: the kick and the spin-up (Steps 1-3)"
    ]
    assert _news(scene, replace(est, tick=15), 15) == []
    assert _news(scene, Status(robot=2, tick=41, phase=Phase.INERTIA), 41) == [
        "robot 2: inertia from tick 41: Step 4, the moment of inertia"
    ]
    # Estimates of before the switch arrive late: no news; those of after it: none either.
    assert _news(scene, replace(est, tick=39), 39) == []
    assert _news(scene, replace(est, tick=42, phase=Phase.INERTIA, phase_since=40), 42) == []
    assert _news(scene, Status(robot=2, tick=30, phase=Phase.EXCITE), 30) == []
    # The floor holds the load; then the team is done, with its estimates.
    held = replace(est, tick=50, phase=Phase.INERTIA, phase_since=40, stuck_torque=1.33)
    assert _news(scene, held, 50) == [
        "robot 2: the floor holds the load (1.33 N m applied without turning it): the robot"
        " pushes no more"
    ]
    assert _news(scene, replace(held, tick=51), 51) == []
    done = replace(held, tick=90, phase=Phase.DONE, phase_since=90, mass=5.0, moment=12.5)
    done = replace(done, contact_to_com=(0.3, 0.4), settled={4: 60})
    assert _news(scene, done, 90) == [
        "robot 2: done from tick 90: zero force, the load coasts",
        "robot 2: Step 4 (moment of inertia J) settled at tick 60",
        "robot 2's estimates at tick 90: m̂ = 5.0000 kg, Ĵ = 12.5000 kg m², ‖p̂_C − p_Ci‖ = 0.5000 m",
    ]
    assert _news(scene, replace(done, tick=91), 91) == []
    # A changed load: the team estimates it again; Step 4 settles again, at a new tick.
    again = replace(done, tick=120, phase=Phase.INERTIA, phase_since=120, load_changes=1)
    again = replace(again, settled={4: 60}, stuck_torque=None)
    assert _news(scene, again, 120) == [
        "robot 2: the load changed: the team estimates it again from Step 4 (load change 1)",
        "robot 2: inertia from tick 120: Step 4, the moment of inertia",
    ]
    assert _news(scene, replace(again, tick=150, settled={4: 150}), 150) == [
        "robot 2: Step 4 (moment of inertia J) settled at tick 150"
    ]
    # Every robot back after a halt: the team begins again from Step 1.
    back = replace(again, tick=200, phase=Phase.EXCITE, phase_since=200, rejoins=1)
    assert _news(scene, replace(back, settled={4: 150}), 200) == [
        "robot 2: every robot is back: the team begins again from Step 1 (rejoin 1)",
        "robot 2: excite from tick 200: the kick and the spin-up (Steps 1-3)",
    ]


def test_a_lost_neighbour_and_a_halt_are_errors() -> None:
    scene = Scene("t")
    status = Status(robot=1, tick=100, phase=Phase.PUSH)
    scene.of(status, 100)
    out = [
        decode_message(m) for _, m in scene.of(replace(status, tick=101, lost_neighbours=(3,)), 101)
    ]
    assert [(m.level, m.message) for m in out] == [(4, "robot 1 lost its neighbour(s) 3")]
    out = [
        decode_message(m)
        for _, m in scene.of(
            replace(status, tick=102, phase=Phase.HALTED, lost_neighbours=(3,)), 102
        )
    ]
    assert [(m.level, m.message) for m in out] == [
        (4, "robot 1: halted from tick 102: a robot was lost, the team stopped pushing")
    ]
    halted = replace(status, tick=103, phase=Phase.HALTED, lost_neighbours=(3,))
    assert scene.of(halted, 103) == []


def test_the_colours_are_the_pages() -> None:
    """The scene's and the layout's colours are the page's (dashboard/static/dashboard.js)."""
    from dashboard.scene import PHASE_COLOURS, ROBOT_COLOURS, TRUTH_COLOUR

    script = (ROOT / "dashboard" / "static" / "dashboard.js").read_text()
    colours = re.search(r"const COLOURS = \[(.*?)\];", script, re.S).group(1)
    assert tuple(re.findall(r'"(#[0-9a-f]{6})"', colours)) == ROBOT_COLOURS
    phases = re.search(r"const PHASE_COLOURS = \{(.*?)\};", script, re.S).group(1)
    assert dict(re.findall(r'(\w+): "(#[0-9a-f]{6})"', phases)) == PHASE_COLOURS
    assert f'const TRUTH_COLOUR = "{TRUTH_COLOUR}";' in script
    assert set(PHASE_COLOURS) == {p.label for p in Phase}


# ------------------------------------------------------------------------------ the picture
def _render(update, frame, truth: Truth, t: float) -> None:
    """The decoded scene as Foxglove's 3D panel shows it from above (world frame), to
    :data:`PICTURE`: every primitive where the frame puts it, in its own colour."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def rgba(c):
        return (c.r, c.g, c.b, c.a)

    fig, ax = plt.subplots(figsize=(5.6, 4.4), dpi=100)
    fig.patch.set_facecolor("#15171c")
    ax.set_facecolor("#15171c")
    for entity in update.entities:
        for line in entity.lines:
            points = [in_world(frame, line.pose, p.x, p.y) for p in line.points]
            if line.type == 1:  # LineLoop
                points.append(points[0])
            if line.type == 2:  # LineList
                for a, b in zip(points[::2], points[1::2]):
                    ax.plot(*zip(a, b), color=rgba(line.color), lw=line.thickness * 0.8)
            else:
                ax.plot(*zip(*points), color=rgba(line.color), lw=line.thickness * 0.8)
        for arrow in entity.arrows:
            x, y = in_world(frame, arrow.pose)
            heading = _heading(frame, arrow.pose)
            length = arrow.shaft_length + arrow.head_length
            ax.annotate(
                "",
                xy=(x + length * math.cos(heading), y + length * math.sin(heading)),
                xytext=(x, y),
                arrowprops={"arrowstyle": "-|>", "color": rgba(arrow.color), "lw": 2},
            )
        for sphere in entity.spheres:
            x, y = in_world(frame, sphere.pose)
            ax.add_patch(plt.Circle((x, y), sphere.size.x / 2, color=rgba(sphere.color), zorder=3))
        for text in entity.texts:
            x, y = in_world(frame, text.pose)
            ax.text(x, y, text.text, color=rgba(text.color), ha="center", va="bottom",
                    fontsize=10, fontweight="bold", zorder=4)  # fmt: skip
    ax.set_aspect("equal")
    ax.margins(0.08)
    ax.tick_params(colors="#9aa3b2", labelsize=8)
    for spine in ax.spines.values():
        spine.set_color("#3a3f4b")
    ax.grid(color="#2a2f3a", lw=0.6)
    ax.set_title(
        f"heft/paper/scene at t = {t:.2f} s, world frame (m)", color="#d8dde6", fontsize=10
    )
    fig.tight_layout()
    PICTURE.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(PICTURE, facecolor=fig.get_facecolor(), metadata={"Software": None})
    plt.close(fig)


# ------------------------------------------------------------------------------ no plant
def test_without_a_plant_the_scene_is_the_teams_own_picture() -> None:
    """Real robots: no truth. Once the robots have their centroid offsets, their estimates draw
    the team as it sees itself, about the centroid of its contacts (frame ``team`` at W's
    origin): each contact at its own ``ẑ_i``, its arrow along its command, its estimated COM
    at ``ẑ_i + (p̂_C − p_Ci)``, its neighbours at ``ẑ_i − ẑ_ij``; nothing of a truth. Once a
    truth is heard, the scene is the plant's again."""
    z = {1: (-1.0, 0.5), 2: (1.0, 0.5), 3: (0.0, -1.0)}  # ẑ_i: they sum to zero
    com = (0.2, 0.1)  # p_C − p_G, as every robot estimates it
    scene = Scene("lab")
    scene.of(Command(1, 40, (2.0, 0.0)), 400_000_000)
    scene.of(Command(3, 40, (0.0, 1.0)), 400_000_000)
    before = Estimates(1, 30, Phase.EXCITE)  # Step 2 not done: nothing to draw yet
    assert [topic for topic, _ in scene.of(before, 300_000_000)] == ["heft/lab/log"]
    out = []
    for i, zi in z.items():
        relative = {j: (zi[0] - zj[0], zi[1] - zj[1]) for j, zj in z.items() if abs(j - i) == 1}
        est = Estimates(
            i,
            40,
            Phase.INERTIA,
            centroid_offset=zi,
            relative_positions=relative,
            contact_to_com=(com[0] - zi[0], com[1] - zi[1]),
        )
        out += scene.of(est, 400_000_000 + i)  # one picture per 50 ms: robot 1's
    frames = [decode_message(m) for topic, m in out if topic == "heft/lab/transforms"]
    updates = [decode_message(m) for topic, m in out if topic == "heft/lab/scene"]
    assert len(frames) == len(updates) == 1
    frame = frames[0]
    assert (frame.parent_frame_id, frame.child_frame_id) == ("world", "team")
    assert (frame.translation.x, frame.translation.y, turn(frame.rotation)) == (0.0, 0.0, 0.0)
    entities = {e.id: e for e in updates[0].entities}
    assert set(entities) == {"contact/1", "force/1", "com_estimate/1", "geometry/1"}
    assert all(e.frame_id == "team" for e in entities.values())
    assert close(in_world(frame, entities["contact/1"].spheres[0].pose), z[1])
    assert abs(_heading(frame, entities["force/1"].arrows[0].pose)) < 1e-12  # along +x
    ring = entities["com_estimate/1"].lines[0]
    points = [in_world(frame, ring.pose, p.x, p.y) for p in ring.points]
    assert close(tuple(sum(c) / len(points) for c in zip(*points)), com, 1e-9)
    placed = [in_world(frame, s.pose) for s in entities["geometry/1"].spheres]
    assert placed == [pytest.approx(z[2])]

    # 50 ms on, every robot's estimates are in: the whole team, and the arrows of both commands.
    later = scene.of(replace(est, tick=45), 460_000_000)
    update = decode_message(next(m for topic, m in later if topic == "heft/lab/scene"))
    ids = {e.id for e in update.entities}
    assert {f"contact/{i}" for i in z} | {"force/1", "force/3"} <= ids
    assert "force/2" not in ids and "load" not in ids and "com" not in ids
    for e in update.entities:
        if e.id.startswith("contact/"):
            i = int(e.id.split("/")[1])
            assert close(in_world(frame, e.spheres[0].pose), z[i])

    # A truth: the plant's scene from now on, the team's picture no more.
    zero = (0.0, 0.0)
    truth = Truth(46, 0.46, zero, 0.0, zero, 0.0, (zero,) * 3, (zero,) * 3, (zero,) * 3, 5, 1)
    assert [t for t, _ in scene.of(truth, 520_000_000)] == [
        "heft/lab/transforms",
        "heft/lab/scene",
    ]
    assert [t for t, _ in scene.of(replace(est, tick=55), 580_000_000)] == []
