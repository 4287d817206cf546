"""The noise benchmark (``heft bench noise``): the robust estimators, the paper's, and the
centralized reference, on the same noisy runs.

For each seed, the scenario (the paper's, or a generated one) gets the sensors' noise
(``σ_v`` m/s and ``σ_f`` N per axis) and the AGVs' drives (a first-order lag and a per-robot
gain error), Step 1 spins the load up faster (:attr:`NoiseSettings.spin_speed`), and it runs
twice in this process:

- with ``[agent] estimator = "robust"``: its measurements, every robot's at every tick, are
  kept, and ``heft baseline``'s batch fit (:func:`simulator.baseline.fit`, the floor's
  friction with it) is made on them from the first tick to the robust run's final instant,
  then compared with the truth then, its friction parameters kept beside (if the run was
  done: a run not done has no final estimates to set it beside, and on a load the team could
  not break away from its floor the fit has no signal: on one generated load it had not
  finished after a quarter of an hour);
- with ``estimator = "paper"``.

Errors are the worst over robots (``m`` and ``J`` relative, ``contact_to_com`` in metres) and
over edges (``z_ij``); the baseline's relative positions are differences of its contact
offsets. The report gives their medians over the seeds, each estimator's ratio to the
baseline's, how many runs were done within :data:`DONE_WITHIN_S` simulated, and how often the
truth fell inside the robust estimators' published 95 % intervals. Its goals (:data:`GOALS`,
measured by :func:`figures`): each robust median within :data:`RATIO_GOAL` times the
baseline's, the truth inside each quantity's intervals 90–99 % of the time, at least
:data:`DONE_GOAL` % of the robust runs done within :data:`DONE_WITHIN_S`, every one on its
floor. Each seed's result also keeps every robot's published
estimates beside the truth (:class:`Interval`), from which ``heft bench calibrate``
(:mod:`simulator.bench.calibrate`) computes the factors the published uncertainties are
scaled by.

On a floor (:attr:`NoiseSettings.floor`, ``--coulomb`` or ``--coulomb-range``: each seed's
``μ`` and its supports as :mod:`simulator.bench.floor` gives them) the robots' friction
estimates are judged too (:data:`FRICTION`): the floor's Coulomb torque on a spin
``τ_c = μ m g c`` relative to the truth's, and ``μ`` absolute, with the share of their 95 %
intervals that hold the truth. The centralized fit fits the floor's friction too, but its own
friction parameters are not judged: beside the robots' it gives nothing.

``z_ij``'s errors are also split (:func:`~agent.platform.evaluation.relative_position_split`),
the robust estimators' beside the baseline's: the turn that every edge's estimate shares (the
team's rotation misjudged), the worst error of an edge's length, and the worst error left once
that common turn is taken out.

A sweep (``heft bench sweep``, :func:`run_sweep`) repeats this over ``σ_v`` with
``σ_f = 50 σ_v`` and plots the medians against ``σ_v``; it checks no goal. Another
(``heft bench friction``, :mod:`simulator.bench.friction`) repeats it over ``μ``.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from agent.algorithm.robust.uncertainty import FitShares
from agent.algorithm.tuning import Estimators
from agent.platform.cli_helpers import PROG
from agent.platform.evaluation import (
    ERROR_KEYS,
    RelativePositionSplit,
    relative_position_split,
    scalar_interval,
    team_errors,
    true_relative,
)
from agent.platform.goals import Goal, Sense
from agent.platform.protocol import Estimates, Measurement, Phase, Truth
from simulator.bench.floor import FloorSettings, on_floor
from simulator.inprocess import RunOutcome, Sample, run_inprocess
from simulator.results import errors, floor_check, intervals
from simulator.scenario import Actuators, Scenario

if TYPE_CHECKING:
    from simulator.baseline import BaselineFit

DONE_WITHIN_S = 30.0
"""s simulated: the goal for a run's end."""
DONE_GOAL = 95.0
"""% of the robust runs done within :data:`DONE_WITHIN_S` at least (38 of 40)."""
RATIO_GOAL = 1.5
"""Each median error within this factor of the baseline's."""
COVERAGE_GOAL = (0.90, 0.99)
"""The share of the published 95 % intervals that hold the truth: at least, at most."""
QUANTITIES = (
    ("m", "mass_rel", 100.0, "%"),
    ("J", "moment_rel", 100.0, "%"),
    ("contact_to_com", "contact_to_com_m", 1000.0, "mm"),
    ("z_ij", "relative_positions_m", 1000.0, "mm"),
)
"""Label, key (:data:`~agent.platform.evaluation.ERROR_KEYS`), display scale and unit of each
error reported and compared with the baseline's."""
FRICTION = (
    ("tau_c", "friction_torque_rel", 100.0, "%"),
    ("mu", "coulomb", 100.0, "% abs"),
)
"""The same for the friction estimates, which the baseline does not fit: ``τ̂_c``'s error
relative to the truth's ``μ m g c`` (:func:`friction_errors`; none on a floor without
friction), and ``|μ̂ − μ|`` (shown in hundredths, as μ is written in %)."""
JUDGED = QUANTITIES + FRICTION
"""Every quantity whose published 95 % intervals are judged."""
GOALS = (
    *(
        Goal(
            f"ratio {key}",
            f"{name}: robust median / baseline's (runs done)",
            RATIO_GOAL,
            Sense.AT_MOST,
        )
        for name, key, _, _ in QUANTITIES
    ),
    *(
        Goal(f"inside {key}", f"{name}: truth inside the 95 % intervals", 100 * low, sense, "%")
        for name, key, _, _ in JUDGED
        for low, sense in zip(COVERAGE_GOAL, (Sense.AT_LEAST, Sense.AT_MOST))
    ),
    Goal(
        "done",
        f"robust runs done within {DONE_WITHIN_S:g} s simulated",
        DONE_GOAL,
        Sense.AT_LEAST,
        "%",
    ),
    Goal("on floor", "robust runs that kept the load on its floor", 100.0, Sense.AT_LEAST, "%"),
)
"""What the noise benchmark checks, on the figures of :func:`figures`."""
GENERATED_PUSH_DAMPING = 2.0
"""N s/m: :attr:`NoiseSettings.push_damping` for the generated scenarios, whose loads (1 to
50 kg, 3 to 8 robots) under one push force would otherwise swing by up to ``n f T/2m`` =
16 m/s; with it, the COM's speed stays within about ``f / b`` = 1 m/s (``heft bench noise
--generated 20`` gives the largest speed over its runs, and how many kept to their floor)."""
GENERATED_INERTIA_BRAKE_S = 0.5
"""s: :attr:`NoiseSettings.inertia_brake_s` for the generated scenarios: Step 4 brakes first
for half of its 1 s flip, so that ω swings about the turn the load had; speeding up first, a
compact light load (``J`` of 1.6 kg m² under 7 robots) turned at up to 2.75 rad/s, beyond its
floor's 2 rad/s (``heft bench noise --generated 20`` gives the largest ``|ω|`` over its runs,
and how many kept to their floor)."""
FRICTION_KEYS = {
    "friction_torque_Nm": "friction_torque",
    "spin_drag_N_m": "spin_drag",
    "sliding_friction_N": "sliding_friction",
}
"""The baseline's friction errors (:func:`baseline_errors`), ``|τ̂_c − τ_c|`` (N m),
``|κ̂ − κ|`` (N/m) and ``|F̂_s − μ m g|`` (N) against the truth's
(:func:`~simulator.baseline.truth_friction`; 0 on a frictionless floor), and the parameter
each is of."""
SWEEP = (0.0, 0.001, 0.003, 0.01, 0.03)
"""σ_v (m/s) of the sweep; σ_f = 50 σ_v."""


