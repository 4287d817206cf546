"""Figures of a run, after Figs. 4–6 of the paper: estimates (solid) against truth (dashed).

:func:`write_plots` writes three PNGs into a directory:

- ``relative_positions.png`` (Fig. 4): for every directed graph edge ``i → j``, the ``x`` and
  ``y`` components of robot ``i``'s ``ẑ_ij`` and of the true ``z_ij = p_Ci − p_Cj``;
- ``inertia_mass.png`` (Fig. 5): every robot's ``Ĵ`` (a) and ``m̂`` (b) against truth;
- ``com_observer.png`` (Fig. 6): (a) the components of ``z_C = p_G − p_C`` as estimated by the
  team (``Estimates.com_offset``) and by observer (24) (``Estimates.com_observer``), and ``ω̂``,
  against truth; (b) the norms of their errors; (c) observer (24)'s Lyapunov function
  ``V = ½ (‖z_C − ẑ_C‖² + (ω − ω̂)²)``.

All vectors are in the world frame, so they turn with the load. The background is shaded by
the team's force regime (excite, inertia, push, done). Samples where an estimate is still
``None`` are skipped.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from agent.platform.evaluation import robot_errors, true_relative  # noqa: E402

if TYPE_CHECKING:
    from agent.platform.protocol import Estimates
    from simulator.inprocess import RunOutcome, Sample

PHASE_COLOURS = {"excite": "#fff3d6", "inertia": "#e3f0ff", "push": "#e6f6e6", "done": "#f0f0f0"}
COMPONENTS = ("x", "y")
DPI = 120
ESTIMATE = {"lw": 2.4, "alpha": 0.45}
"""Estimates: wide, light, solid lines..."""
TRUTH = {"lw": 1.1, "dashes": (4, 2), "zorder": 3}
"""...and the truth dashed on top of them, so both stay visible where they agree."""
AIM = 0.005
"""Relative accuracy aim on m and J, drawn as a band around the truth in Fig. 5."""

Getter = Callable[["Sample"], float | None]


# ------------------------------------------------------------------------------ data
def _series(history: Sequence[Sample], get: Getter) -> tuple[np.ndarray, np.ndarray]:
    """Times and values of ``get(sample)`` over ``history``, skipping None values."""
    points = [(s.time_s, v) for s in history if (v := get(s)) is not None]
    if not points:
        return np.empty(0), np.empty(0)
    t, v = zip(*points)
    return np.asarray(t, dtype=float), np.asarray(v, dtype=float)


def _estimate(robot: int, read: Callable[[Estimates], float | None]) -> Getter:
    """A getter of one robot's estimate (None when the robot or the estimate is missing)."""

    def get(sample: Sample) -> float | None:
        est = sample.estimates.get(robot)
        return None if est is None else read(est)

    return get


def _component(vector: Sequence[float] | None, axis: int) -> float | None:
    return None if vector is None else float(vector[axis])


def directed_edges(outcome: RunOutcome) -> list[tuple[int, int]]:
    """Every graph edge in both directions, ``(1, 2), (2, 1), (2, 3), ...`` (Fig. 4's order)."""
    return [pair for i, j in outcome.scenario.edges for pair in ((i, j), (j, i))]


def _lead_robot(outcome: RunOutcome) -> int:
    """The robot whose team-wide estimates (``z_C``, ``ω``) are plotted: the lowest id."""
    return min(outcome.final.estimates, default=1)


# ------------------------------------------------------------------------------ decoration
def _phase_spans(outcome: RunOutcome) -> list[tuple[str, float, float]]:
    """``(phase, start_s, end_s)`` of each team force regime, in order."""
    period = outcome.scenario.period_s
    starts = sorted(outcome.phase_ticks.items(), key=lambda item: item[1])
    end_of_run = max(outcome.sim_time_s, outcome.history[-1].time_s if outcome.history else 0.0)
    spans = []
    for k, (name, tick) in enumerate(starts):
        stop = starts[k + 1][1] * period if k + 1 < len(starts) else end_of_run
        spans.append((name, tick * period, stop))
    return spans


