"""A run's results: the JSON document, the worst errors against truth, and a text table.

Everything here is computed from the final :class:`~simulator.inprocess.Sample` of a run (every
robot's :class:`~agent.platform.protocol.Estimates` and the plant's truth of the same instant) and
from the scenario (robot ids and graph). Units are SI; vectors are ``[x, y]`` in the world frame
``W`` at the final estimation instant.

Conventions (those of :mod:`agent.platform.protocol`):

- ``contact_to_com`` of robot ``i`` is ``p_C − p_Ci``;
- ``relative_positions[j]`` of robot ``i`` is ``z_ij = p_Ci − p_Cj`` (``j`` a graph neighbour);
- ``centroid_offset`` is ``z_i = p_Ci − p_G`` (``p_G`` the centroid of the contacts);
- ``com_offset`` is ``z_C = p_G − p_C``; ``com_observer`` is observer (24)'s ``ẑ_C``.

Paper steps (``phases`` of the JSON), from each robot's :class:`~agent.platform.protocol.Estimates`
(``started[step]`` and ``settled[step]``, ticks):

- ``start_s`` = when the first robot began the step, ``min_i started_i[step] × period``;
- ``end_s`` = when the last robot's estimate settled, ``max_i settled_i[step] × period``;
- either is ``None`` if some robot never reached it. Steps 1–3 run side by side, and so do 5–7.

The times at which the *team* switched force regime (``excite``, ``inertia``, ``push``,
``done``) are given beside them, under ``team_phases``.

Uncertainty (the robust estimators publish it): each robot's ``mass_std`` and ``moment_std``,
``friction_torque_std`` and ``coulomb_std``, and the covariances ``[xx, xy, yy]`` of
``contact_to_com`` and of each ``relative_positions`` entry, as published; and under
``intervals`` (:func:`intervals`) the 95 % intervals' half-widths and whether the truth fell
inside each: ``|error| ≤ 1.96 σ`` for a scalar (m, J, ``τ̂_c``, ``μ̂``), the 95 % ellipse
``eᵀ C⁻¹ e ≤ 5.99`` for a vector (its half-width given along its least certain axis).

Friction (the robust estimators estimate it): ``friction_torque`` ``τ̂_c`` (N m) is the floor's
Coulomb friction torque on a spin about the COM, judged against the truth's ``μ m g c``
(:attr:`~agent.platform.protocol.Truth.coulomb_torque`, ``truth.ground.coulomb_torque``), and
``coulomb`` ``μ̂`` its kinetic coefficient, judged against ``truth.ground.coulomb``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from agent.platform import evaluation
from agent.platform.evaluation import (
    ERROR_KEYS,
    edges_interval,
    planar_interval,
    scalar_interval,
    true_relative,
)
from agent.platform.protocol import STEP_NAMES, STEPS

if TYPE_CHECKING:
    from agent.platform.protocol import Estimates, Truth
    from simulator.inprocess import RunOutcome
    from simulator.scenario import Scenario

FRICTION_KEYS = ("friction_torque", "friction_torque_std", "coulomb", "coulomb_std")
"""The floor's friction as a robot estimates it (:class:`~agent.platform.protocol.Estimates`):
``τ̂_c`` (N m) and ``μ̂`` with their standard deviations."""


# ------------------------------------------------------------------------------ small helpers
def _number(value: float | None) -> float | None:
    """``value`` as a float, or None when it is missing or not finite (JSON has no NaN)."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def _vec(value: Sequence[float] | None) -> list[float] | None:
    """``value`` as a JSON pair ``[x, y]``, or None when missing or not finite."""
    if value is None:
        return None
    x, y = _number(value[0]), _number(value[1])
    return None if x is None or y is None else [x, y]


# ------------------------------------------------------------------------------ truth
def _neighbours(outcome: RunOutcome) -> dict[int, tuple[int, ...]]:
    scenario = outcome.scenario
    return {i: scenario.neighbours(i) for i in range(1, scenario.n + 1)}


