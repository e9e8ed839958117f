"""`depthq ros`: the ROS-free robot core (decisions at the policy's rate on the newest frame, the
watchdog, any camera encoding and size), the simulated robot, and a closed loop through a real ROS 1
master: roscore, `depthq ros sim`, `depthq ros drive` and `rosbag record` as separate processes.

The ROS tests need ROS 1's system packages (`.ci/run` installs them on Debian 12); where they are
not installed those tests are skipped, saying so."""

from __future__ import annotations

import io
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from depthq.data.manifest import Dataset
from depthq.deploy.canyon_robot import CanyonRobot, RobotSimConfig
from depthq.deploy.onnx_export import export_onnx
from depthq.deploy.robot import (
    LINEAR_SPEED,
    STOP,
    Command,
    DriverConfig,
    Frame,
    RobotDriver,
    Twist,
    decode,
    fit,
    robot_policy,
)
from depthq.deploy.ros1 import DEBIAN_PACKAGES
from depthq.deploy.ros_graph import RosGraph, decisions, summary
from depthq.errors import ConfigError, DataError
from depthq.experiments.ros_fidelity import replica_run

ROOT = Path(__file__).resolve().parents[1]


def _ros_missing() -> str | None:
    """Why the ROS tests cannot run here, or None."""
    if shutil.which("roscore") is None or shutil.which("rosbag") is None:
        return f"ROS 1 is not installed (roscore, rosbag): apt-get install {DEBIAN_PACKAGES}"
    code = "from depthq.deploy.ros1 import import_rospy; import_rospy()"
    probe = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    return None if probe.returncode == 0 else f"rospy does not import: {probe.stderr.strip()[-300:]}"


ROS_MISSING = _ros_missing()
needs_ros = pytest.mark.skipif(ROS_MISSING is not None, reason=str(ROS_MISSING))


def _frames(data: Path, n: int) -> list[np.ndarray]:
    dataset = Dataset.open(data)
    entry = dataset.entries("val")[0]
    with dataset.reader(entry) as reader:
        return [reader.image(t) for t in range(min(n, entry.n_frames))]


