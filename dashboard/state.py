"""What the page shows, aggregated from the team's messages: pure, no I/O, no clock of its own.

A source (the live Zenoh feed, a replayed recording, a test) hands :class:`TeamState` each
decoded message with the time it arrived (:meth:`TeamState.ingest`); the web app asks it, about
20 times a second, for a frame (:meth:`TeamState.frame`): the new points of every chart and the
scene (each robot's latest estimates, the graph's health, the top view, the alarms, the
table). Memory is bounded whatever the run's length: every chart keeps its newest
``capacity`` points, and a chart trace gets a point every :data:`RESOLUTION_S` of simulated
time at most, so the page's load does not grow with the team's message rate either.

Names follow the paper: ``m̂`` (``mass``), ``Ĵ`` (``moment``, about the COM), ``z_ij = p_Ci −
p_Cj`` (``relative_positions``), ``z_C = p_G − p_C`` (``com_offset``), ``ω`` (``omega``),
``p_C − p_Ci`` (``contact_to_com``).

Chart traces are named ``QUANTITY/ROBOT``: one per scalar of :data:`~dashboard.quantities.
SCALARS` (``mass/2``, ``moment/2``, ``friction_torque/2``, ``coulomb/2``), ``omega/2``,
``ctc/2`` (``‖p̂_C − p_C2‖``, robot 2's distance from its contact to the COM), ``edge/1-2``
(``‖ẑ_12‖`` as robot 1 knows it); the truth's are ``mass/truth``, ``moment/truth`` (and
likewise each scalar's), ``omega/truth``, ``ctc/2/truth`` and ``edge/1-2/truth``. Each point
is ``[t, value]``, ``t`` in simulated seconds (tick × period), or ``[t, value, h]`` when the
robot published an uncertainty of it: ``value ± h`` is its 95 % interval (``h = 1.96 σ``; for
the norms ``‖v̂‖``, ``σ² = ûᵀ C û`` with ``û = v̂ / ‖v̂‖`` and ``C`` the vector's covariance,
to first order). An uncertainty that is not one (non-finite, negative, not a covariance) is
dropped: that point has no ``h``.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass, field

from agent.platform.config import MAX_ROBOTS
from agent.platform.evaluation import (
    PLANAR_95,
    SCALAR_95,
    covariance,
    edges_interval,
    final_instant,
    planar_interval,
    robot_errors,
    scalar_interval,
    standard_deviation,
)
from agent.platform.protocol import (
    BridgeStatus,
    Clock,
    Command,
    Control,
    Estimates,
    LoadGeometry,
    Measurement,
    Phase,
    PlantStatus,
    Share,
    Status,
    Truth,
)
from dashboard.quantities import SCALARS
from dashboard.ticks import TickWindow

CAPACITY = 3000
"""Points kept per chart trace (at the 20 Hz frame rate, 2.5 minutes of a live run)."""
KEEP_TICKS = 1000
"""Ticks of truth and of done robots' estimates kept to find the final instant."""
MAX_SEGMENTS = 64
"""Phase changes kept per robot (a phase flapping forever cannot grow the timeline)."""
LINK_OK_S = 0.5
LINK_SILENT_S = 2.0
"""A link whose newest message is older than :data:`LINK_OK_S` is late, older than this,
silent."""
STALE_S = 3.0
"""No message from the team for this long, while it is not done: an alarm."""
DEFAULT_PERIOD_S = 0.01
RESOLUTION_S = 0.05
"""Simulated seconds between two points of a chart trace: what a page draws does not depend
on how often the robots report, nor on the speed of a replay, and is the same live and
replayed."""
_PHASES = [p.label for p in Phase]


def _norm(v) -> float | None:
    return None if v is None else math.hypot(v[0], v[1])


def _norm_half(v, cov) -> float | None:
    """The 95 % half-width of ``‖v‖`` for ``v`` of covariance ``cov``: ``1.96 σ`` with
    ``σ² = ûᵀ C û`` (``û = v / ‖v‖``); None without a covariance (:func:`~agent.platform.
    evaluation.covariance`) or a direction."""
    cov = covariance(cov)
    norm = _norm(v)
    if cov is None or not norm or not math.isfinite(norm):
        return None
    ux, uy = v[0] / norm, v[1] / norm
    xx, xy, yy = cov
    half = SCALAR_95 * math.sqrt(max(ux * ux * xx + 2.0 * ux * uy * xy + uy * uy * yy, 0.0))
    return half if math.isfinite(half) else None