def _shade(ax: Axes, outcome: RunOutcome) -> None:
    """Shade ``ax`` by the team's force regime (see :func:`_phase_handles` for the key)."""
    for name, start, stop in _phase_spans(outcome):
        if stop > start:
            ax.axvspan(start, stop, color=PHASE_COLOURS.get(name, "#f4f4f4"), zorder=0, lw=0)


def _phase_handles(outcome: RunOutcome, since: float = -math.inf) -> list[Patch]:
    """Legend entries for the shading: one patch per team phase that lasted and that ends
    after ``since`` (the left edge of the plots)."""
    return [
        Patch(color=PHASE_COLOURS.get(name, "#f4f4f4"), label=f"phase: {name}")
        for name, start, stop in _phase_spans(outcome)
        if stop > start and stop > since
    ]


def _figure_legend(fig: Figure, handles: list, ncol: int) -> None:
    """A legend along the bottom of ``fig`` (leave room with ``tight_layout(rect=...)``)."""
    fig.legend(handles=handles, loc="lower center", ncol=ncol, fontsize=9, frameon=False)


def _finish(ax: Axes, ylabel: str, title: str) -> None:
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10, loc="left")
    ax.grid(True, alpha=0.3)
    ax.margins(x=0)


def _save(fig: Figure, path: Path) -> Path:
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


# ------------------------------------------------------------------------------ Fig. 4
def plot_relative_positions(outcome: RunOutcome, path: Path) -> Path:
    """Fig. 4: ``ẑ_ij`` (solid) against ``z_ij`` (dashed), one panel per directed edge."""
    edges = directed_edges(outcome)
    cols = 2 if len(edges) <= 8 else 4
    rows = max(1, math.ceil(len(edges) / cols))
    fig, axes = plt.subplots(
        rows, cols, figsize=(5.2 * cols, 2.3 * rows + 1.0), sharex=True, squeeze=False
    )
    history = outcome.history
    for k, ax in enumerate(axes.flat):
        if k >= len(edges):
            ax.set_visible(False)
            continue
        i, j = edges[k]
        _shade(ax, outcome)
        for axis, colour in zip((0, 1), ("C0", "C3")):
            c = COMPONENTS[axis]
            t, v = _series(
                history,
                _estimate(i, lambda e, j=j, a=axis: _component(e.relative_positions.get(j), a)),
            )
            ax.plot(t, v, "-", color=colour, **ESTIMATE, label=f"estimated $\\hat z_{{ij,{c}}}$")
            t, v = _series(history, lambda s, i=i, j=j, a=axis: true_relative(s.truth, i, j)[a])
            ax.plot(t, v, "--", color=colour, **TRUTH, label=f"true $z_{{ij,{c}}}$")
        letter = chr(ord("a") + k) if k < 26 else str(k)
        ij = f"{i}{j}" if max(i, j) < 10 else f"{i},{j}"
        _finish(ax, "m", f"({letter}) $z_{{{ij}}} = p_{{C{i}}} - p_{{C{j}}}$, robot {i}")
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    handles = axes.flat[0].get_legend_handles_labels()[0] + _phase_handles(outcome)
    _figure_legend(fig, handles, ncol=4)
    fig.suptitle("Step 1: relative positions of the contact points (world frame)")
    fig.tight_layout(rect=(0, 0.07 if rows <= 3 else 0.04, 1, 1))
    return _save(fig, path)


