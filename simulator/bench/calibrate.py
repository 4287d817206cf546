"""``heft bench calibrate``: the factors that scale the robust estimators' published
uncertainties, measured again and printed (never changed: each constant's module says which
command gives it).

Each factor ``k`` scales a variance the estimators publish, or a share of it. The intervals are
those the noise benchmark judges (:func:`simulator.results.intervals`): a scalar's error ``e``
within ``1.96 σ`` (``e² ≤ χ²₁ = 3.84 σ²``), a vector's ``eᵀ C⁻¹ e ≤ χ²₂ = 5.99`` (the 95 %
ellipse, ``√5.99 = 2.45``). For each estimate the *needed* factor is the least ``k`` that puts
its truth inside:

- a scalar whose variance is ``k a + b`` (``b`` the share ``k`` does not scale):
  ``k_e = (e²/χ²₁ − b) / a``, at least 0 (:func:`scalar_factor`);
- a vector whose covariance is ``A`` along one axis and ``k B`` across it:
  ``e_∥²/A + e_⊥²/(k B) ≤ χ²₂``, so ``k_e = (e_⊥²/B) / (χ²₂ − e_∥²/A)``, infinite if the
  error along ``A`` alone leaves the ellipse (:func:`planar_factor`); with the whole
  covariance scaled, ``k_e = d²/χ²₂``, ``d²`` its ``eᵀ C⁻¹ e`` at ``k = 1``.

The interval with factor ``k`` holds the truth for the estimates with ``k_e ≤ k``: the report
gives that share at the current factor, and the least factor with at least 95 % of the
estimates inside (:func:`covering`, the ``⌈0.95 N⌉``-th smallest ``k_e``).

The calibrations (:data:`CALIBRATIONS`), each the measurement its constant's docstring
describes, on the seeds it names by default:

- ``published-variance``:
  :data:`~agent.algorithm.robust.uncertainty.PUBLISHED_VARIANCE` on the published ``m̂``,
  ``Ĵ``, ``contact_to_com``, ``z_ij`` and the floor's friction, over the noise benchmark's runs
  of the generated loads on floors, seeds 0–39;
- ``step5-com-variance``: :data:`~agent.algorithm.robust.uncertainty.STEP5_COM_VARIANCE` on
  each robot's ``contact_to_com`` from Step 5's ``ẑ_C`` alone (not published: Step 7 refines
  it), its whole covariance scaled, seeds 0–39;
- ``direction-variance``: :data:`~agent.algorithm.robust.arc_fit.DIRECTION_VARIANCE` on the
  variance across each ``z_ij`` (the direction filter's ``r² P``), the ellipse taken without
  ``PUBLISHED_VARIANCE``, seeds 0–39;
- ``correlation-time``: :data:`~agent.algorithm.robust.least_squares.CORRELATION_TIME` on
  the inertia fit's share of ``Ĵ``'s variance (without ``PUBLISHED_VARIANCE``), and the mass
  fit's factor (:class:`~agent.algorithm.robust.mass_fit.MassFit`: each row counted, factor
  1) on its share of each robot's own ``m̂``'s variance, seeds 0–39;
- ``arc-correlation``: :data:`~agent.algorithm.robust.arc_fit.CORRELATION` on the arc fit's
  radius and centre, over simulated arcs (:mod:`simulator.bench.arcs`).

The noise calibrations read the noise benchmark's runs (:func:`~simulator.bench.noise.
run_noise_bench`, the paper's scenario with its default :class:`~simulator.bench.noise.
NoiseSettings`) and each robot's :class:`~simulator.bench.noise.Interval` at the final instant.
A factor other than ``PUBLISHED_VARIANCE`` also changes what the estimators settle by, hence
the runs: the factor printed is that of the runs as they went.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import statistics
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

from agent.platform.cli_helpers import PROG, HelpFormatter
from agent.platform.evaluation import PLANAR_95, SCALAR_95, distance2

CHI2_SCALAR = SCALAR_95**2
"""χ²₁'s 95 % quantile: a scalar within 1.96 standard deviations."""
CHI2_PLANAR = PLANAR_95
"""χ²₂'s 95 % quantile: a planar error within the 95 % ellipse."""
SHARE = 0.95
"""The share of the estimates the published intervals should hold."""


