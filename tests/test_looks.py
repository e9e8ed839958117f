"""Looks apart from geometry and the robot camera model, rendered by real MuJoCo at small sizes."""

import hashlib
import json
import shutil
import struct
import zlib
from dataclasses import replace

import numpy as np
import pytest
from PIL import Image

from depthq.cli import main
from depthq.data.manifest import Dataset, upgrade_config
from depthq.errors import ConfigError
from depthq.sim.broad import BROAD_PHOTOS, PATTERNS, draw_broad_texture
from depthq.sim.camera_model import ImagingConfig
from depthq.sim.env import CanyonEnv, EnvConfig
from depthq.sim.look import (
    BROAD_IMAGING,
    BROAD_LIGHT,
    HELDOUT_LIGHT,
    SKY_JITTER,
    SURFACES,
    TRAINING_LIGHT,
    draw_canyon_look,
    imaging,
    upgrade_world,
)
from depthq.sim.mjcf import CameraConfig
from depthq.sim.textures import GENERATORS, HELDOUT_BANK, TRAINING_BANK, draw_texture, folder_bank, photo
from depthq.sim.world import WorldConfig, world_for

SMALL = CameraConfig(width=80, height=60)
# Recorded from the code before looks existed (main at 166244c): 5 steps of fixed actions, seed 3, in
# each family's own look (then `appearance` default and randomized), the observations' images and
# scans hashed, and the last render's hash. Flat and colours must reproduce them byte for byte.
BEFORE = {
    "eval:0": ("3daf56b542ed4073", "ed7e27f3f1294142"),
    "hard/eval:0": ("3e518ea5902fc94a", "ea0e084b1763dd38"),
}


def _world(family: str, look: str | None = None, **kw) -> WorldConfig:
    world = world_for(WorldConfig(camera=SMALL), family)
    return replace(world, **({"look": look} if look else {}), **kw)


def _drive(world: WorldConfig, canyon: str, actions=(0.0, 0.5, -1.0, 1.0, 0.2)):
    """(hash of observations, hash of last render, last image, ray casts) of a short fixed drive."""
    env = CanyonEnv(EnvConfig(world=world))
    try:
        h, scans = hashlib.sha256(), []
        obs, _ = env.reset(seed=3, options={"canyon": canyon})
        for a in actions:
            h.update(obs["image"].tobytes())
            h.update(obs["scan"].tobytes())
            scans.append(env.world.last_raycast.copy())  # noise-free: the geometry the LiDAR sees
            obs, *_ = env.step(np.array([a], np.float32))
        h.update(obs["image"].tobytes())
        render = hashlib.sha256(env.world.render().tobytes()).hexdigest()[:16]
        return h.hexdigest()[:16], render, obs["image"].copy(), np.array(scans)
    finally:
        env.close()


@pytest.mark.parametrize("canyon, look", [("eval:0", "flat"), ("hard/eval:0", "colours")])
def test_flat_and_colours_are_byte_identical_to_before(canyon, look):
    family = "hard" if canyon.startswith("hard") else "paper"
    assert world_for(WorldConfig(), family).look == look  # the family's own look is its default
    observed, render, _, _ = _drive(_world(family), canyon)
    assert (observed, render) == BEFORE[canyon]


def test_textured_looks_keep_the_lidar_and_are_deterministic():
    _, _, colours, scans = _drive(_world("hard", "colours"), "hard/val:1000")
    first = _drive(_world("hard", "textured"), "hard/val:1000")
    again = _drive(_world("hard", "textured"), "hard/val:1000")
    held = _drive(_world("hard", "heldout"), "hard/val:1000")
    np.testing.assert_array_equal(first[3], scans)  # the geometry the LiDAR sees: untouched
    np.testing.assert_array_equal(held[3], scans)
    assert first[:2] == again[:2]  # same canyon, same seed: the same frames
    np.testing.assert_array_equal(first[2], again[2])
    for other in (colours, held[2]):
        assert np.abs(first[2].astype(int) - other.astype(int)).mean() > 5


