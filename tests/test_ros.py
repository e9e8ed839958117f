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
import threading
import time
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
from depthq.policies.spec import PolicySpec
from research.ros_fidelity import replica_run

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
    policy, rate, frame_size = robot_policy(PolicySpec.parse(str(toy_nets["depth"])))
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
                decisions.append(now)
            elif command is not None:
                stops.append((now, command))
    assert len(decisions) in (12, 13) and np.allclose(np.diff(decisions), 0.25, atol=0.021)
    assert driver.stats.rate == pytest.approx(4.0, rel=0.05)
    assert len(stops) == 1 and stops[0][1] == Command(STOP, "watchdog")
    assert 0.44 - 1e-9 <= stops[0][0] - newest <= 0.46 + 1e-9  # out 40 ms before the 0.5 s at the latest
    assert driver.on_frame(Frame(4.0, jpegs[0]), 4.6).startswith("stale")  # 0.6 s old: never decided on
    assert driver.stats.stale == 1 and driver.tick(4.75) is None
    assert driver.stop() == Command(STOP, "stop")
    driver.on_frame(Frame(5.0, jpegs[0]), 5.0)
    assert driver.tick(5.0) is None  # stopped for good: a frame after the stop moves nothing


class _Steer:
    """A policy of the test's own: steers by the frame's brightness, or raises while `broken`."""

    name = "steer"
    broken = False

    def reset(self, seed: int | None = None) -> None: ...

    def describe(self) -> dict:
        return {"name": self.name}

    def act(self, obs: dict) -> float:
        if self.broken:
            raise RuntimeError("the policy's device is gone")
        return float(obs["image"].mean()) / 255.0


def _huge_jpeg(width: int, height: int) -> bytes:
    """A JPEG whose header says width × height (the pixels do not follow: it must be refused unread)."""
    data = bytearray(_jpeg(np.zeros((8, 8, 3), np.uint8)))
    sof = data.index(b"\xff\xc0")
    data[sof + 5: sof + 9] = height.to_bytes(2, "big") + width.to_bytes(2, "big")
    return bytes(data)


BAD_FRAMES = {  # what a camera (or a broken driver) may send, each with what the node must say of it
    "empty": (Frame(0.0, b""), "bad frame"),
    "random bytes": (Frame(0.0, np.random.default_rng(0).bytes(5000)), "bad frame"),
    "rgba8": (Frame(0.0, bytes(48 * 64 * 4), "rgba8", 48, 64, 64 * 4), "bad frame"),
    "0 × 0": (Frame(0.0, b"", "rgb8", 0, 0, 0), "bad frame"),
    "8000 × 6000": (Frame(0.0, _huge_jpeg(8000, 6000)), "bad frame"),
    "stamped 30 s ahead": (Frame(30.0, _jpeg(np.full((48, 64, 3), 99, np.uint8))), "from another clock"),
    "stamped 5 s ago": (Frame(-5.0, _jpeg(np.full((48, 64, 3), 99, np.uint8))), "stale"),
}


@pytest.mark.parametrize("kind", list(BAD_FRAMES))
def test_a_frame_the_node_cannot_use_is_counted_and_never_refreshes_the_watchdog(kind: str) -> None:
    """Good frames until 1 s, then only the bad kind at 30 Hz: it is dropped, saying why, never raises,
    and the zero twist still leaves within 0.5 s of the last good frame; good frames drive again."""
    bad, why = BAD_FRAMES[kind]
    good = _jpeg(np.full((48, 64, 3), 128, np.uint8))
    driver = RobotDriver(_Steer(), DriverConfig(decision_hz=4.0))
    stops, moves = [], []
    for k in range(int(3.0 * 300)):
        now = k / 300
        if k % 10 == 0:
            frame = Frame(now, good) if now < 1.0 or now >= 2.0 else Frame(now + bad.stamp, bad.data,
                                                                         bad.encoding, bad.height, bad.width,
                                                                         bad.step)
            dropped = driver.on_frame(frame, now + 0.002)
            assert (dropped is None) == (now < 1.0 or now >= 2.0)
            assert dropped is None or dropped.startswith(why), dropped
        if k % 6 == 0 and (command := driver.tick(now)) is not None:
            (moves if command.twist.linear_x else stops).append((now, command))
    assert [c.reason for _, c in stops] == ["watchdog"]
    last_good = 0.99 - 0.99 % (10 / 300)
    assert 0.4 <= stops[0][0] - last_good <= 0.5
    assert any(t < 1.0 for t, _ in moves) and any(t >= 2.0 for t, _ in moves)  # driven again on good frames
    assert not any(1.0 <= t < 2.0 and c.stamp >= 1.0 for t, c in moves)
    counts = driver.stats
    assert counts.bad + counts.stale + counts.future == 30