@dataclass(frozen=True)
class NoiseSettings:
    velocity_noise: float = 0.01
    force_noise: float = 0.5
    time_constant_s: float = 0.02
    """The drives' lag (s)."""
    gain_error_std: float = 0.02
    """The drives' gain error (a fraction, per robot)."""
    seeds: int = 20
    first_seed: int = 0
    """The seeds run are ``first_seed .. first_seed + seeds − 1`` (the published variances'
    factors were measured on the generated loads on floors, seeds 80–199; seeds 0–79 are their
    check: ``heft bench calibrate published-variance --generated --coulomb-range 0.005 0.03
    --first-seed 80 --seeds 120``)."""
    max_time_s: float = 60.0
    spin_speed: float = 1.0
    """m/s: Step 1's spin-up target, for both estimators (the default; the paper's scenario
    runs its estimators at 0.5: a faster turn gives the arcs and the angle fits more signal
    against the same noise)."""
    spin_gain: float = 10.0
    """N s/m: the spin-up's gain, for both estimators (the default; 4, the paper's scenario's,
    holds a turn this fast only well below its target against the damping that keeps the floor
    bounded)."""
    push_force: float = 2.0
    """N: the robust estimators' common push, the default (the paper's size theirs by eq. 17)."""
    push_flip_s: float = 2.0
    """s: how often the push reverses, for both estimators (the default; the paper's scenario
    runs its estimators at 1): against noise, the COM's displacement, ``n f T²/8m``, is the
    mass's signal; the speed it swings by, ``n f T/2m``, is bounded by the floor."""
    inertia_brake_s: float = 0.0
    """s: the robust estimators' first braking in Step 4 (``heft bench noise --generated``
    sets :data:`GENERATED_INERTIA_BRAKE_S`, the default; the paper's scenario speeds up first,
    as ``paper-noisy.toml`` does: its ``|ω|`` stays within 1 rad/s, and its ``z_ij`` are better
    for the faster turn)."""
    push_damping: float = 0.0
    """N s/m: the robust estimators' damping of the centroid's velocity during the push
    (``heft bench noise --generated`` sets :data:`GENERATED_PUSH_DAMPING`, the default). The
    paper's scenario does without, as ``paper-noisy.toml`` does: its push is sized for its
    load (``heft bench noise``, measured before the team agreed on its rotation and mass: m
    0.76 % with it, 0.58 % without)."""
    floor: FloorSettings | None = None
    """The floor's friction for each seed (:mod:`simulator.bench.floor`); None: each
    scenario's own ``[ground]``, or none."""
    paper_estimators: bool = True
    """Whether the paper's estimators run too (``heft bench friction`` runs the robust ones
    alone: with noise the paper's never get past Step 1)."""

    @property
    def noise_text(self) -> str:
        """The sensors' noise, the drives and the floor, as the reports give them."""
        floor = "" if self.floor is None else f"; {self.floor.text}"
        return (
            f"sigma_v {self.velocity_noise:g} m/s, sigma_f {self.force_noise:g} N, drives:"
            f" lag {self.time_constant_s:g} s, gain error {100 * self.gain_error_std:g} %{floor}"
        )