def test_banks_are_disjoint_and_photos_ship_with_scikit_image():
    assert not set(TRAINING_BANK.photos) & set(HELDOUT_BANK.photos)
    assert not set(TRAINING_BANK.generators) & set(HELDOUT_BANK.generators)
    assert not {g.kind for g in TRAINING_BANK.generators} & {g.kind for g in HELDOUT_BANK.generators}
    for name in (*TRAINING_BANK.photos, *HELDOUT_BANK.photos):  # files inside the wheel: no download
        assert photo(name, size=8).shape == (8, 8, 3)
    for field in ("elevation_deg", "strength", "ambient", "kelvin"):  # held-out light outside training's
        (lo, hi), = getattr(TRAINING_LIGHT, field)
        assert all(b < lo or a > hi for a, b in getattr(HELDOUT_LIGHT, field))
    assert not set(TRAINING_LIGHT.skies) & set(HELDOUT_LIGHT.skies)
    texture = draw_texture(TRAINING_BANK, np.random.default_rng(0), 64)
    assert texture.shape == (64, 64, 3) and texture.dtype == np.uint8 and texture.std() > 1


def _flat(texture: np.ndarray) -> bool:
    return bool((texture == texture[:1, :1]).all())


def _inside(value: float, ranges) -> bool:
    return any(lo <= value <= hi for lo, hi in ranges)


def test_the_broad_look_draws_nothing_held_out_and_widens_training():
    # no held-out photograph, no held-out generator kind; the training photographs all
    assert set(BROAD_PHOTOS) == set(TRAINING_BANK.photos) and not set(BROAD_PHOTOS) & set(HELDOUT_BANK.photos)
    kinds = {p.kind for p in PATTERNS}
    assert not kinds & {g.kind for g in HELDOUT_BANK.generators} and kinds <= set(GENERATORS)
    assert {g.kind for g in TRAINING_BANK.generators} < kinds  # training's kinds and more
    for field in ("elevation_deg", "strength", "ambient", "kelvin"):
        broad, held = getattr(BROAD_LIGHT, field), getattr(HELDOUT_LIGHT, field)
        assert all(b < lo or a > hi for a, b in broad for lo, hi in held), field  # disjoint intervals
        (lo, hi), = getattr(TRAINING_LIGHT, field)
        below, above = min(a for a, _ in broad), max(b for _, b in broad)
        assert below < lo and above > hi, field  # wider than training on both sides
        assert _inside(lo, broad) and _inside(hi, broad) and _inside((lo + hi) / 2, broad), field
    j_lo, j_hi = SKY_JITTER
    for sky in BROAD_LIGHT.skies:  # no sky colour a held-out sky can take, however jittered
        for held in HELDOUT_LIGHT.skies:
            for mine, theirs in zip(sky, held, strict=True):
                assert any(j_hi * a < j_lo * b or j_lo * a > j_hi * b
                           for a, b in zip(mine, theirs, strict=True))
    assert set(TRAINING_LIGHT.skies) < set(BROAD_LIGHT.skies)
    default = ImagingConfig()  # the textured look's camera ranges: every one widened or kept
    for name in ("ae_target", "ae_rate", "vignetting", "exposure_ms", "noise_scale", "jpeg_quality"):
        (a, b), (lo, hi) = getattr(BROAD_IMAGING, name), getattr(default, name)
        assert a <= lo and b >= hi and b - a > hi - lo, name
    assert BROAD_IMAGING.wb_offset > default.wb_offset and BROAD_IMAGING.wb_drift > default.wb_drift
    assert imaging("textured", default) == default and imaging("broad", default) == BROAD_IMAGING
    mine = ImagingConfig(vignetting=(0.1, 0.2))  # a range set by the user wins in the broad look
    assert imaging("broad", mine) == replace(BROAD_IMAGING, vignetting=(0.1, 0.2))


def test_broad_textures_are_flat_or_textured_and_all_differ():
    textures = [draw_broad_texture(np.random.default_rng(seed), 64) for seed in range(40)]
    assert all(t.shape == (64, 64, 3) and t.dtype == np.uint8 for t in textures)
    flat = [_flat(t) for t in textures]
    assert 3 <= sum(flat) <= 20  # a quarter flat, the rest textured
    assert len({t.tobytes() for t in textures}) == len(textures)


