"""Scenarios: the load, where the robots hold it, who talks to whom, the sensors, the run.

A scenario is a TOML file (``simulator/scenarios/paper.toml`` is the paper's Sec. VI case)::

    name = "paper"
    [body]
    polygon = [[x, y], ...]   # load frame, metres, counter-clockwise; may be concave
    mass = 5.0                # kg
    moment = 12.3795          # kg m² about the COM; omitted -> uniform density over the polygon
    com = [x, y]              # load frame; omitted -> the polygon's area centroid
    [contacts]
    points = [[x, y], ...]    # load frame; robot 1..n in this order, on or near the boundary
    [graph]
    edges = [[1, 2], [2, 3]]  # undirected, connected
    [sensors]
    rate_hz = 100
    [floor]                   # optional: travel_m = 3.0, speed = 2.0 (m/s), omega = 2.0 (rad/s)
    [ground]                  # optional: friction; none -> frictionless, as in the paper
    coulomb = 0.02            # μ, kinetic, a fraction of the weight m g
    static = 0.03             # μ_s >= μ, breakaway; omitted -> coulomb
    viscous = 0.0             # N s/m for the whole load
    supports = [[x, y], ...]  # load frame; omitted -> the weight over the polygon's area
    [agvs]                    # optional: the AGVs; none -> force drives ([actuators])
    profile = "velocity"      # velocity-commanded bases pushing through compliant contacts
    [run]
    seed = 1
    [[events]]                # optional, any number: the load changes at at_s
    at_s = 30.0
    mass = 6.0                # kg; any of mass, moment (kg m², about the new COM), com

:func:`load_scenario` reads a file and :func:`parse_scenario` a table already decoded; both
return a validated, frozen :class:`Scenario` or raise :class:`ScenarioError`, whose one-line
message names the offending key. Every value has a range, declared next to its field
(:func:`agent.platform.config.bounded`) or as a constant below, and listed in
docs/configuration.md ("Limits").
:func:`scenario_to_toml` writes a scenario back.
Tables are turned into dataclasses by :func:`agent.platform.config.from_table`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tomllib
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agent.algorithm.tuning import AgentTuning
from agent.platform.config import (
    MAX_ROBOTS,
    MAX_SEED,
    ConfigError,
    bounded,
    bounds,
    check_bounds,
    from_table,
    toml_fields,
    toml_tables,
    toml_value,
)
from agent.platform.geometry import Vec2
from agent.platform.protocol import GRAVITY, LoadGeometry
from bridge.admittance import AdmittanceSettings
from simulator.polygon import (
    area_cells,
    distance_to_boundary,
    first_self_intersection,
    point_in_polygon,
    polygon_area_centroid_moment,
    polygon_diameter,
    polygon_signed_area,
)

PAPER_SCENARIO = Path(__file__).resolve().parent / "scenarios" / "paper.toml"
"""The paper's Sec. VI scenario, shipped with the simulator package."""
MAX_PHYSICS_HZ = 100_000.0
"""Physics steps per second, at most."""
MAX_SUBSTEPS = 100
"""Physics steps per sensor tick, at most."""
MAX_TIME_S = 3600.0
"""A run's simulated-time limit, at most."""
MAX_VERTICES = 1000
"""Vertices of the load's polygon, at most (checking that it is simple takes time quadratic in
their number: 0.3 s for 1000)."""
MAX_COORDINATE = 100.0
"""m: every vertex and the COM lie within this of the load frame's origin, per axis."""
MIN_DIAMETER = 0.1
"""m: the polygon is at least this wide (its diameter: the largest distance between vertices)."""
MAX_POSITION = 1000.0
"""m: the load starts within this of the world frame's origin, per axis (the messages carry
positions up to 10 km)."""
MAX_ANGLE = 2 * math.pi
"""rad: the load's initial angle is in [-2π, 2π]."""
GYRATION_RANGE = (0.01, 1.0)
"""The moment of inertia's radius of gyration ``sqrt(J/m)``, as fractions of the polygon's
diameter: a load whose mass lies within its outline stays below its diameter, and one below
1 % of it would be a point mass on a weightless plate."""

MAX_EVENTS = 100
"""Load changes (``[[events]]``) in a scenario, at most."""

MIN_CONTACT_SPACING = 0.05
"""m: two contacts must be at least this far apart."""
BOUNDARY_TOLERANCE = 0.05
"""m: a contact may lie up to ``max(BOUNDARY_TOLERANCE, BOUNDARY_FRACTION · diameter)`` off
the load's boundary."""
BOUNDARY_FRACTION = 0.02
"""Fraction of the polygon's diameter allowed between a contact and the boundary."""

MAX_FRICTION = 2.0
"""The largest friction coefficient, kinetic or static (``[ground]``): rubber on dry concrete
is about 1, a wooden pallet on wood 0.2–0.35, a caster's rolling resistance 0.002–0.02."""
MAX_VISCOUS = 10_000.0
"""N s/m: the largest viscous drag of the floor on the whole load."""
MAX_SUPPORTS = 100
"""Supports (``ground.supports``) at most: each costs the plant time at every physics step
(:mod:`simulator.friction`)."""
DEFAULT_SUPPORT_CELLS = 40
"""The cells of the polygon's area that carry a load without ``ground.supports``
(:func:`simulator.polygon.area_cells`: 40 to 60 of them, as the grid falls). With a support at
each cell's centroid, a pure spin about the COM meets a friction torque within 1 % of the
continuous one's, ``μ ∫ p ‖r‖ dA`` (the discrete one is lower: ‖r‖ is convex, so its mean
over a cell exceeds its value at the centroid). Measured against 90 000 cells:
the paper's plate −0.63 % with 44 cells, a square −0.96 % (49), a thin 20:1 bar −0.12 % (58),
a right triangle −0.47 % (58), an L −0.33 % (51), a hexagon −0.90 % (52); 20 cells give up to
−2 %, and every support costs the plant time at every physics step."""


