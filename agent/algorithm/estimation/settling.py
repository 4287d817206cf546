"""Deciding, from an agent's own evidence, that an estimate has settled.

An estimate has settled when, for ``window`` updates running, it is within ``tolerance`` times
its size of the oldest of its last ``window`` values (where it was ``window`` updates before,
once there are that many), and no single update moved it by more than that. This looks at
drift, not at jitter: lost messages make estimates tremble by tiny amounts from one tick to the
next, which must not keep a converged estimate from counting as settled.
O(size of the estimate) per update.

An estimate that comes with its standard deviation ``σ`` (the robust estimators' do) is judged
by it instead: it has settled once, for ``window`` updates running, ``σ`` is at most
``uncertainty`` times its size (or times a ``scale`` given with it, for an estimate that may be
small: an offset measured against the load's size), or has stopped shrinking (a small load under
much noise may never reach the fraction: the team then goes on with what it has, and the
published ``σ`` says how good that is). An estimate that an iteration computes
from uncertain inputs (Step 2's consensus: its ``σ`` is its inputs', not how far the iteration
still has to go) is judged by both: ``σ`` small enough, and no drift beyond ``3σ``.

A robot watches six of its estimates (:class:`SettleDetectors`); the team leaves a phase once
every robot's estimates of that phase have settled (:mod:`agent.algorithm.phase_machine`).
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from operator import mul

PLATEAU = 0.02
"""An uncertainty that shrank by less than this fraction over a window has stopped shrinking."""


class SettleDetector:
    """Tracks whether a (vector) estimate has stopped moving; remembers when it first did."""

    def __init__(
        self,
        window: int,
        tolerance: float,
        floor: float = 1e-3,
        uncertainty: float = 0.0,
        iterated: bool = False,
    ):
        self.window = max(1, int(window))
        self.tolerance = tolerance
        self.floor = floor
        self.uncertainty = uncertainty
        self.iterated = iterated
        """Whether an estimate with a standard deviation is judged by its drift as well."""
        self.streak = 0
        self.first_settled: int | None = None
        self._past: deque[tuple[float, ...]] = deque(maxlen=self.window + 1)
        self._stds: deque[float] = deque(maxlen=self.window + 1)

    def fresh(self) -> SettleDetector:
        """A detector like this one that has seen nothing."""
        return SettleDetector(
            self.window, self.tolerance, self.floor, self.uncertainty, self.iterated
        )

    def update(
        self, value: Sequence[float], tick: int, std: float | None = None, scale: float = 0.0
    ) -> bool:
        """Feed the estimate at ``tick`` (with its standard deviation ``std``, same units, if
        it has one, and the ``scale`` its size is at least taken to be); returns whether it is
        settled now."""
        past = self._past
        if std is not None:
            self._stds.append(std)
        if std is not None and not (self.iterated and past):
            size = max(math.sqrt(sum(map(mul, value, value))), scale)
            self.streak = self.streak + 1 if self._certain(std, size) else 0
        elif past:
            last, oldest = past[-1], past[0]
            size2 = step2 = drift2 = 0.0
            for v, a, b in zip(value, last, oldest):
                size2 += v * v
                step2 += (v - a) * (v - a)
                drift2 += (v - b) * (v - b)
            limit2 = self.tolerance * self.tolerance * max(size2, self.floor * self.floor)
            if std is not None:  # iterated: both its drift and its own uncertainty
                limit2 = max(limit2, 9.0 * std * std)
            quiet = step2 <= limit2 and drift2 <= limit2
            if std is not None and not self._certain(std, max(math.sqrt(size2), scale)):
                quiet = False
            self.streak = self.streak + 1 if quiet else 0
        past.append(tuple(value))
        if self.settled and self.first_settled is None:
            self.first_settled = tick
        return self.settled

    def _certain(self, std: float, size: float) -> bool:
        """Certain enough: ``std`` at most ``uncertainty`` times ``size``, or no longer
        shrinking (by under :data:`PLATEAU` over the window: more data will not make it so;
        the published uncertainty says how good it is)."""
        if std <= self.uncertainty * size:
            return True
        stds = self._stds
        return len(stds) > self.window and std >= (1.0 - PLATEAU) * stds[0]

    @property
    def settled(self) -> bool:
        return self.streak >= self.window


ITERATED = {0, 1, 2, 3}
"""The detectors (by position in :class:`SettleDetectors`) judged by their drift as well:
the distances, the centroid, ``ξ_i`` and ``Ĵ``, each of which a noise-free run would
otherwise call settled on its first window (their uncertainty then is nil, not their error).
``z_C`` and ``m̂``, judged by uncertainty alone, settle within 20 s at 1 cm/s."""


@dataclass(frozen=True, slots=True)
class SettleDetectors:
    """The estimates a robot watches, by what they are."""

    distances: SettleDetector
    """Step 1 (and 3): every ``‖z_ij‖``."""
    centroid: SettleDetector
    """Step 2: ``z_i`` in the frame of the longest edge (constant once converged)."""
    mean_square_offset: SettleDetector
    """``ξ_i = w / n`` (eq. 16), the team quantity of that name."""
    moment: SettleDetector
    """Step 4: ``Ĵ``."""
    com_offset: SettleDetector
    """Step 5: ``z_C`` at the push phase's reference instant."""
    mass: SettleDetector
    """Step 7: ``m̂``."""

    @classmethod
    def of(cls, window: int, tolerance: float, uncertainty: float = 0.0) -> SettleDetectors:
        """Six detectors alike (see :class:`SettleDetector`)."""
        iterated = ITERATED
        return cls(
            *(
                SettleDetector(window, tolerance, uncertainty=uncertainty, iterated=i in iterated)
                for i in range(6)
            )
        )

    def with_load_forgotten(self) -> SettleDetectors:
        """These detectors with those of the load's own estimates (``Ĵ``, ``z_C``, ``m̂``)
        started afresh, for a changed load."""
        return dataclasses.replace(
            self,
            moment=self.moment.fresh(),
            com_offset=self.com_offset.fresh(),
            mass=self.mass.fresh(),
        )

    def first_settled(self) -> dict[int, int]:
        """Paper step (1..7) → the tick its estimate first settled (steps not settled yet are
        left out). ω (Step 3) comes from the distances, ``ṗ_C`` (Step 6) from ``z_C``."""
        settled = {}
        for step, detector in (
            (1, self.distances),
            (2, self.centroid),
            (3, self.distances),
            (4, self.moment),
            (5, self.com_offset),
            (6, self.com_offset),
            (7, self.mass),
        ):
            tick = detector.first_settled
            if tick is not None:
                settled[step] = tick
        return settled
