"""The friction sweep (``heft bench friction``): the noise benchmark's robust runs over the
floor's friction.

At each kinetic coefficient ``μ`` of :data:`FRICTION_SWEEP` (``μ_s`` =
:data:`~simulator.bench.floor.STATIC_RATIO` ``μ``; ``μ = 0``: no friction, the paper's floor)
every seed of the load (the paper's, by default on ``paper-floor.toml``'s four casters, or the
generated loads on their area: :mod:`simulator.bench.floor`) runs with the noise benchmark's
sensors, drives and settings (:func:`simulator.bench.noise.run_noise_bench`; the robust
estimators alone), and the centralized fit is made on each run's measurements. Per ``μ`` the
report gives the medians of the worst robot's errors (``m``, ``J``, ``contact_to_com``,
``z_ij``) beside the fit's and their ratios, those of the friction estimates (``τ_c``
relative, ``μ`` absolute; the fit has none), the share of the robots' 95 % intervals holding
the truth, the runs done within :data:`~simulator.bench.noise.DONE_WITHIN_S` and when, and the
runs that kept to their floor; :func:`plot_friction_sweep` draws the errors against ``μ``.

Its goals (:data:`GOALS`, the issue's for the paper's load over the sweep, measured by
:func:`figures`): ``m``'s median within :data:`~simulator.bench.noise.RATIO_GOAL` times the
fit's at every ``μ``, and no quantity's published intervals holding the truth less than
90 % of the time at any ``μ``.
"""

from __future__ import annotations

import dataclasses
import statistics
from collections.abc import Callable, Sequence
from pathlib import Path

from agent.platform.goals import Goal, Sense
from simulator.bench.floor import STATIC_RATIO, FloorSettings
from simulator.bench.noise import (
    COVERAGE_GOAL,
    DONE_WITHIN_S,
    FRICTION,
    JUDGED,
    QUANTITIES,
    RATIO_GOAL,
    NoiseSettings,
    SeedResult,
    median,
    ratio,
    run_noise_bench,
    share,
)
from simulator.scenario import Scenario

FRICTION_SWEEP = (0.0, 0.005, 0.01, 0.02, 0.03, 0.05)
"""``μ`` of the sweep: frictionless, casters rolling (0.5–3 %), a stiff caster (5 %)."""
GOALS = (
    Goal(
        "ratio mass_rel", "m: robust median / baseline's, worst over mu", RATIO_GOAL, Sense.AT_MOST
    ),
    Goal(
        "inside",
        "truth inside the 95 % intervals, least over mu and quantities",
        100 * COVERAGE_GOAL[0],
        Sense.AT_LEAST,
        "%",
    ),
)
"""What the friction sweep checks, on the figures of :func:`figures`."""

Sweep = dict[float, list[SeedResult]]
"""Each ``μ`` of the sweep and its runs, one per seed."""


def run_friction_sweep(
    scenarios: Callable[[int], Scenario],
    base: NoiseSettings,
    on_level: Callable[[float, list[SeedResult]], None] | None = None,
    levels: Sequence[float] = FRICTION_SWEEP,
) -> Sweep:
    """:func:`~simulator.bench.noise.run_noise_bench` with ``base``'s seeds, noise and drives
    on a floor of each ``μ`` of ``levels`` (``μ_s`` = :data:`STATIC_RATIO` ``μ``), the robust
    estimators alone."""
    found = {}
    for mu in levels:
        settings = dataclasses.replace(base, floor=FloorSettings((mu, mu)), paper_estimators=False)
        found[mu] = run_noise_bench(scenarios, settings)
        if on_level is not None:
            on_level(mu, found[mu])
    return found


def _percent(fraction: float | None) -> float | None:
    return None if fraction is None else 100 * fraction


def _worst(values: Sequence[float | None], pick: Callable) -> float | None:
    """``pick`` (max or min) of ``values``; None if any is None (unknown) or there is none."""
    return None if not values or None in values else pick(values)


