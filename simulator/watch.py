"""``heft watch SCENARIO --team T``: follow a team whose processes run elsewhere.

On a bench of several hosts (or robots with the simulated plant standing in for their
AGVs), the router, the plant and each robot's agent are started by their own hosts' service
managers, not by a launcher. The watcher is the operator's side of such a run: it joins the
team's network as any display does (with the operator's identity where the network is
secured), follows what the robots and the plant say through the launcher's
:class:`~simulator.launcher.Collector`, and ends with the same outcome as ``heft run``: the
table of every robot's estimates against the truth, and the results JSON.

A halted team is not the end of a run here: robots come back (a link up again, an agent
restarted by its unit), and the team begins again (:mod:`agent.algorithm.coordination`). The watcher
gives it ``rejoin_s`` to do so. Verdicts (``reason``):

- the team done → converged (``""``);
- the team halted and not begun again within ``rejoin_s`` → ``robot(s) [i, ...] lost``;
- nothing heard of the team within ``start_timeout_s`` → ``agents did not come up``;
- no new truth from the plant for ``stall_s`` once it started → ``stalled``;
- the plant past the scenario's ``run.max_time_s`` → ``out of simulated time (…)``;
- asked to stop → ``interrupted``.

With ``stop_when_done`` it then tells every process of the team to stop (the ``control`` key:
only the operator's identity may, on a secured network).
"""

from __future__ import annotations

import threading
import time
from typing import TYPE_CHECKING

from agent.platform.protocol import Control, Keys, encode
from agent.platform.zenoh_session import ZenohSettings, open_session

if TYPE_CHECKING:  # (the command line reads this module's defaults: it stays light)
    from simulator.inprocess import RunOutcome
    from simulator.launcher import Collector, Progress
    from simulator.lockstep import Verdict
    from simulator.scenario import Scenario

START_TIMEOUT_S = 60.0
"""How long the watcher waits for the plant's first truth."""
STALL_S = 15.0
"""Once the plant has started: no new truth for this long ends the watch."""
REJOIN_S = 30.0
"""How long a halted team is given to begin again, by default."""


def watch_team(
    scenario: Scenario,
    team: str,
    settings: ZenohSettings,
    *,
    rejoin_s: float = REJOIN_S,
    start_timeout_s: float = START_TIMEOUT_S,
    stall_s: float = STALL_S,
    stop_when_done: bool = False,
    record_every: int = 5,
    progress: Progress | None = None,
    progress_every_s: float = 5.0,
    stop: threading.Event | None = None,
) -> RunOutcome:
    """Follow ``team`` (running ``scenario``) until its run is over (see the module
    docstring); :class:`~simulator.launcher.RunFailed` if no instant of every robot's
    estimates with the truth was heard."""
    from simulator.launcher import Collector, run_outcome

    stop = stop or threading.Event()
    keys = Keys(team)
    started = time.perf_counter()
    with open_session(settings) as session:
        collector = Collector(
            session, keys, scenario.n, record_every, scenario.end_tick, rejoin_s=rejoin_s
        )
        try:
            verdict = _follow(
                collector, scenario, stop, start_timeout_s, stall_s, progress, progress_every_s
            )
            collector.conclude()
            if stop_when_done:
                session.put(keys.control(), encode(Control("stop")))
            collector.drain(0.2)
        finally:
            collector.close()
    return run_outcome(scenario, collector, verdict, started, {}, heard="heard")


def _follow(
    collector: Collector,
    scenario: Scenario,
    stop: threading.Event,
    start_timeout_s: float,
    stall_s: float,
    progress: Progress | None,
    every_s: float,
) -> Verdict:
    """Drain the collector until the run is over; the verdict."""
    from simulator.launcher import AGENTS_NOT_UP, STALLED
    from simulator.lockstep import INTERRUPTED, RunEnd, Verdict, halted

    began = time.perf_counter()
    end = RunEnd.of(scenario)
    next_report = every_s
    while not collector.finished():
        if stop.is_set():
            return Verdict(INTERRUPTED, "asked to stop")
        collector.drain(0.05)
        now = time.perf_counter()
        t = collector.latest_tick * scenario.period_s
        if progress is not None and t >= next_report:
            phases = sorted(collector.phase_ticks, key=collector.phase_ticks.get)
            progress(t, ", ".join(phases))
            next_report += every_s
        if collector.first_truth_at is None:
            if now - began > start_timeout_s:
                return Verdict(
                    AGENTS_NOT_UP, f"nothing heard of the plant within {start_timeout_s:g} s"
                )
            continue
        if now - (collector.advanced_at or now) > stall_s:
            return Verdict(
                STALLED, f"no new truth from the plant for {stall_s:g} s after t = {t:.2f} s"
            )
        if end.out_of_time(collector.latest_tick) and collector.done_instant is None:
            return end.out_of_time_verdict()
    if collector.halted:
        detail = (
            f"the team halted at t = {collector.halted_tick * scenario.period_s:.2f} s and did"
            f" not begin again within {collector.rejoin_s:g} s"
        )
        return halted(collector.lost, detail)
    return Verdict()
