"""Linear least squares, one row at a time: the solver under every robust estimator.

For rows ``a_k ∈ R^p`` and targets ``b_k``, the estimate ``p̂`` minimises
``Σ_k λ^{N−k} (a_kᵀ p − b_k)²`` (``λ ∈ (0, 1]``: exponential forgetting, 1 = none). Only the
normal equations are kept, ``M = Σ λ^{N−k} a_k a_kᵀ``, ``v = Σ λ^{N−k} a_k b_k``,
``Σ λ^{N−k} b_k²`` and the (forgotten) row count ``N``: O(p²) per row, whatever the run's
length. Then ``p̂ = M⁻¹ v`` (Cholesky: ``M`` is symmetric and, once the rows span ``R^p``,
positive definite), the residual sum of squares is ``Σ b² − p̂ᵀ v``, and the textbook
covariance ``σ̂² M⁻¹`` with ``σ̂² = RSS / (N − p)`` — for independent residuals. The estimators
say how they scale it when theirs are not.

Plain floats, no numpy: ``p ≤ 7`` here, where small arrays cost more than they save; the
normal equations are solved by code written out for ``p`` (:mod:`agent.algorithm.robust.
normal_equations`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from agent.algorithm.robust.normal_equations import (
    QuadraticForm,
    accumulator,
    quadratic_form,
    solver,
)

T = TypeVar("T")


@functools.cache
def _lower_triangle_index(p: int) -> tuple[int, ...]:
    """For each entry ``(i, j)`` of a ``p × p`` symmetric matrix (row-major), where it is kept
    in the lower triangle: ``max(i, j) p + min(i, j)``."""
    return tuple(max(i, j) * p + min(i, j) for i in range(p) for j in range(p))


class LeastSquares:
    """Accumulates rows ``a_kᵀ p ≈ b_k``; :meth:`solve` gives ``p̂`` and ``M⁻¹``."""

    def __init__(self, params: int, forgetting: float = 1.0):
        if params < 1:
            raise ValueError("params must be at least 1")
        if not 0.0 < forgetting <= 1.0:
            raise ValueError("forgetting must be in (0, 1]")
        self.params = params
        self.forgetting = forgetting
        self.rows = 0.0
        """The (forgotten) number of rows."""
        self._m = [0.0] * (params * params)
        """``M``, row-major (its lower triangle kept: it is symmetric)."""
        self._v = [0.0] * params
        self._bb = 0.0
        self._add = accumulator(params)
        self._solve = solver(params)
        self._form = quadratic_form(params)
        self._mirror = _lower_triangle_index(params)
        """Where each entry of the full ``M`` (row-major) is kept in :attr:`_m`."""

    def add(self, row: Sequence[float], target: float) -> None:
        """One more row ``rowᵀ p ≈ target`` (``row``: ``p`` numbers)."""
        m, v, lam = self._m, self._v, self.forgetting
        if lam != 1.0:
            self._m = m = [lam * x for x in m]
            self._v = v = [lam * x for x in v]
            self._bb *= lam
            self.rows *= lam
        self._add(m, v, row, target)
        self._bb += target * target
        self.rows += 1.0

    def solve(self) -> Solution | None:
        """``p̂``, ``M⁻¹`` and ``σ̂²``, or ``None`` while the rows do not determine ``p``
        (fewer than ``p + 1`` rows, or ``M`` singular to working precision)."""
        p = self.params
        if self.rows <= p:
            return None
        solved = self._solve(self._m, self._v)
        if solved is None:
            return None
        estimate, inverse, explained = solved
        rss = max(self._bb - explained, 0.0)
        return Solution(estimate, inverse, rss / (self.rows - p), self.rows, self._form)

    def solve_with_prior(
        self, at: tuple[int, int], mean: Sequence[float], information: Sequence[float], scale: float
    ) -> Solution | None:
        """``p̂`` with a Gaussian prior on the two parameters ``at``: its ``mean`` and its
        ``information`` (the inverse of its covariance, row-major 2 × 2), beside the rows whose
        covariance is ``scale σ̂² M⁻¹`` (``scale``: a :class:`RunFit`'s correlation factor).
        The two combine in information form,

            (M / (scale σ̂²) + Eᵀ I E) p̂ = v / (scale σ̂²) + Eᵀ I μ,

        ``E`` picking the two parameters, with ``σ̂² = RSS(p̂) / (N − p)`` the rows' own mean
        square residual at ``p̂`` (``RSS(p) = Σb² − 2 pᵀ v + pᵀ M p``), found by fixed-point
        iteration from a negligible weight of the prior's (:data:`PRIOR_PASSES` passes). The
        rows need not determine every parameter: the prior completes them. The
        :class:`Solution`'s ``inverse`` is that of the combined matrix times ``scale σ̂²``, so
        that its :meth:`~Solution.covariance` ``(scale)`` is the posterior's. ``None`` with
        fewer than ``p + 1`` rows or a singular combination."""
        p = self.params
        if self.rows <= p:
            return None
        full = [self._m[k] for k in self._mirror]
        i, j = sorted(at)
        a, b, _, d = information
        trace = sum(full[k * (p + 1)] for k in range(p))
        weight = _FIRST_WEIGHT * trace / max(a + d, 1e-300)
        solved = None
        for _ in range(PRIOR_PASSES):
            m, v = list(self._m), list(self._v)
            m[i * p + i] += weight * a
            m[j * p + i] += weight * b
            m[j * p + j] += weight * d
            v[i] += weight * (a * mean[0] + b * mean[1])
            v[j] += weight * (b * mean[0] + d * mean[1])
            solved = self._solve(m, v)
            if solved is None:
                return None
            estimate = solved[0]
            fitted = sum(e * f for e, f in zip(estimate, self._v, strict=True))
            rss = max(self._bb - 2.0 * fitted + self._form(full, estimate), 0.0)
            variance = rss / (self.rows - p)
            if variance == 0.0:
                break
            weight = scale * variance
        estimate, inverse, _ = solved
        return Solution(estimate, inverse, variance, self.rows, self._form)


PRIOR_PASSES = 3
"""Passes of :meth:`LeastSquares.solve_with_prior`'s fixed point on ``σ̂²``: the first with the
prior's weight a negligible share of the rows' (:data:`_FIRST_WEIGHT`), each next at the last
``σ̂²``."""
_FIRST_WEIGHT = 1e-9


CORRELATION_TIME = 0.4
"""s: how long the errors of an angle fit's rows (the load's rotation, summed from the arcs)
stay correlated; its rows count as one independent row per this time. Set over 40 runs of the
paper's scenario at 1 cm/s (seeds 0–39), where 95 % of the robots' ``Ĵ`` fell within 1.96
standard deviations with 0.2 s scaled by 1.3 to 1.6 (``Ĵ``'s standard deviation was then the
inertia fit's and the torque scale's alone).

