"""Oracles and a policy's agreement with them along its own runs (docs/design.md#oracles): real MuJoCo
canyons and evaluations, no mocks."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from depthq.cli import main
from depthq.control.action_selection import ACTIONS
from depthq.errors import ConfigError
from depthq.evaluate.online import EvalConfig, evaluate, parse_canyon_set
from depthq.evaluate.oracle import Oracle, OracleWorld, agreement, drive_oracle, env_config
from depthq.networks import Selection
from depthq.sim.env import SPAWN
from depthq.train.config import TrainConfig
from depthq.train.trainer import train


def test_oracles_parse_by_name_and_refuse_bad_ones() -> None:
    assert Oracle.parse("depth") == Oracle("depth", 1)
    assert Oracle.parse("coll:5") == Oracle("coll", 5)
    rule = Selection("farthest_nearest_bin")
    assert Oracle.parse("depth:3:farthest_nearest_bin") == Oracle("depth", 3, rule)
    assert str(Oracle.parse("depth:3")) == "depth:3:discounted_nearest_bin"
    for bad in ("bump:1", "depth:x", "coll:0", "coll:2:farthest_nearest_bin", "depth:2:nearest"):
        with pytest.raises(ConfigError):
            Oracle.parse(bad)


def test_a_collision_oracle_sees_the_wall_a_depth_oracle_scores_it() -> None:
    sim = OracleWorld(env_config(["hard/val:1000"], 4.0))
    try:
        sim.load("hard/val:1000")
        x, y = sim.env.world.canyon.left[1]  # the left wall where the canyon starts
        wall = np.array([x + 0.25, y + 0.3, np.pi])  # 25 cm from it, facing it
        assert sim.scores(Oracle("coll", 3), wall).tolist() == [1.0, 1.0, 1.0]  # every action bumps
        free = np.array(SPAWN)  # the canyon's start, facing along it
        assert sim.scores(Oracle("coll", 1), free).tolist() == [0.0, 0.0, 0.0]
        depth = sim.scores(Oracle("depth", 2), free)
        assert depth.shape == (3,) and (depth > 0).all()
        assert np.allclose(sim.env.world.pose, free)  # trying the candidates puts the robot back
    finally:
        sim.close()


def test_the_one_step_oracle_drives_a_paper_canyon() -> None:
    result = drive_oracle(Oracle(), ["val:1000"], 4.0)
    assert result["oracle"] == "depth:1" and result["canyons"] == 1
    assert result["progress_mean"] > 10 and result["runs"][0]["canyon"] == "val:1000"


@pytest.fixture(scope="module")
def ou_evaluation(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """OU exploration driven in two hard val canyons until it bumps: a policy with collisions."""
    out = tmp_path_factory.mktemp("agreement") / "ou"
    config = EvalConfig(canyons=parse_canyon_set("hard/val:1000-1001"), time_limit_s=20.0)
    evaluate("ou", out, config, workers=1, progress=False, video=False)
    return out


def test_agreement_along_a_policys_own_runs(ou_evaluation: Path, tmp_path: Path) -> None:
    summary, arrays = agreement(ou_evaluation, Oracle())
    with (ou_evaluation / "runs.csv").open() as f:
        runs = list(csv.DictReader(f))
    assert summary["steps"] == sum(int(r["steps"]) for r in runs) == len(arrays["agrees"])
    assert summary["collisions"] == sum(r["end_reason"] in ("bump", "contact") for r in runs) > 0
    assert 0 <= summary["collisions_with_pillar"] <= summary["collisions"]
    for key in ("agreement", "agreement_decisive", "agreement_before_collision"):
        assert 0 <= summary[key] <= 1
    late = arrays["to_collision_s"] <= 2.0
    assert summary["steps_before_collision"] == late.sum() > 0
    # the oracle's recorded choice is its choice from that pose, re-simulated
    sim = OracleWorld(env_config([runs[0]["canyon"]], 4.0))
    try:
        sim.load(runs[0]["canyon"])
        with np.load(ou_evaluation / "trajectories.npz") as t:
            pose = t["hard_val_1000_poses"][3]
        assert sim.choose(Oracle(), pose.astype(np.float64))[0] == arrays["oracle"][3]
    finally:
        sim.close()
    with pytest.raises(ConfigError, match="not a complete evaluation"):
        agreement(tmp_path, Oracle())


def test_probe_writes_agreement_and_refuses_bad_input(ou_evaluation: Path, tmp_path: Path) -> None:
    out = tmp_path / "probe"
    assert main(["probe", "--parts", "agreement", "--evals", str(ou_evaluation), "--oracle", "coll:2",
                 "--out", str(out)]) == 0
    assert (out / "probe.json").is_file() and (out / "agreement" / "ou_coll-2.png").stat().st_size > 1000
    assert main(["probe", "--parts", "agreement", "--out", str(tmp_path / "x")]) == 2
    assert main(["probe", "--parts", "oracle", "--oracle", "bump:1", "--out", str(tmp_path / "y")]) == 2


@pytest.mark.slow
def test_a_checkpoints_values_are_re_predicted_along_its_runs(
    small_dataset: Path, ou_evaluation: Path, tmp_path: Path
) -> None:
    with pytest.raises(ConfigError, match="checkpoint"):
        agreement(ou_evaluation, Oracle(), predictions=True)
    fast = {"epochs": 1, "train_batches": 2, "val_batches": 1, "batch_size": 16, "hidden": 32}
    folder = train(TrainConfig(model="depth", data=str(small_dataset), **fast), tmp_path / "dqn",
                   progress=False)
    config = EvalConfig(canyons=parse_canyon_set("hard/val:1000"), time_limit_s=3.0)
    evaluate(str(folder), tmp_path / "eval", config, workers=1, progress=False, video=False)
    summary, arrays = agreement(tmp_path / "eval", Oracle(), predictions=True)
    steps = summary["steps"]
    assert arrays["predicted"].shape == (steps, 3, 26) and arrays["predicted_scores"].shape == (steps, 3)
    assert arrays["true_bins"].shape == (steps, 3, 1, 26)
    assert 0 <= summary["same_decision_new_noise"] <= 1 and summary["score_error"] > 0
    assert summary["true_spread"] >= 0 and summary["predicted_spread"] >= 0
    # A Coll-Q-Net's decision is its lowest collision probability, and its values are no depth scores.
    folder = train(TrainConfig(model="coll", data=str(small_dataset), **fast), tmp_path / "cqn",
                   progress=False)
    evaluate(str(folder), tmp_path / "eval_coll", config, workers=1, progress=False, video=False)
    summary, arrays = agreement(tmp_path / "eval_coll", Oracle(), predictions=True)
    lowest = np.array(ACTIONS)[arrays["predicted_scores"].argmin(1)]
    assert summary["same_decision_new_noise"] == pytest.approx(float((lowest == arrays["policy"]).mean()))
    assert "score_error" not in summary
