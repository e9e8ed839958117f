"""Frozen-dataclass configs to and from JSON: every artifact stores the config that made it."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import json
import math
import os
import tempfile
import types
import typing
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar

from depthq import __version__
from depthq.errors import ConfigError, DataError

T = TypeVar("T")


# Field metadata of a setting added after artifacts were written without it: `to_dict` leaves it out
# while it holds its default, so configs that do not use it keep their bytes (and old manifests match).
OMIT_DEFAULT = {"omit_default": True}
# Field metadata of a config whose class the value of another field chooses (a tagged union, as
# LeRobot's `--policy.type` chooses a policy's config): `tagged(tag, classes)`. Records, flags and field
# paths spell it by the tag's value, never by its own name: `TrainConfig.settings` of a "depth" model is
# "depth" in config.json and `--depth.lookahead` on the command line. None as its value: the chosen
# class's defaults (the class resolves it in its `__post_init__`).
TAGGED = "tagged"


# Field metadata of a field holding one config per name of a registry (`keyed(classes)`), a `Keyed`
# mapping: `EvalConfig.acting`, each registered network's own acting settings, since one evaluation
# config serves every network a sweep drives. Records, flags and field paths spell each config by its
# name, as a tagged one by its tag value: "depth" in summary.json, `--depth.rule` on the command line.
KEYED = "keyed"


def tagged(tag: str, classes: Callable[[], dict[str, type]]) -> dict[str, Any]:
    """The metadata of a tagged config field (`TAGGED`): `tag` names the field whose value chooses its
    class, `classes()` gives every value's class (called when needed: a registry may grow)."""
    return {TAGGED: (tag, classes)}


def tagged_field(cls: type) -> tuple[dataclasses.Field, str, dict[str, type]] | None:
    """The tagged config field of dataclass `cls` (at most one), its tag field and its classes; None
    without one."""
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        if TAGGED in f.metadata:
            tag, classes = f.metadata[TAGGED]
            return f, tag, classes()
    return None


def keyed(classes: Callable[[], dict[str, type]]) -> dict[str, Any]:
    """The metadata of a keyed config field (`KEYED`): `classes()` gives each name's class (called when
    needed: a registry may grow)."""
    return {KEYED: classes}


