"""The commands of the user docs' Getting started page work as written: each `depthq` line of its bash
blocks runs, in order, at toy size (flags appended that shrink it: argparse takes a flag's last value),
and writes what the next line reads; a long job (`reproduce`) has its flags parsed only."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from depthq.cli import build_parser, main

PAGE = Path(__file__).parents[1] / "docs" / "getting-started.md"
# Appended to a verb's documented command so that it runs in seconds; verbs not named here run as written.
TOY = {
    "collect": ["--runs", "4", "--val-runs", "1", "--max-steps", "40", "--workers", "1"],
    "train": ["--epochs", "1", "--train-batches", "2", "--val-batches", "1"],
    "evaluate": ["--time-limit-s", "3", "--no-video", "--workers", "1"],
    "drive": ["--time-limit-s", "3"],
}
PARSED_ONLY = {"reproduce"}  # long jobs; the smoke preset itself runs in tests/test_reproduce.py


def _commands(page: Path) -> list[list[str]]:
    blocks = re.findall(r"```bash\n(.*?)```", page.read_text(), flags=re.S)
    lines = [line.split("  #")[0].strip() for block in blocks for line in block.splitlines()]
    return [shlex.split(line)[1:] for line in lines if line.startswith("depthq ")]


@pytest.mark.slow
def test_getting_started_commands_run_as_written(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    commands = _commands(PAGE)
    assert [c[0] for c in commands] == ["reproduce", "collect", "train", "evaluate", "drive"]
    monkeypatch.chdir(tmp_path)
    for argv in commands:
        verb = argv[0]
        if verb in PARSED_ONLY:
            build_parser(verb).parse_args(argv)
            continue
        assert main([*argv, *TOY.get(verb, [])]) == 0, argv
    assert (tmp_path / "runs/dqn/config.json").is_file()
    assert (tmp_path / "runs/dqn-eval/summary.json").is_file()
    assert any((tmp_path / "runs/drive").iterdir())
