"""Re-rendered looks (docs/design.md#re-rendered-looks): a dataset's runs rendered again in other looks.

A run's poses, LiDAR, depth bins, actions and end do not depend on the look; its frames do. For each
collected run and each new look, `rerender` writes a run of the same split whose frames are rendered at
the recorded poses in that look and whose other arrays and metadata (but its index) are the source's,
byte for byte. Its manifest row names its source and look (`depthq.data.manifest.Rendering`): training,
labelling and the feature cache read it as one more run, and a validation run's re-render stays in val.

Each frame is taken in the sensor state the collector took it in. MuJoCo's kinematics after a physics
step are those of the step's start, so the collector's camera and LiDAR saw from one step before the
recorded pose: the robot is set there and driven that step at the recorded command. Then the LiDAR is
cast and the frame rendered, their noise and the robot camera's (`depthq.sim.camera_model`: exposure,
white balance, blur from the recorded yaw rate) drawn from one stream in the collector's order. The
frames a run skipped (`CollectConfig.skip_frames`) are not stored, but the camera metered them: they are
driven again from the spawn point with the run's exploration commands (its OU seed), and where that does
not land on the first stored pose, rendered on the way there, the first stored frame taking the command
after it as the one before it. So a run rendered in its own look with its own seeds is its recorded run,
as close as its float32 poses allow (tests/test_rerender.py).

The dataset's v-th re-rendered look (v = 1, 2, ...: a look and a seed) holds run v × STRIDE + i of the
split for source run i (`runs/train_1000012.h5`). Its canyon's appearance and its frames' noise and
camera are drawn from (seed, look, split, source index) alone, so the same calls give the same bytes;
a call stopped at any point resumes where it stopped, as `collect` does.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

import numpy as np

from depthq.configio import check_seed, from_dict
from depthq.control.ou import OUConfig, OUPolicy
from depthq.data.manifest import Dataset, Rendering, RunEntry, run_path
from depthq.data.run import SPLITS, Run, RunMeta, meta_fields
from depthq.data.runfile import FileInfo, RunReader, write_run
from depthq.errors import ConfigError, DataError
from depthq.parallel import LOCAL, Executor
from depthq.progress import Bar
from depthq.sim.canyon import Canyon, CanyonId, generate_canyon
from depthq.sim.env import SPAWN, EnvConfig
from depthq.sim.look import check_look
from depthq.sim.world import CanyonWorld, WorldConfig

STRIDE = 1_000_000  # run indices per look: a collection's own stay below it
POSE_TOLERANCE = 1e-4  # m and rad: a pose driven again is the recorded one (float32) within this
_ARRAYS = ("scans", "bins", "actions", "poses", "times")  # what a re-render copies from its source


@dataclass(frozen=True)
class RenderTask:
    """One run to write: `source` rendered in `look` from `seed`, as run `index` of its split."""

    source: RunEntry
    index: int
    look: str
    seed: int


def render_seeds(seed: int, look: str, split: str, index: int) -> tuple[int, int]:
    """(appearance seed, frame-stream seed) of run `index` of `split` rendered in `look` from `seed`."""
    ss = np.random.SeedSequence([seed, zlib.crc32(look.encode())], spawn_key=(SPLITS.index(split), index))
    appearance, frames = ss.generate_state(2, np.uint64)
    return int(appearance), int(frames)


def render_frames(world: CanyonWorld, run: Run, canyon: Canyon, appearance: np.random.Generator,
                  frames: np.random.Generator, ou: OUConfig | None) -> np.ndarray:
    """`run`'s frames rendered again at its recorded poses in `world`'s look, uint8 (N, H, W, 3): `canyon`
    built with `appearance`, the pixel noise and the run's camera drawn from `frames` as the collector's
    env drew them (its `np_random`); `ou`: the exploration policy that drove it (None: unknown)."""
    world.load(canyon, appearance)
    skipped = round(float(run.times[0]) / world.config.period)
    commands = skipped_commands(world, run, ou, skipped)
    world.place(*SPAWN)
    world.start_run(frames)
    start, first = np.array(SPAWN), run.poses[0].astype(np.float64)
    for k in range(skipped):  # not stored, but metered by the camera
        if commands is None:
            world.place(*(start + k / skipped * (first - start)))
        elif k:
            world.advance(commands[k - 1])
        world.scan(frames)
        world.image(frames)
    before_first = commands[-1] if commands else run.actions[0]
    images = []
    for t in range(run.n_frames):
        _sensor_state(world, run, t, before_first)
        world.scan(frames)  # the LiDAR's noise draws come before the frame's, as in the collector
        images.append(world.image(frames))
    return np.stack(images)


def skipped_commands(world: CanyonWorld, run: Run, ou: OUConfig | None, skipped: int) -> list[float] | None:
    """The commands the collector drove the `skipped` frames before the first stored one with, drawn
    from the run's exploration policy (`ou`, the run's policy seed), if driving them from the spawn point
    lands on the first stored pose; else None."""
    if ou is None or skipped == 0:
        return None
    policy, limit = OUPolicy(ou, seed=run.meta.policy_seed), world.config.max_yaw_rate
    # as the collector sends them: clipped to the robot's limit, then float32 (`collect_run`)
    commands = [float(np.float32(np.clip(policy.act(None), -limit, limit))) for _ in range(skipped)]
    world.place(*SPAWN)
    for command in commands:
        world.advance(command)
    return commands if np.allclose(world.pose, run.poses[0], rtol=0, atol=POSE_TOLERANCE) else None


def _sensor_state(world: CanyonWorld, run: Run, t: int, before_first: float) -> None:
    """The robot as the collector's sensors saw it at frame t: at rest at the spawn point (time 0), or
    one physics step before the recorded pose, driven that step at the command before frame t (before
    frame 0: `before_first`)."""
    if run.times[t] == 0:
        world.place(*SPAWN)
        return
    config = world.config
    command = run.actions[t - 1] if t else before_first
    yaw_rate = float(command) if np.isfinite(command) else 0.0
    x, y, yaw = run.poses[t].astype(np.float64)
    dt, before = config.physics_dt, yaw - config.physics_dt * yaw_rate
    world.place(x - dt * config.speed * math.cos(before), y - dt * config.speed * math.sin(before), before)
    world.drive(config.speed, yaw_rate, 1)


def dataset_env(dataset: Dataset) -> EnvConfig:
    """The env a dataset's runs were collected in (a ConfigError for a robot's recording: no canyon)."""
    env = dataset.config.get("env")
    if env is None or any(e.canyon_split == "recorded" for e in dataset.entries()):
        raise ConfigError(f"{dataset.root} holds a robot's recording: only simulated runs can be re-rendered")
    return from_dict(EnvConfig, env)


def rendered_looks(dataset: Dataset) -> dict[int, tuple[str, int]]:
    """The dataset's re-rendered looks: number v → (look, seed)."""
    return {e.index // STRIDE: (e.rendered.look, e.rendered.seed) for e in dataset.entries() if e.rendered}


class _RenderWorker:
    """One world rendering run after run (a worker of `depthq.parallel`), rebuilt when the look changes;
    only the parent writes the manifest."""

    def __init__(self, root: str, world: WorldConfig, ou: OUConfig | None) -> None:
        self.root, self.base, self.ou = Path(root), world, ou
        self.world: CanyonWorld | None = None

    def __call__(self, task: RenderTask) -> tuple[RunMeta, FileInfo]:
        if self.world is None or self.world.config.look != task.look:
            self.close()
            self.world = CanyonWorld(replace(self.base, look=task.look))
        source = task.source
        with RunReader(self.root / source.file, source.info) as reader:
            run, quality = reader.run(images=False), reader.jpeg_quality
        config = self.world.config
        canyon_id = CanyonId(source.canyon_split, source.canyon_index, config.family)
        if int(canyon_id.seed_sequence.generate_state(1)[0]) != source.canyon_seed:
            raise DataError(f"{self.root / source.file}: drove a canyon of seed {source.canyon_seed}, canyon "
                            f"{canyon_id} has another: it cannot be rendered again")
        appearance, frames = render_seeds(task.seed, task.look, source.split, source.index)
        images = render_frames(self.world, run, generate_canyon(canyon_id, config.canyon),
                               np.random.default_rng(appearance), np.random.default_rng(frames), self.ou)
        meta = replace(run.meta, index=task.index)
        out = Run(meta=meta, images=images, **{name: getattr(run, name) for name in _ARRAYS})
        return meta, write_run(run_path(self.root, source.split, task.index), out, quality)

    def close(self) -> None:
        if self.world is not None:
            self.world.close()
            self.world = None


def rerender(root: Path, looks: tuple[str, ...], seed: int = 1, workers: int = 1, progress: bool = True,
             executor: Executor = LOCAL) -> Dataset:
    """Render every collected run of the dataset in `root` again in each of `looks` (drawn from `seed`),
    adding each as a run; what is there already is kept (an interrupted call resumes)."""
    check_seed(seed)
    if workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {workers}")
    if not looks:
        raise ConfigError("--looks names no look; give one or more, e.g. broad,textured")
    repeated = sorted({look for look in looks if looks.count(look) > 1})
    if repeated:
        raise ConfigError(f"--looks names {', '.join(repeated)} twice; another draw of a look takes another "
                          "--seed")
    for look in looks:
        check_look(look)
    opened = Dataset.open(root)
    env = dataset_env(opened)
    executor.check_shared(root)  # workers write the run files themselves
    ou = from_dict(OUConfig, opened.config["ou"]) if "ou" in opened.config else None
    dataset = Dataset.create(opened.root.resolve(), opened.config, opened.seed)  # a resume: stray files go
    sources = [e for e in dataset.entries() if e.rendered is None]
    if any(e.index >= STRIDE for e in sources):
        raise ConfigError(f"{root} holds runs of index {STRIDE} or more: no room for re-rendered ones")
    numbers = {draw: v for v, draw in rendered_looks(dataset).items()}
    todo = []
    for look in looks:
        v = numbers.setdefault((look, seed), max(numbers.values(), default=0) + 1)
        todo += [RenderTask(e, v * STRIDE + e.index, look, seed) for e in sources
                 if not dataset.has(e.split, v * STRIDE + e.index)]
    origin = {(t.source.split, t.index): Rendering(t.source.index, t.look, t.seed) for t in todo}
    frames = sum(t.source.n_frames for t in todo)
    with Bar(total=frames, desc="rerender", unit="frame", disable=not progress, dynamic_ncols=True) as bar:
        for meta, info in _render_all(todo, partial(_RenderWorker, str(dataset.root), env.world, ou), workers,
                                      executor):
            dataset.add(meta, info, origin[(meta.split, meta.index)])
            bar.update(meta.n_frames)
    return dataset


def _render_all(todo: list[RenderTask], make_worker: partial, workers: int, executor: Executor
                ) -> Iterator[tuple[RunMeta, FileInfo]]:
    if workers == 1 and executor.kind == "local":  # in this process: no worker to start
        worker = make_worker()
        try:
            yield from (worker(task) for task in todo)
        finally:
            worker.close()
        return
    for _, result in executor.run(make_worker, todo, workers, "re-rendering"):
        yield result


def verify_rendered(dataset: Dataset) -> list[str]:
    """One message per re-rendered run that is not its source's run in another look: a source missing,
    an index or look that does not match its row, or metadata or non-image data differing from the
    source's. Files that cannot be read are `Dataset.verify`'s to name."""
    problems, looks = [], {}
    for entry in dataset.entries():
        origin = entry.rendered
        if origin is None:
            continue
        path = dataset.path(entry)
        v, source_index = divmod(entry.index, STRIDE)
        if v < 1 or source_index != origin.source:
            problems.append(f"{path}: index {entry.index} is not a re-render of run {origin.source} (that "
                            f"run's index plus a multiple of {STRIDE})")
            continue
        if looks.setdefault(v, (origin.look, origin.seed)) != (origin.look, origin.seed):
            problems.append(f"{path}: look {origin.look!r} seed {origin.seed}, but the other runs of "
                            f"re-rendered look {v} have look {looks[v][0]!r} seed {looks[v][1]}")
        if not dataset.has(entry.split, origin.source) or dataset.entry(entry.split, origin.source).rendered:
            problems.append(f"{path}: its source, run {origin.source} of {entry.split}, is not a collected "
                            "run of the manifest")
            continue
        source = dataset.entry(entry.split, origin.source)
        try:
            with dataset.reader(entry) as mine, dataset.reader(source) as theirs:
                a, b = mine.run(images=False), theirs.run(images=False)
                shapes = mine.image_shape, theirs.image_shape
        except DataError:
            continue
        differing = [name for name in meta_fields() if name != "index" and getattr(a.meta, name) !=
                     getattr(b.meta, name)]
        differing += [name for name in _ARRAYS if getattr(a, name).tobytes() != getattr(b, name).tobytes()]
        differing += ["image_shape"] if shapes[0] != shapes[1] else []
        if differing:
            problems.append(f"{path}: differs from its source {dataset.path(source)} in "
                            f"{', '.join(differing)}; a re-rendered run keeps its source's poses, LiDAR, "
                            "bins, actions and end")
    return problems
