"""The robot camera's imaging chain, applied to each frame as it is taken (docs/design.md#camera-model).

A real TurtleBot3 camera (the Raspberry Pi camera v2, a Sony IMX219) meters the scene and sets its
exposure and gain, drifts in white balance, darkens towards the corners, smears the scene while the
robot turns, adds sensor noise and compresses to JPEG. `RobotCamera` does the same to a render, in
this order: vignetting, exposure × gain and white balance, motion blur from the yaw rate during the
exposure, sensor noise (the world's, `CameraConfig.noise_std`, scaled with the gain), JPEG. Its
settings are drawn per run from `ImagingConfig`'s ranges. It is on in the textured looks and off in
flat and colours, whose frames stay what they were (render plus pixel noise).
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass

import numpy as np
from PIL import Image

from depthq.errors import ConfigError

Range = tuple[float, float]


@dataclass(frozen=True)
class ImagingConfig:
    """Ranges a run's camera is drawn from (each uniform between its two values). The real values each
    stands for are in docs/design.md#camera-model."""

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
    """One run's camera: its drawn settings and its state (exposure, white balance) from frame to frame."""

    def __init__(self, config: ImagingConfig, width: int, height: int, hfov_deg: float,
                 rng: np.random.Generator) -> None:
        u = lambda r: float(rng.uniform(*r))  # noqa: E731
        self.target, self.rate, self.limits = u(config.ae_target), u(config.ae_rate), config.ae_limits
        self.wb = np.array([1 + rng.normal(0, config.wb_offset), 1.0, 1 + rng.normal(0, config.wb_offset)])
        self.wb_drift = config.wb_drift
        self.exposure_s = u(config.exposure_ms) / 1000
        self.noise_scale = u(config.noise_scale)
        self.quality = round(u(config.jpeg_quality))
        self.gain = 1.0
        self.focal_px = width / 2 / math.tan(math.radians(hfov_deg) / 2)
        y, x = np.mgrid[0:height, 0:width].astype(np.float32)
        corner2 = (width / 2) ** 2 + (height / 2) ** 2
        r2 = ((x - (width - 1) / 2) ** 2 + (y - (height - 1) / 2) ** 2) / corner2
        self.vignette = (1 - u(config.vignetting) * r2)[..., None].astype(np.float32)
        self._rng = rng

    def blur_px(self, yaw_rate: float) -> float:
        """Pixels the scene sweeps across the image during one exposure at `yaw_rate` (rad/s)."""
        return abs(yaw_rate) * self.exposure_s * self.focal_px

    def expose(self, frame: np.ndarray, yaw_rate: float) -> np.ndarray:
        """A render (uint8) as the sensor records it, before noise: float32 in grey levels."""
        x = frame.astype(np.float32) * (self.vignette * (self.gain * self.wb).astype(np.float32))
        n = round(self.blur_px(yaw_rate))
        if n >= 2:  # a box blur along the rows: the image sweeps sideways while the robot turns
            c = np.cumsum(np.pad(x, ((0, 0), (n // 2 + 1, n - n // 2 - 1), (0, 0)), mode="edge"), axis=1)
            x = (c[:, n:] - c[:, :-n]) / n
        level = float(x[::8, ::8].mean()) / 255  # metering for the next frame
        if level > 0:
            step = self.rate * math.log(self.target / level)
            self.gain = float(np.clip(self.gain * math.exp(step), *self.limits))
        self.wb[[0, 2]] = np.clip(self.wb[[0, 2]] + self._rng.normal(0, self.wb_drift, 2), 0.7, 1.3)
        return x

    def finish(self, frame: np.ndarray) -> np.ndarray:
        """The camera's JPEG, decoded: what its stream carries."""
        buffer = io.BytesIO()
        Image.fromarray(frame).save(buffer, format="JPEG", quality=self.quality)
        buffer.seek(0)
        with Image.open(buffer) as image:
            return np.asarray(image.convert("RGB"))
