"""Step 4: the moment of inertia ``J`` (Sec. V-A).

With ``Σ_i z_i = 0``, the forces ``f_i = k z_i⊥`` (eq. 14, scaled by a gain ``k`` common to the
team and signed to speed up the turn the load already has) add up to zero net force and a
torque ``k Σ_i ‖z_i‖²`` about any point, so (eq. 15)

    ω̇ = (k w) / J,      w = Σ_i ‖z_i‖²  (from average consensus, eq. 16).

Each robot knows ``w`` and ``ω`` (eq. 5); ``θ = 1/J`` follows from the Appendix's filtered
regression with ``y = ω`` and ``u = ±k w``. The load would spin up at a constant rate
(Remark V.2); instead every robot reverses the torque when |ω| leaves a band (the robots all
measure the same ω, so they reverse at the same tick), which keeps ω bounded and of one sign.
"""

from __future__ import annotations

from agent.algorithm.paper.filtered_regression import FilteredRegression


class InertiaEstimator:
    """``J`` from ``ω`` samples while the team applies eq. (14) with torque ``±k w``."""

    def __init__(self, filter_gain: float, forgetting: float = 1.0):
        self.regression = FilteredRegression(
            filter_gain, outputs=1, params=1, forgetting=forgetting
        )

    @property
    def started(self) -> bool:
        """Whether the first sample has started the filters."""
        return self.regression.started

    def update(self, omega: float, torque: float, dt: float) -> None:
        """Feed ``ω`` at the end of an interval ``dt`` during which the team's torque was
        ``torque`` (``±k w``); the first call only starts the filters."""
        if not self.regression.started:
            self.regression.start((omega,))
        else:
            self.regression.update((omega,), ((torque * dt,),), dt)

    @property
    def estimate(self) -> float | None:
        """``Ĵ = 1/θ̂`` (``None`` until ``θ̂ > 0``)."""
        est = self.regression.estimate
        return None if est is None or est[0] <= 0.0 else 1.0 / est[0]

    @property
    def covariance(self) -> None:
        """Not estimated yet."""
        return None
