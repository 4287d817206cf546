"""The team's quantities averaged in flow form: Step 2's offsets and every mean (eq. 16).

The quantities are declared once (:data:`agent.platform.team.TEAM_QUANTITIES`); this module runs
those averaged in flow form (``OFFSETS`` and ``MEAN``), all on the same messages, whatever
they are.

Step 2, Aragues et al. [10]: from ``x_i = 0`` iterate

    x_i ← x_i + Σ_{j∈N_i} a_ij (x_j − x_i + z_ij)

with symmetric weights ``a_ij`` (Metropolis, :mod:`agent.algorithm.estimation.consensus`). Since
``z_ji = −z_ij`` the sum ``Σ x_i`` stays 0, and the fixed point is ``x_j − x_i + z_ij = 0`` on
every edge, i.e. ``x_i = z_i = p_Ci − p_G``.

Each mean, eq. (16) sampled with input tracking: ``ξ_i ← ξ_i + Σ_j a_ij (ξ_j − ξ_i) +
(r_i⁺ − r_i)`` keeps ``Σ ξ_i = Σ r_i``, so every ``ξ_i`` converges to the inputs' mean. A robot's
inputs may depend on its own ``x_i`` (``r_i = ‖x_i‖²`` gives ``w / n``): the family gives them
as a function of ``x_i`` (:attr:`TeamConsensus.inputs`), evaluated with the current iterate.

The vectors of the load (``x_i`` and any quantity declared ``turns``) turn with it, so the
iteration must run in a frame fixed to the load (notes, Step 2). Here every vector stays in the
world frame ``W`` at the robot's current instant: before each update the robot turns its own
previous iterate, and each neighbour's (stamped with the instant it refers to), by the load's
rotation since then. That is the load-frame iteration written in ``W``, and it needs no
agreement on a reference instant.

Flow form (Jesus, Baquero & Almeida, "Fault-tolerant aggregation by flow updating", 2009): when
a message is lost, the two ends of an edge apply different updates and a sum that must never
change (``Σ x_i = 0``, ``Σ ξ_i = Σ r_i``) drifts for good. Written as *flows* on the edges, each
robot keeps, for each neighbour ``j``, what has flowed from it to ``j``: ``F_ij``. Its estimate
is its input minus its outflows, ``ξ_i = r_i − Σ_j F_ij`` (``x_i = −Σ_j F_ij``), an update moves
each edge's term ``Δ_ij`` into the estimate (``F_ij ← F_ij − Δ_ij``), each robot sends its flows
to its neighbours and, on hearing from ``j``, takes ``F_ij = −F_ji``. The flows of an edge are
then antisymmetric whatever was lost, so the sums hold and the iteration converges to the same
point as without loss. Without loss this is exactly the iteration above.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from operator import neg, sub
from typing import TYPE_CHECKING, Protocol

from agent.algorithm.estimation.consensus import metropolis_weight
from agent.platform.geometry import Vec2, rotate
from agent.platform.team import (
    TEAM_QUANTITIES,
    Averaging,
    TeamQuantity,
    consensus_state_type,
    flatten,
)

if TYPE_CHECKING:
    from agent.platform.protocol import Share


class LoadFrame(Protocol):
    """The load's motion as the robot knows it: what brings a vector of the load to the
    current instant (Steps 1 and 3)."""

    instant: int
    """The current instant (the one the update is for)."""

    def turned_since(self, instant: int) -> float:
        """The load's rotation (rad) from ``instant`` to the current instant."""
        ...

    def relative_position(self, j: int) -> Vec2 | None:
        """``z_ij`` in ``W`` at the current instant, ``None`` while unknown."""
        ...


_NUMBER, _VECTOR, _TURNING = 0, 1, 2

Inputs = Callable[[Vec2], Sequence[float]]
"""A robot's inputs of the ``MEAN`` quantities (one number per component, declaration order),
given its offsets iterate ``x_i``."""