class ScenarioError(ConfigError):
    """A scenario is invalid or unreadable. ``str()`` is one line naming the key, prefixed by
    the source (the file path when loading a file), e.g.
    ``paper.toml: graph.edges: the graph is not connected (robot 4 unreachable)``."""

    def __init__(self, message: str) -> None:
        super().__init__(" ".join(str(message).splitlines()))


# --------------------------------------------------------------------------------------------
# The scenario
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Body:
    """The load: its shape, mass, moment of inertia, COM and initial pose."""

    polygon: tuple[Vec2, ...]
    """Vertices in the load frame (m), counter-clockwise, simple, possibly concave: 3 to
    :data:`MAX_VERTICES` (1000) of them, each coordinate in [-100, 100] m, at least
    :data:`MIN_DIAMETER` (0.1 m) across."""
    mass: float
    """kg, in [0.01, 10000]."""
    moment: float
    """kg m², about the COM, in [0.0001, 1000000], with a radius of gyration ``sqrt(J/m)``
    between 1 % and 100 % of the polygon's diameter (:data:`GYRATION_RANGE`)."""
    com: Vec2
    """Centre of mass in the load frame (m), within the polygon's bounding box."""
    position: Vec2 = (0.0, 0.0)
    """Initial position of the load frame's origin in the world frame ``W`` (m), each
    coordinate in [-1000, 1000]."""
    angle: float = 0.0
    """Initial angle of the load frame in ``W`` (rad), in [-2π, 2π]."""
    moment_given: bool = True
    """False when the file omitted ``moment``: it is then the polygon's moment for uniform
    density about its area centroid (also when ``com`` is given elsewhere)."""
    com_given: bool = True
    """False when the file omitted ``com`` and it is the polygon's area centroid."""


@dataclass(frozen=True)
class Sensors:
    """What the robots sense: sample rate and white measurement noise."""

    rate_hz: float = bounded(100.0, 10, 1000, "Hz")
    """Sensor (and agent) tick rate: robots' odometry runs at 10 Hz to 1 kHz (the agents'
    defaults, e.g. the 0.5 s kick of Step 1, assume at least 10 Hz)."""
    velocity_noise_std: float = bounded(0.0, 0, 1, "m/s")
    """m/s per axis, white, on each contact-point velocity."""
    force_noise_std: float = bounded(0.0, 0, 100, "N")
    """N per axis, white, on each measured force."""

    def validate(self, where: str) -> None:
        """Raise :class:`ConfigError` naming the key and its range unless every field is in
        its range."""
        check_bounds(self, where)


@dataclass(frozen=True)
class Actuators:
    """How each robot's drive applies the force it is commanded (the paper's robots are ideal
    force sources: these default to that).

    Robot ``i`` commanded ``u_i`` applies ``f_i`` with ``τ ḟ_i = g_i u_i + w_i − f_i``: a
    first-order lag of time constant ``τ`` (none when 0), a gain ``g_i`` and white actuator
    noise ``w_i`` (N per axis, drawn once per tick and held over it). The gains are ``gains``
    when given, else ``1 + ε_i`` with ``ε_i ~ N(0, gain_error_std²)`` drawn once per run from
    the seed (and kept within [0.5, 1.5]). What a robot measures is the force it applied,
    averaged over the tick, plus ``sensors.force_noise_std``."""

    time_constant_s: float = bounded(0.0, 0, 1, "s")
    """``τ`` of the drive's first-order lag; 0: the force follows the command at once."""
    gain_error_std: float = bounded(0.0, 0, 0.3)
    """Relative standard deviation of the robots' gains (0.02: 2 %)."""
    gains: tuple[float, ...] = ()
    """Each robot's gain ``g_i``, robot 1 first, each in [0.5, 1.5]; when given,
    ``gain_error_std`` is not used."""
    force_noise_std: float = bounded(0.0, 0, 100, "N")
    """N per axis, white, on the applied force (the drive's own noise, not the sensor's)."""

    @property
    def ideal(self) -> bool:
        """Whether every robot applies exactly its command (the paper's assumption)."""
        return (
            self.time_constant_s == 0.0
            and self.gain_error_std == 0.0
            and all(g == 1.0 for g in self.gains)
            and self.force_noise_std == 0.0
        )

    def validate(self, where: str) -> None:
        """Raise :class:`ConfigError` naming the key and its range unless every field is in
        its range (the number of gains is checked with the scenario)."""
        check_bounds(self, where)
        for i, gain in enumerate(self.gains):
            if not 0.5 <= gain <= 1.5:
                key = f"{where}.gains[{i}]"
                raise ConfigError(f"{key}: expected a number in [0.5, 1.5], got {gain!r}")


MAX_CONTACT_STEP = 0.5
"""The largest ``ω_max / physics_hz`` of the contacts' springs on the load (rad per physics
step), and the largest ``C λ / physics_hz`` of their dampers (:func:`_check_contact_rate`):
the explicit step is stable below 2, and within 0.5 it follows the contact's motion to a few
per cent."""


