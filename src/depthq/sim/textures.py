"""Texture banks of the textured looks (docs/design.md#looks): real photographs that scikit-image
ships inside its wheel, procedural patterns seeded by the canyon, or a user's folder of images.

A source image of any mode and bit depth is read as it looks (`rgb8`: 16-bit grey scaled, transparency
over white); a user's image over `MAX_PIXELS` is refused when its folder is named as a look, before
any work. A texture is a square uint8 RGB image that tiles: MuJoCo repeats it every `TEXTURE_METRES` m on the
walls, pillars and floor (`depthq.sim.mjcf`). `draw_texture` picks a source from a bank and draws its
scale (how many copies of the source fill one repeat), offset (a cyclic shift) and tint.

The training bank (`textured`) and the held-out bank (`heldout`) share no photograph and no
generator setting: the held-out patterns are other generators altogether.
"""

from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from PIL import Image, ImageOps

from depthq.checksum import file_sha256
from depthq.errors import ConfigError

TEXTURE_SIZE = 128  # pixels a side of every texture: 64 px per metre (256 costs ×1.3 per frame)
TEXTURE_METRES = 2.0  # one texture repeat spans this many metres of wall or floor
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
# Copies of the source across one repeat: the source spans 2, 1, 0.67 or 0.5 m.
SCALES = (1, 2, 3, 4)
# The largest source image a look folder may hold: Pillow's decompression-bomb threshold (89.5 MP, a
# 50 MP phone photograph passes); a larger one would take seconds and gigabytes to decode per worker,
# for a texture of TEXTURE_SIZE pixels a side.
MAX_PIXELS = Image.MAX_IMAGE_PIXELS
_SIXTEEN_BIT = ("I;16", "I;16L", "I;16B", "I;16N", "I")  # Pillow's modes of 16-bit grey (PNG, TIFF)
_ALPHA = ("RGBA", "LA", "PA", "RGBa", "La")


@dataclass(frozen=True)
class Generator:
    """A procedural pattern: `kind` (a function of `GENERATORS`) and its fixed parameters."""

    kind: str
    params: tuple[tuple[str, float], ...]

    def render(self, rng: np.random.Generator, size: int) -> np.ndarray:
        """A float32 (size, size) pattern in [0, 1] that tiles."""
        return GENERATORS[self.kind](rng, size, **dict(self.params))


@dataclass(frozen=True)
class TextureBank:
    """Where a look's textures come from: photographs (file names inside scikit-image's data module,
    or paths of a user's images) and procedural generators."""

    name: str
    photos: tuple[str, ...] = ()
    generators: tuple[Generator, ...] = ()
    folder: str | None = None  # photos are paths of this folder's images (a user's bank)

    def __post_init__(self) -> None:
        if not self.photos and not self.generators:
            raise ConfigError(f"texture bank {self.name!r} holds no image and no generator")

    @property
    def size(self) -> int:
        return len(self.photos) + len(self.generators)


def _coords(size: int) -> tuple[np.ndarray, np.ndarray]:
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size
    return y, x


def periodic_noise(rng: np.random.Generator, size: int, beta: float, stretch: float = 1.0) -> np.ndarray:
    """Noise with a 1/f^beta power spectrum, periodic by construction (FFT-filtered white noise);
    `stretch` > 1 draws it out along the rows (grain), < 1 along the columns."""
    f = np.fft.fftfreq(size)
    radius = np.sqrt((f[:, None] / stretch) ** 2 + (f[None, :] * stretch) ** 2)
    radius[0, 0] = 1.0
    spectrum = np.fft.fft2(rng.standard_normal((size, size))) / radius ** (beta / 2)
    spectrum[0, 0] = 0.0
    out = np.real(np.fft.ifft2(spectrum))
    return _normalise(out)


def _normalise(a: np.ndarray) -> np.ndarray:
    lo, hi = np.percentile(a, (1, 99))
    return np.clip((a - lo) / max(hi - lo, 1e-9), 0, 1).astype(np.float32)


def _bricks(rng: np.random.Generator, size: int, rows: float, cols: float, mortar: float) -> np.ndarray:
    """Running-bond bricks: `rows` × `cols` per tile, each brick's shade jittered, mortar lines."""
    rows, cols = int(rows), int(cols)
    y, x = _coords(size)
    r = np.floor(y * rows).astype(int)
    xs = x * cols + 0.5 * (r % 2)
    c = np.floor(xs).astype(int) % cols
    shade = rng.uniform(0.55, 1.0, size=(rows, cols))[r, c]
    fy, fx = y * rows - r, xs - np.floor(xs)
    joint = (fy < mortar * rows) | (fx < mortar * cols)
    grain = 0.15 * periodic_noise(rng, size, 1.0)
    return np.clip(np.where(joint, 0.2, shade) + grain - 0.07, 0, 1).astype(np.float32)


