"""Step 7: the mass ``m`` (Sec. V-C).

While every robot applies the same force ``f_m`` (its sign may reverse: ``s(t) f_m``, see
:meth:`~agent.algorithm.phase_machine.PhaseMachine.push_sign`), eq. (1) reads (eq. 25)

    p̈_C = (n / m) s f_m,

a linear system whose output ``ṗ_C`` each robot knows from eq. (7). ``θ = 1/m`` follows from
the Appendix's filtered regression with ``y = ṗ_C`` and ``u = n f_m``.
"""

from __future__ import annotations

from agent.algorithm.paper.filtered_regression import FilteredRegression
from agent.platform.geometry import Vec2


class MassEstimator:
    """``m`` from ``ṗ_C`` samples while the ``n`` robots each push with ``f_m``."""

    def __init__(self, filter_gain: float, n: int, force: Vec2, forgetting: float = 1.0):
        self.total_force = (n * force[0], n * force[1])
        self.regression = FilteredRegression(
            filter_gain, outputs=2, params=1, forgetting=forgetting
        )

    @property
    def started(self) -> bool:
        """Whether the first sample has started the filters."""
        return self.regression.started

    def update(self, com_velocity: Vec2, sign: float, dt: float) -> None:
        """Feed ``ṗ_C`` at the end of an interval ``dt`` over which the force's mean sign was
        ``sign`` (the first call starts the filters)."""
        if not self.regression.started:
            self.regression.start(com_velocity)
        else:
            fx, fy = self.total_force
            u = sign * dt
            self.regression.update(com_velocity, ((fx * u,), (fy * u,)), dt)

    @property
    def estimate(self) -> float | None:
        """``m̂ = 1/θ̂`` (``None`` until ``θ̂ > 0``)."""
        est = self.regression.estimate
        return None if est is None or est[0] <= 0.0 else 1.0 / est[0]

    @property
    def covariance(self) -> None:
        """Not estimated yet."""
        return None
