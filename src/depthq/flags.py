"""Command-line flags made from a frozen config dataclass, so that flags and config cannot drift apart.

Each field of a simple type (str, int, float, bool, `X | None`, `tuple[X, ...]`, `Literal[...]`)
becomes `--field-name` (`--field_name` is accepted too): its type, default and help come from the
class, the help from the comment above or beside the field, else from a docstring sentence that
starts with the field's name in backticks. A field added to the class is a flag with no edit here;
nested config dataclasses are left to the verb. `depthq sweep --set` parses values the same way.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import io
import re
import textwrap
import tokenize
import types
import typing
from typing import Any, Literal, TypeVar

from depthq.errors import ConfigError

T = TypeVar("T")

_NONE = ("none", "null")
_TRUE, _FALSE = ("true", "1", "yes"), ("false", "0", "no")
_SENTENCE_END = re.compile(r"(?<=[.!?])\s+(?=[A-Z`])")


def flag_fields(cls: type) -> list[dataclasses.Field]:
    """The fields of `cls` that are flags: all but nested dataclasses (a type no flag can spell is an
    error here, when the parser is built, rather than a field silently left out)."""
    hints = typing.get_type_hints(cls, include_extras=False)
    out = []
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        if dataclasses.is_dataclass(hint):
            continue
        _check_type(hint, f"{cls.__name__}.{f.name}")
        out.append(f)
    return out


def field_name(cls: type, name: str) -> str:
    """'depth-loss' or 'depth_loss' → 'depth_loss', a field of `cls` (ConfigError naming it otherwise)."""
    key = name.strip().replace("-", "_")
    if key not in {f.name for f in flag_fields(cls)}:
        allowed = ", ".join(f.name for f in flag_fields(cls))
        raise ConfigError(f"{name!r} is not a setting of {cls.__name__}; one of: {allowed}")
    return key


def parse_value(cls: type, name: str, text: str) -> Any:
    """`text` as a value of field `name` of `cls` (ConfigError naming the field and the text)."""
    hint = typing.get_type_hints(cls)[name]
    try:
        return _parse(hint, text)
    except ValueError as err:
        raise ConfigError(f"{name}: {err}") from None


def add_config_arguments(
    parser: argparse.ArgumentParser,
    cls: type,
    *,
    exclude: tuple[str, ...] = (),
    aliases: dict[str, tuple[str, ...]] | None = None,
    more_help: dict[str, str] | None = None,
) -> None:
    """A flag for every field of `cls` but `exclude`, in a group of its own. `aliases`: older
    spellings of a field's flag (shown in --help); `more_help`: what the verb puts before a field's
    help (its choices, or a text where the class has none)."""
    aliases, more_help = aliases or {}, more_help or {}
    hints = typing.get_type_hints(cls)
    docs = field_help(cls)
    summary = (inspect.getdoc(cls) or "").split("\n\n")[0].replace("\n", " ")
    group = parser.add_argument_group(f"{cls.__name__} (every field a flag)", summary.replace("%", "%%"))
    for f in flag_fields(cls):
        if f.name in exclude:
            continue
        hint, default = hints[f.name], _default(f)
        text = "; ".join(t for t in (more_help.get(f.name), docs.get(f.name)) if t)
        if default is not dataclasses.MISSING:
            text = f"{text} (default: {_show(default)})".strip()
        names = (f"--{f.name.replace('_', '-')}", *aliases.get(f.name, ()))
        kwargs: dict[str, Any] = {"dest": f.name}
        if hint is bool:
            kwargs["action"] = argparse.BooleanOptionalAction
        else:
            kwargs["type"] = _argparse_type(hint)
            kwargs["metavar"] = _metavar(hint, f.name)
        if default is dataclasses.MISSING:
            kwargs["required"] = True
        else:
            kwargs["default"] = default
        group.add_argument(*names, help=text.replace("%", "%%"), **kwargs)
        if "_" in f.name:  # the field's own spelling, not listed twice in --help
            group.add_argument(f"--{f.name}", **{**kwargs, "required": False, "default": argparse.SUPPRESS},
                               help=argparse.SUPPRESS)


def config_from_args(cls: type[T], args: argparse.Namespace, **given: Any) -> T:
    """`cls` from the flags `add_config_arguments` made, and `given` for the fields the verb sets."""
    values = {f.name: getattr(args, f.name) for f in flag_fields(cls) if hasattr(args, f.name)}
    return cls(**{**values, **given})


def field_help(cls: type) -> dict[str, str]:
    """Each field's help: the first sentence of the comment block above it and the comment beside
    it, else the class docstring's sentences that start with `field`."""
    source = textwrap.dedent(inspect.getsource(cls))
    comments: dict[int, tuple[str, bool]] = {}  # line → (text, whole line)
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            whole = not tok.line[: tok.start[1]].strip()
            comments[tok.start[0]] = (tok.string.lstrip("#").strip(), whole)
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
    return out


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


def _show(value: Any) -> str:
    if isinstance(value, tuple):
        return ",".join(map(str, value)) if value else "empty"
    return "none" if value is None else str(value)


def _metavar(hint: Any, name: str) -> str | None:
    if typing.get_origin(hint) is Literal:
        return "{" + ",".join(map(str, typing.get_args(hint))) + "}"
    if typing.get_origin(hint) is tuple:
        return f"{name.upper()}[,...]"
    return None


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
            return hint(text)
        except ValueError:
            kind = "an integer" if hint is int else "a number"
            raise ValueError(f"expected {kind}, got {text!r}") from None
    return text
