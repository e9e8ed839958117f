"""LiDAR post-processing as pure functions of a scan: depth bins and the bump rule
(docs/design.md#bins, docs/design.md#bump).

A scan is 360 readings; index i is the bearing i degrees counter-clockwise from straight ahead
(so index 90 looks left, index 270 right). `inf` is "no return within range", 0 or NaN is an
invalid reading, as the TurtleBot3's LDS-01 reports them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from depthq.errors import ConfigError

N_RAYS = 360


@dataclass(frozen=True)
class LidarConfig:
    """LDS-01 as simulated in the original system."""

    n_rays: int = N_RAYS  # rays per scan, 1 degree apart (360: the only one simulated)
    range_min: float = 0.12  # nearer returns read 0 (invalid), m
    range_max: float = 3.5  # farther returns read inf (nothing in range), m
    noise_std: float = 0.01  # Gaussian range noise's standard deviation, m
    height: float = 0.172  # the scan plane's height above the floor, m

    def __post_init__(self) -> None:
        if self.n_rays != N_RAYS:
            raise ConfigError(f"the LiDAR has 360 rays (1° apart); got n_rays={self.n_rays}")
        if not 0 <= self.range_min < self.range_max:
            raise ConfigError(
                f"LiDAR range must satisfy 0 <= min < max, got {self.range_min}, {self.range_max}"
            )
        if not self.noise_std >= 0:
            raise ConfigError(f"LiDAR noise_std must be >= 0, got {self.noise_std}")


@dataclass(frozen=True)
class BinConfig:
    """The 26 depth bins: 104 readings from +51° to −52°, clipped at 2 m, averaged in groups of 4.

    `invalid_as_far`: the original recorder stored a reading of 0 or no return as 5 m, so after the
    clip it is far, never invalid (docs/design.md#bins). False keeps such readings out of the mean (NaN bins).
    """

    first_bearing: int = 51  # bearing of the leftmost reading, degrees (CCW from ahead)
    n_readings: int = 104  # readings from there clockwise, one per degree
    group: int = 4  # readings averaged into one bin
    clip: float = 2.0  # readings clipped to this before the mean, m
    invalid_as_far: bool = True

    @property
    def n_bins(self) -> int:
        return self.n_readings // self.group


@dataclass(frozen=True)
class BumpConfig:
    """A bump ends a run: readings within ±45°, clipped at 1 m, averaged in groups of 4, min < 0.2 m.

    Checked from the first step: in the original the robot stood still for 1 s, then driving and the
    bump check started together (`grace_s` > 0 delays the check after the start of driving).
    """

    half_angle: int = 45  # readings within ±this of ahead, degrees
    group: int = 4  # readings averaged into one value
    clip: float = 1.0  # readings clipped to this before the mean, m
    threshold: float = 0.2  # a bump: the smallest mean below this, m
    grace_s: float = 0.0  # seconds after the start of driving before the bump check starts


def ray_directions(n_rays: int = N_RAYS) -> np.ndarray:
    """Unit vectors of the rays in the sensor frame (x forward, y left), shape (n, 2)."""
    angles = np.deg2rad(np.arange(n_rays))
    return np.stack([np.cos(angles), np.sin(angles)], axis=1)


def finish_scan(distance: np.ndarray, config: LidarConfig, rng: np.random.Generator) -> np.ndarray:
    """Raw ray-cast distances (−1 = no hit) → a sensor reading: noise, then the range limits.

    Beyond `range_max` (or no hit) reads `inf`; closer than `range_min` reads 0 (invalid).
    """
    scan = distance + config.noise_std * rng.standard_normal(distance.shape)
    scan = np.where(distance < 0, np.inf, scan)
    scan = np.where(scan > config.range_max, np.inf, scan)
    scan = np.where(scan < config.range_min, 0.0, scan)
    return scan.astype(np.float32)


def _bearings_left_to_right(first: int, count: int) -> np.ndarray:
    """Scan indices from bearing `first` (left) clockwise through `count` readings."""
    return (first - np.arange(count)) % N_RAYS


def _group_mean(readings: np.ndarray, clip: float, group: int) -> np.ndarray:
    """Mean of each consecutive group, ignoring invalid readings (0/NaN); `inf` counts as `clip`."""
    valid = np.isfinite(readings) & (readings > 0) | np.isposinf(readings)
    values = np.where(valid, np.minimum(np.nan_to_num(readings, posinf=clip), clip), 0.0)
    n_groups = -(-readings.shape[-1] // group)
    pad = n_groups * group - readings.shape[-1]
    if pad:
        values = np.concatenate([values, np.zeros((*values.shape[:-1], pad))], axis=-1)
        valid = np.concatenate([valid, np.zeros((*valid.shape[:-1], pad), bool)], axis=-1)
    values = values.reshape(*values.shape[:-1], n_groups, group)
    counts = valid.reshape(*valid.shape[:-1], n_groups, group).sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, values.sum(-1) / counts, np.nan)


def depth_bins(scan: np.ndarray, config: BinConfig = BinConfig()) -> np.ndarray:
    """The 26 depth bins (left to right) of a scan (..., 360).

    With `invalid_as_far` (the original) an invalid reading counts as the clip; otherwise it is left
    out of its bin's mean, and NaN marks a bin with no valid reading.
    """
    idx = _bearings_left_to_right(config.first_bearing, config.n_readings)
    readings = np.asarray(scan, dtype=np.float64)[..., idx]
    if config.invalid_as_far:
        readings = np.where(np.isnan(readings) | (readings <= 0), np.inf, readings)
    return _group_mean(readings, config.clip, config.group).astype(np.float32)


def bump(scan: np.ndarray, config: BumpConfig = BumpConfig()) -> bool:
    """True when something is closer than the threshold in front (±45°), by the original rule."""
    idx = _bearings_left_to_right(config.half_angle - 1, 2 * config.half_angle)
    groups = _group_mean(np.asarray(scan, dtype=np.float64)[idx], config.clip, config.group)
    return bool(np.nanmin(groups, initial=np.inf) < config.threshold)
