"""The broad look's textures (docs/design.md#broad-look): domain randomisation over many kinds of
surface rather than one more photo set.

Per canyon and surface, `draw_broad_texture` draws one of: a flat colour (as the colour look's), a
photograph of the training bank (at a random scale, offset, contrast, saturation and tint), or a
procedural pattern of `PATTERNS`, its parameters drawn from continuous ranges and mapped between two
random colours at a random contrast. Nothing is drawn from the held-out bank: no photograph of it
and none of its generator kinds (marble, tiles, dots), so the held-out look stays a test.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from depthq.sim.textures import GENERATORS, SCALES, TEXTURE_SIZE, TRAINING_BANK, photo

# A surface's source: a flat colour, a training photograph or a procedural pattern, with these odds.
SOURCE_ODDS = {"flat": 0.25, "photo": 0.25, "pattern": 0.5}
BROAD_PHOTOS = TRAINING_BANK.photos


@dataclass(frozen=True)
class Pattern:
    """A generator kind of `depthq.sim.textures.GENERATORS` and the range each parameter is drawn
    from (uniform; `whole` parameters are counts across one texture repeat, so that it tiles)."""

    kind: str
    ranges: tuple[tuple[str, float, float], ...]
    whole: tuple[str, ...] = ()

    def draw(self, rng: np.random.Generator) -> dict[str, float]:
        """One setting of every parameter (a whole one: each count from lo to hi alike)."""
        return {name: float(np.floor(rng.uniform(lo, hi + 1)) if name in self.whole else rng.uniform(lo, hi))
                for name, lo, hi in self.ranges}


# Training's generator kinds at continuous settings, and three kinds no bank holds.
PATTERNS = (
    Pattern("noise", (("beta", 0.5, 3.5), ("stretch", 0.25, 4.0))),
    Pattern("bricks", (("rows", 3, 16), ("cols", 1, 6), ("mortar", 0.008, 0.02)), whole=("rows", "cols")),
    Pattern("stripes", (("period", 2, 20), ("duty", 0.15, 0.85)), whole=("period",)),
    Pattern("wood", (("rings", 2, 16), ("turbulence", 0.2, 1.5)), whole=("rings",)),
    Pattern("cells", (("count", 3, 10), ("edge", 0.0, 0.12)), whole=("count",)),
    Pattern("waves", (("count", 1, 3), ("frequency", 1, 8), ("sharpness", 0.3, 3.0)),
            whole=("count", "frequency")),
    Pattern("plaid", (("bands", 2, 8), ("mix", 0.2, 0.8)), whole=("bands",)),
)
FLAT_COLOURS = (0.1, 0.95)  # each channel of a flat surface, uniform (the colour look's walls: 0.15–0.95)


def draw_broad_texture(rng: np.random.Generator, size: int = TEXTURE_SIZE) -> np.ndarray:
    """One surface's texture in the broad look: uint8 (size, size, 3) that tiles."""
    source = rng.choice(list(SOURCE_ODDS), p=list(SOURCE_ODDS.values()))
    if source == "flat":
        image = np.broadcast_to(rng.uniform(*FLAT_COLOURS, size=3), (size, size, 3))
    elif source == "photo":
        image = _photo(rng, size)
    else:
        image = _pattern(rng, size)
    return np.clip(image * 255 + 0.5, 0, 255).astype(np.uint8)


def _photo(rng: np.random.Generator, size: int) -> np.ndarray:
    """A training photograph: 1–4 copies per repeat, a cyclic offset, then contrast (× 0.4–1.4 about
    its mean), saturation (0–1.2) and a brightness and tint (each channel × 0.45–1.15)."""
    name = BROAD_PHOTOS[int(rng.integers(len(BROAD_PHOTOS)))]
    copies = int(rng.choice(SCALES))
    tiled = np.tile(photo(name, None, -(-size // copies)), (copies, copies, 1))[:size, :size]
    tiled = np.roll(tiled, tuple(rng.integers(0, size, size=2)), axis=(0, 1))
    grey = tiled.mean(axis=2, keepdims=True)
    tiled = grey + rng.uniform(0.0, 1.2) * (tiled - grey)
    mean = tiled.mean()
    tiled = mean + rng.uniform(0.4, 1.4) * (tiled - mean)
    return tiled * rng.uniform(0.45, 1.15, size=3)


def _pattern(rng: np.random.Generator, size: int) -> np.ndarray:
    """A procedural pattern at drawn settings, maybe turned a quarter (walls: upright or lying
    features), mapped between two random colours pulled together by a contrast of 0.15–1."""
    pattern = PATTERNS[int(rng.integers(len(PATTERNS)))]
    values = GENERATORS[pattern.kind](rng, size, **pattern.draw(rng))
    if rng.random() < 0.5:
        values = values.T
    low, high = rng.uniform(0.0, 1.0, size=(2, 3))
    middle = (low + high) / 2
    contrast = rng.uniform(0.15, 1.0)
    low, high = middle + contrast * (low - middle), middle + contrast * (high - middle)
    return low + values[..., None] * (high - low)
