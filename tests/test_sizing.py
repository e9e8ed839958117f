"""The head-size experiment (`depthq.experiments.sizing`): its four sweeps as `depthq sweep` builds
them, and the choice it draws from the driven models, paired by family, size and seed."""

from __future__ import annotations

import itertools

from depthq.experiments import sizing
from depthq.experiments.sizing import Point
from depthq.lock import exclusive


def test_the_sweeps_train_every_width_and_depth_q_net_every_epoch_budget() -> None:
    depth, coll = sizing.sweep("hard", "depth"), sizing.sweep("paper", "coll")
    names = {m.name for m in depth.models()}
    assert len(names) == 4 * 3 * 2 * 2 and "depth_n500_s0" in names  # the reference: no suffix
    assert "depth_n200_s1_hidden512_epochs20" in names
    assert {m.name for m in coll.models()} >= {"coll_n500_s1", "coll_n200_s0_hidden1024"}
    assert len(coll.models()) == 4 * 2 * 2 and coll.canyons == "val:1000-1019"
    assert depth.canyons == "hard/val:1000-1019" and depth.family == "hard"


def _points(distance: dict[tuple[int, int], float], net: str = "depth") -> list[Point]:
    """Every cell of the grid, each variant at `distance[(hidden, epochs)]` plus a seed's offset."""
    return [Point(family, net, runs, seed, hidden, epochs, d + seed, 0, 1.0)
            for (hidden, epochs), d in distance.items()
            for family, runs, seed in itertools.product(sizing.CANYONS, sizing.SIZES, sizing.SEEDS)]


def test_the_cheapest_variant_that_drives_as_far_is_chosen() -> None:
    distance = {sizing.REFERENCE: 20.0, (512, 40): 15.0, (1024, 20): 19.5, (1024, 40): 20.5, (2048, 40): 21.0}
    rows = sizing.compare(_points(distance))
    by = {(r["hidden"], r["epochs"]): r for r in rows}
    assert by[sizing.REFERENCE]["difference"] == 0 and by[(512, 40)]["difference"] == -5
    assert by[(512, 40)]["pairs"] == 8 and by[(512, 40)]["spread"] > 0
    assert not by[(512, 40)]["as_far"] and by[(1024, 20)]["as_far"]  # within the seeds' spread
    assert sizing.choice(rows, "depth")["hidden"] == 1024 and sizing.choice(rows, "depth")["epochs"] == 20
    assert sizing.choice(rows, "coll") is None  # not measured

    partial = [p for p in _points(distance) if not (p.hidden == 1024 and p.seed == 1)]
    assert sizing.choice(sizing.compare(partial), "depth") is None  # a variant lacks pairs: no choice yet


def test_one_writer_per_experiment_folder(tmp_path) -> None:
    out = tmp_path / "sizing"
    out.mkdir()
    with exclusive(out):
        assert sizing.main(["report", str(out)]) == 2  # another process writes there
    assert sizing.main(["report", str(out)]) == 0 and (out / "report.md").is_file()