@dataclass(frozen=True)
class Agvs:
    """The robots' AGVs (``[agvs]``; none: force drives, as in the paper).

    With ``profile = "velocity"`` each robot ``i`` is a base at ``x_i`` with velocity ``v_i``
    (world frame) under a speed loop ``v̇_i = clamp((v_cmd,i − v_i)/τ, max_accel)``,
    ``‖v_i‖ ≤ max_speed``, holding the load at ``C_i`` through a spring and damper,
    ``f_i = K (x_i − p_Ci) + C (v_i − ṗ_Ci)``; a force/torque sensor in the contact measures
    ``f_i`` plus a bias drawn per robot from the seed and ``sensors.force_noise_std``. The
    agent's force command reaches the base through the admittance loop
    (:mod:`bridge.admittance`) of ``admittance`` (:mod:`simulator.bases`)."""

    profile: str = "force"
    """``force`` (the paper's robots, ``[actuators]``) or ``velocity``: the CAN protocol's
    profiles (:data:`bridge.dbc.PROFILES`)."""
    speed_time_constant_s: float = bounded(0.05, 0.001, 1, "s")
    """``τ``: the base's speed loop, first order."""
    max_accel: float = bounded(3.0, 0, 100, "m/s²", open_low=True)
    """The base's own acceleration limit."""
    max_speed: float = bounded(4.0, 0, 16, "m/s", open_low=True)
    """The base's own speed limit."""
    contact_stiffness: float = bounded(3000.0, 10, 1_000_000, "N/m")
    """``K``: the contact's spring; 1000 (soft foam) to 10 000 (a sprung bumper) is the range
    the admittance loop is made for."""
    contact_damping: float = bounded(20.0, 0, 10_000, "N s/m")
    """``C``: the contact's damper."""
    sensor_bias_std: float = bounded(0.3, 0, 100, "N")
    """N per axis: each robot's force/torque sensor's bias, drawn once per run from the seed
    (the admittance loop tares it at start-up)."""
    admittance: AdmittanceSettings = AdmittanceSettings()
    """The admittance loop's gains and limits (``[agvs.admittance]``): in one process the
    plant's; over CAN written into every bridge's ``[can.admittance]``."""

    @property
    def velocity(self) -> bool:
        """Whether the robots are velocity-commanded bases."""
        return self.profile == "velocity"

    def validate(self, where: str) -> None:
        """Raise :class:`ConfigError` naming the key unless the profile is known and every
        field is in its range."""
        from bridge.dbc import PROFILES  # cantools: only for a scenario with [agvs]

        if self.profile not in PROFILES:
            raise ConfigError(
                f"{where}.profile: expected one of {', '.join(PROFILES)}, got {self.profile!r}"
            )
        check_bounds(self, where)


@dataclass(frozen=True)
class Floor:
    """The floor the load must stay on: limits on its COM's travel from where it started, its
    speed and its angular speed. The agents keep to it by their force laws (the damping and the
    reversing push of :mod:`agent.algorithm.phase_machine`); each run's results check the truth
    against it
    (:func:`simulator.results.floor_check`)."""

    travel_m: float = bounded(3.0, 0, 1000, "m", open_low=True)
    """m: the COM's largest distance from its starting point."""
    speed: float = bounded(2.0, 0, 100, "m/s", open_low=True)
    """m/s: the COM's largest speed."""
    omega: float = bounded(2.0, 0, 100, "rad/s", open_low=True)
    """rad/s: the largest angular speed."""

    def validate(self, where: str) -> None:
        """Raise :class:`ConfigError` naming the key and its range unless every field is in
        its range."""
        check_bounds(self, where)


@dataclass(frozen=True)
class LoadChange:
    """A change of the load at ``at_s`` (``[[events]]``): part of it dropped or added, as in the
    paper's motivation. Each of ``mass``, ``moment`` and ``com`` that is given replaces the
    load's; the robots keep holding it at the same contacts, and every contact's velocity is
    unchanged at the instant of the change (the load's velocity field is continuous)."""

    at_s: float = bounded(dataclasses.MISSING, 0, MAX_TIME_S, "s", open_low=True)
    """s of simulated time, within ``run.max_time_s``; the events in increasing order."""
    mass: float | None = None
    """kg, in [0.01, 10000]."""
    moment: float | None = None
    """kg m² about the (new) COM, in [0.0001, 1000000], with the body's radius-of-gyration
    range."""
    com: Vec2 | None = None
    """The new COM in the load frame (m), within the polygon's bounding box."""

    def validate(self, where: str) -> None:
        """Raise :class:`ConfigError` naming the key unless every given field is in range."""
        check_bounds(self, where)
        if self.mass is not None:
            _BODY_BOUNDS["mass"].check(f"{where}.mass", self.mass)
        if self.moment is not None:
            _BODY_BOUNDS["moment"].check(f"{where}.moment", self.moment)
        if self.mass is None and self.moment is None and self.com is None:
            raise ConfigError(f"{where}: expected at least one of mass, moment, com")

    def applied_to(self, body: Body) -> Body:
        """``body`` after this change."""
        return dataclasses.replace(
            body,
            mass=body.mass if self.mass is None else self.mass,
            moment=body.moment if self.moment is None else self.moment,
            com=body.com if self.com is None else self.com,
        )


@dataclass(frozen=True)
class SupportLoads:
    """How a load of mass ``m`` and COM ``p_C`` rests on the floor's supports
    (:meth:`Ground.loads`), with the friction figures that follow."""

    normal: tuple[float, ...]
    """``N_k`` (N), one per support, each ``≥ 0``: ``Σ N_k = m g`` and ``Σ N_k r_k = 0``,
    ``r_k = s_k − p_C``."""
    friction_radius: float
    """``c = Σ N_k ‖r_k‖ / (m g)`` (m): a pure spin about the COM meets the friction torque
    ``μ m g c``."""
    viscous_radius2: float
    """``ρ² = Σ N_k ‖r_k‖² / (m g)`` (m²): a spin meets the viscous torque ``b ρ² ω``."""


