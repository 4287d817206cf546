"""A team's Zenoh keys as typed channels, and protocol messages as JSON records.

Every key and payload is :mod:`agent.platform.protocol`'s: :func:`kind_of` tells which message class
a key carries by asking :class:`~agent.platform.protocol.Keys` for the keys it knows, and a payload
becomes a message only through :func:`agent.platform.protocol.decode` (which checks every field's
domain).

Recordings (:mod:`dashboard.recorder`) store each message as a JSON object under a JSON schema
derived from its dataclass (:func:`json_schema`), both within what Foxglove's JSON-schema support
reads, so that the files open in Foxglove and PlotJuggler with every field named. Record format
``2`` (:func:`to_record`) writes:

- every field by name; an optional one (``X | None``) absent when None, never ``null``;
- a vector ``{"x", "y"}``, a covariance ``{"xx", "xy", "yy"}``, a barrier's levels
  ``{"torque", "force"}``, a graph edge ``{"i", "j"}``;
- a map from ids (``dict[int, X]``) as an array of ``{"key", "value"}`` objects, by key;
- a share's flow ``(j, F…)`` as ``{"neighbour": j, "outflows": {quantity: F}}``;
- a phase by name (``"push"``).

Format ``1``, the protocol's JSON messages as they are on the wire (pairs as arrays, ``null``,
integer map keys as strings), is still read. :func:`from_record` reads either back through the
protocol again: a recording is as untrusted as the network.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import json
import types
import typing
from collections.abc import Callable

from agent.platform import protocol, team
from agent.platform.config import ConfigError, from_table
from agent.platform.geometry import Vec2
from agent.platform.protocol import (
    Barrier,
    BridgeStatus,
    Clock,
    Command,
    Control,
    Cov2,
    DecodeError,
    Estimates,
    Keys,
    LoadGeometry,
    LogLine,
    Measurement,
    PlantStatus,
    Share,
    Status,
    Truth,
)

MESSAGE_KINDS: tuple[type, ...] = tuple(protocol.KINDS)
"""Every message class of the protocol."""
ROBOT_KINDS: dict[type, Callable[[Keys, int], str]] = {
    Measurement: Keys.velocity,
    Command: Keys.force,
    Share: Keys.share,
    Estimates: Keys.estimate,
    Status: Keys.status,
    BridgeStatus: Keys.bridge,
    LogLine: Keys.log,
}
"""The per-robot message classes and the :class:`Keys` method of each one's key."""
TEAM_KINDS: dict[type, Callable[[Keys], str]] = {
    Clock: Keys.clock,
    Truth: Keys.truth,
    LoadGeometry: Keys.geometry,
    PlantStatus: Keys.plant_status,
    Control: Keys.control,
}
"""The team-wide message classes and the :class:`Keys` method of each one's key."""
_SENDER = {Share: "sender"}


def team_wildcard(keys: Keys) -> str:
    """Every key of the team (``heft/<team>/**``)."""
    return f"{keys.root}/**"


def kind_of(keys: Keys, key: str) -> type | None:
    """The message class carried on ``key`` of ``keys``' team, or None for a key that carries
    none (a liveliness token's, another team's, a malformed one)."""
    return _kind_on(keys.team, key)


@functools.lru_cache(maxsize=4096)
def _kind_on(team: str, key: str) -> type | None:
    """:func:`kind_of`, remembered: a team's few keys carry every message (a flood of other
    keys only evicts entries, bounded)."""
    keys = Keys(team)
    for kind, method in TEAM_KINDS.items():
        if key == method(keys):
            return kind
    try:
        robot = Keys.robot_of(key)
        for kind, method in ROBOT_KINDS.items():
            if key == method(keys, robot):
                return kind
    except (DecodeError, ValueError):
        return None
    return None


def robot_of(message: object) -> int | None:
    """The robot a per-robot message is about (a share's sender), None for team messages."""
    if type(message) not in ROBOT_KINDS:
        return None
    return getattr(message, _SENDER.get(type(message), "robot"))


