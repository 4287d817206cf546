"""The simulator's benchmarks, subcommands of ``heft bench`` (entry point of the group
``heft.bench``)::

    heft bench accuracy [SCENARIO] [-n/--repeat N]
    heft bench generated [-n/--count N]
    heft bench zenoh [--sizes 4,8,16]
    heft bench noise [SCENARIO] [--seeds N] [--first-seed S] [--generated N] [--ideal-drives]
                     [--coulomb MU | --coulomb-range LO HI] [--static MU_S]
    heft bench sweep [...as noise...] [--plot DIR]
    heft bench friction [SCENARIO] [--seeds N] [--first-seed S] [--generated N]
                        [--ideal-drives] [--plot FILE]
    heft bench changes [SCENARIO] [--seeds N] [--first-seed S]
    heft bench calibrate published-variance|direction-variance|correlation-time [--seeds N]
                         [--first-seed S] [--ideal-drives]
    heft bench calibrate arc-correlation [--seeds N]

Each runs in this process (``zenoh``: as processes on 127.0.0.1) and prints its report on
standard output, its progress on stderr. ``accuracy`` (the robust estimators' speed against
the paper's), ``generated``, ``noise``, ``friction`` and ``changes`` check goals (their
modules' ``GOALS``): each goal's figure and verdict are printed last, and the exit status is 0
when every one is met, 1 when one is not. ``zenoh`` and ``sweep`` report figures and check
none: 0 once they ran; so does ``calibrate`` (:mod:`simulator.bench.calibrate`), which
registers its own parser.

Building the parsers imports nothing heavy (no pymunk, numpy or matplotlib): the handlers
import what they run.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from agent.platform.cli_helpers import PROG, HelpFormatter, UsageError, check_writable
from agent.platform.config import Bound
from agent.platform.goals import conclude
from simulator.bench import calibrate
from simulator.cli import load_scenario_argument
from simulator.scenario import MAX_FRICTION, PAPER_SCENARIO

if TYPE_CHECKING:
    from simulator.bench.floor import FloorSettings
    from simulator.bench.noise import NoiseSettings
    from simulator.inprocess import RunOutcome
    from simulator.scenario import Scenario

NOISE_SEEDS = 20
"""Seeds of ``noise``, ``sweep``, ``friction`` and ``changes`` when not told (that of
:class:`simulator.bench.noise.NoiseSettings`)."""
PAPER_FLOOR_SCENARIO = PAPER_SCENARIO.with_name("paper-floor.toml")
"""The paper's load on four casters, ``heft bench friction``'s load when not told."""
FRICTION_BOUND = Bound(0, MAX_FRICTION)
"""The range of ``--coulomb``, ``--coulomb-range`` and ``--static``: the scenario's."""


def register(benchmarks: argparse._SubParsersAction) -> None:
    """Add the simulator's benchmarks to ``heft bench`` (entry point of the group
    ``heft.bench``); a benchmark module with an ``add_parser(benchmarks)`` of its own joins
    :data:`PARSERS`."""
    for add_parser in PARSERS:
        add_parser(benchmarks)


def _say_run(label: str, outcome: RunOutcome) -> None:
    """One progress line on stderr per benchmark run."""
    state = "converged" if outcome.converged else "NOT converged"
    print(
        f"{PROG}: {label}: {state}, {outcome.sim_time_s:.2f} s simulated in"
        f" {outcome.wall_s:.2f} s wall",
        file=sys.stderr,
        flush=True,
    )


def _scenario_argument(
    parser: argparse.ArgumentParser | argparse._MutuallyExclusiveGroup,
    default: Path = PAPER_SCENARIO,
    what: str = "the paper's",
):
    parser.add_argument(
        "scenario",
        metavar="SCENARIO",
        nargs="?",
        default=str(default),
        help=f"scenario TOML file (default: {what}, simulator/scenarios/{default.name})",
    )


