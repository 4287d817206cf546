"""Typed configuration: frozen dataclasses filled from TOML tables.

:func:`from_table` is the one way the project turns a TOML table into a dataclass: unknown
keys, missing required keys and values of the wrong type raise :class:`ConfigError` with a
message that names the key (``where.key``) and what was expected.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import math
import tomllib
import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")
MAX_ROBOTS = 32
"""The largest team supported: in one process, and over Zenoh with every process on one
2-core machine (16 robots stepped at 1.3x real time in lockstep there)."""


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


Key = str | tuple
"""Where a value is, for an error message: a name, or ``(parent, suffix)`` with a ``str``
suffix (``.field``) or an ``int`` one (``[i]``); joined by :func:`_key` only when an error is
raised, so that a value that is fine costs no string formatting."""


def _key(key: Key) -> str:
    suffixes = []
    while isinstance(key, tuple):
        key, suffix = key
        suffixes.append(suffix if isinstance(suffix, str) else f"[{suffix}]")
    return key + "".join(reversed(suffixes))


Coercer = typing.Callable[[Any, Key], Any]


@functools.cache
def _coercer(tp: Any) -> Coercer:
    """The function that checks and converts a value for the annotation ``tp``, built once
    per annotation: every decoded JSON message goes through these, field by field."""
    if dataclasses.is_dataclass(tp):
        return lambda value, key: _from_table(tp, value, key)
    if isinstance(tp, type) and issubclass(tp, tuple) and hasattr(tp, "_fields"):
        return _named_tuple_coercer(tp)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return _enum_coercer(tp)
    origin = typing.get_origin(tp)
    if origin is dict:
        return _dict_coercer(*typing.get_args(tp))
    if origin in (typing.Union, types.UnionType):
        return _union_coercer(tp)
    if origin is tuple:
        return _tuple_coercer(tp)
    scalar = _SCALARS.get(tp)
    if scalar is None:
        raise TypeError(f"unsupported annotation {tp!r}")
    return scalar


def _named_tuple_coercer(tp: type) -> Coercer:
    """A typed named tuple from a table of its fields (each present, each checked)."""
    hints = typing.get_type_hints(tp)
    items = [(name, _coercer(hints[name])) for name in tp._fields]

    def check(value: Any, key: Key) -> Any:
        if not isinstance(value, dict):
            raise ConfigError(f"{_key(key)}: expected a table, got {value!r}")
        if value.keys() != set(tp._fields):
            raise ConfigError(f"{_key(key)}: expected the keys {', '.join(tp._fields)}")
        return tp(*[item(value[name], (key, f".{name}")) for name, item in items])

    return check


def _enum_coercer(tp: type[enum.Enum]) -> Coercer:
    names = {m.name.lower(): m for m in tp}

    def check(value: Any, key: Key) -> Any:
        if isinstance(value, str) and value in names:
            return names[value]
        raise ConfigError(f"{_key(key)}: expected one of {', '.join(names)}, got {value!r}")

    return check


def _dict_coercer(key_type: Any, value_type: Any) -> Coercer:
    item = _coercer(value_type)

    def check(value: Any, key: Key) -> Any:
        if not isinstance(value, dict):
            raise ConfigError(f"{_key(key)}: expected a table, got {value!r}")
        out = {}
        for k, v in value.items():
            if key_type is int:
                if not (isinstance(k, str) and k.isascii() and k.isdigit() and len(k) < 20):
                    raise ConfigError(f"{_key(key)}: expected integer keys, got {k!r}")
                k = int(k)
                out[k] = item(v, (key, k))
            else:
                out[k] = item(v, (key, f"[{k}]"))
        return out

    return check


def _union_coercer(tp: Any) -> Coercer:
    args = typing.get_args(tp)
    optional = type(None) in args
    choices = [_coercer(arg) for arg in args if arg is not type(None)]
    if optional and len(choices) == 1:  # X | None, the common case: no exception handling
        (only,) = choices

        def check_optional(value: Any, key: Key) -> Any:
            if value is None:
                return None
            try:
                return only(value, key)
            except ConfigError:
                expected = _type_name(tp)
                raise ConfigError(f"{_key(key)}: expected {expected}, got {value!r}") from None

        return check_optional

    def check(value: Any, key: Key) -> Any:
        if value is None and optional:
            return None
        for choice in choices:
            try:
                return choice(value, key)
            except ConfigError:
                pass
        raise ConfigError(f"{_key(key)}: expected {_type_name(tp)}, got {value!r}")

    return check


def _tuple_coercer(tp: Any) -> Coercer:
    args = typing.get_args(tp)
    if len(args) == 2 and args[1] is Ellipsis:
        item = _coercer(args[0])

        def check_all(value: Any, key: Key) -> Any:
            if not isinstance(value, (list, tuple)):
                raise ConfigError(f"{_key(key)}: expected {_type_name(tp)}, got {value!r}")
            return tuple([item(v, (key, i)) for i, v in enumerate(value)])

        return check_all
    items = [_coercer(arg) for arg in args]
    floats = all(item is _float for item in items)
    n = len(items)

    def check(value: Any, key: Key) -> Any:
        # The common case first: a vector of n finite floats (the protocol's every point);
        # x - x == 0.0 holds for every finite float and for no NaN or infinity.
        if floats and type(value) is list and len(value) == n:
            if n == 2:
                x, y = value
                if type(x) is float and type(y) is float and x - x == 0.0 and y - y == 0.0:
                    return (x, y)
            elif all(type(v) is float for v in value) and all(map(math.isfinite, value)):
                return tuple(value)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{_key(key)}: expected {_type_name(tp)}, got {value!r}")
        if len(items) != len(value):
            raise ConfigError(f"{_key(key)}: expected {len(items)} values, got {len(value)}")
        return tuple([c(v, (key, i)) for i, (c, v) in enumerate(zip(items, value))])

    return check


def _float(value: Any, key: Key) -> float:
    if isinstance(value, float) and math.isfinite(value):
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{_key(key)}: expected a number, got {value!r}")
    if not math.isfinite(value):
        raise ConfigError(f"{_key(key)}: expected a finite number, got {value!r}")
    return float(value)


def _int(value: Any, key: Key) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ConfigError(f"{_key(key)}: expected an integer, got {value!r}")
    return value


def _bool(value: Any, key: Key) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(f"{_key(key)}: expected true or false, got {value!r}")
    return value


def _str(value: Any, key: Key) -> str:
    if not isinstance(value, str):
        raise ConfigError(f"{_key(key)}: expected a string, got {value!r}")
    return value


_SCALARS: dict[Any, Coercer] = {float: _float, int: _int, bool: _bool, str: _str}


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    """``cls``'s resolved annotations (resolving them is most of a small table's cost, and
    every decoded protocol message is one: once per class)."""
    return typing.get_type_hints(cls)


@functools.cache
def _fields(cls: type) -> dict[str, dataclasses.Field]:
    return {f.name: f for f in dataclasses.fields(cls)}


def fields_of(cls: type) -> tuple[str, ...]:
    """The field names of dataclass ``cls``: the keys of its table."""
    return tuple(_fields(cls))


# The shapes of the fields that :func:`_from_table` checks inline (every decoded protocol
# message is mostly these; a value that does not fit its shape's common case goes to the
# field's coercer, which accepts or explains it).
_FLOAT, _INT, _OPTIONAL_FLOAT, _VECTOR, _OPTIONAL_VECTOR = 1, 2, 3, 4, 5
_SHAPES = {
    float: _FLOAT,
    int: _INT,
    float | None: _OPTIONAL_FLOAT,
    tuple[float, float]: _VECTOR,
    tuple[float, float] | None: _OPTIONAL_VECTOR,
}


@functools.cache
def _table_plan(cls: type) -> tuple[tuple[str, Coercer, str, bool, int], ...]:
    """Per field of dataclass ``cls``: its name, coercer, key suffix, whether it is required
    and its shape (0 unless one of :data:`_SHAPES`) (built once per class)."""
    hints = _hints(cls)
    return tuple(
        (
            name,
            _coercer(hints[name]),
            f".{name}",
            f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING,
            _SHAPES.get(hints[name], 0),
        )
        for name, f in _fields(cls).items()
    )


def read_toml(path: str | Path) -> dict[str, Any]:
    """The TOML file ``path`` as a dict; :class:`ConfigError` (one line) if it cannot be read
    or is not TOML."""
    try:
        return tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as err:
        raise ConfigError(f"{path}: cannot read ({err.strerror or err})") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ConfigError(f"{path}: not valid TOML: {err}") from None


def from_table(cls: type[T], table: Any, where: str) -> T:
    """Build dataclass ``cls`` from a TOML table; ``where`` prefixes key names in errors."""
    return _from_table(cls, table, where)


def _from_table(cls: type[T], table: Any, where: Key) -> T:
    if not isinstance(table, dict):
        raise ConfigError(f"{_key(where)}: expected a table, got {table!r}")
    if not table.keys() <= _fields(cls).keys():
        unknown = sorted(set(table) - set(_fields(cls)))
        moved = getattr(cls, "MOVED_KEYS", {}).get(unknown[0])
        if moved is not None:
            raise ConfigError(
                f"{_key(where)}.{unknown[0]}: this key lives in the {moved!r} table now:"
                f" {_key(where)}.{moved}.{unknown[0]}"
            )
        raise ConfigError(
            f"{_key(where)}.{unknown[0]}: unknown key (expected one of: {', '.join(_fields(cls))})"
        )
    values = {}
    for name, check, suffix, required, shape in _table_plan(cls):
        if name in table:
            v = table[name]
            # x - x == 0.0 holds for every finite float and for no NaN or infinity; an int
            # here is never a bool (type(True) is bool).
            if shape:
                if shape == _FLOAT or (shape == _OPTIONAL_FLOAT and v is not None):
                    if type(v) is float and v - v == 0.0:
                        values[name] = v
                        continue
                elif shape == _INT:
                    if type(v) is int:
                        values[name] = v
                        continue
                elif v is None and shape != _VECTOR:
                    values[name] = None
                    continue
                elif shape >= _VECTOR and type(v) is list and len(v) == 2:
                    x, y = v
                    if type(x) is float and type(y) is float and x - x == 0.0 and y - y == 0.0:
                        values[name] = (x, y)
                        continue
            values[name] = check(v, (where, suffix))
        elif required:
            hint = _type_name(_hints(cls)[name])
            raise ConfigError(f"{_key(where)}{suffix}: missing (expected {hint})")
    obj = cls(**values)
    validate = getattr(obj, "validate", None)
    if validate is not None:
        validate(_key(where))
    return obj


# ------------------------------------------------------------------------------ ranges
MAX_SEED = 2**63 - 1
"""The largest seed: every seed is in ``[0, 2**63 - 1]``."""


def _number(value: float) -> str:
    """A bound as messages and docs/configuration.md write it: 3600, 0.1, 1e-08, 6.28319,
    2**63 - 1."""
    if value == MAX_SEED:
        return "2**63 - 1"
    if isinstance(value, int) or (float(value).is_integer() and abs(value) < 1e16):
        return str(int(value))
    return f"{value:g}"


@dataclass(frozen=True)
class Bound:
    """A field's documented range: ``low <= value <= high`` (``low < value`` if ``open_low``),
    or exactly ``off`` when that is given (a setting that this value switches off).
    ``min_ticks``: the lower end is also that many sensor periods, checked by
    :func:`check_ticks` where the period is known."""

    low: float
    high: float
    unit: str = ""
    open_low: bool = False
    off: float | None = None
    min_ticks: float = 0.0

    def text(self, low: float | None = None) -> str:
        """The range as messages and docs/configuration.md write it: ``(0, 1000] N``,
        ``[1 tick, 60] s``, ``0 (off) or [10 ticks, 3600] s``; ``low``, if given, replaces the
        lower end."""
        if low is not None:
            start = f"[{_number(low)}"
        elif self.min_ticks:
            start = "[1 tick" if self.min_ticks == 1 else f"[{_number(self.min_ticks)} ticks"
        else:
            start = f"{'(' if self.open_low else '['}{_number(self.low)}"
        interval = f"{start}, {_number(self.high)}]" + (f" {self.unit}" if self.unit else "")
        return interval if self.off is None else f"{_number(self.off)} (off) or {interval}"

    def contains(self, value: float, low: float | None = None) -> bool:
        """Whether ``value`` is in the range (with ``low`` as the lower end, if given)."""
        if self.off is not None and value == self.off:
            return True
        if low is not None:
            return low <= value <= self.high
        above = value > self.low if self.open_low else value >= self.low
        return above and value <= self.high  # NaN is neither

    def message(self, key: str, value: float, low: float | None = None, why: str = "") -> str:
        """``key: expected a number in RANGE[why], got VALUE``."""
        noun = "integer" if isinstance(value, int) and not isinstance(value, bool) else "number"
        if self.off is None and low is None and self.low == 0 and not self.min_ticks:
            kind = f"a positive {noun}" if self.open_low else f"a non-negative {noun}"
        else:
            kind = f"an {noun}" if noun == "integer" else f"a {noun}"
        interval = self.text(low)
        if self.off is not None:
            interval = interval.split(" or ", 1)[1]
            kind = f"{_number(self.off)} (off) or {kind}"
        return f"{key}: expected {kind} in {interval}{why}, got {value!r}"

    def check(self, key: str, value: float) -> None:
        """:class:`ConfigError` naming ``key`` and the range unless ``value`` is in it."""
        if not self.contains(value):
            raise ConfigError(self.message(key, value))


def bounded(
    default: Any,
    low: float,
    high: float,
    unit: str = "",
    *,
    open_low: bool = False,
    off: float | None = None,
    min_ticks: float = 0.0,
) -> Any:
    """A dataclass field with its default and its documented range (a :class:`Bound`),
    checked by :func:`check_bounds`, e.g.
    ``max_force: float = bounded(10.0, 0, 1000, "N", open_low=True)``."""
    bound = Bound(low, high, unit, open_low or bool(min_ticks and low == 0), off, min_ticks)
    return dataclasses.field(default=default, metadata={"bound": bound})


def bounds(cls: type) -> dict[str, Bound]:
    """The declared range of each field of dataclass ``cls`` that has one, by field name."""
    return {
        f.name: f.metadata["bound"]
        for f in dataclasses.fields(cls)  # type: ignore[arg-type]
        if "bound" in f.metadata
    }


def check_bounds(obj: Any, where: str) -> None:
    """:class:`ConfigError` naming ``where.key`` and its range for the first field of the
    dataclass ``obj`` outside its declared range."""
    for name, bound in bounds(type(obj)).items():
        bound.check(f"{where}.{name}", getattr(obj, name))


def check_ticks(obj: Any, where: str, period_s: float, rate: str) -> None:
    """The lower ends that count sensor ticks (``min_ticks``) of ``obj``'s fields, for a sensor
    period of ``period_s`` s; ``rate`` names where the period comes from, for the message."""
    for name, bound in bounds(type(obj)).items():
        if not bound.min_ticks:
            continue
        low = max(bound.low, bound.min_ticks * period_s)
        value = getattr(obj, name)
        if not bound.contains(value, low * (1 - 1e-9)):  # 1/30 s written as 0.0333333333
            ticks = "1 tick" if bound.min_ticks == 1 else f"{_number(bound.min_ticks)} ticks"
            why = f" (at least {ticks} of {_number(period_s)} s: {rate})"
            raise ConfigError(bound.message(f"{where}.{name}", value, low, why))


# ------------------------------------------------------------------------------ writing TOML
_ESCAPES = {
    '"': '\\"',
    "\\": "\\\\",
    "\b": "\\b",
    "\t": "\\t",
    "\n": "\\n",
    "\f": "\\f",
    "\r": "\\r",
}


def _toml_string(text: str) -> str:
    out = []
    for char in text:
        if char in _ESCAPES:
            out.append(_ESCAPES[char])
        elif ord(char) < 0x20 or ord(char) == 0x7F:
            out.append(f"\\u{ord(char):04x}")
        else:
            out.append(char)
    return '"' + "".join(out) + '"'


def toml_value(value: Any) -> str:
    """One TOML value: booleans, integers, floats (``repr``, exact), strings, arrays."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, enum.Enum):
        return _toml_string(value.name.lower())
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {value!r} as TOML")