def _truth_dict(outcome: RunOutcome) -> dict[str, Any]:
    truth = outcome.final.truth
    robots = {}
    for i, neighbours in _neighbours(outcome).items():
        robots[str(i)] = {
            "contact_to_com": _vec(truth.contact_to_com[i - 1]),
            "relative_positions": {str(j): _vec(true_relative(truth, i, j)) for j in neighbours},
            "centroid_offset": _vec(truth.centroid_offsets[i - 1]),
        }
    return {
        "mass": _number(truth.mass),
        "moment": _number(truth.moment),
        "omega": _number(truth.omega),
        "com_offset": _vec(truth.com_offset),
        "robots": robots,
        "ground": ground_dict(truth),
    }


def ground_dict(truth: Truth) -> dict[str, Any]:
    """The floor under the load as the plant applied it at the final instant (all zero without
    friction): ``coulomb`` μ, ``static`` μ_s, ``viscous`` b (N s/m), ``friction_radius`` c (m:
    a pure spin meets ``μ m g c``), ``coulomb_torque`` ``τ_c = μ m g c`` (N m, what the robots'
    ``friction_torque`` estimates), ``viscous_radius2`` ρ² (m²: a spin meets ``b ρ² ω``), and
    the floor's ``friction_force`` (N, ``[x, y]``) and ``friction_torque`` (N m, about the COM)
    averaged over the last period."""
    return {
        "coulomb": _number(truth.ground_coulomb),
        "static": _number(truth.ground_static),
        "viscous": _number(truth.ground_viscous),
        "friction_radius": _number(truth.friction_radius),
        "coulomb_torque": _number(truth.coulomb_torque),
        "viscous_radius2": _number(truth.viscous_radius2),
        "friction_force": _vec(truth.friction_force),
        "friction_torque": _number(truth.friction_torque),
    }


# ------------------------------------------------------------------------------ estimates
def _robot_dict(est: Estimates | None, period: float) -> dict[str, Any]:
    """One robot's estimates as JSON (all None when the robot reported nothing)."""
    if est is None:
        return {
            **dict.fromkeys(("mass", "moment", "contact_to_com")),
            "relative_positions": {},
            **dict.fromkeys(("centroid_offset", "com_offset", "com_observer", "omega", "phase")),
            "settled_s": {},
            **dict.fromkeys(("mass_std", "moment_std", "contact_to_com_cov")),
            "relative_positions_cov": {},
            **dict.fromkeys(("drive_gain", "drive_gain_std")),
            **dict.fromkeys(FRICTION_KEYS),
        }
    return {
        "mass": _number(est.mass),
        "moment": _number(est.moment),
        "contact_to_com": _vec(est.contact_to_com),
        "relative_positions": {str(j): _vec(z) for j, z in sorted(est.relative_positions.items())},
        "centroid_offset": _vec(est.centroid_offset),
        "com_offset": _vec(est.com_offset),
        "com_observer": _vec(est.com_observer),
        "omega": _number(est.omega),
        "phase": est.phase.label,
        "settled_s": {str(step): tick * period for step, tick in sorted(est.settled.items())},
        "mass_std": _number(est.mass_std),
        "moment_std": _number(est.moment_std),
        "contact_to_com_cov": None
        if est.contact_to_com_cov is None
        else list(est.contact_to_com_cov),
        "relative_positions_cov": {
            str(j): list(c) for j, c in sorted(est.relative_positions_cov.items())
        },
        "drive_gain": _number(est.drive_gain),
        "drive_gain_std": _number(est.drive_gain_std),
        **{key: _number(getattr(est, key)) for key in FRICTION_KEYS},
    }


# ------------------------------------------------------------------------------ errors
def robot_errors(outcome: RunOutcome, robot: int) -> dict[str, float | None]:
    """Robot ``robot``'s errors against truth at the final instant
    (:func:`agent.platform.evaluation.robot_errors`: ``relative_positions_m`` over its graph
    neighbours; None: no estimate)."""
    final = outcome.final
    neighbours = outcome.scenario.neighbours(robot)
    return evaluation.robot_errors(final.estimates.get(robot), final.truth, neighbours)


