"""One validation layer for every setting a user types: typed config dataclasses with ranges.

Every settings dataclass of the project (``SolverCfg``, ``SRVNetCfg``, ``FCNNTrainCfg``, the job
configs of ``graspnet_torch.jobs.configs``...) declares its fields with :func:`setting`, which
records the allowed range or choices beside the default. :func:`build` turns a mapping (a Hydra
group as a dict, a YAML mapping) into the dataclass and refuses, with one line naming the key, the
value and what is allowed:

- unknown keys;
- a value of the wrong type: strict, a number is an ``int``/``float`` (never a bool or a string
  such as ``"0.03"``), an integer is an ``int`` (not ``2.0``), a string is a ``str``;
- a number that is not finite, or outside its range; a string outside its choices.

:func:`lookup` finds the type and range of a dotted key (``solver.threshold``) so that command-line
overrides are checked before Hydra composes anything (``graspnet_torch.jobs.cli``). Messages quote
at most a short prefix of a bad value (:func:`short`), however large it is.
"""

from __future__ import annotations

import dataclasses
import math
import re
import reprlib
import types
import typing
from collections.abc import Mapping, Sequence
from functools import cache
from typing import Any, Literal, TypeVar, Union

import yaml

from graspnet_torch.errors import ConfigError

__all__ = ["MAX_ANGLE_DEG", "MAX_LENGTH_M", "DefaultsFile", "Free", "build", "check_value", "clip", "lookup",
           "number_list", "setting", "short", "sync_defaults"]

T = TypeVar("T")

_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxlist, _REPR.maxtuple, _REPR.maxdict = 2, 4, 4, 4
_REPR.maxstring, _REPR.maxother, _REPR.maxlong = 40, 40, 24


def short(value: Any, limit: int = 60) -> str:
    """A bounded repr: at most ``limit`` characters, whatever the size or depth of ``value``."""
    try:
        text = _REPR.repr(value)
    except Exception:  # a hostile __repr__
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def clip(text: str, limit: int = 120) -> str:
    """A string for a one-line message: non-printable characters escaped, at most ``limit`` long."""
    text = str(text)[: limit * 4]
    if not text.isprintable():
        text = text.encode("unicode_escape").decode("ascii")
    return text if len(text) <= limit else text[: limit - 3] + "..."


class Free:
    """Marks a field whose value another parser validates (a task mapping, a robot config)."""


