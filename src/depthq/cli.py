"""The `depthq` command: one sub-command per verb, each defined in `depthq.scripts.<verb>`."""

from __future__ import annotations

import argparse
import errno
import importlib
import sys

from depthq import __version__
from depthq.errors import ConfigError, DataError

# verb -> module in depthq.scripts; each module has `add_arguments(parser)` and `run(args) -> int`.
VERBS: dict[str, str] = {
    "drive": "drive",
    "bench": "bench",
    "collect": "collect",
    "dataset": "dataset",
    "train": "train",
    "evaluate": "evaluate",
    "reproduce": "reproduce",
    "sweep": "sweep",
    "probe": "probe",
    "export": "export",
    "bag": "bag",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="depthq",
        description="Monocular collision avoidance from future depth: collect, train, evaluate, reproduce.",
    )
    parser.add_argument("--version", action="version", version=f"depthq {__version__}")
    sub = parser.add_subparsers(dest="verb", required=True, metavar="VERB")
    for verb, module_name in VERBS.items():
        try:
            module = importlib.import_module(f"depthq.scripts.{module_name}")
        except ModuleNotFoundError as err:
            if err.name == f"depthq.scripts.{module_name}":
                continue  # verb not built yet
            raise
        summary = (module.__doc__ or "").strip().splitlines()[0]
        p = sub.add_parser(verb, help=summary.replace("%", "%%"))  # argparse %-formats help texts
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except ConfigError as err:
        print(f"depthq {args.verb}: error: {err}", file=sys.stderr)
        return 2
    except DataError as err:
        print(f"depthq {args.verb}: data error: {err}", file=sys.stderr)
        return 1
    except OSError as err:
        if err.errno != errno.ENOSPC:
            raise
        print(f"depthq {args.verb}: disk full ({err.filename or err}); nothing half-written is kept as a "
              "result: free space and run the same command to resume.", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"depthq {args.verb}: interrupted; run the same command again to resume.", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
