"""The CLI reference page (docs/cli.md), generated from the parsers the `depthq` command builds, so that
it cannot drift from the flags: `python -m depthq.cli_reference docs/cli.md` rewrites it, and a test
checks that the page equals what this module generates."""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path

from depthq.cli import VERBS, build_parser

WIDTH = 100  # help text is wrapped at this width, whatever the terminal, so the page is the same anywhere

HEADER = """# CLI reference

Every `depthq` verb with every flag, as `depthq VERB --help` prints it. Every field of a verb's
configs is a flag (a nested config's fields dotted), so this page is generated from the code:
`python -m depthq.cli_reference docs/cli.md` rewrites it, and a test fails when it is out of date.
"""


def _sub_parsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The sub-commands of `parser` (a verb's actions such as `bench sim`), by name, in order."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _help(parser: argparse.ArgumentParser) -> str:
    parser.formatter_class = functools.partial(argparse.HelpFormatter, width=WIDTH)
    return parser.format_help().rstrip()


def _section(name: str, parser: argparse.ArgumentParser, level: int) -> list[str]:
    lines = [f"{'#' * level} `{name}`", "", "```text", _help(parser), "```", ""]
    for sub, child in _sub_parsers(parser).items():
        lines += _section(f"{name} {sub}", child, level + 1)
    return lines


def reference() -> str:
    """The page: the command's own help, then a section per verb and per sub-command."""
    top = build_parser()
    lines = [HEADER, "```text", _help(top), "```", ""]
    verbs = _sub_parsers(top)
    for verb in VERBS:
        if verb in verbs:
            lines += _section(f"depthq {verb}", _sub_parsers(build_parser(verb))[verb], 2)
    return "\n".join(lines).rstrip() + "\n"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python -m depthq.cli_reference PAGE  (e.g. docs/cli.md)", file=sys.stderr)
        return 2
    Path(argv[0]).write_text(reference())
    return 0


if __name__ == "__main__":
    sys.exit(main())