@dataclass(frozen=True)
class Interval:
    """One robot's estimate with its uncertainty at the robust run's final instant, beside
    the truth then: a scalar as one component, a vector as two; ``covariance`` as the robot
    published it, ``(σ²,)`` or ``(xx, xy, yy)``."""

    robot: int
    estimate: tuple[float, ...]
    truth: tuple[float, ...]
    covariance: tuple[float, ...]
    fit_std: float | None = None
    """For ``Ĵ`` and a robot's own ``m̂``: the share of the standard deviation that the fit's
    rows give (:class:`~agent.algorithm.robust.uncertainty.FitShares`)."""

    @property
    def error(self) -> tuple[float, ...]:
        """The estimate minus the truth."""
        return tuple(e - t for e, t in zip(self.estimate, self.truth))


@dataclass
class SeedResult:
    """One seed: each estimator's worst errors (``None``: not estimated), done or not."""

    seed: int
    robust: dict[str, float | None]
    paper: dict[str, float | None]
    baseline: dict[str, float | None]
    robust_time_s: float
    robust_done: bool
    paper_done: bool
    inside: dict[str, list[bool]] = field(default_factory=dict)
    """Per quantity, whether the truth was inside each robot's 95 % interval."""
    floor: dict = field(default_factory=dict)
    """The robust run's excursion against the scenario's floor
    (:func:`~simulator.results.floor_check`)."""
    intervals: dict[str, list[Interval]] = field(default_factory=dict)
    """The robust run's published estimates (:func:`published`): ``mass``, ``moment``,
    ``contact_to_com``, ``relative_positions`` (one per edge), ``own_mass`` and
    ``push_offset``."""
    baseline_friction: dict[str, float | None] = field(default_factory=dict)
    """The batch fit's friction parameters and their standard deviations
    (:func:`baseline_friction`)."""
    coulomb: float = 0.0
    """The floor's ``μ`` in the runs (0: frictionless)."""
    dropped_cells: int = 0
    """The cells of the load's area it did not rest on, the floor pulling there
    (:func:`~simulator.bench.floor.on_floor`)."""
    split: dict[str, RelativePositionSplit | None] = field(default_factory=dict)
    """The robust estimators' and the baseline's ``z_ij`` errors split
    (:func:`~agent.platform.evaluation.relative_position_split`), by ``robust`` and
    ``baseline``; ``None`` where some edge has no estimate."""


def for_generated(settings: NoiseSettings) -> NoiseSettings:
    """``settings`` as the generated scenarios run: :data:`GENERATED_PUSH_DAMPING` and
    :data:`GENERATED_INERTIA_BRAKE_S`."""
    return dataclasses.replace(
        settings,
        push_damping=GENERATED_PUSH_DAMPING,
        inertia_brake_s=GENERATED_INERTIA_BRAKE_S,
    )


