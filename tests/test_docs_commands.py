"""The commands of the user docs work as written: each `depthq` line of the bash blocks of Getting
started, then of each guide and network page, runs in order in one folder at toy size (flags appended
that shrink it: argparse takes a flag's last value), and writes what the next line reads; a long job
(`reproduce`, `sweep`) has its flags parsed only. The guides that need ROS or a Ray cluster (robot.md,
cluster.md) have every command parsed by its verb's parser (they run in tests/test_ros.py and
tests/test_cluster.py)."""

from __future__ import annotations

import os
import re
import shlex
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

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


def _photos(folder: Path) -> None:
    """A user's folder of "photographs" (Getting started's `~/lab_photos`): coarse random blocks."""
    folder.mkdir()
    rng = np.random.default_rng(7)
    for k in range(3):
        blocks = rng.integers(0, 256, size=(4, 4, 3), dtype=np.uint8)
        Image.fromarray(np.kron(blocks, np.ones((16, 16, 1), np.uint8))).save(folder / f"wall{k}.png")


def test_every_bash_block_of_getting_started_is_run() -> None:
    """Getting started says every command on it runs here: each of its blocks is a `bash` block (the
    ones `_commands` reads) of `depthq` lines, or the install line (which CI's own venv runs)."""
    page = (DOCS / "getting-started.md").read_text()
    fences = re.findall(r"^```(\w*)\n(.*?)^```", page, flags=re.S | re.M)
    assert fences and all(language == "bash" for language, _ in fences), [f[0] for f in fences]
    for _, block in fences:
        lines = [line for line in block.splitlines() if line.strip()]
        assert all(line.startswith("depthq ") for line in lines) or "pip install" in block, block


def test_ci_runs_the_readmes_test_command_and_install() -> None:
    """`.ci/run` runs the README's command 2 as written (its venv named .venv-ci), and that command
    installs torch as the README's install line does (the CPU build, from PyTorch's CPU index)."""
    readme = (DOCS.parent / "README.md").read_text()
    command = next(line for line in readme.splitlines()
                   if line.startswith("python3 -m venv") and "pytest" in line)
    ci = (DOCS.parent / ".ci" / "run").read_text()
    assert command.replace(".venv", ".venv-ci") in ci.splitlines()
    install = re.search(r"```bash\n(python3 -m venv .*)\n```", readme).group(1)
    assert install.split(" && ")[2] == command.split(" && ")[2]
    assert "--index-url https://download.pytorch.org/whl/cpu" in install


@pytest.mark.slow
def test_user_docs_commands_run_as_written(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    commands = [c for page in PAGES for c in _commands(DOCS / page)]
    assert commands[0][:3] == ["reproduce", "--preset", "smoke"]
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HOME", str(tmp_path))  # `~` as the shell expands it: this folder
    _photos(tmp_path / "lab_photos")
    for argv in ([os.path.expanduser(a) for a in c] for c in commands):
        verb = argv[0]
        if verb in PARSED_ONLY:
            build_parser(verb).parse_args(argv)
            continue
        assert main([*argv, *TOY.get(verb, [])]) == 0, argv
    for written in ("runs/dqn/config.json", "runs/dqn-eval/summary.json", "runs/dqn-camera/config.json",
                    "runs/robot-dqn/config.json", "runs/onnx", "runs/dqn-heldout/summary.json",
                    "runs/dqn-look/summary.json", "runs/lab-data/manifest.json", "runs/dqn-lab/summary.json",
                    "runs/dqn-world/config.json", "runs/dqn-world-heldout/summary.json"):
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


def test_extending_pages_network_loads_through_its_entry_point(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Extending's third network, written as its package's module, is found by the entry point the page
    declares (as every process finds it), and its own setting is a flag of its name and a record's."""
    import tomllib
    from importlib.metadata import EntryPoint

    from depthq.configio import to_dict
    from depthq.flags import build_config
    from depthq.networks import get_network, registry
    from depthq.train.config import TrainConfig

    page = (DOCS / "extending.md").read_text()
    module = next(b for b in re.findall(r"```python\n(.*?)```", page, flags=re.S) if "register_network" in b)
    declared = tomllib.loads(next(iter(re.findall(r"```toml\n(.*?)```", page, flags=re.S))))
    points = declared["project"]["entry-points"][registry.ENTRY_POINTS]
    (tmp_path / "mypackage").mkdir()
    (tmp_path / "mypackage" / "__init__.py").write_text("")
    (tmp_path / "mypackage" / "clearance.py").write_text(module)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(registry, "_NETWORKS", dict(registry._NETWORKS))  # unregistered after the test
    monkeypatch.setattr(registry, "_installed", False)
    installed = [EntryPoint(name, value, registry.ENTRY_POINTS) for name, value in points.items()]
    monkeypatch.setattr(registry, "entry_points",
                        lambda group: installed if group == registry.ENTRY_POINTS else [])

    network = get_network("clearance")
    assert type(network).__module__ == "mypackage.clearance" and network.title == "Clearance-Net"
    config = build_config(TrainConfig, {"model": "clearance", "data": "d", "clearance.reach": 1.5})
    assert to_dict(config)["clearance"] == {"reach": 1.5} and config.head().kind == "clearance"
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    assert "--clearance.reach REACH" in capsys.readouterr().out
    assert main(["train", "--model", "clearance", "--data", "d", "--out", str(tmp_path / "o"),
                 "--clearance.reach", "0"]) == 2
    assert "clearance.reach must be > 0 m, got 0.0" in capsys.readouterr().err