def errors(outcome: RunOutcome) -> dict[str, float | None]:
    """The worst error over robots of each estimate at the final instant
    (:func:`agent.platform.evaluation.team_errors`).

    Keys are :data:`~agent.platform.evaluation.ERROR_KEYS`: ``mass_rel`` and ``moment_rel``
    are relative (``|m̂ − m| / m``), the ``_m`` keys are Euclidean distances in metres,
    ``omega_rad_s`` is ``|ω̂ − ω|``, ``friction_torque_nm`` ``|τ̂_c − μ m g c|`` (N m) and
    ``coulomb`` ``|μ̂ − μ|``. A value is None when some robot has no such estimate.
    """
    final = outcome.final
    found = evaluation.team_errors(final.estimates, final.truth, _neighbours(outcome))
    return {key: _number(value) for key, value in found.items()}


# ------------------------------------------------------------------------------ intervals
def intervals(outcome: RunOutcome, robot: int) -> dict[str, Any] | None:
    """Robot ``robot``'s published 95 % intervals against the truth at the final instant:
    ``{"mass": [half-width kg, inside], "moment": [...], "friction_torque": [half-width N m,
    inside], "coulomb": [...], "contact_to_com": [half-width m, inside], "relative_positions":
    [widest half-width m, every edge inside]}``, ``[None, None]`` for a quantity without an
    uncertainty; ``None`` for a robot that published none."""
    est = outcome.final.estimates.get(robot)
    if est is None or (est.mass_std is None and not est.relative_positions_cov):
        return None
    truth = outcome.final.truth
    return {
        "mass": list(scalar_interval(est.mass, est.mass_std, truth.mass)),
        "moment": list(scalar_interval(est.moment, est.moment_std, truth.moment)),
        "friction_torque": list(
            scalar_interval(est.friction_torque, est.friction_torque_std, truth.coulomb_torque)
        ),
        "coulomb": list(scalar_interval(est.coulomb, est.coulomb_std, truth.ground_coulomb)),
        "contact_to_com": list(
            planar_interval(
                est.contact_to_com, est.contact_to_com_cov, truth.contact_to_com[robot - 1]
            )
        ),
        "relative_positions": list(edges_interval(est, truth)),
    }


# ------------------------------------------------------------------------------ phases
def step_times(outcome: RunOutcome) -> list[dict[str, Any]]:
    """``[{"step", "start_s", "end_s"}, ...]`` for steps 1..7 (see the module docstring)."""
    period = outcome.scenario.period_s
    estimates = [outcome.final.estimates.get(i) for i in range(1, outcome.scenario.n + 1)]
    rows: list[dict[str, Any]] = []
    for step in STEPS:
        starts = [None if e is None else e.started.get(step) for e in estimates]
        ends = [None if e is None else e.settled.get(step) for e in estimates]
        start = None if None in starts else min(starts) * period  # type: ignore[type-var]
        end = None if None in ends else max(ends) * period  # type: ignore[type-var]
        rows.append({"step": step, "start_s": start, "end_s": end, "name": STEP_NAMES[step]})
    return rows


def floor_check(outcome: RunOutcome) -> dict[str, Any]:
    """The load's excursion against the scenario's floor: its COM's largest distance from
    where it started (m), largest speed (m/s) and largest ``|ω|`` (rad/s) over every tick
    from the start to the final instant, as the plant tracked them (the final truth's
    ``largest_travel``, ``largest_speed`` and ``largest_omega``: the same figures in one
    process and over Zenoh, whatever the launcher heard); the limits, and whether all three
    were kept (``within``)."""
    floor = outcome.scenario.floor
    truth = outcome.final.truth
    travel, speed, omega = truth.largest_travel, truth.largest_speed, truth.largest_omega
    return {
        "travel_m": travel,
        "speed": speed,
        "omega": omega,
        "limits": {"travel_m": floor.travel_m, "speed": floor.speed, "omega": floor.omega},
        "within": travel <= floor.travel_m and speed <= floor.speed and omega <= floor.omega,
    }