# ------------------------------------------------------------------------------ accuracy
def cmd_accuracy(args: argparse.Namespace) -> int:
    """``heft bench accuracy``: run a scenario several times; accuracy and speed."""
    from simulator.bench.accuracy import GOALS, figures, format_report, run_benchmark

    Bound(1, 1000, "runs").check("--repeat", args.repeat)
    scenario = load_scenario_argument(args.scenario)

    def on_run(k: int, family, outcome: RunOutcome) -> None:
        _say_run(f"run {k}/{args.repeat}, {family.value} estimators", outcome)

    report = run_benchmark(scenario, args.repeat, source=args.scenario, on_run=on_run)
    print(format_report(report))
    return conclude(GOALS, figures(report))


def _add_accuracy(benchmarks: argparse._SubParsersAction) -> None:
    parser = benchmarks.add_parser(
        "accuracy",
        help="accuracy, step durations and speed of each family of estimators",
        formatter_class=HelpFormatter,
        description=(
            "Run SCENARIO in this process N times with each family of estimators (robust,\n"
            "paper: its [agent] estimator set to each, the same load, sensors and drives) and\n"
            "print, for its own estimators, the worst final errors (mass %, J %,\n"
            "contact-to-COM and z_ij in mm) and the simulated time each paper step took; for\n"
            "each family, how many times faster than real time the runs went (median, min,\n"
            "max), the wall-clock time per simulated second and each agent's time in its step\n"
            "calls per simulated second; the robust / paper ratio of the wall-clock time per\n"
            "simulated second and the peak resident memory.\n\n"
            "Goal: that ratio at most 1.5.\n\n"
            "Exit status: 0 goal met, 1 not met, 2 bad scenario or arguments, 130 interrupted."
        ),
    )
    _scenario_argument(parser)
    parser.add_argument(
        "-n",
        "--repeat",
        metavar="N",
        type=int,
        default=9,
        help="number of runs with each family (default: 9), in [1, 1000]",
    )
    parser.set_defaults(handler=cmd_accuracy)


# ------------------------------------------------------------------------------ generated
def cmd_generated(args: argparse.Namespace) -> int:
    """``heft bench generated``: the generated scenarios once each (generality)."""
    Bound(1, 1000, "scenarios").check("--count", args.count)
    from simulator.bench.generated import (
        GOALS,
        figures,
        format_generated,
        run_generated,
        run_paper,
    )

    def on_run(seed: int, outcome: RunOutcome) -> None:
        _say_run(f"seed {seed}, {outcome.scenario.n} robots", outcome)

    paper = run_paper()
    _say_run("the paper's load", paper)
    outcomes = run_generated(args.count, on_run)
    print(format_generated(paper, outcomes))
    return conclude(GOALS, figures(paper, outcomes))


def _add_generated(benchmarks: argparse._SubParsersAction) -> None:
    parser = benchmarks.add_parser(
        "generated",
        help="generality without noise: the default estimators on many loads",
        formatter_class=HelpFormatter,
        description=(
            "Run the default estimators (no [agent] table: the robust ones) without noise, once\n"
            "each in this process, on the paper's load and on the loads of the generated\n"
            "scenarios of seeds 0..N-1 (heft scenario generate: 3-8 robots, every graph and load\n"
            "shape), and print the paper's load's final errors, then the generated loads'\n"
            "median and worst final errors and durations.\n\n"
            "Goals: every run converged and on its floor; the paper's load within 0.01 % (m),\n"
            "0.05 % (J) and 1 mm (contact_to_com); the generated loads' medians within 0.1 %\n"
            "(m and J) and 2 mm (contact_to_com).\n\n"
            "Exit status: 0 every goal met, 1 one not met, 2 bad arguments, 130 interrupted."
        ),
    )
    parser.add_argument(
        "-n",
        "--count",
        metavar="N",
        type=int,
        default=20,
        help="scenarios, seeds 0..N-1 (default: 20), in [1, 1000]",
    )
    parser.set_defaults(handler=cmd_generated)