Measured again by ``heft bench calibrate correlation-time`` (the noise benchmark's runs of
seeds 0–39; ``Ĵ``'s published variance without ``PUBLISHED_VARIANCE``, of which this scales
the fit's share alone, not the torque scale's or the drives' gains'). On 2026-11-27 it printed
3.93 s for 95 % of the ``Ĵ`` inside (85.6 % with 0.4 s; ``PUBLISHED_VARIANCE["moment"]`` makes
up the rest), and with ``--ideal-drives`` 0 s (95.0 % with 0.4 s): the fit's share is a small
part of ``Ĵ``'s variance now (a median of 9 %, 7 % with ideal drives)."""


class RunFit:
    """A fit over a run of :attr:`t` seconds whose rows' errors stay correlated for
    :attr:`correlation_time` (0: each row counts on its own): its covariance is the
    least-squares one scaled by ``correlation_time × rows / t``. Subclasses add rows to
    :attr:`fit`, advance :attr:`t` and call :meth:`_solve` with every row, so that a solution
    fixes everything its reports depend on (:meth:`_of_solution`)."""

    min_rows = 10
    correlation_time = CORRELATION_TIME
    """s: the rows count as one per this time (0: each row counts)."""

    def __init__(self, params: int, forgetting: float = 1.0):
        self.fit = LeastSquares(params, forgetting)
        self.t = 0.0
        """s since the first sample."""
        self._solution: Solution | None = None
        self._made: tuple[Solution | None, dict[str, Any]] = (None, {})
        """The solution :meth:`_of_solution` last made values of, and them by name."""

    def _solve(self) -> None:
        self._solution = self.fit.solve() if self.fit.rows >= self.min_rows else None

    def _of_solution(self, name: str, make: Callable[[Solution], T]) -> T:
        """``make(solution)`` for the current (not None) solution, made once per solution: the
        reports read it many times a solve, and after the fit's last solve at every report.
        Exact, since every row comes with a solve: :attr:`t` and the rows, all that the
        scale and the solution depend on, stay as they were until the next solution."""
        fit = self._solution
        made_of, made = self._made
        if made_of is not fit:
            made = {}
            self._made = (fit, made)
        if name not in made:
            made[name] = make(fit)
        return made[name]

    @property
    def _scale(self) -> float:
        """The factor on the least-squares covariance (see the class docstring)."""
        return self._scale_for(self._solution.rows)

    def _scale_for(self, rows: float) -> float:
        """``correlation_time × rows / t`` (1 for an uncorrelated fit)."""
        return self.correlation_time * rows / max(self.t, 1e-9) or 1.0