def load_changes(outcome: RunOutcome) -> dict[str, Any]:
    """The scenario's load changes and the team's restarts (:mod:`agent.algorithm.coordination`):
    each change with the first restart after it (``restarted_s``, ``None`` if the team never
    restarted for it) and the delay (``latency_s``); every restart (``restarts_s``, from the
    recorded estimates: the tick at which each load change's Step 4 began); and the restarts
    that followed no change (``false_alarms``)."""
    period = outcome.scenario.period_s
    began: dict[int, int] = {}
    for sample in (*outcome.history, outcome.final):
        for est in sample.estimates.values():
            start = est.started.get(4)
            if est.load_changes > 0 and start is not None:
                began[est.load_changes] = min(began.get(est.load_changes, start), start)
    restarts = [began[e] * period for e in sorted(began)]
    changes = [
        {
            "at_s": event.at_s,
            **{k: v for k, v in (("mass", event.mass), ("moment", event.moment)) if v is not None},
            **({"com": list(event.com)} if event.com is not None else {}),
            "restarted_s": None,
            "latency_s": None,
        }
        for event in outcome.scenario.events
    ]
    false_alarms = 0
    for t in restarts:
        before = [c for c in changes if c["at_s"] <= t]
        if before and before[-1]["restarted_s"] is None:
            before[-1]["restarted_s"] = t
            before[-1]["latency_s"] = t - before[-1]["at_s"]
        else:
            false_alarms += 1
    return {"changes": changes, "restarts_s": restarts, "false_alarms": false_alarms}


def team_phases(outcome: RunOutcome) -> dict[str, float]:
    """When the team entered each force regime (s), from the run's phase switches."""
    period = outcome.scenario.period_s
    return {name: tick * period for name, tick in outcome.phase_ticks.items()}


# ------------------------------------------------------------------------------ the document
def results_dict(outcome: RunOutcome) -> dict[str, Any]:
    """The results JSON of a run (see the module docstring and docs/results.md)."""
    period = outcome.scenario.period_s
    robots = {
        str(i): _robot_dict(outcome.final.estimates.get(i), period)
        for i in range(1, outcome.scenario.n + 1)
    }
    document = {
        "scenario": outcome.scenario.name,
        "converged": bool(outcome.converged),
        "reason": outcome.reason,
        "detail": outcome.detail,
        "sim_time_s": float(outcome.sim_time_s),
        "wall_time_s": float(outcome.wall_s),
        "n": outcome.scenario.n,
        "edges": [list(e) for e in outcome.scenario.edges],
        "phases": step_times(outcome),
        "team_phases": team_phases(outcome),
        "robots": robots,
        "truth": _truth_dict(outcome),
        "errors": errors(outcome),
        "intervals": {str(i): intervals(outcome, i) for i in range(1, outcome.scenario.n + 1)},
        "rejections": rejection_counts(outcome.transport.get("rejections")),
        "floor": floor_check(outcome),
        "load_changes": load_changes(outcome),
    }
    if "bridges" in outcome.transport:  # a run over CAN: each robot's AGV bridge's counters
        document["bridges"] = outcome.transport["bridges"]
    network = network_dict(outcome)
    if network is not None:
        document["network"] = network
    if outcome.converged:
        del document["detail"]  # a sentence saying why not: only when it did not
    return document


def network_dict(outcome: RunOutcome) -> dict[str, Any] | None:
    """A run over Zenoh: each tick's command latency as the plant measured it (publishing the
    tick to receiving its command: p50, p99, ms) and each time the team halted and began
    again (``halted_s``, null when the halt was not heard, e.g. the router was down;
    ``began_s``); ``None`` in one process."""
    plant = outcome.transport.get("plant")
    if plant is None:
        return None
    period = outcome.scenario.period_s
    return {
        "command_latency_ms": {
            "p50": plant.get("latency_ms_p50"),
            "p99": plant.get("latency_ms_p99"),
            "samples": plant.get("latency_samples"),
        },
        "rejoins": [
            {
                "halted_s": None if r["halted"] is None else r["halted"] * period,
                "began_s": r["began"] * period,
            }
            for r in outcome.transport.get("rejoins", [])
        ],
    }


