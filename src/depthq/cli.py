"""The `depthq` command: one sub-command per verb, each defined in `depthq.scripts.<verb>`."""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback
from contextlib import ExitStack
from pathlib import Path
from typing import NoReturn

from depthq import __version__
from depthq.errors import explain
from depthq.lock import exclusive

DEBUG_ENV = "DEPTHQ_DEBUG"

# verb -> module in depthq.scripts; each module has `add_arguments(parser)` and `run(args) -> int`.
VERBS: dict[str, str] = {
    "drive": "drive",
    "bench": "bench",
    "collect": "collect",
    "dataset": "dataset",
    "labeller": "labeller",
    "label": "label",
    "train": "train",
    "evaluate": "evaluate",
    "reproduce": "reproduce",
    "sweep": "sweep",
    "probe": "probe",
    "export": "export",
    "bag": "bag",
    "ros": "ros",
    "host": "host",
}


class Parser(argparse.ArgumentParser):
    """argparse's parser, but a bad flag is one line (what is wrong, where --help is), not the usage."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser(verb: str | None = None) -> argparse.ArgumentParser:
    """Every verb with its summary, and the flags of `verb` alone: building a verb's flags imports its
    config classes (MuJoCo's for collect), which only that verb should pay for."""
    parser = Parser(
        prog="depthq",
        description="Monocular collision avoidance from future depth: collect, train, evaluate, reproduce.",
    )
    parser.add_argument("--version", action="version", version=f"depthq {__version__}")
    parser.add_argument("--debug", action="store_true",
                        help=f"full tracebacks instead of one-line errors (also {DEBUG_ENV}=1)")
    sub = parser.add_subparsers(dest="verb", required=True, metavar="VERB")
    for name, module_name in VERBS.items():
        try:
            module = importlib.import_module(f"depthq.scripts.{module_name}")
        except ModuleNotFoundError as err:
            if err.name == f"depthq.scripts.{module_name}":
                continue  # verb not built yet
            raise
        summary = (module.__doc__ or "").strip().splitlines()[0]
        p = sub.add_parser(name, help=summary.replace("%", "%%"))  # argparse %-formats help texts
        if name == verb:
            module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    verb = next((a for a in argv if not a.startswith("-")), None)  # the global flags take no value
    before_verb = argv[: argv.index(verb)] if verb else argv
    debug = "--debug" in before_verb or os.environ.get(DEBUG_ENV, "") not in ("", "0")
    writes: list[Path] = []  # the folders the verb writes: named when the system names no path
    try:
        args = build_parser(verb).parse_args(argv)  # a verb's flags may load MuJoCo, and so fail
        writes = [path for _, path in written(args)]
        with ExitStack() as held:
            for flag, path in written(args):
                held.enter_context(exclusive(path, flag, verb or ""))
            return int(args._run(args) or 0)
    except KeyboardInterrupt:
        print(f"depthq {verb}: interrupted; run the same command again to resume.", file=sys.stderr)
        return 130
    except Exception as err:
        status, line = explain(err, writes)
        if status is None:
            raise  # a bug, not the input or the machine: the traceback is what helps
        if debug:
            traceback.print_exc()
        print(f"depthq {verb}: {line}", file=sys.stderr)
        return status


def written(args: argparse.Namespace) -> list[tuple[str, Path]]:
    """The folders a verb writes, by the flag that names them, each locked for the verb's life
    (`depthq.lock`): its --out, or what it names in `_writes` (label: the dataset it labels); none
    in a dry run, which writes nothing (not even a lock file)."""
    if getattr(args, "dry_run", False):
        return []
    names = getattr(args, "_writes", ("out",))
    return [(f"--{name}" if name == "out" else name.upper(), getattr(args, name))
            for name in names if isinstance(getattr(args, name, None), Path)]


if __name__ == "__main__":
    sys.exit(main())
