"""Lock-step evaluation (docs/design.md#lockstep) gives the runs of one canyon at a time: a batched
decision is the one-frame decision, from values equal but for the last bits a batch's sums may
change, and whole runs (every action, every runs.csv record) are the same. Real MuJoCo runs, real
EfficientNet-Lite0 weights, real trainings; no mocks."""

from __future__ import annotations

import csv
import json
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np
import pytest
import torch
from paper_head import paper_head

from depthq.blocks.heads import QNet
from depthq.blocks.trunk import DEFAULT_TRUNK, build_trunk
from depthq.cli import main
from depthq.control.heuristic import DepthHeuristic
from depthq.control.ou import OUPolicy
from depthq.control.policy import BatchPolicy
from depthq.evaluate.lockstep import Lane, drive_lockstep, lane_policies
from depthq.evaluate.online import EvalConfig, drive, evaluate, parse_canyon_set, shares
from depthq.networks import build_head, get_network
from depthq.policies.qnet import BATCH_FRAMES, QNetPolicy
from depthq.sim.env import CanyonEnv

DEPTH = get_network("depth")
COLL = get_network("coll")

CANYONS = ("val:1000", "val:1001", "val:1002")
LAST_BITS = 2.5e-6  # + 1e-6 relative: what a batch's sums may change (docs/design.md#lockstep)


def _untrained() -> list[QNetPolicy]:
    """Depth-Q-Net (one step and 3 ahead) and Coll-Q-Net policies on the real trunk with freshly
    initialised heads (bits need no training)."""
    torch.manual_seed(0)
    trunk = build_trunk(DEFAULT_TRUNK)
    heads = [paper_head("depth", trunk.feature_dim), paper_head("depth", trunk.feature_dim, lookahead=3),
             paper_head("coll", trunk.feature_dim)]
    return [QNetPolicy(QNet(trunk, build_head(head)), head.kind) for head in heads]


def _same_run(a: dict, b: dict) -> bool:
    """Two runs' records equal, their decision times aside (arrays compared element by element)."""
    keys = a.keys() - {"decision_ms_median", "snapshots", "video"}
    return keys == b.keys() - {"decision_ms_median", "snapshots", "video"} and all(
        np.array_equal(a[k], b[k]) for k in keys
    )


def _alone_and_lockstep(make, lanes: list[Lane], time_limit_s: float) -> tuple[list, list]:
    """Every lane driven alone in one env by a policy from `make`, then all of them in lock-step, each
    in an env of its own."""
    policy = make()
    config = EvalConfig(canyons=tuple(lane.canyon for lane in lanes), time_limit_s=time_limit_s).env
    envs, expert = [CanyonEnv(config) for _ in lanes], DepthHeuristic()
    try:
        alone = [drive(policy, envs[0], expert, lane.canyon, lane.seed, lane.keep_every, lane.video)
                 for lane in lanes]
        together = drive_lockstep(lane_policies(policy, make, len(lanes)), envs, expert, lanes)
    finally:
        for env in envs:
            env.close()
    return alone, together