def failed_results_dict(
    scenario: Scenario,
    reason: str,
    detail: str,
    wall_s: float | None = None,
    rejections: dict | None = None,
) -> dict[str, Any]:
    """The results JSON of a run that recorded nothing: the same keys as :func:`results_dict`,
    ``converged`` false, the reason, and null estimates, truth and errors."""
    n = scenario.n
    return {
        "scenario": scenario.name,
        "converged": False,
        "reason": reason,
        "detail": detail,
        "sim_time_s": None,
        "wall_time_s": _number(wall_s),
        "n": n,
        "edges": [list(e) for e in scenario.edges],
        "phases": [
            {"step": step, "start_s": None, "end_s": None, "name": STEP_NAMES[step]}
            for step in STEPS
        ],
        "team_phases": {},
        "robots": {str(i): _robot_dict(None, scenario.period_s) for i in range(1, n + 1)},
        "truth": None,
        "errors": dict.fromkeys(ERROR_KEYS),
        "intervals": {str(i): None for i in range(1, n + 1)},
        "rejections": rejection_counts(rejections),
        "floor": None,
        "load_changes": None,
    }


def rejection_counts(rejections: dict | None) -> dict[str, Any] | None:
    """The messages a run over Zenoh rejected, with totals (None in one process: nothing there
    is decoded). ``launcher``: by message kind; ``plant``: its count; ``robots``: each robot's
    agent's ``decode_errors`` (undecodable, or on the wrong key) and ``rejected`` (decoded but
    refused), as of its latest status — a robot that never sent one is absent."""
    if rejections is None:
        return None
    launcher = {str(kind): int(count) for kind, count in rejections.get("launcher", {}).items()}
    plant = rejections.get("plant")
    robots = {
        str(robot): {
            "decode_errors": int(c["decode_errors"]),
            "rejected": int(c["rejected"]),
            "total": int(c["decode_errors"]) + int(c["rejected"]),
        }
        for robot, c in rejections.get("robots", {}).items()
    }
    return {
        "total": sum(launcher.values()) + (plant or 0) + sum(r["total"] for r in robots.values()),
        "launcher": launcher,
        "launcher_total": sum(launcher.values()),
        "plant": plant,
        "robots": robots,
    }


# ------------------------------------------------------------------------------ the table
def _fmt(value: float | None, spec: str, width: int) -> str:
    return ("-" if value is None else format(value, spec)).rjust(width)


def _scaled(value: float | None, factor: float) -> float | None:
    return None if value is None else value * factor


_HEADER = (
    f"{'robot':>5} {'m [kg]':>9} {'J [kg m2]':>10} {'ctc x [m]':>10} {'ctc y [m]':>10}"
    f" {'m err %':>8} {'J err %':>8} {'ctc err mm':>10} {'z_ij err mm':>11}"
)


def _table_row(
    label: str,
    mass: float | None,
    moment: float | None,
    ctc: Sequence[float] | None,
    errs: dict[str, float | None],
) -> str:
    """One line of the table; ``-`` where a value is missing."""
    x, y = (None, None) if ctc is None else ctc
    return (
        f"{label:>5} {_fmt(mass, '.5f', 9)} {_fmt(moment, '.5f', 10)}"
        f" {_fmt(x, '.4f', 10)} {_fmt(y, '.4f', 10)}"
        f" {_fmt(_scaled(errs.get('mass_rel'), 100), '.4f', 8)}"
        f" {_fmt(_scaled(errs.get('moment_rel'), 100), '.4f', 8)}"
        f" {_fmt(_scaled(errs.get('contact_to_com_m'), 1000), '.3f', 10)}"
        f" {_fmt(_scaled(errs.get('relative_positions_m'), 1000), '.3f', 11)}"
    )


def _robots_block(
    outcome: RunOutcome,
    header: str,
    row: Callable[..., str],
    values: Callable[[Estimates], tuple],
    truth: tuple,
) -> list[str]:
    """A block of the table: ``header`` underlined, each robot's ``row(label, *values(est),
    errors)`` (its values ``-`` when it reported nothing), the truth's and the worst errors."""
    lines = [header, "-" * len(header)]
    none = (None,) * len(truth)
    for i in range(1, outcome.scenario.n + 1):
        est = outcome.final.estimates.get(i)
        shown = none if est is None else values(est)
        lines.append(row(str(i), *shown, robot_errors(outcome, i)))
    lines.append(row("truth", *truth, {}))
    lines.append(row("worst", *none, errors(outcome)))
    return lines


def _time(value: float | None) -> str:
    """A time as ``'   3.40 s'``, or ``-`` in the same width."""
    return f"{'-':>7}  " if value is None else f"{value:7.2f} s"


