"""The canyon world in real MuJoCo: geometry, driving, LiDAR, camera, termination, env checker."""

import json
import math
import subprocess
import sys

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import depthq.sim
from depthq.errors import ConfigError
from depthq.sim.canyon import CanyonConfig, CanyonId, eval_canyon_ids, generate_canyon
from depthq.sim.env import CanyonEnv, EnvConfig
from depthq.sim.mjcf import CameraConfig
from depthq.sim.sensors import LidarConfig
from depthq.sim.world import CanyonWorld, WorldConfig

TEN_HZ = WorldConfig(decision_hz=10.0)  # the step counts below are written for 0.1 s decisions
NOISELESS = WorldConfig(
    lidar=LidarConfig(noise_std=0.0), camera=CameraConfig(noise_std=0.0), decision_hz=10.0
)


@pytest.fixture(scope="module")
def env():
    e = CanyonEnv(EnvConfig(world=TEN_HZ))
    yield e
    e.close()


@pytest.fixture(scope="module")
def world():
    w = CanyonWorld(NOISELESS, render=False)
    yield w
    w.close()


def test_canyon_follows_the_spec():
    c = generate_canyon(CanyonId("eval", 0))
    assert c.left.shape == (152, 2)  # back-wall extension + 150 pieces
    np.testing.assert_allclose(c.left[1], (-1.5, 0.0))
    np.testing.assert_allclose(c.right - c.left, np.tile([3.0, 0.0], (152, 1)))
    lengths = np.linalg.norm(np.diff(c.left[1:], axis=0), axis=1)
    assert lengths.min() >= 0.3 and lengths.max() <= 0.7
    assert np.all(np.diff(c.left[1:, 1]) > 0)  # |α| < 90° always heads forward
    assert c.back[0, 1] == -2.0


def test_same_id_same_canyon_and_streams_are_disjoint():
    a, b = generate_canyon(CanyonId("train", 5)), generate_canyon(CanyonId("train", 5))
    np.testing.assert_array_equal(a.left, b.left)
    train = {generate_canyon(CanyonId("train", i)).left.tobytes() for i in range(40)}
    val = {generate_canyon(CanyonId("val", i)).left.tobytes() for i in range(40)}
    evals = {generate_canyon(c).left.tobytes() for c in eval_canyon_ids()}
    assert len(train) == 40 and len(evals) == 20
    assert not (train & evals) and not (train & val) and not (val & evals)


def test_same_seed_same_first_observation(env):
    first, _ = env.reset(seed=3, options={"canyon": "eval:2"})
    first = {k: v.copy() for k, v in first.items()}
    env.reset(seed=4, options={"canyon": "eval:5"})
    again, _ = env.reset(seed=3, options={"canyon": "eval:2"})
    for key in first:
        np.testing.assert_array_equal(first[key], again[key])
    assert first["image"].shape == (308, 410, 3) and first["image"].dtype == np.uint8
    assert first["image"].std() > 5  # a real rendered scene, not a blank frame


def test_driving_straight_for_two_seconds_covers_one_metre(env):
    env.reset(seed=0, options={"canyon": "eval:0"})
    for _ in range(20):
        _, _, terminated, _, info = env.step(np.zeros(1, np.float32))
        assert not terminated
    assert info["path_length"] == pytest.approx(1.0, rel=0.02)
    assert info["distance"] == pytest.approx(1.0, rel=0.02)


def test_turning_at_one_rad_per_second_for_pi_seconds_turns_pi(world):
    world.load(generate_canyon(CanyonId("eval", 0)))
    world.place(0.0, 0.0, 0.0)
    # pi seconds = 31.4 decisions of 0.1 s: advance 31 and measure the exact fraction.
    for _ in range(31):
        world.advance(1.0)
    turned = world.pose[2]
    assert turned == pytest.approx(3.1, rel=1e-3)
    assert turned / 3.1 * math.pi == pytest.approx(math.pi, rel=0.03)


def test_lidar_reads_known_wall_distances(world):
    world.load(generate_canyon(CanyonId("eval", 0)))
    world.place(0.0, 0.0, math.pi / 2)
    distance = world.raycast()
    origin = world.sensor_origin()
    # Left wall's first piece is the plane x = −1.5 (faces at ±1 cm), the back wall y = −2.
    assert distance[90] == pytest.approx(abs(-1.5 + 0.01 - origin[0]), abs=0.02)
    assert distance[180] == pytest.approx(origin[1] - (-2 + 0.01), abs=0.02)
    assert distance[270] == pytest.approx(1.5 - 0.01 - origin[0], abs=0.02)


def test_contact_with_a_wall_is_detected(world):
    world.load(generate_canyon(CanyonId("eval", 0)))
    world.place(-1.3, -1.0, math.pi)  # 0.19 m from the left wall, facing it
    contacts = [world.advance(0.0) for _ in range(5)]
    assert any(contacts)


