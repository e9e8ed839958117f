"""One collected run in memory: per-frame arrays plus the metadata that identifies it.

Shapes and dtypes are checked here, once, so the writer, the reader and the collector agree on
what a run is. Frame t holds the observation at step t and the action applied after seeing it;
the last frame has no action (NaN) because the run ended there.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from depthq.data.camera_labels import CameraLabels
from depthq.sim.sensors import N_RAYS

SPLITS = ("train", "val")
# the canyon streams of depthq.sim.canyon, and "recorded": a run imported from a robot's bag
CANYON_SPLITS = ("train", "val", "eval", "recorded")
COLLISION_END_REASONS = ("bump", "contact")
# "stop": an imported run ended where the robot stood still or the recording broke off; "end": the
# run reached the open end of its canyon (a short one, `depthq.sim.canyon.FAMILIES`)
END_REASONS = (*COLLISION_END_REASONS, "time_limit", "step_limit", "stop", "end")


@dataclass(frozen=True)
class RunMeta:
    """What identifies a run and how it ended; stored in the run file and in the manifest."""

    split: str
    index: int
    canyon_split: str
    canyon_index: int
    canyon_seed: int
    policy_seed: int
    end_reason: str
    n_frames: int

    def __post_init__(self) -> None:
        for name, allowed in (
            ("split", SPLITS),
            ("canyon_split", CANYON_SPLITS),
            ("end_reason", END_REASONS),
        ):
            if getattr(self, name) not in allowed:
                raise ValueError(f"run {name} must be one of {allowed}, got {getattr(self, name)!r}")
        for name in ("index", "canyon_index", "canyon_seed", "policy_seed", "n_frames"):
            value = getattr(self, name)
            if not isinstance(value, int | np.integer) or isinstance(value, bool) or value < 0:
                raise ValueError(f"run {name} must be an integer >= 0, got {value!r}")
        if self.n_frames < 1:
            raise ValueError(f"a run has at least one frame, got n_frames={self.n_frames}")

    @property
    def name(self) -> str:
        """File stem, e.g. `train_000123`: the split and the position in it."""
        return f"{self.split}_{self.index:06d}"

    @property
    def collision(self) -> bool:
        """Whether the run ended by hitting something (its last H actions get collision targets)."""
        return self.end_reason in COLLISION_END_REASONS


def meta_fields() -> tuple[str, ...]:
    """Names of the RunMeta fields, in declaration order (run-file attributes and manifest rows)."""
    return tuple(f.name for f in fields(RunMeta))


@dataclass(frozen=True, eq=False)
class Run:
    """A run's frames. `images` is None when a run was read without them (labels and stats need none)."""

    meta: RunMeta
    images: np.ndarray | None  # uint8 (N, H, W, 3)
    scans: np.ndarray  # float32 (N, 360), metres, inf = no return
    bins: np.ndarray  # float32 (N, B), NaN = invalid bin
    actions: np.ndarray  # float32 (N,), rad/s; actions[-1] is NaN
    poses: np.ndarray  # float32 (N, 3): x, y, yaw
    times: np.ndarray  # float32 (N,), seconds since the start of the run
    camera: CameraLabels | None = None  # bins estimated from the camera (`depthq label`), if written

    def __post_init__(self) -> None:
        n = self.meta.n_frames
        if self.images is not None:
            _check(self.images, "images", np.uint8, (n, None, None, 3))
        _check(self.scans, "scans", np.float32, (n, N_RAYS))
        _check(self.bins, "bins", np.float32, (n, None))
        _check(self.actions, "actions", np.float32, (n,))
        _check(self.poses, "poses", np.float32, (n, 3))
        _check(self.times, "times", np.float32, (n,))
        if not np.isfinite(self.actions[:-1]).all() or not np.isnan(self.actions[-1]):
            raise ValueError(f"run {self.meta.name}: actions must be finite except the last, which is NaN")
        if self.camera is not None and self.camera.bins.shape != self.bins.shape:
            raise ValueError(f"run {self.meta.name}: camera labels {self.camera.bins.shape} do not match "
                             f"its bins {self.bins.shape}")

    @property
    def n_frames(self) -> int:
        return self.meta.n_frames


def _check(array: np.ndarray, name: str, dtype: type, shape: tuple[int | None, ...]) -> None:
    """Raise ValueError unless `array` has `dtype` and `shape` (None = any size)."""
    ok = (
        isinstance(array, np.ndarray)
        and array.dtype == dtype
        and array.ndim == len(shape)
        and all(want is None or want == got for want, got in zip(shape, array.shape, strict=True))
    )
    if not ok:
        got = f"{array.dtype} {array.shape}" if isinstance(array, np.ndarray) else type(array).__name__
        want = ", ".join("*" if s is None else str(s) for s in shape)
        raise ValueError(f"run {name} must be {np.dtype(dtype)} ({want}), got {got}")
