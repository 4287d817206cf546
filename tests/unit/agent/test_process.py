"""A process's stop (agent/platform/process.py's :class:`StopSignals`), in this test's own
main thread: the first of SIGINT, SIGTERM or SIGHUP sets the event and is named, a signal
inside ``raising`` interrupts the main thread, and the handlers that were there come back.
(Taken by ``sigwait``, and taken by another thread: tests/integration/test_supervision.py.)"""

from __future__ import annotations

import os
import signal
import threading
import time

import pytest

from agent.platform.process import STOP_SIGNALS, StopEvent, StopSignals


def _handlers() -> list:
    return [signal.getsignal(sig) for sig in STOP_SIGNALS]


def test_the_first_stop_signal_sets_the_event_and_is_named() -> None:
    before = _handlers()
    with StopSignals().handle() as stop:
        assert isinstance(stop.event, StopEvent) and stop.received is None
        os.kill(os.getpid(), signal.SIGHUP)
        assert stop.event.wait(10)
        os.kill(os.getpid(), signal.SIGTERM)  # a second one: the first stays the one named
        assert stop.received == signal.SIGHUP
    assert _handlers() == before


def test_inside_raising_a_stop_signal_interrupts_the_main_thread() -> None:
    with StopSignals().handle() as stop:
        with pytest.raises(KeyboardInterrupt), stop.raising():
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):  # the handler runs at the next bytecode: well before 10 s
                time.sleep(0.01)
        assert stop.received == signal.SIGTERM
        with pytest.raises(KeyboardInterrupt), stop.raising():  # one came: at once
            pass
    assert stop.event.wait(10)


def test_outside_raising_a_stop_signal_only_asks() -> None:
    with StopSignals().handle() as stop:
        os.kill(os.getpid(), signal.SIGINT)  # not a KeyboardInterrupt here
        assert stop.event.wait(10) and stop.received == signal.SIGINT


class _NeverStarted:
    """A thread that never runs: the event's lock is never taken to set it."""

    def __init__(self, *args, **kwargs) -> None:
        pass

    def start(self) -> None:
        pass


def test_the_event_is_set_as_soon_as_the_handler_ran(monkeypatch) -> None:
    """Whoever asks after the handler ran sees the stop, before any thread sets the event: a
    run that finds its router gone because the same Ctrl-C stopped it was asked to stop, not
    left by its router."""
    monkeypatch.setattr("agent.platform.process.threading.Thread", _NeverStarted)
    with StopSignals().handle() as stop:
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(1000):  # the handler runs at the next bytecode
            if stop.received is not None:
                break
            time.sleep(0.01)
        assert stop.received == signal.SIGINT
        assert stop.event.is_set() and stop.event.wait() and stop.event.wait(0.01)
        assert not threading.Event.is_set(stop.event)  # nothing took the event's lock


def test_an_event_marked_wakes_a_waiter_at_its_next_poll() -> None:
    event = StopEvent()
    assert not event.is_set() and not event.wait(0.01)
    threading.Timer(0.05, event.mark).start()
    assert event.wait()  # no timeout: woken by its poll within SIGNAL_POLL_S
