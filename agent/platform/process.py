"""What every long-lived process of the project does the same way: stop on a signal, hand what
its network threads receive to its main thread, and count and log the messages it had to
reject without flooding its log."""

from __future__ import annotations

import logging
import queue
import signal
import threading
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
SIGNAL_POLL_S = 0.5
"""How often a :class:`StopEvent`'s wait without a timeout wakes, so that the main thread runs
a signal's handler."""


class StopEvent(threading.Event):
    """An event whose wait without a timeout wakes every :data:`SIGNAL_POLL_S`, and that a
    signal's handler can mark set at once (:meth:`mark`).

    Python runs a signal's handler in the main thread only, at its next bytecode; a signal the
    kernel hands to another thread (one of Zenoh's, the log relay's) only marks it pending, and
    a main thread blocked in a wait with no timeout may never get there. Measured: ``heft
    router`` (``stop.wait()``) was still running 8 s after SIGTERM in 3 of 32 runs; waking
    every 0.5 s, in none of 30."""

    def __init__(self) -> None:
        super().__init__()
        self._marked = False

    def mark(self) -> None:
        """Set, as far as :meth:`is_set` and :meth:`wait` tell, without taking the event's lock
        (which the thread running a signal's handler may hold); waiters blocked in
        :meth:`wait` wake once :meth:`set` is called too, or at their next poll."""
        self._marked = True

    def is_set(self) -> bool:
        return self._marked or super().is_set()

    def wait(self, timeout: float | None = None) -> bool:
        if self._marked:
            return True
        if timeout is not None:
            return super().wait(timeout) or self._marked
        while not super().wait(SIGNAL_POLL_S):
            if self._marked:
                return True
        return True


class StopSignals:
    """SIGINT, SIGTERM and SIGHUP, each a request to stop, alike: the first one sets
    :attr:`event` (a :class:`StopEvent`) and is :attr:`received`. Every process's stop is one
    of these, taken one of two ways:

    - :meth:`handle` (from the main thread): a Python handler. It runs in the main thread
      between two bytecodes, possibly while that thread holds the event's own lock (inside
      ``wait`` or ``set``); setting the event there could deadlock, so the handler only marks
      it (:meth:`StopEvent.mark`: whoever asks the event sees it set at once, before anything
      the same signal did elsewhere, such as a child process that stopped on it) and a
      short-lived thread sets it, waking its waiters. Inside :meth:`raising` the handler also
      raises ``KeyboardInterrupt`` where the main thread is, for work that does not look at
      the event (a simulation loop, plots, a child's wait).
    - :meth:`take`: no Python handler. The signals are blocked in the calling thread (call it
      from the main thread before any other thread starts, so that every thread inherits the
      mask) and a thread of its own takes them with ``sigwait``. The AGV bridge uses it:
      measured in a bridge under User-Mode Linux, the handler left the process stuck in a
      0.01 s queue wait after SIGTERM about 2 times in 3.

    Used as a context manager (``with StopSignals().handle() as stop:``), the handlers that were
    there before :meth:`handle` are put back on leaving; otherwise they stay for the process's
    life."""

    def __init__(self) -> None:
        self.event = StopEvent()
        self.received: signal.Signals | None = None
        """The first stop signal, once one came."""
        self._raising = False
        self._previous: dict = {}

    def handle(self) -> StopSignals:
        """Take the signals with a Python handler (from the main thread; elsewhere, where
        Python allows no handler, the signals keep theirs)."""
        if threading.current_thread() is threading.main_thread():
            for sig in STOP_SIGNALS:
                self._previous.setdefault(sig, signal.signal(sig, self._handler))
        return self

    def take(self) -> StopSignals:
        """Take the signals with ``sigwait`` on a thread of its own (see the class docstring)."""
        signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)

        def wait_for_one() -> None:
            self._stop(signal.Signals(signal.sigwait(STOP_SIGNALS)))

        threading.Thread(target=wait_for_one, name="stop-signals", daemon=True).start()
        return self

    def _handler(self, signum: int, _frame: object) -> None:
        # Signals come in bursts, and a handler can run again inside itself: nothing here
        # takes a lock.
        if self.received is None:
            self.received = signal.Signals(signum)
        self.event.mark()
        threading.Thread(target=self.event.set, name="stop-signal", daemon=True).start()
        if self._raising:
            raise KeyboardInterrupt

    def _stop(self, sig: signal.Signals) -> None:
        if self.received is None:
            self.received = sig
        self.event.set()

    @contextmanager
    def raising(self) -> Iterator[None]:
        """Inside this block a stop signal raises ``KeyboardInterrupt`` in the main thread
        (at once if one came already)."""
        self._raising = True
        try:
            if self.received is not None:
                raise KeyboardInterrupt
            yield
        finally:
            self._raising = False

    def __enter__(self) -> StopSignals:
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()


def in_user_mode_linux(cpuinfo: str | None = None) -> bool:
    """Whether this kernel is User-Mode Linux (its ``/proc/cpuinfo``, or ``cpuinfo``, says so):
    one CPU for every process, and every system call about 100 µs (``heft vcan`` runs there
    where the machine's kernel has no SocketCAN)."""
    if cpuinfo is None:
        try:
            with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as file:
                cpuinfo = file.read()
        except OSError:
            return False
    return "User Mode Linux" in cpuinfo


class RejectLog:
    """Counts rejected messages by what they were (e.g. ``"measurement"``) and why (e.g.
    ``"undecodable"``, ``"tick out of window"``), and logs them without flooding the log: the
    first ``first`` of each kind, then one in ``every``."""

    def __init__(self, log: logging.Logger, who: str, first: int = 10, every: int = 1000):
        self.log = log
        self.who = who
        self.first = first
        self.every = every
        self.counts: Counter[str] = Counter()
        """Rejections by what was rejected."""
        self.reasons: Counter[tuple[str, str]] = Counter()
        """Rejections by what and why."""

    def __call__(self, what: str, reason: object, why: str = "undecodable") -> None:
        self.counts[what] += 1
        self.reasons[what, why] += 1
        count = self.counts[what]
        if count <= self.first or count % self.every == 0:
            self.log.warning("%s: rejected %s #%d (%s): %s", self.who, what, count, why, reason)

    @property
    def total(self) -> int:
        return sum(self.counts.values())


class EventQueue:
    """Where a process's Zenoh callbacks leave what they receive, for its main thread.

    Callbacks run on Zenoh's threads and must stay tiny (a busy thread holding the GIL delays
    them by milliseconds): they only :meth:`put`; the main thread :meth:`drain`\\ s.
    """

    def __init__(self) -> None:
        self._queue: queue.SimpleQueue = queue.SimpleQueue()

    def put(self, event) -> None:
        self._queue.put(event)

    def drain(self, handle, timeout: float | None) -> None:
        """Wait up to ``timeout`` s for an event, then ``handle`` it and the others queued by
        then; not those that arrive meanwhile, so that a flood (a bus at its full rate, a
        machine too slow to keep up) never keeps the caller from its own duties (a watchdog,
        a tick) for longer than one batch."""
        try:
            handle(self._queue.get(timeout=timeout))
            for _ in range(self._queue.qsize()):
                handle(self._queue.get_nowait())
        except queue.Empty:
            pass
