"""The robot camera's imaging chain, applied to each frame as it is taken (docs/design.md#camera-model).

A real TurtleBot3 camera (the Raspberry Pi camera v2, a Sony IMX219) meters the scene and sets its
exposure and gain, drifts in white balance, darkens towards the corners, smears the scene while the
robot turns, adds sensor noise and compresses to JPEG. `RobotCamera` does the same to a render, in
this order: motion blur from the yaw rate during the exposure, vignetting, exposure × gain and white
balance, sensor noise (the world's, `CameraConfig.noise_std`, scaled with the gain), and JPEG: the
recorder's, as a run is stored (`ImagingConfig.jpeg` compresses every frame as it is taken, in
evaluation too). Its settings are drawn per run from `ImagingConfig`'s ranges. It is on in the
textured looks and off in flat and colours, whose frames stay what they were (render plus noise).
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np
from PIL import Image

from depthq.errors import ConfigError

Range = tuple[float, float]
_MAX_BLUR_PX = 64  # a longer blur is cut to this (a turn far faster than the robot's)


@dataclass(frozen=True)
class ImagingConfig:
    """Ranges a run's camera is drawn from (each uniform between its two values); the broad look widens
    every one left at its default (`depthq.sim.look.BROAD_IMAGING`). The real values each stands for
    are in docs/design.md#camera-model."""

    # On or off; none: on in the textured looks, off in flat and colours (today's frames).
    enabled: bool | None = None
    # The mean level, of full scale, auto-exposure steers the frame to.
    ae_target: Range = (0.36, 0.50)
    # The fraction of the log-exposure error auto-exposure corrects per frame.
    ae_rate: Range = (0.3, 0.7)
    # The exposure × gain auto-exposure can reach, relative to the render's (IMX219: analogue gain 1–10.7×).
    ae_limits: Range = (0.4, 4.0)
    # Standard deviation of the red and blue gains' offset from green's, per run (auto white balance's error).
    wb_offset: float = 0.06
    # Standard deviation of the red and blue gains' random walk per frame (white-balance drift).
    wb_drift: float = 0.005
    # The corners' loss of light, a fraction (falls off with the square of the radius).
    vignetting: Range = (0.15, 0.40)
    # Exposure time, ms: the blur is the yaw rate × this × the focal length in pixels.
    exposure_ms: Range = (8.0, 33.0)
    # The sensor noise's standard deviation, × `CameraConfig.noise_std`.
    noise_scale: Range = (1.0, 2.0)
    # JPEG quality of the camera's stream.
    jpeg_quality: Range = (70, 95)
    # JPEG-compress every frame as it is taken (+10 % a step); off: the recorder's JPEG is the camera's.
    jpeg: bool = False

    def __post_init__(self) -> None:
        ranges = {"ae_target": (0, 1), "ae_rate": (0, 1), "ae_limits": (0, math.inf), "vignetting": (0, 1),
                  "exposure_ms": (0, 1000), "noise_scale": (0, math.inf), "jpeg_quality": (1, 100)}
        for name, (lo, hi) in ranges.items():
            a, b = getattr(self, name)
            if not lo <= a <= b <= hi:
                raise ConfigError(
                    f"imaging.{name} must be a range lo <= hi within [{lo}, {hi}], got ({a}, {b})"
                )
        if self.ae_limits[0] <= 0:
            raise ConfigError(f"imaging.ae_limits must be > 0, got {self.ae_limits}")
        if not (self.wb_offset >= 0 and self.wb_drift >= 0):
            raise ConfigError(
                f"imaging.wb_offset and wb_drift must be >= 0, got {self.wb_offset}, {self.wb_drift}"
            )

    def on(self, textured: bool) -> bool:
        """Whether frames pass through the camera model in a look (textured or not)."""
        return textured if self.enabled is None else self.enabled