def decode_on(keys: Keys, key: str, payload: bytes):
    """The message ``payload`` on ``key``: decoded and checked by the protocol, and a per-robot
    message only on its own robot's key. :class:`DecodeError` otherwise (count and drop it)."""
    kind = kind_of(keys, key)
    if kind is None:
        raise DecodeError(f"key {key!r} carries no message of team {keys.team!r}")
    message = protocol.decode(kind, payload)
    robot = robot_of(message)
    if robot is not None and key != ROBOT_KINDS[kind](keys, robot):
        raise DecodeError(f"{kind.__name__} of robot {robot} on key {key!r}")
    return message


# ------------------------------------------------------------------------------ JSON records
RECORD_FORMAT = "2"
"""The record format written (named in a recording's ``heft.team`` metadata)."""
RECORD_FORMATS = ("1", "2")
"""The record formats read: ``1`` is the protocol's JSON messages as they are on the wire
(pairs as arrays, ``null`` for what is not estimated, integer map keys as strings), the
recordings' format before the metadata named one."""
_NAMES: dict[object, tuple[str, ...]] = {Vec2: ("x", "y"), Cov2: ("xx", "xy", "yy")}
"""The names of a fixed tuple's numbers by its type: a pair of floats is a planar vector, a
triple of floats a covariance."""
_FIELD_NAMES: dict[tuple[type, str], tuple[str, ...]] = {
    (Barrier, "levels"): ("torque", "force"),
    (LoadGeometry, "edges"): ("i", "j"),
}
"""The names of a fixed tuple's numbers by the field that holds it (a pair of integers means
what its field says)."""


def _refuse(where: str, expected: str, value: object) -> DecodeError:
    shown = json.dumps(value)
    shown = shown if len(shown) <= 60 else shown[:57] + "..."
    return DecodeError(f"{where}: expected {expected}, got {shown}")


class _Form:
    """One annotation's form in a record: its JSON schema, a value's record (:meth:`record`)
    and, back, the protocol's JSON form of a record (:meth:`table`, what
    :func:`~agent.platform.config.from_table` reads and checks)."""

    schema: dict
    as_is = False
    """Whether :meth:`table` gives the record back as it is (a scalar: checked by
    :func:`~agent.platform.config.from_table`)."""

    def record(self, value):
        return value

    def table(self, value, where: str):
        return value


class _Scalar(_Form):
    as_is = True

    def __init__(self, json_type: str, **bounds: float):
        self.schema = {"type": json_type, **bounds}


class _Enum(_Form):
    """An enum by its member's name in lower case (a phase: ``"push"``)."""

    as_is = True

    def __init__(self, tp: type[enum.Enum]):
        self.schema = {"type": "string", "enum": [m.name.lower() for m in tp]}

    def record(self, value):
        return value.name.lower()


class _Object(_Form):
    """Named fields: a dataclass's or a named tuple's (``positional`` false: its fields by
    attribute, read back as a table), or a fixed tuple's (``positional``: its items in order,
    read back as a list). An optional field (``X | None``) is left out when None, and is not
    required."""

    def __init__(self, fields: list[tuple[str, _Form, bool]], positional: bool = False):
        self.fields = fields
        self.positional = positional
        self.names = {name for name, _, _ in fields}
        self.required = {name for name, _, optional in fields if not optional}
        self.order = [name for name, _, _ in fields]
        self.plain = positional and all(form.as_is for _, form, _ in fields)
        """A fixed tuple of scalars (a vector): read back as its items in order."""
        self.schema = {
            "type": "object",
            "properties": {name: form.schema for name, form, _ in fields},
            "required": [name for name, _, optional in fields if not optional],
            "additionalProperties": False,
        }

    def record(self, value) -> dict:
        items = value if self.positional else (getattr(value, name) for name, _, _ in self.fields)
        return {
            name: form.record(v)
            for (name, form, _), v in zip(self.fields, items, strict=True)
            if v is not None
        }

    def table(self, value, where: str):
        if type(value) is not dict:
            raise _refuse(where, "an object", value)
        keys = value.keys()
        if not self.required <= keys <= self.names:
            unknown, missing = sorted(keys - self.names), sorted(self.required - keys)
            expected = f"no field {unknown[0]!r}" if unknown else f"the field {missing[0]!r}"
            raise _refuse(where, expected, value)
        if self.plain:
            return [value[name] for name in self.order]
        out = {}
        for name, form, _ in self.fields:
            v = value.get(name)
            if v is None:
                if name in value:
                    raise _refuse(f"{where}.{name}", "a value (absent when there is none)", v)
                out[name] = None
            else:
                out[name] = v if form.as_is else form.table(v, f"{where}.{name}")
        return list(out.values()) if self.positional else out


