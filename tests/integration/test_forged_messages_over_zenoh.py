"""No message can crash, stall or hijack a run over Zenoh: a second client on the run's router
forges thousands of well-encoded, adversarial messages on every key of the team while the
paper's scenario runs in real time, and the run converges within the usual bounds, every
forgery counted. (The same messages on an in-process bus: tests/unit/agent/test_hardening.py.)"""

from __future__ import annotations

import io
import random
import threading
import time
from collections import defaultdict

import pytest

from agent.platform.protocol import Keys
from agent.platform.zenoh_session import ZenohSettings, open_session
from simulator import launcher
from tests.helpers.accuracy import assert_within
from tests.helpers.forged import KEYS, forged_messages
from tests.helpers.paths import paper_at_half_pace


@pytest.mark.slow
def test_a_realtime_run_over_zenoh_shrugs_off_forged_messages(monkeypatch) -> None:
    """A second Zenoh client on the run's router forges messages on every key of the team —
    thousands on each, as in the probes that once crashed every agent — while the paper's
    scenario runs on the wall clock, at half pace (:func:`~tests.helpers.paths.
    paper_at_half_pace`): the run converges within the usual bounds."""
    port = launcher.free_port()
    monkeypatch.setattr(launcher, "free_port", lambda: port)
    scenario = paper_at_half_pace()
    keys = Keys(launcher._team_name(scenario))
    assert keys.team == "paper"  # the scenario's name, as a deployed team's
    stop = threading.Event()
    sent = defaultdict(int)

    def forge() -> None:
        settings = ZenohSettings(mode="client", connect=(f"tcp/127.0.0.1:{port}",))
        rng = random.Random(3)
        with open_session(settings) as session:
            publishers = {}
            while not stop.is_set():
                for key, payload in forged_messages(rng, scenario.n, 0):
                    key = key.replace(KEYS.root, keys.root)
                    if key not in publishers:
                        publishers[key] = session.declare_publisher(key)
                    publishers[key].put(payload)
                    sent[key.rsplit("/", 2)[-1]] += 1
                time.sleep(0.002)

    forger = threading.Thread(target=forge, daemon=True)
    forger.start()
    try:
        outcome = launcher.run_zenoh(scenario, clock="realtime", log_stream=io.StringIO())
    finally:
        stop.set()
        forger.join(timeout=10)
    assert_within(outcome, rel=0.005, metres=0.005)
    print("forged messages by key:", dict(sent))
    assert min(sent.values()) >= 2000, dict(sent)
    # The rejections reach the results: the launcher's by kind, and each agent's.
    rejections = outcome.transport["rejections"]
    assert rejections["launcher"]["Estimates"] > 0 and rejections["launcher"]["Truth"] > 0
    assert all(r["decode_errors"] > 0 for r in rejections["robots"].values()), rejections
