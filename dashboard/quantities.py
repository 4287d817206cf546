"""The estimated scalars the page charts and tabulates with their 95 % intervals, declared once.

Each :class:`Scalar` names a field of :class:`~agent.platform.protocol.Estimates`, the field of
its standard deviation and the field of :class:`~agent.platform.protocol.Truth` it is judged
against. For every scalar of :data:`SCALARS`, :class:`~dashboard.state.TeamState` charts each
robot's estimate (trace ``KEY/ROBOT``, points ``[t, value, half-width]``) and the truth
(``KEY/truth``), and puts the estimate, its interval and whether the truth lies inside it in
the table's rows; the page is sent the declarations in its ``hello`` and builds a chart, a
value column and an error column for each. A quantity estimated with a standard deviation
(a friction term, say) is one more line of :data:`SCALARS`.

The 95 % interval is ``±1.96 σ`` (:func:`~agent.platform.evaluation.scalar_interval`): the
robust estimators publish standard deviations scaled so that it holds the truth 95 % of the
time (:data:`agent.algorithm.robust.uncertainty.PUBLISHED_VARIANCE`); the paper's estimators
publish none, and their estimates are drawn without one. What comes over the network is
used only if it can be a standard deviation (finite, ``≥ 0``).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Scalar:
    """An estimated scalar and how the page shows it."""

    key: str
    """Its :class:`~agent.platform.protocol.Estimates` field; also its chart's name."""
    std: str
    """The :class:`~agent.platform.protocol.Estimates` field of its standard deviation (same
    unit)."""
    truth: str
    """The :class:`~agent.platform.protocol.Truth` field it is judged against (a truth without
    it: not judged)."""
    error: str | None
    """Its key among :func:`~agent.platform.evaluation.robot_errors`' (``…_rel``: relative,
    shown in %; else in ``unit``), or None: no error column."""
    symbol: str
    """As the page writes the estimate (``m̂``)."""
    unit: str
    title: str
    """Its chart's heading."""
    digits: int
    """Decimals of the estimate and its ``±`` in the table."""

    def declaration(self) -> dict:
        """What the page is told of it (in its ``hello``)."""
        return {
            "key": self.key,
            "symbol": self.symbol,
            "unit": self.unit,
            "title": self.title,
            "digits": self.digits,
            "error": self.error,
            "relative": self.error is not None and self.error.endswith("_rel"),
        }


SCALARS: tuple[Scalar, ...] = (
    Scalar("mass", "mass_std", "mass", "mass_rel", "m̂", "kg", "mass", 4),
    Scalar("moment", "moment_std", "moment", "moment_rel", "Ĵ", "kg m²", "moment of inertia", 4),
)
"""Every estimated scalar the page shows, in the order of its charts and columns."""

DECLARATIONS = [scalar.declaration() for scalar in SCALARS]
""":data:`SCALARS` as the page's ``hello`` carries them."""