class _Array(_Form):
    """A tuple of any length, as an array."""

    def __init__(self, item: _Form):
        self.item = item
        self.schema = {"type": "array", "items": item.schema}

    def record(self, value) -> list:
        return [self.item.record(v) for v in value]

    def table(self, value, where: str) -> list:
        if type(value) is not list:
            raise _refuse(where, "an array", value)
        if self.item.as_is:
            return value
        return [self.item.table(v, f"{where}[{i}]") for i, v in enumerate(value)]


class _Map(_Form):
    """A ``dict[int, X]``, as an array of ``{"key": k, "value": x}`` objects by key."""

    def __init__(self, value: _Form):
        self.value = value
        key = _Scalar("integer", minimum=0)
        self.entry = _Object([("key", key, False), ("value", value, False)])
        self.schema = {"type": "array", "items": self.entry.schema}

    def record(self, value) -> list:
        return [{"key": k, "value": self.value.record(v)} for k, v in sorted(value.items())]

    def table(self, value, where: str) -> dict:
        if type(value) is not list:
            raise _refuse(where, "an array", value)
        out = {}
        for i, item in enumerate(value):
            entry = self.entry.table(item, f"{where}[{i}]")
            key = entry["key"]
            if type(key) is not int or key < 0 or str(key) in out:
                raise _refuse(f"{where}[{i}].key", "an integer ≥ 0, each once", key)
            out[str(key)] = entry["value"]
        return out


class _Flows(_Form):
    """A share's flows ``(j, F…)`` as ``{"neighbour": j, "outflows": {quantity: F}}``: the
    outflows of the quantities averaged in flow form, by name (a vector's as ``x``, ``y``)."""

    def __init__(self):
        self.quantities = tuple(q for q in protocol.SHARE_WIRE.quantities if q.flows)
        self.outflows = _Object(
            [(q.name, _form(float if q.shape == 1 else Vec2), False) for q in self.quantities],
            positional=True,
        )
        self.flow = _Object(
            [("neighbour", _Scalar("integer"), False), ("outflows", self.outflows, False)]
        )
        self.schema = {"type": "array", "items": self.flow.schema}

    def record(self, value) -> list:
        width = team.flow_width(self.quantities)
        out = []
        for j, *outflows in value:
            if len(outflows) != width:
                raise ValueError(f"a flow of {len(outflows)} numbers, expected {width}")
            grouped = team.grouped(outflows, self.quantities)
            out.append({"neighbour": j, "outflows": self.outflows.record(grouped)})
        return out

    def table(self, value, where: str) -> list:
        if type(value) is not list:
            raise _refuse(where, "an array", value)
        out = []
        for i, item in enumerate(value):
            flow = self.flow.table(item, f"{where}[{i}]")
            j = flow["neighbour"]
            if type(j) is not int:
                raise _refuse(f"{where}[{i}].neighbour", "an integer", j)
            out.append([j, *team.flatten(flow["outflows"], self.quantities)])
        return out


_SCALARS = {float: "number", int: "integer", bool: "boolean", str: "string"}