@dataclass(frozen=True)
class Ground:
    """The floor under the load (``[ground]``; none: frictionless, as in the paper).

    The load rests on supports ``s_k`` (load frame): the given ``ground.supports`` (casters,
    pallet feet), else the centroids of the polygon's area cells (:data:`DEFAULT_SUPPORT_CELLS`).
    Each slides on the floor against its velocity ``u_k`` with the Coulomb force ``μ N_k``,
    sticks while the applied wrench cannot break the load away (up to ``μ_s N_k`` at each),
    and is dragged back by ``−b (N_k / m g) u_k``: a force and a torque, coupled as on a real
    floor (:mod:`simulator.friction`). The drag sums to ``−b ṗ_C`` and ``−b ρ² ω``."""

    coulomb: float
    """``μ``, kinetic, a fraction of the weight ``m g`` (``g`` =
    :data:`~agent.platform.protocol.GRAVITY`), in [0, :data:`MAX_FRICTION`]."""
    static: float
    """``μ_s``, breakaway, in [``coulomb``, :data:`MAX_FRICTION`]."""
    viscous: float
    """``b`` (N s/m) for the whole load, in [0, :data:`MAX_VISCOUS`]."""
    supports: tuple[Vec2, ...]
    """``s_k``: load-frame points the load rests on."""
    stiffness: tuple[float, ...]
    """Each support's share of the floor's stiffness (:meth:`loads`): 1 for each given
    support, its cell's area (m²) for the polygon's cells."""
    supports_given: bool = True
    """False when the file omitted ``supports`` and they are the polygon's cells."""

    def loads(self, mass: float, com: Vec2) -> SupportLoads:
        """The normal loads of a rigid load of ``mass`` and ``com`` on these supports, each a
        spring of its :attr:`stiffness` ``k_k``; negative ones that are only rounding are 0.

        The floor yields by a plane, ``δ(s) = a + βᵀ(s − s̄)`` about the supports'
        stiffness-weighted centroid ``s̄``, so ``N_k = k_k δ(s_k)``; the vertical force and the
        two tilting moments balance the weight at the COM: ``Σ N_k = m g`` gives
        ``a = m g / Σ k_k``, ``Σ N_k (s_k − s̄) = m g (p_C − s̄)`` gives ``β = m g C⁻¹ (p_C − s̄)``
        with ``C = Σ k_k (s_k − s̄)(s_k − s̄)ᵀ``. Of the loads in statics, these have the least
        ``Σ N_k² / k_k``: for given supports (equal springs) the minimum-norm ones, for the
        cells the linear pressure of a rigid plate on an elastic floor, uniform when the COM is
        the area centroid."""
        weight = mass * GRAVITY
        normal = tuple(max(0.0, n) for n in self.normal_loads(weight, com))
        arms = [math.hypot(x - com[0], y - com[1]) for x, y in self.supports]
        return SupportLoads(
            normal=normal,
            friction_radius=math.fsum(n * r for n, r in zip(normal, arms)) / weight,
            viscous_radius2=math.fsum(n * r * r for n, r in zip(normal, arms)) / weight,
        )

    def normal_loads(self, weight: float, com: Vec2) -> list[float]:
        """:meth:`loads`' ``N_k`` for the weight ``weight`` (N), before rounding is cleared:
        one below zero says the load would lift off that support."""
        k = self.stiffness
        total = math.fsum(k)
        gx = math.fsum(w * s[0] for w, s in zip(k, self.supports)) / total
        gy = math.fsum(w * s[1] for w, s in zip(k, self.supports)) / total
        dx, dy = com[0] - gx, com[1] - gy
        cxx, cxy, cyy = _second_moments(self.supports, k, (gx, gy))
        det = cxx * cyy - cxy * cxy
        bx = weight * (cyy * dx - cxy * dy) / det
        by = weight * (cxx * dy - cxy * dx) / det
        a = weight / total
        return [w * (a + bx * (x - gx) + by * (y - gy)) for w, (x, y) in zip(k, self.supports)]


def _second_moments(
    points: Sequence[Vec2], weights: Sequence[float], about: Vec2
) -> tuple[float, float, float]:
    """``Σ w (p − about)(p − about)ᵀ`` as ``(xx, xy, yy)``."""
    ox, oy = about
    xx = math.fsum(w * (x - ox) ** 2 for w, (x, y) in zip(weights, points))
    xy = math.fsum(w * (x - ox) * (y - oy) for w, (x, y) in zip(weights, points))
    yy = math.fsum(w * (y - oy) ** 2 for w, (x, y) in zip(weights, points))
    return xx, xy, yy


@dataclass(frozen=True)
class RunSettings:
    """How a run is simulated."""

    seed: int = bounded(1, 0, MAX_SEED)
    """Seed of every random draw of the run (noise, the agents' kicks)."""
    physics_hz: float = bounded(1000.0, 10, MAX_PHYSICS_HZ, "Hz")
    """Physics step rate: an integer multiple of ``sensors.rate_hz``, at most
    :data:`MAX_SUBSTEPS` (100) times it."""
    max_time_s: float = bounded(60.0, 0, MAX_TIME_S, "s", open_low=True)
    """Simulated-time limit of a run (s)."""
    real_time_factor: float = bounded(1.0, 0.01, 100.0)
    """The pace of the wall clock (``--clock realtime``): simulated seconds per wall-clock
    second. 1 is real time; below 1 gives each tick more wall time, for a machine that cannot
    keep up at the sensor rate (User-Mode Linux, a loaded laptop). The physics, the ticks and
    the estimates are the same; only the wall time between ticks changes. Lockstep ignores it."""
    hold_s: float = bounded(0.0, 0, MAX_TIME_S, "s")
    """Simulated seconds the run goes on after the last load change (``[[events]]``; after
    the start when there is none) before it may end with the team done: the time the team has
    to notice a change, and, with no change, to show it raises no false alarm."""

    def validate(self, where: str) -> None:
        """Raise :class:`ConfigError` naming the key and its range unless every field is in
        its range (the ratio to ``sensors.rate_hz`` is checked with the scenario)."""
        check_bounds(self, where)


@dataclass(frozen=True)
class Scenario:
    """A validated scenario: robot ``i`` (1-based) holds the load at ``contacts[i - 1]``."""

    name: str
    body: Body
    contacts: tuple[Vec2, ...]
    """Contact points in the load frame, robot 1..n in this order."""
    edges: tuple[tuple[int, int], ...]
    """Undirected communication graph over robots 1..n, connected."""
    sensors: Sensors = Sensors()
    run: RunSettings = RunSettings()
    agent: AgentTuning = AgentTuning()
    description: str = ""
    actuators: Actuators = Actuators()
    floor: Floor = Floor()
    events: tuple[LoadChange, ...] = ()
    """The load's changes during the run, in time order."""
    ground: Ground | None = None
    """The floor's friction; None: frictionless, as in the paper."""
    agvs: Agvs = Agvs()
    """The AGVs: force drives (the default) or velocity-commanded bases."""

    @property
    def end_s(self) -> float:
        """The earliest simulated time (s) at which a run with the team done may end: the last
        load change's time (0 without one) plus ``run.hold_s``."""
        last = self.events[-1].at_s if self.events else 0.0
        return last + self.run.hold_s

    @property
    def end_tick(self) -> int:
        """The first tick at or after :attr:`end_s`."""
        return math.ceil(self.end_s / self.period_s - 1e-9)

    @property
    def n(self) -> int:
        """Number of robots (one per contact)."""
        return len(self.contacts)

    @property
    def period_s(self) -> float:
        """Sensor period (s)."""
        return 1.0 / self.sensors.rate_hz

    @property
    def substeps(self) -> int:
        """Physics steps per sensor tick."""
        return round(self.run.physics_hz / self.sensors.rate_hz)

    def neighbours(self, robot: int) -> tuple[int, ...]:
        """The graph neighbours of ``robot`` (1-based), sorted."""
        if not 1 <= robot <= self.n:
            raise ValueError(f"robot {robot} does not exist (robots are 1..{self.n})")
        found = {j for i, j in self.edges if i == robot} | {i for i, j in self.edges if j == robot}
        return tuple(sorted(found))

    def load_geometry(self) -> LoadGeometry:
        """What the plant tells displays of this scenario (:class:`LoadGeometry`): the load's
        polygon about its COM, the graph, the sensor period and :attr:`end_tick`."""
        cx, cy = self.body.com
        return LoadGeometry(
            n=self.n,
            outline=tuple((x - cx, y - cy) for x, y in self.body.polygon),
            edges=tuple(sorted((min(e), max(e)) for e in self.edges)),
            period_s=self.period_s,
            end_tick=self.end_tick,
        )