class TeamConsensus:
    """One robot's states of the flow-form team quantities (see the module docstring).

    The first flow-form quantity must be the ``OFFSETS`` one (Step 2's ``x_i``); the others
    are ``MEAN``. :attr:`state` holds every declared quantity (the others at their defaults
    unless set by their own consensus), ready to be shared."""

    def __init__(
        self,
        robot: int,
        neighbours: Sequence[int],
        inputs: Inputs,
        quantities: Sequence[TeamQuantity] = TEAM_QUANTITIES,
    ):
        self.robot = robot
        self.neighbours = tuple(neighbours)
        self.degree = len(self.neighbours)
        self.quantities = tuple(quantities)
        self.inputs = inputs
        """This robot's inputs of the means, as a function of ``x_i``."""
        self.flowing = tuple(q for q in self.quantities if q.flows)
        if not self.flowing or self.flowing[0].averaging is not Averaging.OFFSETS:
            raise ValueError("the first flow-form quantity must be the offsets (Step 2)")
        if any(q.averaging is Averaging.OFFSETS for q in self.flowing[1:]):
            raise ValueError("one offsets quantity")
        self._state_type = consensus_state_type(self.quantities)
        self._index = {q.name: i for i, q in enumerate(self.quantities)}
        self._slots = tuple(self._index[q.name] for q in self.flowing)
        """Where each flow-form quantity is in :attr:`state`."""
        self._plan = tuple(
            (slot, _NUMBER if q.shape == 1 else _TURNING if q.turns else _VECTOR)
            for q, slot in zip(self.flowing, self._slots)
        )
        """How to read each flow-form quantity from a neighbour's state."""
        self._start = {q.name: start for q, start in zip(self.flowing, _starts(self.flowing))}
        """Where each flow-form quantity starts in :attr:`values` (and in a flow)."""
        self._shape = {q.name: q.shape for q in self.flowing}
        width = sum(q.shape for q in self.flowing)
        self._width = width
        self._zero = (0.0,) * width
        self._turning_offsets = tuple(
            start for q, start in zip(self.flowing, _starts(self.flowing)) if q.turns
        )
        """Where the vectors that turn with the load start in a flow."""
        self.flows: dict[int, tuple[float, ...]] = dict.fromkeys(self.neighbours, self._zero)
        """``F_ij`` per neighbour ``j``: the flow-form quantities' numbers, declaration order."""
        self.values: list[float] = flatten([q.initial for q in self.flowing], self.flowing)
        """The flow-form quantities' states, their components in place (``x_i`` first)."""
        self._other = {i: q.initial for i, q in enumerate(self.quantities) if not q.flows}
        """The other quantities' states (set by their own consensus: :meth:`set`)."""
        self._c, self._s = 1.0, 0.0
        self._adopted: dict[int, int] = {}
        """The tick of the message of each neighbour ``j`` whose ``F_ji`` was adopted last."""

    # ------------------------------------------------------------------ reading
    @property
    def centroid(self) -> Vec2:
        """``x_i`` → ``z_i``, in ``W`` at the last update's instant."""
        return (self.values[0], self.values[1])

    def __getitem__(self, name: str):
        """The state of quantity ``name``."""
        start = self._start.get(name)
        if start is None:
            return self._other[self._index[name]]
        v = self.values
        return v[start] if self._shape[name] == 1 else (v[start], v[start + 1])

    def set(self, name: str, value) -> None:
        """The state of a quantity that another consensus runs (``LEVEL``, ``OWN``)."""
        i = self._index[name]
        if i not in self._other:
            raise KeyError(f"{name} runs in this consensus")
        self._other[i] = value

    @property
    def state(self):
        """Every declared quantity's state, as shared
        (:class:`~agent.platform.team.ConsensusState`)."""
        flowing = self._grouped()
        values = list(self._other.get(i) for i in range(len(self.quantities)))
        for slot, value in zip(self._slots, flowing):
            values[slot] = value
        return self._state_type(*values)

    def shared_flows(self) -> tuple[tuple[float, ...], ...]:
        """``(j, F…)`` per neighbour ``j``: the flows a message carries."""
        return tuple((j, *f) for j, f in self.flows.items())

    def _grouped(self) -> list:
        out, i = [], 0
        v = self.values
        for q in self.flowing:
            out.append(v[i] if q.shape == 1 else (v[i], v[i + 1]))
            i += q.shape
        return out

    # ------------------------------------------------------------------ one iteration
    def update(self, turn: float, shares: Mapping[int, Share], frame: LoadFrame) -> None:
        """One iteration at ``frame.instant``, ``turn`` (rad) after the previous one, on the
        neighbours' latest messages ``shares`` (by sender: their ``team`` states, and
        ``flows`` holding ``F_ji``). The iteration advances one step per update."""
        self._turn(turn)
        flows = self.flows
        adopted = self._adopted
        for j, s in shares.items():
            if adopted.get(j) != s.tick:  # a message not heard before: F_ij = −F_ji
                adopted[j] = s.tick
                for flow in s.flows:
                    if flow[0] == self.robot:
                        since = frame.turned_since(s.instant)
                        flows[j] = tuple(map(neg, self._rotated(flow[1:], since)))
        out = self._outflow()
        values = self._of(out, self.inputs((-out[0], -out[1])))
        previous = frame.instant - 1
        read = self._read
        for j in self.neighbours:
            s = shares.get(j)
            if s is None:
                continue
            a = metropolis_weight(self.degree, s.degree)
            if s.instant == previous:  # usually one tick old: turned by this update's turn
                c, sn = self._c, self._s
            else:
                since = frame.turned_since(s.instant)
                c, sn = math.cos(since), math.sin(since)
            z = frame.relative_position(j) or (0.0, 0.0)
            delta = list(map(sub, read(s.consensus, c, sn), values))
            delta[0] += z[0]
            delta[1] += z[1]
            delta = [a * d for d in delta]
            flows[j] = tuple(map(sub, flows[j], delta))
            out = list(map(sub, out, delta))
        self.values = self._of(out, self.inputs((-out[0], -out[1])))

    def _read(self, state: Sequence, c: float, s: float) -> list[float]:
        """A neighbour's flow-form states, flat in declaration order, its vectors of the load
        turned by the angle whose cosine and sine are ``c`` and ``s``."""
        theirs: list[float] = []
        for slot, kind in self._plan:
            value = state[slot]
            if kind == _NUMBER:
                theirs.append(value)
            elif kind == _VECTOR:
                theirs.extend(value)
            else:  # a vector of the load, turned to this instant
                x, y = value
                theirs += (c * x - s * y, s * x + c * y)
        return theirs

    def _of(self, out: Sequence[float], inputs: Sequence[float]) -> list[float]:
        """The states from the outflows: ``x_i = −Σ F``, then each mean's ``r_i − Σ F``."""
        return [-out[0], -out[1], *(r - f for r, f in zip(inputs, out[2:]))]

    def _outflow(self) -> list[float]:
        """``Σ_j F_ij``."""
        return list(map(sum, zip(self._zero, *self.flows.values())))

    def _turn(self, angle: float) -> None:
        """Turn the flows' vectors of the load with it (they live in the co-rotating frame)."""
        self._c, self._s = math.cos(angle), math.sin(angle)
        if angle:
            for j, f in self.flows.items():
                self.flows[j] = self._rotated(f, angle, (self._c, self._s))

    def _rotated(self, flow: Sequence[float], angle: float, cs=None) -> tuple[float, ...]:
        """``flow`` with its vectors of the load turned by ``angle``."""
        out = list(flow)
        if cs is None:
            for k in self._turning_offsets:
                out[k], out[k + 1] = rotate((flow[k], flow[k + 1]), angle)
        else:
            c, s = cs
            for k in self._turning_offsets:
                x, y = flow[k], flow[k + 1]
                out[k], out[k + 1] = c * x - s * y, s * x + c * y
        return tuple(out)

    def turned(self, v: Vec2) -> Vec2:
        """``v`` turned by the angle of the last update's turn."""
        c, s = self._c, self._s
        return (c * v[0] - s * v[1], s * v[0] + c * v[1])


def _starts(quantities: Sequence[TeamQuantity]) -> list[int]:
    """Where each quantity's numbers start in a flow."""
    out, i = [], 0
    for q in quantities:
        out.append(i)
        i += q.shape
    return out
