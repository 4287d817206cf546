"""The floor the noise benchmarks put their loads on (``heft bench noise --coulomb`` or
``--coulomb-range``, ``heft bench friction``): each seed's friction coefficients, and the
supports the load rests on.

Per seed ``s`` the kinetic coefficient ``μ`` is drawn uniformly in ``[μ_lo, μ_hi]`` from
``numpy.random.default_rng((s, FRICTION_STREAM))``, a stream of its own (the plant's draws
are ``default_rng(s)``'s and ``default_rng((s, 1))``'s), so a seed's ``μ`` is the same in every
benchmark, and ``μ_lo = μ_hi`` gives that ``μ`` to every seed without a draw. The breakaway
coefficient is ``μ_s`` as given, else :data:`STATIC_RATIO` ``μ`` (at most
:data:`~simulator.scenario.MAX_FRICTION`).

The supports (:func:`on_floor`): a scenario's own ``[ground]`` keeps its supports and its
viscous drag (``paper-floor.toml``: four casters), with ``μ`` and ``μ_s`` replaced; a scenario
without one rests on its whole area, the plant's default (the polygon's
:data:`~simulator.scenario.DEFAULT_SUPPORT_CELLS` cells, :meth:`~simulator.scenario.Ground.loads`:
the linear pressure of a rigid load on an elastic floor). When the COM is too far from the
area's centroid for that pressure to be positive everywhere (the scenario's parser refuses
such a ``[ground]``: a floor cannot pull), the load rests on the cells that bear it: the cell of
the most negative load is dropped, and the loads of the others computed again, until none is
negative (the statics still hold: ``Σ N_k = m g``, their centre the COM). A floor without
friction (``μ = μ_s = 0`` and no viscous drag) is none: the frictionless floor of the paper.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from agent.platform.protocol import GRAVITY
from simulator.polygon import area_cells
from simulator.scenario import (
    DEFAULT_SUPPORT_CELLS,
    MAX_FRICTION,
    Body,
    Ground,
    Scenario,
    ScenarioError,
)

FRICTION_STREAM = 2
"""Each seed's ``μ`` is ``default_rng((seed, FRICTION_STREAM))``'s first draw."""
STATIC_RATIO = 1.5
"""``μ_s / μ`` when ``μ_s`` is not given: breaking away takes more than rolling or sliding."""
MIN_SUPPORTS = 3
"""A load rests on at least three supports that are not on one line."""


@dataclass(frozen=True)
class FloorSettings:
    """The floor's friction for every seed of a benchmark."""

    coulomb: tuple[float, float]
    """``(μ_lo, μ_hi)``: each seed's kinetic ``μ`` drawn uniformly between them (equal: that
    ``μ`` for every seed)."""
    static: float | None = None
    """``μ_s`` for every seed; None: :data:`STATIC_RATIO` ``μ``."""

    def draw(self, seed: int) -> tuple[float, float]:
        """``(μ, μ_s)`` for seed ``seed`` (see the module docstring)."""
        low, high = self.coulomb
        mu = (
            low
            if low == high
            else float(np.random.default_rng((seed, FRICTION_STREAM)).uniform(low, high))
        )
        return mu, min(STATIC_RATIO * mu, MAX_FRICTION) if self.static is None else self.static

    @property
    def text(self) -> str:
        """The floor as the reports give it."""
        low, high = self.coulomb
        mu = f"mu {100 * low:g} %" if low == high else f"mu {100 * low:g}-{100 * high:g} % per seed"
        static = f"{STATIC_RATIO:g} mu" if self.static is None else f"{100 * self.static:g} %"
        return f"floor: {mu}, mu_s {static}"


def on_floor(scenario: Scenario, coulomb: float, static: float) -> tuple[Scenario, int]:
    """``scenario`` on a floor of kinetic ``coulomb`` and breakaway ``static`` coefficients
    (see the module docstring), and how many of its area's cells were dropped because the
    floor would have pulled there (0 on its own supports or its whole area)."""
    own = scenario.ground
    viscous = 0.0 if own is None else own.viscous
    if coulomb == 0.0 and static == 0.0 and viscous == 0.0:
        return dataclasses.replace(scenario, ground=None), 0
    if own is not None:
        ground = dataclasses.replace(own, coulomb=coulomb, static=static)
        return dataclasses.replace(scenario, ground=ground), 0
    cells = area_cells(scenario.body.polygon, DEFAULT_SUPPORT_CELLS)
    whole = Ground(
        coulomb,
        static,
        0.0,
        tuple(centroid for centroid, _ in cells),
        tuple(area for _, area in cells),
        supports_given=False,
    )
    ground = bearing(whole, scenario.body)
    for event in scenario.events:
        if min(ground.normal_loads(GRAVITY, event.applied_to(scenario.body).com)) < -1e-9:
            raise ScenarioError(
                f"{scenario.name}: after its load change at {event.at_s:g} s the load would not"
                " rest on the supports it starts on"
            )
    return dataclasses.replace(scenario, ground=ground), len(whole.supports) - len(ground.supports)


def bearing(ground: Ground, body: Body) -> Ground:
    """``ground`` with only the supports that bear ``body`` when the floor cannot pull: while
    some support's normal load (:meth:`~simulator.scenario.Ground.normal_loads`) is negative,
    the most negative one is dropped. Raises :class:`~simulator.scenario.ScenarioError` if
    fewer than :data:`MIN_SUPPORTS` would be left."""
    weight = body.mass * GRAVITY
    while True:
        normal = ground.normal_loads(weight, body.com)
        k = min(range(len(normal)), key=normal.__getitem__)
        if normal[k] >= -1e-9 * weight:
            return ground
        if len(normal) <= MIN_SUPPORTS:
            raise ScenarioError(f"body.com: {list(body.com)}: the load rests on no support")
        ground = dataclasses.replace(
            ground,
            supports=ground.supports[:k] + ground.supports[k + 1 :],
            stiffness=ground.stiffness[:k] + ground.stiffness[k + 1 :],
        )