# ------------------------------------------------------------------------------ arithmetic
def scalar_factor(error: float, scaled: float, fixed: float = 0.0) -> float:
    """The least ``k ≥ 0`` with ``error² ≤ χ²₁ (k scaled + fixed)``: ``scaled`` the variance
    ``k`` scales (at ``k = 1``), ``fixed`` the rest (infinite if ``scaled`` is 0 and ``fixed``
    falls short)."""
    excess = error * error / CHI2_SCALAR - fixed
    if excess <= 0.0:
        return 0.0
    return excess / scaled if scaled > 0.0 else math.inf


def planar_factor(fixed2: float, scaled2: float) -> float:
    """The least ``k ≥ 0`` with ``fixed2 + scaled2 / k ≤ χ²₂``: ``scaled2`` the squared
    Mahalanobis distance of the error's share whose covariance ``k`` scales (at ``k = 1``),
    ``fixed2`` that of the rest (infinite if ``fixed2`` alone reaches ``χ²₂``)."""
    room = CHI2_PLANAR - fixed2
    if scaled2 <= 0.0:
        return 0.0 if room >= 0.0 else math.inf
    return scaled2 / room if room > 0.0 else math.inf


def covering(needed: Sequence[float], share: float = SHARE) -> float:
    """The least of ``needed`` with at least ``share`` of them at or below it: the factor
    whose intervals hold that share of the estimates (NaN for none)."""
    if not needed:
        return math.nan
    ordered = sorted(needed)
    rank = max(math.ceil(share * len(ordered) - 1e-9), 1)
    return ordered[rank - 1]


@dataclass(frozen=True)
class Factor:
    """One quantity's calibration: the current ``factor`` and, per estimate, the needed one."""

    quantity: str
    factor: float
    needed: tuple[float, ...]
    unit: str = ""

    @property
    def inside(self) -> float:
        """The share of the estimates whose truth the current factor's interval holds."""
        if not self.needed:
            return math.nan
        return sum(k <= self.factor for k in self.needed) / len(self.needed)

    @property
    def exact(self) -> float:
        """The factor whose intervals hold :data:`SHARE` of the estimates (:func:`covering`)."""
        return covering(self.needed)


def _worst_per_robot(needed: Iterable[tuple[tuple[int, int], float]]) -> tuple[float, ...]:
    """Per ``(seed, robot)``, the largest needed factor of its estimates: its edges are all
    inside exactly when that one is (how ``heft bench --noise`` counts ``z_ij``)."""
    worst: dict[tuple[int, int], float] = {}
    for key, k in needed:
        worst[key] = max(worst.get(key, 0.0), k)
    return tuple(worst.values())


def _edge_rows(name: str, factor: float, needed: list[tuple[tuple[int, int], float]]):
    return [
        Factor(f"{name}, each edge", factor, tuple(k for _, k in needed)),
        Factor(f"{name}, each robot's edges at once", factor, _worst_per_robot(needed)),
    ]


