"""What depthq promises identical on every machine (docs/design.md#determinism): canyons, exploration
runs (every non-image array: LiDAR scans, bins, OU actions, poses, times, run metadata), samples' targets
and Table II. Golden SHA-256 digests of a small collection, committed here, catch a drift in MuJoCo, NumPy
or the project's own code on any host; frames are left out (the renderer's pixels may differ).

A digest that changes on purpose (a new canyon generator, new targets) is updated here with the
change, and the docs say which results it invalidates."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from depthq.cli import main
from depthq.data import DataConfig
from depthq.data.manifest import Dataset
from depthq.data.samples import bins_target, collision_target
from depthq.data.stats import dataset_stats
from depthq.data.views import view_arrays
from depthq.sim.canyon import CanyonId, generate_canyon

GOLDEN = {
    "canyons": "aa9414eef44769e55379d9bcf7f8f4a45c422c51f2edc531b4d924591148fa5e",
    "runs": "58b5e4d51c84eb28ab3c9f91ac513d4728a684615c78baf698e5982738d8a8a6",
    "targets": "654af33db476a4686cd5279b11e11f0a9e9be25a7d90786bb29ec05294ff951a",
    # Table II record without data_config.jpeg_quality (#48: DataConfig counts, StorageConfig stores);
    # the same record with it back digests to 7e659bfb…, the golden before: no number changed.
    "table2": "7f20099fd381149a1bf74512355237308096439b892c669a537bfe270d4b7d0a",
}
CANYONS = ("train:0", "val:1000", "eval:19", "hard/train:0", "hard/val:1000", "hard/eval:3")


def _digest(*arrays: np.ndarray | str) -> str:
    digest = hashlib.sha256()
    for a in arrays:
        if isinstance(a, str):
            digest.update(a.encode())
        else:  # dtype, shape and bytes: a float64 that became float32 is a change too
            a = np.ascontiguousarray(a)
            digest.update(f"{a.dtype.str}{a.shape}".encode())
            digest.update(a.tobytes())
    return digest.hexdigest()


def digests(root: Path) -> dict[str, str]:
    """The digest of each promise for the dataset in `root` and the canyons in CANYONS."""
    canyons = [generate_canyon(CanyonId.parse(text)) for text in CANYONS]
    dataset = Dataset.open(root)
    runs = []
    for entry in dataset.entries():
        with dataset.reader(entry) as reader:
            run = reader.run(images=False)
        meta = json.dumps(asdict(run.meta), sort_keys=True, default=int)
        runs += [meta, run.scans, run.bins, run.actions, run.poses, run.times]
    targets = [view_arrays(dataset, split, None, kind, DataConfig())[key]
              for split in ("train", "val") for kind in (bins_target, collision_target)
              for key in ("run_offsets", "frame_id", "action", "target")]
    # Table II's numbers; not the dataset's path, nor its bytes per frame (JPEG: the renderer's pixels)
    stats = dataset_stats(dataset, DataConfig())
    table2 = {k: v for k, v in stats.items() if k not in ("dataset", "kb_per_frame")}
    return {
        "canyons": _digest(*(a for c in canyons for a in (c.left, c.right, c.back, c.obstacles))),
        "runs": _digest(*runs),
        "targets": _digest(*targets),
        "table2": _digest(json.dumps(table2, sort_keys=True)),
    }


def test_canyons_runs_targets_and_table_ii_are_the_golden_bytes(small_dataset: Path) -> None:
    found = digests(small_dataset)
    drifted = {part: digest for part, digest in found.items() if digest != GOLDEN[part]}
    assert not drifted, (
        f"{sorted(drifted)} differ from the golden digests (mujoco, numpy or depthq changed what every "
        f"machine must compute alike; docs/design.md#determinism): {json.dumps(drifted, indent=1)}"
    )


def test_the_host_fingerprint_is_printed_and_recorded(capsys) -> None:
    assert main(["host", "--threads", "3"]) == 0
    host = json.loads(capsys.readouterr().out)
    assert host["torch"]["threads"] == 3 and host["cpu"]["machine"]
    assert {"version", "blas", "simd"} <= host["numpy"].keys() and host["mujoco"]
    assert main(["host", "--threads", "0"]) == 2