class ReciprocalFit(RunFit):
    """A :class:`RunFit` one of whose parameters, ``p[index]``, is the reciprocal of the
    estimate (``1/J``, ``1/m``): :attr:`estimate` is ``1/p̂[index]`` once the fit gives it
    positive, and :attr:`std` its standard deviation."""

    index = 2
    _std: float | None = None
    """:attr:`std`, from the last solve."""

    def _solve(self) -> None:
        super()._solve()
        fit = self._solution
        if fit is not None and fit.estimate[self.index] <= 0.0:
            self._solution = fit = None
        self._std = None if fit is None else fit.reciprocal(self.index, self._scale)[1]

    @property
    def estimate(self) -> float | None:
        """``1/p̂[index]`` (``None`` until the fit gives it positive)."""
        fit = self._solution
        return None if fit is None else 1.0 / fit.estimate[self.index]

    @property
    def std(self) -> float | None:
        """The standard deviation of :attr:`estimate` (kept from the last solve)."""
        return self._std

    @property
    def covariance(self) -> tuple[tuple[float]] | None:
        """``((std²,),)``."""
        std = self.std
        return None if std is None else ((std * std,),)


class Solution:
    """A solved fit: ``estimate`` ``p̂``, ``inverse`` ``M⁻¹`` (row-major), ``variance``
    ``σ̂²`` (the residuals' mean square) and the number of ``rows``; ``form`` is
    :func:`~agent.algorithm.robust.normal_equations.quadratic_form` of ``p`` (looked up once
    per fit rather than at every variance)."""

    __slots__ = ("estimate", "inverse", "variance", "rows", "_form")

    def __init__(self, estimate, inverse, variance: float, rows: float, form: QuadraticForm):
        self.estimate: tuple[float, ...] = estimate
        self.inverse: tuple[float, ...] = inverse
        self.variance = variance
        self.rows = rows
        self._form = form

    def covariance(self, scale: float = 1.0, of: Sequence[int] | None = None) -> list[list[float]]:
        """``scale · σ̂² M⁻¹``, or its rows and columns ``of`` (the covariance of those
        parameters)."""
        p = len(self.estimate)
        k = scale * self.variance
        indices = range(p) if of is None else of
        return [[k * self.inverse[i * p + j] for j in indices] for i in indices]

    def reciprocal(self, index: int, scale: float = 1.0) -> tuple[float, float]:
        """``1/p̂_index`` and its standard deviation ``std(p̂_index) / p̂_index²`` (first
        order), for a parameter fitted as the reciprocal of a positive quantity (``1/J``,
        ``1/m``). ``Var(p̂_index)`` is :meth:`variance_of` the unit gradient at ``index``:
        ``M⁻¹``'s diagonal entry there, read directly."""
        p = self.estimate[index]
        diagonal = self.inverse[index * (len(self.estimate) + 1)]
        variance = max(scale * self.variance * diagonal, 0.0)
        return 1.0 / p, math.sqrt(variance) / (p * p)

    def variance_of(self, gradient: Sequence[float], scale: float = 1.0) -> float:
        """``scale · σ̂² gᵀ M⁻¹ g``: the variance of a function of ``p̂`` with gradient ``g``."""
        total = self._form(self.inverse, gradient)
        return max(scale * self.variance * total, 0.0)
