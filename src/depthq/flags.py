"""Command-line flags made from a frozen config dataclass, so that flags and config cannot drift apart.

Each field of a simple type (str, int, float, bool, `X | None`, `tuple[X, ...]`, `Literal[...]`)
becomes `--field-name` (`--field_name` is accepted too); a field that is itself a config dataclass
becomes one flag per field of its own, dotted, recursively (the way tyro spells them):
`TrainConfig.samples.horizon` is `--samples.horizon`, `CollectConfig.env.world.decision_hz` is
`--env.world.decision-hz`; a tagged config (`depthq.configio.TAGGED`) is spelled by its tag's value,
one group per value: `TrainConfig.settings` of Depth-Q-Net is `--depth.lookahead`; a keyed field's
configs (`depthq.configio.KEYED`) by their names: `EvalConfig.acting` of Depth-Q-Net is
`--depth.rule`. Type, default and help come from the classes: the help from the comment above or
beside the field, else from a docstring sentence that starts with the field's name in backticks; a
nested field's default is its enclosing config's (CollectConfig's env is `exploration_env()`, not a
bare `EnvConfig()`). A field added to a class is a flag with no edit here.

A flag not given is not set: `config_from_args` builds the config from the flags given and leaves
every other field at its default (or at the `base` config a verb passes), so what --help shows as a
default is what a config gets.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import functools
import inspect
import io
import math
import re
import textwrap
import tokenize
import types
import typing
from typing import Any, Literal, TypeVar

from depthq.configio import (
    KEYED,
    TAGGED,
    Keyed,
    choices,
    field_default,
    keyed_fields,
    tag_default,
    tagged_field,
)
from depthq.errors import ConfigError

T = TypeVar("T")

# A field's metadata key for its choices, when no Literal can list them: a function giving them when
# the parser is built (e.g. the registered networks' names, `TrainConfig.model`).
CHOICES = "choices"
_NONE = ("none", "null")
_TRUE, _FALSE = ("true", "1", "yes"), ("false", "0", "no")
_SENTENCE_END = re.compile(r"(?<=[.!?])\s+(?=[A-Z`])")
# A tool's directive in a comment (mypy's "type: ignore[...]", ruff's "noqa", coverage's "pragma", ...),
# alone or after the help text on its line: it is for the tool, never part of a flag's help.
_DIRECTIVE = re.compile(r"(?:^|\s*#\s*)(?:type:|noqa\b|pragma:|pyright:|mypy:|fmt:|isort:|ruff:).*$")


@dataclasses.dataclass(frozen=True)
class Flag:
    """The flag of one field of a config: `path` is the field's name, dotted below nested configs
    ('samples.horizon'), and the flag's destination in the parsed arguments."""

    path: str
    owner: type  # the dataclass that declares the field
    hint: Any
    default: Any  # dataclasses.MISSING: a required flag
    help: str  # from the class (`field_help`); empty when it has none
    choices: tuple[str, ...] | None = None  # a str field's choices (`CHOICES`); None: any value

    @property
    def name(self) -> str:
        """'--samples.min-frames' for path 'samples.min_frames'."""
        return flag_name(self.path)


def flag_name(path: str) -> str:
    """The flag of a field path: 'env.world.decision_hz' → '--env.world.decision-hz'."""
    return "--" + path.replace("_", "-")


def config_flags(cls: type, default: Any = None, prefix: str = "") -> list[Flag]:
    """The flags of `cls`, nested configs' fields recursively; a tagged config's (`TAGGED`) for each of
    its classes, or for `default`'s alone; a keyed field's (`KEYED`) for each of its names. `default`:
    an instance whose values are the defaults (None: the fields' own). A type no flag can spell is an
    error here, when the parser is built, rather than a field silently left out."""
    hints = typing.get_type_hints(cls)
    docs = field_help(cls)
    out = []
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        value = getattr(default, f.name) if default is not None else field_default(f)
        if TAGGED in f.metadata:
            tag, classes = f.metadata[TAGGED]
            chosen = classes() if default is None else {getattr(default, tag): type(value)}
            for name, inner in chosen.items():
                out += config_flags(inner, value if default is not None else None, f"{prefix}{name}.")
            continue
        if KEYED in f.metadata:
            for name, inner in f.metadata[KEYED]().items():
                given = value.get(name) if default is not None else None
                out += config_flags(inner, given, f"{prefix}{name}.")
            continue
        hint = hints[f.name]
        if dataclasses.is_dataclass(hint):
            out += config_flags(hint, None if value is dataclasses.MISSING else value, f"{prefix}{f.name}.")
            continue
        _check_type(hint, f"{cls.__name__}.{f.name}")
        choices = tuple(f.metadata[CHOICES]()) if CHOICES in f.metadata else None
        out.append(Flag(prefix + f.name, cls, hint, value, docs.get(f.name, ""), choices))
    return out