def _ellipse(cov) -> list[float] | None:
    """The 95 % ellipse of a planar estimate of covariance ``cov`` (``eᵀ C⁻¹ e ≤ 5.99``):
    ``[major semi-axis, minor semi-axis, angle of the major axis]`` (m, m, rad), or None
    without a covariance."""
    cov = covariance(cov)
    if cov is None:
        return None
    xx, xy, yy = cov
    mean, radius = 0.5 * (xx + yy), math.hypot(0.5 * (xx - yy), xy)
    k = math.sqrt(PLANAR_95)
    axes = [k * math.sqrt(mean + radius), k * math.sqrt(max(mean - radius, 0.0))]
    if not all(map(math.isfinite, axes)):
        return None
    return [*axes, 0.5 * math.atan2(2.0 * xy, xx - yy)]


def _round(value, digits: int = 6):
    if value is None:
        return None
    if isinstance(value, dict):
        return {k: _round(v, digits) for k, v in value.items()}
    if isinstance(value, (tuple, list)):
        return [_round(v, digits) for v in value]
    return round(value, digits)


@dataclass
class RobotView:
    """What the dashboard knows of one robot."""

    robot: int
    estimates: Estimates | None = None
    status: Status | None = None
    bridge: BridgeStatus | None = None
    command: Command | None = None
    alive: bool | None = None
    """From its agent's liveliness token: None until heard of."""
    segments: list[tuple[str, int]] = field(default_factory=list)
    """The phase timeline: ``(phase, first tick)``, oldest first."""
    sampled_tick: int = -(2**62)
    """The tick of its newest estimates on the charts."""
    shares: deque = field(default_factory=lambda: deque(maxlen=1000))
    """When its shares arrived (for the links' age and rate)."""
    done_estimates: dict[int, Estimates] = field(default_factory=dict)
    """Its estimates in the done phase, by tick (the final instant's are among them)."""