class RobotCamera:
    """One run's camera: its drawn settings and its state (exposure, white balance) from frame to frame.
    Its buffers are allocated once per run: fresh large arrays per frame cost more than the arithmetic."""

    def __init__(self, config: ImagingConfig, width: int, height: int, hfov_deg: float, noise_std: float,
                 rng: np.random.Generator) -> None:
        u = lambda r: float(rng.uniform(*r))  # noqa: E731
        self.target, self.rate, self.limits = u(config.ae_target), u(config.ae_rate), config.ae_limits
        self.wb = np.array([1 + rng.normal(0, config.wb_offset), 1.0, 1 + rng.normal(0, config.wb_offset)])
        self.wb_drift = config.wb_drift
        self.exposure_s = u(config.exposure_ms) / 1000
        self.noise = noise_table(255.0 * noise_std * u(config.noise_scale))
        self.quality = round(u(config.jpeg_quality)) if config.jpeg else None
        self.gain = 1.0
        self.focal_px = width / 2 / math.tan(math.radians(hfov_deg) / 2)
        y, x = np.mgrid[0:height, 0:width].astype(np.float32)
        corner2 = (width / 2) ** 2 + (height / 2) ** 2
        r2 = ((x - (width - 1) / 2) ** 2 + (y - (height - 1) / 2) ** 2) / corner2
        self.vignette = np.repeat((1 - u(config.vignetting) * r2)[..., None], 3, axis=2).astype(np.float32)
        self._rng = rng
        self._width = width
        self._x = np.empty((height, width, 3), np.float32)
        self._noise = np.empty((height, width, 3), np.int16)
        self._out = np.empty((height, width, 3), np.uint8)

    def blur_px(self, yaw_rate: float) -> float:
        """Pixels the scene sweeps across the image during one exposure at `yaw_rate` (rad/s)."""
        return abs(yaw_rate) * self.exposure_s * self.focal_px

    def expose(self, frame: np.ndarray, yaw_rate: float) -> np.ndarray:
        """A render (uint8) as the sensor records it, before noise: float32 in grey levels (a buffer
        the next call reuses)."""
        x, w = self._x, self._width
        from scipy.ndimage import uniform_filter1d  # here: naming a look (`depthq --help`) loads no scipy

        n = min(round(self.blur_px(yaw_rate)), _MAX_BLUR_PX)
        if n >= 2:  # a box blur along the rows: the scene sweeps sideways across the sensor while turning
            uniform_filter1d(frame, n, axis=1, output=x, mode="nearest")
        else:
            np.copyto(x, frame)
        x *= self.vignette
        rows = x.reshape(x.shape[0], -1)
        rows *= np.tile((self.gain * self.wb).astype(np.float32), w)
        level = float(x[::8, ::8].mean()) / 255  # metering for the next frame
        if level > 0:
            step = self.rate * math.log(self.target / level)
            self.gain = float(np.clip(self.gain * math.exp(step), *self.limits))
        self.wb[[0, 2]] = np.clip(self.wb[[0, 2]] + self._rng.normal(0, self.wb_drift, 2), 0.7, 1.3)
        return x

    def take(self, frame: np.ndarray, yaw_rate: float, rng: np.random.Generator) -> np.ndarray:
        """The frame the camera gives for a render while turning at `yaw_rate`: exposed, with sensor
        noise (drawn from `rng`, as the world's pixel noise is), JPEG-compressed and decoded (a new array)."""
        x = self.expose(frame, yaw_rate)
        np.take(self.noise, rng.integers(0, 256, size=frame.shape, dtype=np.uint8), out=self._noise)
        x += self._noise
        np.clip(x, 0, 255, out=x)
        if self.quality is None:
            return x.astype(np.uint8)
        np.copyto(self._out, x, casting="unsafe")
        buffer = io.BytesIO()
        Image.fromarray(self._out).save(buffer, format="JPEG", quality=self.quality)
        buffer.seek(0)
        with Image.open(buffer) as image:
            return np.asarray(image)


def noise_table(std_levels: float) -> np.ndarray:
    """Gaussian pixel noise quantised to grey levels, as a lookup from one random byte.

    Indexing this 256-entry table with uniform random bytes draws from N(0, std²) at the resolution
    of 1/256 in probability — exact enough for σ ≈ 1.8 levels and ~10× cheaper than normal floats.
    """
    if std_levels == 0:
        return np.zeros(256, np.int16)
    dist = NormalDist(0.0, std_levels)
    return np.array([round(dist.inv_cdf((k + 0.5) / 256)) for k in range(256)], np.int16)
