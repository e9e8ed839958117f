"""How a canyon looks, apart from its geometry (docs/design.md#looks).

Looks: `flat` (the paper family's: grey walls, grey floor, one sun), `colours` (the hard family's:
random colours per wall side, floor and pillars, a random sun direction), `textured` (image textures
on walls, pillars and floor from the training bank, randomised light and sky), `heldout` (the same
from a bank that shares nothing with the training one, light outside the training ranges), or a
folder of images (the user's bank, the training ranges of light), or `broad` (per surface a flat
colour, a training photograph or a procedural pattern at continuous settings, `depthq.sim.broad`;
light and camera ranges wider than textured's, never the held-out ones). Each canyon's look is drawn
from its own seed (`CanyonId.appearance_seed`), so the same canyon always looks the same.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from depthq.errors import ConfigError
from depthq.sim.broad import draw_broad_texture
from depthq.sim.camera_model import ImagingConfig
from depthq.sim.textures import (
    HELDOUT_BANK,
    TRAINING_BANK,
    TextureBank,
    draw_texture,
    folder_bank,
    folder_checksums,
)

FLAT, COLOURS, TEXTURED, HELDOUT, BROAD = "flat", "colours", "textured", "heldout", "broad"
LOOKS = (FLAT, COLOURS, TEXTURED, HELDOUT, BROAD)
# `WorldConfig.appearance`, as records written before looks name it: the paper's and the hard family's.
LEGACY_APPEARANCE = {"default": FLAT, "randomized": COLOURS}
# The textured surfaces, each drawn from the bank per canyon: wall sides, the back wall, pillars, floor.
SURFACES = ("left", "right", "back", "pillars", "floor")
Range = tuple[float, float]
SKY_JITTER = (0.9, 1.1)  # each sky colour (zenith, horizon) × one draw of this range


@dataclass(frozen=True)
class Lighting:
    """Ranges a canyon's light is drawn from; each a union of intervals: one interval drawn, then a
    value uniformly within it."""

    elevation_deg: tuple[Range, ...]  # the sun's height above the horizon
    strength: tuple[Range, ...]  # the sun's diffuse intensity
    ambient: tuple[Range, ...]  # the ambient light (MuJoCo's headlight ambient)
    kelvin: tuple[Range, ...]  # the sun's colour temperature
    skies: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...]  # (zenith, horizon)
    # An interval drawn in proportion to its length (uniform over the union); else each alike.
    by_length: bool = False


# The training ranges: daylight through windows, indoor lamps.
TRAINING_LIGHT = Lighting(
    elevation_deg=((30.0, 75.0),),
    strength=((0.35, 0.65),),
    ambient=((0.22, 0.40),),
    kelvin=((3500.0, 6500.0),),
    skies=(((0.45, 0.62, 0.85), (0.80, 0.86, 0.92)), ((0.62, 0.64, 0.66), (0.85, 0.85, 0.85)),
           ((0.90, 0.90, 0.86), (0.70, 0.68, 0.62))),
)
# The held-out ranges, all outside the training ones: low sun, dim or glaring, warm or cold light.
HELDOUT_LIGHT = Lighting(
    elevation_deg=((12.0, 25.0),),
    strength=((0.18, 0.30), (0.70, 0.85)),
    ambient=((0.12, 0.20), (0.42, 0.50)),
    kelvin=((2700.0, 3300.0), (7000.0, 9000.0)),
    skies=(((0.95, 0.55, 0.30), (0.98, 0.85, 0.60)), ((0.10, 0.12, 0.25), (0.35, 0.30, 0.40))),
)
# The broad ranges: training's, widened on every side the held-out ones leave free, and beyond them
# (a union of intervals that skips every held-out one); training's skies and three more.
BROAD_LIGHT = Lighting(
    elevation_deg=((26.0, 88.0),),
    strength=((0.08, 0.17), (0.31, 0.69), (0.86, 1.0)),
    ambient=((0.04, 0.11), (0.21, 0.41), (0.51, 0.62)),
    kelvin=((2000.0, 2650.0), (3350.0, 6950.0), (9100.0, 12000.0)),
    skies=(*TRAINING_LIGHT.skies, ((0.20, 0.35, 0.75), (0.65, 0.78, 0.95)),
           ((0.95, 0.95, 0.95), (0.88, 0.88, 0.88)), ((0.32, 0.34, 0.36), (0.55, 0.56, 0.58))),
    by_length=True,
)
# The broad look's camera ranges: each of textured's (`ImagingConfig`'s defaults) widened.
BROAD_IMAGING = ImagingConfig(
    ae_target=(0.28, 0.60), ae_rate=(0.15, 0.9), wb_offset=0.12, wb_drift=0.01, vignetting=(0.0, 0.6),
    exposure_ms=(4.0, 50.0), noise_scale=(0.5, 3.5), jpeg_quality=(50, 95),
)


@dataclass(frozen=True)
class CanyonLook:
    """One canyon's drawn textured look: a uint8 texture per surface, the sun, ambient light, sky."""

    textures: dict[str, np.ndarray]
    sun_dir: np.ndarray  # unit vector, pointing from the sun
    sun_diffuse: np.ndarray  # RGB
    ambient: float
    sky: tuple[tuple[float, float, float], tuple[float, float, float]]