def noisy(scenario: Scenario, settings: NoiseSettings, seed: int, estimator: Estimators):
    """``scenario`` with the settings' noise and drives, run seed ``seed``, ``estimator``."""
    return dataclasses.replace(
        scenario,
        sensors=dataclasses.replace(
            scenario.sensors,
            velocity_noise_std=settings.velocity_noise,
            force_noise_std=settings.force_noise,
        ),
        actuators=dataclasses.replace(
            scenario.actuators,
            time_constant_s=settings.time_constant_s,
            gain_error_std=settings.gain_error_std,
        )
        if settings.time_constant_s or settings.gain_error_std
        else Actuators(),
        run=dataclasses.replace(scenario.run, seed=seed, max_time_s=settings.max_time_s),
        agent=dataclasses.replace(
            scenario.agent,
            estimator=estimator,
            spin_speed=settings.spin_speed,
            spin_gain=settings.spin_gain,
            push_flip_s=settings.push_flip_s,
            robust=dataclasses.replace(
                scenario.agent.robust,
                push_force=settings.push_force,
                push_damping=settings.push_damping,
                inertia_brake_s=settings.inertia_brake_s,
            ),
        ),
    )


def baseline_fit(
    outcome: RunOutcome,
    measured: list[list[Measurement]],
    settings: NoiseSettings,
    since_tick: int = 0,
) -> BaselineFit | None:
    """The batch fit (with the floor's friction) on the run's measurements from
    ``since_tick`` (at most :data:`~simulator.baseline.MAX_TICKS` of them) up to its final
    instant; None if it fails."""
    from simulator.baseline import MAX_TICKS, fit

    last = min(outcome.final.truth.tick, len(measured) - 1)
    first = max(since_tick, last + 1 - MAX_TICKS)
    ticks = measured[first : last + 1]
    v = np.array([[m.velocity for m in tick] for tick in ticks])
    f = np.array([[m.force for m in tick] for tick in ticks])
    try:
        return fit(
            v, f, outcome.scenario.period_s, settings.velocity_noise, settings.force_noise, first
        )
    except ValueError:
        return None


def baseline_errors(outcome: RunOutcome, found: BaselineFit | None) -> dict[str, float | None]:
    """The batch fit ``found`` (:func:`baseline_fit`) against the truth at the run's final
    instant, as the robots' estimates are (:func:`~agent.platform.evaluation.team_errors`;
    its m, J, ``contact_to_com`` and ``z_ij``), and its friction's absolute errors
    (:data:`FRICTION_KEYS`, ``None`` if fitted without or the truth lacks it); ``None``
    everywhere if the fit failed."""
    from simulator.baseline import truth_friction

    if found is None:
        return dict.fromkeys((*ERROR_KEYS, *FRICTION_KEYS))
    truth = outcome.final.truth
    true = truth_friction(truth)
    errors = team_errors(fitted_estimates(outcome, found), truth, _graph(outcome))
    for key, name in FRICTION_KEYS.items():
        value, exact = getattr(found, name), true[name]
        errors[key] = None if value is None or exact is None else abs(value - exact)
    return errors


def _graph(outcome: RunOutcome) -> dict[int, tuple[int, ...]]:
    scenario = outcome.scenario
    return {i: tuple(scenario.neighbours(i)) for i in range(1, scenario.n + 1)}


def fitted_estimates(outcome: RunOutcome, found: BaselineFit) -> dict[int, Estimates]:
    """The batch fit ``found`` as each robot's estimates at the run's final instant: its m,
    J, ``contact_to_com`` and ``z_ij``."""
    tick = outcome.final.truth.tick
    return {
        i: Estimates(
            robot=i,
            tick=tick,
            phase=Phase.DONE,
            mass=found.mass,
            moment=found.moment,
            contact_to_com=found.contact_to_com[i - 1],
            relative_positions={j: found.relative_position(i, j) for j in neighbours},
        )
        for i, neighbours in _graph(outcome).items()
    }


def baseline_friction(found: BaselineFit | None) -> dict[str, float | None]:
    """The batch fit's friction parameters and their standard deviations (``None``: the fit
    failed)."""
    keys = [key + end for key in FRICTION_KEYS.values() for end in ("", "_std")]
    return {key: None if found is None else getattr(found, key) for key in keys}


