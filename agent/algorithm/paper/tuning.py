"""The paper's estimators' own gains (``[agent.paper]`` in a scenario, ``[tuning.paper]`` in
robot.toml)."""

from __future__ import annotations

from dataclasses import dataclass

from agent.platform.config import bounded, check_bounds


@dataclass(frozen=True)
class PaperTuning:
    """The gains of the paper's estimators and force laws (Sec. IV-V, the Appendix)."""

    filter_gain: float = bounded(5.0, 0, 1000, "1/s", open_low=True)
    """k_f (1/s), the low-pass filters of the Appendix."""
    inertia_max_omega: float = bounded(1.0, 0, 10, "rad/s", open_low=True)
    """rad/s: Step 4 brakes when |ω| reaches this and speeds up again below half of it."""
    push_fbar: float = bounded(1.0, 0, 1000, "rad/s² per m", open_low=True)
    """f̄_y (rad/s² per m) of Steps 5–7: each robot pushes with ``f = f̄_y Ĵ / n`` (Sec. VI) ..."""
    push_min_force: float = bounded(1.0, 0, 1000, "N", open_low=True)
    """N: ... but at least this much (a compact load's COM would barely accelerate for Step 7),
    and at most ``max_force``."""

    def validate(self, where: str) -> None:
        """:class:`~agent.platform.config.ConfigError` naming the key and its range unless every
        field is in range."""
        check_bounds(self, where)