def test_the_broad_look_is_deterministic_per_canyon_and_mixes_flat_and_textured_surfaces():
    looks = [draw_canyon_look("broad", np.random.default_rng(seed)) for seed in range(12)]
    again = draw_canyon_look("broad", np.random.default_rng(5))
    for surface in SURFACES:
        np.testing.assert_array_equal(looks[5].textures[surface], again.textures[surface])
    flat = {(k, s) for k, look in enumerate(looks) for s in SURFACES if _flat(look.textures[s])}
    for surface in ("left", "floor"):  # flat in some canyons, textured in others
        assert 0 < sum((k, surface) in flat for k in range(len(looks))) < len(looks)
    looks += [draw_canyon_look("broad", np.random.default_rng(seed)) for seed in range(12, 150)]
    for look in looks:  # the light: never a held-out value
        assert _inside(float(look.ambient), BROAD_LIGHT.ambient)
        assert not _inside(float(look.ambient), HELDOUT_LIGHT.ambient)
        elevation = np.degrees(np.arcsin(-look.sun_dir[2]))
        assert _inside(elevation, BROAD_LIGHT.elevation_deg)
        assert not _inside(elevation, HELDOUT_LIGHT.elevation_deg)
    # uniform over the union: training's middle interval (0.53 of its length) keeps its share, not 1/3
    middle = np.mean([_inside(float(look.ambient), BROAD_LIGHT.ambient[1:2]) for look in looks])
    assert 0.42 < middle < 0.65
    # real frames: the same canyon twice alike, two canyons apart, the LiDAR's geometry untouched
    first = _drive(_world("hard", "broad"), "hard/val:1000", actions=(0.0, 0.5))
    same = _drive(_world("hard", "broad"), "hard/val:1000", actions=(0.0, 0.5))
    other = _drive(_world("hard", "broad"), "hard/val:1001", actions=(0.0, 0.5))
    textured = _drive(_world("hard", "textured"), "hard/val:1000", actions=(0.0, 0.5))
    assert first[:2] == same[:2]
    np.testing.assert_array_equal(first[3], textured[3])
    for image in (other[2], textured[2]):
        assert np.abs(first[2].astype(int) - image.astype(int)).mean() > 5
    env = CanyonEnv(EnvConfig(world=_world("hard", "broad")))
    try:
        env.reset(seed=1, options={"canyon": "hard/val:1000"})
        camera = env.world.robot_camera
        assert camera is not None and 4 <= camera.exposure_s * 1000 <= 50  # the broad camera's ranges
    finally:
        env.close()


def test_a_folder_of_images_is_a_look(tmp_path):
    rng = np.random.default_rng(7)
    for k in range(3):  # a user's "photographs": coarse random blocks, nothing like the built-in banks
        blocks = rng.integers(0, 256, size=(4, 4, 3), dtype=np.uint8)
        Image.fromarray(np.kron(blocks, np.ones((16, 16, 1), np.uint8))).save(tmp_path / f"wall{k}.png")
    (tmp_path / "notes.txt").write_text("not an image")
    own = _drive(_world("hard", str(tmp_path)), "hard/val:1001", actions=(0.0,))[2]
    for look in ("textured", "heldout"):
        built_in = _drive(_world("hard", look), "hard/val:1001", actions=(0.0,))[2]
        assert np.abs(own.astype(int) - built_in.astype(int)).mean() > 5
    with pytest.raises(ConfigError, match=f"the folder {tmp_path / 'missing'} does not exist"):
        WorldConfig(look=str(tmp_path / "missing"))
    with pytest.raises(ConfigError, match="is a file"):
        WorldConfig(look=str(tmp_path / "notes.txt"))
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ConfigError, match="holds no image"):
        WorldConfig(look=str(empty))


def test_camera_model_is_off_in_flat_and_blurs_with_the_yaw_rate():
    assert not ImagingConfig().on(textured=False) and ImagingConfig().on(textured=True)
    with pytest.raises(ConfigError, match="jpeg_quality"):
        ImagingConfig(jpeg_quality=(90, 80))
    env = CanyonEnv(EnvConfig(world=_world("hard", "textured")))
    try:
        env.reset(seed=1, options={"canyon": "hard/val:1000"})
        camera = env.world.robot_camera
        assert camera is not None and camera.quality is None  # the recorder's JPEG is the camera's
        assert camera.blur_px(0.0) == 0 and camera.blur_px(1.0) > camera.blur_px(0.5) > 0
        frame = env.world.render().copy()
        still = camera.expose(frame, 0.0).copy()
        turning = camera.expose(frame, 20.0)
        # a horizontal blur: neighbouring columns grow alike, rows barely change
        assert np.abs(np.diff(turning, axis=1)).mean() < 0.7 * np.abs(np.diff(still, axis=1)).mean()
    finally:
        env.close()