def published(sample: Sample, shares: dict[int, FitShares]) -> dict[str, list[Interval]]:
    """Every robot's estimates in ``sample`` that it published an uncertainty for, beside the
    truth then (:class:`Interval`): ``mass`` (the team's), ``moment``, ``contact_to_com``, one
    ``relative_positions`` per edge, ``friction_torque`` and ``coulomb`` (the floor's, against
    ``μ m g c`` and ``μ``), and ``own_mass`` (the robot's own fit, not published),
    with the shares of their fits (``shares``, per robot) for ``moment`` and ``own_mass``; and
    ``push_offset``, ``contact_to_com`` from Step 5's ``ẑ_C`` alone (not published), its
    covariance before :data:`~agent.algorithm.robust.uncertainty.STEP5_COM_VARIANCE`."""
    truth = sample.truth
    found: dict[str, list[Interval]] = {
        key: []
        for key in (
            "mass",
            "moment",
            "contact_to_com",
            "relative_positions",
            "own_mass",
            "push_offset",
            "friction_torque",
            "coulomb",
        )
    }
    for i, est in sorted(sample.estimates.items()):
        share = shares.get(i, FitShares())
        if est.mass is not None and est.mass_std is not None:
            found["mass"].append(Interval(i, (est.mass,), (truth.mass,), (est.mass_std**2,)))
        if est.moment is not None and est.moment_std is not None:
            found["moment"].append(
                Interval(i, (est.moment,), (truth.moment,), (est.moment_std**2,), share.moment)
            )
        if est.contact_to_com is not None and est.contact_to_com_cov is not None:
            found["contact_to_com"].append(
                Interval(
                    i,
                    tuple(est.contact_to_com),
                    tuple(truth.contact_to_com[i - 1]),
                    tuple(est.contact_to_com_cov),
                )
            )
        for j, cov in sorted(est.relative_positions_cov.items()):
            z = est.relative_positions.get(j)
            if z is not None:
                found["relative_positions"].append(
                    Interval(i, tuple(z), true_relative(truth, i, j), tuple(cov))
                )
        if share.own_mass is not None:
            mass, std, fit_std = share.own_mass
            found["own_mass"].append(Interval(i, (mass,), (truth.mass,), (std * std,), fit_std))
        if share.push_offset is not None:
            offset, cov = share.push_offset
            true_offset = tuple(truth.contact_to_com[i - 1])
            found["push_offset"].append(Interval(i, tuple(offset), true_offset, tuple(cov)))
        for key, value, std, true in (
            ("friction_torque", est.friction_torque, est.friction_torque_std, truth.coulomb_torque),
            ("coulomb", est.coulomb, est.coulomb_std, truth.ground_coulomb),
        ):
            if value is not None and std is not None:
                found[key].append(Interval(i, (value,), (true,), (std * std,)))
    return found


def friction_errors(found: dict[str, float | None], truth: Truth) -> dict[str, float | None]:
    """``found`` (:func:`~agent.platform.evaluation.team_errors`' keys) with
    ``friction_torque_rel``: ``friction_torque_nm`` over the truth's ``τ_c = μ m g c``
    (None without friction, where that is 0)."""
    error, torque = found.get("friction_torque_nm"), truth.coulomb_torque
    relative = None if error is None or not torque > 0.0 else error / torque
    return {**found, "friction_torque_rel": relative}


def friction_inside(outcome: RunOutcome) -> dict[str, list[bool]]:
    """Per robot that published them, whether the truth's ``τ_c`` and ``μ`` lie inside its
    95 % intervals of ``friction_torque`` and ``coulomb``
    (:func:`~agent.platform.evaluation.scalar_interval`), keyed as :data:`FRICTION`."""
    truth = outcome.final.truth
    found: dict[str, list[bool]] = {"friction_torque_rel": [], "coulomb": []}
    for _, est in sorted(outcome.final.estimates.items()):
        for key, estimate, std, true in (
            (
                "friction_torque_rel",
                est.friction_torque,
                est.friction_torque_std,
                truth.coulomb_torque,
            ),
            ("coulomb", est.coulomb, est.coulomb_std, truth.ground_coulomb),
        ):
            inside = scalar_interval(estimate, std, true)[1]
            if inside is not None:
                found[key].append(inside)
    return found


