"""A dataset folder: one manifest and one HDF5 file per run.

Layout:

    DIR/manifest.json           what the folder holds (rewritten atomically after every run)
    DIR/runs/train_000123.h5    training run 123 (see `depthq.data.runfile` for the file's layout)
    DIR/runs/val_000004.h5      validation run 4
    DIR/runs/.*.tmp             a run being written; never read, removed when collection resumes

manifest.json:

    format, format_version      "depthq-dataset", 1
    provenance                  package and version that wrote it (`depthq.configio.provenance`)
    seed                        the collection seed
    config                      the collection config that made the runs (a JSON object); a DAgger
                                round's adds `rounds` (docs/formats.md#manifest)
    look_images                 only when the look is a folder of images: each image's SHA-256 by file
                                name, so a collection does not resume with other images
    runs                        one row per completed run, sorted by split and index:
        split, index            "train" | "val", position in that split (the file name says both)
        file                    path relative to DIR, e.g. "runs/train_000123.h5"
        n_frames, end_reason    frame count; "bump" | "contact" (collisions) | "time_limit" | "step_limit"
                                | "stop" (a run imported from a bag: the robot stood or the frames stopped)
                                | "end" (the run reached its canyon's open end)
        canyon_split, canyon_index, canyon_seed, policy_seed
                                the canyon the run drove in and the exploration policy's seed
                                ("recorded", its position in the bag, 0, 0 for an imported run)
        sha256, bytes           the file's hash and size, checked before the file is read as data
        rendered                only in a re-rendered run's row (`depthq dataset rerender`): its source
                                run's index in the same split, and the look and seed it was drawn in

A run exists once its row is in the manifest: a file without a row (a crash between the two
writes) is written again on resume. Rows hold no timestamps, so the same seeds give the same bytes.
Only one process (the collector's parent) writes the manifest; workers only write run files.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from depthq.configio import OMIT_DEFAULT, from_dict, provenance, read_json, to_dict, write_json
from depthq.data.camera_labels import CameraLabels
from depthq.data.run import Run, RunMeta, meta_fields
from depthq.data.runfile import JPEG_QUALITY, FileInfo, RunReader, file_sha256, write_labelled, write_run
from depthq.data.samples import MIN_FRAMES, usable
from depthq.errors import ConfigError, DataError
from depthq.lock import writer
from depthq.progress import Bar
from depthq.sim.canyon import PAPER
from depthq.sim.look import upgrade_world

MANIFEST = "manifest.json"
RUNS = "runs"
FORMAT = "depthq-dataset"
FORMAT_VERSION = 1
_MISSING = object()
# The settings a collection config's `data` held until #48 that change no stored run (a training's
# sample settings, and the subsets Table II counts): a manifest written then reads without them.
_NOT_STORED = ("horizon", "every_run_end", "action_clip", "action_lag", "subsets")


@dataclass(frozen=True)
class Rendering:
    """Where a re-rendered run's frames come from (`depthq.data.rerender`): run `source` of its split,
    rendered again in `look`, its appearance and camera drawn from `seed`."""

    source: int
    look: str
    seed: int


@dataclass(frozen=True)
class RunEntry(RunMeta):
    """A manifest row: a completed run's metadata plus where its file is and how to check it."""

    file: str
    sha256: str
    bytes: int
    rendered: Rendering | None = field(default=None, metadata=OMIT_DEFAULT)  # a re-rendered run's origin

    @property
    def info(self) -> FileInfo:
        return FileInfo(sha256=self.sha256, bytes=self.bytes)

    def run_meta(self) -> RunMeta:
        return RunMeta(**{name: getattr(self, name) for name in meta_fields()})


def upgrade_config(config: dict[str, Any]) -> dict[str, Any]:
    """A manifest's collection config in today's shape, so an older dataset resumes and compares equal:
    a world recorded before looks (`appearance`) names its look (`depthq.sim.look.upgrade_world`), and
    `data` holds only what changes the stored runs (`depthq.data.StorageConfig`; `_NOT_STORED`)."""
    if not isinstance(config, dict):
        return config
    data = config.get("data")
    if isinstance(data, dict):
        config = {**config, "data": {k: v for k, v in data.items() if k not in _NOT_STORED}}
    env = config.get("env")
    if not isinstance(env, dict) or not isinstance(env.get("world"), dict):
        return config
    return {**config, "env": {**env, "world": upgrade_world(env["world"])}}


def run_path(root: Path, split: str, index: int) -> Path:
    """Where run `index` of `split` lives in the dataset folder `root` (workers write there)."""
    return Path(root) / RUNS / f"{split}_{index:06d}.h5"


