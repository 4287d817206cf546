"""The team's shared quantities, declared once.

Every quantity the robots agree on by consensus is one :class:`TeamQuantity` in
:data:`TEAM_QUANTITIES`: its name, its shape (a number or a planar vector), the bound of its
domain and how the team averages it. Everything else follows from the declaration:

- the consensus part of each :class:`~agent.platform.protocol.Share` (its :class:`ConsensusState`,
  one field per quantity) and, for the quantities averaged in flow form, one flow per edge
  (:func:`flow_width` numbers after the neighbour's id);
- the share's wire layout, its layout code (:func:`layout_code`, checked on decoding: robots
  that declare different quantities refuse each other's shares) and its domain checks
  (:func:`check_state`);
- the flow-form iteration that runs them (:mod:`agent.algorithm.estimation.team_consensus`).

A family of estimators gives each quantity it uses an input (what the robot contributes) and
reads its state; the others keep their defaults.
"""

from __future__ import annotations

import enum
import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

MAX_DISTANCE = 10_000.0
"""m, a position or offset shared between agents."""
MAX_FLOW = 1e9
"""What has flowed on an edge of the consensus iterations (m, m² and gains)."""
MAX_FORCE = 1000.0
"""N, a force shared between agents (a tuning's ``max_force`` is at most this)."""
MAX_GAIN = 100.0
"""A drive's gain, or the team's mean gain as a consensus state."""
MAX_TURN_VARIANCE = 100.0
"""rad²: a robot's turn's variance over one instant, or the team's mean as a consensus state
(a turn measured from ``ż``'s direction alone has at most 1e-3)."""


class Averaging(enum.Enum):
    """How the team averages a quantity."""

    OFFSETS = "offsets"
    """Aragues et al. [10]: ``x_i ← x_i + Σ_j a_ij (x_j − x_i + z_ij)`` from ``x_i = 0``, whose
    fixed point is each robot's offset from the contacts' centroid (Step 2); flow form."""
    MEAN = "mean"
    """Average consensus with input tracking (eq. 16):
    ``ξ_i ← ξ_i + Σ_j a_ij (ξ_j − ξ_i) + (r_i⁺ − r_i)`` → the mean of the inputs ``r_i``;
    flow form (:mod:`agent.algorithm.estimation.team_consensus`), so lost messages do not
    bias it."""
    LEVEL = "level"
    """Consensus on a level that every robot also integrates on its own (the load's rotation,
    :mod:`agent.algorithm.robust.rotation`): sent modulo ``2π``."""
    OWN = "own"
    """Not averaged: the sender's own value, which its neighbours weigh its level by."""


FLOWING = (Averaging.OFFSETS, Averaging.MEAN)
"""The averagings run in flow form: their quantities have a flow on every edge."""


@dataclass(frozen=True)
class TeamQuantity:
    """One quantity the team averages (see the module docstring)."""

    name: str
    """The field of :class:`ConsensusState` (and so of the wire)."""
    shape: int
    """1: a number; 2: a planar vector ``(x, y)`` in ``W`` at the sender's estimation instant."""
    bound: float
    """Its domain: ``|value| ≤ bound`` (a vector's length); what arrives outside is refused."""
    averaging: Averaging
    turns: bool = False
    """A vector of the load: turned with it, like the iterates of Step 2."""
    default: float = 0.0
    """Every component's value before the robot has one (and for families that do not use it)."""
    doc: str = ""

    def __post_init__(self) -> None:
        if self.shape not in (1, 2) or (self.turns and self.shape != 2):
            raise ValueError(f"team quantity {self.name}: shape 1 or 2, turning only if 2")

    @property
    def initial(self) -> float | tuple[float, float]:
        """The value before the robot has one."""
        return self.default if self.shape == 1 else (self.default, self.default)

    @property
    def flows(self) -> bool:
        """Whether it is averaged in flow form (a flow per edge)."""
        return self.averaging in FLOWING


