"""``python -m tests.helpers.stall_monitor OUT``: how long the host stalls this machine, for
the hardware-in-the-loop tests' stop timings (:class:`tests.helpers.hil.DriverRig`).

It wakes every :data:`PERIOD_S` at a real-time priority above the bridge's, where it may
(root: in ``heft vcan``'s User-Mode Linux guest), and appends each wake-up later than
:data:`LATE_S` to ``OUT`` as a line ``<wall clock at waking> <lateness>`` (seconds, the wall
clock being that of SocketCAN's kernel timestamps). At that priority nothing in the guest but
its kernel keeps it from waking on time, so a late wake-up is the host stalling the guest:
every process in it, the bridge included, stood still that long. Ends on SIGTERM."""

from __future__ import annotations

import os
import signal
import sys
import time

PERIOD_S = 0.005
LATE_S = 0.001
PRIORITY = 60
"""SCHED_FIFO priority: above the bridge's under test (50)."""


def main(out: str) -> None:
    stopping = []
    signal.signal(signal.SIGTERM, lambda *_: stopping.append(True))
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(PRIORITY))
    except (PermissionError, AttributeError):  # not root: still a measure, a coarser one
        pass
    with open(out, "a", buffering=1) as log:
        while not stopping:
            slept = time.monotonic()
            time.sleep(PERIOD_S)
            late = time.monotonic() - slept - PERIOD_S
            if late > LATE_S:
                log.write(f"{time.time():.6f} {late:.6f}\n")


if __name__ == "__main__":
    main(sys.argv[1])