def add_config_arguments(
    parser: argparse.ArgumentParser,
    cls: type,
    *,
    exclude: tuple[str, ...] = (),
    only: tuple[str, ...] | None = None,
    aliases: dict[str, tuple[str, ...]] | None = None,
    more_help: dict[str, str] | None = None,
    default: Any = None,
    shown_defaults: dict[str, str] | None = None,
) -> list[Flag]:
    """A flag for every field of `cls` (nested configs' fields dotted) but `exclude` (field paths, or
    a nested config's path for all of its fields), in a group per config; `only`: the flags of these
    paths alone, for a verb that sets one or two fields of a config it does not build itself.
    `aliases`: other spellings of a field's flag, e.g. the ones it had before (shown in --help);
    `more_help`: what the verb adds to a field's help; `default`: an instance of `cls` whose
    values the help shows as defaults; `shown_defaults`: a default in words, where the verb's is not
    the config's ("the preset's"). Keyed by field path. Returns the flags made."""
    aliases, more_help, shown_defaults = aliases or {}, more_help or {}, shown_defaults or {}
    flags = [f for f in config_flags(cls, default)
             if not _excluded(f.path, exclude) and (only is None or f.path in only)]
    # A group per config, outer ones first: CollectConfig's own fields, then env's, env.world's, ...
    owners = {f.path.rpartition(".")[0]: f.owner for f in flags}
    order = [p for f in flags for p in _prefixes(f.path)]
    but = "" if only is not None else ", ".join(exclude)
    groups = {where: _group(parser, cls, where, owners[where], only is not None, but)
              for where in sorted(owners, key=order.index)}
    for flag in flags:
        where = flag.path.rpartition(".")[0]
        text = "; ".join(t.rstrip(".") for t in (flag.help, more_help.get(flag.path)) if t)
        if flag.path in shown_defaults:
            text = f"{text} (default: {shown_defaults[flag.path]})".strip()
        elif flag.default is not dataclasses.MISSING:
            text = f"{text} (default: {_show(flag.default)})".strip()
        kwargs: dict[str, Any] = {"dest": flag.path, "default": argparse.SUPPRESS}
        if flag.hint is bool:
            kwargs["action"] = argparse.BooleanOptionalAction
        else:
            kwargs["type"] = _argparse_type(flag.hint)
            kwargs["metavar"] = _metavar(flag.hint, flag.path.rpartition(".")[2])
            if flag.choices is not None:
                kwargs["choices"], kwargs["metavar"] = flag.choices, "{" + ",".join(flag.choices) + "}"
        names = (flag.name, *aliases.get(flag.path, ()))
        groups[where].add_argument(*names, required=flag.default is dataclasses.MISSING,
                                   help=text.replace("%", "%%"), **kwargs)
        for name in names:  # the field's own spelling (underscores), not listed twice in --help
            spelling = "--" + name[2:].replace("-", "_")
            if spelling != name and spelling not in parser._option_string_actions:
                groups[where].add_argument(spelling, help=argparse.SUPPRESS, **kwargs)
    return flags


def parse_value(flag: Flag, text: str, what: str | None = None) -> Any:
    """`text` as `flag`'s value, parsed as the flag parses it on the command line ('none' for a field
    that may be unset, one of a Literal's choices, a tuple's items joined by ','): the one parser of a
    setting given as text, so `depthq sweep --set` takes what the flags take. Else a ConfigError
    naming `what` (by default the flag) and the value."""
    try:
        return _parse(flag.hint, text)
    except ValueError as err:
        raise ConfigError(f"{what or flag.name}: {err}") from None


def config_from_args(cls: type[T], args: argparse.Namespace, base: T | None = None, **given: Any) -> T:
    """`cls` from the flags `add_config_arguments` made that were given, and `given` (field paths)
    for the fields the verb sets; every other field at its default, or `base`'s when given."""
    paths = {f.path for f in config_flags(cls)}
    values = {k: v for k, v in vars(args).items() if k in paths}
    return build_config(cls, {**values, **given}, base)