def _stripes(rng: np.random.Generator, size: int, period: float, duty: float) -> np.ndarray:
    """Stripes across the tile (`period` of them), of a `duty` fraction, worn by noise."""
    _, x = _coords(size)
    band = ((x * period) % 1.0 < duty).astype(np.float32)
    return np.clip(0.25 + 0.6 * band + 0.2 * (periodic_noise(rng, size, 1.5) - 0.5), 0, 1)


def _wood(rng: np.random.Generator, size: int, rings: float, turbulence: float) -> np.ndarray:
    """Wood grain: `rings` bands along the tile, bent by `turbulence` × low-frequency noise."""
    _, x = _coords(size)
    warp = periodic_noise(rng, size, 3.0)
    v = 0.5 + 0.5 * np.sin(2 * np.pi * (rings * x + turbulence * warp))
    return (0.35 + 0.5 * v**3 + 0.15 * periodic_noise(rng, size, 0.8)).clip(0, 1).astype(np.float32)


def _marble(rng: np.random.Generator, size: int, veins: float, turbulence: float) -> np.ndarray:
    """Marble: diagonal veins (`veins` per tile) warped by noise."""
    y, x = _coords(size)
    warp = periodic_noise(rng, size, 2.2)
    v = np.abs(np.sin(np.pi * (veins * (x + y) + turbulence * warp)))
    return (0.3 + 0.7 * v**0.3).astype(np.float32)


def _tiles(rng: np.random.Generator, size: int, count: float, grout: float) -> np.ndarray:
    """Square tiles, `count` a side, in two shades, with grout lines `grout` of a tile wide."""
    count = int(count)
    y, x = _coords(size)
    i, j = np.floor(y * count).astype(int), np.floor(x * count).astype(int)
    shade = rng.uniform(0.5, 1.0, size=(count, count))[i, j]
    line = ((y * count) % 1.0 < grout) | ((x * count) % 1.0 < grout)
    return np.where(line, 0.15, shade).astype(np.float32)


def _dots(rng: np.random.Generator, size: int, count: float, radius: float) -> np.ndarray:
    """A grid of `count` × `count` dots of `radius` (of a cell) on a mottled ground."""
    y, x = _coords(size)
    fy, fx = (y * count) % 1.0 - 0.5, (x * count) % 1.0 - 0.5
    dot = (fy**2 + fx**2) < radius**2
    ground = 0.65 + 0.25 * periodic_noise(rng, size, 2.8)
    return np.where(dot, 0.1, ground).astype(np.float32)


def _cells(rng: np.random.Generator, size: int, count: float, edge: float) -> np.ndarray:
    """Irregular stones: the Voronoi cells of a jittered `count` × `count` grid of points (wrapped, so
    it tiles), each its own shade, with dark joints where two cells meet within `edge` of a cell."""
    count = int(count)
    y, x = _coords(size)
    points = rng.uniform(0.1, 0.9, size=(count * count, 2)).astype(np.float32)
    shades = rng.uniform(0.4, 1.0, size=count * count)
    y, x = y * count, x * count  # in cells
    cy, cx = np.floor(y).astype(int), np.floor(x).astype(int)
    nearest = np.full((size, size), np.inf, np.float32)
    second = np.full((size, size), np.inf, np.float32)
    shade = np.zeros((size, size), np.float32)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            i, j = cy + di, cx + dj
            cell = (i % count) * count + j % count
            d = np.sqrt((y - i - points[cell, 0]) ** 2 + (x - j - points[cell, 1]) ** 2)
            closer = d < nearest
            second = np.where(closer, nearest, np.minimum(second, d))
            shade = np.where(closer, shades[cell], shade)
            nearest = np.minimum(nearest, d)
    grain = 0.12 * periodic_noise(rng, size, 1.2)
    return np.clip(np.where(second - nearest < edge, 0.15, shade) + grain - 0.06, 0, 1).astype(np.float32)