def boundary_tolerance(polygon: Sequence[Vec2]) -> float:
    """How far (m) a contact may lie from the boundary of ``polygon``."""
    return max(BOUNDARY_TOLERANCE, BOUNDARY_FRACTION * polygon_diameter(polygon))


# --------------------------------------------------------------------------------------------
# Parsing and validation
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _BodyTable:
    """The ``[body]`` table as written. ``moment`` and ``com`` are optional: their defaults
    here are placeholders, whether they were given is read from the table's keys."""

    polygon: tuple[Vec2, ...]
    mass: float = bounded(dataclasses.MISSING, 0.01, 10_000, "kg")
    moment: float = bounded(1.0, 1e-4, 1e6, "kg m²")
    com: Vec2 = (0.0, 0.0)
    position: Vec2 = (0.0, 0.0)
    angle: float = bounded(0.0, -MAX_ANGLE, MAX_ANGLE, "rad")

    def validate(self, where: str) -> None:
        check_bounds(self, where)


_BODY_BOUNDS = bounds(_BodyTable)


@dataclass(frozen=True)
class _ContactsTable:
    points: tuple[Vec2, ...]


@dataclass(frozen=True)
class _GraphTable:
    edges: tuple[tuple[int, int], ...]


@dataclass(frozen=True)
class _GroundTable:
    """The ``[ground]`` table as written; whether ``supports`` was given is read from the
    table's keys (its default here is a placeholder)."""

    coulomb: float = bounded(0.0, 0, MAX_FRICTION)
    static: float | None = None
    viscous: float = bounded(0.0, 0, MAX_VISCOUS, "N s/m")
    supports: tuple[Vec2, ...] = ()

    def validate(self, where: str) -> None:
        check_bounds(self, where)
        bound = bounds(_GroundTable)["coulomb"]
        if self.static is not None and not bound.contains(self.static, low=self.coulomb):
            why = f" (at least {where}.coulomb)"
            raise ConfigError(bound.message(f"{where}.static", self.static, self.coulomb, why))


_TOP_LEVEL: dict[str, str | None] = {
    # key -> what is expected when it is required, None when it is optional
    "name": "a string",
    "description": None,
    "body": "a table",
    "contacts": "a table",
    "graph": "a table",
    "sensors": None,
    "actuators": None,
    "floor": None,
    "run": None,
    "agent": None,
    "events": None,
    "ground": None,
    "agvs": None,
}


def _check_top_level(data: Any) -> None:
    if not isinstance(data, Mapping):
        raise ScenarioError(f"expected a table at the top level, got {type(data).__name__}")
    unknown = sorted(set(data) - set(_TOP_LEVEL))
    if unknown:
        raise ScenarioError(f"{unknown[0]}: unknown key (expected one of: {', '.join(_TOP_LEVEL)})")
    for key, expected in _TOP_LEVEL.items():
        if expected is not None and key not in data:
            raise ScenarioError(f"{key}: missing (expected {expected})")


def _check_text(data: Mapping[str, Any], key: str, nonempty: bool) -> str:
    value = data.get(key, "")
    if not isinstance(value, str):
        raise ScenarioError(f"{key}: expected a string, got {value!r}")
    if nonempty and not value.strip():
        raise ScenarioError(f"{key}: expected a non-empty string")
    return value


def _check_polygon(polygon: tuple[Vec2, ...], key: str) -> None:
    """Raise unless ``polygon`` is a simple, counter-clockwise polygon of nonzero area."""
    if not 3 <= len(polygon) <= MAX_VERTICES:
        raise ScenarioError(f"{key}: expected 3 to {MAX_VERTICES} vertices, got {len(polygon)}")
    _check_coordinates(polygon, key, MAX_COORDINATE)
    for j, q in enumerate(polygon):
        for i in range(j):
            if polygon[i] == q:
                raise ScenarioError(f"{key}[{j}]: repeats vertex {key}[{i}] {list(q)}")
    diameter = polygon_diameter(polygon)
    if diameter < MIN_DIAMETER:
        raise ScenarioError(
            f"{key}: the polygon is {diameter:.3g} m across; expected at least {MIN_DIAMETER} m"
        )
    area = polygon_signed_area(polygon)
    if abs(area) <= 1e-12 * diameter**2:
        raise ScenarioError(f"{key}: the polygon has zero area")
    crossing = first_self_intersection(polygon)
    if crossing is not None:
        i, j = crossing
        count = len(polygon)
        raise ScenarioError(
            f"{key}: the polygon is self-intersecting (edge {i}->{(i + 1) % count} meets "
            f"edge {j}->{(j + 1) % count}); expected a simple polygon"
        )
    if area < 0:
        raise ScenarioError(f"{key}: the vertices are clockwise; they must be counter-clockwise")