class TeamState:
    """The team as the page shows it (see the module docstring).

    ``geometry`` (the load's outline, the graph and the period) comes from the plant
    (:class:`~agent.platform.protocol.LoadGeometry`, ingested as any message) or is given;
    without it the top view shows the contacts only, the graph is the one the robots'
    estimates reveal, and the period is learned from the plant's messages."""

    def __init__(
        self,
        team: str,
        geometry: LoadGeometry | None = None,
        capacity: int = CAPACITY,
    ):
        if capacity < 2:
            raise ValueError("capacity must be at least 2")
        self.team = team
        self.geometry = geometry
        self.capacity = capacity
        self.robots: dict[int, RobotView] = {}
        self.truth: Truth | None = None
        self.plant: PlantStatus | None = None
        self.truths: dict[int, Truth] = {}
        self._truth_rows: tuple[Truth | None, dict | None] = (None, None)
        """The last truth row made and its truth: a scene needs it twice, and a page's frames
        (~20 a second) ask for the same truth until a new one arrives."""
        self.series: dict[str, deque] = {}
        self._fresh: dict[str, deque] = {}
        """Points added since the last frame, per trace."""
        self.window = TickWindow()
        self.truth_sampled = -(2**62)
        self.period_s = geometry.period_s if geometry else None
        self.received: Counter[str] = Counter()
        self.rejected: Counter[tuple[str, str]] = Counter()
        self.stopped = False
        """The launcher told the team to stop (a lost robot then is not news)."""
        self.last_heard: float | None = None
        self.switches: dict[str, int] = {}
        """The team's phase switches: each phase's first tick (min over robots)."""
        self.final: dict | None = None
        self._scanned = False
        self.version = 0
        """Bumped by every accepted message (the app sends frames only on change)."""

    # ------------------------------------------------------------------ team facts
    @property
    def n(self) -> int | None:
        """The team's size: the scenario's, else the truth's contacts, else unknown."""
        if self.geometry is not None:
            return self.geometry.n
        if self.truth is not None:
            return len(self.truth.contacts)
        return None

    @property
    def period(self) -> float:
        return self.period_s or DEFAULT_PERIOD_S

    def t(self, tick: int) -> float:
        """Simulated seconds of ``tick``."""
        return round(tick * self.period, 9)

    @property
    def done(self) -> bool:
        """Every robot of the team is in the done phase."""
        n = self.n or len(self.robots)
        views = [self.robots.get(i) for i in range(1, n + 1)]
        return n > 0 and all(
            v is not None and v.estimates is not None and v.estimates.phase == Phase.DONE
            for v in views
        )

    @property
    def halted(self) -> bool:
        return any(
            (v.estimates is not None and v.estimates.phase == Phase.HALTED)
            or (v.status is not None and v.status.phase == Phase.HALTED)
            for v in self.robots.values()
        )

    # ------------------------------------------------------------------ intake
    def reject(self, what: str, why: str) -> None:
        """Count a message that could not be used (``why`` from a short fixed set)."""
        self.rejected[what, why] += 1

    def ingest(self, message: object, now: float) -> bool:
        """Take one decoded message that arrived at ``now`` (seconds, any steady clock);
        False (and counted) if it is not this team's or its tick is out of the window."""
        kind = type(message).__name__
        robot = getattr(message, "sender" if isinstance(message, Share) else "robot", None)
        limit = self.n or MAX_ROBOTS
        if robot is not None and not 1 <= robot <= limit:
            self.reject(kind, "not in the team")
            return False
        if not self.window.admits(message):
            self.reject(kind, "tick out of window")
            return False
        if isinstance(message, Truth) and self.n is not None and len(message.contacts) != self.n:
            self.reject(kind, "not the team's load")
            return False
        truth = self.truth
        if isinstance(message, LoadGeometry) and truth and len(truth.contacts) != message.n:
            self.reject(kind, "not the team's load")
            return False
        self.received[kind] += 1
        self.last_heard = now
        self.version += 1
        self.window.hear(message)
        view = self._robot(robot) if robot is not None else None
        if isinstance(message, Estimates):
            self._estimates(view, message)
        elif isinstance(message, Status):
            view.status = message
            self._phase(view, message.phase, message.tick)
        elif isinstance(message, Share):
            view.shares.append(now)
        elif isinstance(message, Command):
            if view.command is None or message.tick >= view.command.tick:
                view.command = message
        elif isinstance(message, BridgeStatus):
            view.bridge = message
        elif isinstance(message, Truth):
            self._truth(message)
        elif isinstance(message, LoadGeometry):
            self.geometry = message
            self.period_s = message.period_s
        elif isinstance(message, PlantStatus):
            self.plant = message
            self._learn_period(message.tick, message.time_s)
        elif isinstance(message, (Clock, Measurement)):
            self._learn_period(message.tick, message.time_s)
        elif isinstance(message, Control):
            self.stopped = True
        return True

    def liveliness(self, robot: int, alive: bool, now: float) -> None:
        """Robot ``robot``'s agent's liveliness token appeared (``alive``) or went away."""
        if not 1 <= robot <= (self.n or MAX_ROBOTS):
            self.reject("liveliness", "not in the team")
            return
        self._robot(robot).alive = alive
        self.version += 1

    def _robot(self, robot: int) -> RobotView:
        view = self.robots.get(robot)
        if view is None:
            view = self.robots[robot] = RobotView(robot)
        return view

    def _learn_period(self, tick: int, time_s: float) -> None:
        if self.geometry is None and tick > 0 and time_s > 0:
            period = time_s / tick
            if 1e-4 <= period <= 1.0:
                self.period_s = period

    def _phase(self, view: RobotView, phase: Phase, tick: int) -> None:
        label = phase.label
        if not view.segments or view.segments[-1][0] != label:
            view.segments.append((label, max(0, tick)))
            del view.segments[:-MAX_SEGMENTS]
        first = self.switches.get(label)
        if first is None or 0 <= tick < first:
            self.switches[label] = max(0, tick)

    def _estimates(self, view: RobotView, est: Estimates) -> None:
        if view.estimates is None or est.tick >= view.estimates.tick:  # else overtaken
            changed = view.estimates is None or view.estimates.phase != est.phase
            view.estimates = est
            self._phase(view, est.phase, est.phase_since)
            self._plot_estimates(view, est, force=changed)
        if est.phase == Phase.DONE:
            view.done_estimates[est.tick] = est
            if len(view.done_estimates) > KEEP_TICKS:
                del view.done_estimates[min(view.done_estimates)]
            self._conclude(est.tick)

    def _truth(self, truth: Truth) -> None:
        self._learn_period(truth.tick, truth.time_s)
        if self.truth is None or truth.tick >= self.truth.tick:
            self.truth = truth
            self._plot_truth(truth)
        self.truths[truth.tick] = truth
        if len(self.truths) > KEEP_TICKS:
            for old in sorted(self.truths)[: len(self.truths) - KEEP_TICKS]:
                del self.truths[old]
        self._conclude(truth.tick)

    # ------------------------------------------------------------------ the final instant
    @property
    def done_instant(self) -> int | None:
        """The first instant at which every robot was done, not before the scenario's end
        (:func:`~agent.platform.evaluation.final_instant` of each robot's latest estimates, as
        the launcher finds it), or None before every robot is done."""
        n = self.n
        if not n:
            return None
        latest = [view.estimates if (view := self.robots.get(i)) else None for i in range(1, n + 1)]
        end = self.geometry.end_tick if self.geometry is not None else 0
        return final_instant(latest, end)

    def _conclude(self, tick: int) -> None:
        """Look for the final table after a done estimate or a truth of ``tick`` arrived.

        The final instant is the first complete instant (every robot's done estimates and the
        truth) at or after :attr:`done_instant`, as the launcher takes it: a message of the
        done instant itself that a congested link dropped leaves the next complete one, and
        a complete instant that arrives late replaces a later one. A team done again after a
        restart for a changed load (a later done instant) gets a new final table."""
        instant = self.done_instant
        if instant is None:
            return
        final = self.final
        if final is not None and final["tick"] == instant:
            return
        if final is not None and final["tick"] < instant:
            # The team was done, then restarted for a changed load and is done again.
            self.final = final = None
            self._scanned = False
        if final is None and not self._scanned:
            self._scanned = True  # the done instant just became known: what came before it
            ticks = sorted(t for t in self.truths if t >= instant)
        else:
            ticks = [tick]
        for t in ticks:
            if t < instant or (final is not None and t >= final["tick"]):
                continue
            robots = {}
            for i in range(1, self.n + 1):
                est = self.robots[i].done_estimates.get(t)
                if est is None:
                    break
                robots[i] = est
            else:
                if t in self.truths:
                    self.final = self.table(self.truths[t], robots, final=True)
                    for i, est in robots.items():  # the charts end with the final values
                        self._plot_estimates(self.robots[i], est, force=True)
                    return

    # ------------------------------------------------------------------ the table
    def table(self, truth: Truth | None, robots: dict[int, Estimates], final: bool) -> dict:
        """Each robot's estimates against ``truth`` (when known): each of
        :data:`~dashboard.quantities.SCALARS` (m̂, Ĵ, ``τ̂_c``, ``μ̂``), ``p_C − p_Ci``,
        ``ẑ_C`` and their errors (:func:`~agent.platform.evaluation.robot_errors`: relative,
        metres, rad/s, N m and μ's, ``relative_positions_m`` over the neighbours its estimates
        name),
        the 95 % intervals of each of :data:`~dashboard.quantities.SCALARS`, of
        ``p_C − p_Ci`` and of the ``ẑ_ij`` as ``[half-width, truth inside]`` (the inside
        None without the truth; both None without an uncertainty:
        :mod:`agent.platform.evaluation`), and the worst of each error over the robots that
        have one."""
        rows = {}
        worst: dict[str, float] = {}
        for i, est in sorted(robots.items()):
            judged = truth if truth is not None and i <= len(truth.contacts) else None
            row = {
                "phase": est.phase.label,
                "load_changes": est.load_changes,
                "rejoins": est.rejoins,
                "change_score": est.change_score,
                "tick": est.tick,
                **{s.key: getattr(est, s.key) for s in SCALARS},
                "contact_to_com": est.contact_to_com,
                "com_offset": est.com_offset,
                "omega": est.omega,
                "relative_positions": _by_neighbour(est),
                "intervals": _intervals(est, judged),
            }
            if judged is not None:
                known = [j for j in est.relative_positions if 1 <= j <= len(truth.contacts)]
                errors = robot_errors(est, truth, known)
                row["errors"] = errors
                for name, value in errors.items():
                    if value is not None:
                        worst[name] = max(worst.get(name, 0.0), value)
            rows[str(i)] = row
        return {
            "final": final,
            "tick": truth.tick if truth else max((e.tick for e in robots.values()), default=-1),
            "t": self.t(truth.tick) if truth else None,
            "robots": rows,
            "truth": self._truth_row(truth),
            "worst": worst,
        }

    def _truth_row(self, truth: Truth | None) -> dict | None:
        """:func:`_truth_row` of ``truth``, made once per truth (see :attr:`_truth_rows`)."""
        made_for, row = self._truth_rows
        if truth is not made_for:
            row = _truth_row(truth)
            self._truth_rows = (truth, row)
        return row

    # ------------------------------------------------------------------ frames
    def _add(self, trace: str, tick: int, value, half: float | None = None) -> None:
        """A point of ``trace``: ``value`` at ``tick``, with its 95 % half-width ``half`` when
        it has one (see the module docstring)."""
        if value is None or not math.isfinite(value):
            return
        points = self.series.get(trace)
        if points is None:
            points = self.series[trace] = deque(maxlen=self.capacity)
        point = [self.t(tick), round(value, 9)]
        if half is not None and math.isfinite(value - half) and math.isfinite(value + half):
            point.append(round(half, 9))
        points.append(point)
        fresh = self._fresh.get(trace)
        if fresh is None:
            fresh = self._fresh[trace] = deque(maxlen=self.capacity)
        fresh.append(point)

    def _stride(self) -> int:
        """Ticks between two points of a chart trace (:data:`RESOLUTION_S`)."""
        return max(1, round(RESOLUTION_S / self.period))

    def _plot_estimates(self, view: RobotView, est: Estimates, force: bool = False) -> None:
        """Put ``est`` on the charts if it is :meth:`_stride` ticks after the previous point
        of its robot (or ``force``: a phase change, the final instant)."""
        if est.tick < view.sampled_tick + self._stride() and not force:
            return
        if est.tick <= view.sampled_tick:
            return
        view.sampled_tick = est.tick
        i, k = est.robot, max(est.tick, 0)
        for s in SCALARS:
            value = getattr(est, s.key)
            half, _ = scalar_interval(value, getattr(est, s.std), None)
            self._add(f"{s.key}/{i}", k, value, half)
        self._add(f"omega/{i}", k, est.omega)
        ctc = est.contact_to_com
        self._add(f"ctc/{i}", k, _norm(ctc), _norm_half(ctc, est.contact_to_com_cov))
        covs = est.relative_positions_cov
        for j, z in est.relative_positions.items():
            if j > i:
                self._add(f"edge/{i}-{j}", k, _norm(z), _norm_half(z, covs.get(j)))

    def _plot_truth(self, truth: Truth) -> None:
        """The truth beside the estimates: ``ω``, and the constants m, J, ``μ m g c`` and ``μ``
        (each of :data:`~dashboard.quantities.SCALARS` the truth has), each robot's
        ``‖p_C − p_Ci‖`` and each edge's ``‖z_ij‖`` as lines (so that a chart's range always
        holds the truth)."""
        if truth.tick < self.truth_sampled + self._stride():
            return
        self.truth_sampled = k = truth.tick
        self._add("omega/truth", k, truth.omega)
        for s in SCALARS:
            self._add(f"{s.key}/truth", k, getattr(truth, s.truth, None))
        for i, ctc in enumerate(truth.contact_to_com, start=1):
            self._add(f"ctc/{i}/truth", k, _norm(ctc))
        contacts = truth.contacts
        for i, j in self.edges():
            if j <= len(contacts):
                self._add(f"edge/{i}-{j}/truth", k, math.dist(contacts[i - 1], contacts[j - 1]))

    def frame(self, now: float) -> dict:
        """The new chart points since the previous frame and the scene at ``now``."""
        fresh, self._fresh = self._fresh, {}
        points = {trace: list(p) for trace, p in fresh.items()}
        return {"type": "frame", "points": points, "scene": self.page_scene(now)}

    def all_series(self) -> dict[str, list]:
        """Every chart trace's kept points (a page that connects starts from these; the next
        frame's points follow them, none left out, some perhaps repeated)."""
        return {trace: list(points) for trace, points in self.series.items()}

    # ------------------------------------------------------------------ the scene
    def edges(self) -> list[tuple[int, int]]:
        """The graph's edges: the scenario's, else those the robots' estimates name."""
        if self.geometry is not None:
            return list(self.geometry.edges)
        found = set()
        limit = self.n or MAX_ROBOTS
        for i, view in self.robots.items():
            if view.estimates is not None:
                for j in view.estimates.relative_positions:
                    if j != i and 1 <= j <= limit:
                        found.add((min(i, j), max(i, j)))
        return sorted(found)

    def lost(self) -> list[int]:
        """Robots known lost: by their liveliness, a neighbour's status or the plant's."""
        lost = {i for i, v in self.robots.items() if v.alive is False}
        for view in self.robots.values():
            if view.status is not None:
                lost.update(view.status.lost_neighbours)
        if self.plant is not None:
            lost.update(self.plant.lost)
        return sorted(lost)

    def _share_rate(self, view: RobotView | None, now: float) -> tuple[float | None, float]:
        if view is None or not view.shares:
            return None, 0.0
        age = max(0.0, now - view.shares[-1])
        rate = sum(1 for t in view.shares if now - 1.0 < t <= now)
        return age, float(rate)

    def links(self, now: float) -> list[dict]:
        """Each edge's health: the age of the older endpoint's newest share, the slower
        endpoint's rate (messages/s over the last second) and a verdict."""
        lost = set(self.lost())
        over = self.done or self.stopped
        out = []
        for i, j in self.edges():
            (age_i, rate_i), (age_j, rate_j) = (
                self._share_rate(self.robots.get(i), now),
                self._share_rate(self.robots.get(j), now),
            )
            age = None if age_i is None or age_j is None else max(age_i, age_j)
            if (i in lost or j in lost) and not over:
                health = "lost"
            elif over:
                health = "ended"
            elif age is None or age > LINK_SILENT_S:
                health = "silent"
            elif age > LINK_OK_S:
                health = "late"
            else:
                health = "ok"
            out.append(
                {
                    "edge": [i, j],
                    "age_s": None if age is None else round(age, 3),
                    "rate_hz": min(rate_i, rate_j),
                    "health": health,
                }
            )
        return out

    def alarms(self, now: float) -> list[dict]:
        """What an operator must see at once: a lost robot, a halt, a bridge's watchdog or stale
        force/torque sensor, a silent team, rejected messages."""
        alarms = []
        over = self.done or self.stopped
        lost = self.lost()
        if lost and not over:
            alarms.append({"level": "error", "text": f"robot(s) {lost} lost"})
        if self.halted:
            alarms.append(
                {
                    "level": "error",
                    "text": "team halted: a robot was lost, every robot stopped pushing",
                }
            )
        for i, view in sorted(self.robots.items()):
            bridge = view.bridge
            if bridge is None or over:
                continue
            stop = "standstill" if bridge.profile == "velocity" else "zero force"
            if bridge.watchdog:
                text = f"robot {i}'s bridge watchdog: {stop} (its agent fell silent)"
                alarms.append({"level": "error", "text": text})
            if bridge.sensor_stale:
                text = f"robot {i}'s force/torque sensor is stale: {stop}"
                alarms.append({"level": "error", "text": text})
            if bridge.overload_stops:
                text = (
                    f"robot {i}'s contact force went beyond max_contact_force:"
                    f" {bridge.overload_stops} protective stop(s)"
                )
                alarms.append({"level": "warning", "text": text})
        if self.last_heard is not None and not over and now - self.last_heard > STALE_S:
            silent = now - self.last_heard
            text = f"no message from the team for {silent:.0f} s"
            alarms.append({"level": "warning", "text": text})
        rejected = sum(self.rejected.values())
        if rejected:
            alarms.append({"level": "warning", "text": f"{rejected} message(s) rejected"})
        return alarms

    def top_view(self) -> dict | None:
        """The load seen from above: outline, contacts, true and estimated COM (with the 95 %
        ellipse of each robot's ``p̂_C − p_Ci``, when it published its covariance), forces.

        With the truth, in ``W``; without it, the team's own geometry about ``p_G``
        (contacts at ``ẑ_i``, COM at ``−ẑ_C``), so the view works on real robots too."""
        truth = self.truth
        n = self.n or (max(self.robots) if self.robots else 0)
        if truth is not None:
            contacts = [list(p) for p in truth.contacts]
            com = list(truth.com_position)
            outline = (
                self.geometry.world_outline(truth.com_position, truth.angle)
                if self.geometry is not None
                else None
            )
            source = "truth"
        else:
            contacts = []
            for i in range(1, n + 1):
                est = self.robots.get(i) and self.robots[i].estimates
                contacts.append(list(est.centroid_offset) if est and est.centroid_offset else None)
            com, outline, source = None, None, "estimates"
        com_estimates, ellipses, forces = {}, {}, {}
        for i in range(1, n + 1):
            view = self.robots.get(i)
            if view is None:
                continue
            est = view.estimates
            contact = contacts[i - 1] if i - 1 < len(contacts) else None
            if est is not None:
                if source == "truth" and contact is not None and est.contact_to_com is not None:
                    c = est.contact_to_com
                    com_estimates[str(i)] = [contact[0] + c[0], contact[1] + c[1]]
                elif source == "estimates" and est.com_offset is not None:
                    com_estimates[str(i)] = [-est.com_offset[0], -est.com_offset[1]]
                ellipse = _ellipse(est.contact_to_com_cov)
                if str(i) in com_estimates and ellipse is not None:
                    ellipses[str(i)] = ellipse
            if view.command is not None:
                forces[str(i)] = list(view.command.force)
        if not contacts and not com_estimates:
            return None
        return {
            "source": source,
            "outline": _round(outline),
            "contacts": _round(contacts),
            "com": _round(com),
            "com_estimates": _round(com_estimates),
            "com_ellipses": _round(ellipses),
            "forces": _round(forces),
            "angle": None if truth is None else round(truth.angle, 6),
        }

    def scene(self, now: float) -> dict:
        """Everything but the charts' points, as plain JSON values."""
        robots = {}
        for i, view in sorted(self.robots.items()):
            est = view.estimates
            robots[str(i)] = {
                "phase": None if est is None else est.phase.label,
                "tick": None if est is None else est.tick,
                **{s.key: None if est is None else getattr(est, s.key) for s in SCALARS},
                **_uncertainty(est),
                "omega": None if est is None else est.omega,
                "contact_to_com": None if est is None else est.contact_to_com,
                "com_offset": None if est is None else est.com_offset,
                "relative_positions": {} if est is None else _by_neighbour(est),
                "alive": view.alive,
                "segments": [[label, self.t(tick)] for label, tick in view.segments],
                "status": None
                if view.status is None
                else {
                    "rejected": view.status.rejected,
                    "decode_errors": view.status.decode_errors,
                    "late": view.status.late,
                    "lost_neighbours": list(view.status.lost_neighbours),
                },
                "bridge": None
                if view.bridge is None
                else {
                    "watchdog": view.bridge.watchdog,
                    "watchdog_trips": view.bridge.watchdog_trips,
                    "frames_in": view.bridge.frames_in,
                    "frames_out": view.bridge.frames_out,
                },
            }
        truth = self.truth
        plant = self.plant
        table = self.final
        if table is None:
            latest = {i: v.estimates for i, v in self.robots.items() if v.estimates is not None}
            table = self.table(truth, latest, final=False)
        return {
            "team": self.team,
            "n": self.n,
            "period_s": self.period,
            "t": self.t(max(self.window.latest, 0)),
            "done": self.done,
            "halted": self.halted,
            "stopped": self.stopped,
            "phases": _PHASES,
            "switches": {label: self.t(tick) for label, tick in self.switches.items()},
            "robots": robots,
            "truth": self._truth_row(truth),
            "plant": None
            if plant is None
            else {
                "clock": plant.clock,
                "late_commands": plant.late_commands,
                "missing_commands": plant.missing_commands,
                "latency_ms_p50": plant.latency_ms_p50,
                "latency_ms_p99": plant.latency_ms_p99,
            },
            "links": self.links(now),
            "alarms": self.alarms(now),
            "top": self.top_view(),
            "table": table,
            "received": dict(self.received),
            "rejected": {f"{what}: {why}": count for (what, why), count in self.rejected.items()},
        }

    def page_scene(self, now: float) -> dict:
        """The scene as the page draws it (its frames carry it ~20 times a second): what
        :meth:`scene` holds, less what the page does not show (per robot only its phase, tick,
        segments and liveliness; the table's rows without ω, ``ẑ_C`` and ``ẑ_ij``, of their
        errors those of :data:`~dashboard.quantities.SCALARS`, ``p_C − p_Ci`` and ``ẑ_ij``
        only, and of their intervals those published)."""
        scene = self.scene(now)
        scene["robots"] = {
            i: {key: view[key] for key in _PAGE_ROBOT} for i, view in scene["robots"].items()
        }
        table = scene["table"]  # the final table itself, once there is one: not changed
        truth = table["truth"]
        scene["table"] = {
            "final": table["final"],
            "t": table["t"],
            "robots": {i: _page_row(row) for i, row in table["robots"].items()},
            "truth": None if truth is None else {s.key: truth[s.key] for s in SCALARS},
        }
        for key in _NOT_ON_PAGE:
            del scene[key]
        return scene

    def snapshot(self, now: float) -> dict:
        """``GET /api/snapshot``: the scene (per robot: phase, m̂, Ĵ, ``τ̂_c``, ``μ̂``,
        ``contact_to_com``,
        ``relative_positions`` and their uncertainties; the links' health; the truth when
        known)."""
        return self.scene(now)