def test_a_clock_that_jumps_back_stops_the_robot_until_frames_of_the_new_clock_come() -> None:
    """A simulator restarted (or a bag looped) under /use_sim_time: its clock runs back from 100 s to 0.
    Everything from the old clock is dropped, one zero twist goes out at once, and the frames of the new
    clock are decided on."""
    driver = RobotDriver(_Steer(), DriverConfig(decision_hz=4.0))
    image = _jpeg(np.full((48, 64, 3), 128, np.uint8))
    commands = []
    for clock in (100.0, 0.0):
        for k in range(300):
            now = clock + k / 300
            if k % 10 == 0 and k >= 150 * (clock == 0.0):  # the new clock's frames start 0.5 s after the jump
                driver.on_frame(Frame(now, image), now)
            if k % 6 == 0 and (command := driver.tick(now)) is not None:
                commands.append((now, command))
    reasons = [(t, c.reason) for t, c in commands if c.stamp is None]
    assert reasons == [(0.0, "clock jumped back")] and driver.stats.clock_jumps == 1
    after = [t for t, c in commands if c.stamp is not None and t < 100]
    assert after and min(after) >= 0.5 and len(after) in (2, 3)  # decided again, at 4 Hz, on the new clock
    assert driver.on_frame(Frame(100.5, image), 1.0).startswith("from another clock")  # a late old frame


def test_a_clock_that_jumps_forward_stops_the_robot_until_frames_of_the_new_clock_come() -> None:
    driver = RobotDriver(_Steer(), DriverConfig(decision_hz=4.0))
    image = _jpeg(np.full((48, 64, 3), 128, np.uint8))
    driver.on_frame(Frame(10.0, image), 10.0)
    assert driver.tick(10.0).reason == "decision"
    assert driver.on_frame(Frame(10.1, image), 40.0).startswith("stale")  # the old clock's last frame
    assert driver.tick(40.0).reason == "watchdog"  # at the first check after the jump
    driver.on_frame(Frame(40.1, image), 40.1)
    assert driver.tick(40.1).reason == "decision"


def test_a_failing_policy_stops_the_robot_and_a_stalled_decision_loop_is_stopped_by_the_watchdog() -> None:
    policy = _Steer()
    driver = RobotDriver(policy, DriverConfig(decision_hz=4.0))
    image = _jpeg(np.full((48, 64, 3), 128, np.uint8))
    driver.on_frame(Frame(0.0, image), 0.0)
    assert driver.tick(0.0).reason == "decision"
    policy.broken = True
    driver.on_frame(Frame(0.25, image), 0.25)
    command = driver.decide(0.25)
    assert command.reason == "decision failed" and driver.commit(command, 0.25)
    assert driver.stats.failed == 1 and "device is gone" in driver.failure
    policy.broken = False
    driver.on_frame(Frame(0.5, image), 0.5)
    assert driver.tick(0.5).reason == "decision"
    # frames keep coming but the decision loop stops: the robot must not drive on a 0.7 s old decision
    stops = []
    for k in range(26, 70):
        now = k / 50
        driver.on_frame(Frame(now, image), now)
        if (command := driver.watch(now)) is not None:
            stops.append((now, command.reason))
    assert stops == [(1.2, "decisions stalled")]  # 0.25 s period + 0.44 s after the frame of 0.5 s
    decided = driver.decide(1.2)
    assert decided.reason == "decision" and driver.commit(decided, 1.2)  # the loop is back: it drives again
    driver.on_frame(Frame(1.5, image), 1.5)
    late = driver.decide(1.5)
    assert late.stamp == 1.5 and not driver.commit(late, 1.5 + 0.45)  # the watchdog gave its frame up


def test_the_node_loops_survive_their_bodies_exceptions_and_the_watchdogs_ends_it() -> None:
    from depthq.deploy.ros_drive import guarded_loop

    calls, errors, done = [], [], threading.Event()

    def body() -> None:
        calls.append(time.monotonic())
        if len(calls) in (2, 3):
            raise RuntimeError(f"call {len(calls)}")
        if len(calls) == 6:
            done.set()

    guarded_loop(body, 0.01, done, errors.append, fatal=False)
    assert len(calls) == 6 and [str(e) for e in errors] == ["call 2", "call 3"]  # went on after each
    calls.clear(), errors.clear()
    done.clear()
    guarded_loop(body, 0.01, done, errors.append, fatal=True)
    assert len(calls) == 2 and [str(e) for e in errors] == ["call 2"]  # a fatal loop ends at its first


