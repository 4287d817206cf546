"""The ``heft`` command line.

::

    heft run SCENARIO [--out results.json] [--plot DIR] [--quiet]
    heft scenario generate SEED [-o FILE]
    heft bench [SCENARIO] [--repeat N]

Exit status: 0 success (``run``: every robot converged), 1 ``run`` did not converge within the
scenario's ``run.max_time_s``, 2 bad input (a one-line ``heft: error: ...`` on stderr).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections import defaultdict
from collections.abc import Sequence
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from agent.protocol import CLOCKS
from heft.network_cli import add_commands as add_network_commands
from simulator.scenario import Scenario, ScenarioError, load_scenario, scenario_to_toml

if TYPE_CHECKING:
    from agent.agent import Agent
    from heft.inprocess import Progress, RunOutcome

PROG = "heft"
PROGRESS_EVERY_S = 5.0
"""Simulated seconds between two progress lines of ``heft run``."""


class UsageError(Exception):
    """Bad input the user can fix: reported as ``heft: error: <message>``, exit status 2."""


# ------------------------------------------------------------------------------ helpers
def _version() -> str:
    try:
        return metadata.version("heft-hil")
    except metadata.PackageNotFoundError:  # pragma: no cover - running from a bare checkout
        return "unknown"


def _load(path: str) -> Scenario:
    """The scenario at ``path``; a :class:`UsageError` naming the problem if it is invalid."""
    try:
        return load_scenario(path)
    except ScenarioError as err:
        raise UsageError(str(err)) from None


def _write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path``, creating its directory; a :class:`UsageError` on failure."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    except OSError as err:
        raise UsageError(f"{path}: cannot write ({err.strerror or err})") from None


def _check_writable(path: Path, directory: bool = False) -> None:
    """Fail before a run, not after it, when its output cannot be written."""
    folder = path if directory else path.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if not directory:
            with path.open("a", encoding="utf-8"):
                pass
    except OSError as err:
        raise UsageError(f"{path}: cannot write ({err.strerror or err})") from None
    if directory and not os.access(folder, os.W_OK):
        raise UsageError(f"{path}: cannot write (permission denied)")


def _team_phase(agents: Sequence[Agent]) -> str:
    """``'inertia'`` when every robot is in that phase, else e.g. ``'excite: 1,2; inertia: 3'``."""
    from agent.agent import PHASES

    robots: dict[str, list[int]] = defaultdict(list)
    for agent in agents:
        robots[PHASES[agent.phase]].append(agent.robot)
    if len(robots) == 1:
        return next(iter(robots))
    return "; ".join(f"{name}: {','.join(map(str, ids))}" for name, ids in robots.items())


def _progress_printer(started: float, stream: TextIO) -> Progress:
    """A :data:`heft.inprocess.Progress` callback printing one line per call to ``stream``."""

    def report(tick: int, time_s: float, agents: list[Agent]) -> None:
        if tick == 0:
            return
        wall = time.perf_counter() - started
        print(
            f"{PROG}: t = {time_s:6.1f} s simulated, phase {_team_phase(agents)},"
            f" {wall:.2f} s wall",
            file=stream,
            flush=True,
        )

    return report


# ------------------------------------------------------------------------------ heft run
def cmd_run(args: argparse.Namespace) -> int:
    """``heft run``: simulate a scenario, print the table, write JSON and plots."""
    from heft.inprocess import run_inprocess
    from heft.results import format_table, results_dict

    scenario = _load(args.scenario)
    faults = _faults(args, scenario)
    if args.out is not None:
        _check_writable(Path(args.out))
    if args.plot is not None:
        _check_writable(Path(args.plot), directory=True)
    progress = None
    if not args.quiet:
        print(f"{PROG}: running {scenario.name!r} ({scenario.n} robots)", file=sys.stderr)
        progress = _progress_printer(time.perf_counter(), sys.stderr)
    if args.transport == "zenoh":
        outcome = _run_zenoh(args, scenario, faults)
    else:
        every = max(1, round(PROGRESS_EVERY_S / scenario.period_s))
        transport = None
        if faults.active:
            from agent.faults import FaultyTransport
            from agent.transport import InMemoryTransport

            transport = FaultyTransport(InMemoryTransport(scenario.n, scenario.edges), faults)
        outcome = run_inprocess(
            scenario, transport=transport, progress=progress, progress_every=every
        )
    print(format_table(outcome))
    if args.out is not None:
        text = json.dumps(results_dict(outcome), indent=2, allow_nan=False) + "\n"
        _write_text(Path(args.out), text)
        print(f"wrote results to {args.out}")
    if args.plot is not None:
        for path in _write_plots(outcome, Path(args.plot)):
            print(f"wrote plot {path}")
    if not outcome.converged:
        lost = outcome.transport.get("lost")
        if outcome.transport.get("halted"):
            print(
                f"{PROG}: not converged: the team stopped because robot(s) {lost} were lost"
                " (n is fixed: estimates without a robot would be wrong)",
                file=sys.stderr,
            )
        else:
            print(
                f"{PROG}: not converged: the team did not finish every step within"
                f" run.max_time_s = {scenario.run.max_time_s:g} s of simulated time",
                file=sys.stderr,
            )
        return 1
    return 0


def _faults(args: argparse.Namespace, scenario: Scenario):
    from agent.faults import FaultSettings

    if not 0.0 <= args.drop < 1.0:
        raise UsageError(f"--drop: expected a probability in [0, 1), got {args.drop:g}")
    if not args.delay_ms >= 0.0:
        raise UsageError(f"--delay-ms: expected a number >= 0, got {args.delay_ms:g}")
    if args.delay_ms and args.transport != "zenoh":
        raise UsageError("--delay-ms needs --transport zenoh (in one process time is simulated)")
    return FaultSettings(drop=args.drop, delay_s=args.delay_ms / 1000.0, seed=scenario.run.seed)


def _run_zenoh(args: argparse.Namespace, scenario: Scenario, faults) -> RunOutcome:
    from heft.launcher import run_zenoh

    def report(time_s: float, phases: str) -> None:
        if not args.quiet:
            print(
                f"{PROG}: t = {time_s:6.1f} s simulated, phases so far: {phases}",
                file=sys.stderr,
                flush=True,
            )

    stream = sys.stderr if not args.quiet else open(os.devnull, "w")  # noqa: SIM115
    try:
        return run_zenoh(
            scenario, clock=args.clock, faults=faults, progress=report, log_stream=stream
        )
    finally:
        if stream is not sys.stderr:
            stream.close()


def _write_plots(outcome: RunOutcome, directory: Path) -> list[Path]:
    """Write the figures of ``outcome`` into ``directory``; a :class:`UsageError` on failure."""
    from heft.plots import write_plots

    try:
        return write_plots(outcome, directory)
    except OSError as err:
        raise UsageError(f"{directory}: cannot write the plots ({err.strerror or err})") from None


# ------------------------------------------------------------------------------ heft scenario
def cmd_generate(args: argparse.Namespace) -> int:
    """``heft scenario generate``: write the random scenario of a seed as TOML."""
    from simulator.generate import generate_scenario

    if args.seed < 0:
        raise UsageError(f"SEED must be a non-negative integer, got {args.seed}")
    text = scenario_to_toml(generate_scenario(args.seed))
    if args.output is None:
        sys.stdout.write(text)
    else:
        _write_text(Path(args.output), text)
        print(f"wrote scenario {args.output}", file=sys.stderr)
    return 0


# ------------------------------------------------------------------------------ heft bench
def cmd_bench(args: argparse.Namespace) -> int:
    """``heft bench``: run a scenario several times and report accuracy and speed."""
    from heft.benchmark import format_report, run_benchmark

    if args.generated is not None:
        return _bench_generated(args.generated)
    if args.transport == "zenoh":
        return _bench_zenoh(args.sizes)
    if args.repeat < 1:
        raise UsageError(f"--repeat must be at least 1, got {args.repeat}")
    scenario = _load(args.scenario)

    def on_run(k: int, outcome: RunOutcome) -> None:
        _say_run(f"run {k}/{args.repeat}", outcome)

    report = run_benchmark(scenario, args.repeat, source=args.scenario, on_run=on_run)
    print(format_report(report))
    return 0


def _say_run(label: str, outcome: RunOutcome) -> None:
    """One progress line on stderr per benchmark run."""
    state = "converged" if outcome.converged else "NOT converged"
    print(
        f"{PROG}: {label}: {state}, {outcome.sim_time_s:.2f} s simulated in"
        f" {outcome.wall_s:.2f} s wall",
        file=sys.stderr,
        flush=True,
    )


def _bench_zenoh(sizes: str) -> int:
    from heft.benchmark import format_zenoh_report, run_zenoh_benchmark

    try:
        counts = [int(s) for s in sizes.split(",")]
    except ValueError:
        raise UsageError(f"--sizes: expected numbers like 4,8,16, got {sizes!r}") from None
    for n in counts:
        if n < 3 or 32 % n:
            raise UsageError(f"--sizes: a ring team needs n >= 3 dividing 32, got {n}")

    print(format_zenoh_report(run_zenoh_benchmark(counts, _say_run)))
    return 0


def _bench_generated(count: int) -> int:
    from heft.benchmark import format_generated, run_generated

    if count < 1:
        raise UsageError(f"--generated must be at least 1, got {count}")

    def on_run(seed: int, outcome: RunOutcome) -> None:
        _say_run(f"seed {seed}, {outcome.scenario.n} robots", outcome)

    outcomes = run_generated(count, on_run)
    print(format_generated(outcomes))
    return 0 if all(o.converged for o in outcomes) else 1


# ------------------------------------------------------------------------------ the parser
class _Formatter(argparse.RawDescriptionHelpFormatter):
    """Keeps the descriptions' line breaks; a little wider help column."""

    def __init__(self, prog: str) -> None:
        super().__init__(prog, max_help_position=30)