_PAGE_ROBOT = ("phase", "tick", "segments", "alive")
_PAGE_ROW = (
    "phase",
    "load_changes",
    "rejoins",
    "change_score",
    *(s.key for s in SCALARS),
    "contact_to_com",
    "intervals",
    "errors",
)
_PAGE_ERRORS = (
    *(s.error for s in SCALARS if s.error is not None),
    "contact_to_com_m",
    "relative_positions_m",
)
_NOT_ON_PAGE = ("truth", "plant", "received", "rejected")


def _page_row(row: dict) -> dict:
    """A row of the table as the page draws it (:data:`_PAGE_ROW`, :data:`_PAGE_ERRORS`; of
    the intervals only those the robot published)."""
    drawn = {key: row[key] for key in _PAGE_ROW if key in row}
    if "errors" in drawn:
        drawn["errors"] = {key: drawn["errors"][key] for key in _PAGE_ERRORS}
    if "intervals" in drawn:
        drawn["intervals"] = {k: v for k, v in drawn["intervals"].items() if v[0] is not None}
    return drawn


def _truth_row(truth: Truth | None) -> dict | None:
    if truth is None:
        return None
    n = len(truth.contacts)
    pairs = {}
    for i in range(n):
        for j in range(i + 1, n):
            a, b = truth.contacts[i], truth.contacts[j]
            pairs[f"{i + 1}-{j + 1}"] = round(math.dist(a, b), 9)
    return {
        "tick": truth.tick,
        **{s.key: getattr(truth, s.truth, None) for s in SCALARS},
        "omega": truth.omega,
        "com_offset": list(truth.com_offset),
        "com_offset_norm": round(_norm(truth.com_offset), 9),
        "contact_to_com": [list(c) for c in truth.contact_to_com],
        "edge_norms": pairs,
    }