# ------------------------------------------------------------------------------ Fig. 5
def plot_inertia_mass(outcome: RunOutcome, path: Path) -> Path:
    """Fig. 5: every robot's ``Ĵ`` (a) and ``m̂`` (b), truth dashed, each panel from the first
    estimate on; the grey band is the accuracy aim (truth ± 0.5 %)."""
    fig, (ax_j, ax_m) = plt.subplots(2, 1, figsize=(9, 6.5))
    truth = outcome.final.truth
    panels = (
        (ax_j, "moment", truth.moment, "kg m²", "(a) Step 4: moment of inertia about the COM"),
        (ax_m, "mass", truth.mass, "kg", "(b) Step 7: mass"),
    )
    first = math.inf
    for ax, key, true_value, unit, title in panels:
        first = min(first, _plot_parameter(ax, outcome, key, true_value, unit))
        _finish(ax, f"{key} [{unit}]", title)
        ax.set_xlabel("time [s]")
    _figure_legend(fig, _phase_handles(outcome, since=first), ncol=4)
    fig.suptitle("Inertial parameters estimated by each robot (truth dashed)")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    return _save(fig, path)


def _plot_parameter(ax: Axes, outcome: RunOutcome, key: str, true_value: float, unit: str) -> float:
    """Every robot's estimate ``key`` against ``true_value`` on ``ax``; returns the time of the
    first estimate (the panel's left edge)."""
    _shade(ax, outcome)
    band = (true_value * (1 - AIM), true_value * (1 + AIM))
    ax.axhspan(*band, color="0.5", alpha=0.12, lw=0, label=f"truth ± {AIM:.1%}")
    first = math.inf
    for robot in sorted(outcome.final.estimates):
        t, v = _series(outcome.history, _estimate(robot, lambda e: getattr(e, key)))
        ax.plot(t, v, "-", **ESTIMATE, label=f"robot {robot}")
        first = min(first, t[0]) if len(t) else first
    ax.axhline(true_value, color="k", **TRUTH, label=f"truth {true_value:g} {unit}")
    end = outcome.history[-1].time_s if outcome.history else 0.0
    if math.isfinite(first) and first < end:
        ax.set_xlim(first, end)
    ax.ticklabel_format(axis="y", useOffset=False)
    ax.legend(fontsize=8, loc="best", ncol=2)
    return first


# ------------------------------------------------------------------------------ Fig. 6
def _com_rows(outcome: RunOutcome) -> list[Sample]:
    """The samples where the lead robot has either estimate of ``z_C`` (Step 5 onwards)."""
    robot = _lead_robot(outcome)
    rows = []
    for sample in outcome.history:
        est = sample.estimates.get(robot)
        if est is not None and (est.com_offset is not None or est.com_observer is not None):
            rows.append(sample)
    return rows


def _error(robot: int, key: str) -> Getter:
    """A getter of one of ``robot``'s errors against the truth
    (:func:`~agent.platform.evaluation.robot_errors`, ``key`` one of its keys)."""

    def get(sample: Sample) -> float | None:
        return robot_errors(sample.estimates.get(robot), sample.truth, ())[key]

    return get


def _lyapunov(sample: Sample, robot: int) -> float | None:
    """``V = ½ (‖z_C − ẑ_C‖² + (ω − ω̂)²)`` with observer (24)'s ``ẑ_C``."""
    errors = robot_errors(sample.estimates.get(robot), sample.truth, ())
    e_z, e_omega = errors["com_observer_m"], errors["omega_rad_s"]
    return None if e_z is None or e_omega is None else 0.5 * (e_z**2 + e_omega**2)


def _positive(values: np.ndarray) -> np.ndarray:
    """``values`` with non-positive entries masked (for a log scale)."""
    return np.where(values > 0, values, np.nan)


