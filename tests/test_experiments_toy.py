"""The investigations behind the docs' measurements (research/: action fidelity, hard canyons, the
investigation, the lookahead table, precision, val choices, DAgger rounds) at toy size: real
collections in the hard family, real trainings and evaluations, a copy of the suite's smoke run."""

from __future__ import annotations

import importlib
import json
import math
import pkgutil
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import research
from depthq.checksum import read_checked_json
from depthq.control.action_selection import ACTIONS
from depthq.control.ou import OUConfig, OUPolicy
from depthq.data.manifest import Dataset
from depthq.data.samples import SampleConfig
from depthq.errors import ConfigError
from depthq.evaluate.online import EvalConfig
from depthq.evaluate.oracle import OracleWorld, env_config
from depthq.pipeline.presets import get_preset
from depthq.pipeline.runner import run_sweep
from depthq.pipeline.sweep import parse_setting, widened
from depthq.sim.canyon import HARD_CANYON
from depthq.sim.sensors import depth_bins, finish_scan
from depthq.train.config import TrainConfig
from depthq.train.trainer import train
from research import (
    action_fidelity,
    coll_learning,
    dagger,
    hard_canyons,
    investigation,
    lookahead,
    precision,
    truth,
    val_choices,
)

TOY_TRAINING = {"epochs": 2, "train_batches": 5, "val_batches": 2}
DOCS = Path(__file__).resolve().parents[1] / "docs"