def build_config(cls: type[T], values: dict[str, Any], base: T | None = None) -> T:
    """`cls` with the fields at the paths of `values` set ('samples.horizon' sets a field of the
    nested config `samples`; 'depth.lookahead' one of the tagged config of tag value "depth", and
    'depth.rule' one of a keyed field's config of that name), every other field from `base`, else at
    its default; an unknown path, or one of another tag value than the config's, is a ConfigError
    naming it."""
    own: dict[str, Any] = {}
    nested: dict[str, dict[str, Any]] = {}
    for path, value in values.items():
        name, dot, rest = path.partition(".")
        if dot:
            nested.setdefault(name, {})[rest] = value
        else:
            own[name] = value
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    _build_tagged(cls, own, nested, base)
    _build_keyed(cls, own, nested, base)
    unknown = sorted((set(own) | set(nested)) - set(fields))
    if unknown:
        raise ConfigError(f"{cls.__name__} has no setting {', '.join(unknown)}")
    hints = typing.get_type_hints(cls)
    for name, inner in nested.items():
        if not dataclasses.is_dataclass(hints[name]):
            raise ConfigError(f"{cls.__name__}.{name} is not a config: it has no {', '.join(inner)}")
        if name in own:
            inner_base = own[name]
        elif base is not None:
            inner_base = getattr(base, name)
        else:
            inner_base = field_default(fields[name])
        inner_base = None if inner_base is dataclasses.MISSING else inner_base
        own[name] = build_config(hints[name], inner, inner_base)
    return dataclasses.replace(base, **own) if base is not None else cls(**own)  # type: ignore[type-var]


def _build_tagged(cls: type, own: dict[str, Any], nested: dict[str, dict[str, Any]], base: Any) -> None:
    """Into `own`: the tagged config of `cls` (`TAGGED`), from the settings `nested` holds under its tag
    value (taken out of `nested`), on `base`'s when the tag value stays; its class's defaults (None)
    when the tag value changes and none are given."""
    found = tagged_field(cls)
    if found is None:
        return
    f, tag, classes = found
    chosen = own.get(tag, getattr(base, tag) if base is not None else tag_default(cls, tag))
    same = base is not None and getattr(base, tag) == chosen
    for name in [n for n in nested if n in classes and n not in own]:
        inner = nested.pop(name)
        if name != chosen:
            paths = ", ".join(f"{name}.{k}" for k in inner)
            raise ConfigError(f"{cls.__name__}: {paths}: a setting of {tag} {name!r}, not of {tag} "
                              f"{chosen!r}")
        own[f.name] = build_config(classes[name], inner, getattr(base, f.name) if same else None)
    if base is not None and not same and f.name not in own:
        own[f.name] = None  # another tag value: its class's defaults


def _build_keyed(cls: type, own: dict[str, Any], nested: dict[str, dict[str, Any]], base: Any) -> None:
    """Into `own`: each keyed field of `cls` (`KEYED`), its configs of the names `nested` holds settings
    of (taken out of `nested`) built on `base`'s, the others as they were (the class completes them)."""
    for f, classes in keyed_fields(cls):
        names = [name for name in nested if name in classes]
        if not names:
            continue
        held = own.get(f.name, getattr(base, f.name) if base is not None else Keyed())
        own[f.name] = Keyed({**held, **{name: build_config(classes[name], nested.pop(name), held.get(name))
                                        for name in names}})


def get_path(config: Any, path: str) -> Any:
    """The value of a field path: get_path(train_config, 'samples.horizon'); a tagged config's by its
    tag value: get_path(train_config, 'depth.lookahead'); a keyed field's by its name:
    get_path(eval_config, 'depth.rule')."""
    for name in path.split("."):
        if dataclasses.is_dataclass(config) and not hasattr(config, name):
            found = tagged_field(type(config))
            if found is not None and name == getattr(config, found[1]):
                config = getattr(config, found[0].name)
                continue
            held = [getattr(config, f.name) for f, _ in keyed_fields(type(config))]
            owner = next((configs for configs in held if name in configs), None)
            config = owner[name] if owner is not None else getattr(config, name)
        else:
            config = getattr(config, name)
    return config


@functools.cache
def field_help(cls: type) -> dict[str, str]:
    """Each field's help: the first sentence of the comment block above it and the comment beside
    it, else the class docstring's sentences that start with `field`."""
    source = textwrap.dedent(inspect.getsource(cls))
    comments: dict[int, tuple[str, bool]] = {}  # line → (text, whole line)
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            whole = not tok.line[: tok.start[1]].strip()
            text = _DIRECTIVE.sub("", tok.string.lstrip("#").strip()).strip()
            if text:
                comments[tok.start[0]] = (text, whole)
    body = next(n for n in ast.parse(source).body if isinstance(n, ast.ClassDef)).body
    sentences = _SENTENCE_END.split(" ".join((inspect.getdoc(cls) or "").split()))
    out = {}
    for node in body:
        if not (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)):
            continue
        name, block, line = node.target.id, [], node.lineno - 1
        while line in comments and comments[line][1]:
            block.insert(0, comments[line][0])
            line -= 1
        parts = [_SENTENCE_END.split(" ".join(block))[0]] if block else []
        beside = comments.get(node.end_lineno or node.lineno)
        if beside and not beside[1]:
            parts.append(beside[0])
        if not parts:
            parts = [s for s in sentences if s.startswith(f"`{name}`")]
        out[name] = " ".join(parts)
    for base in cls.__mro__[1:]:  # a field an ancestor declares, with the ancestor's help
        if dataclasses.is_dataclass(base):
            out = {**field_help(base), **out}
    return out