# ------------------------------------------------------------------------------ calibrations
def published_variance(results: Sequence) -> list[Factor]:
    """:data:`~agent.algorithm.robust.uncertainty.PUBLISHED_VARIANCE` from the seeds'
    results (:class:`~simulator.bench.noise.SeedResult`): the whole published variance is
    scaled."""
    from agent.algorithm.robust.uncertainty import PUBLISHED_VARIANCE

    factors = PUBLISHED_VARIANCE
    mass, moment, offset, edges = [], [], [], []
    for result in results:
        found = result.intervals
        for s in found.get("mass", []):
            mass.append(scalar_factor(s.error[0], s.covariance[0] / factors["mass"]))
        for s in found.get("moment", []):
            moment.append(scalar_factor(s.error[0], s.covariance[0] / factors["moment"]))
        for s in found.get("contact_to_com", []):
            d2 = distance2(s.error, s.covariance) * factors["contact_to_com"]
            offset.append(planar_factor(0.0, d2))
        for s in found.get("relative_positions", []):
            d2 = distance2(s.error, s.covariance) * factors["relative"]
            edges.append(((result.seed, s.robot), planar_factor(0.0, d2)))
    friction = {
        key: tuple(
            scalar_factor(s.error[0], s.covariance[0] / factors[key]) for s in found_all(key)
        )
        for key in ("friction_torque", "coulomb")
        for found_all in [lambda k: [s for r in results for s in r.intervals.get(k, [])]]
    }
    return [
        Factor('m ("mass", the team\'s)', factors["mass"], tuple(mass)),
        Factor('J ("moment")', factors["moment"], tuple(moment)),
        Factor('contact_to_com ("contact_to_com")', factors["contact_to_com"], tuple(offset)),
        *_edge_rows('z_ij ("relative")', factors["relative"], edges),
        *(
            Factor(f'{name} ("{key}")', factors[key], friction[key])
            for name, key in (("tau_c", "friction_torque"), ("mu", "coulomb"))
            if friction[key]
        ),
    ]


def step5_com_variance(results: Sequence) -> list[Factor]:
    """:data:`~agent.algorithm.robust.uncertainty.STEP5_COM_VARIANCE` from the seeds'
    results: each robot's ``contact_to_com`` from Step 5's ``ẑ_C`` alone (``push_offset``), its
    whole covariance scaled, as it was when Step 5's ``ẑ_C`` was the one published."""
    from agent.algorithm.robust.uncertainty import STEP5_COM_VARIANCE

    offset = [
        planar_factor(0.0, distance2(s.error, s.covariance))
        for result in results
        for s in result.intervals.get("push_offset", [])
    ]
    return [Factor("contact_to_com from Step 5's z_C", STEP5_COM_VARIANCE, tuple(offset))]


def direction_variance(results: Sequence) -> list[Factor]:
    """:data:`~agent.algorithm.robust.arc_fit.DIRECTION_VARIANCE` from the seeds' results:
    each published ``z_ij``'s covariance is ``R (Var(r̂) u uᵀ + D r² P u⊥ u⊥ᵀ)``, ``u`` along
    the estimate, ``R`` = ``PUBLISHED_VARIANCE["relative"]`` and ``D`` the factor; the ellipse
    without ``R``, with ``D`` on ``r² P`` alone."""
    from agent.algorithm.robust.arc_fit import DIRECTION_VARIANCE
    from agent.algorithm.robust.uncertainty import PUBLISHED_VARIANCE

    scale = PUBLISHED_VARIANCE["relative"]
    edges = []
    for result in results:
        for s in result.intervals.get("relative_positions", []):
            along, across = _along_across(s.estimate, s.error, s.covariance)
            fixed2 = along[0] ** 2 / (along[1] / scale)
            scaled2 = across[0] ** 2 / (across[1] / (scale * DIRECTION_VARIANCE))
            edges.append(((result.seed, s.robot), planar_factor(fixed2, scaled2)))
    return _edge_rows("z_ij, across (r^2 P)", DIRECTION_VARIANCE, edges)


def _along_across(estimate, error, cov) -> tuple[tuple[float, float], tuple[float, float]]:
    """``((e_∥, uᵀCu), (e_⊥, u⊥ᵀCu⊥))``: the error and the variance along the estimate's
    direction ``u`` and across it."""
    norm = math.hypot(*estimate)
    ux, uy = estimate[0] / norm, estimate[1] / norm
    xx, xy, yy = cov
    along = ux * ux * xx + 2.0 * ux * uy * xy + uy * uy * yy
    across = uy * uy * xx - 2.0 * ux * uy * xy + ux * ux * yy
    return (
        (ux * error[0] + uy * error[1], along),
        (-uy * error[0] + ux * error[1], across),
    )


