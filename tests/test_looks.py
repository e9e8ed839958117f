"""Looks apart from geometry and the robot camera model, rendered by real MuJoCo at small sizes."""

import hashlib
import json
import shutil
from dataclasses import replace

import numpy as np
import pytest
from PIL import Image

from depthq.cli import main
from depthq.data.manifest import Dataset, upgrade_config
from depthq.errors import ConfigError
from depthq.sim.camera_model import ImagingConfig
from depthq.sim.env import CanyonEnv, EnvConfig
from depthq.sim.look import HELDOUT_LIGHT, TRAINING_LIGHT, upgrade_world
from depthq.sim.mjcf import CameraConfig
from depthq.sim.textures import HELDOUT_BANK, TRAINING_BANK, draw_texture, photo
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