def test_driving_into_a_wall_ends_the_run(env):
    env.reset(seed=0, options={"canyon": "eval:1"})
    for step in range(200):
        turn = 1.0 if step < 15 else 0.0  # face the left wall, then drive into it
        _, _, terminated, truncated, info = env.step(np.array([turn], np.float32))
        if terminated:
            break
    assert terminated and not truncated
    assert info["end_reason"] in ("bump", "contact")
    assert step < 100


def test_one_step_is_one_camera_frame_at_the_decision_rate():
    """At 4 Hz a step lasts 0.25 s (12.5 cm); the action space is the robot's yaw-rate limit."""
    e = CanyonEnv(EnvConfig(world=WorldConfig(decision_hz=4.0, max_yaw_rate=2.84)), camera=False)
    e.reset(seed=0, options={"canyon": "eval:0"})
    assert e.action_space.high[0] == pytest.approx(2.84) and e.metadata["render_fps"] == 4.0
    _, _, _, _, info = e.step(np.zeros(1, np.float32))
    assert info["time"] == pytest.approx(0.25) and info["path_length"] == pytest.approx(0.125, rel=0.01)
    yaw = info["pose"][2]
    _, _, _, _, info = e.step(np.array([2.0], np.float32))  # not clipped to 1: turns 0.5 rad
    assert info["pose"][2] - yaw == pytest.approx(0.5, rel=1e-3)
    _, _, _, _, info = e.step(np.array([9.0], np.float32))  # clipped to 2.84 rad/s
    assert info["pose"][2] - yaw == pytest.approx(0.5 + 0.71, rel=1e-3)
    e.close()
    with pytest.raises(ConfigError, match="decision_hz"):
        WorldConfig(decision_hz=3.0)  # 1/3 s is no whole number of 5 ms physics steps


def test_time_limit_truncates():
    e = CanyonEnv(EnvConfig(world=TEN_HZ, time_limit_s=0.5))
    e.reset(seed=0, options={"canyon": "eval:0"})
    results = [e.step(np.zeros(1, np.float32)) for _ in range(5)]
    e.close()
    assert results[-1][3] and results[-1][4]["end_reason"] == "time_limit"
    assert not any(r[3] for r in results[:-1])


def test_env_checker_passes_and_registered_id_builds():
    e = gymnasium.make(depthq.sim.ENV_ID)
    check_env(e.unwrapped, skip_render_check=False)
    e.close()


@pytest.mark.parametrize(
    "code",
    [
        "import gymnasium, depthq; e = gymnasium.make('depthq/Canyon-v0')",  # `import depthq` registers
        "import gymnasium; e = gymnasium.make('depthq:depthq/Canyon-v0')",  # gymnasium imports depthq
    ],
)
def test_env_id_works_as_in_every_gymnasium_package(code: str) -> None:
    """In a fresh interpreter, where nothing has imported depthq.sim yet."""
    check = code + "; obs, _ = e.reset(seed=0); assert obs['image'].shape == (308, 410, 3); e.close()"
    result = subprocess.run([sys.executable, "-c", check], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr


def test_colours_look_changes_colours_not_geometry():
    plain = CanyonEnv()
    rand = CanyonEnv(EnvConfig(world=WorldConfig(look="colours")))
    a, _ = plain.reset(seed=0, options={"canyon": "eval:4"})
    b, _ = rand.reset(seed=0, options={"canyon": "eval:4"})
    np.testing.assert_array_equal(a["scan"], b["scan"])
    assert np.abs(a["image"].astype(int) - b["image"].astype(int)).mean() > 5
    plain.close()
    rand.close()


@pytest.mark.parametrize(
    "make, name",
    [
        (lambda: WorldConfig(speed=0.0), "speed"),
        (lambda: CameraConfig(width=0), "resolution"),
        (lambda: CameraConfig(hfov_deg=180.0), "hfov_deg"),
        (lambda: CanyonId("eval", 20), "20"),
        (lambda: CanyonId.parse("nowhere:1"), "nowhere"),
        (lambda: CanyonConfig(n_segments=0), "n_segments"),
        (lambda: WorldConfig(look="neon"), "neon"),
    ],
)
def test_bad_configuration_names_the_value(make, name):
    with pytest.raises(ConfigError, match=name):
        make()


def test_nan_action_is_refused(env):
    env.reset(seed=0, options={"canyon": "eval:0"})
    with pytest.raises(ConfigError, match="nan"):
        env.step(np.array([np.nan], np.float32))


def test_drive_writes_a_map_and_frames_and_refuses_bad_input(tmp_path, capsys):
    from depthq.cli import main

    assert main(["drive", "--canyon", "eval:33", "--out", str(tmp_path / "bad")]) == 2
    assert "33" in capsys.readouterr().err and not (tmp_path / "bad").exists()
    assert main(["drive", "--canyon", "eval:2", "--time-limit", "2", "--frames", "2", "--json",
                 "--out", str(tmp_path / "ok")]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["end_reason"] == "time_limit" and 0.9 < result["distance"] <= 1.01
    assert (tmp_path / "ok" / "top_down.png").stat().st_size > 1000
    assert len(list((tmp_path / "ok").glob("frame_*.png"))) == 2
