"""Order statistics of measured samples: the one percentile every figure of the project uses
(the plant's command latencies, the benchmarks' round trips and page latencies)."""

from __future__ import annotations

import math
from collections.abc import Iterable


def percentile(values: Iterable[float], q: float) -> float:
    """The ``q``-th percentile (``q`` in 0..100) of ``values``, linearly interpolated between
    the closest ranks (numpy's default): over the sorted ``x_0 ≤ … ≤ x_{n−1}``, at
    ``r = (n − 1) q / 100``, ``x_⌊r⌋ + (x_⌊r⌋+1 − x_⌊r⌋)(r − ⌊r⌋)``; so ``q = 0`` is the
    smallest and ``q = 100`` the largest. ``ValueError`` if there are none, or ``q`` is outside
    0..100."""
    ordered = sorted(values)
    if not ordered:
        raise ValueError("percentile of no values")
    if not 0 <= q <= 100:
        raise ValueError(f"percentile: q must be in [0, 100], got {q}")
    position = (len(ordered) - 1) * q / 100
    low = math.floor(position)
    high = min(low + 1, len(ordered) - 1)
    return ordered[low] + (ordered[high] - ordered[low]) * (position - low)