def correlation_time(results: Sequence) -> list[Factor]:
    """:data:`~agent.algorithm.robust.least_squares.CORRELATION_TIME` (s) on the inertia
    fit's share of ``Ĵ``'s variance, the published one without ``PUBLISHED_VARIANCE``; and the
    factor on the mass fit's share of each robot's own ``m̂``'s (1: each row counted; a factor
    ``k`` is a correlation time of ``k Δt / 2``, two rows a tick)."""
    from agent.algorithm.robust.least_squares import CORRELATION_TIME
    from agent.algorithm.robust.uncertainty import PUBLISHED_VARIANCE

    moment, mass = [], []
    for result in results:
        for s in result.intervals.get("moment", []):
            if s.fit_std is not None:
                var = s.covariance[0] / PUBLISHED_VARIANCE["moment"]
                fit = s.fit_std**2
                moment.append(CORRELATION_TIME * scalar_factor(s.error[0], fit, max(var - fit, 0)))
        for s in result.intervals.get("own_mass", []):
            fit = s.fit_std**2
            mass.append(scalar_factor(s.error[0], fit, max(s.covariance[0] - fit, 0.0)))
    return [
        Factor("J, the inertia fit's rows: one per", CORRELATION_TIME, tuple(moment), " s"),
        Factor("own m, the mass fit's variance (each row counted)", 1.0, tuple(mass)),
    ]


def fit_shares(results: Sequence) -> list[str]:
    """The median share of the variance that the fit gives, for ``Ĵ`` (without
    ``PUBLISHED_VARIANCE``) and each robot's own ``m̂``: how much a correlation time can
    change."""
    from agent.algorithm.robust.uncertainty import PUBLISHED_VARIANCE

    moment = [
        s.fit_std**2 / (s.covariance[0] / PUBLISHED_VARIANCE["moment"])
        for r in results
        for s in r.intervals.get("moment", [])
        if s.fit_std is not None and s.covariance[0] > 0.0
    ]
    mass = [
        s.fit_std**2 / s.covariance[0]
        for r in results
        for s in r.intervals.get("own_mass", [])
        if s.covariance[0] > 0.0
    ]
    text = ", ".join(
        f"{name} {100 * statistics.median(shares):.0f} %"
        for name, shares in (("J", moment), ("own m", mass))
        if shares
    )
    return [f"the fit's share of the variance (median over the estimates): {text}"]


def arc_correlation(readings: Sequence) -> list[Factor]:
    """:data:`~agent.algorithm.robust.arc_fit.CORRELATION` from simulated arcs
    (:class:`~simulator.bench.arcs.ArcReading`): it scales the radius' variance and the
    centre's covariance whole."""
    from agent.algorithm.robust.arc_fit import CORRELATION

    radius = tuple(scalar_factor(r.radius_error, r.radius_variance / CORRELATION) for r in readings)
    centre = tuple(
        planar_factor(0.0, distance2(r.centre_error, r.centre_covariance) * CORRELATION)
        for r in readings
    )
    return [
        Factor("radius |z_ij|", CORRELATION, radius),
        Factor("centre c = -z_ij(t0)", CORRELATION, centre),
    ]


def arc_ratios(readings: Sequence) -> dict[tuple[float, float], float]:
    """Per ``(σ, arc length)``: the centre's mean squared error per axis over its mean
    variance per axis, over the seeds."""
    sums: dict[tuple[float, float], list[float]] = {}
    for r in readings:
        (ex, ey), (xx, _, yy) = r.centre_error, r.centre_covariance
        total = sums.setdefault((r.noise, r.seconds), [0.0, 0.0])
        total[0] += ex * ex + ey * ey
        total[1] += xx + yy
    return {key: error / var for key, (error, var) in sums.items() if var > 0.0}


