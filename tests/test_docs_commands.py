"""The commands of the user docs work as written: each `depthq` line of the bash blocks of Getting
started, then of each guide and network page, runs in order in one folder at toy size (flags appended
that shrink it: argparse takes a flag's last value), and writes what the next line reads; a long job
(`reproduce`, `sweep`) has its flags parsed only. The guides that need ROS or a Ray cluster (robot.md,
cluster.md) have every command parsed by its verb's parser (they run in tests/test_ros.py and
tests/test_cluster.py)."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from depthq.cli import build_parser, main

DOCS = Path(__file__).parents[1] / "docs"
# The user pages, in an order a reader may follow: later pages use what earlier ones wrote (camera labels
# last: labelling rewrites runs/data's run files).
PAGES = ("getting-started.md", "networks/depth-q-net.md", "networks/coll-q-net.md", "guides/evaluate.md",
         "guides/own-data.md", "guides/looks.md", "guides/camera-labels.md")
# Appended to a verb's documented command so that it runs in seconds; verbs not named here run as written.
TOY = {
    "collect": ["--runs", "4", "--val-runs", "1", "--max-steps", "40", "--workers", "1"],
    "train": ["--epochs", "1", "--train-batches", "2", "--val-batches", "1", "--runs", "none"],
    "evaluate": ["--time-limit-s", "3", "--no-video", "--workers", "1"],
    "drive": ["--time-limit-s", "3"],
    "labeller": ["--steps", "2", "--batch-size", "4"],
}
# Guides whose commands need ROS 1 or a Ray cluster: parsed, so a flag they name cannot drift away.
PARSED_PAGES = ("robot.md", "cluster.md")
PARSED_ONLY = {"reproduce", "sweep"}  # long jobs; the smoke preset itself runs in tests/test_reproduce.py


def _commands(page: Path) -> list[list[str]]:
    blocks = re.findall(r"```bash\n(.*?)```", page.read_text(), flags=re.S)
    lines = [line.split("  #")[0].strip() for block in blocks for line in block.splitlines()]
    return [shlex.split(line.removesuffix("&"))[1:] for line in lines if line.startswith("depthq ")]


def test_every_user_page_is_run() -> None:
    """A user page with commands is in PAGES (so a new guide's commands cannot go untested)."""
    pages = {str(p.relative_to(DOCS)) for p in [DOCS / "getting-started.md", *DOCS.glob("guides/*.md"),
                                                 *DOCS.glob("networks/*.md")] if _commands(p)}
    assert pages <= set(PAGES), sorted(pages - set(PAGES))


@pytest.mark.parametrize("page", PARSED_PAGES)
def test_the_ros_and_cluster_guides_commands_parse(page: str) -> None:
    commands = _commands(DOCS / page)
    assert commands
    for argv in commands:
        try:
            build_parser(argv[0]).parse_args(argv)
        except SystemExit as stop:  # `--help`
            assert stop.code == 0 and "--help" in argv, argv


@pytest.mark.slow
def test_user_docs_commands_run_as_written(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    commands = [c for page in PAGES for c in _commands(DOCS / page)]
    assert commands[0][:3] == ["reproduce", "--preset", "smoke"]
    monkeypatch.chdir(tmp_path)
    for argv in commands:
        verb = argv[0]
        if verb in PARSED_ONLY:
            build_parser(verb).parse_args(argv)
            continue
        assert main([*argv, *TOY.get(verb, [])]) == 0, argv
    for written in ("runs/dqn/config.json", "runs/dqn-eval/summary.json", "runs/dqn-camera/config.json",
                    "runs/robot-dqn/config.json", "runs/onnx", "runs/dqn-heldout/summary.json"):
        assert (tmp_path / written).exists(), written
    assert any((tmp_path / "runs/drive").iterdir())


def test_extending_pages_policy_loop_drives_a_canyon() -> None:
    """Extending's Gymnasium loop runs as written, with the expert as `my_policy`, to the run's end."""
    from depthq.control.heuristic import DepthHeuristic

    blocks = re.findall(r"```python\n(.*?)```", (DOCS / "extending.md").read_text(), flags=re.S)
    loop = next(b for b in blocks if "gym.make" in b)
    scope: dict = {"my_policy": DepthHeuristic()}
    exec(loop, scope)  # the project's own docs page
    assert scope["done"] and scope["info"]["distance"] > 5.0