@functools.cache
def _form(tp, names: tuple[str, ...] | None = None) -> _Form:
    """The form of annotation ``tp`` (``names``: a fixed tuple's, if its field names it)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp in _SCALARS:
        return _Scalar(_SCALARS[tp])
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return _Enum(tp)
    if dataclasses.is_dataclass(tp) or (isinstance(tp, type) and hasattr(tp, "_fields")):
        return _object_form(tp)
    if origin is dict and args[0] is int:
        return _Map(_form(args[1]))
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        return _Array(_form(args[0], names))
    if origin is tuple and len(names or _NAMES.get(tp, ())) == len(args):
        items = zip(names or _NAMES[tp], args, strict=True)
        return _Object([(name, _form(arg), False) for name, arg in items], positional=True)
    raise TypeError(f"no record form for {tp!r}")


@functools.cache
def _object_form(tp: type) -> _Object:
    """A dataclass's or a named tuple's fields by name; ``X | None`` ones optional."""
    hints = typing.get_type_hints(tp)
    names = [f.name for f in dataclasses.fields(tp)] if dataclasses.is_dataclass(tp) else tp._fields
    fields = []
    for name in names:
        hint = hints[name]
        args = typing.get_args(hint)
        optional = typing.get_origin(hint) in (typing.Union, types.UnionType) and type(None) in args
        if optional:
            (hint,) = [a for a in args if a is not type(None)]
        if (tp, name) == (Share, "flows"):
            fields.append((name, _Flows(), optional))
        else:
            fields.append((name, _form(hint, _FIELD_NAMES.get((tp, name))), optional))
    return _Object(fields)


def to_record(message: object) -> dict:
    """``message`` as a JSON object of the current record format: every field by name, an
    optional one absent when None, a vector ``{"x", "y"}``, a covariance ``{"xx", "xy",
    "yy"}``, a map from ids an array of ``{"key", "value"}`` objects, a phase by name."""
    return _object_form(type(message)).record(message)


def record_bytes(message: object) -> bytes:
    """:func:`to_record` as compact UTF-8 JSON."""
    return json.dumps(to_record(message), allow_nan=False, separators=(",", ":")).encode()


def _no_constants(name: str):
    raise ValueError(f"{name} is not a number")


def from_record(kind: type, data: bytes, record_format: str = RECORD_FORMAT):
    """The message of class ``kind`` recorded as ``data`` in ``record_format`` (one of
    :data:`RECORD_FORMATS`; :func:`record_bytes` writes the current one), checked as the
    protocol checks what arrives over the network (every field typed, none missing, numbers
    finite, each field's domain: :data:`agent.platform.protocol.DOMAINS`);
    :class:`DecodeError` if it is not one."""
    name = kind.__name__
    try:
        table = json.loads(data, parse_constant=_no_constants)
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        raise DecodeError(f"{name}: not JSON ({err})") from None
    if record_format == "1":
        if not isinstance(table, dict) or set(table) != _FIELDS[kind]:
            raise DecodeError(f"{name}: not an object with the fields of {name}")
    elif record_format == "2":
        table = _object_form(kind).table(table, name)
    else:
        raise ValueError(f"record format {record_format!r} is not one of {RECORD_FORMATS}")
    try:
        message = from_table(kind, table, name)
    except (ConfigError, TypeError, RecursionError) as err:
        raise DecodeError(str(err)) from None
    except OverflowError:  # an integer beyond a float's range, where a number is expected
        raise DecodeError(f"{name}: a number beyond a float's range") from None
    protocol.DOMAINS[kind](message)
    return message


_FIELDS = {kind: {f.name for f in dataclasses.fields(kind)} for kind in MESSAGE_KINDS}


def json_schema(kind: type) -> dict:
    """The JSON schema (2020-12) of :func:`to_record`'s objects of class ``kind``, described
    by the class's docstring. Within what Foxglove's JSON-schema support reads: objects with
    their properties, arrays of numbers or of objects, no ``null`` and no type unions."""
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": f"heft.{kind.__name__}",
        "description": " ".join((kind.__doc__ or "").split()),
        **_object_form(kind).schema,
    }