def check_look(look: str) -> None:
    """A ConfigError naming `look` unless it is a look's name or a folder of images."""
    if look not in LOOKS:
        bank(look)


def is_textured(look: str) -> bool:
    """Whether `look` draws image textures (every look but flat and colours)."""
    return look not in (FLAT, COLOURS)


def bank(look: str) -> TextureBank:
    """The texture bank of a textured look (a folder: its images)."""
    if look == TEXTURED:
        return TRAINING_BANK
    if look == HELDOUT:
        return HELDOUT_BANK
    if look in (FLAT, COLOURS, BROAD):
        raise ConfigError(f"look {look!r} has no texture bank")
    if Path(look).is_file():
        raise ConfigError(f"look {look!r} is a file; a look is one of {LOOKS} or a folder of images")
    if not Path(look).is_dir() and ("/" in look or look.startswith(("~", "."))):
        raise ConfigError(f"look {look!r}: the folder {look} does not exist; name a folder of images or "
                          f"one of the looks {LOOKS}")
    if not Path(look).is_dir():
        raise ConfigError(f"unknown look {look!r}; expected one of {LOOKS} or a folder of images (no "
                          f"folder {look} exists here)")
    return folder_bank(look)


def look_images(look: str) -> dict[str, str] | None:
    """A folder look's images, SHA-256 by file name (what a dataset collected in it records); None for
    a named look, whose images ship with the code."""
    if look in LOOKS:
        return None
    return folder_checksums(bank(look))


def lighting(look: str) -> Lighting:
    return {HELDOUT: HELDOUT_LIGHT, BROAD: BROAD_LIGHT}.get(look, TRAINING_LIGHT)


def imaging(look: str, config: ImagingConfig) -> ImagingConfig:
    """The camera ranges a run in `look` draws from: `config`, where in the broad look every setting
    left at its default is BROAD_IMAGING's (one set on the command line wins)."""
    if look != BROAD:
        return config
    default = ImagingConfig()
    return replace(config, **{f.name: getattr(BROAD_IMAGING, f.name) for f in fields(ImagingConfig)
                              if getattr(config, f.name) == getattr(default, f.name)})


def _uniform(rng: np.random.Generator, ranges: tuple[Range, ...], by_length: bool) -> float:
    if len(ranges) == 1:
        lo, hi = ranges[0]
    elif by_length:
        lengths = np.array([b - a for a, b in ranges])
        lo, hi = ranges[int(rng.choice(len(ranges), p=lengths / lengths.sum()))]
    else:
        lo, hi = ranges[int(rng.integers(len(ranges)))]
    return float(rng.uniform(lo, hi))


def kelvin_rgb(kelvin: float) -> np.ndarray:
    """A colour temperature's RGB, brightest channel 1 (Tanner Helland's fit of the Planck locus)."""
    t = kelvin / 100.0
    r = 255.0 if t <= 66 else 329.698727446 * (t - 60) ** -0.1332047592
    g = (99.4708025861 * math.log(t) - 161.1195681661 if t <= 66
         else 288.1221695283 * (t - 60) ** -0.0755148492)
    b = 255.0 if t >= 66 else (0.0 if t <= 19 else 138.5177312231 * math.log(t - 10) - 305.0447927307)
    rgb = np.clip([r, g, b], 0, 255)
    return rgb / rgb.max()


def draw_canyon_look(look: str, rng: np.random.Generator) -> CanyonLook:
    """A canyon's textured look from its appearance seed: textures, then light, then sky."""
    if look == BROAD:
        textures = {surface: draw_broad_texture(rng) for surface in SURFACES}
    else:
        source = bank(look)
        textures = {surface: draw_texture(source, rng) for surface in SURFACES}
    light = lighting(look)
    elevation = math.radians(_uniform(rng, light.elevation_deg, light.by_length))
    azimuth = float(rng.uniform(0, 2 * math.pi))
    sun_dir = -np.array([math.cos(elevation) * math.cos(azimuth), math.cos(elevation) * math.sin(azimuth),
                         math.sin(elevation)])
    diffuse = _uniform(rng, light.strength, light.by_length) * kelvin_rgb(
        _uniform(rng, light.kelvin, light.by_length))
    ambient = _uniform(rng, light.ambient, light.by_length)
    zenith, horizon = light.skies[int(rng.integers(len(light.skies)))]
    jitter = rng.uniform(*SKY_JITTER, size=2)
    sky = tuple(tuple(np.clip(np.array(c) * j, 0, 1).tolist())
                for c, j in zip((zenith, horizon), jitter, strict=True))
    return CanyonLook(textures, sun_dir, diffuse, ambient, sky)  # type: ignore[arg-type]


def upgrade_world(world: dict[str, Any]) -> dict[str, Any]:
    """A world config record written before looks (`appearance`) in today's shape (`look`)."""
    if "appearance" not in world:
        return world
    out = {k: v for k, v in world.items() if k != "appearance"}
    out.setdefault("look", LEGACY_APPEARANCE.get(world["appearance"], world["appearance"]))
    return out