def run_seed(scenario: Scenario, settings: NoiseSettings, seed: int) -> SeedResult:
    """The three estimators on seed ``seed`` of ``scenario`` (see the module docstring), on
    the settings' floor if they give one (the paper's only if
    :attr:`NoiseSettings.paper_estimators`)."""
    dropped = 0
    if settings.floor is not None:
        scenario, dropped = on_floor(scenario, *settings.floor.draw(seed))
    measured: list[list[Measurement]] = []
    final: dict[str, list[Interval]] = {}

    def keep(sample: Sample, agents) -> None:
        final.clear()
        final.update(published(sample, {a.robot: a.pipeline.fit_shares() for a in agents}))

    robust = run_inprocess(
        noisy(scenario, settings, seed, Estimators.ROBUST),
        record_every=1000,
        on_measure=measured.append,
        on_sample=keep,
    )
    reference = baseline_fit(robust, measured, settings) if robust.converged else None
    paper = (
        run_inprocess(noisy(scenario, settings, seed, Estimators.PAPER), record_every=1000)
        if settings.paper_estimators
        else None
    )
    inside: dict[str, list[bool]] = {key: [] for _, key, _, _ in QUANTITIES}
    names = {  # the errors' keys, those of simulator.results.intervals
        "mass_rel": "mass",
        "moment_rel": "moment",
        "contact_to_com_m": "contact_to_com",
        "relative_positions_m": "relative_positions",
    }
    for i in range(1, scenario.n + 1):
        row = intervals(robust, i)
        if row is None:
            continue
        for key, name in names.items():
            if row[name][1] is not None:
                inside[key].append(bool(row[name][1]))
    inside.update(friction_inside(robust))
    truth = robust.final.truth
    graph = _graph(robust)
    split = {
        "robust": relative_position_split(robust.final.estimates, truth, graph),
        "baseline": None
        if reference is None
        else relative_position_split(fitted_estimates(robust, reference), truth, graph),
    }
    return SeedResult(
        seed=seed,
        robust=friction_errors(errors(robust), truth),
        paper=friction_errors(dict.fromkeys(ERROR_KEYS), truth)
        if paper is None
        else friction_errors(errors(paper), paper.final.truth),
        baseline=friction_errors(baseline_errors(robust, reference), truth),
        baseline_friction=baseline_friction(reference),
        robust_time_s=robust.sim_time_s,
        robust_done=robust.converged,
        paper_done=paper is not None and paper.converged,
        inside=inside,
        floor=floor_check(robust),
        intervals=dict(final),
        coulomb=truth.ground_coulomb,
        dropped_cells=dropped,
        split=split,
    )


def say_seed(result: SeedResult) -> None:
    """One progress line on stderr per seed: the robust run done or not, and when."""
    state = "done" if result.robust_done else "NOT done"
    print(
        f"{PROG}: seed {result.seed}: robust {state} at {result.robust_time_s:.2f} s simulated",
        file=sys.stderr,
        flush=True,
    )


def run_noise_bench(
    scenarios: Callable[[int], Scenario],
    settings: NoiseSettings,
    on_seed: Callable[[SeedResult], None] | None = None,
) -> list[SeedResult]:
    """The settings' seeds (:attr:`NoiseSettings.first_seed` on); ``scenarios(seed)`` gives
    each one's scenario."""
    results = []
    for seed in range(settings.first_seed, settings.first_seed + settings.seeds):
        result = run_seed(scenarios(seed), settings, seed)
        results.append(result)
        if on_seed is not None:
            on_seed(result)
    return results


def median(results: Sequence[SeedResult], which: str, key: str) -> float | None:
    """The median over seeds of ``which`` estimator's ``key`` error; ``None`` if any run has
    no such estimate (its error is then unbounded)."""
    values = [getattr(r, which).get(key) for r in results]
    if not values or any(v is None for v in values):
        return None
    return statistics.median(values)


def coverage(results: Sequence[SeedResult], key: str) -> tuple[int, int]:
    """``(inside, published)``: robots' 95 % intervals holding the truth, over all seeds."""
    flags = [flag for r in results for flag in r.inside.get(key, [])]
    return sum(flags), len(flags)


def _cell(value: float | None, scale: float) -> str:
    return "-" if value is None else f"{value * scale:.3g}"


def ratio(results: Sequence[SeedResult], key: str) -> float | None:
    """The robust estimators' median ``key`` error over the baseline's; None if either is
    unbounded (or the baseline's is 0)."""
    robust, base = median(results, "robust", key), median(results, "baseline", key)
    return robust / base if robust is not None and base else None


def share(results: Sequence[SeedResult], key: str) -> float | None:
    """The share of the published 95 % intervals of ``key`` that held the truth; None if
    none was published."""
    inside, published = coverage(results, key)
    return inside / published if published else None


def _robust_done(results: Sequence[SeedResult]) -> int:
    """Robust runs done within :data:`DONE_WITHIN_S` simulated."""
    return sum(r.robust_done and r.robust_time_s <= DONE_WITHIN_S for r in results)