def toml_fields(obj: Any, only_changed: bool = False) -> list[str]:
    """``key = value`` lines for a dataclass's fields (``None`` ones left out: TOML has no
    null, and reading the table back gives the default); ``only_changed``: those that differ
    from the defaults."""
    default = type(obj)() if only_changed else None
    return [
        f"{f.name} = {toml_value(getattr(obj, f.name))}"
        for f in dataclasses.fields(obj)
        if getattr(obj, f.name) is not None
        and not dataclasses.is_dataclass(getattr(obj, f.name))
        and (default is None or getattr(obj, f.name) != getattr(default, f.name))
    ]


def to_toml(obj: Any, comment: str = "") -> str:
    """TOML text that :func:`from_table` reads back to ``obj``: its plain fields, then one
    table per dataclass field (``[a]``, then ``[a.b]`` for one nested in it, and so on)."""
    lines = [f"# {line}" for line in comment.splitlines()] + toml_fields(obj)
    lines += toml_tables(obj)
    return "\n".join(lines) + "\n"


def toml_tables(obj: Any, prefix: str = "", only_changed: bool = False) -> list[str]:
    """The tables of ``obj``'s dataclass fields, depth first, named ``prefix`` + the field
    (``only_changed``: the fields that differ from the defaults, tables with none left out)."""
    lines: list[str] = []
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            fields = toml_fields(value, only_changed)
            if fields or not only_changed:
                lines += ["", f"[{prefix}{f.name}]", *fields]
            lines += toml_tables(value, f"{prefix}{f.name}.", only_changed)
    return lines