def _jpeg(frame: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(frame).save(buffer, format="JPEG", quality=90)
    return buffer.getvalue()


# -- the core: no ROS ------------------------------------------------------------------------------------


def test_every_camera_encoding_decodes_to_the_same_rgb_frame() -> None:
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    padded = np.zeros((48, 64 * 3 + 8), np.uint8)  # a driver's row padding: step > width × 3
    padded[:, : 64 * 3] = rgb[..., ::-1].reshape(48, -1)
    assert np.array_equal(decode(Frame(0.0, rgb.tobytes(), "rgb8", 48, 64, 64 * 3)), rgb)
    assert np.array_equal(decode(Frame(0.0, padded.tobytes(), "bgr8", 48, 64, 64 * 3 + 8)), rgb)
    grey = rgb[..., 0]
    mono = decode(Frame(0.0, grey.tobytes(), "mono8", 48, 64, 64))
    assert np.array_equal(mono, np.repeat(grey[..., None], 3, 2))
    png = io.BytesIO()
    Image.fromarray(rgb).save(png, format="PNG")
    assert np.array_equal(decode(Frame(0.0, png.getvalue())), rgb)
    smooth = np.repeat(np.linspace(0, 255, 64, dtype=np.uint8)[None, :, None], 48, 0).repeat(3, 2)
    assert np.abs(decode(Frame(0.0, _jpeg(smooth))).astype(int) - smooth).mean() < 2
    with pytest.raises(DataError, match="'rgba16'"):
        decode(Frame(0.0, rgb.tobytes(), "rgba16", 48, 64, 64 * 8))
    with pytest.raises(DataError, match="do not hold"):
        decode(Frame(0.0, rgb.tobytes()[:100], "rgb8", 48, 64, 64 * 3))


def test_a_frame_of_another_size_is_resized_as_the_graph_resizes() -> None:
    """`fit` is Pillow's fixed-point bilinear resize: the arithmetic of torch's uint8 antialiased resize
    that `preprocess` and the ONNX graph do (`depthq.deploy.onnx_export.FrameResize`), to the bit."""
    frame = np.random.default_rng(1).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    fitted = fit(frame, (308, 410))
    reference = torch.nn.functional.interpolate(
        torch.from_numpy(frame).permute(2, 0, 1)[None], size=(308, 410), mode="bilinear", antialias=True
    )[0].permute(1, 2, 0).numpy()
    assert fitted.shape == (308, 410, 3) and np.array_equal(fitted, reference)
    assert fit(frame, None) is frame and fit(frame, (480, 640)) is frame


def test_driver_config_refuses_bad_values() -> None:
    for bad in ({"decision_hz": 0}, {"decision_hz": 4, "watchdog_s": 0.01},
                {"decision_hz": 4, "max_age_s": 0}, {"decision_hz": 40}):
        with pytest.raises(ConfigError):
            DriverConfig(**bad)


@pytest.mark.slow
def test_the_driver_decides_at_the_policys_rate_on_the_newest_frame_and_stops_when_frames_stop(
    small_dataset: Path, toy_nets: dict[str, Path]
) -> None:
    """A 30 Hz camera, a 50 Hz timer: 4 decisions a second, each on the newest frame; stale frames are
    not decided on; the zero twist is out within 0.5 s of the last frame."""
    policy, rate, frame_size = robot_policy(str(toy_nets["depth"]))
    assert rate == 4.0 and frame_size is None
    driver = RobotDriver(policy, DriverConfig(decision_hz=rate))
    jpegs = [_jpeg(f) for f in _frames(small_dataset, 6)]
    decisions, stops, newest = [], [], None
    camera_stops = 3.0
    for k in range(int(4.5 * 300)):  # 300 steps a second: the camera's and the timer's times
        now = k / 300
        if k % 10 == 0 and now < camera_stops:  # a 30 Hz frame stamped now, received 2 ms later
            newest = now
            driver.on_frame(Frame(now, jpegs[k // 10 % len(jpegs)]), now + 0.002)
        if k % 6 == 0:  # the 50 Hz timer
            command = driver.tick(now)
            if command is not None and command.reason == "decision":
                assert command.stamp == newest and command.twist.linear_x == LINEAR_SPEED
                driver.published(command, now)
                decisions.append(now)
            elif command is not None:
                stops.append((now, command))
    assert len(decisions) in (12, 13) and np.allclose(np.diff(decisions), 0.25, atol=0.021)
    assert driver.stats.rate == pytest.approx(4.0, rel=0.05)
    assert len(stops) == 1 and stops[0][1] == Command(STOP, "watchdog")
    assert 0.44 - 1e-9 <= stops[0][0] - newest <= 0.46 + 1e-9  # out 40 ms before the 0.5 s at the latest
    driver.on_frame(Frame(4.0, jpegs[0]), 4.6)  # 0.6 s old: stale, never decided on
    assert driver.stats.stale == 1 and driver.tick(4.75) is None
    assert driver.stop() == Command(STOP, "stop")
    driver.on_frame(Frame(5.0, jpegs[0]), 5.0)
    assert driver.tick(5.0) is None  # stopped for good: a frame after the stop moves nothing


@pytest.mark.slow
def test_an_onnx_graph_drives_frames_of_any_size_at_its_recorded_rate(
    small_dataset: Path, toy_nets: dict[str, Path], tmp_path: Path
) -> None:
    path = export_onnx(toy_nets["depth"], tmp_path)
    policy, rate, frame_size = robot_policy(f"onnx:{path}")
    assert rate == 4.0 and frame_size == (308, 410)  # the rate from the graph's metadata
    frame = _frames(small_dataset, 1)[0]
    big = np.asarray(Image.fromarray(frame).resize((640, 480), Image.Resampling.BILINEAR))
    driver = RobotDriver(policy, DriverConfig(decision_hz=rate), frame_size)
    driver.on_frame(Frame(0.0, big[..., ::-1].tobytes(), "bgr8", 480, 640, 640 * 3), 0.01)  # a 640×480 camera
    command = driver.tick(0.02)
    expected = policy.act({"image": fit(big, frame_size)})
    assert command.reason == "decision" and command.twist == Twist(LINEAR_SPEED, expected)
    with pytest.raises(ConfigError, match="learned policy"):
        robot_policy("heuristic")


@pytest.mark.slow
def test_the_simulated_robot_moves_by_its_last_command_and_senses_on_schedule() -> None:
    robot = CanyonRobot(RobotSimConfig(canyon="val:1000", time_limit_s=2.0, camera_until_s=1.0))
    try:
        ticks = [robot.tick() for _ in range(100)]  # 0.5 s standing: no run yet
        assert robot.start is None and robot.distance < 1e-9 and sum(t.jpeg is not None for t in ticks) == 15
        robot.receive(Twist(0.5, 0.0))
        robot.receive(Twist(0.5, 0.3))  # held until the next
        while (tick := robot.tick()).end_reason is None:
            ticks.append(tick)
            if robot.driven == pytest.approx(1.5):
                robot.receive(STOP)
        assert tick.end_reason == "time_limit" and robot.driven == pytest.approx(2.0)
        assert sum(t.jpeg is not None for t in ticks) == 15 + 29  # 30 Hz, until 1 s of driving
        assert sum(t.scan is not None for t in ticks) == 12  # 5 Hz over 2.5 s
        assert robot.path_length == pytest.approx(0.75, rel=0.01) and robot.pose[2] > np.pi / 2 + 0.4
        summary = robot.summary(wall_s=1.0)
        assert summary["commands"] == 3 and summary["stopped"] == pytest.approx(1.5)
        assert summary["last_frame"] == pytest.approx(0.97, abs=0.006) and summary["real_time_factor"] == 2.5
    finally:
        robot.close()


@pytest.mark.slow
def test_the_replica_applies_each_command_its_latency_after_the_decision(toy_nets: dict[str, Path]) -> None:
    """experiments.ros_fidelity's ROS-free replica, at toy size: the node's core and the simulated robot in
    lock-step; a command decided at t moves the robot from t + latency (its first: the run's start)."""
    policy, rate, _ = robot_policy(str(toy_nets["depth"]))
    runs = [replica_run(policy, rate, "val:1000", 0, latency, jpeg=True, time_limit_s=1.0)
            for latency in (0, 0.1)]
    for run in runs:
        assert run["end_reason"] == "time_limit" and run["commands"] in (4, 5) and run["frames"] >= 30
    assert runs[0]["frames"] + 3 == runs[1]["frames"]  # the start 0.1 s later: three more frames before it


# -- ROS 1 installed or not ------------------------------------------------------------------------------


def _without_ros(code: str) -> subprocess.CompletedProcess:
    """`code` run where rospy is not installed: the system folders `import_rospy` would add are none."""
    prelude = ("import importlib.util, sys, depthq.deploy.ros1 as r; r.SYSTEM_FOLDERS = ()\n"
               "from depthq.cli import main\n")
    return subprocess.run([sys.executable, "-c", prelude + code], capture_output=True, text=True, timeout=120)


def test_without_ros_the_verb_is_listed_its_help_works_and_it_exits_2_naming_what_to_install(
    tmp_path: Path,
) -> None:
    if _without_ros("sys.exit(importlib.util.find_spec('rospy') is None)").returncode == 0:
        pytest.skip("rospy is on this environment's own path: there is no machine without ROS to play")
    done = _without_ros(
        "import contextlib, io\n"
        "for argv in (['--help'], ['ros', '--help'], ['ros', 'drive', '--help'], ['ros', 'sim', '--help']):\n"
        "    out = io.StringIO()\n"
        "    with contextlib.redirect_stdout(out):\n"
        "        try: main(argv)\n"
        "        except SystemExit as e: assert e.code == 0, argv\n"
        "    assert 'ros' in out.getvalue()\n"
        "assert 'rospy' not in sys.modules\n"
        "assert main(['ros', 'sim', '--camera-hz', '0']) == main(['ros', 'drive', '--policy', 'x', "
        "'--watchdog', '0']) == 2\n"
        f"sys.exit(main(['ros', 'sim', '--canyon', 'val:1000']) * 10 + main(['ros', 'drive', '--policy', "
        f"'{tmp_path}']))"
    )
    assert done.returncode == 22, done.stderr
    bad, missing = done.stderr.strip().splitlines()[:2], done.stderr.strip().splitlines()[2:]
    assert "--camera-hz" in bad[0] and "--watchdog" in bad[1]  # bad flags first, ROS or not
    assert len(missing) == 2 and all("apt-get install ros-core python3-rospy" in line for line in missing)


@needs_ros
def test_rospy_comes_from_the_system_without_shadowing_the_environments_packages() -> None:
    done = subprocess.run(
        [sys.executable, "-c",
         "import sys, PIL; before = PIL.__file__\n"
         "from depthq.deploy.ros1 import import_rospy; rospy = import_rospy()\n"
         "import PIL, numpy, yaml\n"
         "print(rospy.__file__, PIL.__file__ == before, sys.path[-1], numpy.__file__)"],
        capture_output=True, text=True, timeout=60, check=True,
    )
    rospy_file, same_pil, last, numpy_file = done.stdout.split()
    assert same_pil == "True" and last.endswith("dist-packages")
    assert not numpy_file.startswith("/usr/lib/python3/")  # the environment's numpy, not Debian's
    assert rospy_file.startswith(("/usr/lib/python3/", "/opt/ros/"))


# -- the closed loop through a real master -----------------------------------------------------------------


@pytest.mark.slow
@needs_ros
def test_a_policy_drives_the_simulated_robot_through_a_real_master(
    toy_nets: dict[str, Path], tmp_path: Path
) -> None:
    """ros sim + ros drive + rosbag record, a roscore between them: the robot drives on, decisions at the
    policy's rate; `rosnode kill` stops it; the bag imports. Then a camera that dies: the robot stops
    within 0.5 s of its last frame."""
    from rosbags.highlevel import AnyReader

    with RosGraph(tmp_path) as graph:
        sim = ["ros", "sim", "--canyon", "val:1000", "--json"]
        drive = ["ros", "drive", "--policy", str(toy_nets["depth"]), "--log-every", "0.5"]
        graph.depthq("sim", *sim, "--time-limit", "6")
        graph.wait_for(lambda: "ready" in graph.log("sim"), 60, "ros sim")
        topics = ["/camera/image_raw/compressed", "/scan", "/cmd_vel", "/odom"]
        graph.start("bag", ["rosbag", "record", "-O", str(tmp_path / "run.bag"), *topics])
        graph.depthq("drive", *drive)
        graph.wait_for(lambda: decisions(graph.log("drive"))[0] >= 10, 60, "ten decisions")
        graph.run("rosnode", "kill", "/depthq_drive")
        graph.finish("drive", 20)
        first = summary(graph.finish("sim", 60))
        graph.stop("bag")
        assert graph.procs["drive"].returncode == 0
        _, rate, latency_ms = decisions(graph.log("drive"))
        assert rate == pytest.approx(4.0, rel=0.1) and latency_ms < 250  # the newest of 30 frames a second
        assert first["end_reason"] == "time_limit" and first["stopped"] is not None
        # driven at 0.5 m/s until the kill's zero twist, standing after it
        assert first["path_length"] == pytest.approx(0.5 * first["stopped"], rel=0.1)
        assert first["distance"] >= 0.25 * first["stopped"] and first["stopped"] >= 2.0
        # the decisions, one every 0.25 s from the first, then the zero twist
        assert abs(first["commands"] - 1 - (1 + 4 * first["stopped"])) <= 1.5, first
        with AnyReader([tmp_path / "run.bag"]) as reader:
            twists = [reader.deserialize(raw, c.msgtype) for c, _, raw in
                      reader.messages([c for c in reader.connections if c.topic == "/cmd_vel"])]
            odom = [(t, reader.deserialize(raw, c.msgtype).pose.pose.position) for c, t, raw in
                    reader.messages([c for c in reader.connections if c.topic == "/odom"])]
        assert twists[-1].linear.x == 0 and twists[-1].angular.z == 0
        # every command the sim heard, but the bag's subscription connects to the drive's publisher on
        # its own (ROS 1's handshake): under load it may miss the first few
        assert 0 <= first["commands"] - len(twists) <= 3, (len(twists), first["commands"])
        still = np.array([(p.x, p.y) for _, p in odom[-20:]])  # the run's last 0.6 s: not a micrometre moved
        assert np.ptp(still, axis=0).max() < 1e-6
        imported = subprocess.run(
            [sys.executable, "-m", "depthq.cli", "bag", "import", str(tmp_path / "run.bag"),
             "--out", str(tmp_path / "imported"), "--val-runs", "0"],
            capture_output=True, text=True, timeout=120,
        )
        assert imported.returncode == 0, imported.stderr
        frames = int(re.search(r"(\d+) frames", imported.stdout).group(1))
        assert frames >= 30 * (first["stopped"] - 1)

        graph.depthq("sim2", *sim, "--time-limit", "4", "--camera-until", "2")
        graph.wait_for(lambda: "ready" in graph.log("sim2"), 60, "ros sim")
        graph.depthq("drive2", *drive, "--node-name", "depthq_drive2")
        second = summary(graph.finish("sim2", 90))
        assert second["end_reason"] == "time_limit" and second["last_frame"] == pytest.approx(2.0, abs=0.04)
        assert 0.3 <= second["stopped"] - second["last_frame"] <= 0.5
        graph.stop("drive2")
        assert "watchdog: zero twist" in graph.log("drive2")
    assert not graph.master_up() and all(p.poll() is not None for p in graph.procs.values())  # nothing left


def test_the_paired_table_pools_measurements(tmp_path: Path) -> None:
    """ros_fidelity --paired: a row per finished measurement and one pooled, the paired interval."""
    from depthq.configio import write_json
    from depthq.experiments.ros_fidelity import main as fidelity
    from depthq.experiments.ros_fidelity import paired

    def row(ros: float, ev: float) -> dict:
        return {"ros": ros, "evaluate": ev, "ros_end": "bump", "evaluate_end": "end" if ev > 20 else "bump"}

    write_json(tmp_path / "a" / "ros_fidelity.json", {"rows": [row(10.0, 12.0), row(14.0, 21.0)]})
    write_json(tmp_path / "b" / "ros_fidelity.json", {"rows": [row(20.0, 18.0)]})
    table = paired([tmp_path / "a", tmp_path / "b"]).splitlines()
    assert len(table) == 5 and table[-1].startswith("| all | 3 | 17.00 m | 14.67 m | 86% | -2.33 [")
    assert "| 1 / 0 |" in table[2]
    assert fidelity(["--paired", str(tmp_path / "a")]) == 0
