"""The dashboard's benchmark, a subcommand of ``heft bench`` (entry point of the group
``heft.bench``)::

    heft bench dashboard

Building the parser imports nothing heavy (no FastAPI, Zenoh or Playwright): the handler
imports what it runs.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import tempfile
from pathlib import Path

from agent.platform.cli_helpers import HelpFormatter, UsageError


def register(benchmarks: argparse._SubParsersAction) -> None:
    """Add ``heft bench dashboard`` (entry point of the group ``heft.bench``)."""
    parser = benchmarks.add_parser(
        "dashboard",
        help="the dashboard: CPU, latency to 3 browsers, memory over a replay",
        formatter_class=HelpFormatter,
        description=(
            "The dashboard's benchmark: 16 fake agents publishing their estimates at 100 Hz\n"
            "through a Zenoh router into a heft dashboard with 3 headless Chromium pages for\n"
            "30 s (its CPU, publish-to-browser latency p50/p99, page redraw times), then its\n"
            "resident memory over a 10-minute synthetic recording replayed at 10x. Every\n"
            "process is on 127.0.0.1; it needs Playwright and /usr/bin/chromium.\n\n"
            "Goals: the dashboard's CPU below 25 % of one core, the latency's p99 below\n"
            "200 ms, the memory's growth after the first quarter of the replay below 10 %.\n\n"
            "Exit status: 0 every goal met, 1 one not met, 130 interrupted."
        ),
    )
    parser.set_defaults(handler=cmd_dashboard)


def cmd_dashboard(args: argparse.Namespace) -> int:
    """``heft bench dashboard``: 16 robots at 100 Hz, 3 browsers, then a 10x replay."""
    problem = missing_browser()
    if problem is not None:
        raise UsageError(f"bench dashboard needs {problem}")
    from agent.platform.goals import conclude
    from dashboard.bench.streaming import GOALS, BenchSettings, run

    with tempfile.TemporaryDirectory(prefix="heft-bench-") as folder:
        report = run(BenchSettings(), Path(folder))
    print("\n".join(report.lines()))
    return conclude(GOALS, report.figures())


def missing_browser() -> str | None:
    """What the benchmark's pages lack to run (``None``: nothing): Playwright, installed with
    the test extras (``pip install -e '.[test]'``, as ``make`` does), and Chromium at
    :data:`dashboard.bench.streaming.CHROMIUM`."""
    from dashboard.bench import streaming

    if importlib.util.find_spec("playwright") is None:
        return "Playwright: pip install -e '.[test]' (make does)"
    if not os.access(streaming.CHROMIUM, os.X_OK):
        return f"Chromium at {streaming.CHROMIUM}: apt-get install chromium"
    return None
