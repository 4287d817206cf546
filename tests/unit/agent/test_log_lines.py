"""An agent's own log lines for the team (agent/platform/log_lines.py): the records of INFO and
above that its loop's thread logs become LogLines with its tick, at a bounded rate (a storm
is cut to the bucket and one notice of what was dropped), and the agent's loop publishes them
through its port."""

from __future__ import annotations

import logging
import threading

from agent.node import AgentNode, AgentNodeConfig
from agent.platform.faults import FaultSettings, FaultyTransport
from agent.platform.log_lines import BURST, PER_S, LogLines
from agent.platform.process import RejectLog
from agent.platform.protocol import MAX_LOG_TEXT, LogLine, Status, decode, encode
from agent.platform.robot_io import InMemoryRobots
from agent.platform.transport import InMemoryTransport

LOG = logging.getLogger("test.log_lines")
LOG.propagate = False  # (a storm of records: for the handlers under test only)


class Clock:
    """A clock the test moves."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def handler(tick: int = 7, clock=None) -> LogLines:
    lines = LogLines(2, lambda: tick, clock=clock or Clock())
    LOG.addHandler(lines)
    LOG.setLevel(logging.DEBUG)
    return lines


def test_its_own_records_of_info_and_above_become_log_lines() -> None:
    lines = handler(tick=41)
    try:
        LOG.debug("robot 2: not for the team")
        LOG.info("robot 2: tick %d: phase %s", 41, "inertia")
        LOG.warning("robot 2: lost neighbour 3; halting the team")
        LOG.error("robot 2: an error\x1b[2J with an escape")
        LOG.critical("x" * 5000)
        elsewhere = threading.Thread(target=LOG.error, args=("another thread's",))
        elsewhere.start()
        elsewhere.join()
        taken = lines.take()
    finally:
        LOG.removeHandler(lines)
    assert taken[:3] == [
        LogLine(2, 41, "info", "robot 2: tick 41: phase inertia"),
        LogLine(2, 41, "warning", "robot 2: lost neighbour 3; halting the team"),
        LogLine(2, 41, "error", "robot 2: an error?[2J with an escape"),
    ]
    assert [line.level for line in taken] == ["info", "warning", "error", "critical"]
    assert len(taken[3].text) == MAX_LOG_TEXT and taken[3].text.endswith("…")
    for line in taken:  # every one is a message the team accepts
        assert decode(LogLine, encode(line)) == line
    assert lines.take() == []


def test_a_log_storm_is_cut_to_the_bucket_and_says_how_much_was_dropped() -> None:
    clock = Clock()
    lines = handler(clock=clock)
    try:
        for i in range(10_000):
            LOG.warning("robot 2: rejected measurement #%d", i)
        burst = lines.take()
        assert [line.text for line in burst] == [
            f"robot 2: rejected measurement #{i}" for i in range(BURST)
        ]
        clock.now += 1.0  # PER_S tokens, all taken by the storm: the notice waits
        for i in range(10_000, 20_000):
            LOG.warning("robot 2: rejected measurement #%d", i)
        then = lines.take()
        clock.now += 10.0
        notice = lines.take()
    finally:
        LOG.removeHandler(lines)
    assert [line.text for line in then] == [
        f"robot 2: rejected measurement #{i}" for i in range(10_000, 10_000 + int(PER_S))
    ]
    dropped = 20_000 - BURST - int(PER_S)
    text = f"robot 2: {dropped} log lines not published (more than 5 a second)"
    assert notice == [LogLine(2, 7, "warning", text)]
    assert lines.dropped == 0


def test_lines_not_taken_for_long_are_bounded_and_counted() -> None:
    clock = Clock()
    lines = handler(clock=clock)
    try:
        for i in range(3 * BURST):
            clock.now += 1.0
            LOG.info("robot 2: line %d", i)
    finally:
        LOG.removeHandler(lines)
    assert lines.dropped == 2 * BURST
    taken = lines.take()
    assert [line.text for line in taken[:BURST]] == [
        f"robot 2: line {i}" for i in range(2 * BURST, 3 * BURST)
    ]
    text = f"robot 2: {2 * BURST} log lines not published (more than 5 a second)"
    assert taken[BURST:] == [LogLine(2, 7, "warning", text)]


def test_an_agent_publishes_what_its_loop_logs(caplog) -> None:
    caplog.set_level(logging.INFO, logger="heft.agent")
    reports: list = []
    hub = InMemoryRobots({1: (2,), 2: (1,)}, RejectLog(LOG, "test"), reports.append)
    port = hub.agent_port(1)
    config = AgentNodeConfig(robot=1, n=2, neighbours=(2,))
    shares = FaultyTransport(InMemoryTransport(2, ((1, 2),)), FaultSettings())
    stop = threading.Event()
    stop.set()  # it comes up, says so and leaves
    handlers = list(logging.getLogger().handlers)
    assert AgentNode(config, port, shares, stop).run() == 0
    assert logging.getLogger().handlers == handlers
    status, line = reports
    assert isinstance(status, Status)
    assert line == LogLine(1, -1, "info", "robot 1: up (team heft, neighbours [2], lockstep clock)")
