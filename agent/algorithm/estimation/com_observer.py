"""Step 5, as in the paper: the nonlinear observer (24) of the centre of mass offset
``z_C = p_G − p_C`` (Sec. V-B).

While every robot applies the same constant force ``f`` (eq. 17), ``Σ z_i⊥ = 0`` leaves
``ω̇ = z_C⊥ᵀ f̄`` with ``f̄ = (n/J) f`` (eqs. 18-19), and ``z_C`` turns with the load (eq. 20).
In coordinates whose y axis points along ``f`` (so ``f̄ = (0, f̄_y)``), with ``x_1, x_2`` the
coordinates of ``z_C`` and ``x_3 = ω``, this is system (21)::

    ẋ_1 = −x_2 x_3,   ẋ_2 = x_1 x_3,   ẋ_3 = x_1 f̄_y,   y = x_3.

Observer (24), with ``k_e > 0``::

    dx̂_1/dt = −x̂_2 x_3 + f̄_y (x_3 − x̂_3)
    dx̂_2/dt =  x̂_1 x_3
    dx̂_3/dt =  x̂_1 f̄_y + k_e (x_3 − x̂_3)

With ``e = x − x̂``, ``V = ½‖e‖²`` has ``V̇ = −k_e e_3²`` (notes): the error never grows, and
it converges while ω ≠ 0 and f̄_y ≠ 0 (Prop. V.1, Thm. V.1). It converges slowly for many
loads (tens of seconds to reach millimetres), so the team's ``z_C`` comes from
:class:`~agent.algorithm.paper.com_regression.ComRegression`; this observer runs beside it.
The observer is integrated with classical Runge-Kutta over each sampling interval, with the
measured ``ω`` interpolated linearly.
"""

from __future__ import annotations

import math

from agent.platform.geometry import Vec2


class ComObserver:
    """Observer (24) of ``z_C`` in ``W``, while the team pushes with a common force ``force``
    (eq. 17); started at ``ẑ_C = 0``, ``x̂_3 = ω``."""

    def __init__(self, n: int, moment: float, force: Vec2, gain: float, omega: float):
        magnitude = math.hypot(force[0], force[1])
        self.axis_y = (force[0] / magnitude, force[1] / magnitude)
        """The unit vector along ``f``: the y axis of system (21)'s coordinates, in ``W``."""
        self.axis_x = (self.axis_y[1], -self.axis_y[0])  # right-handed: x⊥ = y
        """Their x axis (``x⊥ = y``), in ``W``."""
        self.fbar = n * magnitude / moment
        """``f̄_y = (n/J) ‖f‖`` (eq. 19)."""
        self._fbar = self.fbar
        """``f̄_y`` with the sign of the current interval."""
        self.gain = gain
        """``k_e``."""
        self.state = [0.0, 0.0, omega]
        """``(x̂_1, x̂_2, x̂_3)``: ``ẑ_C`` in those coordinates, and ``ω̂``."""
        self.omega = omega
        """``ω`` measured at the end of the last interval."""

    def _rhs(self, h: list[float], x3: float) -> tuple[float, float, float]:
        e3 = x3 - h[2]
        fbar = self._fbar
        return (-h[1] * x3 + fbar * e3, h[0] * x3, h[0] * fbar + self.gain * e3)

    def update(self, omega: float, sign: float, dt: float) -> None:
        """Integrate (24) over an interval ``dt`` at whose end ``ω`` was measured, the force's
        mean sign over it ``sign`` (``f̄_y`` is then ``sign f̄_y``: ``V̇ = −k_e e₃²`` holds for
        any ``f̄_y(t)``)."""
        self._fbar = sign * self.fbar
        w0, w1 = self.omega, omega
        wm = 0.5 * (w0 + w1)
        h = self.state
        k1 = self._rhs(h, w0)
        h2 = [h[i] + 0.5 * dt * k1[i] for i in range(3)]
        k2 = self._rhs(h2, wm)
        h3 = [h[i] + 0.5 * dt * k2[i] for i in range(3)]
        k3 = self._rhs(h3, wm)
        h4 = [h[i] + dt * k3[i] for i in range(3)]
        k4 = self._rhs(h4, w1)
        self.state = [h[i] + dt / 6.0 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]) for i in range(3)]
        self.omega = omega

    @property
    def estimate(self) -> Vec2:
        """``ẑ_C`` in ``W`` now."""
        x1, x2 = self.state[0], self.state[1]
        ax, ay = self.axis_x, self.axis_y
        return (x1 * ax[0] + x2 * ay[0], x1 * ax[1] + x2 * ay[1])

    @property
    def covariance(self) -> None:
        """Not estimated yet."""
        return None