def _add_run(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "run",
        help="simulate a scenario and print the estimates against the truth",
        formatter_class=_Formatter,
        description=(
            "Simulate SCENARIO: one agent per robot and a pymunk plant, until every robot has\n"
            "finished the paper's seven steps or the scenario's run.max_time_s. By default in\n"
            "this process over the in-memory transport; with --transport zenoh as separate\n"
            "processes (a Zenoh router, the plant, one agent per robot) on 127.0.0.1. Prints\n"
            "a table of every robot's estimates (m, J, contact-to-COM offset) and their errors\n"
            "against the ground truth, and when each step started and ended.\n\n"
            "Exit status: 0 converged, 1 not converged (out of time, or a robot was lost),\n"
            "2 bad scenario or arguments, 130 interrupted."
        ),
        epilog=(
            "examples:\n"
            "  heft run simulator/scenarios/paper.toml --out results.json --plot plots\n"
            "  heft run simulator/scenarios/paper.toml --transport zenoh --drop 0.1"
        ),
    )
    parser.add_argument("scenario", metavar="SCENARIO", help="scenario TOML file")
    parser.add_argument(
        "--transport",
        choices=("inprocess", "zenoh"),
        default="inprocess",
        help="inprocess: one process; zenoh: one process per robot (default: inprocess)",
    )
    parser.add_argument(
        "--clock",
        choices=CLOCKS,
        default="lockstep",
        help="with zenoh: lockstep (deterministic, faster than real time) or realtime"
        " (the wall clock) (default: lockstep)",
    )
    parser.add_argument(
        "--drop",
        type=float,
        default=0.0,
        metavar="P",
        help="probability that a message between agents is lost (default: 0)",
    )
    parser.add_argument(
        "--delay-ms",
        type=float,
        default=0.0,
        metavar="MS",
        help="with zenoh: delay added to every message between agents (default: 0)",
    )
    _add_output_options(parser)
    parser.set_defaults(handler=cmd_run)


