"""How a canyon looks, apart from its geometry (docs/design.md#looks).

Looks: `flat` (the paper family's: grey walls, grey floor, one sun), `colours` (the hard family's:
random colours per wall side, floor and pillars, a random sun direction), `textured` (image textures
on walls, pillars and floor from the training bank, randomised light and sky), `heldout` (the same
from a bank that shares nothing with the training one, light outside the training ranges), or a
folder of images (the user's bank, the training ranges of light). Each canyon's look is drawn from
its own seed (`CanyonId.appearance_seed`), so the same canyon always looks the same.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from depthq.errors import ConfigError
from depthq.sim.textures import HELDOUT_BANK, TRAINING_BANK, TextureBank, draw_texture, folder_bank

FLAT, COLOURS, TEXTURED, HELDOUT = "flat", "colours", "textured", "heldout"
LOOKS = (FLAT, COLOURS, TEXTURED, HELDOUT)
# `WorldConfig.appearance`, as records written before looks name it: the paper's and the hard family's.
LEGACY_APPEARANCE = {"default": FLAT, "randomized": COLOURS}
# The textured surfaces, each drawn from the bank per canyon: wall sides, the back wall, pillars, floor.
SURFACES = ("left", "right", "back", "pillars", "floor")
Range = tuple[float, float]


@dataclass(frozen=True)
class Lighting:
    """Ranges a canyon's light is drawn from; each a union of intervals, drawn uniformly."""

    elevation_deg: tuple[Range, ...]  # the sun's height above the horizon
    strength: tuple[Range, ...]  # the sun's diffuse intensity
    ambient: tuple[Range, ...]  # the ambient light (MuJoCo's headlight ambient)
    kelvin: tuple[Range, ...]  # the sun's colour temperature
    skies: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...]  # (zenith, horizon)


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
    if look in (FLAT, COLOURS):
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


def lighting(look: str) -> Lighting:
    return HELDOUT_LIGHT if look == HELDOUT else TRAINING_LIGHT


def _uniform(rng: np.random.Generator, ranges: tuple[Range, ...]) -> float:
    lo, hi = ranges[int(rng.integers(len(ranges)))] if len(ranges) > 1 else ranges[0]
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
    source = bank(look)
    textures = {surface: draw_texture(source, rng) for surface in SURFACES}
    light = lighting(look)
    elevation = math.radians(_uniform(rng, light.elevation_deg))
    azimuth = float(rng.uniform(0, 2 * math.pi))
    sun_dir = -np.array([math.cos(elevation) * math.cos(azimuth), math.cos(elevation) * math.sin(azimuth),
                         math.sin(elevation)])
    diffuse = _uniform(rng, light.strength) * kelvin_rgb(_uniform(rng, light.kelvin))
    ambient = _uniform(rng, light.ambient)
    zenith, horizon = light.skies[int(rng.integers(len(light.skies)))]
    jitter = rng.uniform(0.9, 1.1, size=2)
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
