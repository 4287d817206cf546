"""What ``heft run`` and ``heft demo`` add to a run over Zenoh: its recording and the dashboard.

:class:`RunCompanion` is used in three moments of a run:

1. before it (:meth:`RunCompanion.open`): the dashboard is served (and, if asked, the team live
   to Foxglove on its ``/foxglove`` route), and its URLs printed, before any process starts;
2. once the run's router is up, before the plant and the agents start
   (:meth:`RunCompanion.on_ready`, given the router's endpoint and the team's name): the
   recorder and the dashboard (with Foxglove's live server) subscribe, so nothing of the run
   is missed;
3. after it (:meth:`RunCompanion.run_over`): the recording is closed (summary written) and
   offered to the page for replay; the page keeps what it showed.
"""

from __future__ import annotations

from datetime import datetime
from pathlib import Path
from typing import TextIO

from agent.platform.zenoh_session import ZenohSettings
from dashboard.display import DEFAULT_PORT, Display, TeamRecording

RECORDINGS = Path("out") / "recordings"
"""Where runs are recorded unless told otherwise."""


def default_recording(name: str, folder: Path = RECORDINGS) -> Path:
    """``out/recordings/<scenario>-<date>-<time>.mcap``."""
    return folder / f"{name}-{datetime.now().strftime('%Y%m%d-%H%M%S')}.mcap"


class RunCompanion:
    """A run's recording (``record``: its file, or None) and dashboard (``dashboard``)."""

    def __init__(self, record: Path | None, display: Display | None):
        self.record = record
        self.display = display
        self.recording: TeamRecording | None = None

    @classmethod
    def open(
        cls,
        record: Path | None,
        dashboard: bool,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        token: str | None = None,
        stream: TextIO | None = None,
        foxglove: bool = False,
    ) -> RunCompanion:
        """Serve the dashboard (if ``dashboard``) and print ``dashboard: URL`` to ``stream``;
        with ``foxglove`` the dashboard serves the run live to Foxglove too (as ``heft dashboard
        --foxglove``: behind the same token) and prints ``foxglove: URL`` next.
        :class:`~dashboard.server.ServeError` if its port is taken. The load's outline comes
        from the run's plant, as the rest of its messages."""
        display = None
        if dashboard:
            display = Display.open(None, host, port, token, recording=record, foxglove=foxglove)
            if stream is not None:
                print(f"dashboard: {display.url}", file=stream, flush=True)
                if display.foxglove_url is not None:
                    print(f"foxglove: {display.foxglove_url}", file=stream, flush=True)
        return cls(record, display)

    def on_ready(self, router: str, team: str) -> None:
        """The run's router is up at ``router``, its team is ``team``: subscribe (call before
        the plant and the agents start). :class:`~agent.platform.zenoh_session.SessionError` if the
        router cannot be reached."""
        settings = ZenohSettings(mode="client", connect=(router,))
        if self.record is not None:  # one subscription for both: each message decoded once
            self.record.parent.mkdir(parents=True, exist_ok=True)
            self.recording = TeamRecording.open(self.record, team, settings, self.display)
        elif self.display is not None:
            self.display.watch(settings, team)

    def run_over(self) -> None:
        """The run ended: stop listening, close the recording, offer it for replay."""
        if self.display is not None and self.display.feed is not None:
            self.display.feed.close()
            self.display.feed = None
        if self.recording is not None:
            self.recording.close()
            if self.display is not None:
                self.display.hub.recording = self.record

    def serve_until(self, stop) -> None:
        """Keep the dashboard up until ``stop`` (a ``threading.Event``) is set."""
        if self.display is not None:
            stop.wait()

    def close(self) -> None:
        self.run_over()
        if self.display is not None:
            self.display.close()
            self.display = None