def format_table(outcome: RunOutcome) -> str:
    """A fixed-width table (under 100 columns): each robot's m̂, Ĵ and ``contact_to_com``
    with their errors, the truth, the worst errors (and likewise ``τ̂_c`` and ``μ̂`` when some
    robot estimated the floor's friction), each paper step's start and end, and the 95 %
    intervals the robots published."""
    truth = outcome.final.truth
    status = "converged" if outcome.converged else f"NOT converged ({outcome.reason})"
    lines = [
        f"scenario {outcome.scenario.name!r}: {status} after {outcome.sim_time_s:.2f} s simulated"
        f" ({outcome.wall_s:.2f} s wall); estimates at t = {outcome.final.time_s:.2f} s",
        "ctc = contact_to_com = p_C - p_Ci (world frame); z_ij err: worst over i's neighbours",
        "",
    ]
    lines += _robots_block(
        outcome,
        _HEADER,
        _table_row,
        lambda est: (est.mass, est.moment, est.contact_to_com),
        (truth.mass, truth.moment, None),
    )
    lines += _friction_lines(outcome)
    lines += ["", f"{'paper step':<30} {'start':>7}    {'end':>7}"]
    for row in step_times(outcome):
        label = f"{row['step']} {row['name']}"
        lines.append(f"{label:<30} {_time(row['start_s'])}  {_time(row['end_s'])}")
    regimes = ", ".join(f"{name} {t:.2f} s" for name, t in team_phases(outcome).items())
    lines.append("(start: the first robot began the step; end: the last robot's estimate settled)")
    lines.append(f"team force regimes from: {regimes or '-'}")
    lines += _floor_lines(floor_check(outcome), outcome.final.time_s)
    changes = load_changes(outcome)
    if changes["changes"] or changes["restarts_s"]:
        lines.append(_changes_line(changes))
    lines += _interval_lines(outcome)
    rejected = _rejections_line(outcome.transport.get("rejections"))
    if rejected:
        lines.append(rejected)
    bridges = _bridges_line(outcome.transport.get("bridges"))
    if bridges:
        lines.append(bridges)
    return "\n".join(lines)


def _floor_lines(floor: dict[str, Any], until_s: float) -> list[str]:
    """The floor check, and what it was computed from (every tick up to ``until_s``)."""
    limits = floor["limits"]
    verdict = "within the floor" if floor["within"] else "LEFT THE FLOOR"
    return [
        f"load's largest travel {floor['travel_m']:.2f} m (limit {limits['travel_m']:g}),"
        f" speed {floor['speed']:.2f} m/s ({limits['speed']:g}),"
        f" |ω| {floor['omega']:.2f} rad/s ({limits['omega']:g}): {verdict}",
        f"(the plant's figures over every tick from t = 0 to {until_s:.2f} s)",
    ]


def _changes_line(changes: dict[str, Any]) -> str:
    parts = []
    for c in changes["changes"]:
        what = ", ".join(
            f"{k} {c[k]}" if k != "com" else f"com ({c[k][0]:g}, {c[k][1]:g})"
            for k in ("mass", "moment", "com")
            if k in c
        )
        found = (
            f"restarted {c['latency_s']:.2f} s later"
            if c["latency_s"] is not None
            else "NOT NOTICED"
        )
        parts.append(f"at {c['at_s']:g} s ({what}): {found}")
    alarms = changes["false_alarms"]
    return f"load changes: {'; '.join(parts) or 'none'}; false alarms: {alarms}"


def _published_friction(outcome: RunOutcome) -> bool:
    """Whether some robot published a friction estimate (the robust estimators do)."""
    return any(
        est.friction_torque is not None or est.coulomb is not None
        for est in outcome.final.estimates.values()
    )


_FRICTION_HEADER = f"{'robot':>5} {'tau_c [N m]':>11} {'mu':>9} {'tau_c err N m':>13} {'mu err':>9}"


def _friction_row(
    label: str, torque: float | None, mu: float | None, errs: dict[str, float | None]
) -> str:
    """One line of the friction table; ``-`` where a value is missing."""
    return (
        f"{label:>5} {_fmt(torque, '.5f', 11)} {_fmt(mu, '.6f', 9)}"
        f" {_fmt(errs.get('friction_torque_nm'), '.5f', 13)} {_fmt(errs.get('coulomb'), '.6f', 9)}"
    )


