"""The head-size experiment (`research.sizing`): its four sweeps as `depthq sweep` builds
them, and the choice it draws from the driven models, paired by family, size and seed."""

from __future__ import annotations

import itertools

from depthq.lock import exclusive
from research import sizing
from research.sizing import Point


def test_the_sweeps_train_every_width_and_depth_q_net_every_epoch_budget() -> None:
    depth, coll = sizing.sweep("hard", "depth"), sizing.sweep("paper", "coll")
    names = {m.name for m in depth.models()}
    assert len(names) == 4 * 3 * 2 * 2 and "depth_n500_s0" in names  # the reference: no suffix
    assert "depth_n200_s1_hidden512_epochs20" in names
    assert {m.name for m in coll.models()} >= {"coll_n500_s1", "coll_n200_s0_hidden1024"}
    assert len(coll.models()) == 4 * 2 * 2 and coll.canyons == "val:1000-1019"
    assert depth.canyons == "hard/val:1000-1019" and depth.family == "hard"


def _points(distance: dict[tuple[int, int], float], net: str = "depth",
            hard: dict[tuple[int, int], float] | None = None) -> list[Point]:
    """Every cell of the grid, each variant at `distance[(hidden, epochs)]` (in the hard family
    `hard[(hidden, epochs)]` where given) plus a seed's offset."""
    return [Point(family, net, runs, seed, hidden, epochs,
                  ((hard or {}).get((hidden, epochs), d) if family == "hard" else d) + seed, 0, 1.0)
            for (hidden, epochs), d in distance.items()
            for family, runs, seed in itertools.product(sizing.CANYONS, sizing.SIZES, sizing.SEEDS)]


def test_the_cheapest_variant_that_drives_as_far_is_chosen(tmp_path) -> None:
    distance = {sizing.REFERENCE: 20.0, (512, 40): 15.0, (1024, 20): 19.5, (1024, 40): 20.5, (2048, 40): 21.0}
    rows = sizing.compare(_points(distance))
    by = {(r["hidden"], r["epochs"]): r for r in rows}
    hard = {(h, e): r["families"]["hard"] for (h, e), r in by.items()}
    assert hard[sizing.REFERENCE]["difference"] == 0 and hard[(512, 40)]["difference"] == -5
    assert by[(512, 40)]["pairs"] == 8 and hard[(512, 40)]["spread"] > 0
    assert not by[(512, 40)]["as_far"] and by[(1024, 20)]["as_far"]  # within the seeds' spread
    assert sizing.choice(rows, "depth")["hidden"] == 1024 and sizing.choice(rows, "depth")["epochs"] == 20
    assert sizing.choice(rows, "coll") is None  # not measured

    partial = [p for p in _points(distance) if not (p.hidden == 1024 and p.seed == 1)]
    assert sizing.choice(sizing.compare(partial), "depth") is None  # a variant lacks pairs: no choice yet
    sizing.figure(_points(distance) + _points({sizing.REFERENCE: 18.0}, net="coll"), tmp_path / "sizing.png")
    assert (tmp_path / "sizing.png").stat().st_size > 20_000


def test_a_variant_must_drive_as_far_in_every_family() -> None:
    """1 m short in the hard family only: pooled with the paper family's pairs it would be within the
    spread (0.71 m, from the seeds' offsets), per family it is not."""
    distance = {sizing.REFERENCE: 20.0, (1024, 20): 20.0}
    rows = sizing.compare(_points(distance, hard={sizing.REFERENCE: 20.0, (1024, 20): 19.0}))
    cheap = next(r for r in rows if r["hidden"] == 1024)
    assert cheap["families"]["paper"]["as_far"] and not cheap["families"]["hard"]["as_far"]
    assert cheap["as_far"] is False and sizing.choice(rows, "depth")["hidden"] == 4096


def test_one_writer_per_experiment_folder(tmp_path) -> None:
    out = tmp_path / "sizing"
    out.mkdir()
    with exclusive(out):
        assert sizing.main(["report", str(out)]) == 2  # another process writes there
    assert sizing.main(["report", str(out)]) == 0 and (out / "report.md").is_file()
    assert (out / "sizing.png").is_file()  # drawn with nothing measured yet


def test_a_coll_q_nets_epochs_do_not_depend_on_its_budget(small_dataset, tmp_path) -> None:
    """What `same_net_budget` stands on: the first E epochs of a longer training are a training of E
    epochs, byte for byte (no schedule, one random stream), so the best epoch's weights are the same."""
    from depthq.train.config import TrainConfig
    from depthq.train.trainer import train

    fast = {"train_batches": 2, "val_batches": 1, "batch_size": 8, "hidden": 16}
    short = train(TrainConfig(model="coll", data=str(small_dataset), epochs=2, **fast), tmp_path / "e2",
                  progress=False)
    long = train(TrainConfig(model="coll", data=str(small_dataset), epochs=4, snapshots=(2,), **fast),
                 tmp_path / "e4", progress=False)
    assert (short / "last.safetensors").read_bytes() == (long / "epoch_0002.safetensors").read_bytes()
    row = {"best_epochs": [7, 18, 26], "pairs": 3, "epochs": 40}
    assert sizing.same_net_budget(row) == 30 and sizing.same_net_budget({**row, "best_epochs": [7]}) is None
