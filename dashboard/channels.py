"""A team's Zenoh keys as typed channels, and protocol messages as JSON records.

Every key and payload is :mod:`agent.platform.protocol`'s: :func:`kind_of` tells which message class
a key carries by asking :class:`~agent.platform.protocol.Keys` for the keys it knows, and a payload
becomes a message only through :func:`agent.platform.protocol.decode` (which checks every field's
domain).

Recordings (:mod:`dashboard.recorder`) store each message as a JSON object with every field of
its dataclass, as the protocol's JSON messages are on the wire (pairs as arrays, phases by name,
integer map keys as strings), under a JSON schema derived from the dataclass, so that the files
open in Foxglove and PlotJuggler with named fields. :func:`from_record` reads one back through
the protocol again: a recording is as untrusted as the network.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import json
import types
import typing
from collections.abc import Callable

from agent.platform import protocol
from agent.platform.config import ConfigError, from_table
from agent.platform.protocol import (
    BridgeStatus,
    Clock,
    Command,
    Control,
    DecodeError,
    Estimates,
    Keys,
    LoadGeometry,
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
def _json_value(value):
    if isinstance(value, enum.Enum):
        return value.name.lower()
    if dataclasses.is_dataclass(value):
        return to_record(value)
    if isinstance(value, tuple) and hasattr(value, "_asdict"):  # a typed named tuple
        return {k: _json_value(v) for k, v in value._asdict().items()}
    if isinstance(value, dict):
        return {str(k): _json_value(v) for k, v in value.items()}
    if isinstance(value, (tuple, list)):
        return [_json_value(v) for v in value]
    return value


def to_record(message: object) -> dict:
    """``message`` as a JSON object: every field, as the protocol's JSON messages have them."""
    return {f.name: _json_value(getattr(message, f.name)) for f in dataclasses.fields(message)}


def record_bytes(message: object) -> bytes:
    """:func:`to_record` as compact UTF-8 JSON."""
    return json.dumps(to_record(message), allow_nan=False, separators=(",", ":")).encode()


def _no_constants(name: str):
    raise ValueError(f"{name} is not a number")


def from_record(kind: type, data: bytes):
    """The message of class ``kind`` recorded as ``data`` (:func:`record_bytes`), checked as
    the protocol checks what arrives over the network (every field present and typed, numbers
    finite, each field's domain: :data:`agent.platform.protocol.DOMAINS`); :class:`DecodeError`
    if it is not one."""
    name = kind.__name__
    try:
        table = json.loads(data, parse_constant=_no_constants)
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        raise DecodeError(f"{name}: not JSON ({err})") from None
    if not isinstance(table, dict) or set(table) != _FIELDS[kind]:
        raise DecodeError(f"{name}: not an object with the fields of {name}")
    try:
        message = from_table(kind, table, name)
    except (ConfigError, TypeError, RecursionError) as err:
        raise DecodeError(str(err)) from None
    protocol.DOMAINS[kind](message)
    return message


_FIELDS = {kind: {f.name for f in dataclasses.fields(kind)} for kind in MESSAGE_KINDS}


# ------------------------------------------------------------------------------ JSON schemas
def _schema_of(tp) -> dict:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if tp is float:
        return {"type": "number"}
    if tp is int:
        return {"type": "integer"}
    if tp is bool:
        return {"type": "boolean"}
    if tp is str:
        return {"type": "string"}
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return {"type": "string", "enum": [m.name.lower() for m in tp]}
    if dataclasses.is_dataclass(tp) or (isinstance(tp, type) and hasattr(tp, "_fields")):
        hints = typing.get_type_hints(tp, vars(protocol))
        if dataclasses.is_dataclass(tp):
            names = [f.name for f in dataclasses.fields(tp)]
        else:
            names = list(tp._fields)
        return {
            "type": "object",
            "properties": {name: _schema_of(hints[name]) for name in names},
            "required": list(names),
            "additionalProperties": False,
        }
    if origin in (typing.Union, types.UnionType) and set(args) == {int, float}:
        return {"type": "number"}  # a flow: the neighbour's id, then numbers
    if origin in (typing.Union, types.UnionType):
        (option,) = [a for a in args if a is not type(None)]  # X | None, as the protocol has
        schema = _schema_of(option)
        return {**schema, "type": [schema["type"], "null"]}
    if origin is dict:
        return {"type": "object", "additionalProperties": _schema_of(args[1])}
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return {"type": "array", "items": _schema_of(args[0])}
        items = [_schema_of(a) for a in args]  # a pair, or a flow (j, F_x, F_y, F_s)
        same = all(item == items[0] for item in items)
        return {
            "type": "array",
            "items": items[0] if same else {"type": "number"},
            "minItems": len(args),
            "maxItems": len(args),
        }
    raise TypeError(f"no JSON schema for {tp!r}")


def json_schema(kind: type) -> dict:
    """The JSON schema (2020-12) of :func:`to_record`'s objects of class ``kind``, with each
    field's description where the dataclass documents it."""
    hints = typing.get_type_hints(kind, vars(protocol))
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": f"heft.{kind.__name__}",
        "description": " ".join((kind.__doc__ or "").split()),
        "type": "object",
        "properties": {f.name: _schema_of(hints[f.name]) for f in dataclasses.fields(kind)},
        "required": [f.name for f in dataclasses.fields(kind)],
        "additionalProperties": False,
    }
