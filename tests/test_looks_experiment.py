"""The looks experiment (issue #45 item 3) at toy size: a sweep in the textured look, a floor labeller's
camera-label Depth-Q-Net, every net driven in another look, the labeller measured in it, the tables and
the report; the same command resumes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from depthq.data.manifest import Dataset
from depthq.data.rerender import STRIDE, rendered_looks
from depthq.lock import exclusive
from research import looks

TOY = [
    "--preset", "smoke", "--runs", "3", "--seeds", "0", "--train-looks", "textured",
    "--drive-looks", "heldout", "--canyons", "hard/val:1001", "--choose", "hard/val:1000",
    "--method", "floor", "--time-limit", "2", "--val-runs", "2", "--workers", "1", "--device", "cpu",
    "--no-progress",
    *("--labeller-set", "steps=5", "--labeller-set", "pool_runs=2", "--labeller-set", "pool_frames=3",
      "--labeller-set", "batch_size=4", "--labeller-set", "width=8"),
    *("--set", "epochs=1", "--set", "train_batches=2", "--set", "val_batches=1", "--set", "batch_size=8"),
]


@pytest.mark.slow  # a toy sweep, a labeller, 3 trainings, 8 evaluations, 3 val runs, the report: ~2 min
def test_the_looks_experiment_trains_in_one_look_drives_in_others_and_resumes(tmp_path: Path, capsys) -> None:
    out = tmp_path / "looks"
    assert looks.main(["run", str(out), *TOY]) == 0
    manifest = json.loads((out / "textured" / "sweep" / "data" / "manifest.json").read_text())
    assert manifest["config"]["env"]["world"]["look"] == "textured"
    for net in ("depth", "camera", "coll", "coll_final"):  # trained textured, driven in the held-out look
        summary = json.loads((out / "textured" / "eval_heldout" / f"{net}_s0" / "summary.json").read_text())
        assert summary["look"] == "heldout" and summary["config"]["canyons"] == ["hard/val:1001"]
        assert (summary["config"].get("weights") == "final") == (net == "coll_final")  # its best chance
    # the labeller measured on validation runs of the driving look: its own seed, val canyons, that look
    val = Dataset.open(out / "val_heldout" / "data")
    assert val.seed == looks.VAL_SEED and val.config["env"]["world"]["look"] == "heldout"
    assert len(val.entries("val")) >= 2 and {e.split for e in val.entries()} == {"train", "val"}
    error = json.loads(looks.error_path(out, "textured", "heldout", "floor").read_text())
    assert error["name"] == "floor" and error["split"] == "val" and error["runs"] == len(val.entries("val"))
    assert 0 < error["frames"] <= sum(e.n_frames for e in val.entries("val"))
    assert error["nearest"]["median"] is not None and error["nearest"]["median"] >= 0
    # every net's offline metric on the driving look's validation runs, scored against the LiDAR's bins
    predicted = json.loads(looks.prediction_path(out, "textured", "heldout", "camera", 0).read_text())
    assert predicted["metric"] == "abs_diff" and predicted["value"] > 0 and predicted["data"] == str(val.root)
    printed = capsys.readouterr().out
    assert "| Depth-Q-Net, camera labels | textured |" in printed
    assert f"| floor, trained in textured | {_cell(out)} |" in printed  # the second table: per look
    def stamps() -> dict[Path, int]:  # evaluations, the validation runs' manifest, the labeller's errors
        return {p: p.stat().st_mtime_ns for p in [*out.rglob("summary.json"), *out.glob("val_*/**/*.json")]}

    before = stamps()
    assert looks.main(["run", str(out), *TOY]) == 0  # resumed: no evaluation, collection or measurement again
    assert stamps() == before
    assert looks.main(["run", str(tmp_path / "bad"), *TOY, "--drive-looks", "neon"]) == 2
    assert not (tmp_path / "bad").exists()

    # the report: the tables, the figure, the answers computed from the evaluations
    seeds = ["--runs", "3", "--seeds", "0", "--train-looks", "textured", "--drive-looks", "heldout"]
    assert looks.main(["report", str(out), *seeds, "--method", "floor"]) == 0
    text = (out / "report.md").read_text()
    assert "| Depth-Q-Net, camera labels | textured |" in text and "| floor, trained in textured |" in text
    assert (out / "looks.png").is_file() and "data:image/png;base64," in (out / "report.html").read_text()
    assert (out / "distance_by_look.png").is_file() and "![Distance per driving look]" in text
    (recipe,) = (line for line in text.splitlines() if line.startswith("- `textured`: drives every look"))
    assert "**not yet measured**" in recipe  # no colour-trained reference in OUT
    assert "Dead outputs: " in recipe and looks.NOT_MEASURED not in recipe.split("Dead outputs: ")[1]
    assert f"| Depth-Q-Net, camera labels | textured | {predicted['value']:.3f} | abs_diff | – |" in text
    # how far training carried: the Coll-Q-Net's validation loss after its one epoch, from its metrics.csv
    logged = (out / "textured" / "sweep" / "models" / "coll_n3_s0" / "metrics.csv").read_text().splitlines()
    val_loss = float(logged[1].split(",")[logged[0].split(",").index("val_loss")])
    assert f"| Coll-Q-Net | textured | 1 | {val_loss:.3f} | {val_loss:.3f} (1) |" in text
    # why: the nets' runs in the held-out look checked against the depth oracle; in the canyons `run`
    # drove, its runs are measured, not driven again (the recipe test below drives where it has not)
    assert looks.main(["diagnose", str(out), *seeds, "--method", "floor", "--choose", "hard/val:1001",
                       "--time-limit", "2", "--workers", "1", "--device", "cpu", "--no-progress"]) == 0
    where = looks.diagnosis_folder(out, "textured", "heldout")
    checked = json.loads((where / "agreement" / "camera_s0_depth-1.json").read_text())
    assert checked["look"] == "heldout" and checked["steps"] > 0 and checked["score_error"] >= 0
    assert not (where / "camera_s0").exists() and not (where / "depth_s0").exists()
    assert not (where / "coll_s0").exists()  # Coll-Q-Net's scores are no depth: not diagnosed by default
    assert looks.main(["report", str(out), *seeds, "--method", "floor"]) == 0
    text = (out / "report.md").read_text()
    distance = checked["distance_to_collision_mean"]
    assert f"| Depth-Q-Net, camera labels | textured | heldout | 1 | {distance:.2f} |" in text
    # never driven in the textured look: the first question is open, the second one is answered
    first, second = (line for line in text.splitlines() if line.startswith("- Does"))
    assert "**not yet measured**" in first
    camera, coll = (json.loads((out / "textured" / "eval_heldout" / f"{net}_s0" / "summary.json").read_text())
                    ["summary"]["distance_to_collision_mean"] for net in ("camera", "coll"))
    assert f"**{'yes' if camera >= coll else 'no'}**" in second and f"{camera - coll:+.2f}" in second


def _cell(out: Path) -> str:
    """The labeller's own training runs' nearest-bin error, as its camera-labels stats hold it."""
    stats = json.loads((out / "textured" / "camera" / "floor" / "stats.json").read_text())
    nearest = stats["camera_labels"]["splits"]["train"]["nearest"]
    return f"{nearest['median']:.3f} [{nearest['mean']:.3f}]"


def test_the_looks_report_says_not_yet_measured_for_what_is_missing(tmp_path: Path) -> None:
    """An experiment folder without evaluations or labellers: every answer "not yet measured", every cell
    empty, no error; a folder that does not exist is a clear error (exit 2) and nothing is written."""
    first, second = looks.answers(tmp_path)
    assert "**not yet measured**" in first and "**not yet measured**" in second
    for rows in (looks.table_rows(tmp_path), looks.transfer_rows(tmp_path), looks.labeller_rows(tmp_path),
                 looks.learning_rows(tmp_path), looks.prediction_rows(tmp_path)):
        assert rows and all(cell == "–" for row in rows for key, cell in row.items()
                            if key not in ("Q-net", "trained in", "labeller", "seeds", "metric"))
    assert looks.main(["report", str(tmp_path / "none")]) == 2
    assert not (tmp_path / "none").exists()
    with exclusive(tmp_path, "OUT"):  # one writer per experiment folder: another process writes there
        assert looks.main(["report", str(tmp_path)]) == 2
    assert not (tmp_path / "report.md").exists()


def test_the_labeller_error_is_the_camera_labels_metric() -> None:
    """One function measures the labels (`depthq.data.stats.label_errors`): the report's cell is its
    nearest-bin median [mean], as `depthq dataset stats` writes it."""
    from depthq.data.stats import error_cell, format_label_error, label_errors

    lidar = np.array([[1.0, 2.0], [0.5, np.nan]])
    errors = label_errors(lidar, lidar + 0.25, runs=1)
    assert error_cell(errors["nearest"]) == "0.250 [0.250]"
    assert error_cell(errors["bands"][0]) == "–"  # no bin that near
    report = {"labellers": [{"name": "floor", "fingerprint": "f" * 64}], "splits": {"val": errors}}
    row = format_label_error(report)[2].split()
    assert row[:5] == ["val", "1", "2", "0.250", "[0.250]"] and row[5] == "—"


def test_the_looks_experiment_trains_with_its_pinned_configs() -> None:
    """Today's `hard` preset and defaults are the pinned ones (the experiment's run resumes as it
    started); a default that moves is given back as a setting, and one the nets would need apart is
    an error naming it."""
    from depthq.errors import ConfigError
    from depthq.pipeline.presets import get_preset
    from depthq.pipeline.sweep import retarget, widened

    sweep = widened(retarget(get_preset("hard"), family="hard", canyons=looks.CHOOSE, look="textured"), 500,
                    subsets=(500,), seeds=(0,))
    assert looks.pinned_training(sweep, 500, 0, ()) == ()
    assert looks.pinned_training(sweep, 500, 0, (("epochs", 3),)) == (("epochs", 3),)
    assert looks.pinned_labeller("monodepth", ()) == ()
    moved = widened(sweep, train=(*sweep.train, ("dropout", 0.5), ("lr", 0.01)))  # as if defaults moved
    assert dict(looks.pinned_training(moved, 500, 0, ())) == {"dropout": 0.0, "lr": 0.1}
    assert looks.pinned_training(moved, 500, 0, (("dropout", 0.5),)) == (("lr", 0.1), ("dropout", 0.5))
    assert looks.pinned_training(moved, 500, 0, (), preset="smoke") == ()
    apart = widened(sweep, train=(*sweep.train, ("average", 0.5)))  # pinned 0.25 and 0.0
    with pytest.raises(ConfigError, match="pinned average differently for depth"):
        looks.pinned_training(apart, 500, 0, ())


@pytest.mark.slow  # a toy collection rendered again in two looks, two sweeps, labellers, a diagnosis: ~4 min
def test_a_recipe_renders_its_runs_again_shares_them_and_drives_a_generated_look(tmp_path: Path, capsys):
    """#57's recipes: `broad+looks` collects in the broad look and renders every run again in the colour
    and the textured look before its sweep; a second recipe of the same data links it; `--train-only`
    drives nothing in the table's canyons; `diagnose` drives the net in the generated folder look."""
    out = tmp_path / "recipes"
    toy = [a if a != "textured" else "broad+looks,broad+looks+tuned" for a in TOY]
    toy = [a if a != "heldout" else looks.GENERATED for a in toy]
    assert looks.main(["run", str(out), *toy, "--train-only"]) == 0
    data = Dataset.open(out / "broad+looks" / "sweep" / "data")
    assert sorted(look for look, _ in rendered_looks(data).values()) == ["colours", "textured"]
    collected = [e for e in data.entries("train") if e.index < STRIDE]
    assert len(collected) >= 3 and len(data.entries("train")) == 3 * len(collected)  # each in 3 looks
    times = json.loads((out / "broad+looks" / "times.json").read_text())  # the steps outside the sweep
    assert set(times) == {"collect and rerender"}
    assert {"labeller", "labels", "train depth_n3_s0"} <= set(
        json.loads((out / "broad+looks" / "camera" / "floor" / "times.json").read_text()))
    twin = out / "broad+looks+tuned" / "sweep" / "data"
    assert twin.is_symlink() and twin.resolve() == (out / "broad+looks" / "sweep" / "data").resolve()
    for part in ("labeller", "data"):  # the same data and labeller settings: one labeller, learnt once
        shared, first = (out / recipe / "camera" / "floor" / part
                         for recipe in ("broad+looks+tuned", "broad+looks"))
        assert shared.is_symlink() and shared.resolve() == first.resolve()
    assert not list(out.glob("*/eval_*")) and "choose among them" in capsys.readouterr().out
    why = ["diagnose", str(out), "--runs", "3", "--seeds", "0", "--train-looks", "broad+looks",
           "--drive-looks", looks.GENERATED, "--nets", "depth", "--choose", "hard/val:1000",
           "--method", "floor", "--time-limit", "2", "--workers", "1", "--device", "cpu", "--no-progress"]
    assert looks.main(why) == 0
    images = sorted((out / "generated_look").glob("*.png"))
    assert len(images) == looks.GENERATED_IMAGES
    driven = out / "broad+looks" / "diagnose_generated" / "depth_s0" / "summary.json"
    assert json.loads(driven.read_text())["config"]["look"] == str(out.resolve() / "generated_look")