# ------------------------------------------------------------------------------ zenoh
def cmd_zenoh(args: argparse.Namespace) -> int:
    """``heft bench zenoh``: one process per robot, lockstep speed and real-time latency."""
    try:
        sizes = [int(s) for s in args.sizes.split(",")]
    except ValueError:
        raise UsageError(f"--sizes: expected numbers like 4,8,16, got {args.sizes!r}") from None
    for n in sizes:
        if n < 3 or 32 % n:
            raise UsageError(f"--sizes: a ring team needs n >= 3 dividing 32, got {n}")
    from simulator.bench.over_zenoh import format_zenoh_report, run_zenoh_benchmark

    print(format_zenoh_report(run_zenoh_benchmark(sizes, _say_run)))
    return 0


def _add_zenoh(benchmarks: argparse._SubParsersAction) -> None:
    parser = benchmarks.add_parser(
        "zenoh",
        help="processes over Zenoh: lockstep speed, real-time latency, CPU",
        formatter_class=HelpFormatter,
        description=(
            "Run the team as processes on 127.0.0.1 (a Zenoh router, the plant, one agent per\n"
            "robot): ring teams of each size in lockstep (how much faster than real time they\n"
            "step, CPU per agent), then the paper's scenario in real time (command latency\n"
            "p50/p99, late and missing commands, CPU per agent). It checks no goal.\n\n"
            "Exit status: 0 done, 2 bad arguments, 130 interrupted."
        ),
    )
    parser.add_argument(
        "--sizes",
        default="4,8,16",
        metavar="N,N,...",
        help="ring team sizes, each n >= 3 dividing 32 (default: 4,8,16)",
    )
    parser.set_defaults(handler=cmd_zenoh)


# ------------------------------------------------------------------------------ noise
def _seeds(args: argparse.Namespace, default: int) -> tuple[int, int]:
    """``--seeds`` (else ``default``) and ``--first-seed``, range-checked."""
    seeds = default if args.seeds is None else args.seeds
    if args.seeds is not None:
        Bound(1, 1000, "seeds").check("--seeds", args.seeds)
    Bound(0, 100_000, "seeds").check("--first-seed", args.first_seed)
    return seeds, args.first_seed


def _noisy_runs(
    args: argparse.Namespace,
) -> tuple[Callable[[int], Scenario], str, NoiseSettings]:
    """What ``noise`` and ``sweep`` run: each seed's scenario (SCENARIO's, or with
    ``--generated`` the generated one of that seed), its label, and the settings."""
    from simulator.bench.noise import NoiseSettings, for_generated

    if args.generated is not None:
        from simulator.generate import generate_scenario

        Bound(1, 1000, "scenarios").check("--generated", args.generated)
        seeds, first = _seeds(args, args.generated)
        scenarios, label = generate_scenario, "generated scenarios"
    else:
        scenario = load_scenario_argument(args.scenario)
        seeds, first = _seeds(args, NOISE_SEEDS)
        label = f"scenario {scenario.name!r}"

        def scenarios(seed: int) -> Scenario:
            return scenario

    settings = dataclasses.replace(NoiseSettings(), seeds=seeds, first_seed=first)
    if args.generated is not None:
        settings = for_generated(settings)
    if args.ideal_drives:
        settings = dataclasses.replace(settings, time_constant_s=0.0, gain_error_std=0.0)
    floor = floor_settings(args)
    if floor is not None:
        settings = dataclasses.replace(settings, floor=floor)
    return scenarios, label, settings


