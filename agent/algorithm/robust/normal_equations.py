"""The normal equations ``M p = v`` of a least-squares fit with ``p`` parameters, accumulated
row by row and solved by Cholesky, as straight-line code made once for each ``p``.

A row ``a`` with target ``b`` adds ``a aᵀ`` to ``M`` (row-major; its lower triangle only, as
``M`` is symmetric) and ``a b`` to ``v``, skipping the entries of each ``a_i = 0``. For ``M``
symmetric positive definite:

1. ``L Lᵀ = M``: ``L_ij = (M_ij − Σ_{k<j} L_ik L_jk) / L_jj`` for ``j < i``, then
   ``L_ii = √(M_ii − Σ_{k<i} L_ik²)``; ``M`` is taken for singular (no solution) unless every
   such radicand exceeds ``10⁻¹³`` times ``M``'s largest diagonal entry;
2. ``U = L⁻¹``: ``U_ii = 1 / L_ii``, ``U_ij = −(Σ_{k=j}^{i−1} L_ik U_kj) / L_ii``;
3. ``M⁻¹ = Uᵀ U``: ``(M⁻¹)_ij = Σ_{k≥max(i,j)} U_ki U_kj``, each entry below the diagonal
   computed once and mirrored;
4. ``p̂ = M⁻¹ v`` and ``p̂ᵀ v``;

and the quadratic form ``gᵀ M⁻¹ g`` of a gradient ``g`` (the variance of a function of ``p̂``),
``Σ_i g_i Σ_j (M⁻¹)_ij g_j`` over the ``g_i ≠ 0``.

An estimator adds a row to its fit and solves it a few times per tick and robot, for ``p`` of
3 to 7: there the loops, indexing and slices of these formulas cost several times their
arithmetic. So :func:`accumulator`, :func:`solver` and :func:`quadratic_form` write them out
for ``p`` (every index a number or a name, every sum over its terms) and compile that once.
The code performs the same floating-point operations in the same order as the loops, each sum
added term by term from its first term, so its results are theirs bit for bit
(``tests/unit/agent/test_robust_estimation.py`` holds it to them) and the same on every Python
(``sum`` of floats adds them so up to 3.11, compensated from 3.12 on). (A sum from 0.0 gives
the same numbers but for the sign of an exact zero, for one addition more per sum.)
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence

Accumulator = Callable[[list[float], list[float], Sequence[float], float], None]
"""``add(M, v, a, b)``: the row ``a`` (``p`` numbers) with target ``b`` added to ``M`` and
``v``, in place."""
Solved = tuple[tuple[float, ...], tuple[float, ...], float]
"""``(p̂, M⁻¹ row-major, p̂ᵀ v)``."""
Solver = Callable[[Sequence[float], Sequence[float]], "Solved | None"]
"""``solve(M, v)``: :data:`Solved`, or ``None`` if ``M`` is not positive definite."""

QuadraticForm = Callable[[Sequence[float], Sequence[float]], float]
"""``form(W, g)``: ``gᵀ W g`` for ``W`` symmetric (row-major) and ``g`` of ``p`` numbers."""

SINGULAR = 1e-13
"""A radicand of the Cholesky factor at most this times ``M``'s largest diagonal entry: ``M``
is singular to working precision."""


@functools.cache
def accumulator(p: int) -> Accumulator:
    """The accumulator of rows of ``p`` numbers (see the module docstring)."""
    return _compiled(_add_source(p), "add", p)


@functools.cache
def solver(p: int) -> Solver:
    """The solver of ``p`` normal equations (see the module docstring)."""
    return _compiled(_solve_source(p), "solve", p)


@functools.cache
def quadratic_form(p: int) -> QuadraticForm:
    """The quadratic form of ``p`` numbers (see the module docstring)."""
    return _compiled(_form_source(p), "form", p)


def _compiled(source: str, name: str, p: int) -> Callable:
    if p < 1:
        raise ValueError("p must be at least 1")
    namespace = {"sqrt": math.sqrt, "isfinite": math.isfinite, "SINGULAR": SINGULAR}
    exec(compile(source, f"<normal equations: {name}, p = {p}>", "exec"), namespace)
    return namespace[name]


def _add_source(p: int) -> str:
    """The Python source of ``add(m, v, row, target)`` for ``p`` parameters."""
    lines = ["def add(m, v, row, target):"]
    emit = lines.append
    emit(f"    {''.join(f'a{i}, ' for i in range(p))}= row")
    for i in range(p):
        emit(f"    if a{i} != 0.0:")
        emit(f"        v[{i}] += a{i} * target")
        for j in range(i + 1):
            emit(f"        m[{i * p + j}] += a{i} * a{j}")
    return "\n".join(lines) + "\n"


def _form_source(p: int) -> str:
    """The Python source of ``form(w, g)`` for ``p`` parameters."""
    lines = ["def form(w, g):"]
    emit = lines.append
    emit(f"    {''.join(f'g{i}, ' for i in range(p))}= g")
    emit("    total = 0.0")
    for i in range(p):
        emit(f"    if g{i}:")
        emit(f"        total += g{i} * {_sum([(f'w[{i * p + j}]', f'g{j}') for j in range(p)])}")
    emit("    return total")
    return "\n".join(lines) + "\n"


def _solve_source(p: int) -> str:
    """The Python source of ``solve(m, v)`` for ``p`` parameters."""

    def low(i: int, j: int) -> str:
        return f"l{i}_{j}"

    def inv_low(i: int, j: int) -> str:
        return f"u{i}_{j}"

    def inverse(i: int, j: int) -> str:
        return f"w{max(i, j)}_{min(i, j)}"

    lines = ["def solve(m, v):"]
    emit = lines.append
    lower = [f"m{i}_{j}" if j <= i else "_" for i in range(p) for j in range(p)]
    emit(f"    {''.join(f'{name}, ' for name in lower)}= m")
    emit(f"    {''.join(f'v{i}, ' for i in range(p))}= v")
    emit(f"    scale = max(({''.join(f'abs(m{i}_{i}), ' for i in range(p))}))")
    emit("    if scale == 0.0 or not isfinite(scale):")
    emit("        return None")
    emit("    limit = SINGULAR * scale")
    for i in range(p):  # L
        for j in range(i):
            products = _sum([(low(i, k), low(j, k)) for k in range(j)])
            numerator = f"m{i}_{j}" if products is None else f"(m{i}_{j} - {products})"
            emit(f"    {low(i, j)} = {numerator} / {low(j, j)}")
        products = _sum([(low(i, k), low(i, k)) for k in range(i)])
        emit(f"    t = m{i}_{i}" + ("" if products is None else f" - {products}"))
        emit("    if t <= limit:")
        emit("        return None")
        emit(f"    {low(i, i)} = sqrt(t)")
    for i in range(p):  # U = L⁻¹
        emit(f"    {inv_low(i, i)} = 1.0 / {low(i, i)}")
        for j in range(i):
            total = _sum([(low(i, k), inv_low(k, j)) for k in range(j, i)])
            emit(f"    {inv_low(i, j)} = -{total} / {low(i, i)}")
    for i in range(p):  # M⁻¹ = Uᵀ U
        for j in range(i + 1):
            total = _sum([(inv_low(k, i), inv_low(k, j)) for k in range(i, p)])
            emit(f"    {inverse(i, j)} = {total}")
    for i in range(p):  # p̂ = M⁻¹ v
        emit(f"    e{i} = {_sum([(inverse(i, j), f'v{j}') for j in range(p)])}")
    estimate = "".join(f"e{i}, " for i in range(p))
    matrix = "".join(f"{inverse(i, j)}, " for i in range(p) for j in range(p))
    explained = _sum([(f"e{i}", f"v{i}") for i in range(p)])
    emit(f"    return ({estimate}), ({matrix}), {explained}")
    return "\n".join(lines) + "\n"


def _sum(products: list[tuple[str, str]]) -> str | None:
    """The source of ``Σ a·b`` over ``products``, added in their order from the first
    (``None`` for no terms)."""
    terms = [f"{a} * {b}" for a, b in products]
    if not terms:
        return None
    return f"({' + '.join(terms)})"