def _check_point(point: Vec2, key: str, limit: float) -> None:
    """Raise unless both coordinates of ``point`` are in ``[-limit, limit]``."""
    if not all(-limit <= c <= limit for c in point):
        raise ScenarioError(
            f"{key}: expected coordinates in [-{limit:g}, {limit:g}] m, got {list(point)}"
        )


def _check_coordinates(points: Sequence[Vec2], key: str, limit: float) -> None:
    """Raise unless every coordinate of ``points`` is in ``[-limit, limit]``."""
    for i, point in enumerate(points):
        _check_point(point, f"{key}[{i}]", limit)


def _check_mass_distribution(body: Body) -> None:
    """Raise unless the COM lies in the polygon's bounding box and the radius of gyration is
    within :data:`GYRATION_RANGE` of the polygon's diameter."""
    xs, ys = [p[0] for p in body.polygon], [p[1] for p in body.polygon]
    (x, y) = body.com
    if not (min(xs) <= x <= max(xs) and min(ys) <= y <= max(ys)):
        raise ScenarioError(
            f"body.com: expected a point within the polygon's bounding box"
            f" [{min(xs):g}, {max(xs):g}] x [{min(ys):g}, {max(ys):g}] m, got {list(body.com)}"
        )
    diameter = polygon_diameter(body.polygon)
    low, high = (body.mass * (f * diameter) ** 2 for f in GYRATION_RANGE)
    if not low <= body.moment <= high:
        source = "body.moment" if body.moment_given else "body.moment (implied by the polygon)"
        raise ScenarioError(
            f"{source}: expected a number in [{low:.4g}, {high:.4g}] kg m² for this mass and"
            f" polygon (a radius of gyration of 1 % to 100 % of its {diameter:.3g} m diameter),"
            f" got {body.moment!r}"
        )


def _parse_body(table: Any) -> Body:
    raw = from_table(_BodyTable, table, "body")
    moment_given, com_given = "moment" in table, "com" in table
    _check_polygon(raw.polygon, "body.polygon")
    if com_given:
        _check_point(raw.com, "body.com", MAX_COORDINATE)
    _check_point(raw.position, "body.position", MAX_POSITION)
    _, centroid, uniform_moment = polygon_area_centroid_moment(raw.polygon, raw.mass)
    body = Body(
        polygon=raw.polygon,
        mass=raw.mass,
        moment=raw.moment if moment_given else uniform_moment,
        com=raw.com if com_given else centroid,
        position=raw.position,
        angle=raw.angle,
        moment_given=moment_given,
        com_given=com_given,
    )
    _check_mass_distribution(body)
    return body


def _parse_contacts(table: Any, polygon: tuple[Vec2, ...]) -> tuple[Vec2, ...]:
    points = from_table(_ContactsTable, table, "contacts").points
    if not 2 <= len(points) <= MAX_ROBOTS:
        raise ScenarioError(
            f"contacts.points: expected 2 to {MAX_ROBOTS} contacts (robots), got {len(points)}"
        )
    tolerance = boundary_tolerance(polygon)
    for i, point in enumerate(points):
        distance = distance_to_boundary(point, polygon)
        if distance > tolerance:
            raise ScenarioError(
                f"contacts.points[{i}]: robot {i + 1}'s contact {list(point)} is "
                f"{distance:.3g} m from the load's boundary; expected at most {tolerance:.3g} m"
            )
    for j, q in enumerate(points):
        for i in range(j):
            distance = math.dist(points[i], q)
            if distance < MIN_CONTACT_SPACING:
                raise ScenarioError(
                    f"contacts.points[{j}]: {distance:.3g} m from contacts.points[{i}]; "
                    f"contacts must be at least {MIN_CONTACT_SPACING} m apart"
                )
    return points


def _parse_edges(table: Any, n: int) -> tuple[tuple[int, int], ...]:
    edges = from_table(_GraphTable, table, "graph").edges
    seen: dict[tuple[int, int], int] = {}
    for k, (i, j) in enumerate(edges):
        key = f"graph.edges[{k}]"
        for robot in (i, j):
            if not 1 <= robot <= n:
                raise ScenarioError(
                    f"{key}: robot {robot} does not exist (robots are 1..{n}, one per contact)"
                )
        if i == j:
            raise ScenarioError(f"{key}: self-loop on robot {i}")
        pair = (min(i, j), max(i, j))
        if pair in seen:
            raise ScenarioError(
                f"{key}: duplicate of graph.edges[{seen[pair]}] (edges are undirected)"
            )
        seen[pair] = k
    _check_connected(edges, n)
    return edges


def _check_connected(edges: tuple[tuple[int, int], ...], n: int) -> None:
    adjacency: dict[int, set[int]] = {robot: set() for robot in range(1, n + 1)}
    for i, j in edges:
        adjacency[i].add(j)
        adjacency[j].add(i)
    for robot, neighbours in adjacency.items():
        if not neighbours:
            raise ScenarioError(f"graph.edges: robot {robot} has no edge")
    reached = {1}
    queue = deque([1])
    while queue:
        for other in adjacency[queue.popleft()] - reached:
            reached.add(other)
            queue.append(other)
    if len(reached) < n:
        missing = min(set(adjacency) - reached)
        raise ScenarioError(
            f"graph.edges: the graph is not connected (robot {missing} unreachable)"
        )


def _check_rates(sensors: Sensors, run: RunSettings) -> None:
    ratio = run.physics_hz / sensors.rate_hz
    if round(ratio) < 1 or abs(ratio - round(ratio)) > 1e-9 * ratio:
        raise ScenarioError(
            f"run.physics_hz: expected a positive integer multiple of sensors.rate_hz "
            f"({sensors.rate_hz!r}), got {run.physics_hz!r}"
        )
    if round(ratio) > MAX_SUBSTEPS:
        raise ScenarioError(
            f"run.physics_hz: expected at most {MAX_SUBSTEPS} physics steps per sensor tick"
            f" ({MAX_SUBSTEPS * sensors.rate_hz:g} Hz at {sensors.rate_hz:g} Hz),"
            f" got {run.physics_hz!r}"
        )


