"""Executors: the same results from local processes and from Ray (a real Ray started on this
machine), and a failing worker named instead of a hang."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import without_timing

from depthq.cli import main
from depthq.data.manifest import Dataset
from depthq.data.recorder import CollectConfig, collect
from depthq.errors import ConfigError
from depthq.evaluate.online import EvalConfig, evaluate
from depthq.parallel import Executor, _probe_shared

ray = pytest.importorskip("ray")


@pytest.fixture(scope="module")
def on_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield Executor("ray")
    ray.shutdown()


@pytest.mark.slow
@pytest.mark.ray
def test_ray_gives_the_local_results(
    tmp_path: Path, on_ray: Executor, ou_evaluation_one_worker: tuple[EvalConfig, dict],
    reference_collection: Dataset,
) -> None:
    """The local results are conftest's, each made by one local worker: OU evaluated in 3 canyons, and
    a collection of 5 runs. Two Ray actors repeat them."""
    config, local = ou_evaluation_one_worker
    remote = evaluate("ou", tmp_path / "ray", config, workers=2, progress=False, video=False, executor=on_ray)
    assert without_timing(remote["runs"]) == without_timing(local["runs"])
    assert [r["canyon"] for r in remote["runs"]] == list(config.canyons)

    data = CollectConfig(runs=4, val_runs=1, max_steps=40, seed=reference_collection.seed)
    assert reference_collection.config == data.recorded()
    collect(tmp_path / "d_ray", data, workers=2, progress=False,
            executor=on_ray)
    manifest = "manifest.json"
    assert (tmp_path / "d_ray" / manifest).read_bytes() == (reference_collection.root / manifest).read_bytes()


class Failing:
    """A worker whose second task fails."""

    def __call__(self, task: int) -> int:
        if task == 1:
            raise ValueError(f"task {task} is bad")
        return task

    def close(self) -> None:
        pass


def test_a_failing_worker_is_reported_with_its_error() -> None:
    with pytest.raises(RuntimeError, match=r"(?s)a demo worker failed on task 1.*ValueError: task 1 is bad"):
        list(Executor().run(Failing, [0, 1, 2], workers=1, what="demo"))


def test_bad_executor_settings_are_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ConfigError, match="--executor must be one of"):
        Executor("slurm")
    with pytest.raises(ConfigError, match="needs --executor ray"):
        Executor("local", "auto")
    assert main(["evaluate", "heuristic", "--out", str(tmp_path / "o"), "--executor", "dask"]) == 2
    assert "dask" in capsys.readouterr().err and not (tmp_path / "o").exists()


@pytest.mark.slow
@pytest.mark.ray
def test_the_output_folder_is_checked_from_every_node(tmp_path: Path, on_ray: Executor) -> None:
    """On a Ray started here the folder passes (created, and no probe file left behind); a node that
    does not see the driver's token, or cannot write next to it, says so."""
    folder = tmp_path / "shared" / "out"
    on_ray.check_shared(folder)
    assert folder.is_dir() and not list(folder.iterdir())
    elsewhere = tmp_path / "elsewhere"
    assert _probe_shared(str(elsewhere / ".token"), "n1") == f"does not see {elsewhere}"
    token = folder / ".token"
    token.write_text("driver")
    (folder / ".token-n2").mkdir()  # a file the node cannot create
    assert _probe_shared(str(token), "n2").startswith(f"cannot write to {folder}")
    assert _probe_shared(str(token), "n3") == "" and (folder / ".token-n3").read_text() == "n3"
