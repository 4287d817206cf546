"""The launcher's collector (simulator/launcher.py) fed by hand: the final instant of a run over
Zenoh, whatever the order in which its messages arrive."""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

from agent.platform.protocol import Estimates, Keys, Phase, Truth, encode
from simulator import launcher
from simulator.lockstep import INTERRUPTED, MASS_NOT_DETERMINED, Verdict
from simulator.scenario import load_scenario
from tests.helpers.fakes import FakeFifo
from tests.helpers.paths import PAPER


class _Subscriptions:
    """Just enough of a Zenoh session for a :class:`launcher.Collector` fed by hand:
    :meth:`feed` queues a message on the subscription of its key."""

    def __init__(self) -> None:
        self.fifos: dict[str, FakeFifo] = {}

    def declare_subscriber(self, key, handler):
        return self.fifos.setdefault(key, FakeFifo())

    def feed(self, key: str, payload: bytes) -> None:
        self.fifos[key](SimpleNamespace(payload=SimpleNamespace(to_bytes=lambda: payload)))


def _truth(tick: int) -> Truth:
    return Truth(
        tick=tick,
        time_s=tick * 0.01,
        com_position=(0.0, 0.0),
        angle=0.0,
        com_velocity=(0.0, 0.0),
        omega=0.0,
        contacts=((1.0, 0.0), (-1.0, 0.0)),
        contact_velocities=((0.0, 0.0), (0.0, 0.0)),
        contact_to_com=((-1.0, 0.0), (1.0, 0.0)),
        mass=5.0,
        moment=2.0,
    )


def test_the_final_instant_is_the_first_at_which_every_robot_is_done(monkeypatch) -> None:
    """Messages from different processes cross: the instant after the final one may be complete
    first. The collector still ends on the final instant, the one the in-process run ends on;
    if the final instant never completes, it ends on the later one after a grace."""
    keys = Keys("t")
    key = {Truth: keys.truth(), Estimates: keys.all_estimates()}
    for final_arrives in (True, False):
        subscriptions = _Subscriptions()
        collector = launcher.Collector(subscriptions, keys, 2, record_every=5)
        # Robot 1 done since 98, robot 2 since 100: the final instant is 100.
        messages = [(Truth, _truth(101))]
        messages += [
            (Estimates, Estimates(r, 101, Phase.DONE, since)) for r, since in [(1, 98), (2, 100)]
        ]
        messages += [
            (Estimates, Estimates(r, 100, Phase.DONE, since)) for r, since in [(1, 98), (2, 100)]
        ]
        for kind, message in messages:
            subscriptions.feed(key[kind], encode(message))
        collector.drain(0.0)
        assert collector.final is not None and collector.final.truth.tick == 101
        assert not collector.finished()
        if final_arrives:
            subscriptions.feed(key[Truth], encode(_truth(100)))
            collector.drain(0.0)
            assert collector.finished() and collector.final.truth.tick == 100
        else:
            monkeypatch.setattr(launcher, "FINAL_GRACE_S", 0.0)
            monkeypatch.setattr(launcher, "FINAL_GRACE_TICKS", 0)  # not this test's pace
            assert collector.finished() and collector.final.truth.tick == 101
            monkeypatch.undo()


class _StoppedByTheSameSignal:
    """A collector during whose drain Ctrl-C reached the process group: the launcher's stop is
    set and the router, which took the same SIGINT, has exited."""

    latest_tick = 100
    advanced_at = None

    def __init__(self, stop, router) -> None:
        self.stop, self.router = stop, router

    def finished(self) -> bool:
        return False

    def drain(self, timeout: float) -> None:
        self.stop.set()
        self.router.code = 0


class _Process:
    def __init__(self) -> None:
        self.code = None

    def poll(self):
        return self.code


def test_a_ctrl_c_that_also_stopped_the_router_is_an_interrupted_run() -> None:
    """Asked to stop is judged before the processes: the router gone after the same SIGINT is
    not a lost router."""
    stop = threading.Event()
    router, plant = SimpleNamespace(process=_Process()), SimpleNamespace(process=_Process())
    collector = _StoppedByTheSameSignal(stop, router.process)
    scenario = load_scenario(PAPER)
    watch = launcher._Watch(collector, router, plant, [], scenario)
    verdict = watch.run(stop, None, 1.0, time.perf_counter() + 60)
    assert verdict == Verdict(INTERRUPTED, "asked to stop")
    stop.clear()  # not asked to stop: the router gone is a lost router
    router.process.code = None
    collector.stop = threading.Event()
    assert watch.run(stop, None, 1.0, time.perf_counter() + 60).reason == launcher.ROUTER_LOST


def test_a_team_done_without_a_mass_is_not_converged() -> None:
    """The run over Zenoh judges its final instant as the in-process run does: a team whose
    robots are done while one publishes no mass ends with the verdict "mass not determined"
    (:func:`~simulator.lockstep.mass_verdict`), not as converged."""
    keys = Keys("t")
    scenario = load_scenario(PAPER)
    for masses, reason in (((5.1, 4.9), ""), ((5.1, None), MASS_NOT_DETERMINED)):
        subscriptions = _Subscriptions()
        collector = launcher.Collector(subscriptions, keys, 2, record_every=5)
        subscriptions.feed(keys.truth(), encode(_truth(100)))
        for robot, mass in enumerate(masses, 1):
            done = Estimates(robot, 100, Phase.DONE, 100, mass=mass)
            subscriptions.feed(keys.all_estimates(), encode(done))
        collector.drain(0.0)
        assert collector.finished()
        outcome = launcher.run_outcome(scenario, collector, Verdict(), time.perf_counter(), {})
        assert outcome.reason == reason and outcome.converged == (not reason)
        if reason:
            assert "robot(s) [2]" in outcome.detail and "t = 1.00 s" in outcome.detail