def test_records_written_before_looks_read_appearance_as_look(small_dataset, tmp_path):
    assert upgrade_world({"appearance": "randomized", "speed": 0.5}) == {"look": "colours", "speed": 0.5}
    config = {"env": {"world": {"appearance": "default"}}, "runs": 3}
    assert upgrade_config(config) == {"env": {"world": {"look": "flat"}}, "runs": 3}
    old = tmp_path / "data"  # a dataset whose manifest was written before looks: appearance, no look
    shutil.copytree(small_dataset, old, ignore=shutil.ignore_patterns("features"))
    manifest = json.loads((old / "manifest.json").read_text())
    world = manifest["config"]["env"]["world"]
    assert world.pop("look") == "flat"
    world["appearance"] = "default"
    (old / "manifest.json").write_text(json.dumps(manifest))
    dataset = Dataset.open(old)
    upgraded = dataset.config["env"]["world"]
    assert upgraded["look"] == "flat" and "appearance" not in upgraded
    resumed = Dataset.create(old, Dataset.open(small_dataset).config, dataset.seed)  # the same collection
    assert resumed.fingerprint() == Dataset.open(small_dataset).fingerprint()


def test_a_bad_look_is_exit_status_2_naming_it(tmp_path, capsys):
    for argv in (["drive", "--look", "neon"], ["bench", "sim", "--look", "colours,neon", "--steps", "1"],
                 ["collect", "--look", "neon", "--runs", "1"], ["evaluate", "heuristic", "--look", "neon"]):
        assert main([*argv, "--out", str(tmp_path / "o")] if argv[0] != "bench" else argv) == 2, argv
        assert "neon" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_bench_sim_measures_several_looks_in_one_call(capsys):
    argv = ["bench", "sim", "--family", "hard", "--look", "textured,broad", "--steps", "3", "--json"]
    assert main(argv) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert set(result["looks"]) == {"textured", "broad"} and result["relative"]["textured"] == 1.0
    assert all(e["steps"] == 3 and e["steps_per_s"] > 0 for e in result["looks"].values())


def test_images_of_any_mode_and_bit_depth_are_textures_as_they_look(tmp_path):
    """A 16-bit PNG is scaled to 8 bits (Pillow's own conversion clips it: white), and every other mode
    keeps its mean grey; transparency shows the white behind it."""
    rng = np.random.default_rng(5)
    blocks = rng.integers(2000, 63000, size=(8, 8))  # a 16-bit "photograph": coarse blocks, mean ≈ 0.5
    sixteen = np.kron(blocks, np.ones((32, 32), np.int64)).astype(np.uint16)
    Image.fromarray(sixteen).save(tmp_path / "sixteen.png")
    assert Image.open(tmp_path / "sixteen.png").mode == "I;16"
    grey = Image.fromarray((sixteen // 257).astype(np.uint8))
    variants = {"la.png": grey.convert("LA"), "p.png": grey.convert("RGB").convert("P"),
                "cmyk.jpg": grey.convert("CMYK"), "one.png": grey.convert("1"),
                "f.tif": Image.fromarray(sixteen.astype(np.float32) / 65535),
                "rgba.png": grey.convert("RGBA")}
    for name, image in variants.items():
        image.save(tmp_path / name)
    clear = grey.convert("RGBA")
    clear.putalpha(0)  # wholly transparent: white, whatever colour lies under it
    clear.save(tmp_path / "clear.png")
    bank = folder_bank(tmp_path)
    source = sixteen.mean() / 65535
    for name in ("sixteen.png", *variants):
        texture = photo(name, bank.folder)
        assert texture.shape == (128, 128, 3) and abs(texture.mean() - source) < 0.03, (name, texture.mean())
    assert photo("clear.png", bank.folder).min() == 1.0
    frame = _drive(_world("hard", str(tmp_path)), "hard/val:1001", actions=(0.0,))[2]
    assert 0.05 < frame.mean() / 255 < 0.95  # not washed out


def _png_header(width: int, height: int) -> bytes:
    """A PNG file that says it is `width` × `height` (grey, 8 bits) but holds no pixel: Pillow reads
    the size from the header alone."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    pixels = chunk(b"IDAT", zlib.compress(b""))
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + pixels + chunk(b"IEND", b"")


@pytest.mark.parametrize("side, said", [(10000, "10000 × 10000 pixels"), (14000, "over 179.0 MP")])
def test_an_oversized_image_is_refused_in_one_line_before_any_work(tmp_path, capsys, side, said):
    folder = tmp_path / "look"
    folder.mkdir()
    Image.fromarray(np.full((64, 64, 3), 128, np.uint8)).save(folder / "fine.png")
    (folder / "huge.png").write_bytes(_png_header(side, side))  # over Pillow's decompression-bomb limit
    out = tmp_path / "data"
    argv = ["collect", "--look", str(folder), "--runs", "1", "--val-runs", "0", "--out", str(out)]
    assert main(argv) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "huge.png" in lines[0] and said in lines[0] and "89.5 MP" in lines[0]
    assert not out.exists()  # no manifest with an empty runs/