def _add_output_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--out",
        metavar="FILE",
        help="write the results as JSON (SI units, world frame) to FILE (default: none)",
    )
    parser.add_argument(
        "--plot",
        metavar="DIR",
        help="write the paper's Figs. 4-6 as PNGs into DIR, created if needed (default: none)",
    )
    parser.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        help=f"no progress lines on stderr (default: one every {PROGRESS_EVERY_S:g} simulated s)",
    )


def _add_scenario(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "scenario",
        help="make scenario files",
        formatter_class=_Formatter,
        description="Work with scenario files.",
    )
    sub = parser.add_subparsers(dest="scenario_command", metavar="COMMAND", required=True)
    generate = sub.add_parser(
        "generate",
        help="write a random scenario for a seed",
        formatter_class=_Formatter,
        description=(
            "Write the random scenario of SEED as TOML: 3-8 robots, a line, ring, star or\n"
            "random graph (seed % 4), a convex or concave load (seed // 4 % 2), random mass,\n"
            "moment, COM, contacts and pose. The same seed always gives the same scenario."
        ),
        epilog="example: heft scenario generate 7 -o load7.toml && heft run load7.toml",
    )
    generate.add_argument("seed", metavar="SEED", type=int, help="non-negative integer seed")
    generate.add_argument(
        "-o", "--output", metavar="FILE", help="write to FILE (default: standard output)"
    )
    generate.set_defaults(handler=cmd_generate)


