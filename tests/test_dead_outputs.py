"""Dead outputs (`depthq.train.dead_outputs`): a Depth-Q-Net's bins that are 0 for every validation
frame and candidate action, counted on trained toy nets, through `depthq probe --parts dead` and the
offline metric; and the straight-through bin gradient, which keeps them alive."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from depthq.cli import main
from depthq.data.manifest import Dataset
from depthq.networks import DepthSettings
from depthq.policies.qnet import QNetPolicy
from depthq.train.config import TrainConfig
from depthq.train.dead_outputs import count_dead_outputs, dead_outputs
from depthq.train.offline_metric import offline_metric
from depthq.train.trainer import train


def brute_force_dead(folder: Path, dataset: Path) -> list[int]:
    """The bins the checkpoint's policy gives as 0 for every candidate on every validation frame, one
    decoded frame at a time through its own trunk (no feature cache)."""
    policy = QNetPolicy.from_checkpoint(folder)
    data = Dataset.open(dataset)
    alive = np.zeros(26, bool)
    for entry in data.entries():
        if entry.split != "val":
            continue
        with data.reader(entry) as reader:
            for t in range(entry.n_frames):
                alive |= (policy.values(reader.image(t)) > 0).any(axis=0)
    return np.flatnonzero(~alive).tolist()


def test_the_dead_outputs_of_a_toy_net_are_those_its_policy_never_reads(toy_nets, small_dataset, tmp_path):
    found = count_dead_outputs(toy_nets["depth"])
    assert found.dead, "the toy Depth-Q-Net has no dead output: this test checks nothing"
    assert list(found.dead) == brute_force_dead(toy_nets["depth"], small_dataset)
    assert found.outputs == 26 and found.candidates == 3 and found.split == "val"
    assert found.frames == sum(e.n_frames for e in Dataset.open(small_dataset).entries() if e.split == "val")
    assert str(found).startswith(f"{len(found.dead)} of 26 outputs dead ({', '.join(map(str, found.dead))})")
    assert count_dead_outputs(toy_nets["coll"]) is None  # no bins: nothing can die
    # the evaluation's offline metric (on the validation samples, a subset of the frames) says it too
    offline = offline_metric(toy_nets["depth"], Dataset.open(small_dataset))
    assert set(offline["dead_outputs"]) >= set(found.dead) and offline["outputs"] == 26
    assert "dead_outputs" not in offline_metric(toy_nets["coll"], Dataset.open(small_dataset))

    out = tmp_path / "probe"
    assert main(["probe", "--parts", "dead", "--checkpoints", f"{toy_nets['depth']},{toy_nets['coll']}",
                 "--out", str(out)]) == 0
    rows = json.loads((out / "probe.json").read_text())["dead"]
    assert rows[0]["dead_outputs"] == list(found.dead) and rows[0]["text"] == str(found)
    assert rows[1]["dead_outputs"] is None


def test_dead_outputs_counts_an_output_dead_only_where_every_row_is_0():
    values = np.zeros((4, 3, 2, 5))
    values[3, 2, 1, 4] = 0.5  # one reading of output 9 in one frame, for one candidate
    values[:, :, 0, 1] = -1.0  # below 0 is no reading either
    assert dead_outputs(values) == tuple(i for i in range(10) if i != 9)


def test_the_probe_part_needs_checkpoints(tmp_path, capsys):
    assert main(["probe", "--parts", "dead", "--out", str(tmp_path / "p")]) == 2
    assert "--checkpoints" in capsys.readouterr().err and not (tmp_path / "p").exists()


@pytest.mark.slow
def test_a_straight_through_bin_gradient_leaves_no_output_dead(small_dataset, tmp_path):
    """Trained a little longer than `toy_nets`, the default head loses more bins; the same training with
    the straight-through gradient keeps every one alive."""
    config = TrainConfig(model="depth", data=str(small_dataset), epochs=1, train_batches=20, val_batches=1,
                         batch_size=16)
    dead = {gradient: count_dead_outputs(train(replace(config, settings=DepthSettings(bin_gradient=gradient)),
                                               tmp_path / gradient,
                                               progress=False)).dead
            for gradient in ("relu", "straight_through")}
    assert dead["relu"] and dead["straight_through"] == ()