def _friction_lines(outcome: RunOutcome) -> list[str]:
    """Each robot's ``τ̂_c`` and ``μ̂`` with their errors (absolute: N m, and μ's own unit), the
    truth's ``μ m g c`` and ``μ``, and the worst errors (no robot published friction: no
    lines)."""
    if not _published_friction(outcome):
        return []
    truth = outcome.final.truth
    return [
        "",
        "tau_c: friction torque on a spin about the COM (truth mu m g c); mu: kinetic coefficient",
        *_robots_block(
            outcome,
            _FRICTION_HEADER,
            _friction_row,
            lambda est: (est.friction_torque, est.coulomb),
            (truth.coulomb_torque, truth.ground_coulomb),
        ),
    ]


def _interval_lines(outcome: RunOutcome) -> list[str]:
    """The 95 % intervals' half-widths and whether the truth is inside (robots that published
    an uncertainty; none: no lines); ``τ̂_c``'s and ``μ̂``'s when some robot published
    friction."""
    rows = {i: intervals(outcome, i) for i in range(1, outcome.scenario.n + 1)}
    if not any(rows.values()):
        return []
    friction = _published_friction(outcome)
    lines = [
        "",
        f"{'95 % intervals':<14} {'m ±%':>8} {'J ±%':>8} {'ctc ±mm':>9} {'z_ij ±mm':>9}"
        + (f" {'tau_c ±N m':>11} {'mu ±':>9}" if friction else "")
        + "   truth inside",
    ]
    truth = outcome.final.truth
    for i, row in rows.items():
        if row is None:
            lines.append(
                f"{'robot ' + str(i):<14} {'-':>8} {'-':>8} {'-':>9} {'-':>9}"
                + (f" {'-':>11} {'-':>9}" if friction else "")
            )
            continue
        names = (("m", "mass"), ("J", "moment"), ("ctc", "contact_to_com"))
        names += (("z_ij", "relative_positions"),)
        if friction:
            names += (("tau_c", "friction_torque"), ("mu", "coulomb"))
        inside = [name for name, key in names if row[key][1]]
        lines.append(
            f"{'robot ' + str(i):<14}"
            f" {_fmt(_scaled(row['mass'][0], 100 / truth.mass), '.3f', 8)}"
            f" {_fmt(_scaled(row['moment'][0], 100 / truth.moment), '.3f', 8)}"
            f" {_fmt(_scaled(row['contact_to_com'][0], 1000), '.2f', 9)}"
            f" {_fmt(_scaled(row['relative_positions'][0], 1000), '.2f', 9)}"
            + (
                f" {_fmt(row['friction_torque'][0], '.5f', 11)} {_fmt(row['coulomb'][0], '.6f', 9)}"
                if friction
                else ""
            )
            + f"   {' '.join(inside) or 'none'}"
        )
    return lines


def _bridges_line(bridges: dict | None) -> str:
    """One line of the AGV bridges' counters summed over robots (a CAN run; ``""`` else)."""
    if not bridges:
        return ""
    keys = ("frames_in", "frames_out", "missed_ticks", "decode_errors", "watchdog_trips")
    total = {key: sum(int(b.get(key) or 0) for b in bridges.values()) for key in keys}
    return f"{len(bridges)} AGV bridges: " + ", ".join(
        f"{key.replace('_', ' ')} {value}" for key, value in total.items()
    )


def _rejections_line(rejections: dict | None) -> str:
    """One line of the messages rejected, when there were any (``""`` otherwise)."""
    counts = rejection_counts(rejections)
    if not counts or not counts["total"]:
        return ""
    parts = []
    if counts["launcher_total"]:
        kinds = ", ".join(f"{kind} {n}" for kind, n in sorted(counts["launcher"].items()) if n)
        parts.append(f"launcher {counts['launcher_total']} ({kinds})")
    if counts["plant"]:
        parts.append(f"plant {counts['plant']}")
    for robot, robot_counts in counts["robots"].items():
        if robot_counts["total"]:
            parts.append(f"robot {robot} {robot_counts['total']}")
    return f"messages rejected: {counts['total']}: {'; '.join(parts)}"