def _by_neighbour(est: Estimates) -> dict[str, list]:
    """``ẑ_ij`` by neighbour ``j`` (as a string, for JSON)."""
    return {str(j): list(z) for j, z in sorted(est.relative_positions.items())}


def _intervals(est: Estimates, truth: Truth | None) -> dict[str, list]:
    """Robot ``est.robot``'s 95 % intervals as the table gives them (see
    :meth:`TeamState.table`)."""
    found = {
        s.key: scalar_interval(
            getattr(est, s.key), getattr(est, s.std), getattr(truth, s.truth, None)
        )
        for s in SCALARS
    }
    mine = None if truth is None else truth.contact_to_com[est.robot - 1]
    found["contact_to_com"] = planar_interval(est.contact_to_com, est.contact_to_com_cov, mine)
    found["relative_positions"] = edges_interval(est, truth)
    return {key: list(interval) for key, interval in found.items()}


def _uncertainty(est: Estimates | None) -> dict:
    """The uncertainties ``est`` published, those that can be one (else None): each scalar's
    standard deviation, the covariances of ``p_C − p_Ci`` and of each ``ẑ_ij`` by neighbour."""
    if est is None:
        return {
            **{s.std: None for s in SCALARS},
            "contact_to_com_cov": None,
            "relative_positions_cov": {},
        }
    return {
        **{s.std: standard_deviation(getattr(est, s.std)) for s in SCALARS},
        "contact_to_com_cov": covariance(est.contact_to_com_cov),
        "relative_positions_cov": {
            str(j): covariance(c) for j, c in sorted(est.relative_positions_cov.items())
        },
    }