def _waves(rng: np.random.Generator, size: int, count: float, frequency: float, sharpness: float
           ) -> np.ndarray:
    """`count` plane waves of up to `frequency` periods per tile, each in its own direction (whole
    periods, so it tiles), summed and shaped by `sharpness` (< 1 soft, > 1 crisp bands)."""
    y, x = _coords(size)
    k = int(frequency)
    total = np.zeros((size, size), np.float32)
    for _ in range(int(count)):
        a, b = 0, 0
        while a == 0 and b == 0:
            a, b = (int(v) for v in rng.integers(-k, k + 1, size=2))
        total += np.sin(2 * np.pi * (a * x + b * y) + rng.uniform(0, 2 * np.pi))
    v = total / int(count)
    return (0.5 + 0.5 * np.sign(v) * np.abs(v) ** (1 / sharpness)).astype(np.float32)


def _plaid(rng: np.random.Generator, size: int, bands: float, mix: float) -> np.ndarray:
    """Tartan: `bands` bands of random widths and shades across the tile and as many along it,
    crossed (`mix` of the one, the rest of the other)."""
    def profile() -> np.ndarray:
        edges = np.sort(rng.integers(0, size, size=int(bands)))
        shades = rng.uniform(0.0, 1.0, size=int(bands))
        return shades[np.searchsorted(edges, np.arange(size), side="right") % int(bands)]
    return (mix * profile()[None, :] + (1 - mix) * profile()[:, None]).astype(np.float32)


GENERATORS = {
    "noise": periodic_noise, "bricks": _bricks, "stripes": _stripes, "wood": _wood,
    "marble": _marble, "tiles": _tiles, "dots": _dots, "cells": _cells, "waves": _waves, "plaid": _plaid,
}


def _gen(kind: str, **params: float) -> Generator:
    return Generator(kind, tuple(sorted(params.items())))


# The training bank: scikit-image's texture photographs (brick, gravel) and pictures that pass for
# posters, plus four generators.
TRAINING_BANK = TextureBank(
    "textured",
    photos=("brick.png", "gravel.png", "camera.png", "coffee.png", "astronaut.png", "page.png", "coins.png"),
    generators=(
        _gen("noise", beta=1.6), _gen("noise", beta=2.4),
        _gen("bricks", rows=8, cols=4, mortar=0.012), _gen("bricks", rows=16, cols=4, mortar=0.01),
        _gen("stripes", period=8, duty=0.5), _gen("stripes", period=4, duty=0.3),
        _gen("wood", rings=6, turbulence=0.8), _gen("wood", rings=12, turbulence=0.4),
    ),
)
# The held-out bank: other photographs, other generators (no setting shared with the training bank).
HELDOUT_BANK = TextureBank(
    "heldout",
    photos=("grass.png", "chelsea.png", "rocket.jpg", "text.png", "moon.png", "hubble_deep_field.jpg",
            "color.png"),
    generators=(
        _gen("marble", veins=2, turbulence=1.2), _gen("marble", veins=4, turbulence=0.6),
        _gen("tiles", count=4, grout=0.04), _gen("tiles", count=8, grout=0.06),
        _gen("dots", count=8, radius=0.3), _gen("dots", count=4, radius=0.2),
    ),
)