def plot_com_observer(outcome: RunOutcome, path: Path) -> Path:
    """Fig. 6: ``ẑ_C`` of the team and of observer (24) and ``ω̂`` vs truth, error norms and
    observer (24)'s Lyapunov function."""
    robot = _lead_robot(outcome)
    estimated = _com_rows(outcome)
    rows = estimated or outcome.history
    fig, axes = plt.subplots(
        4, 1, figsize=(9, 10), sharex=True, gridspec_kw={"height_ratios": [1.2, 0.8, 1, 1]}
    )
    ax_z, ax_w, ax_e, ax_v = axes
    for ax in axes:
        _shade(ax, outcome)
    handles: dict[str, list] = {"true": [], "team": [], "observer": []}
    for axis, colour in zip((0, 1), ("C0", "C3")):
        c = COMPONENTS[axis]
        t, v = _series(rows, lambda s, a=axis: s.truth.com_offset[a])
        handles["true"] += ax_z.plot(t, v, color=colour, **TRUTH, label=f"true $z_{{C,{c}}}$")
        t, v = _series(rows, _estimate(robot, lambda e, a=axis: _component(e.com_offset, a)))
        handles["team"] += ax_z.plot(
            t, v, "-", color=colour, **ESTIMATE, label=f"team $\\hat z_{{C,{c}}}$"
        )
        t, v = _series(rows, _estimate(robot, lambda e, a=axis: _component(e.com_observer, a)))
        handles["observer"] += ax_z.plot(
            t, v, ":", color=colour, lw=1.8, label=f"observer (24) $\\hat z_{{C,{c}}}$"
        )
    _finish(ax_z, "m", f"(a) $z_C = p_G - p_C$ (world frame), robot {robot}'s estimates")
    ax_z.legend(handles=[h for group in handles.values() for h in group], fontsize=8, ncol=3)

    t, v = _series(rows, lambda s: s.truth.omega)
    ax_w.plot(t, v, color="k", **TRUTH, label="true ω")
    t, v = _series(rows, _estimate(robot, lambda e: e.omega))
    ax_w.plot(t, v, "-", color="C2", **ESTIMATE, label="estimated ω̂")
    _finish(ax_w, "rad/s", "(a) angular velocity ω")
    ax_w.legend(fontsize=8, loc="best")

    errors = (("com_offset_m", "-", "team"), ("com_observer_m", ":", "observer (24)"))
    for key, style, name in errors:
        t, v = _series(rows, _error(robot, key))
        ax_e.plot(t, _positive(v), style, lw=1.4, label=f"{name}: $\\|z_C - \\hat z_C\\|$ [m]")
    t, v = _series(rows, _error(robot, "omega_rad_s"))
    ax_e.plot(t, _positive(v), "-", color="C2", lw=1.0, label="|ω − ω̂| [rad/s]")
    ax_e.set_yscale("log")
    _finish(ax_e, "m, rad/s", "(b) estimation errors")
    ax_e.legend(fontsize=8, loc="best")

    t, v = _series(rows, lambda s: _lyapunov(s, robot))
    ax_v.plot(t, _positive(v), "-", color="C4", lw=1.4, label="V(e) of observer (24)")
    ax_v.set_yscale("log")
    _finish(ax_v, "m², (rad/s)²", "(c) $V = ½(\\|z_C - \\hat z_C\\|^2 + (ω - \\hat ω)^2)$")
    ax_v.legend(fontsize=8, loc="best")
    ax_v.set_xlabel("time [s]")
    if rows and rows[-1].time_s > rows[0].time_s:  # (one instant: matplotlib's own range)
        ax_v.set_xlim(rows[0].time_s, rows[-1].time_s)
    _figure_legend(fig, _phase_handles(outcome, since=rows[0].time_s if rows else 0.0), ncol=4)
    missing = "" if estimated else " (no estimate of $z_C$ in this run)"
    fig.suptitle(f"Step 5: centre-of-mass offset, team estimate and observer (24){missing}")
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    return _save(fig, path)


# ------------------------------------------------------------------------------ entry point
def write_plots(outcome: RunOutcome, directory: str | Path) -> list[Path]:
    """Write Figs. 4–6 of ``outcome`` as PNGs into ``directory`` (created if needed)."""
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    return [
        plot_relative_positions(outcome, out / "relative_positions.png"),
        plot_inertia_mass(outcome, out / "inertia_mass.png"),
        plot_com_observer(outcome, out / "com_observer.png"),
    ]