# ------------------------------------------------------------------------------ the report
@dataclass(frozen=True)
class Calibration:
    """One subcommand: the constant it calibrates (``constant``, in ``module``), what it
    measures on (``about``), its default seeds and how the factors follow from the runs."""

    name: str
    constant: str
    module: str
    about: str
    first_seed: int | None
    """The first seed (``None``: the calibration takes seeds ``0 .. seeds − 1``)."""
    seeds: int
    factors: Callable[[Sequence], list[Factor]]
    notes: Callable[[Sequence], list[str]] = lambda found: []
    """Lines printed below the table."""


CALIBRATIONS = (
    Calibration(
        "published-variance",
        "PUBLISHED_VARIANCE",
        "agent/algorithm/robust/uncertainty.py",
        "factors on the published variances of m, J, contact_to_com, z_ij and the floor's friction",
        0,
        40,
        published_variance,
    ),
    Calibration(
        "step5-com-variance",
        "STEP5_COM_VARIANCE",
        "agent/algorithm/robust/uncertainty.py",
        "the factor on the variance of Step 5's z_C, which Step 7's fits take as known",
        0,
        40,
        step5_com_variance,
    ),
    Calibration(
        "direction-variance",
        "DIRECTION_VARIANCE",
        "agent/algorithm/robust/arc_fit.py",
        "the factor on the direction filter's variance P across each z_ij",
        0,
        40,
        direction_variance,
    ),
    Calibration(
        "correlation-time",
        "CORRELATION_TIME",
        "agent/algorithm/robust/least_squares.py",
        "how long the angle fits' rows stay correlated (J), and the mass fit's factor",
        0,
        40,
        correlation_time,
        fit_shares,
    ),
    Calibration(
        "arc-correlation",
        "CORRELATION",
        "agent/algorithm/robust/arc_fit.py",
        "the factor on the arc fit's N s^2 (A'A)^-1, on simulated arcs",
        None,
        40,
        arc_correlation,
        lambda readings: format_arc_ratios(arc_ratios(readings)),
    ),
)


def command(
    calibration: Calibration,
    first_seed: int | None,
    seeds: int,
    ideal_drives: bool = False,
    coulomb: tuple[float, float] | None = None,
    generated: bool = False,
) -> str:
    """The command line that reproduces a calibration."""
    line = f"{PROG} bench calibrate {calibration.name}"
    if first_seed is not None:
        line += f" --first-seed {first_seed}"
    line += f" --seeds {seeds}" + (" --generated" if generated else "")
    line += " --ideal-drives" if ideal_drives else ""
    return line + ("" if coulomb is None else f" --coulomb-range {coulomb[0]:g} {coulomb[1]:g}")


def seed_range(first: int, count: int) -> str:
    """``seeds 0-39``, or ``seed 5`` for one."""
    return f"seed {first}" if count == 1 else f"seeds {first}-{first + count - 1}"


def _number(value: float, unit: str = "") -> str:
    return "-" if math.isnan(value) else f"{value:.3g}{unit}"


def format_factors(factors: Sequence[Factor]) -> list[str]:
    """The table: per quantity, its estimates, the current factor, the share inside, and the
    factor for :data:`SHARE` inside."""
    width = max(len(f.quantity) for f in factors)
    lines = [
        f"{'quantity':<{width}} {'estimates':>9} {'factor':>8} {'inside':>8}"
        f" {'factor for 95 % inside':>23}"
    ]
    for f in factors:
        inside = "-" if math.isnan(f.inside) else f"{100 * f.inside:.1f} %"
        lines.append(
            f"{f.quantity:<{width}} {len(f.needed):>9} {_number(f.factor, f.unit):>8}"
            f" {inside:>8} {_number(f.exact, f.unit):>23}"
        )
    return lines


