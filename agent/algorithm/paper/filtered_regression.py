"""Parameter estimation by filtering linear dynamics: the paper's Appendix, eq. (26).

Model: an output ``y ∈ R^l`` obeys ``ẏ = Φ(t) θ`` with a known regressor ``Φ ∈ R^{l×p}`` and an
unknown constant ``θ ∈ R^p`` (the paper treats ``p = 1``; Step 5 here uses ``p = 2``).
Accelerations are never measured: both sides go through the same first-order low-pass filter
``ẋ^f = k_f (x − x^f)``, and because the filter is linear,

    k_f (y − y^f) = Φ^f θ                                                     (26)

relates measured quantities only. Started with ``y^f(t0) = y(t0)`` and ``Φ^f(t0) = 0`` the
identity holds from ``t0`` on, with no transient (its error ``e`` obeys ``ė = −k_f e``, e(t0)=0).

Sampled form (exact between samples, whatever the sampling intervals): with
``g_k = 1 − exp(−k_f Δt_k)``, ``r_k = y_k − y^f_k`` and

    y^f_{k+1} = y^f_k + g_k r_k,        S_{k+1} = (1 − g_k) S_k + ∫_{t_k}^{t_{k+1}} Φ dt,

one has ``r_k = S_k θ`` for every ``k`` (``S ≈ Φ^f / k_f``). Instead of the paper's
instantaneous ratio, ``θ`` is the least-squares solution of all these equations,
``θ̂ = (Σ S_kᵀ S_k)⁻¹ Σ S_kᵀ r_k`` (recursive, with an optional forgetting factor ``λ`` for
parameters that may change), which is exact without noise and averages noise when there is.
"""

from __future__ import annotations

import math
from collections.abc import Sequence


class FilteredRegression:
    """Least squares on the filtered regression (26) for ``ẏ = Φ θ``, ``y ∈ R^l``, ``θ ∈ R^p``.

    Call :meth:`start` with the first output sample, then :meth:`update` once per sampling
    interval with the output at its end and ``∫Φ dt`` over it (``l`` rows of ``p`` numbers).
    """

    def __init__(self, filter_gain: float, outputs: int, params: int, forgetting: float = 1.0):
        if params not in (1, 2):
            raise ValueError("params must be 1 or 2")
        if not 0.0 < forgetting <= 1.0:
            raise ValueError("forgetting must be in (0, 1]")
        self.filter_gain = filter_gain
        self.outputs = outputs
        self.params = params
        self.forgetting = forgetting
        self.started = False
        self._y: list[float] = [0.0] * outputs
        self._yf: list[float] = [0.0] * outputs
        self._s: list[list[float]] = [[0.0] * params for _ in range(outputs)]
        self._a = [[0.0] * params for _ in range(params)]
        self._b = [0.0] * params

    def start(self, y: Sequence[float]) -> None:
        """Begin at output sample ``y``: ``y^f = y``, ``S = 0`` (no filter transient)."""
        self._y = [float(v) for v in y]
        self._yf = list(self._y)
        self._s = [[0.0] * self.params for _ in range(self.outputs)]
        self._a = [[0.0] * self.params for _ in range(self.params)]
        self._b = [0.0] * self.params
        self.started = True

    def update(
        self, y: Sequence[float], phi_integral: Sequence[Sequence[float]], dt: float
    ) -> None:
        """Advance one interval of length ``dt``: ``y`` is the output at its end and
        ``phi_integral[i][j] = ∫ Φ_ij dt`` over it."""
        g = 1.0 - math.exp(-self.filter_gain * dt)
        keep = 1.0 - g
        lam = self.forgetting
        a, b, p = self._a, self._b, self.params
        if lam != 1.0:
            for j in range(p):
                b[j] *= lam
                for m in range(p):
                    a[j][m] *= lam
        for i in range(self.outputs):
            yf = self._yf[i] + g * (self._y[i] - self._yf[i])
            self._yf[i] = yf
            row = self._s[i]
            phi = phi_integral[i]
            for j in range(p):
                row[j] = keep * row[j] + phi[j]
            r = y[i] - yf
            for j in range(p):
                b[j] += row[j] * r
                for m in range(p):
                    a[j][m] += row[j] * row[m]
            self._y[i] = float(y[i])

    @property
    def estimate(self) -> tuple[float, ...] | None:
        """``θ̂``, or ``None`` before the data determine it."""
        a, b = self._a, self._b
        if self.params == 1:
            return (b[0] / a[0][0],) if a[0][0] > 0.0 else None
        det = a[0][0] * a[1][1] - a[0][1] * a[1][0]
        scale = max(a[0][0] * a[1][1], 1e-300)
        if det <= 1e-12 * scale:
            return None
        return (
            (a[1][1] * b[0] - a[0][1] * b[1]) / det,
            (a[0][0] * b[1] - a[1][0] * b[0]) / det,
        )