def _prefixes(path: str) -> list[str]:
    """'env.world.decision_hz' → ['', 'env', 'env.world']: the configs a field is in, outermost first."""
    parts = path.split(".")[:-1]
    return [".".join(parts[:k]) for k in range(len(parts) + 1)]


def _excluded(path: str, exclude: tuple[str, ...]) -> bool:
    return any(path == e or path.startswith(f"{e}.") for e in exclude)


def _group(
    parser: argparse.ArgumentParser, cls: type, where: str, owner: type, some: bool = False, but: str = ""
) -> argparse._ArgumentGroup:
    """The --help group of the config at path `where` ('' for `cls` itself); `some`: a few of its
    fields are flags; `but`: the fields that are not."""
    if some:
        title = f"{cls.__name__}{'.' + where + ': ' + owner.__name__ if where else ''} (some fields as flags)"
    elif not where:
        title = f"{cls.__name__} (every field a flag{' but ' + but if but else ''})"
    else:
        title = f"{cls.__name__}.{where}: {owner.__name__} (--{where.replace('_', '-')}.*)"
    summary = (inspect.getdoc(owner) or "").split("\n\n")[0].replace("\n", " ")
    return parser.add_argument_group(title, summary.replace("%", "%%"))


def _show(value: Any) -> str:
    if isinstance(value, tuple):
        return ",".join(map(str, value)) if value else "empty"
    return "none" if value is None else str(value)


def _metavar(hint: Any, name: str) -> str | None:
    options = choices(hint)
    if options is not None:  # a choice-valued field lists its choices ("none" last where it may be unset)
        return "{" + ",".join(_show(o) for o in options) + "}"
    if typing.get_origin(hint) is tuple:
        return f"{name.upper()}[,...]"
    return name.upper()


def _argparse_type(hint: Any):
    def convert(text: str) -> Any:
        try:
            return _parse(hint, text)
        except ValueError as err:
            raise argparse.ArgumentTypeError(str(err)) from None

    return convert


def _optional(hint: Any) -> Any | None:
    """X for `X | None`, else None."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if len(args) == 1 and len(typing.get_args(hint)) == 2:
            return args[0]
    return None


def _check_type(hint: Any, where: str) -> None:
    inner = _optional(hint)
    if inner is not None:
        return _check_type(inner, where)
    origin = typing.get_origin(hint)
    if origin is tuple:
        for arg in typing.get_args(hint):
            if arg is not Ellipsis:
                _check_type(arg, where)
        return
    if origin is Literal or hint in (str, int, float, bool):
        return
    raise TypeError(f"{where}: no command-line flag for type {hint!r}; give it a simple type or exclude it")


def _parse(hint: Any, text: str) -> Any:
    inner = _optional(hint)
    if inner is not None:
        return None if text.strip().lower() in _NONE else _parse(inner, text)
    origin = typing.get_origin(hint)
    if origin is tuple:
        args = typing.get_args(hint)
        items = [t for t in text.split(",") if t.strip()]
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_parse(args[0], t) for t in items)
        if len(items) != len(args):
            raise ValueError(f"expected {len(args)} comma-separated values, got {text!r}")
        return tuple(_parse(a, t) for a, t in zip(args, items, strict=True))
    if origin is Literal:
        choices = typing.get_args(hint)
        for choice in choices:
            if text == str(choice):
                return choice
        raise ValueError(f"expected one of {', '.join(map(str, choices))}, got {text!r}")
    if hint is bool:
        if text.strip().lower() in _TRUE + _FALSE:
            return text.strip().lower() in _TRUE
        raise ValueError(f"expected true or false, got {text!r}")
    if hint in (int, float):
        try:
            value = hint(text)
        except ValueError:
            value = None
        if value is None or not math.isfinite(value):  # JSON, where every config goes, has no nan nor inf
            kind = "an integer" if hint is int else "a finite number"
            raise ValueError(f"expected {kind}, got {text!r}")
        return value
    return text
