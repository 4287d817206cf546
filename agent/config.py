"""Typed configuration: frozen dataclasses filled from TOML tables.

:func:`from_table` is the one way the project turns a TOML table into a dataclass: unknown
keys, missing required keys and values of the wrong type raise :class:`ConfigError` with a
message that names the key (``where.key``) and what was expected.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from dataclasses import dataclass
from typing import Any, TypeVar

T = TypeVar("T")


class ConfigError(ValueError):
    """A configuration value is missing, unknown or malformed. ``str()`` is one clear line."""


def _type_name(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if origin in (tuple, list):
        args = typing.get_args(tp)
        return f"a list of {_type_name(args[0])}" if args else "a list"
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_type_name(a) for a in typing.get_args(tp) if a is not type(None))
    return {float: "a number", int: "an integer", str: "a string", bool: "true or false"}.get(
        tp, getattr(tp, "__name__", str(tp))
    )


def coerce(value: Any, tp: Any, key: str) -> Any:
    """Check ``value`` against the annotation ``tp`` and convert it (lists become tuples)."""
    if dataclasses.is_dataclass(tp):
        return from_table(tp, value, key)
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        for arg in args:
            if arg is type(None):
                continue
            try:
                return coerce(value, arg, key)
            except ConfigError:
                pass
        raise ConfigError(f"{key}: expected {_type_name(tp)}, got {value!r}")
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{key}: expected {_type_name(tp)}, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(coerce(v, args[0], f"{key}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ConfigError(f"{key}: expected {len(args)} values, got {len(value)}")
        return tuple(coerce(v, a, f"{key}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{key}: expected a number, got {value!r}")
        if not math.isfinite(value):
            raise ConfigError(f"{key}: expected a finite number, got {value!r}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{key}: expected an integer, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key}: expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{key}: expected a string, got {value!r}")
        return value
    raise TypeError(f"unsupported annotation {tp!r} for {key}")


def from_table(cls: type[T], table: Any, where: str) -> T:
    """Build dataclass ``cls`` from a TOML table; ``where`` prefixes key names in errors."""
    if not isinstance(table, dict):
        raise ConfigError(f"{where}: expected a table, got {table!r}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(table) - set(fields))
    if unknown:
        raise ConfigError(
            f"{where}.{unknown[0]}: unknown key (expected one of: {', '.join(fields)})"
        )
    values = {}
    for name, f in fields.items():
        if name in table:
            values[name] = coerce(table[name], hints[name], f"{where}.{name}")
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(f"{where}.{name}: missing (expected {_type_name(hints[name])})")
    obj = cls(**values)
    check = getattr(obj, "validate", None)
    if check is not None:
        check(where)
    return obj


def positive(where: str, **values: float) -> None:
    """Raise :class:`ConfigError` unless every value is > 0."""
    for key, value in values.items():
        if not value > 0:
            raise ConfigError(f"{where}.{key}: expected a positive number, got {value!r}")


def non_negative(where: str, **values: float) -> None:
    """Raise :class:`ConfigError` unless every value is >= 0."""
    for key, value in values.items():
        if not value >= 0:
            raise ConfigError(f"{where}.{key}: expected a non-negative number, got {value!r}")


@dataclass(frozen=True)
class AgentTuning:
    """The gains and limits an agent runs with; the same for every robot of a team.

    The defaults are those of the paper's scenario (Sec. VI) and work for the generated ones.
    """

    max_force: float = 10.0
    """N: bound on every commanded force's magnitude (safety)."""
    filter_gain: float = 5.0
    """k_f (1/s), the low-pass filters of the Appendix."""
    regression_memory_s: float = 0.0
    """s: time constant of the least-squares regressions' forgetting (0 = never forget)."""
    kick_force: float = 2.0
    """N: magnitude of the seeded random push that starts Step 1."""
    kick_duration_s: float = 0.5
    spin_gain: float = 4.0
    """N s/m: gain k of the Step-1 spin-up ``f_i = k Σ_j c(‖ż_ij‖) ż_ij``."""
    spin_speed: float = 0.5
    """m/s: relative contact speed the Step-1 spin-up settles towards."""
    inertia_force: float = 2.0
    """N: largest per-robot force of Step 4 (``f_i = k z_i⊥`` with ``k = F/√w``)."""
    inertia_min_s: float = 2.0
    """s: shortest Step 4 (it also spins the load up for Step 5)."""
    inertia_max_omega: float = 1.0
    """rad/s: Step 4 brakes when |ω| reaches this and speeds up again below half of it."""
    push_fbar: float = 1.0
    """f̄_y (rad/s² per m) of Steps 5–7: each robot pushes with ``f = f̄_y Ĵ / n`` (Sec. VI) ..."""
    push_min_force: float = 1.0
    """N: ... but at least this much (a compact load's COM would barely accelerate for Step 7),
    and at most ``max_force``."""
    push_direction: tuple[float, float] = (0.0, 1.0)
    """Direction in ``W`` of the common force ``f`` of Steps 5–7."""
    observer_gain: float = 2.0
    """k_e of observer (24)."""
    settle_window_s: float = 1.0
    """s: an estimate has settled when it moved less than the tolerance over this window."""
    settle_tolerance: float = 1e-4
    """Relative change that counts as settled."""
    switch_margin_ticks: int = 10
    """Ticks added to ``n`` between the team agreeing on a phase switch and making it."""

    def validate(self, where: str) -> None:
        positive(
            where,
            max_force=self.max_force,
            filter_gain=self.filter_gain,
            kick_force=self.kick_force,
            kick_duration_s=self.kick_duration_s,
            spin_gain=self.spin_gain,
            spin_speed=self.spin_speed,
            inertia_force=self.inertia_force,
            inertia_max_omega=self.inertia_max_omega,
            push_fbar=self.push_fbar,
            push_min_force=self.push_min_force,
            observer_gain=self.observer_gain,
            settle_window_s=self.settle_window_s,
            settle_tolerance=self.settle_tolerance,
        )
        for key in ("kick_force", "inertia_force", "push_min_force"):
            if getattr(self, key) > self.max_force:
                raise ConfigError(f"{where}.{key}: must not exceed max_force ({self.max_force})")
        if math.hypot(*self.push_direction) == 0:
            raise ConfigError(f"{where}.push_direction: expected a nonzero vector")
        non_negative(
            where,
            inertia_min_s=self.inertia_min_s,
            regression_memory_s=self.regression_memory_s,
            switch_margin_ticks=self.switch_margin_ticks,
        )


@dataclass(frozen=True)
class AgentConfig:
    """Who one agent is: its id, the team size and its graph neighbours, plus the tuning."""

    robot: int
    n: int
    neighbours: tuple[int, ...]
    period_s: float
    seed: int = 1
    tuning: AgentTuning = AgentTuning()