def floor_settings(args: argparse.Namespace) -> FloorSettings | None:
    """``--coulomb MU`` or ``--coulomb-range LO HI``, with ``--static MU_S``, range-checked;
    None without them (each scenario's own floor)."""
    coulomb = getattr(args, "coulomb", None)
    span = getattr(args, "coulomb_range", None)
    static = getattr(args, "static", None)
    if coulomb is None and span is None:
        if static is not None:
            raise UsageError("--static: needs --coulomb or --coulomb-range")
        return None
    if coulomb is not None:
        FRICTION_BOUND.check("--coulomb", coulomb)
        span = (coulomb, coulomb)
    else:
        low, high = span
        FRICTION_BOUND.check("--coulomb-range LO", low)
        if not FRICTION_BOUND.contains(high, low=low):
            raise UsageError(
                FRICTION_BOUND.message("--coulomb-range HI", high, low, " (at least LO)")
            )
    if static is not None and not FRICTION_BOUND.contains(static, low=span[1]):
        raise UsageError(
            FRICTION_BOUND.message("--static", static, span[1], " (at least the largest mu)")
        )
    from simulator.bench.floor import FloorSettings

    return FloorSettings(tuple(span), static)


def cmd_noise(args: argparse.Namespace) -> int:
    """``heft bench noise``: the robust estimators, the paper's and the centralized fit on the
    same noisy runs."""
    scenarios, label, settings = _noisy_runs(args)
    from simulator.bench.noise import (
        GOALS,
        figures,
        format_noise_report,
        run_noise_bench,
        say_seed,
        timed,
    )

    results, wall = timed(run_noise_bench, scenarios, settings, say_seed)
    print(format_noise_report(results, settings, label, wall))
    return conclude(GOALS, figures(results))


def cmd_sweep(args: argparse.Namespace) -> int:
    """``heft bench sweep``: the noise benchmark over σ_v, a table (and a plot)."""
    if args.plot is not None:
        check_writable(Path(args.plot), directory=True)
    scenarios, label, settings = _noisy_runs(args)
    from simulator.bench.noise import format_sweep, plot_sweep, run_sweep

    found = run_sweep(
        scenarios,
        settings,
        lambda sigma, _: print(f"{PROG}: sigma_v {sigma:g} m/s done", file=sys.stderr),
    )
    print(format_sweep(found, label))
    if args.plot is not None:
        print(f"plot: {plot_sweep(found, Path(args.plot) / 'noise_sweep.png', label)}")
    return 0


def _add_noise_options(
    parser: argparse.ArgumentParser, default: Path = PAPER_SCENARIO, what: str = "the paper's"
) -> None:
    """SCENARIO (``default``, ``what`` it is) or ``--generated``, ``--seeds``,
    ``--first-seed``, ``--ideal-drives``."""
    which = parser.add_mutually_exclusive_group()
    _scenario_argument(which, default, what)
    which.add_argument(
        "--generated",
        metavar="N",
        type=int,
        help="instead of SCENARIO: the generated scenarios of seeds 0..N-1 (N: 1 to 1000;"
        " --seeds, if given, counts them instead), their robust robots damping the push",
    )
    _add_seed_options(parser)
    parser.add_argument(
        "--ideal-drives",
        action="store_true",
        help="drives that apply exactly what they are commanded (no lag, no gain error)",
    )


def _add_floor_options(parser: argparse.ArgumentParser) -> None:
    """``--coulomb MU`` or ``--coulomb-range LO HI``, and ``--static MU_S``."""
    which = parser.add_mutually_exclusive_group()
    which.add_argument(
        "--coulomb",
        metavar="MU",
        type=float,
        help="on a floor of kinetic friction MU (a fraction of the weight, in"
        f" {FRICTION_BOUND.text()}): SCENARIO's own supports if it has a [ground] table, else"
        " the load's whole area (the cells that bear it, if the floor would pull at others)",
    )
    which.add_argument(
        "--coulomb-range",
        metavar=("LO", "HI"),
        nargs=2,
        type=float,
        help="the same with each seed's MU drawn uniformly in [LO, HI] (its own seeded stream)",
    )
    parser.add_argument(
        "--static",
        metavar="MU_S",
        type=float,
        help=f"the breakaway friction, at least MU (default: 1.5 MU, at most {MAX_FRICTION:g})",
    )