TEAM_QUANTITIES: tuple[TeamQuantity, ...] = (
    TeamQuantity(
        "centroid_offset",
        2,
        MAX_DISTANCE,
        Averaging.OFFSETS,
        turns=True,
        doc="x_i → z_i = p_Ci − p_G, Step 2's iterate",
    ),
    TeamQuantity(
        "mean_square_offset",
        1,
        MAX_DISTANCE**2,
        Averaging.MEAN,
        doc="ξ_i → w / n = Σ‖z_i‖² / n (eq. 16), input ‖x_i‖²",
    ),
    TeamQuantity(
        "mean_gain",
        1,
        MAX_GAIN,
        Averaging.MEAN,
        default=1.0,
        doc="γ_i → ḡ, the drives' mean gain (robust estimators), input g_i",
    ),
    TeamQuantity(
        "mean_gain_offset",
        2,
        MAX_GAIN * MAX_DISTANCE,
        Averaging.MEAN,
        turns=True,
        doc="η_i → h = Σ g_j z_j / n, input g_i x_i",
    ),
    TeamQuantity(
        "mean_gain_square_offset",
        1,
        MAX_GAIN * MAX_DISTANCE**2,
        Averaging.MEAN,
        doc="κ_i → q = Σ g_j ‖z_j‖² / n, input g_i ‖x_i‖²",
    ),
    TeamQuantity(
        "mean_mass_information",
        1,
        MAX_FLOW,
        Averaging.MEAN,
        doc="ι_i → the robots' mean mass-fit information ι (robust Step 7)",
    ),
    TeamQuantity(
        "mean_weighted_mass",
        1,
        MAX_FLOW,
        Averaging.MEAN,
        doc="μ_i → the mean of ι_j m_j: the team's mass is μ / ι",
    ),
    TeamQuantity(
        "mean_weighted_log_mass",
        1,
        MAX_FLOW,
        Averaging.MEAN,
        doc="λ_i → the mean of ι_j ln m_j (m in kg; robust Step 7)",
    ),
    TeamQuantity(
        "mean_weighted_square_log_mass",
        1,
        MAX_FLOW,
        Averaging.MEAN,
        doc="ψ_i → the mean of ι_j (ln m_j)²: with λ and ι, how far the robots' fits are apart",
    ),
    TeamQuantity(
        "mean_spin_torque",
        1,
        MAX_FORCE * MAX_DISTANCE,
        Averaging.MEAN,
        doc="τ_i → the robots' mean torque about the centroid in Step 1's spin-up (N m,"
        " robust): n times it is the floor's friction torque once the turn is steady",
    ),
    TeamQuantity(
        "mean_kick_level",
        1,
        MAX_FORCE,
        Averaging.MEAN,
        doc="A_i → the robots' mean kick size in Step 1 (N, robust): the spin-up's gain on"
        " every robot, so that each edge's two terms cancel",
    ),
    TeamQuantity(
        "mean_com_weight",
        1,
        MAX_GAIN,  # (a mean's states overshoot its inputs' range while they converge)
        Averaging.MEAN,
        doc="ζ_i → the share of robots with a z_C of their own (robust Steps 5 and 7),"
        " input 1 or 0",
    ),
    TeamQuantity(
        "mean_weighted_com",
        2,
        MAX_DISTANCE,
        Averaging.MEAN,
        turns=True,
        doc="ψ_i → the mean of ζ_j ẑ_C,j: the team's z_C is it over ζ (robust)",
    ),
    TeamQuantity(
        "rotation",
        1,
        math.pi,
        Averaging.LEVEL,
        doc="θ_i, the load's rotation at the sender's instant, modulo 2π (robust)",
    ),
    TeamQuantity(
        "rotation_weight",
        1,
        MAX_DISTANCE**2,
        Averaging.OWN,
        doc="w_i, the weight of the sender's turns in the team's level: the spread D_i of its"
        " neighbourhood's contacts (m², robust)",
    ),
    TeamQuantity(
        "mean_turn_variance",
        1,
        MAX_TURN_VARIANCE,
        Averaging.MEAN,
        doc="ν_i → the robots' mean turn variance (rad², robust), input Var(δ_i)",
    ),
)
"""The team's quantities, in wire order."""


def consensus_state_type(quantities: Sequence[TeamQuantity] = TEAM_QUANTITIES) -> type:
    """The immutable record of one robot's states of ``quantities`` (a typed named tuple:
    fields by name, in declaration order, each a ``float`` or a ``tuple[float, float]``; every
    field defaults to its quantity's initial value)."""
    names = [q.name for q in quantities]
    if len(set(names)) != len(names):
        raise ValueError(f"team quantities named twice: {names}")
    fields = [(q.name, float if q.shape == 1 else tuple[float, float]) for q in quantities]
    record = NamedTuple("ConsensusState", fields)
    record.__new__.__defaults__ = tuple(q.initial for q in quantities)
    record.__doc__ = "One robot's states of the team's quantities: " + ", ".join(names) + "."
    return record


ConsensusState = consensus_state_type(TEAM_QUANTITIES)
"""One robot's states of :data:`TEAM_QUANTITIES` (``Share.team``)."""


def width(quantities: Sequence[TeamQuantity]) -> int:
    """How many numbers the states of ``quantities`` are."""
    return sum(q.shape for q in quantities)


def flow_width(quantities: Sequence[TeamQuantity] = TEAM_QUANTITIES) -> int:
    """How many numbers an edge's flow is (its neighbour's id not counted)."""
    return sum(q.shape for q in quantities if q.flows)


def flatten(state: Sequence, quantities: Sequence[TeamQuantity]) -> list[float]:
    """The numbers of ``state``, vectors' components in place."""
    out: list[float] = []
    for q, value in zip(quantities, state):
        if q.shape == 1:
            out.append(value)
        else:
            out.extend(value)
    return out


def grouped(numbers: Sequence[float], quantities: Sequence[TeamQuantity]) -> list:
    """The inverse of :func:`flatten`: each quantity's value from ``numbers``."""
    out, i = [], 0
    for q in quantities:
        out.append(numbers[i] if q.shape == 1 else (numbers[i], numbers[i + 1]))
        i += q.shape
    return out


def layout_code(quantities: Sequence[TeamQuantity] = TEAM_QUANTITIES) -> int:
    """A 16-bit code of the quantities' names, shapes and averagings, in order: robots whose
    declarations differ cannot read each other's shares, and say so."""
    text = ";".join(f"{q.name}:{q.shape}:{q.averaging.value}" for q in quantities)
    return zlib.crc32(text.encode()) & 0xFFFF


def check_state(state: Sequence, quantities: Sequence[TeamQuantity], where: str) -> str | None:
    """The first value of ``state`` outside its quantity's domain, as ``"where.name = v is
    ..."``; ``None`` if every value is within."""
    for q, value in zip(quantities, state):
        size = abs(value) if q.shape == 1 else math.hypot(value[0], value[1])
        if not size <= q.bound:
            return f"{where}.{q.name} = {value!r} is outside its bound {q.bound:g}"
    return None