def format_report(
    calibration: Calibration, setting: str, factors: Sequence[Factor], notes: Sequence[str] = ()
) -> str:
    """The report: the constant and what it was measured on, the table, and ``notes``."""
    return "\n".join(
        [
            f"{calibration.constant} ({calibration.module}): {calibration.about}",
            setting,
            "",
            *format_factors(factors),
            "",
            "95 % intervals: |e| <= 1.96 std for a scalar, e' C^-1 e <= 5.99 for a vector;",
            "the factor for 95 % inside: the least with at least 95 % of the estimates inside.",
            *notes,
        ]
    )


def format_arc_ratios(ratios: dict[tuple[float, float], float]) -> list[str]:
    """:func:`arc_ratios` as a table: a row per ``σ``, a column per arc length."""
    noises = sorted({noise for noise, _ in ratios})
    lengths = sorted({seconds for _, seconds in ratios})
    lines = [
        "the centre's mean squared error per axis over its variance per axis, over the seeds:",
        f"{'sigma (m/s)':<12}" + "".join(f"{f'{s:g} s':>8}" for s in lengths),
    ]
    for noise in noises:
        cells = (ratios.get((noise, s), math.nan) for s in lengths)
        lines.append(f"{noise:<12g}" + "".join(f"{_number(c):>8}" for c in cells))
    return lines


# ------------------------------------------------------------------------------ the commands
def _run_noise(
    first_seed: int,
    seeds: int,
    ideal_drives: bool,
    coulomb: tuple[float, float] | None = None,
    generated: bool = False,
) -> tuple[str, list]:
    """The noise benchmark's runs of the seeds (with ideal drives if told), of the paper's
    load or, ``generated``, of each seed's generated load (as ``heft bench noise --generated``
    runs them); with ``coulomb``, on a floor whose ``μ`` each seed draws from it (the paper's
    load on four casters, ``paper-floor.toml``'s; a generated load on its area), and what they
    were run on."""
    from simulator.bench.floor import FloorSettings
    from simulator.bench.noise import (
        NoiseSettings,
        for_generated,
        run_noise_bench,
        say_seed,
        timed,
    )
    from simulator.generate import generate_scenario
    from simulator.scenario import PAPER_SCENARIO, load_scenario

    floor = None if coulomb is None else FloorSettings(coulomb)
    settings = dataclasses.replace(NoiseSettings(), seeds=seeds, first_seed=first_seed, floor=floor)
    if generated:
        scenarios, label = generate_scenario, "the generated scenarios"
        settings = dataclasses.replace(for_generated(settings), paper_estimators=False)
    else:
        scenario = load_scenario(
            PAPER_SCENARIO if coulomb is None else PAPER_SCENARIO.parent / "paper-floor.toml"
        )
        label = f"scenario {scenario.name!r}"

        def scenarios(seed: int):
            return scenario

    if ideal_drives:
        settings = dataclasses.replace(settings, time_constant_s=0.0, gain_error_std=0.0)

    results, wall = timed(run_noise_bench, scenarios, settings, say_seed)
    setting = (
        f"the noise benchmark's runs: {label}, {settings.noise_text},"
        f" {seed_range(first_seed, seeds)} ({wall:.0f} s wall)"
    )
    return setting, results


def _run_arcs(seeds: int) -> tuple[str, list]:
    """The simulated arcs of the seeds, and what they were."""
    from simulator.bench.arcs import LENGTHS_S, NOISES, PERIOD_S, RADIUS, fit_arcs
    from simulator.bench.noise import timed

    readings, wall = timed(fit_arcs, seeds)
    setting = (
        f"simulated arcs: |z_ij| {RADIUS:g} m, omega 0.3 + 0.2 sin t rad/s, {1 / PERIOD_S:g} Hz,"
        f" sigma {', '.join(f'{s:g}' for s in NOISES)} m/s per axis and robot, read at"
        f" {', '.join(f'{s:g}' for s in LENGTHS_S)} s of arc, {seed_range(0, seeds)}"
        f" ({wall:.0f} s wall)"
    )
    return setting, readings