def figures(found: Sweep) -> dict[str, float | None]:
    """The figures :data:`GOALS` bound: the largest ratio of ``m``'s median to the fit's over
    the sweep, and the least share (%) of a quantity's intervals holding the truth over the
    sweep and :data:`~simulator.bench.noise.JUDGED` (None where one is unknown)."""
    return {
        "ratio mass_rel": _worst([ratio(runs, "mass_rel") for runs in found.values()], max),
        "inside": _worst(
            [_percent(share(runs, key)) for runs in found.values() for _, key, _, _ in JUDGED], min
        ),
    }


def _cell(value: float | None, scale: float = 1.0, digits: int = 3) -> str:
    return "-" if value is None else f"{value * scale:.{digits}g}"


def _done(results: Sequence[SeedResult]) -> tuple[str, str]:
    """``within / done / runs`` and the done runs' median / slowest time (s)."""
    times = [r.robust_time_s for r in results if r.robust_done]
    within = sum(t <= DONE_WITHIN_S for t in times)
    counts = f"{within} / {len(times)} / {len(results)}"
    if not times:
        return counts, "-"
    return counts, f"{statistics.median(times):.1f} / {max(times):.1f}"


def format_friction_sweep(found: Sweep, label: str) -> str:
    """A markdown table: per ``μ`` the medians of the robust estimators' and the fit's errors,
    their ratios, the friction estimates' medians, the share of the 95 % intervals holding the
    truth (per quantity, %), runs done and when, runs on their floor."""
    runs = len(next(iter(found.values()), []))
    head = [
        "μ (%)",
        *(f"{name} ({unit}) robust / fit" for name, _, _, unit in QUANTITIES),
        "robust / fit: " + " / ".join(name for name, _, _, _ in QUANTITIES),
        *(f"{name} ({unit})" for name, _, _, unit in FRICTION),
        "95 % inside (%): " + " / ".join(name for name, _, _, _ in JUDGED),
        f"done ≤ {DONE_WITHIN_S:g} s / done / runs",
        "time to done (s), median / slowest",
        "on the floor",
    ]
    lines = [
        f"{label}, robust estimators, medians over {runs} seeds; μ_s = {STATIC_RATIO:g} μ",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for mu, results in found.items():
        errors = [
            " / ".join(_cell(median(results, w, key), scale) for w in ("robust", "baseline"))
            for _, key, scale, _ in QUANTITIES
        ]
        ratios = " / ".join(_cell(ratio(results, key), digits=2) for _, key, _, _ in QUANTITIES)
        friction = [_cell(median(results, "robust", key), scale) for _, key, scale, _ in FRICTION]
        inside = " / ".join(
            _cell(_percent(share(results, key)), digits=3) for _, key, _, _ in JUDGED
        )
        counts, times = _done(results)
        floor = f"{sum(r.floor.get('within', False) for r in results)} / {len(results)}"
        cells = [f"{100 * mu:g}", *errors, ratios, *friction, inside, counts, times, floor]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot_friction_sweep(found: Sweep, path: Path, label: str) -> Path:
    """The medians against ``μ`` (%), one panel per quantity: the robust estimators' and the
    fit's for :data:`~simulator.bench.noise.QUANTITIES`, the robust ones' for the friction
    estimates; the error axis logarithmic."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mus = sorted(found)
    quantities = (*QUANTITIES, *FRICTION)
    fig, axes = plt.subplots(2, 3, figsize=(15, 8), constrained_layout=True)
    for ax, (name, key, scale, unit) in zip(axes.flat, quantities):
        for which, style in (("robust", "o-"), ("baseline", "^:")):
            ys = [median(found[mu], which, key) for mu in mus]
            pts = [(100 * mu, y * scale) for mu, y in zip(mus, ys) if y is not None and y > 0]
            if pts:
                ax.plot(*zip(*pts), style, label=which)
        ax.set_yscale("log")
        ax.set_xlim(-0.05 * 100 * mus[-1], 1.05 * 100 * mus[-1])
        ax.set_xlabel(f"μ (% of the weight), μ_s = {STATIC_RATIO:g} μ")
        ax.set_title(f"{name} ({unit}), median")
        ax.grid(True, which="both", alpha=0.3)
    axes.flat[0].legend()
    fig.suptitle(f"{label}, medians over {len(found[mus[0]])} seeds")
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