def _parse(data: Any) -> Scenario:
    _check_top_level(data)
    name = _check_text(data, "name", nonempty=True)
    description = _check_text(data, "description", nonempty=False)
    body = _parse_body(data["body"])
    contacts = _parse_contacts(data["contacts"], body.polygon)
    edges = _parse_edges(data["graph"], len(contacts))
    sensors = from_table(Sensors, data.get("sensors", {}), "sensors")
    run = from_table(RunSettings, data.get("run", {}), "run")
    _check_rates(sensors, run)
    agent = from_table(AgentTuning, data.get("agent", {}), "agent")
    agent.check_period("agent", 1.0 / sensors.rate_hz, f"sensors.rate_hz = {sensors.rate_hz:g}")
    actuators = from_table(Actuators, data.get("actuators", {}), "actuators")
    if actuators.gains and len(actuators.gains) != len(contacts):
        raise ScenarioError(
            f"actuators.gains: expected one gain per robot ({len(contacts)}),"
            f" got {len(actuators.gains)}"
        )
    floor = from_table(Floor, data.get("floor", {}), "floor")
    events = _parse_events(data.get("events", []), body, run)
    ground = None if "ground" not in data else _parse_ground(data["ground"], body, events)
    agvs = from_table(Agvs, data.get("agvs", {}), "agvs")
    if agvs.velocity:
        if "actuators" in data:
            raise ScenarioError(
                "actuators: models force drives; the AGVs of agvs.profile = velocity are bases"
                " with a speed loop (agvs.speed_time_constant_s, max_accel, max_speed)"
            )
        _check_contact_rate(agvs, body, contacts, events, run)
    return Scenario(
        name,
        body,
        contacts,
        edges,
        sensors,
        run,
        agent,
        description,
        actuators,
        floor,
        events,
        ground,
        agvs,
    )


def _check_contact_rate(
    agvs: Agvs,
    body: Body,
    contacts: tuple[Vec2, ...],
    events: tuple[LoadChange, ...],
    run: RunSettings,
) -> None:
    """Raise unless the physics steps resolve the contacts' springs and dampers on every load of
    the run. With ``λ = Σ_i (2/m + ‖C_i − p_C‖²/J)`` (the trace of ``M⁻¹`` mapped to the
    contacts, which bounds the largest eigenvalue of the load's three degrees of freedom on
    ``n`` unit springs), ``ω_max = √(K λ)`` and ``C λ`` are each within
    :data:`MAX_CONTACT_STEP` per physics step."""
    loads = [body]
    for event in events:
        loads.append(event.applied_to(loads[-1]))
    worst = max(
        sum(2.0 / b.mass + math.dist(c, b.com) ** 2 / b.moment for c in contacts) for b in loads
    )
    omega = math.sqrt(agvs.contact_stiffness * worst)
    rate = agvs.contact_damping * worst
    if max(omega, rate) / run.physics_hz > MAX_CONTACT_STEP:
        key, value = "contact_stiffness", f"{agvs.contact_stiffness:g} N/m"
        if rate > omega:
            key, value = "contact_damping", f"{agvs.contact_damping:g} N s/m"
        raise ScenarioError(
            f"run.physics_hz: expected at least {max(omega, rate) / MAX_CONTACT_STEP:.4g} Hz"
            f" for agvs.{key} = {value} on this load, got {run.physics_hz!r}"
        )


def _parse_ground(table: Any, body: Body, events: tuple[LoadChange, ...]) -> Ground:
    """``[ground]``: its supports (given, or the polygon's cells), each load the run has (the
    body, then after each change) resting on them with no support lifting off."""
    raw = from_table(_GroundTable, table, "ground")
    given = "supports" in table
    if given:
        _check_supports(raw.supports, body.polygon)
        supports, stiffness = raw.supports, (1.0,) * len(raw.supports)
    else:
        cells = area_cells(body.polygon, DEFAULT_SUPPORT_CELLS)
        supports, stiffness = tuple(c for c, _ in cells), tuple(a for _, a in cells)
    static = raw.coulomb if raw.static is None else raw.static
    ground = Ground(raw.coulomb, static, raw.viscous, supports, stiffness, given)
    _check_resting(ground, body, "")
    for i, event in enumerate(events):
        body = event.applied_to(body)
        _check_resting(ground, body, f"events[{i}]: ")
    return ground


def _check_supports(supports: tuple[Vec2, ...], polygon: tuple[Vec2, ...]) -> None:
    """Raise unless there are 3 to :data:`MAX_SUPPORTS` distinct supports, not on one line,
    each on the load (within the contacts' boundary tolerance of it)."""
    key = "ground.supports"
    if not 3 <= len(supports) <= MAX_SUPPORTS:
        raise ScenarioError(f"{key}: expected 3 to {MAX_SUPPORTS} points, got {len(supports)}")
    _check_coordinates(supports, key, MAX_COORDINATE)
    tolerance = boundary_tolerance(polygon)
    for j, q in enumerate(supports):
        for i in range(j):
            if supports[i] == q:
                raise ScenarioError(f"{key}[{j}]: repeats {key}[{i}] {list(q)}")
        if not point_in_polygon(q, polygon) and distance_to_boundary(q, polygon) > tolerance:
            raise ScenarioError(
                f"{key}[{j}]: {list(q)} is off the load (outside its polygon by more than"
                f" {tolerance:.3g} m)"
            )
    count = len(supports)
    centre = (sum(x for x, _ in supports) / count, sum(y for _, y in supports) / count)
    xx, xy, yy = _second_moments(supports, (1.0,) * count, centre)
    if xx * yy - xy * xy <= 1e-12 * (xx + yy) ** 2:
        raise ScenarioError(
            f"{key}: the supports lie on one line; a load rests on three or more that do not"
        )