def _on_floor(results: Sequence[SeedResult]) -> int:
    """Robust runs that kept the load on its floor."""
    return sum(r.floor["within"] for r in results if r.floor)


def figures(results: Sequence[SeedResult]) -> dict[str, float | None]:
    """The figures :data:`GOALS` bound: per quantity the ratio of the medians
    (:data:`QUANTITIES`) over the robust runs done (a run that ended with a verdict, or ran out
    of time, has no estimates to judge: how many were done is a goal of its own), the share of
    the intervals holding the truth (%, :data:`JUDGED`), and the shares of robust runs done in
    time and on their floor (%)."""
    n = len(results)
    found: dict[str, float | None] = {}
    done = [r for r in results if r.robust_done]
    for _, key, _, _ in QUANTITIES:
        found[f"ratio {key}"] = ratio(done, key) if done else None
    for _, key, _, _ in JUDGED:
        inside = share(results, key)
        found[f"inside {key}"] = None if inside is None else 100 * inside
    found["done"] = 100 * _robust_done(results) / n if n else None
    found["on floor"] = 100 * _on_floor(results) / n if n else None
    return found


def format_noise_report(
    results: Sequence[SeedResult], settings: NoiseSettings, label: str, wall_s: float
) -> str:
    """The report: medians, ratios to the baseline, runs done in time, coverage (the goals'
    verdicts follow it: :data:`GOALS`); when some robust runs were not done (their unknown
    errors leave the medians unbounded), the same over the runs that were, beside it."""
    n = len(results)
    seeds = f"{n} seeds" if not results else f"{n} seeds ({results[0].seed}-{results[-1].seed})"
    lines = [
        f"heft bench noise: {label}, {seeds}, {settings.noise_text} ({wall_s:.0f} s wall)",
        "",
        *_median_table(results),
        *_split_lines(results),
    ]
    done = [r for r in results if r.robust_done]
    if 0 < len(done) < n:
        which = ", ".join(str(r.seed) for r in done)
        lines += [
            "",
            f"over the {len(done)} robust runs done (seeds {which}):",
            *_median_table(done),
        ]
    slowest = max((r.robust_time_s for r in results), default=math.nan)
    floors = [r.floor for r in results if r.floor]
    lines += [
        "",
        f"robust runs done within {DONE_WITHIN_S:g} s simulated: {_robust_done(results)}/{n}"
        f" (slowest {slowest:.2f} s); paper runs done: {sum(r.paper_done for r in results)}/{n}",
        f"robust runs that kept the load on its floor: {_on_floor(results)}/{n} (largest travel"
        f" {max((f['travel_m'] for f in floors), default=math.nan):.2f} m, speed"
        f" {max((f['speed'] for f in floors), default=math.nan):.2f} m/s, |ω|"
        f" {max((f['omega'] for f in floors), default=math.nan):.2f} rad/s)",
        *_floor_lines(results),
    ]
    return "\n".join(lines)


def _median_table(results: Sequence[SeedResult]) -> list[str]:
    """Per quantity of :data:`JUDGED`: each estimator's median error, the robust one's ratio
    to the baseline's, and the share of the 95 % intervals that held the truth."""
    lines = [
        f"{'median error':<20} {'robust':>9} {'paper':>9} {'baseline':>9}"
        f" {'robust/baseline':>16} {'95 % inside':>12}",
    ]
    for name, key, scale, unit in JUDGED:
        robust, paper, base = (median(results, w, key) for w in ("robust", "paper", "baseline"))
        against = ratio(results, key)
        inside = share(results, key)
        published = coverage(results, key)[1]
        lines.append(
            f"{name + ' (' + unit + ')':<20} {_cell(robust, scale):>9} {_cell(paper, scale):>9}"
            f" {_cell(base, scale):>9} {'-' if against is None else f'{against:.2f}':>16}"
            f" {'-' if inside is None else f'{100 * inside:.0f} % of {published}':>12}"
        )
    return lines


def _split_lines(results: Sequence[SeedResult]) -> list[str]:
    """``z_ij``'s errors split (:func:`~agent.platform.evaluation.relative_position_split`):
    the medians over the runs where both the robust estimators and the baseline have every
    edge, of the turn common to the edges, the worst length and the worst error without the
    common turn; nothing without such runs."""
    both = [r for r in results if r.split.get("robust") and r.split.get("baseline")]
    if not both:
        return []

    def med(which: str, name: str, scale: float) -> str:
        values = [scale * abs(getattr(r.split[which], name)) for r in both]
        return f"{statistics.median(values):.3g}"

    cells = [
        f"{label} {med('robust', name, scale)} / {med('baseline', name, scale)} {unit}"
        for label, name, scale, unit in (
            ("common turn", "common_turn", 1000.0, "mrad"),
            ("worst length", "worst_length", 1000.0, "mm"),
            ("worst without the common turn", "worst_own", 1000.0, "mm"),
        )
    ]
    return [f"z_ij split, robust / baseline (medians over {len(both)} runs): " + "; ".join(cells)]


