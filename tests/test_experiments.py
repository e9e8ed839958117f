"""The oracle-gap investigations of research/ (oracle_gap, privileged, training_length) at toy size,
on a copy of the suite's smoke run (a real collection, trainings and evaluations): each runs, resumes
and tabulates what it measured."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import torch

from depthq.checkpoint import read_weights
from depthq.errors import ConfigError
from research import oracle_gap, privileged, training_length


@pytest.mark.slow
def test_the_oracle_gap_runs_a_candidate_measures_agreement_and_tabulates(
    smoke: Path, tmp_path: Path
) -> None:
    out = tmp_path / "gap"
    shutil.copytree(smoke, out)
    setup = oracle_gap.Setup(preset="smoke", canyons=None, runs=6, sizes=(6,), seeds=(0,))
    candidates = (oracle_gap.Candidate("default"),
                  oracle_gap.Candidate("bootstrap", ("depth.bootstrap=0.5",)))
    assert oracle_gap.run(out, setup, candidates) == 0
    names = [oracle_gap.model_names(setup, c, 6)[0] for c in candidates]
    assert names == ["depth_n6_s0", "depth_n6_s0_bootstrap0.5"]
    measured = json.loads((out / "agreement.json").read_text())
    assert set(measured) == set(names) and all(0 <= m["agreement"] <= 1 for m in measured.values())
    recorded = json.loads((out / "models" / names[1] / "config.json").read_text())["train"]
    assert recorded["depth"]["bootstrap"] == 0.5
    rows = oracle_gap.table(out, setup, candidates).splitlines()
    assert len(rows) == 4 and rows[3].startswith("| bootstrap | 6 | 1 | ")
    assert oracle_gap.main(["table", str(out), "--only", "no such candidate"]) == 2
    summary = json.loads((out / "eval" / names[1] / "summary.json").read_text())["summary"]
    assert f"{summary['distance_to_collision_mean']:.2f}" in rows[3]
    assert f"| b | `{names[1]}` | {summary['distance_to_collision_mean']:.2f} |" in oracle_gap.compare(
        [("b", out / "eval" / names[1])])
    assert "| agrees, decisive steps | 2 | – | – |" in oracle_gap.predicts(out)  # 2 models: no ρ
    oracle_gap.plot_predicts(out, out / "diagnostics.png")
    assert (out / "diagnostics.png").stat().st_size > 5000
    failing = oracle_gap.where_it_fails(out)  # which states, actions and bins, per model
    assert set(failing) == set(names) and all(len(r["bin_error"]) == 26 for r in failing.values())
    assert all(abs(sum(r["mistakes"]) - 1) < 1e-9 or sum(r["mistakes"]) == 0 for r in failing.values())
    assert oracle_gap.where(out).count("| `depth_n6_s0") == 2
    for name, r in failing.items():  # bins 0 along its runs include those 0 on every training frame
        dead = oracle_gap.dead_bins(out / "models" / name, frames=50)
        assert all(0 <= b < 26 for b in dead) and set(r["dead_bins"]) <= set(range(26))
    oracle_gap.plot_where(out, out / "where.png")
    assert (out / "where.png").stat().st_size > 5000
    stamp = (out / "agreement.json").stat().st_mtime_ns
    assert oracle_gap.run(out, setup, candidates) == 0  # resumed: nothing trained or measured again
    assert (out / "agreement.json").stat().st_mtime_ns == stamp


def test_the_diagnostics_rank_correlation_with_driving(tmp_path: Path) -> None:
    def model(agreement: float, distance: float, pillars: int) -> dict:
        return {"agreement": agreement, "agreement_decisive": 1 - agreement, "collisions": 4,
                "collisions_with_pillar": pillars, "distance_to_collision_mean": distance}

    measured = {"a": model(0.2, 5.0, 4), "b": model(0.5, 9.0, 2), "c": model(0.4, 7.0, 3),
                "d": model(0.9, 20.0, 0)}
    (tmp_path / "agreement.json").write_text(json.dumps(measured))
    rows = oracle_gap.predicts(tmp_path).splitlines()
    assert "| agrees with the oracle, all steps | 4 | +1.00 | 0.000 |" in rows
    assert "| agrees, decisive steps | 4 | -1.00 | 0.000 |" in rows
    assert "| pillar share of the collisions | 4 | -1.00 | 0.000 |" in rows
    assert "| same decision under new pixel noise | 0 | – | – |" in rows  # not measured: no value


@pytest.mark.slow
def test_privileged_input_trains_on_the_lidar_and_drives_without_a_camera(
    small_dataset: Path, tmp_path: Path
) -> None:
    results = privileged.run(small_dataset, tmp_path, ("bins", "scan"), ("depth",), "val:1000", runs=None,
                             epochs=1)
    assert set(results) == {"depth_bins_nNone_s0", "depth_scan_nNone_s0"}
    for r in results.values():
        assert r["per_canyon"][0]["canyon"] == "val:1000" and r["progress_mean"] > 0
    stamp = (tmp_path / "results.json").stat().st_mtime_ns
    assert privileged.run(small_dataset, tmp_path, ("bins",), ("depth",), "val:1000", runs=None) == results
    assert (tmp_path / "results.json").stat().st_mtime_ns == stamp  # resumed: nothing trained again
    assert "| Depth-Q-Net | the current 26 bins (LiDAR) | None | 0 |" in privileged.table([tmp_path])
    with pytest.raises(ConfigError, match="privileged input"):
        privileged.run(small_dataset, tmp_path, ("image",), ("depth",), "val:1000", runs=None)


@pytest.mark.slow
def test_training_length_drives_every_snapshot_beside_its_validation_loss(
    smoke: Path, tmp_path: Path
) -> None:
    out = tmp_path / "length"
    shutil.copytree(smoke, out)
    setup = oracle_gap.Setup(preset="smoke", canyons=None, runs=6, sizes=(6,), seeds=(0,))
    assert training_length.run(out, setup, 3, (1,), average=True) == 0
    model = "depth_n6_s0_epochs3_snapshots1_average0"
    assert (out / "models" / model / "epoch_0001.safetensors").is_file()
    points = training_length.rows(out, setup, 3, (1,), average=True)
    assert [p["epoch"] for p in points] == [1, 3, "mean"]
    # The mean of epochs 1 and 3, weight by weight, is the checkpoint the last point drove.
    mean_folder = out / "models" / training_length.averaged_name(model)
    (first, _), (last, _), (mean, _) = (read_weights(folder / f"{stem}.safetensors") for folder, stem in (
        (out / "models" / model, "epoch_0001"), (out / "models" / model, "last"), (mean_folder, "last")))
    assert all(torch.allclose(mean[k], (first[k] + last[k]) / 2) for k in mean if mean[k].is_floating_point())
    driven = json.loads((out / "eval" / mean_folder.name / "summary.json").read_text())["policy"]
    assert driven["checkpoint"] == str(mean_folder)
    points = points[:2]
    with (out / "models" / model / "metrics.csv").open() as f:
        losses = [float(line.split(",")[2]) for line in f.read().splitlines()[1:]]
    assert [p["val_loss"] for p in points] == pytest.approx([losses[0], losses[2]])
    for point, name in zip(points, (f"{model}_epoch1", model), strict=True):
        written = json.loads((out / "eval" / name / "summary.json").read_text())
        assert point["distance_to_collision_mean"] == written["summary"]["distance_to_collision_mean"]
        assert written["config"]["weights"] == (None if name == model else f"epoch:{point['epoch']}")
        assert 0 <= point["agreement"] <= 1
    assert points[0]["val_loss"] != points[1]["val_loss"]
    stamp = (out / training_length.MEASURED).stat().st_mtime_ns
    assert training_length.run(out, setup, 3, (1,)) == 0  # resumed: nothing measured twice
    assert (out / training_length.MEASURED).stat().st_mtime_ns == stamp
    rows = training_length.table(points).splitlines()
    assert len(rows) == 4 and rows[3].startswith(f"| 0 | 3 | {points[1]['val_loss']:.4f} | ")
    assert "| validation loss | 2 | – | – |" in training_length.predicts(points)  # 2 points: no ρ
    training_length.plot(points, out / "length.png")
    assert (out / "length.png").stat().st_size > 5000
    with pytest.raises(ConfigError, match="snapshots"):
        training_length.run(out, setup, 3, (3,))
    assert training_length.main(["table", str(tmp_path / "nowhere")]) == 2