def _add_seed_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--seeds",
        type=int,
        metavar="N",
        help=f"seeds 0..N-1 (default: {NOISE_SEEDS}), in [1, 1000]",
    )
    parser.add_argument(
        "--first-seed",
        type=int,
        metavar="S",
        default=0,
        help="seeds S..S+N-1 instead (default: 0; the published uncertainties were calibrated"
        " on the generated loads on floors, --generated --first-seed 80 --seeds 120)",
    )


def _add_noise(benchmarks: argparse._SubParsersAction) -> None:
    parser = benchmarks.add_parser(
        "noise",
        help="under sensor noise: robust vs paper vs the centralized fit",
        formatter_class=HelpFormatter,
        description=(
            "The robust estimators, the paper's and the centralized batch fit (heft baseline)\n"
            "on the same runs at 1 cm/s and 0.5 N of sensor noise with lagging drives of 2 %\n"
            "gain error, over --seeds seeds of SCENARIO (or of the generated scenarios), on a\n"
            "floor of friction with --coulomb or --coulomb-range (else SCENARIO's own): median\n"
            "errors, ratios to the fit (with the floor's friction), runs done within 30 s, how\n"
            "often the truth is inside the published 95 % intervals (friction's included).\n\n"
            "Goals: the medians of m, J, contact_to_com and z_ij within 1.5x the fit's, each\n"
            "quantity's 95 % intervals holding the truth 90-99 % of the time, at least 95 % of\n"
            "the robust runs done within 30 s simulated, every one on its floor.\n\n"
            "Exit status: 0 every goal met, 1 one not met, 2 bad scenario or arguments,\n"
            "130 interrupted."
        ),
    )
    _add_noise_options(parser)
    _add_floor_options(parser)
    parser.set_defaults(handler=cmd_noise)


def _add_sweep(benchmarks: argparse._SubParsersAction) -> None:
    parser = benchmarks.add_parser(
        "sweep",
        help="the noise benchmark over sigma_v: a table of medians, a plot",
        formatter_class=HelpFormatter,
        description=(
            "The noise benchmark at sigma_v 0, 1 mm/s, 3 mm/s, 1 cm/s and 3 cm/s (sigma_f =\n"
            "50 sigma_v; the drives ideal at 0): a markdown table of each estimator's median\n"
            "errors. It checks no goal.\n\n"
            "Exit status: 0 done, 2 bad scenario or arguments, 130 interrupted."
        ),
    )
    _add_noise_options(parser)
    _add_floor_options(parser)
    parser.add_argument(
        "--plot",
        metavar="DIR",
        help="write noise_sweep.png (error against sigma_v) into DIR, created if needed",
    )
    parser.set_defaults(handler=cmd_sweep)


# ------------------------------------------------------------------------------ friction
def cmd_friction(args: argparse.Namespace) -> int:
    """``heft bench friction``: the robust runs over the floor's friction, a table (and a
    plot)."""
    if args.plot is not None:
        check_writable(Path(args.plot))
    scenarios, label, settings = _noisy_runs(args)
    from simulator.bench.friction import (
        GOALS,
        figures,
        format_friction_sweep,
        plot_friction_sweep,
        run_friction_sweep,
    )
    from simulator.bench.noise import timed

    def on_level(mu: float, results) -> None:
        print(f"{PROG}: mu {100 * mu:g} % done", file=sys.stderr, flush=True)

    found, wall = timed(run_friction_sweep, scenarios, settings, on_level)
    print(format_friction_sweep(found, f"{label}, {settings.noise_text}"))
    print(f"\n({wall:.0f} s wall)")
    if args.plot is not None:
        print(f"plot: {plot_friction_sweep(found, Path(args.plot), label)}")
    return conclude(GOALS, figures(found))