@pytest.mark.slow
def test_an_onnx_graph_drives_frames_of_any_size_at_its_recorded_rate(
    small_dataset: Path, toy_nets: dict[str, Path], tmp_path: Path
) -> None:
    path = export_onnx(toy_nets["depth"], tmp_path)
    policy, rate, frame_size = robot_policy(PolicySpec.parse(f"onnx:{path}"))
    assert rate == 4.0 and frame_size == (308, 410)  # the rate from the graph's metadata
    frame = _frames(small_dataset, 1)[0]
    big = np.asarray(Image.fromarray(frame).resize((640, 480), Image.Resampling.BILINEAR))
    driver = RobotDriver(policy, DriverConfig(decision_hz=rate), frame_size)
    driver.on_frame(Frame(0.0, big[..., ::-1].tobytes(), "bgr8", 480, 640, 640 * 3), 0.01)  # a 640×480 camera
    command = driver.tick(0.02)
    expected = policy.act({"image": fit(big, frame_size)})
    assert command.reason == "decision" and command.twist == Twist(LINEAR_SPEED, expected)
    with pytest.raises(ConfigError, match="learned policy"):
        robot_policy(PolicySpec("heuristic"))


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
    policy, rate, _ = robot_policy(PolicySpec.parse(str(toy_nets["depth"])))
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


def _drive_the_test_camera(graph: RosGraph, checkpoint: Path, *flags: str, drive: list[str] | None = None,
                           during=None) -> tuple[dict, str]:
    """tests/ros_camera.py (a camera and a base) with `flags`, and `depthq ros drive` on it (`drive`: its
    argv, else the CLI's); `during(graph)` is called once the drive has decided twice. The camera's
    record and the drive's log."""
    graph.start("camera", [sys.executable, str(ROOT / "tests" / "ros_camera.py"), *flags])
    graph.wait_for(lambda: "ready" in graph.log("camera"), 60, "the test camera")
    topic = "/camera/image_raw" if "--raw" in flags else "/camera/image_raw/compressed"
    args = ["ros", "drive", "--policy", str(checkpoint), "--image-topic", topic, "--log-every", "0.25"]
    graph.start("drive", drive or [sys.executable, "-m", "depthq.cli", *args])
    if during is not None:
        graph.wait_for(lambda: decisions(graph.log("drive"))[0] >= 2, 60, "two decisions")
        during(graph)
    record = summary(graph.finish("camera", 90))
    graph.stop("drive")
    return record, graph.log("drive")


def _after(twists: list, t: float, moving: bool) -> list[float]:
    return [w for w, x, _ in twists if w > t and (x > 0) == moving]


@pytest.mark.slow
@needs_ros
@pytest.mark.parametrize("flags", [(), ("--raw", "--jump")], ids=["compressed", "raw-and-clock-jump"])
def test_no_frame_and_no_clock_jump_leaves_the_robot_driving(
    toy_nets: dict[str, Path], tmp_path: Path, flags: tuple[str, ...]
) -> None:
    """Bad frames of every kind between good ones (ros_camera.py): the robot is driven on the good ones;
    when they stop (the bad ones go on) a zero twist reaches it within 0.5 s, and it drives again when
    they resume. With a clock that runs back (a restarted simulator): a zero twist at once, decisions
    again on the new clock's frames. The node's log counts every kind and holds no traceback."""
    with RosGraph(tmp_path) as graph:
        record, log = _drive_the_test_camera(graph, toy_nets["depth"], *flags)
    twists, last_good = record["twists"], record["last_good"]
    assert any(w < last_good for w, x, _ in twists if x > 0), twists  # driven on the good frames
    stop = min(_after(twists, last_good, moving=False))
    assert stop - last_good <= 0.5, (stop, last_good)
    assert not [w for w in _after(twists, stop, moving=True) if w < record["resume"]]  # bad frames: no move
    assert [w for w in _after(twists, record["resume"], moving=True) if w < (record["jump"] or 1e9)]
    if record["jump"] is not None:
        moving_before = _after(twists, record["jump"] - 0.5, moving=True)
        assert moving_before and min(moving_before) < record["jump"]  # it was driving when the clock ran back
        stop = min(_after(twists, record["jump"], moving=False))
        assert stop - record["jump"] <= 0.5
        again = _after(twists, stop, moving=True)
        assert again and min(again) >= record["jump"] + record["new_frames"]  # on the new clock's frames
        assert log.count("the clock jumped back") == 1
    assert "Traceback" not in log and "frames dropped" in log
    counts = re.findall(r"(\d+) stale frames, (\d+) from another clock, (\d+) bad frames", log)[-1]
    assert all(int(n) > 0 for n in counts), counts