@pytest.fixture(autouse=True)
def one_torch_thread():
    """One torch thread, as in an evaluation's workers: with two, torch splits a batch's sums
    otherwise than one frame's (the bits differ at any batch size)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def assert_batch_decides_as_alone(policy: QNetPolicy, observations: list[dict]) -> None:
    """`act_batch` on all frames and on two of them: each frame's decision as alone, its values within
    last-bit noise (well inside the selection's tie tolerance, so no tie can flip)."""
    alone, values = [], []
    for obs in observations:
        alone.append(policy.act(obs))
        values.append(policy.last_values)
    for frames in (slice(None), slice(5, 7)):  # whichever frames share the call
        assert policy.act_batch(observations[frames]) == alone[frames]
        for batched, one in zip(policy.last_batch_values, values[frames], strict=True):
            np.testing.assert_allclose(batched, one, rtol=1e-6, atol=LAST_BITS)


def test_a_batched_decision_is_one_frame_decisions() -> None:
    rng = np.random.default_rng(0)
    observations = [{"image": f} for f in rng.integers(0, 256, (BATCH_FRAMES + 3, 308, 410, 3), np.uint8)]
    for policy in _untrained():
        assert_batch_decides_as_alone(policy, observations)  # two trunk calls, one head call


def test_a_tie_within_last_bit_noise_stays_a_tie() -> None:
    actions = np.array([-1.0, 0.0, 1.0])
    for noise in (0.0, 3e-6, -3e-6):  # a few ulps of 2.5 m, as a batch's sums may add
        assert DEPTH.choose(np.array([[2.5], [2.5 + noise], [1.0]]), actions) == 0.0
        assert DEPTH.choose(np.array([[2.5 + noise], [1.0], [2.5]]), actions) == -1.0
    for noise in (0.0, 4e-7, -4e-7):  # a probability's last bits, at most a quarter of its logit's
        assert COLL.choose(np.array([0.2, 0.9, 0.2 + noise]), actions) == -1.0
    assert DEPTH.choose(np.array([[2.5], [2.5 - 2 * DEPTH.tie_tol], [1.0]]), actions) == -1.0


def test_which_policies_decide_in_batches() -> None:
    assert isinstance(DepthHeuristic(), BatchPolicy) and not isinstance(OUPolicy(), BatchPolicy)
    heuristic = DepthHeuristic()
    assert lane_policies(heuristic, DepthHeuristic, 3) == [heuristic] * 3
    ou = lane_policies(OUPolicy(seed=0), OUPolicy, 3)  # per-run noise state: an instance per run
    assert len({id(p) for p in ou}) == 3
    assert shares(tuple(f"eval:{i}" for i in range(5)), True, 2) == [
        ((0, "eval:0"), (2, "eval:2"), (4, "eval:4")), ((1, "eval:1"), (3, "eval:3"))
    ]
    assert len(shares(("eval:0", "eval:1"), False, 2)) == 2 and len(shares(("eval:0",), True, 4)) == 1


@pytest.mark.parametrize("name", ["heuristic", "ou"])
def test_reference_policies_drive_in_lockstep_as_alone(name: str) -> None:
    make = {"heuristic": DepthHeuristic, "ou": lambda: OUPolicy(seed=0)}[name]
    lanes = [Lane(c, 1000 + k, keep_every=5 * (k == 0), video=k == 0) for k, c in enumerate(CANYONS)]
    alone, together = _alone_and_lockstep(make, lanes, time_limit_s=3.0)
    assert [r["canyon"] for r in together] == list(CANYONS)
    assert all(_same_run(a, b) for a, b in zip(alone, together, strict=True))
    assert len(together[0]["video"]) == together[0]["steps"] and not together[1]["video"]


@pytest.fixture
def checkpoints(toy_nets: dict[str, Path]) -> dict[str, Path]:
    """A Depth-Q-Net and a Coll-Q-Net trained for two batches on conftest's small dataset (conftest's)."""
    return toy_nets


@pytest.mark.slow
def test_a_checkpoint_drives_in_lockstep_as_alone(checkpoints: dict[str, Path]) -> None:
    for folder in checkpoints.values():
        lanes = [Lane(c, 1000 + k, keep_every=5 * (k == 0), video=k == 0) for k, c in enumerate(CANYONS)]
        alone, together = _alone_and_lockstep(partial(QNetPolicy.from_checkpoint, folder), lanes, 4.0)
        assert all(_same_run(a, b) for a, b in zip(alone, together, strict=True))
        for a, b in zip(alone[0]["snapshots"], together[0]["snapshots"], strict=True):
            np.testing.assert_allclose(a["values"], b["values"], rtol=1e-6, atol=LAST_BITS)


def _records(folder: Path) -> list[dict[str, str]]:
    with (folder / "runs.csv").open() as f:
        return [{k: v for k, v in row.items() if k != "decision_ms_median"} for row in csv.DictReader(f)]


@pytest.mark.slow
def test_lockstep_evaluation_writes_the_sequential_runs(checkpoints: dict[str, Path], tmp_path: Path) -> None:
    config = EvalConfig(canyons=parse_canyon_set("val:1000-1002"), time_limit_s=6.0)
    spec, alone, together = str(checkpoints["depth"]), tmp_path / "alone", tmp_path / "lockstep"
    evaluate(spec, alone, replace(config, lockstep=False), workers=1, progress=False, video=False)
    evaluate(spec, together, config, workers=1, progress=False)  # one worker: all three in one batch
    assert _records(together) == _records(alone)
    for folder in (together, alone):  # the machine that made them (docs/design.md#determinism)
        assert json.loads((folder / "summary.json").read_text())["host"]["torch"]["threads"] == 1
    trained = json.loads((checkpoints["depth"] / "config.json").read_text())["host"]
    assert trained["torch"]["threads"] >= 1 and trained["cpu"]["machine"]
    with np.load(together / "trajectories.npz") as a, np.load(alone / "trajectories.npz") as b:
        assert a.files == b.files and all(np.array_equal(a[k], b[k]) for k in a.files)
    assert (together / "video.mp4").stat().st_size > 1000


@pytest.mark.slow
def test_benches_time_a_batch_and_both_evaluations(
    checkpoints: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    def bench(*args: str) -> dict:
        assert main(["bench", *args, "--json"]) == 0
        return json.loads(capsys.readouterr().out.strip().splitlines()[-1])

    result = bench("policy", "--policy", str(checkpoints["coll"]), "--decisions", "2", "--batches", "1",
                   "--threads", "1")
    (policy,) = result["policies"]
    assert result["batch"] == 20 and 0 < policy["batch_ms_per_decision"] < policy["batch_ms_median"]
    assert policy["candidates"] == 3
    result = bench("evaluate", "--policy", "heuristic", "--canyons", "val:1000-1001", "--time-limit", "1",
                   "--workers", "1")
    assert result["same_runs"] and result["decisions"] == 2 * 4 and result["sequential_s"] > 0
    result = bench("step", "--policy", str(checkpoints["depth"]), "--canyon", "hard/val:1000", "--steps", "3")
    sim, nets = result["sim_ms"], result["policy_ms"]
    assert result["canyon"] == "hard/val:1000" and all(v >= 0 for v in (*sim.values(), *nets.values()))
    assert sim["render"] > 0 and nets["trunk_one"] > 0 and nets["head_in_batch"] > 0
    floor = sum(sim.values()) + nets["trunk_in_batch"] + nets["head_in_batch"]
    assert result["floor_ms_per_step"] == pytest.approx(floor, abs=0.02)
    assert result["batch_bound"] > 1  # 20 frames through the trunk cost more than one decision
    assert main(["bench", "step", "--canyon", "nowhere:1"]) == 2
