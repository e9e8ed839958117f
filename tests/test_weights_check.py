"""The weights check (`research.weights_check`): per weights choice, dead bins, the spread of
the candidates' scores and the actions chosen on the checkpoint's validation frames, and each choice
driven; bad input named before any work."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from depthq.checkpoint import (
    AVERAGE_TOLERANCE_SE,
    average_fails,
    average_margin,
    chosen_weights,
    read_config,
    read_sidecar,
    write_sidecar,
)
from depthq.configio import read_json
from depthq.errors import ConfigError
from depthq.evaluate.online import EvalConfig, evaluate, evaluation_done
from depthq.policies.qnet import QNetPolicy
from research import weights_check


def test_each_weights_choice_is_looked_at_and_driven(toy_nets: dict[str, Path], tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    depth, coll = toy_nets["depth"], toy_nets["coll"]
    assert weights_check.available(depth) == ("final", "best", "average")  # the depth-first default averages
    assert weights_check.available(coll) == ("final", "best")
    measured = weights_check.measure(depth, ("final", "average"), frames=12)
    for m in measured.values():
        assert m["frames"] == 12 and set(m["dead_bins"]) <= set(range(26))
        assert 0 <= m["phantom"] <= 1 and set(m["phantom_bins"]) <= set(range(26)) - set(m["dead_bins"])
        assert bool(m["phantom_bins"]) == (m["phantom"] > 0)
        assert 0 <= m["spread_median"] <= m["spread_p90"]
        assert sum(m["chosen"].values()) == pytest.approx(1.0) and list(m["chosen"]) == ["-1", "+0", "+1"]
    assert weights_check.range_min(depth) == 0.12  # the toy dataset's LiDAR
    coll_best = weights_check.measure(coll, ("best",), frames=12)["best"]
    assert coll_best["dead_bins"] == coll_best["phantom_bins"] == [] and coll_best["phantom"] == 0  # no bins

    out = tmp_path / "check"
    argv = [str(depth), "--weights", "final,best", "--frames", "12", "--canyons", "val:1000",
            "--out", str(out)]
    assert weights_check.main(argv) == 0
    rows = capsys.readouterr().out.splitlines()
    assert rows[0].startswith("| weights | dead bins | phantom readings (bins) |")
    assert [r.split(" | ")[0] for r in rows[2:]] == ["| final", "| best"]
    record = read_json(out / "weights_check.json")
    for choice in ("final", "best"):
        summary = read_json(out / choice / "summary.json")
        assert summary["summary"]["distance_to_collision_mean"] == record["driven"][choice][
            "distance_to_collision_mean"]
        assert summary["policy"]["weights"] == ("last" if choice == "final" else choice)


def test_parts_pair_one_choice_perception_with_another_dynamics(toy_nets: dict[str, Path]) -> None:
    depth = toy_nets["depth"]
    mixed = weights_check.parts(depth, ("final", "average"), frames=12)
    measured = weights_check.measure(depth, ("final", "average"), frames=12)
    for choice in ("final", "average"):  # a choice paired with itself is that choice
        assert mixed[choice][choice] == pytest.approx(measured[choice]["spread_median"])
    assert set(mixed["final"]) == {"final", "average"}
    with pytest.raises(ConfigError, match="depth_first"):
        weights_check.parts(toy_nets["coll"], ("final",), frames=12)


def test_bad_input_is_named_before_any_work(toy_nets: dict[str, Path], tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    depth = str(toy_nets["depth"])
    for argv, named in (([depth, "--weights", "mean"], "mean"), ([depth, "--frames", "0"], "--frames"),
                        ([depth, "--canyons", "val:1000"], "--out")):
        assert weights_check.main(argv) == 2
        assert named in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_a_weight_average_that_fails_its_check_is_not_acted_with(toy_nets: dict[str, Path], tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "depth"
    shutil.copytree(toy_nets["depth"], folder)
    config = read_config(folder)
    assert config["train"]["weights"] == "average" and not average_fails(folder, config)
    assert QNetPolicy.from_checkpoint(folder).weights == "average"
    driven = tmp_path / "eval"
    evaluate(str(folder), driven, EvalConfig(canyons=("val:1000",), time_limit_s=1.0), workers=1,
             progress=False, video=False)
    assert evaluation_done(driven)

    # Its validation loss worse than the final weights' by more than the tolerance: the final act.
    final, average = read_sidecar(folder, "last"), read_sidecar(folder, "average")
    samples = config["train"]["val_batches"] * config["train"]["batch_size"]
    error = ((average["val_loss_std"] ** 2 + final["val_loss_std"] ** 2) / samples) ** 0.5
    for z, fails in ((AVERAGE_TOLERANCE_SE - 0.1, False), (AVERAGE_TOLERANCE_SE + 0.1, True)):
        write_sidecar(folder, "average", {**average, "val_loss": final["val_loss"] + z * error})
        assert average_fails(folder, config) is fails
    assert chosen_weights(config, None, folder) == "final"
    assert chosen_weights(config, "average", folder) == "average"
    assert average_margin(folder, config) == pytest.approx(AVERAGE_TOLERANCE_SE + 0.1)
    assert weights_check.main(["--margins", str(folder)]) == 0  # the survey of many checkpoints, here one
    assert f"| {folder} | {AVERAGE_TOLERANCE_SE + 0.1:+.2f} | final |" in capsys.readouterr().out
    assert QNetPolicy.from_checkpoint(folder).weights == "last"
    assert QNetPolicy.from_checkpoint(folder, weights="average").weights == "average"  # asked for: given
    assert not evaluation_done(driven)  # driven with the average: to drive again
    evaluate(str(folder), driven, EvalConfig(canyons=("val:1000",), time_limit_s=1.0), workers=1,
             progress=False, video=False)
    assert evaluation_done(driven) and read_json(driven / "summary.json")["policy"]["weights"] == "last"