def _check_resting(ground: Ground, body: Body, where: str) -> None:
    """Raise unless ``body`` rests on ``ground``'s supports with none of them pulling it down
    (:meth:`Ground.loads`; ``where`` prefixes the message for a load after a change)."""
    weight = body.mass * GRAVITY
    normal = ground.normal_loads(weight, body.com)
    k = min(range(len(normal)), key=normal.__getitem__)
    if normal[k] >= -1e-9 * weight:
        return
    com = [round(c, 6) for c in body.com]
    if ground.supports_given:
        raise ScenarioError(
            f"{where}ground.supports[{k}]: would carry {normal[k]:.3g} N, less than nothing:"
            f" the COM {com} lies outside the supports' hull or too near its edge for a rigid"
            f" load on supports of equal stiffness"
        )
    _, centroid, _ = polygon_area_centroid_moment(body.polygon, body.mass)
    raise ScenarioError(
        f"{where}body.com: {com} is too far from the polygon's centroid"
        f" {[round(c, 6) for c in centroid]} for the load to rest on its whole area (the floor's"
        f" pressure would be negative near {[round(c, 3) for c in ground.supports[k]]});"
        f" give ground.supports"
    )


def _parse_events(array: Any, body: Body, run: RunSettings) -> tuple[LoadChange, ...]:
    """``[[events]]``: each a :class:`LoadChange`, in increasing time within the run, each
    leaving a load whose COM and moment pass the body's checks."""
    if not isinstance(array, list):
        raise ScenarioError(f"events: expected an array of tables ([[events]]), got {array!r}")
    if len(array) > MAX_EVENTS:
        raise ScenarioError(f"events: expected at most {MAX_EVENTS} load changes, got {len(array)}")
    events = []
    for i, table in enumerate(array):
        where = f"events[{i}]"
        event = from_table(LoadChange, table, where)
        if event.com is not None:
            _check_point(event.com, f"{where}.com", MAX_COORDINATE)
        if event.at_s >= run.max_time_s:
            raise ScenarioError(
                f"{where}.at_s: expected a time before run.max_time_s ({run.max_time_s:g} s),"
                f" got {event.at_s!r}"
            )
        if events and event.at_s <= events[-1].at_s:
            raise ScenarioError(
                f"{where}.at_s: expected a time after the previous event's"
                f" ({events[-1].at_s:g} s), got {event.at_s!r}"
            )
        body = event.applied_to(body)
        try:
            _check_mass_distribution(body)
        except ScenarioError as err:
            raise ScenarioError(f"{where}: {err}") from None
        events.append(event)
    return tuple(events)


def parse_scenario(data: Mapping[str, Any], source: str = "<scenario>") -> Scenario:
    """Validate a decoded TOML table and build the :class:`Scenario`.

    Raises :class:`ScenarioError` (``"<source>: <key>: <what was expected>"``).
    """
    try:
        return _parse(data)
    except ConfigError as err:
        raise ScenarioError(f"{source}: {err}") from err


def load_scenario(path: str | os.PathLike[str]) -> Scenario:
    """Read and validate a scenario file; errors are prefixed by the path as given."""
    source = os.fspath(path)
    try:
        raw = Path(path).read_bytes()
    except FileNotFoundError:
        raise ScenarioError(f"{source}: no such file") from None
    except OSError as err:
        raise ScenarioError(f"{source}: cannot read the file ({err.strerror or err})") from err
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as err:
        raise ScenarioError(f"{source}: not valid TOML (not UTF-8 text: {err.reason})") from err
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"{source}: not valid TOML: {err}") from err
    return parse_scenario(data, source)


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------


def _toml_points(key: str, points: Sequence[Vec2]) -> list[str]:
    return [f"{key} = ["] + [f"    {toml_value(p)}," for p in points] + ["]"]


def _toml_body(body: Body) -> list[str]:
    lines = ["[body]", *_toml_points("polygon", body.polygon), f"mass = {body.mass!r}"]
    if body.moment_given:
        lines.append(f"moment = {body.moment!r}")
    else:
        lines.append(f"# moment omitted: uniform density over the polygon gives {body.moment!r}")
    if body.com_given:
        lines.append(f"com = {toml_value(body.com)}")
    else:
        lines.append(f"# com omitted: the polygon's area centroid {toml_value(body.com)}")
    lines += [f"position = {toml_value(body.position)}", f"angle = {body.angle!r}"]
    return lines


def _toml_ground(ground: Ground) -> list[str]:
    lines = ["[ground]", f"coulomb = {ground.coulomb!r}", f"static = {ground.static!r}"]
    lines.append(f"viscous = {ground.viscous!r}")
    if ground.supports_given:
        return lines + _toml_points("supports", ground.supports)
    return lines + ["# supports omitted: the polygon's area cells"]


def scenario_to_toml(s: Scenario) -> str:
    """TOML text that :func:`parse_scenario` reads back to a scenario equal to ``s``.

    ``moment`` and ``com`` are written when the scenario gave them; when they were implied
    (uniform density), they are written as comments so that reading the text back implies
    them again, to the same values. ``[agent]`` lists only the values that differ from the
    defaults.
    """
    lines = [f"name = {toml_value(s.name)}"]
    if s.description:
        lines.append(f"description = {toml_value(s.description)}")
    lines += ["", *_toml_body(s.body), "", "[contacts]", *_toml_points("points", s.contacts)]
    lines += ["", "[graph]", f"edges = {toml_value(s.edges)}"]
    lines += ["", "[sensors]", *toml_fields(s.sensors)]
    actuators = toml_fields(s.actuators, only_changed=True)
    if actuators:
        lines += ["", "[actuators]", *actuators]
    floor = toml_fields(s.floor, only_changed=True)
    if floor:
        lines += ["", "[floor]", *floor]
    if s.ground is not None:
        lines += ["", *_toml_ground(s.ground)]
    agvs = toml_fields(s.agvs, only_changed=True)
    admittance = toml_tables(s.agvs, "agvs.", only_changed=True)
    if agvs or admittance:
        lines += ["", "[agvs]", *agvs, *admittance]
    lines += ["", "[run]", *toml_fields(s.run)]
    agent = toml_fields(s.agent, only_changed=True)
    if agent:
        lines += ["", "[agent]", *agent]
    lines += toml_tables(s.agent, "agent.", only_changed=True)
    for event in s.events:
        lines += ["", "[[events]]", f"at_s = {event.at_s!r}"]
        lines += [
            f"{key} = {toml_value(getattr(event, key))}"
            for key in ("mass", "moment", "com")
            if getattr(event, key) is not None
        ]
    return "\n".join(lines) + "\n"