def folder_bank(folder: str | Path) -> TextureBank:
    """A user's folder of images as a bank: every image file directly in it (sorted by name), each
    checked to be at most `MAX_PIXELS`."""
    path = Path(folder)
    if not path.is_dir():
        raise ConfigError(f"look {str(folder)!r}: not a look name nor a folder")
    images = sorted(p.name for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not images:
        raise ConfigError(f"look folder {str(folder)!r} holds no image ({', '.join(IMAGE_SUFFIXES)})")
    for name in images:
        stat = (path / name).stat()
        _check_size(str(path.resolve() / name), stat.st_mtime_ns, stat.st_size)
    return TextureBank(f"folder:{path.resolve()}", photos=tuple(images), folder=str(path.resolve()))


def folder_checksums(bank: TextureBank) -> dict[str, str]:
    """The SHA-256 of each image of a folder's bank, by file name (a dataset's manifest records them)."""
    if bank.folder is None:
        raise ConfigError(f"texture bank {bank.name!r} is not a folder of images")
    return {name: file_sha256(Path(bank.folder) / name) for name in bank.photos}


@functools.lru_cache(maxsize=1024)
def _check_size(path: str, mtime_ns: int, size: int) -> None:
    """A ConfigError naming the image at `path` if it is over `MAX_PIXELS` (its header read; once per
    version of the file, which `mtime_ns` and `size` tell apart)."""
    limit = f"the limit of {MAX_PIXELS / 1e6:.1f} MP for a texture source ({TEXTURE_SIZE} px a side " \
            "is what a texture keeps): shrink it or move it out of the look folder"
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as image:
                width, height = image.size
    except Image.DecompressionBombError:
        over = 2 * MAX_PIXELS / 1e6
        raise ConfigError(f"texture image {path!r}: over {over:.1f} MP, over {limit}") from None
    except (OSError, ValueError) as err:
        raise ConfigError(f"texture image {path!r} cannot be read ({err})") from err
    if width * height > MAX_PIXELS:
        raise ConfigError(f"texture image {path!r}: {width} × {height} pixels "
                          f"({width * height / 1e6:.1f} MP), over {limit}")


def rgb8(image: Image.Image) -> Image.Image:
    """`image` as 8-bit RGB, as an image viewer shows it: turned by its EXIF orientation, 16-bit grey
    scaled to 8 bits (÷ 257; Pillow's own conversion clips it, white), float grey in [0, 1] scaled to
    255 (larger values taken as 8-bit levels), transparency over white; every other mode (L, 1, P,
    CMYK, YCbCr, RGB of 16 bits, which Pillow reads as 8) by Pillow's conversion."""
    image = ImageOps.exif_transpose(image)
    if image.mode in _SIXTEEN_BIT or image.mode == "F":
        values = np.asarray(image, np.float64)
        if image.mode in _SIXTEEN_BIT:
            values = values / 257.0
        elif values.size and np.nanmax(values) <= 1.0:
            values = values * 255.0
        grey = np.clip(np.rint(np.nan_to_num(values)), 0, 255).astype(np.uint8)
        return Image.fromarray(grey).convert("RGB")
    if image.mode in _ALPHA or "transparency" in image.info:
        rgba = image.convert("RGBA")
        return Image.alpha_composite(Image.new("RGBA", rgba.size, (255, 255, 255, 255)), rgba).convert("RGB")
    return image.convert("RGB")


def photo(name: str, folder: str | None = None, size: int = TEXTURE_SIZE) -> np.ndarray:
    """A photograph as float32 (size, size, 3) in [0, 1]: its centre square, resized. Without `folder`,
    a file inside scikit-image's installed data module (read as a file: never a download)."""
    square = _square(name, folder)
    if size != TEXTURE_SIZE:
        square = square.resize((size, size), Image.Resampling.BILINEAR)
    return np.asarray(square, np.float32) / 255.0


@functools.lru_cache(maxsize=256)
def _square(name: str, folder: str | None) -> Image.Image:
    """A photograph's centre square at TEXTURE_SIZE, decoded once per process."""
    if folder is None:
        try:
            path = resources.files("skimage") / "data" / name
        except ModuleNotFoundError as err:
            raise ConfigError(
                "the textured looks' photographs come with scikit-image: pip install scikit-image"
            ) from err
    else:
        path = Path(folder) / name
    try:
        with path.open("rb") as f, Image.open(f) as image:
            rgb = rgb8(image)
    except (OSError, ValueError, Image.DecompressionBombError) as err:
        raise ConfigError(f"texture image {str(path)!r} cannot be read ({err})") from err
    w, h = rgb.size
    side = min(w, h)
    box = ((w - side) // 2, (h - side) // 2, (w - side) // 2 + side, (h - side) // 2 + side)
    return rgb.crop(box).resize((TEXTURE_SIZE, TEXTURE_SIZE), Image.Resampling.LANCZOS)


def draw_texture(bank: TextureBank, rng: np.random.Generator, size: int = TEXTURE_SIZE) -> np.ndarray:
    """One texture of `bank`: a random source at a random scale (copies per repeat), offset and tint;
    uint8 (size, size, 3)."""
    k = int(rng.integers(bank.size))
    copies = int(rng.choice(SCALES))
    cell = -(-size // copies)
    if k < len(bank.photos):
        source = photo(bank.photos[k], bank.folder, cell)
    else:
        pattern = bank.generators[k - len(bank.photos)].render(rng, cell)
        low, high = rng.uniform(0.1, 0.5, size=3), rng.uniform(0.6, 1.0, size=3)
        source = low + pattern[..., None] * (high - low)
    tiled = np.tile(source, (copies, copies, 1))[:size, :size]
    tiled = np.roll(tiled, tuple(rng.integers(0, size, size=2)), axis=(0, 1))
    tint = rng.uniform(0.6, 1.0, size=3)
    return np.clip(tiled * tint * 255 + 0.5, 0, 255).astype(np.uint8)