def test_every_experiment_is_a_module_with_a_command_line_and_docs_hold_no_python(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The experiments, live (how a published table is made now) and finished, are research/'s, outside
    the wheel (tests/test_layers.py: no `depthq` module imports one); each runs as `python -m NAME`."""
    assert not sorted(DOCS.rglob("*.py"))
    names = [f"research.{m.name}" for m in pkgutil.iter_modules(research.__path__)]
    assert {f"research.{name}" for name in (
        "camera_labels", "coll_learning", "looks", "ros_fidelity", "sizing", "weights_check",  # live
        "action_fidelity", "hard_canyons", "investigation", "lookahead", "oracle_gap", "precision",
        "val_choices",
    )} <= set(names)
    for name in names:
        module = importlib.import_module(name)
        if not hasattr(module, "main"):  # a shared helper (truth)
            continue
        with pytest.raises(SystemExit) as exit_:
            module.main(["--help"])
        assert exit_.value.code == 0
        assert capsys.readouterr().out.startswith(f"usage: python -m {name}")


@pytest.fixture(scope="module")
def hard_data(small_hard_dataset: Path) -> Path:
    """A toy dataset of the hard family (conftest's: 3 training runs and 1 validation run of ≤ 40
    steps); the experiments read it and add to its feature cache."""
    return small_hard_dataset


@pytest.fixture(scope="module")
def hard_checkpoints(hard_data: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Two Depth-Q-Nets on `hard_data`: the default target horizon (5) and horizon 1."""
    out = tmp_path_factory.mktemp("hard_models")
    return tuple(  # type: ignore[return-value]
        train(TrainConfig(model="depth", data=str(hard_data), samples=SampleConfig(horizon=h),
                          **TOY_TRAINING), out / f"h{h}", progress=False)
        for h in (5, 1)
    )


def _current_bins(sim: OracleWorld, pose: np.ndarray) -> np.ndarray:
    sim.env.world.place(*pose)
    return depth_bins(finish_scan(sim.env.world.raycast(), sim.exact, sim.rng), sim.env.config.bins)


@pytest.mark.slow
def test_truth_is_simulated_in_the_datasets_own_canyon_family(hard_data: Path) -> None:
    dataset = Dataset.open(hard_data)
    assert truth.family(dataset) == "hard" and truth.canyon(dataset, "val", 2) == "hard/val:2"
    run = dataset.read_run(dataset.entry("val", 0), images=False)
    own = truth.dataset_world(dataset)
    paper = OracleWorld(env_config(["val:0"], float(dataset.config["env"]["world"]["decision_hz"])))
    try:
        own.load("hard/val:0")
        paper.load("val:0")
        recorded = np.nan_to_num(run.bins[:10], nan=2.0)
        seen = {name: np.nan_to_num([_current_bins(sim, p.astype(float)) for p in run.poses[:10]], nan=2.0)
                for name, sim in (("own", own), ("paper", paper))}
    finally:
        own.close()
        paper.close()
    assert np.abs(seen["own"] - recorded).mean() < 0.03  # the recorded scans, up to the LiDAR's noise
    assert np.abs(seen["paper"] - recorded).mean() > 0.1  # the paper's canyon of that name is elsewhere


@pytest.mark.slow
def test_action_fidelity_shares_the_truth_between_label_horizons(
    hard_checkpoints: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    h5, h1 = hard_checkpoints
    cache: dict = {}
    first = action_fidelity.fidelity(h5, cache)
    frames = len(cache)
    second = action_fidelity.fidelity(h1, cache)  # more samples (those before each run's end): no crash
    assert len(cache) > frames
    for result in (first, second):
        assert len(result["l1_left_straight_right"]) == 3
        assert all(math.isfinite(v) and v >= 0 for v in result["l1_left_straight_right"])
        assert result["spread_true"] >= 0 and 0 <= result["agree"] <= 1 and result["decisive_frames"] > 0
    assert second["decisive_frames"] >= first["decisive_frames"]
    assert action_fidelity.main([str(h5), str(h1)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == ["h5", "h1"] and f"'agree': {second['agree']}" in lines[1]


@pytest.mark.slow
def test_the_investigation_checks_a_hard_dataset(hard_data: Path) -> None:
    dataset = Dataset.open(hard_data)
    assert set(investigation.sign_check(dataset)) == {1, -1}
    distances = investigation.oracle_distances(("val:1000",))
    assert len(distances) == 1 and distances[0] > 0
    assert 0 < investigation.constant_baseline(dataset) < 2
    effect, slope = investigation.action_effects(dataset)
    assert effect.shape == slope.shape == (26,) and np.isfinite(slope).all()
    assert np.isfinite(effect).any() and np.nanmax(np.abs(effect)) > 0  # turning changes what is seen


@pytest.mark.slow
def test_precision_compares_bf16_decisions_with_the_policys_own(hard_checkpoints: tuple[Path, Path]) -> None:
    result = precision.measure(hard_checkpoints[0], frames=8)  # asserts fp32 decides as the policy does
    assert result["frames"] == 8 and 0 <= result["changed"] <= 8
    assert 0 < result["fp32_ms"] < 1e4 and 0 < result["bf16_ms"] < 1e4


def test_coll_learning_scores_rank_probabilities_as_the_roc_area_does() -> None:
    positive = np.array([True, False, True, False])
    assert coll_learning.auc(np.array([0.9, 0.1, 0.8, 0.2]), positive) == 1.0
    assert coll_learning.auc(np.array([0.1, 0.9, 0.2, 0.8]), positive) == 0.0
    assert coll_learning.auc(np.full(4, 0.5), positive) == 0.5  # ties halved
    assert math.isnan(coll_learning.auc(np.ones(2), np.array([True, True])))


@pytest.mark.slow
def test_coll_learning_measures_a_coll_q_net_and_trains_drives_and_resumes_its_variants(
    hard_data: Path, tmp_path: Path
) -> None:
    like = train(TrainConfig(model="coll", data=str(hard_data), **TOY_TRAINING), tmp_path / "coll",
                 progress=False)
    (row,) = coll_learning.measure(like)
    assert row["look"] == Dataset.open(hard_data).config["env"]["world"]["look"]
    assert row["samples"] > 0 and 0 <= row["positives"] <= 1
    assert 0 <= row["spread"] <= 1 and row["constant"] > 0 and row["bce"] > 0
    with pytest.raises(ConfigError, match="not a Coll-Q-Net"):
        coll_learning.measure(train(TrainConfig(model="depth", data=str(hard_data), **TOY_TRAINING),
                                    tmp_path / "depth", progress=False))
    out = tmp_path / "chances"
    argv = ["run", str(like), str(out), "--variants", "pinned,final", "--canyons", "hard/val:1000"]
    assert coll_learning.main(argv) == 0
    results = read_checked_json(out / "results.json", coll_learning.FIX)
    assert set(results) == {"pinned", "final"} and not (out / "models" / "final").exists()  # one training
    summary = json.loads((out / "eval" / "final" / "summary.json").read_text())
    assert summary["config"]["weights"] == "final" and summary["config"]["canyons"] == ["hard/val:1000"]
    pinned = out / "eval" / "pinned" / "summary.json"
    stamp = pinned.stat().st_mtime_ns
    assert coll_learning.main(argv) == 0 and pinned.stat().st_mtime_ns == stamp  # resumed: not driven again
    assert coll_learning.main([*argv[:4], "pinned", *argv[5:], "--look", "flat"]) == 0  # another look
    flat = json.loads((out / "eval_flat" / "pinned" / "summary.json").read_text())
    assert flat["config"]["look"] == "flat" and pinned.stat().st_mtime_ns == stamp  # its own drive
    results = read_checked_json(out / "results.json", coll_learning.FIX)
    assert set(results) == {"pinned", "final", "flat/pinned"}
    assert coll_learning.main(["run", str(like), str(tmp_path / "bad"), "--canyons", "hard/eval:0"]) == 2
    assert not (tmp_path / "bad").exists()


@pytest.mark.slow
def test_dagger_drives_a_round_with_the_learned_policy_beside_the_linked_base_and_resumes(
    hard_data: Path, tmp_path: Path
) -> None:
    # The smoke preset's toy training; each model driven for 10 s in one paper canyon.
    setup = dagger.Setup(str(hard_data), preset="smoke", canyons="val:1000-1000", runs=3, rounds=1,
                         round_runs=1, time_limit_s=10.0)
    out = tmp_path / "dagger"
    assert dagger.run(out, setup) == 0
    base, data = Dataset.open(hard_data), Dataset.open(out / "s0" / "round1" / "data")
    last = dagger.base_indices(base, setup)[1]  # round 0's last usable run
    assert data.config["rounds"] == [{"round": 1, "driver": "round0/model", "noise": 1.0,
                                      "first": last + 1}]
    for entry in [base.entry("train", i) for i in range(last + 1)] + base.entries("val"):  # linked as is
        assert data.entry(entry.split, entry.index) == entry
    # Round 1 drives on from there, without a gap, until it has its one usable run.
    driven = [e for e in data.entries("train") if e.index > last]
    assert [e.index for e in driven] == list(range(last + 1, last + 1 + len(driven)))
    min_frames = base.config["data"]["min_frames"]
    assert [e.n_frames >= min_frames for e in driven] == [False] * (len(driven) - 1) + [True]
    new = driven[-1].index
    # Round 1's run drives the base run's canyon with its seeds; each command is the policy's action
    # plus the same OU command the base run had (where the robot's limit did not clip it).
    ours, theirs = data.entry("train", new), base.entry("train", new)
    assert (ours.canyon_seed, ours.policy_seed) == (theirs.canyon_seed, theirs.policy_seed)
    ou = OUPolicy(OUConfig(**base.config["ou"]), seed=ours.policy_seed)
    commands = np.array([ou.act() for _ in range(base.config["skip_frames"] + ours.n_frames)])
    actions = data.read_run(ours, images=False).actions[:-1]
    residual = actions - commands[base.config["skip_frames"]:][: len(actions)]
    inside = np.abs(actions) < base.config["env"]["world"]["max_yaw_rate"] - 1e-4
    assert inside.any() and np.allclose(np.min(np.abs(residual[inside, None] - np.array(ACTIONS)), axis=1), 0,
                                        atol=1e-5)
    assert np.abs(residual[inside]).max() > 0.5  # the policy steered, not only the noise
    names = ["round0", "round1", "coll"]
    configs = [json.loads((out / "s0" / "eval" / n / "summary.json").read_text())["config"] for n in names]
    assert [c["time_limit_s"] for c in configs] == [10.0] * 3
    rows = dagger.table(out, setup).splitlines()
    assert len(rows) == 2 + 3 and rows[2].startswith("| Depth-Q-Net, round 0 (exploration runs only) | 1 | ")
    rows = dagger.stats(out, setup).splitlines()  # what round 1 adds: its one usable run
    assert len(rows) == 2 + 2 and rows[3].startswith(f"| 0 | round 1 | 1 | {ours.n_frames:.1f} | ")
    manifest = (data.root / "manifest.json").read_bytes()
    assert dagger.run(out, setup) == 0 and (data.root / "manifest.json").read_bytes() == manifest  # resumed
    assert dagger.main(["run", str(out)]) == 2  # no --base
    assert dagger.main(["run", str(out), "--base", str(hard_data), "--runs", "3", "--rounds", "3"]) == 2
    assert dagger.main(["run", str(out), "--base", str(hard_data), "--net", "heuristic"]) == 2


@pytest.mark.slow
def test_val_choices_trains_drives_tabulates_and_resumes(hard_data: Path, tmp_path: Path) -> None:
    variants = {"coll_toy": {"model": "coll", **TOY_TRAINING}}
    config = EvalConfig(canyons=("hard/val:1000",), time_limit_s=5.0)
    row = val_choices.run_variant(hard_data, tmp_path, "coll_toy", variants, config)
    summary = json.loads((tmp_path / "eval" / "coll_toy" / "summary.json").read_text())["summary"]
    assert row["successes"] == summary["successes"] and sum(row["ends"].values()) == 1
    assert row["val_loss"] == json.loads((tmp_path / "coll_toy" / "best.json").read_text())["val_loss"]
    stamp = (tmp_path / "eval" / "coll_toy" / "summary.json").stat().st_mtime_ns
    assert val_choices.run_variant(hard_data, tmp_path, "coll_toy", variants, config) == row  # resumed
    assert (tmp_path / "eval" / "coll_toy" / "summary.json").stat().st_mtime_ns == stamp
    lines = val_choices.table([row]).splitlines()
    assert len(lines) == 3 and lines[2].startswith(f"| coll_toy | {row['val_loss']:.4f} | ")


@pytest.mark.slow
def test_hard_canyons_measures_a_candidate_and_draws_the_chosen_one(tmp_path: Path) -> None:
    short = replace(HARD_CANYON, n_segments=6)
    text = hard_canyons.calibrate(tmp_path, {"short": short}, "hard/val:1000", ou_runs=2, chosen=short)
    lines = text.splitlines()
    assert len(lines) == 3 and lines[2].startswith("| short (chosen) | ")
    assert lines[2].split(" | ")[1] in ("0/1", "1/1")
    assert (tmp_path / "hard_canyons.png").stat().st_size > 1000


@pytest.fixture(scope="module")
def looked_ahead(smoke: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of the smoke run with a Depth-Q-Net looking 3 steps ahead beside its own (`depthq sweep
    --preset smoke --nets depth --sizes 6 --seeds 0 --set depth.lookahead=3`)."""
    out = tmp_path_factory.mktemp("lookahead") / "sweep"
    shutil.copytree(smoke, out)
    sweep = widened(get_preset("smoke"), name="smoke sweep", subsets=(6,), seeds=(0,), nets=("depth",),
                    grid=(parse_setting("depth.lookahead=3"),))
    run_sweep(sweep, out, progress=False)
    return out


@pytest.mark.slow
def test_the_lookahead_table_pairs_the_two_depth_q_nets_by_seed(looked_ahead: Path) -> None:
    folder = looked_ahead
    lines = lookahead.table((folder, folder), sizes=(6,), seeds=(0,)).splitlines()
    assert [line.split(" | ")[0] for line in lines[2:]] == [
        "| Coll-Q-Net", "| Depth-Q-Net, one step", "| Depth-Q-Net, lookahead 3",
        "| lookahead 3 − one step, paired by seed"]
    one, look = (json.loads((folder / "eval" / name / "summary.json").read_text())["summary"]
                 for name in ("depth_n6_s0", "depth_n6_s0_lookahead3"))
    difference = look["distance_to_collision_mean"] - one["distance_to_collision_mean"]
    assert lines[5].split(" | ")[3] == f"{difference:.2f}"
    assert lines[4].endswith(f" | {look['distance_to_collision_mean']:.2f} |")