def _add_bench(commands: argparse._SubParsersAction) -> None:
    from heft.benchmark import DEFAULT_REPEAT, PAPER_SCENARIO

    parser = commands.add_parser(
        "bench",
        help="accuracy, step durations and speed of repeated runs",
        formatter_class=_Formatter,
        description=(
            "Run SCENARIO in this process N times and print the worst final errors (mass %,\n"
            "J %, contact-to-COM and z_ij in mm), the simulated time each paper step took,\n"
            "how many times faster than real time the runs went (median, min, max) and the\n"
            "peak resident memory."
        ),
    )
    parser.add_argument(
        "scenario",
        metavar="SCENARIO",
        nargs="?",
        default=str(PAPER_SCENARIO),
        help="scenario TOML file (default: the paper's, simulator/scenarios/paper.toml)",
    )
    parser.add_argument(
        "-n",
        "--repeat",
        metavar="N",
        type=int,
        default=DEFAULT_REPEAT,
        help=f"number of runs (default: {DEFAULT_REPEAT})",
    )
    parser.add_argument(
        "--transport",
        choices=("inprocess", "zenoh"),
        default="inprocess",
        help="zenoh: instead, one process per robot: lockstep speed of ring teams (--sizes),"
        " then the paper's scenario in real time: command latency p50/p99, CPU per agent",
    )
    parser.add_argument(
        "--sizes",
        default="4,8,16",
        metavar="N,N,...",
        help="with --transport zenoh: ring team sizes (default: 4,8,16)",
    )
    parser.add_argument(
        "--generated",
        metavar="N",
        type=int,
        help="instead: run the generated scenarios of seeds 0..N-1 once each and print the"
        " median and worst errors and durations (generality)",
    )
    parser.set_defaults(handler=cmd_bench)


def build_parser() -> argparse.ArgumentParser:
    """The ``heft`` argument parser with its subcommands."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        formatter_class=_Formatter,
        description=(
            "Distributed estimation of an unknown load's mass, moment of inertia and centre\n"
            "of mass by a team of pushing robots (Franchi, Petitti, Rizzo, CDC 2014)."
        ),
        epilog="Run 'heft COMMAND --help' for a command's options.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")
    _add_run(commands)
    _add_scenario(commands)
    _add_bench(commands)
    add_network_commands(commands, _Formatter, _add_output_options)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``heft``; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "handler", None) is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        return args.handler(args)
    except UsageError as err:
        print(f"{PROG}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