def run(calibration: Calibration, args: argparse.Namespace) -> int:
    """A calibration's handler: run, print the report (never changes a constant)."""
    from agent.platform.config import Bound

    Bound(1, 1000, "seeds").check("--seeds", args.seeds)
    first_seed = getattr(args, "first_seed", None)
    ideal = getattr(args, "ideal_drives", False)
    generated = getattr(args, "generated", False)
    coulomb = None
    if calibration.first_seed is None:
        setting, found = _run_arcs(args.seeds)
    else:
        Bound(0, 100_000, "seeds").check("--first-seed", first_seed)
        coulomb = getattr(args, "coulomb_range", None)
        if coulomb is not None:
            Bound(0, 0.5, "").check("--coulomb-range", coulomb[0])
            Bound(coulomb[0], 0.5, "").check("--coulomb-range", coulomb[1])
            coulomb = (coulomb[0], coulomb[1])
        setting, found = _run_noise(first_seed, args.seeds, ideal, coulomb, generated)
    print(command(calibration, first_seed, args.seeds, ideal, coulomb, generated))
    notes = calibration.notes(found)
    print(format_report(calibration, setting, calibration.factors(found), notes))
    return 0


def add_parser(benchmarks: argparse._SubParsersAction) -> None:
    """Add ``calibrate`` and its subcommands, one per :data:`CALIBRATIONS`, to
    ``benchmarks`` (``heft bench``'s subcommands)."""
    parser = benchmarks.add_parser(
        "calibrate",
        help="the published uncertainties' factors, measured again",
        formatter_class=HelpFormatter,
        description=(
            "Measure again each factor that scales the robust estimators' published\n"
            "uncertainties, on the runs (or simulated arcs) it was calibrated on, and print\n"
            "per quantity: the current factor, the share of the estimates whose truth its 95 %\n"
            "interval holds, and the factor that would make that share 95 %. It changes no\n"
            "constant and checks no goal.\n\n"
            "Exit status: 0 done, 2 bad arguments, 130 interrupted."
        ),
    )
    which = parser.add_subparsers(dest="calibration", metavar="FACTOR", required=True)
    for calibration in CALIBRATIONS:
        sub = which.add_parser(
            calibration.name,
            help=f"{calibration.constant}: {calibration.about}",
            formatter_class=HelpFormatter,
            description=f"{calibration.constant} in {calibration.module}: {calibration.about}."
            "\n\nExit status: 0 done, 2 bad arguments, 130 interrupted.",
        )
        if calibration.first_seed is not None:
            sub.add_argument(
                "--first-seed",
                type=int,
                default=calibration.first_seed,
                metavar="S",
                help=f"the noise benchmark's seeds from S (default: {calibration.first_seed})",
            )
            sub.add_argument(
                "--generated",
                action="store_true",
                help="each seed's generated load (as heft bench noise --generated runs it)"
                " instead of the paper's",
            )
            sub.add_argument(
                "--ideal-drives",
                action="store_true",
                help="drives that apply exactly what they are commanded (no lag, no gain"
                " error) instead of the benchmark's",
            )
            sub.add_argument(
                "--coulomb-range",
                type=float,
                nargs=2,
                metavar=("LO", "HI"),
                help="on a real floor: the paper's load on four casters (paper-floor.toml's) or"
                " a generated load on its area, each seed's kinetic friction drawn in [LO, HI]"
                " (default: frictionless)",
            )
        sub.add_argument(
            "--seeds",
            type=int,
            default=calibration.seeds,
            metavar="N",
            help=f"how many seeds, in [1, 1000] (default: {calibration.seeds})",
        )
        sub.set_defaults(handler=lambda args, c=calibration: run(c, args))