def _add_friction(benchmarks: argparse._SubParsersAction) -> None:
    parser = benchmarks.add_parser(
        "friction",
        help="the noise benchmark over the floor's friction: a table, a plot",
        formatter_class=HelpFormatter,
        description=(
            "The robust estimators and the centralized fit on the noise benchmark's runs (1 cm/s,\n"
            "0.5 N, lagging drives of 2 % gain error) on floors of kinetic friction mu = 0, 0.5,\n"
            "1, 2, 3 and 5 % of the weight (breakaway 1.5 mu; 0: frictionless), over --seeds\n"
            "seeds of SCENARIO (its own supports: by default the paper's load on four casters)\n"
            "or of the generated scenarios (on their area): per mu a markdown table of the\n"
            "medians of m, J, contact_to_com and z_ij beside the fit's and their ratios, the\n"
            "friction estimates' (tau_c relative, mu absolute), how often the truth is inside\n"
            "the published 95 % intervals, runs done within 30 s and when, runs on their floor.\n\n"
            "Goals: m's median within 1.5x the fit's at every mu; no quantity's 95 % intervals\n"
            "holding the truth less than 90 % of the time at any mu.\n\n"
            "Exit status: 0 every goal met, 1 one not met, 2 bad scenario or arguments,\n"
            "130 interrupted."
        ),
    )
    _add_noise_options(parser, PAPER_FLOOR_SCENARIO, "the paper's load on four casters")
    parser.add_argument(
        "--plot",
        metavar="FILE",
        help="write the medians against mu into FILE (PNG), its folder created if needed",
    )
    parser.set_defaults(handler=cmd_friction)


# ------------------------------------------------------------------------------ changes
def cmd_changes(args: argparse.Namespace) -> int:
    """``heft bench changes``: a changed mass, a moved COM and no change, per seed."""
    scenario = load_scenario_argument(args.scenario)
    seeds, first = _seeds(args, NOISE_SEEDS)
    from simulator.bench.changes import GOALS, figures, format_change_report, run_change_bench
    from simulator.bench.noise import NoiseSettings

    def on_result(result) -> None:
        noticed = "-" if result.latency_s is None else f"{result.latency_s:.2f} s"
        print(
            f"{PROG}: seed {result.seed} {result.case}: restart after {noticed},"
            f" false alarms {result.false_alarms}",
            file=sys.stderr,
            flush=True,
        )

    settings = dataclasses.replace(NoiseSettings(), seeds=seeds, first_seed=first)
    results = run_change_bench(scenario, settings, on_result)
    print(format_change_report(results))
    return conclude(GOALS, figures(results))


def _add_changes(benchmarks: argparse._SubParsersAction) -> None:
    parser = benchmarks.add_parser(
        "changes",
        help="load changes under noise: noticed, re-estimated, no false alarm",
        formatter_class=HelpFormatter,
        description=(
            "Per seed of the noise benchmark's runs of SCENARIO (robust estimators): the mass\n"
            "grown by 20 % at 25 s, the COM moved by 10 cm at 25 s, and no change until 45 s:\n"
            "changes noticed (the team restarts), the delays, errors after re-estimation\n"
            "beside the centralized fit's, false alarms.\n\n"
            "Goals: every change noticed within 5 s, no false alarm, every run done and on\n"
            "its floor.\n\n"
            "Exit status: 0 every goal met, 1 one not met, 2 bad scenario or arguments,\n"
            "130 interrupted."
        ),
    )
    _scenario_argument(parser)
    _add_seed_options(parser)
    parser.set_defaults(handler=cmd_changes)


PARSERS: tuple[Callable[[argparse._SubParsersAction], None], ...] = (
    _add_accuracy,
    _add_generated,
    _add_zenoh,
    _add_noise,
    _add_sweep,
    _add_friction,
    _add_changes,
    calibrate.add_parser,
)
"""Each adds one benchmark's parser to ``heft bench``, in the order its help lists them."""
