"""Shared fixtures. Rendering is real MuJoCo through EGL (software Mesa on CPU machines)."""

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
# Ray's token authentication, as Ray itself turns on for a cluster started here, set before Ray is
# imported (it reads the mode once per process): the two-node test's driver must join with it.
os.environ.setdefault("RAY_AUTH_MODE", "token")
# Ray starts its workers at niceness 15; beside another pytest-xdist worker's tests they would wait
# for the core (the two-node test took 7 min instead of 1): here they run at the tests' own priority.
os.environ.setdefault("RAY_worker_niceness", "0")

# Under pytest-xdist (the default, `-n auto` in pyproject.toml) each worker's tests get their own
# share of the cores, as every long job here is pinned: torch sizes its thread pool to the affinity
# (`depthq.parallel.cores`), and two pools spinning on the same cores run several times slower.
# A Ray test gets every core: the Ray nodes and workers it starts are processes of its own, which
# inherit the affinity they are started with.
# (Linux only: elsewhere every test runs where the OS puts it.)
_PINNED = hasattr(os, "sched_setaffinity")
_ALL_CPUS = sorted(os.sched_getaffinity(0)) if _PINNED else []
_MY_CPUS = _ALL_CPUS
if _PINNED and "PYTEST_XDIST_WORKER" in os.environ:
    _index, _count = int(os.environ["PYTEST_XDIST_WORKER"][2:]), int(os.environ["PYTEST_XDIST_WORKER_COUNT"])
    if _count <= len(_ALL_CPUS):
        _MY_CPUS = _ALL_CPUS[_index::_count]


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    """Before any of a test's fixtures: the cores it may use (see `_MY_CPUS`)."""
    if _PINNED:
        os.sched_setaffinity(0, _ALL_CPUS if item.get_closest_marker("ray") else _MY_CPUS)


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """`-n auto`: one worker per core this process may use (not the machine's count)."""
    return len(_ALL_CPUS) or os.cpu_count() or 1


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The tests that start Ray run in one worker, one after another (`--dist loadgroup`): a second
    Ray runtime on the same machine would compete for its ports and temp folders. A test that needs
    the smoke preset's run (the `smoke` fixture) is `slow`, so the fast loop never runs the preset."""
    for item in items:
        if item.get_closest_marker("ray"):
            item.add_marker(pytest.mark.xdist_group("ray"))
        if "smoke" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.slow)


@pytest.fixture(scope="session")
def smoke(tmp_path_factory):
    """The smoke preset run end to end on this machine's processes (about a minute), under umask 022
    (tests/test_reproduce.py checks every file's mode)."""
    from depthq.report.reproduce import reproduce

    out = tmp_path_factory.mktemp("smoke") / "out"
    old = os.umask(0o022)
    try:
        reproduce("smoke", out, progress=False)
    finally:
        os.umask(old)
    return out


@pytest.fixture(scope="session")
def small_dataset(tmp_path_factory):
    """The suite's small collected dataset, for every test that needs "some runs": 6 training runs
    (3 end in a bump) and 2 validation runs of ≤ 60 steps, seed 0; collected once per session. Tests
    may add to its feature cache (training does) but must not change its runs: copy it first."""
    from depthq.data.recorder import CollectConfig, collect

    root = tmp_path_factory.mktemp("small") / "data"
    collect(root, CollectConfig(runs=6, val_runs=2, max_steps=60), workers=1, progress=False)
    return root


@pytest.fixture(scope="session")
def small_hard_dataset(tmp_path_factory):
    """A small dataset of the hard canyon family: 3 training runs and 1 validation run of ≤ 40 steps,
    seed 0, collected once per session (the other family than `small_dataset`'s, for what must learn on
    one family and act on the other). Tests may add to its feature cache but must not change its runs."""
    from depthq.data.recorder import CollectConfig, collect, exploration_env

    root = tmp_path_factory.mktemp("small_hard") / "data"
    config = CollectConfig(runs=3, val_runs=1, max_steps=40, env=exploration_env(family="hard"))
    collect(root, config, workers=1, progress=False)
    return root


@pytest.fixture(scope="session")
def toy_nets(small_dataset, tmp_path_factory):
    """A Depth-Q-Net and a Coll-Q-Net trained for two batches of one epoch on `small_dataset`, once per
    session: {"depth": folder, "coll": folder}, for what needs some trained network (export, lock-step
    driving, benches). Read-only: a test that trains on goes on in a copy."""
    from depthq.train.config import TrainConfig
    from depthq.train.trainer import train

    root = tmp_path_factory.mktemp("toy_nets")
    fast = {"epochs": 1, "train_batches": 2, "val_batches": 1, "batch_size": 16}
    return {kind: train(TrainConfig(model=kind, data=str(small_dataset), **fast), root / kind, progress=False)
            for kind in ("depth", "coll")}


@pytest.fixture(scope="session")
def reference_collection(tmp_path_factory):
    """4 training runs and 1 validation run of ≤ 40 steps, seed 3, collected in this process (one
    worker): the collection tests/test_collect.py tests, which its other collections (2 workers, the
    CLI, resumed after kill -9) must repeat, as tests/test_parallel.py's on Ray must. Read-only."""
    from depthq.data.recorder import CollectConfig, collect

    root = tmp_path_factory.mktemp("reference") / "ds"
    return collect(root, CollectConfig(runs=4, val_runs=1, max_steps=40, seed=3), workers=1, progress=False)


OU_CANYONS = ("val:1000", "val:1001", "val:1002")


@pytest.fixture(scope="session")
def ou_evaluation_one_worker(tmp_path_factory):
    """OU exploration evaluated in 3 val canyons for 6 s each by one local worker, no video: what 2
    workers (tests/test_evaluate.py) and Ray actors (tests/test_parallel.py) must repeat. Returns
    (its EvalConfig, its summary). Read-only."""
    from depthq.evaluate.online import EvalConfig, evaluate

    config = EvalConfig(canyons=OU_CANYONS, time_limit_s=6.0)
    out = tmp_path_factory.mktemp("ou_one_worker") / "eval"
    return config, evaluate("ou", out, config, workers=1, progress=False, video=False)


def unchecked(record: dict) -> dict:
    """A checkpoint's config.json record, edited by a test, as a depthq before checksums wrote it: without
    its "sha256" (an edited record with it is refused as changed, docs/formats.md#checksums)."""
    return {k: v for k, v in record.items() if k != "sha256"}


def without_timing(runs: list[dict]) -> list[dict]:
    """Evaluated runs less what depends on the machine's speed."""
    return [{k: v for k, v in r.items() if k != "decision_ms_median"} for r in runs]


def assert_video(path, n_frames: int, fps: float) -> None:
    """A playable H.264 MP4 of the first canyon: one 1280×400 frame per decision, not blank, moving."""
    import imageio_ffmpeg
    import numpy as np

    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    assert meta["codec"] == "h264" and meta["size"] == (1280, 400) and meta["fps"] == fps
    frames = [np.frombuffer(f, np.uint8).reshape(400, 1280, 3) for f in reader]
    assert len(frames) == n_frames
    assert frames[0].std() > 20 and np.abs(frames[-1].astype(int) - frames[0]).mean() > 0.5
