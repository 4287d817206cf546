"""What Foxglove draws of a team: the load's scene, its frame and the team's news, in Foxglove's
own schemas (the messages of the Foxglove SDK, :mod:`foxglove.messages`).

:meth:`Scene.of` turns each decoded protocol message into the Foxglove messages it adds, each
on its topic (:class:`SceneTopics`) and stamped with the instant the caller gives (the same as
the message's own record: :class:`~dashboard.topics.Topics`):

- with each :class:`~agent.platform.protocol.Truth`, the pose of the load frame ``load`` in the
  world frame ``W`` (``world``) as a ``foxglove.FrameTransform`` (translation ``p_C``, a turn
  by the load frame's angle ``θ`` about ``z``);
- with a Truth every :data:`SCENE_EVERY_S` of the messages' own time, a
  ``foxglove.SceneUpdate`` that replaces the whole scene (every entity deleted, then each
  drawn again under the same id, so that the scene at any instant is the last update's, as
  Foxglove shows it after a seek):

  ========================= =============================================================
  entity                     what
  ========================= =============================================================
  ``load``                   the outline (:class:`~agent.platform.protocol.LoadGeometry`)
  ``com``                    the true COM ``p_C``, labelled ``C``
  ``contact/<i>``            robot ``i``'s contact ``p_Ci``, labelled ``i``
  ``force/<i>``              its force (its latest Command) as an arrow from ``p_Ci``, the
                             largest a quarter of the load's size
  ``com_estimate/<i>``       its estimated COM ``p_Ci + (p̂_C − p_Ci)``, a ring
  ``geometry/<i>``           its estimated geometry of the team: each neighbour's contact
                             where it puts it, ``p_Ci − ẑ_ij``, and the centroid
                             ``p_Ci − ẑ_i`` (a cross)
  ========================= =============================================================

  every entity in the load frame and locked to it (a point ``p`` of ``W`` at
  ``R(θ)ᵀ (p − p_C)``, a force ``f`` turned to ``R(θ)ᵀ f``), so that between two updates the
  drawing moves with the load as each transform places it. Coloured per robot as the
  dashboard's page colours them (:data:`ROBOT_COLOURS`), the truth in :data:`TRUTH_COLOUR`;
  sizes are fractions of the load's size (the larger side of its outline's box, at least
  0.5 m), as the page's top view draws them. Each entity's metadata names its robot and, for
  an arrow, the force in newtons (in ``W``);
- with each :class:`~agent.platform.protocol.Estimates` or
  :class:`~agent.platform.protocol.Status` that says something a log panel should show, a
  ``foxglove.Log`` (:class:`TeamNews`): a robot's phase changes, its steps settling, its
  estimates once done, and what stopped or restarted it.

A team without a plant (real robots) has no truth. Until a truth is heard, each robot's
estimates of a centroid offset (Step 2 done) draw instead, every :data:`SCENE_EVERY_S`, the
team's own picture of itself (:meth:`Scene.team_picture`) in the frame ``team``: the centroid
``p_G`` of the contacts at its origin, ``W``'s axes (placed at ``W``'s origin by an identity
transform: the robots know the load's shape about ``p_G``, not where it is). There robot
``i``'s contact is its own ``ẑ_i``, its force arrow its latest command, its estimated COM
``ẑ_i + (p̂_C − p_Ci)`` and its neighbours' contacts ``ẑ_i − ẑ_ij``, as above; nothing of the
truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from foxglove.messages import (
    ArrowPrimitive,
    Color,
    FrameTransform,
    KeyValuePair,
    LinePrimitive,
    LinePrimitiveLineType,
    Log,
    LogLevel,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneEntityDeletion,
    SceneEntityDeletionType,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    Vector3,
)

from agent.platform.geometry import Vec2, rotate
from agent.platform.protocol import (
    STEP_NAMES,
    Command,
    Estimates,
    LoadGeometry,
    LogLine,
    Phase,
    Status,
    Truth,
)
from dashboard.log_entries import log_entry, timestamp
from dashboard.quantities import SCALARS

WORLD = "world"
"""The frame id of ``W``."""
LOAD = "load"
"""The frame id of the load frame (origin at the COM, turned by the truth's angle)."""
TEAM = "team"
"""The frame id of the team's own picture without a plant: origin at the estimated centroid
``p_G`` of the contacts, ``W``'s axes."""
ROBOT_COLOURS = (
    "#4e9bff", "#ff6b6b", "#5fd35f", "#ffb020", "#c77dff", "#2ee6d6", "#ff85c8", "#e8e85a",
    "#b08060", "#a8b3c2", "#8a6cff", "#ff8f5a", "#2fa37a", "#f0c0ff", "#d0383a", "#1e90b0",
)  # fmt: skip
"""Robot ``i``'s colour is ``ROBOT_COLOURS[(i − 1) % 16]``: the dashboard page's hues
(``COLOURS`` in ``dashboard/static/dashboard.js``)."""
TRUTH_COLOUR = "#f0f3f6"
OUTLINE_COLOUR = "#8a93a3"
PHASE_COLOURS = {
    "excite": "#4e9bff",
    "inertia": "#c77dff",
    "push": "#ffb020",
    "done": "#3fb950",
    "halted": "#f85149",
}
"""Each phase's colour, as the page's phase timeline draws it."""
SCENE_EVERY_S = 0.05
"""A scene update at most this often (s of the messages' own time; the transform goes with
every truth): 20 a second move smoothly, and the scene costs a recording a fifth of what one
every tick of 100 Hz would."""
ARROW_FRACTION = 0.25
"""The largest force's arrow is this fraction of the load's size (the page's rule)."""
MIN_SIZE_M = 0.5
"""The smallest load size the drawing's proportions are taken from."""
RING_SIDES = 16
"""Of the ring drawn at an estimated COM."""


def robot_colour(robot: int) -> str:
    """Robot ``robot``'s colour (``#rrggbb``)."""
    return ROBOT_COLOURS[(robot - 1) % len(ROBOT_COLOURS)]


@dataclass(frozen=True)
class SceneTopics:
    """The topics of what Foxglove draws of team ``team`` (beside its messages' own, which
    are the Zenoh keys)."""

    team: str

    @property
    def scene(self) -> str:
        """``foxglove.SceneUpdate``: the load's scene."""
        return f"heft/{self.team}/scene"

    @property
    def transforms(self) -> str:
        """``foxglove.FrameTransform``: world → load."""
        return f"heft/{self.team}/transforms"

    @property
    def log(self) -> str:
        """``foxglove.Log``: the team's news."""
        return f"heft/{self.team}/log"


class Scene:
    """One team's messages as Foxglove messages (see the module docstring): remembers the
    load's geometry, each robot's latest command and estimates, and what its news said."""

    def __init__(self, team: str):
        self.topics = SceneTopics(team)
        self.geometry: LoadGeometry | None = None
        self.commands: dict[int, Command] = {}
        self.estimates: dict[int, Estimates] = {}
        self.news = TeamNews()
        self.drawn_ns: int | None = None
        """The instant of the last scene update."""
        self.truth_heard = False
        """Whether a plant's truth was heard (else the scene is the team's own picture)."""

    def of(self, message: object, log_time_ns: int) -> list[tuple[str, object]]:
        """``(topic, Foxglove message)`` pairs that ``message``, of instant ``log_time_ns``
        (ns), adds to Foxglove's panels (often none)."""
        stamp = timestamp(log_time_ns)
        if isinstance(message, Truth):
            self.truth_heard = True
            out = [(self.topics.transforms, load_frame(message, stamp))]
            if self._due(log_time_ns):
                out.append((self.topics.scene, self.update(message, stamp)))
            return out
        if isinstance(message, LoadGeometry):
            self.geometry = message
        elif isinstance(message, Command):
            latest = self.commands.get(message.robot)
            if latest is None or message.tick >= latest.tick:
                self.commands[message.robot] = message
        elif isinstance(message, Estimates):
            latest = self.estimates.get(message.robot)
            if latest is None or message.tick >= latest.tick:
                self.estimates[message.robot] = message
            out = [(self.topics.log, entry) for entry in self.news.estimates(message, stamp)]
            placed = message.centroid_offset is not None  # Step 2 done: a picture to draw
            if placed and not self.truth_heard and self._due(log_time_ns):
                out.append((self.topics.transforms, team_frame(stamp)))
                out.append((self.topics.scene, self.team_picture(stamp)))
            return out
        elif isinstance(message, Status):
            return [(self.topics.log, entry) for entry in self.news.status(message, stamp)]
        elif isinstance(message, LogLine):
            return [(self.topics.log, log_entry(message, stamp))]
        return []

    def _due(self, log_time_ns: int) -> bool:
        """Whether a scene update is due at ``log_time_ns`` (:data:`SCENE_EVERY_S` since the
        last, or the clock went back); if so, it is counted as made."""
        last = self.drawn_ns
        if last is not None and 0 <= log_time_ns - last < SCENE_EVERY_S * 1e9:
            return False
        self.drawn_ns = log_time_ns
        return True

    def team_picture(self, stamp: Timestamp) -> SceneUpdate:
        """The team as its robots estimate it, without a plant (see the module docstring): in
        the frame ``team``, each robot's contact at its own ``ẑ_i``."""
        own = {
            i: est.centroid_offset
            for i, est in sorted(self.estimates.items())
            if est.centroid_offset is not None
        }
        size = MIN_SIZE_M
        if own:
            spans = [
                max(p[k] for p in own.values()) - min(p[k] for p in own.values()) for k in (0, 1)
            ]
            size = max(*spans, size)
        drawing = _Drawing(stamp, size, (0.0, 0.0), 0.0, TEAM)
        return SceneUpdate(
            deletions=[SceneEntityDeletion(timestamp=stamp, type=SceneEntityDeletionType.All)],
            entities=self._robots(drawing, own),
        )

    def update(self, truth: Truth, stamp: Timestamp) -> SceneUpdate:
        """The whole scene at ``truth``'s instant (see the module docstring)."""
        drawing = _Drawing(stamp, self._size(truth), truth.com_position, truth.angle)
        entities = []
        if self.geometry is not None:
            entities.append(drawing.outline(self.geometry.outline))
        entities.append(drawing.com())
        contacts = dict(enumerate(truth.contacts, start=1))
        return SceneUpdate(
            deletions=[SceneEntityDeletion(timestamp=stamp, type=SceneEntityDeletionType.All)],
            entities=entities + self._robots(drawing, contacts),
        )

    def _robots(self, drawing: _Drawing, contacts: dict[int, Vec2]) -> list[SceneEntity]:
        """Each robot's contact at ``contacts[i]`` (a point of ``W``), its force, and its
        estimated COM and geometry about its contact."""
        entities = []
        forces = {
            i: command.force
            for i in contacts
            if (command := self.commands.get(i)) is not None and math.hypot(*command.force) > 0
        }
        largest = max((math.hypot(*f) for f in forces.values()), default=0.0)
        scale = ARROW_FRACTION * drawing.size / largest if largest > 0.0 else 0.0
        for i, contact in contacts.items():
            entities.append(drawing.contact(i, contact))
            if i in forces:
                entities.append(drawing.force(i, contact, forces[i], scale))
            est = self.estimates.get(i)
            if est is None:
                continue
            if est.contact_to_com is not None:
                entities.append(drawing.com_estimate(i, _plus(contact, est.contact_to_com)))
            others = [_minus(contact, z) for _, z in sorted(est.relative_positions.items())]
            centroid = None
            if est.centroid_offset is not None:
                centroid = _minus(contact, est.centroid_offset)
            if others or centroid is not None:
                entities.append(drawing.geometry(i, others, centroid))
        return entities

    def _size(self, truth: Truth) -> float:
        """The load's size (m): the larger side of the box around its outline (its contacts
        without one), at least :data:`MIN_SIZE_M`."""
        points = self.geometry.outline if self.geometry is not None else truth.contacts
        spans = [max(p[k] for p in points) - min(p[k] for p in points) for k in (0, 1)]
        return max(*spans, MIN_SIZE_M)


def load_frame(truth: Truth, stamp: Timestamp) -> FrameTransform:
    """The load frame in ``W`` at ``truth``'s instant: origin ``p_C``, turned by ``θ``."""
    x, y = truth.com_position
    return FrameTransform(
        timestamp=stamp,
        parent_frame_id=WORLD,
        child_frame_id=LOAD,
        translation=Vector3(x=x, y=y, z=0.0),
        rotation=_turn(truth.angle),
    )


def team_frame(stamp: Timestamp) -> FrameTransform:
    """The team's own frame ``team`` at ``W``'s origin, with its axes (the robots know the
    load's shape about the centroid, not where it is)."""
    return FrameTransform(
        timestamp=stamp,
        parent_frame_id=WORLD,
        child_frame_id=TEAM,
        translation=Vector3(x=0.0, y=0.0, z=0.0),
        rotation=_turn(0.0),
    )


def _turn(angle: float) -> Quaternion:
    """The rotation by ``angle`` about ``z``."""
    return Quaternion(x=0.0, y=0.0, z=math.sin(0.5 * angle), w=math.cos(0.5 * angle))


def _origin() -> Pose:
    """The frame's own origin and axes (a pose left out would be no rotation at all)."""
    return Pose(position=Vector3(x=0.0, y=0.0, z=0.0), orientation=_turn(0.0))


def _plus(a: Vec2, b: Vec2) -> Vec2:
    return (a[0] + b[0], a[1] + b[1])


def _minus(a: Vec2, b: Vec2) -> Vec2:
    return (a[0] - b[0], a[1] - b[1])


def _colour(hex_colour: str, alpha: float = 1.0) -> Color:
    r, g, b = (int(hex_colour[k : k + 2], 16) / 255.0 for k in (1, 3, 5))
    return Color(r=r, g=g, b=b, a=alpha)


def _meta(**values: object) -> list[KeyValuePair]:
    return [KeyValuePair(key=k, value=str(v)) for k, v in values.items()]


@dataclass(frozen=True)
class _Drawing:
    """The entities of one instant, sized after a load of ``size`` metres, in the load frame
    of the pose ``(com, angle)``."""

    stamp: Timestamp
    size: float
    com_position: Vec2
    angle: float
    frame: str = LOAD

    def _local(self, p: Vec2) -> Vec2:
        """Point ``p`` of ``W`` in the load frame: ``R(θ)ᵀ (p − p_C)``."""
        return rotate(_minus(p, self.com_position), -self.angle)

    def _pose(self, p: Vec2, heading: float = 0.0, z: float = 0.0) -> Pose:
        """At point ``p`` of ``W`` (heading ``heading`` in ``W``), in the load frame."""
        x, y = self._local(p)
        return Pose(position=Vector3(x=x, y=y, z=z), orientation=_turn(heading - self.angle))

    def _entity(self, id: str, **parts) -> SceneEntity:
        return SceneEntity(
            timestamp=self.stamp, frame_id=self.frame, id=id, frame_locked=True, **parts
        )

    def _label(self, p: Vec2, text: str, colour: str) -> TextPrimitive:
        return TextPrimitive(
            pose=self._pose(_plus(p, (0.0, 0.05 * self.size)), z=0.01),
            billboard=True,
            font_size=14.0,
            scale_invariant=True,
            color=_colour(colour),
            text=text,
        )

    def _sphere(self, p: Vec2, fraction: float, colour: Color) -> SpherePrimitive:
        d = fraction * self.size
        return SpherePrimitive(pose=self._pose(p), size=Vector3(x=d, y=d, z=d), color=colour)

    def _shape(
        self, kind: LinePrimitiveLineType, at: Vec2, points: list[Vec2], colour: Color
    ) -> LinePrimitive:
        """Lines through ``points`` about point ``at`` of ``W``, in ``W``'s axes, 2 pixels
        thick (the points are the same at every instant: a recording compresses them)."""
        return LinePrimitive(
            type=kind,
            pose=self._pose(at),
            thickness=2.0,
            scale_invariant=True,
            points=[Point3(x=x, y=y, z=0.0) for x, y in points],
            color=colour,
        )

    def outline(self, outline: tuple[Vec2, ...]) -> SceneEntity:
        """The outline: its vertices are the load frame's own."""
        line = LinePrimitive(
            type=LinePrimitiveLineType.LineLoop,
            pose=_origin(),
            thickness=1.5,
            scale_invariant=True,
            points=[Point3(x=x, y=y, z=0.0) for x, y in outline],
            color=_colour(OUTLINE_COLOUR),
        )
        return self._entity("load", lines=[line], metadata=_meta(what="the load's outline"))

    def com(self) -> SceneEntity:
        p = self.com_position
        return self._entity(
            "com",
            spheres=[self._sphere(p, 0.03, _colour(TRUTH_COLOUR))],
            texts=[self._label(p, "C", TRUTH_COLOUR)],
            metadata=_meta(what="true COM p_C"),
        )

    def contact(self, robot: int, p: Vec2) -> SceneEntity:
        colour = robot_colour(robot)
        return self._entity(
            f"contact/{robot}",
            spheres=[self._sphere(p, 0.05, _colour(colour))],
            texts=[self._label(p, str(robot), colour)],
            metadata=_meta(robot=robot, what="contact p_Ci"),
        )

    def force(self, robot: int, p: Vec2, force: Vec2, scale: float) -> SceneEntity:
        """An arrow from ``p`` along ``force``, ``scale × ‖force‖`` long (head included)."""
        length = scale * math.hypot(*force)
        arrow = ArrowPrimitive(
            pose=self._pose(p, math.atan2(force[1], force[0])),
            shaft_length=0.7 * length,
            shaft_diameter=0.012 * self.size,
            head_length=0.3 * length,
            head_diameter=0.035 * self.size,
            color=_colour(robot_colour(robot)),
        )
        return self._entity(
            f"force/{robot}",
            arrows=[arrow],
            metadata=_meta(robot=robot, what="commanded force (N, in W)", x=force[0], y=force[1]),
        )

    def com_estimate(self, robot: int, p: Vec2) -> SceneEntity:
        radius = 0.025 * self.size
        ring = [
            (radius * math.cos(a), radius * math.sin(a))
            for a in (2.0 * math.pi * k / RING_SIDES for k in range(RING_SIDES))
        ]
        colour = _colour(robot_colour(robot))
        return self._entity(
            f"com_estimate/{robot}",
            lines=[self._shape(LinePrimitiveLineType.LineLoop, p, ring, colour)],
            metadata=_meta(robot=robot, what="estimated COM p_Ci + (p̂_C − p_Ci)"),
        )

    def geometry(self, robot: int, others: list[Vec2], centroid: Vec2 | None) -> SceneEntity:
        colour = _colour(robot_colour(robot), 0.8)
        spheres = [self._sphere(q, 0.02, colour) for q in others]
        lines = []
        if centroid is not None:
            arm = 0.02 * self.size
            cross = [(-arm, 0.0), (arm, 0.0), (0.0, -arm), (0.0, arm)]
            lines.append(self._shape(LinePrimitiveLineType.LineList, centroid, cross, colour))
        return self._entity(
            f"geometry/{robot}",
            spheres=spheres,
            lines=lines,
            metadata=_meta(
                robot=robot, what="neighbours' contacts p_Ci − ẑ_ij, centroid p_Ci − ẑ_i"
            ),
        )


# ------------------------------------------------------------------------------ the news
PHASE_NEWS = {
    Phase.EXCITE: "the kick and the spin-up (Steps 1-3)",
    Phase.INERTIA: "Step 4, the moment of inertia",
    Phase.PUSH: "the push (Steps 5-7)",
    Phase.DONE: "zero force, the load coasts",
    Phase.HALTED: "a robot was lost, the team stopped pushing",
}
"""What entering each phase means, as the log says it."""
RESTARTS = (
    (
        "load_changes",
        LogLevel.Warning,
        ": the load changed: the team estimates it again from Step 4 (load change {})",
    ),
    (
        "rejoins",
        LogLevel.Info,
        ": every robot is back: the team begins again from Step 1 (rejoin {})",
    ),
)
"""The counters of :class:`~agent.platform.protocol.Estimates` that say the team began again,
each with its log level and what the log says."""


@dataclass
class _Heard:
    """What the news has said of one robot."""

    phase: Phase | None = None
    since: int = -1
    """The tick from which it is in :attr:`phase`, as far as heard."""
    estimates_tick: int = -(2**62)
    status_tick: int = -(2**62)
    """The ticks of its newest estimates and status heard (older ones say nothing new)."""
    settled: dict[int, int] = field(default_factory=dict)
    """The tick each step settled at, as said."""
    restarts: dict[str, int] = field(default_factory=dict)
    """Each counter of :data:`RESTARTS`, as said."""
    held: bool = False
    lost: tuple[int, ...] = ()
    concluded: bool = False
    """Whether its estimates once done were said."""


class TeamNews:
    """What a log panel should show of a team, from its robots' estimates and statuses, each
    said once: a robot's phase changes (from whichever of its estimates and statuses tells
    first; an older message does not take it back), each of its steps settling, its estimates
    once done, the floor holding the load, a changed load, a new beginning after a halt, and
    lost neighbours."""

    def __init__(self) -> None:
        self.robots: dict[int, _Heard] = {}

    def _robot(self, robot: int) -> _Heard:
        return self.robots.setdefault(robot, _Heard())

    def estimates(self, est: Estimates, stamp: Timestamp) -> list[Log]:
        """What robot ``est.robot``'s estimates say that was not said (nothing if older than
        its newest heard)."""
        heard = self._robot(est.robot)
        if est.tick < heard.estimates_tick:
            return []
        heard.estimates_tick = est.tick
        name = f"robot {est.robot}"
        news = []

        def say(level: LogLevel, text: str) -> None:
            news.append(_log(stamp, level, name, f"{name}{text}"))

        for key, level, text in RESTARTS:
            count = getattr(est, key)
            if count > heard.restarts.get(key, 0):
                heard.restarts[key] = count
                heard.held = heard.concluded = False
                say(level, text.format(count))
        news += self._phase(heard, name, est.phase, est.phase_since, stamp)
        for step, tick in sorted(est.settled.items()):
            if heard.settled.get(step) != tick:
                heard.settled[step] = tick
                say(LogLevel.Info, f": Step {step} ({STEP_NAMES[step]}) settled at tick {tick}")
        if est.stuck_torque is not None and not heard.held:
            heard.held = True
            say(
                LogLevel.Warning,
                f": the floor holds the load ({est.stuck_torque:.3g} N m applied without turning"
                " it): the robot pushes no more",
            )
        if est.phase == Phase.DONE and not heard.concluded:
            heard.concluded = True
            say(LogLevel.Info, f"'s estimates at tick {est.tick}: {_values(est)}")
        return news

    def status(self, status: Status, stamp: Timestamp) -> list[Log]:
        heard = self._robot(status.robot)
        if status.tick < heard.status_tick:
            return []
        heard.status_tick = status.tick
        name = f"robot {status.robot}"
        news = self._phase(heard, name, status.phase, status.tick, stamp)
        lost = tuple(sorted(status.lost_neighbours))
        if lost != heard.lost:
            if set(lost) - set(heard.lost):
                text = f"{name} lost its neighbour(s) {', '.join(map(str, lost))}"
                news.append(_log(stamp, LogLevel.Error, name, text))
            heard.lost = lost
        return news

    def _phase(
        self, heard: _Heard, name: str, phase: Phase, since: int, stamp: Timestamp
    ) -> list[Log]:
        if phase == heard.phase or since < heard.since:
            return []
        heard.phase, heard.since = phase, since
        level = LogLevel.Error if phase == Phase.HALTED else LogLevel.Info
        text = f"{name}: {phase.label} from tick {max(since, 0)}: {PHASE_NEWS[phase]}"
        return [_log(stamp, level, name, text)]


def _values(est: Estimates) -> str:
    """The scalars of :data:`~dashboard.quantities.SCALARS` that ``est`` has, and
    ``‖p̂_C − p_Ci‖``."""
    values = [
        f"{s.symbol} = {value:.{s.digits}f}{' ' + s.unit if s.unit else ''}"
        for s in SCALARS
        if (value := getattr(est, s.key)) is not None
    ]
    if est.contact_to_com is not None:
        values.append(f"‖p̂_C − p_Ci‖ = {math.hypot(*est.contact_to_com):.4f} m")
    return ", ".join(values) or "none"


def _log(stamp: Timestamp, level: LogLevel, name: str, text: str) -> Log:
    return Log(timestamp=stamp, level=level, message=text, name=name)