def setting(default: Any = dataclasses.MISSING, *, lo: float | None = None, hi: float | None = None,
            lo_open: bool = False, choices: Sequence[str] | None = None, factory: Any = None,
            doc: str = "") -> Any:
    """A dataclass field with its range: ``lo <= value <= hi`` (``lo < value`` with ``lo_open``),
    or one of ``choices``; for sequences the range applies to every element."""
    meta = {"lo": lo, "hi": hi, "lo_open": lo_open, "choices": tuple(choices) if choices else None, "doc": doc}
    if factory is not None:
        return dataclasses.field(default_factory=factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


@cache
def _fields(cls: type) -> dict[str, tuple[Any, Mapping[str, Any]]]:
    hints = typing.get_type_hints(cls)
    return {f.name: (hints[f.name], f.metadata) for f in dataclasses.fields(cls) if f.init}


def _num(v: float) -> str:
    if isinstance(v, int) or (float(v).is_integer() and abs(v) < 1e16):
        return str(int(v))
    return f"{v:g}"


def _describe(tp: Any, meta: Mapping[str, Any]) -> str:
    """What a field allows, in words: 'a number in [0, 1]', 'one of best, final', ..."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (Union, types.UnionType):
        parts = [_describe(a, meta) for a in args if a is not type(None)]
        return " or ".join(parts) + (" or null" if type(None) in args else "")
    if origin is Literal:
        return "one of " + ", ".join(map(str, args))
    if meta.get("choices"):
        return "one of " + ", ".join(meta["choices"])
    if origin in (tuple, list):
        inner = _describe(args[0], meta) if args else "anything"
        n = f"{len(args)} " if origin is tuple and args and args[-1] is not Ellipsis else ""
        return f"a list of {n}values, each {inner}"
    lo, hi = meta.get("lo"), meta.get("hi")
    name = {bool: "true or false", int: "an integer", float: "a number", str: "a string"}.get(tp, getattr(
        tp, "__name__", str(tp)))
    if tp in (int, float) and (lo is not None or hi is not None):
        if lo is not None and hi is not None:
            name += f" in {'(' if meta.get('lo_open') else '['}{_num(lo)}, {_num(hi)}]"
        elif lo is not None:
            name += f" {'>' if meta.get('lo_open') else '>='} {_num(lo)}"
        else:
            name += f" <= {_num(hi)}"
    return name


def _fail(key: str, value: Any, tp: Any, meta: Mapping[str, Any]) -> ConfigError:
    return ConfigError(f"{key}={short(value)}: expected {_describe(tp, meta)}")


def check_value(tp: Any, meta: Mapping[str, Any], value: Any, key: str) -> Any:
    """``value`` converted to ``tp`` (lists to tuples, ints to floats) or a :class:`ConfigError`."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is Any or tp is Free:
        return value
    if origin in (Union, types.UnionType):
        if value is None:
            if type(None) in args:
                return None
            raise _fail(key, value, tp, meta)
        options = [a for a in args if a is not type(None)]
        for a in options:  # the first that accepts it; bool never passes for a number
            try:
                return check_value(a, meta, value, key)
            except ConfigError:
                continue
        raise _fail(key, value, tp, meta)
    if dataclasses.is_dataclass(tp):
        if isinstance(value, bool) and "enabled" in _fields(tp):  # a switched group: reach=true = reach.enabled=true
            value = {"enabled": value}
        return build(tp, value, key)
    if origin is Literal:
        if value in args and not isinstance(value, bool):
            return value
        raise _fail(key, value, tp, meta)
    if origin in (tuple, list):
        if isinstance(value, str | bytes | Mapping) or not isinstance(value, Sequence):
            raise _fail(key, value, tp, meta)
        fixed = origin is tuple and args and args[-1] is not Ellipsis
        if fixed and len(value) != len(args):
            raise _fail(key, value, tp, meta)
        inner = args if fixed else (args[0] if args else Any,) * len(value)
        items = [check_value(a, meta, v, f"{key}[{i}]") for i, (a, v) in enumerate(zip(inner, value, strict=True))]
        return tuple(items) if origin is tuple else items
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise _fail(key, value, tp, meta)
    if tp is str:
        if not isinstance(value, str) or (meta.get("choices") and value not in meta["choices"]):
            raise _fail(key, value, tp, meta)
        return value
    if tp in (int, float):
        ok = isinstance(value, int) if tp is int else isinstance(value, int | float)
        if isinstance(value, bool) or not ok or (tp is float and not math.isfinite(value)):
            raise _fail(key, value, tp, meta)
        lo, hi = meta.get("lo"), meta.get("hi")
        below = lo is not None and (value <= lo if meta.get("lo_open") else value < lo)
        if below or (hi is not None and value > hi):
            raise _fail(key, value, tp, meta)
        return tp(value)
    raise TypeError(f"settings: unsupported field type {tp!r} for {key}")  # a bug in a schema, not user input


def build(cls: type[T], data: Any, where: str = "") -> T:
    """The dataclass ``cls`` from a mapping, every field checked; missing fields take defaults.

    Args:
        cls: a dataclass whose fields carry :func:`setting` metadata (plain fields: type only).
        data: a mapping (``None``: all defaults) or an instance of ``cls`` (returned as is).
        where: the dotted prefix of the keys, for messages (``solver``).
    """
    if isinstance(data, cls):
        return data
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise ConfigError(f"{where or cls.__name__}: expected a mapping of settings, got {short(data)}")
    fields = _fields(cls)
    unknown = [k for k in data if k not in fields]
    if unknown:
        key = f"{where}.{unknown[0]}" if where else str(unknown[0])
        raise ConfigError(f"unknown setting '{clip(key, 80)}' (allowed{' in ' + where if where else ''}: "
                          f"{', '.join(fields)})")
    values = {name: check_value(fields[name][0], fields[name][1], v, f"{where}.{name}" if where else name)
              for name, v in data.items()}
    return cls(**values)


def unset(cls: type, data: Mapping[str, Any]) -> dict[str, Any]:
    """``data`` without the keys whose value is None where the field does not allow None: in a
    group's YAML, ``null`` on such a key means "the robot's default" (e.g. ``srv.lr_bp``)."""
    fields = _fields(cls)
    return {k: v for k, v in data.items()
            if not (v is None and k in fields and type(None) not in typing.get_args(fields[k][0]))}


def with_defaults(cls: type[T], data: Mapping[str, Any] | T | None, defaults: Mapping[str, Any] | None,
                  where: str = "") -> T:
    """``cls`` from ``defaults`` (a robot's ``solver_defaults`` of this group) overridden by the
    keys of ``data`` that are set: a None value is unset where the field does not allow None
    (:func:`unset`) or where ``defaults`` has the key (``reward.p: null`` = the robot's p, else
    the budget); an instance of ``cls`` is returned as is."""
    if isinstance(data, cls):
        return data
    defaults = dict(defaults or {})
    kept = {k: v for k, v in unset(cls, data or {}).items() if not (v is None and k in defaults)}
    return build(cls, {**defaults, **kept}, where)


def lookup(cls: type, dotted: str) -> tuple[Any, Mapping[str, Any]] | None:
    """Type and metadata of a dotted key below ``cls``; ``(Free, {})`` inside a free-form field;
    ``None`` for a key that does not exist."""
    tp: Any = cls
    meta: Mapping[str, Any] = {}
    for part in dotted.split("."):
        if tp is Free:
            return Free, {}
        if not dataclasses.is_dataclass(tp):
            return None
        fields = _fields(tp)
        if part not in fields:
            return None
        tp, meta = fields[part]
        while typing.get_origin(tp) in (Union, types.UnionType):  # Optional[SomeCfg] -> SomeCfg
            inner = [a for a in typing.get_args(tp) if a is not type(None)]
            if len(inner) == 1 and (dataclasses.is_dataclass(inner[0]) or inner[0] is Free):
                tp = inner[0]
            else:
                break
    return tp, meta


# Physical ranges of the numbers in problem files and robot configs: nothing a grasp needs lies
# beyond them, and nothing within them overflows float32 downstream.
MAX_LENGTH_M = 10.0  # positions, sizes, translations (metres)
MAX_ANGLE_DEG = 360.0  # pose angles, bounds, joint values (degrees)


def number_list(value: Any, n: int | None, where: str, error: type[Exception], lo: float, hi: float,
                what: str = "numbers") -> list[float]:
    """``n`` numbers (any count if ``None``), each an int or float (not a bool, not a string),
    finite and within ``[lo, hi]``; else ``error`` with one line."""
    count = f"{n} " if n is not None else ""
    if isinstance(value, str | bytes | Mapping) or not isinstance(value, Sequence) or (
            n is not None and len(value) != n):
        raise error(f"{where}: expected {count}{what}, got {short(value)}")
    out = []
    for i, v in enumerate(value):
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise error(f"{where}[{i}]: expected a number, got {short(v)}")
        if not (math.isfinite(v) and lo <= v <= hi):
            raise error(f"{where}[{i}]: {short(v)} is not a finite number within [{_num(lo)}, {_num(hi)}]")
        out.append(float(v))
    return out


# -- YAML files that list a dataclass's defaults (configs/solver/srv.yaml...): written from it ----------------------


@dataclasses.dataclass(frozen=True)
class DefaultsFile:
    """A YAML file under ``configs/`` whose values of ``cls``'s settings are written from the
    dataclass's defaults (:func:`sync_defaults`, ``make sync-defaults``): the file keeps its keys,
    order and comments, the dataclass owns the values.

    Attributes:
        path: below ``configs/``.
        cls: the settings dataclass.
        under: the mapping the settings sit in (``("experiments", "fig3")``); () for the top level.
        skip: keys at that level that are not ``cls``'s settings (``defaults``, ``hydra``, ``quick``).
        unset: a ``null`` stays where the dataclass has a value: "the robot's" (a group a robot's
            ``solver_defaults`` sets, :func:`with_defaults`).
        differs: keys whose value differs from the dataclass's on purpose (kept as written).
        complete: every setting of ``cls`` must be listed (so that ``group.key=value`` overrides it).
    """

    path: str
    cls: type
    under: tuple[str, ...] = ()
    skip: tuple[str, ...] = ()
    unset: bool = False
    differs: tuple[str, ...] = ()
    complete: bool = True


_KEY_LINE = re.compile(r"^(?P<indent> *)(?P<key>[A-Za-z_]\w*):(?P<rest>.*)$")


def _split_comment(rest: str) -> tuple[str, str]:
    """A key line's text after the colon -> (the value, the comment with the spaces before it)."""
    quote = None
    for i, ch in enumerate(rest):
        if quote is not None:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and (i == 0 or rest[i - 1] == " "):
            value = rest[:i].rstrip(" ")
            return value, rest[len(value):]
    return rest.rstrip(" "), ""


def _brackets(text: str) -> int:
    """Flow brackets ``text`` opens less those it closes (outside quotes and its comment)."""
    value = _split_comment(text)[0]
    value = re.sub(r"'[^']*'|\"[^\"]*\"", "", value)
    return sum(value.count(c) for c in "[{") - sum(value.count(c) for c in "]}")


def _plain(value: Any) -> Any:
    """A default as YAML writes it: dataclasses as mappings, tuples as lists."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return value


def _same(a: Any, b: Any) -> bool:
    """Equal as settings: 30 and 30.0 are the same number; a bool, None or a string only itself."""
    number = (int, float)
    if isinstance(a, number) and isinstance(b, number) and not isinstance(a, bool) and not isinstance(b, bool):
        return a == b
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b


def _default(field: dataclasses.Field) -> Any:
    return field.default if field.default is not dataclasses.MISSING else field.default_factory()


def _leaves(cls: type, prefix: str = "") -> dict[str, Any]:
    """Every setting of ``cls`` below its groups (``polish.iterations``) -> its default."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        value = _default(f)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            out.update(_leaves(type(value), f"{prefix}{f.name}."))
        else:
            out[f"{prefix}{f.name}"] = _plain(value)
    return out


def sync_defaults(text: str, spec: DefaultsFile) -> tuple[str, list[str]]:
    """``text`` (the YAML file ``spec.path``) with every value of one of ``spec.cls``'s settings
    written from its default where the two differ (else the line as it is), and the settings the
    file does not list. A key that is not a setting is a :class:`ConfigError`."""
    defaults = _leaves(spec.cls)
    seen: set[str] = set()
    stack: list[tuple[int, str]] = []  # the open mappings: (indent, key)
    out = []
    depth = 0  # brackets a flow collection left open on the lines before (`quick: {a: 1,` ...)
    for line in text.splitlines(keepends=True):
        m = _KEY_LINE.match(line.rstrip("\n")) if depth == 0 else None
        depth += _brackets(_split_comment(line)[0] if m is None else m["rest"])
        if m is None:
            out.append(line)
            continue
        indent = len(m["indent"])
        while stack and stack[-1][0] >= indent:
            stack.pop()
        path = [k for _, k in stack] + [m["key"]]
        value, comment = _split_comment(m["rest"])
        if not value.strip():  # a mapping opens
            stack.append((indent, m["key"]))
        n = len(spec.under)
        if not value.strip() or tuple(path[:n]) != spec.under or len(path) == n or path[n] in spec.skip:
            out.append(line)
            continue
        key = ".".join(path[n:])
        if key not in defaults:
            raise ConfigError(f"configs/{spec.path}: '{key}' is not a setting of {spec.cls.__name__}")
        seen.add(key)
        written, default = yaml.safe_load(value), defaults[key]
        if _same(written, default) or key in spec.differs or (written is None and spec.unset):
            out.append(line)
            continue
        new = " " + yaml.safe_dump(default, default_flow_style=True, width=10**6).removesuffix("\n...\n").strip()
        end = "\n" if line.endswith("\n") else ""
        if comment:  # the comment stays in its column where the value leaves room
            col = len(value) + len(comment) - len(comment.lstrip(" "))
            new = f"{new.ljust(col - 1)} {comment.lstrip(' ')}"
        out.append(f"{m['indent']}{m['key']}:{new}{end}")
    return "".join(out), [k for k in defaults if k not in seen]
