"""When to send a message again that may have been lost: a timeout that follows the pace.

In lockstep nothing moves until every message of a tick has arrived, so a lost one (the fault
injector's, or one sent before a subscription reached the router) is sent again after a
timeout. A fixed timeout is wrong both ways: too long, a loss stalls the team; shorter than a
tick takes on a slow machine (User-Mode Linux, a loaded robot computer), every tick is sent
twice, which loads the machine further and slows every tick more.

:class:`ResendTimeout` is the retransmission timeout of TCP (Jacobson and Karels; RFC 6298,
Sec. 2) on the time a tick takes. With ``R`` each new sample of that time::

    first sample:   SRTT = R,  RTTVAR = R / 2
    then:           RTTVAR = (1 - β) RTTVAR + β |SRTT - R|,   β = 1/4
                    SRTT   = (1 - α) SRTT + α R,              α = 1/8
    timeout         RTO = clamp(SRTT + 4 RTTVAR, floor, ceiling)

Like TCP (Karn's rule), a sample that spans a resend is not taken: it says how long the loss
took to repair, not how long a tick takes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

ALPHA = 1 / 8
BETA = 1 / 4
K = 4


@dataclass
class ResendTimeout:
    """The timeout after which a tick's message is sent again (see the module docstring)."""

    floor_s: float = 0.2
    """The shortest timeout, and the timeout before the first sample."""
    ceiling_s: float = 5.0
    """The longest timeout: a loss is repaired within it however slow the pace."""
    srtt_s: float | None = field(default=None, init=False)
    """The smoothed time a tick takes (``None`` before the first sample)."""
    rttvar_s: float = field(default=0.0, init=False)
    """Its smoothed mean deviation."""

    def observe(self, sample_s: float) -> None:
        """One tick took ``sample_s`` seconds (without a resend on the way)."""
        if sample_s < 0:
            return
        if self.srtt_s is None:
            self.srtt_s, self.rttvar_s = sample_s, sample_s / 2
            return
        self.rttvar_s = (1 - BETA) * self.rttvar_s + BETA * abs(self.srtt_s - sample_s)
        self.srtt_s = (1 - ALPHA) * self.srtt_s + ALPHA * sample_s

    @property
    def timeout_s(self) -> float:
        if self.srtt_s is None:
            return self.floor_s
        return min(self.ceiling_s, max(self.floor_s, self.srtt_s + K * self.rttvar_s))