@pytest.mark.slow
@needs_ros
def test_a_watchdog_that_fails_stops_the_robot_and_ends_the_node_with_an_error(
    toy_nets: dict[str, Path], tmp_path: Path
) -> None:
    """The watchdog's loop raises (injected) while the robot drives: a zero twist, a clear log line, the
    node's exit status 1 for a supervisor to restart it."""
    args = ["ros", "drive", "--policy", str(toy_nets["depth"]), "--log-every", "0.25"]
    code = ("import sys, depthq.deploy.robot as robot\n"
            "watch, calls = robot.RobotDriver.watch, [0]\n"
            "def failing(self, now):\n"
            "    calls[0] += 1\n"
            "    if self.stats.decisions >= 4: raise RuntimeError('injected')\n"
            "    return watch(self, now)\n"
            "robot.RobotDriver.watch = failing\n"
            f"from depthq.cli import main; sys.exit(main({args!r}))\n")
    with RosGraph(tmp_path) as graph:
        record, log = _drive_the_test_camera(graph, toy_nets["depth"], drive=[sys.executable, "-c", code])
        assert graph.procs["drive"].returncode == 1
    twists = record["twists"]
    last_move = max(w for w, x, _ in twists if x > 0)
    assert _after(twists, last_move, moving=False), twists  # the zero twist came after the last move
    assert "the watchdog failed (RuntimeError: injected)" in log and "exits with an error" in log


@pytest.mark.slow
@needs_ros
def test_when_the_master_goes_the_robot_gets_a_zero_twist_and_the_node_ends_with_an_error(
    toy_nets: dict[str, Path], tmp_path: Path
) -> None:
    killed = []

    def kill_master(graph: RosGraph) -> None:
        killed.append(time.monotonic())
        graph.stop("roscore")

    with RosGraph(tmp_path) as graph:
        record, log = _drive_the_test_camera(graph, toy_nets["depth"], during=kill_master)
        assert graph.procs["drive"].returncode == 1
    twists = record["twists"]
    last_move = max(w for w, x, _ in twists if x > 0)
    assert _after(twists, last_move, moving=False)
    assert "is gone: zero twist, the node exits with an error" in log


@pytest.mark.slow
@needs_ros
def test_one_drive_node_drives_two_simulator_runs_in_a_row(toy_nets: dict[str, Path], tmp_path: Path) -> None:
    """A restarted `ros sim` under /use_sim_time: the clock runs back to 0; the node drives both runs."""
    with RosGraph(tmp_path) as graph:
        runs = []
        for k in range(2):
            graph.depthq(f"sim{k}", "ros", "sim", "--canyon", "val:1000", "--json", "--time-limit", "3")
            graph.wait_for(lambda k=k: "ready" in graph.log(f"sim{k}"), 60, "ros sim")
            if k == 0:
                graph.depthq("drive", "ros", "drive", "--policy", str(toy_nets["depth"]),
                             "--log-every", "0.5")
            runs.append(summary(graph.finish(f"sim{k}", 90)))
        graph.stop("drive")
        log = graph.log("drive")
    for run in runs:
        assert run["end_reason"] == "time_limit" and run["commands"] >= 8 and run["path_length"] > 1.0, run
    assert log.count("the clock jumped back") == 1 and "Traceback" not in log


def test_the_paired_table_pools_measurements(tmp_path: Path) -> None:
    """ros_fidelity --paired: a row per finished measurement and one pooled, the paired interval."""
    from depthq.configio import write_json
    from research.ros_fidelity import main as fidelity
    from research.ros_fidelity import paired

    def row(ros: float, ev: float) -> dict:
        return {"ros": ros, "evaluate": ev, "ros_end": "bump", "evaluate_end": "end" if ev > 20 else "bump"}

    write_json(tmp_path / "a" / "ros_fidelity.json", {"rows": [row(10.0, 12.0), row(14.0, 21.0)]})
    write_json(tmp_path / "b" / "ros_fidelity.json", {"rows": [row(20.0, 18.0)]})
    table = paired([tmp_path / "a", tmp_path / "b"]).splitlines()
    assert len(table) == 5 and table[-1].startswith("| all | 3 | 17.00 m | 14.67 m | 86% | -2.33 [")
    assert "| 1 / 0 |" in table[2]
    assert fidelity(["--paired", str(tmp_path / "a")]) == 0
