"""Files and folders depthq writes have the modes `open()` and `mkdir` would give them under the user's
umask (0o644 and 0o755 under 022, 0o600 and 0o700 under 077): a report copied to a shared folder stays
readable, a private one stays private. Atomic writes go through a temporary sibling, whose own mode
(tempfile's 0o600) must not leak into the result."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest
import torch

from depthq.checkpoint import weights_bytes
from depthq.configio import atomic_write_bytes, temp_sibling, umask, write_json
from depthq.data.recorder import CollectConfig, collect
from depthq.data.rosbag import ImportConfig, export_bag, import_bag


@pytest.fixture(params=[0o022, 0o077], ids=["umask022", "umask077"])
def mask(request: pytest.FixtureRequest) -> Iterator[int]:
    old = os.umask(request.param)
    try:
        yield request.param
    finally:
        os.umask(old)


def _modes(root: Path) -> dict[str, int]:
    return {str(p.relative_to(root)): p.stat().st_mode & 0o777 for p in [root, *root.rglob("*")]}


def test_umask_is_read_without_changing_it(mask: int) -> None:
    assert umask() == mask
    assert umask() == mask  # still set: reading it did not change it


def test_atomic_writes_json_and_safetensors_keep_the_umask(mask: int, tmp_path: Path) -> None:
    write_json(tmp_path / "summary.json", {"a": 1})
    atomic_write_bytes(tmp_path / "runs.csv", b"a,b\n1,2\n")
    atomic_write_bytes(tmp_path / "last.safetensors", weights_bytes({"w": torch.ones(2)}))
    atomic_write_bytes(tmp_path / "runs.csv", b"a,b\n3,4\n")  # replacing a file: the same mode again
    tmp = temp_sibling(tmp_path / "video.mp4", ".mp4")
    assert tmp.name.startswith(".video.mp4.") and tmp.stat().st_size == 0
    tmp.unlink()
    (tmp_path / "plain.txt").write_text("x")  # what open() gives, for comparison
    modes = _modes(tmp_path)
    assert set(modes.values()) - {modes["."]} == {0o666 & ~mask}, modes
    assert (tmp_path / "runs.csv").read_bytes() == b"a,b\n3,4\n"
    assert not list(tmp_path.glob(".*"))  # no temporary left behind


def test_a_collection_and_a_bag_imported_keep_the_umask(mask: int, tmp_path: Path) -> None:
    """Run files (HDF5 written through a temporary), the manifest, the dataset's folders, and a dataset
    imported from a bag (assembled in a temporary folder that is renamed)."""
    data = tmp_path / "data"
    collect(data, CollectConfig(runs=1, val_runs=1, max_steps=40), workers=1, progress=False)
    bag = export_bag(data, tmp_path / "bag", progress=False)
    import_bag(bag, tmp_path / "back", ImportConfig(val_runs=1), progress=False)
    for root in (data, tmp_path / "back"):
        modes = _modes(root)
        files = {name: mode for name, mode in modes.items() if (root / name).is_file()}
        folders = {name: mode for name, mode in modes.items() if (root / name).is_dir()}
        assert any(name.endswith(".h5") for name in files) and "manifest.json" in files
        assert set(files.values()) == {0o666 & ~mask}, files
        assert set(folders.values()) == {0o777 & ~mask}, folders