def _floor_lines(results: Sequence[SeedResult]) -> list[str]:
    """What the runs stood on: the range of ``μ`` over them, the loads that rested on part of
    their area (:func:`~simulator.bench.floor.on_floor`), and that the baseline fits no
    friction; nothing for runs that all had none."""
    mus = [r.coulomb for r in results]
    if not any(mus):
        return []
    partial = [f"{r.seed} ({r.dropped_cells})" for r in results if r.dropped_cells]
    lines = [
        f"floor: mu {100 * min(mus):.3g}-{100 * max(mus):.3g} % (median"
        f" {100 * statistics.median(mus):.3g} %); tau_c's error relative to the truth's"
        " mu m g c, mu's absolute (in %); the baseline fits the floor's friction too (heft"
        " baseline), compared here on m, J, contact_to_com and z_ij",
    ]
    if partial:
        lines.append(
            "loads resting on part of their area (cells dropped where the floor would pull):"
            f" seeds {', '.join(partial)}"
        )
    return lines


# ------------------------------------------------------------------------------ the sweep
def run_sweep(
    scenarios: Callable[[int], Scenario],
    base: NoiseSettings,
    on_level: Callable[[float, list[SeedResult]], None] | None = None,
    levels: Sequence[float] = SWEEP,
) -> dict[float, list[SeedResult]]:
    """:func:`run_noise_bench` with ``base``'s seeds and drives at each ``σ_v`` of ``levels``
    (``σ_f = 50 σ_v``; the drives ideal at ``σ_v = 0``, where nothing is noisy)."""
    found = {}
    for sigma in levels:
        drives = base if sigma else dataclasses.replace(base, time_constant_s=0, gain_error_std=0)
        settings = dataclasses.replace(drives, velocity_noise=sigma, force_noise=50 * sigma)
        found[sigma] = run_noise_bench(scenarios, settings)
        if on_level is not None:
            on_level(sigma, found[sigma])
    return found


def format_sweep(found: dict[float, list[SeedResult]], label: str) -> str:
    """A markdown table: per ``σ_v``, each quantity's median for the three estimators (``-``:
    some run had no such estimate)."""
    head = "| σ_v (m/s) | σ_f (N) | " + " | ".join(
        f"{name} ({unit}) robust / paper / baseline" for name, _, _, unit in QUANTITIES
    )
    lines = [f"{label}, medians over {len(next(iter(found.values()), []))} seeds", "", head + " |"]
    lines.append("|---|---|" + "---|" * len(QUANTITIES))
    for sigma, results in found.items():
        cells = []
        for _, key, scale, _ in QUANTITIES:
            cells.append(
                " / ".join(
                    _cell(median(results, w, key), scale) for w in ("robust", "paper", "baseline")
                )
            )
        lines.append(f"| {sigma:g} | {50 * sigma:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot_sweep(found: dict[float, list[SeedResult]], path: Path, label: str) -> Path:
    """Error against ``σ_v``, one panel per quantity, log-log (the noise-free runs at the left
    edge, at a tenth of the smallest noise, which the axis label says)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sigmas = sorted(found)
    positive = [s for s in sigmas if s > 0]
    floor = min(positive) / 10 if positive else 1e-4
    xs = [s if s > 0 else floor for s in sigmas]
    fig, axes = plt.subplots(1, len(QUANTITIES), figsize=(16, 4), constrained_layout=True)
    for ax, (name, key, scale, unit) in zip(axes, QUANTITIES):
        for which, style in (("robust", "o-"), ("paper", "s--"), ("baseline", "^:")):
            ys = [median(found[s], which, key) for s in sigmas]
            pts = [(x, y * scale) for x, y in zip(xs, ys) if y is not None and y > 0]
            if pts:
                ax.plot(*zip(*pts), style, label=which)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(f"σ_v (m/s), σ_f = 50 σ_v (σ_v = 0 at {floor:g})")
        ax.set_title(f"{name} ({unit}), median")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend()
    fig.suptitle(label)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def timed(function, *args, **kwargs):
    """``(function(*args, **kwargs), wall seconds)``."""
    started = time.perf_counter()
    return function(*args, **kwargs), time.perf_counter() - started
