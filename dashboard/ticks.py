"""The window of ticks a display takes a team's messages in (:class:`TickWindow`): the page's
state (:mod:`dashboard.state`) refuses a message from beyond it, and a recording's clock and
Foxglove's scene (:mod:`dashboard.timeline`, :mod:`dashboard.topics`) record it without
learning from it. A tick far ahead of the team's is a forged message or a robot gone wrong."""

from __future__ import annotations

from agent.platform.protocol import BridgeStatus

TICK_SLACK = 1000
"""How far ahead of the newest tick heard a message's tick may be (as the launcher allows)."""


class TickWindow:
    """The newest tick heard (:attr:`latest`, -1 before any) and the ticks within
    :data:`TICK_SLACK` of it."""

    def __init__(self) -> None:
        self.latest = -1

    def admits(self, message: object) -> bool:
        """Whether ``message``'s tick, if it has one, is within the window (any is, before the
        first)."""
        tick = getattr(message, "tick", None)
        return tick is None or self.latest < 0 or tick <= self.latest + TICK_SLACK

    def hear(self, message: object) -> None:
        """Move the window on to ``message``'s tick if it is newer (a bridge's status's ticks
        are its bus's, not the team's: they do not move it)."""
        tick = getattr(message, "tick", None)
        if tick is not None and tick > self.latest and not isinstance(message, BridgeStatus):
            self.latest = tick