class Dataset:
    """A dataset folder. `create` starts or resumes one (the collector), `open` reads one (everyone else)."""

    def __init__(self, root: Path, config: dict[str, Any], seed: int, runs: list[RunEntry],
                 look_images: dict[str, str] | None = None) -> None:
        self.root = Path(root)
        self.config = config
        self.seed = seed
        self.look_images = look_images  # a folder look's images: SHA-256 by file name
        self._runs = {(r.split, r.index): r for r in runs}

    @classmethod
    def open(cls, root: Path) -> Dataset:
        root = Path(root)
        if not root.is_dir():
            raise ConfigError(f"{root}: no such dataset folder")
        path = root / MANIFEST
        if not path.is_file():
            raise ConfigError(f"{root}: not a dataset folder (no {MANIFEST})")
        data = read_json(path)
        try:
            if data.get("format") != FORMAT or data.get("format_version") != FORMAT_VERSION:
                raise ValueError(f"format {data.get('format')!r} version {data.get('format_version')!r}")
            runs = [from_dict(RunEntry, row) for row in data["runs"]]
            images = data.get("look_images")
            if images is not None and not (isinstance(images, dict) and all(
                    isinstance(v, str) for v in images.values())):
                raise ValueError(f"look_images {images!r}")
            return cls(root, upgrade_config(data["config"]), int(data["seed"]), runs, images)
        except (AttributeError, KeyError, TypeError, ValueError) as err:
            raise DataError(f"{path}: not a valid {FORMAT} manifest ({err})") from err

    @classmethod
    def create(cls, root: Path, config: dict[str, Any], seed: int, overwrite: bool = False,
               look_images: dict[str, str] | None = None) -> Dataset:
        """Start a dataset in `root`, or resume the one there if it was made with the same config and seed.

        A dataset made with another config or seed is a ConfigError naming the differing keys, and so
        is one whose folder look's images (`look_images`: SHA-256 by name) changed since, naming them;
        one written before the manifest recorded them takes today's. `overwrite` starts afresh whatever
        is there: it deletes the manifest and all runs first.
        """
        root = Path(root)
        config = json.loads(json.dumps(config))  # the form it takes in the manifest (tuples become lists)
        if overwrite:
            (root / MANIFEST).unlink(missing_ok=True)
            shutil.rmtree(root / RUNS, ignore_errors=True)
        elif (root / MANIFEST).is_file():
            old = cls.open(root)
            differing = _differing_keys(
                {"config": old.config, "seed": old.seed}, {"config": config, "seed": seed}
            )
            if differing:
                raise ConfigError(
                    f"{root} holds a dataset made with a different configuration (differs in: "
                    f"{', '.join(differing)}); use another folder, or overwrite it"
                )
            old._check_look_images(look_images)
            old._remove_temporaries()
            return old
        elif root.exists() and any(p.name != RUNS for p in root.iterdir()):
            raise ConfigError(f"{root}: exists, is not empty and is not a dataset folder (no {MANIFEST})")
        dataset = cls(root, config, seed, [], look_images)
        (root / RUNS).mkdir(parents=True, exist_ok=True)
        dataset._remove_temporaries()
        dataset._write_manifest()
        return dataset

    def entries(self, split: str | None = None) -> list[RunEntry]:
        """Manifest rows (of one split, or all), sorted by split and index."""
        return [self._runs[key] for key in sorted(self._runs) if split is None or key[0] == split]

    def labeller(self) -> dict[str, str] | None:
        """The labeller ({"name", "fingerprint"}) whose camera labels the runs hold, None if no run holds
        any (`depthq.data.camera_labels`); runs labelled by two or more (a `depthq label --replace`
        stopped part way) are a ConfigError naming each. Read from the files' labels alone: reading the
        runs as data checks the files."""
        found: dict[tuple[str, str], int] = {}
        for entry in self.entries():
            with RunReader(self.path(entry)) as reader:
                labels = reader.camera_labels()
            if labels is not None:
                key = (labels.labeller, labels.fingerprint)
                found[key] = found.get(key, 0) + 1
        if len(found) > 1:
            each = ", ".join(f"{name} (fingerprint {fp[:16]}…) in {n} runs"
                             for (name, fp), n in found.items())
            raise ConfigError(
                f"{self.root}: its runs hold camera labels of {len(found)} labellers, {each}: a `depthq "
                f"label --replace` stopped part way; finish it (`depthq label {self.root} --from camera "
                "--labeller FOLDER --replace`, FOLDER the labeller to keep), then train"
            )
        return next(({"name": name, "fingerprint": fp} for name, fp in found), None)

    def fingerprint(self) -> str:
        """SHA-256 of the manifest's run rows (split, index, file hash): equal runs, equal fingerprint.
        A checkpoint records it (`depthq.checkpoint.DatasetRecord`), and so does a feature cache."""
        digest = hashlib.sha256()
        for entry in self.entries():
            digest.update(f"{entry.split},{entry.index},{entry.sha256}\n".encode())
        return digest.hexdigest()

    def family(self) -> str | None:
        """The canyon family its runs drove in (the manifest's env.world; the paper's if unset); None for
        a robot's recording."""
        env = self.config.get("env")
        return None if env is None else env["world"].get("family", PAPER)

    def missing(self, wanted: dict[str, int], min_frames: int) -> list[tuple[str, int]]:
        """The next runs a collection of `wanted` usable runs per split (at least `min_frames` frames)
        records: each split's lowest missing indices, enough to cover its deficit."""
        todo = []
        for split, n in wanted.items():
            found, index, deficit = 0, 0, []
            while found + len(deficit) < n:
                if self.has(split, index):
                    found += usable(self.entry(split, index), min_frames)
                else:
                    deficit.append((split, index))
                index += 1
            todo += deficit
        return todo

    def incomplete(self) -> str:
        """'' when the folder holds every run its collection config asks for (a DAgger round's, or an
        imported recording's, says no count), else what it lacks: a collection that did not finish, or a
        partial copy."""
        config = self.config
        if not self._runs:
            return f"{self.root}: holds no run ({MANIFEST} lists none)"
        if not isinstance(config.get("runs"), int) or "rounds" in config or "env" not in config:
            return ""
        wanted = {"train": config["runs"], "val": config.get("val_runs", 0)}
        min_frames = config.get("data", {}).get("min_frames", MIN_FRAMES)
        todo = self.missing(wanted, min_frames)
        if not todo:
            return ""
        lacking = ", ".join(f"{sum(s == split for s, _ in todo)} of the {n} {split} runs"
                            for split, n in wanted.items() if any(s == split for s, _ in todo))
        return (f"{self.root}: lacks {lacking} its config asks for (at least {min_frames} frames each): a "
                "collection that did not finish or a partial copy; resume the collection, or copy the rest")

    def has(self, split: str, index: int) -> bool:
        return (split, index) in self._runs

    def entry(self, split: str, index: int) -> RunEntry:
        return self._runs[(split, index)]

    def run_path(self, split: str, index: int) -> Path:
        """Where run `index` of `split` is (to be) written."""
        return run_path(self.root, split, index)

    def path(self, entry: RunEntry) -> Path:
        return self.root / entry.file

    def add(self, meta: RunMeta, info: FileInfo, rendered: Rendering | None = None) -> RunEntry:
        """Record a run whose file was written to `run_path` (by `write_run`, maybe in a worker);
        `rendered`: a re-rendered run's origin."""
        path = self.run_path(meta.split, meta.index)
        if not path.is_file() or path.stat().st_size != info.bytes:
            raise DataError(f"{path}: not the {info.bytes}-byte file that was written for run {meta.name}")
        entry = RunEntry(**to_dict(meta), file=path.relative_to(self.root).as_posix(), **to_dict(info),
                         rendered=rendered)
        self._runs[(meta.split, meta.index)] = entry
        self._write_manifest()
        return entry

    def add_run(self, run: Run, jpeg_quality: int = JPEG_QUALITY) -> RunEntry:
        """Write a run's file and record it (one process; parallel workers use write_run + add)."""
        info = write_run(self.run_path(run.meta.split, run.meta.index), run, jpeg_quality)
        return self.add(run.meta, info)

    def set_camera_labels(self, entry: RunEntry, labels: CameraLabels) -> RunEntry:
        """Write camera `labels` into run `entry`'s file (rewritten, its frames copied byte for byte)
        and record the file's new size and hash: its fingerprint changes (docs/formats.md#camera-labels).
        An interruption between the file's rename and the manifest's is mended by `adopt_labelled`."""
        with self.reader(entry) as reader:
            info = write_labelled(self.path(entry), reader, labels)
        return self._record(entry, info)

    def adopt_labelled(self, entry: RunEntry) -> RunEntry | None:
        """Run `entry`'s file as `set_camera_labels` left it when stopped before the manifest was
        written: if the file holds camera labels and, written without them, is the recorded file (the
        manifest's size and hash), its new size and hash are recorded and the new row returned; else None."""
        path = self.path(entry)
        try:
            with RunReader(path) as reader, tempfile.TemporaryDirectory(prefix=".", dir=path.parent) as tmp:
                if reader.camera_labels() is None:
                    return None
                recorded = write_labelled(Path(tmp) / path.name, reader, None)
        except DataError:
            return None
        if recorded != entry.info:
            return None
        return self._record(entry, FileInfo(sha256=file_sha256(path), bytes=path.stat().st_size))

    def _record(self, entry: RunEntry, info: FileInfo) -> RunEntry:
        new = replace(entry, sha256=info.sha256, bytes=info.bytes)
        self._runs[(entry.split, entry.index)] = new
        self._write_manifest()
        return new

    def check_idle(self) -> None:
        """A ConfigError if another depthq process is writing the folder now (`depthq.lock.writer`): a
        `depthq label` rewriting its run files, or a collection adding runs."""
        held = writer(self.root)
        if held is None:
            return
        pid, verb = held
        if verb == "label":
            raise ConfigError(f"{self.root} is being labelled: `depthq label` (PID {pid}) is rewriting its "
                              "run files with camera labels; wait for it to finish, then run this again")
        who = f"`depthq {verb}`" if verb else "another depthq process"
        raise ConfigError(f"{self.root} is being written by {who} (PID {pid}); wait for it to finish, then "
                          "run this again")

    def reader(self, entry: RunEntry) -> RunReader:
        """An open reader of a run's file, checked against its manifest row: its size and hash, then
        its metadata (so a row edited by hand, its frame count or index, is not read as other data). A
        file that fails its check while another process writes the folder is that (`check_idle`)."""
        try:
            reader = RunReader(self.path(entry), entry.info)
        except DataError:
            self.check_idle()
            raise
        if reader.meta != entry.run_meta():
            reader.close()
            differing = _differing_keys(to_dict(reader.meta), to_dict(entry.run_meta()))
            raise DataError(
                f"{self.path(entry)}: differs from its row in {self.root / MANIFEST} in "
                f"{', '.join(differing)}; the manifest was changed: restore it (`depthq dataset verify "
                f"{self.root}` lists every problem)"
            )
        return reader

    def read_run(self, entry: RunEntry, images: bool = True) -> Run:
        with self.reader(entry) as reader:
            return reader.run(images)

    def verify(self, progress: bool = False) -> list[str]:
        """Read every run in full; one message per missing, extra, truncated, corrupted or odd file, and
        one if the folder holds fewer runs than its config asks for (`incomplete`)."""
        problems = [problem] if (problem := self.incomplete()) else []
        for entry in Bar(self.entries(), desc="verify", unit="run", disable=not progress):
            try:
                self.read_run(entry)
            except DataError as err:
                problems.append(str(err))
        listed = {self.path(entry) for entry in self.entries()}
        for path in sorted((self.root / RUNS).glob("*.h5")):
            if path not in listed:
                problems.append(f"{path}: extra file, not in {MANIFEST}")
        return problems

    def _check_look_images(self, images: dict[str, str] | None) -> None:
        """A ConfigError naming the images added, removed or changed since the runs were collected; a
        manifest written before it recorded them (or a folder look added to it) records `images`."""
        if images is None or images == self.look_images:
            return
        if self.look_images is None:
            self.look_images = images
            self._write_manifest()
            return
        old = self.look_images
        changes = [f"{what} {', '.join(names)}" for what, names in (
            ("added", sorted(set(images) - set(old))),
            ("removed", sorted(set(old) - set(images))),
            ("changed", sorted(n for n in set(old) & set(images) if old[n] != images[n])),
        ) if names]
        look = self.config.get("env", {}).get("world", {}).get("look")
        raise ConfigError(
            f"{self.root} was collected with other images in its look folder {look}: "
            f"{'; '.join(changes)}; restore them, or collect into another folder (or overwrite it)"
        )

    def _write_manifest(self) -> None:
        images = {} if self.look_images is None else {"look_images": self.look_images}
        write_json(
            self.root / MANIFEST,
            {
                "format": FORMAT,
                "format_version": FORMAT_VERSION,
                "provenance": provenance(),
                "seed": self.seed,
                "config": self.config,
                **images,
                "runs": [to_dict(entry) for entry in self.entries()],
            },
        )

    def _remove_temporaries(self) -> None:
        for tmp in (self.root / RUNS).glob(".*.tmp"):
            tmp.unlink(missing_ok=True)


def _differing_keys(old: Any, new: Any, prefix: str = "") -> list[str]:
    """Dotted paths of the leaves that differ between two JSON values."""
    if isinstance(old, dict) and isinstance(new, dict):
        keys = sorted(set(old) | set(new))
        return [
            path
            for key in keys
            for path in _differing_keys(old.get(key, _MISSING), new.get(key, _MISSING), f"{prefix}{key}.")
        ]
    return [] if old == new else [prefix.rstrip(".")]