class Keyed(Mapping[str, Any]):
    """A `KEYED` field's value: name → config, immutable and hashable as a frozen config's fields are."""

    def __init__(self, items: Mapping[str, Any] | Iterable[tuple[str, Any]] = ()) -> None:
        self._items = dict(items)

    def __getitem__(self, name: str) -> Any:
        return self._items[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __hash__(self) -> int:
        return hash(tuple(self._items.items()))

    def __repr__(self) -> str:
        return f"Keyed({self._items!r})"


def keyed_fields(cls: type) -> list[tuple[dataclasses.Field, dict[str, type]]]:
    """The keyed config fields of dataclass `cls` (`KEYED`), each with its classes by name."""
    return [(f, f.metadata[KEYED]()) for f in dataclasses.fields(cls)  # type: ignore[arg-type]
            if KEYED in f.metadata]


def complete_keyed(config: Any) -> None:
    """Set each keyed field of the frozen dataclass `config` (from its `__post_init__`) to a `Keyed` of
    a config for every name, in the classes' order: the given one, else that class's defaults. A name
    of no class, a config of another class or a name that is also a field is a ConfigError."""
    cls = type(config)
    names = {f.name for f in dataclasses.fields(cls)}
    for f, classes in keyed_fields(cls):
        given = getattr(config, f.name)
        if not isinstance(given, Mapping):
            raise ConfigError(f"{cls.__name__}.{f.name} must map names to configs, got {given!r}")
        unknown = sorted(set(given) - set(classes))
        if unknown:
            raise ConfigError(f"{cls.__name__}: {', '.join(map(repr, unknown))} has no settings here; "
                              f"{f.name} holds those of {sorted(classes)}")
        for name, inner in classes.items():
            if name in names:
                raise ConfigError(f"{cls.__name__}: {name!r} is a field and a name of {f.name}")
            if name in given and not isinstance(given[name], inner):
                raise ConfigError(f"{cls.__name__}.{f.name}[{name!r}] must be a {inner.__name__}, "
                                  f"got {given[name]!r}")
        object.__setattr__(config, f.name, Keyed({name: given[name] if name in given else inner()
                                                  for name, inner in classes.items()}))


def to_dict(config: Any) -> dict[str, Any]:
    """A JSON-ready dict of a (nested) dataclass; tuples become lists; `OMIT_DEFAULT` fields at their
    default are left out (`from_dict` restores them)."""
    return json.loads(json.dumps(_as_dict(config)))


def _as_dict(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        out = {}
        for f in dataclasses.fields(value):
            item = getattr(value, f.name)
            if f.metadata.get("omit_default") and item == field_default(f):
                continue
            if KEYED in f.metadata:  # each config under its name, beside the fields
                out.update({name: _as_dict(inner) for name, inner in item.items()})
                continue
            key = getattr(value, f.metadata[TAGGED][0]) if TAGGED in f.metadata else f.name
            out[key] = _as_dict(item)
        return out
    if isinstance(value, tuple | list):
        return [_as_dict(v) for v in value]
    if isinstance(value, Mapping):
        return {k: _as_dict(v) for k, v in value.items()}
    return value


def field_paths(record: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """{'samples': {'horizon': 5}} → {'samples.horizon': 5}: a record's settings by field path."""
    out = {}
    for key, value in record.items():
        if isinstance(value, dict):
            out.update(field_paths(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def field_default(f: dataclasses.Field) -> Any:
    """A dataclass field's default (its factory's value), or `dataclasses.MISSING` without one."""
    if f.default is not dataclasses.MISSING:
        return f.default
    return f.default_factory() if f.default_factory is not dataclasses.MISSING else dataclasses.MISSING


def tag_default(cls: type, tag: str) -> Any:
    """The default of the field `tag` of dataclass `cls`: the tag value a config has unless told."""
    return field_default(next(f for f in dataclasses.fields(cls) if f.name == tag))  # type: ignore[arg-type]


def from_dict(cls: type[T], data: dict[str, Any]) -> T:
    """Build `cls` from a dict, recursing into nested dataclasses (a tagged one under its tag's value,
    `TAGGED`; a keyed field's under their names, `KEYED`); unknown keys are an error."""
    if not isinstance(data, dict):
        raise ConfigError(f"{cls.__name__}: expected a JSON object, got {data!r}")
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    kwargs = {}
    found = tagged_field(cls)
    if found is not None:
        f, tag, classes = found
        names.discard(f.name)
        chosen = data.get(tag, tag_default(cls, tag))
        if isinstance(chosen, str) and chosen in data:
            if chosen not in classes:
                raise ConfigError(f"{cls.__name__}: {tag} {chosen!r} has no settings of its own")
            kwargs[f.name] = from_dict(classes[chosen], data[chosen])
            data = {k: v for k, v in data.items() if k != chosen}
    for f, classes in keyed_fields(cls):
        names.discard(f.name)
        kwargs[f.name] = Keyed({name: from_dict(inner, data[name]) for name, inner in classes.items()
                                if name in data})
        data = {k: v for k, v in data.items() if k not in classes}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ConfigError(f"{cls.__name__}: unknown field(s) {unknown}")
    for key, value in data.items():
        kwargs[key] = _convert(hints[key], value)
    return cls(**kwargs)


def _convert(hint: Any, value: Any) -> Any:
    origin = typing.get_origin(hint)
    if dataclasses.is_dataclass(hint) and isinstance(value, dict):
        return from_dict(hint, value)  # type: ignore[arg-type]
    if origin in (typing.Union, types.UnionType):
        for arg in typing.get_args(hint):
            if dataclasses.is_dataclass(arg) and isinstance(value, dict):
                return from_dict(arg, value)
        return value
    if origin is tuple and isinstance(value, list):
        args = typing.get_args(hint)
        inner = args[0] if args else Any
        return tuple(_convert(inner, v) for v in value)
    return value


def choices(hint: Any) -> tuple[Any, ...] | None:
    """The choices of a choice-valued type, `Literal[...]` or `Literal[...] | None` (None among them
    then); None for any other type."""
    if typing.get_origin(hint) is Literal:
        return typing.get_args(hint)
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = typing.get_args(hint)
        inner = [a for a in args if a is not type(None)]
        if len(inner) == 1 and len(args) == 2 and typing.get_origin(inner[0]) is Literal:
            return (*typing.get_args(inner[0]), None)
    return None


@functools.cache
def _choice_fields(cls: type) -> tuple[tuple[str, tuple[Any, ...]], ...]:
    hints = typing.get_type_hints(cls)
    fields = ((f.name, choices(hints[f.name])) for f in dataclasses.fields(cls))  # type: ignore[arg-type]
    return tuple((name, options) for name, options in fields if options is not None)


def check_choices(config: Any, where: str) -> None:
    """Each choice-valued field of the dataclass `config` (typed `Literal[...]`) holds one of the
    choices its type lists, else a ConfigError naming it ('train.trunk must be one of ...'): the one
    check of such a setting, so its choices are written once, in its type (which `--help` lists too)."""
    for name, options in _choice_fields(type(config)):
        value = getattr(config, name)
        if not any(value == option and type(value) is type(option) for option in options):
            shown = ", ".join("none" if o is None else str(o) for o in options)
            raise ConfigError(f"{where}.{name} must be one of {shown}, got {value!r}")


# Seeds reach NumPy (non-negative only), Gymnasium and torch (below 2**64): one range suits all three,
# with room for the per-run offsets added to them.
SEED_LIMIT = 2**63


def check_seed(seed: object, flag: str = "--seed") -> None:
    """A seed is an integer in [0, 2**63): anything else is a ConfigError naming `flag`."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < SEED_LIMIT:
        raise ConfigError(f"{flag} must be an integer >= 0 (and < 2**63), got {seed!r}")


def umask() -> int:
    """The process's umask, left as it is: read from /proc/self/status where the system has it (Linux);
    else set and restored, 0o077 meanwhile, so a file another thread makes then is stricter, not looser."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o077)
    os.umask(mask)
    return mask


def temp_sibling(path: Path, suffix: str = ".tmp") -> Path:
    """A new empty file beside `path` (`.NAME.XXXX{suffix}`), to be renamed onto it once written, with the
    mode `open()` would give `path` (0o666 less the umask; tempfile's own 0o600 would lock others out)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~umask())
    except BaseException:
        Path(name).unlink(missing_ok=True)
        raise
    finally:
        os.close(fd)
    return Path(name)


@contextlib.contextmanager
def atomic_file(path: Path) -> Iterator[Path]:
    """A `temp_sibling` of `path` for the block to write; fsynced and renamed onto `path` when the block
    ends, removed if it raises: a reader never sees half a file."""
    tmp = temp_sibling(path)
    try:
        yield tmp
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write `data` to `path` through `atomic_file`: whole or not at all, with the umask's mode."""
    with atomic_file(path) as tmp:
        tmp.write_bytes(data)


def write_json(path: Path, obj: Any) -> None:
    """Atomically write strict JSON (sorted keys, so equal content gives equal bytes; a non-finite
    number, which JSON cannot spell, as null)."""
    text = json.dumps(finite(obj), indent=2, sort_keys=True, allow_nan=False)
    atomic_write_bytes(Path(path), (text + "\n").encode())


def finite(value: Any) -> Any:
    """`value` with every NaN or infinite float (in lists, tuples and dicts) replaced by None."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite(v) for v in value]
    return value


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not JSON")


def read_json(path: Path) -> Any:
    """Strict JSON: NaN and Infinity, which Python's json would read, are refused (DataError)."""
    path = Path(path)
    try:
        return json.loads(path.read_text(), parse_constant=_refuse_constant)
    except FileNotFoundError:
        raise
    except (ValueError, UnicodeDecodeError) as err:
        raise DataError(f"{path}: not valid JSON ({err})") from err


def provenance() -> dict[str, str]:
    """What every artifact records about the code that made it."""
    return {"package": "depthq", "version": __version__}
