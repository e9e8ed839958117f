"""The looks experiment (issue #45 item 3) at toy size: a sweep in the textured look, a floor labeller's
camera-label Depth-Q-Net, every net driven in two looks, the table; the same command resumes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from depthq.experiments import looks

TOY = [
    "--preset", "smoke", "--runs", "3", "--seeds", "0", "--train-looks", "textured",
    "--drive-looks", "heldout", "--canyons", "hard/val:1001", "--choose", "hard/val:1000",
    "--method", "floor", "--time-limit", "2", "--workers", "1", "--device", "cpu", "--no-progress",
    *("--labeller-set", "steps=5", "--labeller-set", "pool_runs=2", "--labeller-set", "pool_frames=3",
      "--labeller-set", "batch_size=4", "--labeller-set", "width=8"),
    *("--set", "epochs=1", "--set", "train_batches=2", "--set", "val_batches=1", "--set", "batch_size=8"),
]


@pytest.mark.slow  # a toy sweep, a labeller, 3 trainings, 8 evaluations of one short run: ~1 min
def test_the_looks_experiment_trains_in_one_look_drives_in_others_and_resumes(tmp_path: Path, capsys) -> None:
    out = tmp_path / "looks"
    assert looks.main(["run", str(out), *TOY]) == 0
    manifest = json.loads((out / "textured" / "sweep" / "data" / "manifest.json").read_text())
    assert manifest["config"]["env"]["world"]["look"] == "textured"
    for net in ("depth", "camera", "coll"):  # trained in the textured look, driven in the held-out one
        summary = json.loads((out / "textured" / "eval_heldout" / f"{net}_s0" / "summary.json").read_text())
        assert summary["look"] == "heldout" and summary["config"]["canyons"] == ["hard/val:1001"]
    printed = capsys.readouterr().out
    assert "| Depth-Q-Net, camera labels | textured |" in printed
    stamps = {p: p.stat().st_mtime_ns for p in out.rglob("summary.json")}
    assert looks.main(["run", str(out), *TOY]) == 0  # resumed: no evaluation again
    assert {p: p.stat().st_mtime_ns for p in out.rglob("summary.json")} == stamps
    assert looks.main(["run", str(tmp_path / "bad"), *TOY, "--drive-looks", "neon"]) == 2
    assert not (tmp_path / "bad").exists()


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
