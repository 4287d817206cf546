"""The dashboard's state, shared by its source (live feed or replay) and the web app.

:class:`Hub` holds the :class:`~dashboard.state.TeamState` behind a lock, knows what feeds it
(live, or a replay it can steer) and what time it is for that source, and can start over
(a new replay): each start is a new *epoch*, and a page seeing a new epoch reloads its charts.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

from agent.platform.protocol import (
    BridgeStatus,
    Command,
    Control,
    Estimates,
    LoadGeometry,
    PlantStatus,
    Share,
    Status,
    Truth,
)
from dashboard.quantities import DECLARATIONS
from dashboard.replay import Recorded, Recording, Replayer
from dashboard.state import CAPACITY, TeamState

DISPLAYED = (
    Estimates,
    Status,
    Share,
    Command,
    BridgeStatus,
    Truth,
    LoadGeometry,
    PlantStatus,
    Control,
)
"""What the page shows something of (a replay skips the measurements and the clock)."""
REPLAY_STEP_S = 0.5
"""Recorded seconds one step lets through (a replay's "step" button)."""


class Hub:
    """Thread-safe access to the team's state for one source and many pages."""

    def __init__(self, team: str, capacity: int = CAPACITY, recording: Path | None = None):
        self.team = team
        self.capacity = capacity
        self.lock = threading.Lock()
        self.state = TeamState(team, capacity=capacity)
        self.epoch = 1
        self.mode = "live"
        self.recording = recording
        """A recording the page may replay (live: the run's own, once it is over)."""
        self.replayer: Replayer | None = None

    # ------------------------------------------------------------------ sources
    def now(self) -> float:
        """The source's clock (s): the monotonic clock live, the recording's in a replay."""
        replayer = self.replayer
        return replayer.now() if replayer is not None else time.monotonic()

    def ingest_batch(self, batch) -> None:
        """A live feed's sink: ``(key, message, arrival (s), arrival (ns))`` tuples."""
        if self.mode != "live":
            return
        with self.lock:
            for _, message, arrived, _ in batch:
                self.state.ingest(message, arrived)

    def liveliness(self, robot: int, alive: bool, now: float) -> None:
        if self.mode != "live":
            return
        with self.lock:
            self.state.liveliness(robot, alive, now)

    def _replayed(self, recorded: Recorded, position: float) -> None:
        with self.lock:
            self.state.ingest(recorded.message, position)

    def replay(self, path: Path, speed: float = 1.0, paused: bool = False) -> Replayer:
        """Start over from ``path``: a new epoch, the live feed (if any) ignored from now on.
        :class:`~dashboard.replay.RecordingError` if it is not a team's recording."""
        recording = Recording(path)
        team = recording.header()
        self.stop_replay()
        replayer = Replayer(recording, self._replayed, speed=speed, paused=paused, kinds=DISPLAYED)
        with self.lock:
            self.team = team
            self.state = TeamState(team, capacity=self.capacity)
            self.epoch += 1
            self.recording = Path(path)
            self.replayer = replayer
            self.mode = "replay"
        replayer.start()
        return replayer

    def stop_replay(self) -> None:
        replayer, self.replayer = self.replayer, None
        if replayer is not None:
            replayer.stop()

    # ------------------------------------------------------------------ views
    def source(self) -> dict:
        """What feeds the page: live, or a replay and where it stands."""
        replayer = self.replayer
        info: dict = {
            "mode": self.mode,
            "epoch": self.epoch,
            "recording": None if self.recording is None else self.recording.name,
        }
        if replayer is not None:
            info.update(
                position_s=round(replayer.now(), 3),
                speed=replayer.speed,
                paused=replayer.paused,
                finished=replayer.finished.is_set(),
                cut=replayer.recording.cut,
            )
        return info

    def frame(self) -> dict:
        now = self.now()
        with self.lock:
            frame = self.state.frame(now)
        frame["epoch"] = self.epoch
        frame["source"] = self.source()
        frame["sent_ms"] = round(time.time() * 1000.0, 1)  # for latency measurements
        return frame

    def hello(self) -> dict:
        """What a page gets first: the estimated scalars it charts and tabulates
        (:data:`~dashboard.quantities.DECLARATIONS`), every chart's kept points and the
        scene."""
        now = self.now()
        with self.lock:
            series = self.state.all_series()
            scene = self.state.page_scene(now)
        return {
            "type": "hello",
            "epoch": self.epoch,
            "scalars": DECLARATIONS,
            "series": series,
            "scene": scene,
            "source": self.source(),
        }

    def snapshot(self) -> dict:
        now = self.now()
        with self.lock:
            scene = self.state.snapshot(now)
        scene["source"] = self.source()
        return scene

    def summary(self) -> dict | None:
        with self.lock:
            return self.state.final

    def version(self) -> tuple[int, int]:
        return self.epoch, self.state.version
