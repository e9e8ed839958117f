"""A ROS 1 camera and robot base in one test node, for `depthq ros drive` in tests/test_ros.py.

It publishes good camera frames with every kind of frame a node cannot use between them (empty,
random bytes, an unknown encoding, 0 × 0, 8000 × 6000, stamped 30 s ahead or 5 s ago), stops the good
frames for a while as a camera that dies (the bad ones go on), resumes them, and, with `--jump`, runs
its own /clock back to 0 as a restarted simulator or a looped bag does. It records every twist on
/cmd_vel and prints one JSON line: the twists and the times of its phases, all on the wall clock.

    python tests/ros_camera.py [--raw] [--jump] [--wait S]
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import time

import numpy as np
from PIL import Image

from depthq.deploy.ros1 import import_rospy

GOOD_UNTIL, RESUME, END = 2.0, 3.5, 5.0  # s from the start: good frames stop, resume, the run ends
JUMP_AT, NEW_FRAMES = 5.0, 0.7  # --jump: the clock runs back to 0 at 5 s; frames of it from 0.7 s on
CAMERA_HZ = 30.0


def _jpeg(image: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(image).save(buffer, format="JPEG", quality=90)
    return buffer.getvalue()


def _huge_jpeg(width: int, height: int) -> bytes:
    data = bytearray(_jpeg(np.zeros((8, 8, 3), np.uint8)))
    sof = data.index(b"\xff\xc0")
    data[sof + 5: sof + 9] = height.to_bytes(2, "big") + width.to_bytes(2, "big")
    return bytes(data)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--raw", action="store_true", help="sensor_msgs/Image on /camera/image_raw")
    parser.add_argument("--jump", action="store_true", help="publish /clock, and run it back at 5 s")
    parser.add_argument("--wait", type=float, default=60.0, help="s to wait for the drive node")
    args = parser.parse_args()
    rospy = import_rospy()
    from geometry_msgs.msg import Twist
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import CompressedImage
    from sensor_msgs.msg import Image as RawImage

    rng = np.random.default_rng(0)
    good = rng.integers(0, 256, (240, 320, 3), dtype=np.uint8)
    rospy.init_node("ros_camera", disable_signals=True)
    if args.jump:
        rospy.set_param("/use_sim_time", True)
    clock = rospy.Publisher("/clock", Clock, queue_size=10) if args.jump else None
    topic = "/camera/image_raw" if args.raw else "/camera/image_raw/compressed"
    camera = rospy.Publisher(topic, RawImage if args.raw else CompressedImage, queue_size=10)
    print("ready", flush=True)
    twists: list[tuple[float, float, float]] = []
    rospy.Subscriber("/cmd_vel", Twist, lambda m: twists.append((time.monotonic(), m.linear.x, m.angular.z)),
                     queue_size=100, tcp_nodelay=True)

    def message(stamp: float, kind: str):
        if args.raw:
            msg = RawImage(height=240, width=320, encoding="bgr8", step=960, data=good[..., ::-1].tobytes())
            if kind == "rgba8":
                msg.encoding, msg.step, msg.data = "rgba8", 1280, bytes(240 * 1280)
            elif kind == "0 × 0":
                msg.height = msg.width = msg.step = 0
                msg.data = b""
            elif kind == "8000 × 6000":
                msg.height, msg.width, msg.step = 6000, 8000, 24000
        else:
            broken = {"empty": b"", "random bytes": rng.bytes(5000), "8000 × 6000": _huge_jpeg(8000, 6000)}
            data = broken[kind] if kind in broken else _jpeg(good)
            msg = CompressedImage(format="jpeg", data=data)
        offset = {"30 s ahead": 30.0, "5 s ago": -5.0}.get(kind, 0.0)
        msg.header.stamp = rospy.Time.from_sec(max(stamp + offset, 0.0))
        return msg

    bad_kinds = (["rgba8", "0 × 0"] if args.raw else ["empty", "random bytes"]) + [
        "8000 × 6000", "30 s ahead", "5 s ago"]
    t0 = time.monotonic()
    while camera.get_num_connections() == 0:
        if time.monotonic() - t0 > args.wait:
            sys.exit("no drive node subscribed to the camera")
        if clock is not None:
            clock.publish(Clock(clock=rospy.Time.from_sec(100.0)))
        time.sleep(0.05)
    time.sleep(0.5)  # its publisher's connection to /cmd_vel
    start = time.monotonic()
    end = start + END + (2.0 if args.jump else 0.0)
    frames, last_good = 0, None
    while (now := time.monotonic()) < end:
        t = now - start
        jumped = args.jump and t >= JUMP_AT
        stamp = (t - JUMP_AT) if jumped else (100.0 + t if args.jump else rospy.get_time())
        if clock is not None:
            clock.publish(Clock(clock=rospy.Time.from_sec(stamp)))
        if now - start >= frames / CAMERA_HZ:
            frames += 1
            showing = (t < GOOD_UNTIL or t >= RESUME) and (not jumped or t - JUMP_AT >= NEW_FRAMES)
            if showing:
                camera.publish(message(stamp, "good"))
                last_good = t if t < GOOD_UNTIL else last_good
            if frames % 3 == 0:  # a bad frame of each kind in turn, 10 a second, whatever the good ones do
                camera.publish(message(stamp, bad_kinds[frames // 3 % len(bad_kinds)]))
        time.sleep(0.005)
    time.sleep(0.3)
    print(json.dumps({"last_good": last_good, "resume": RESUME, "jump": JUMP_AT if args.jump else None,
                      "new_frames": NEW_FRAMES, "twists": [(w - start, x, z) for w, x, z in twists]}))
    rospy.signal_shutdown("done")


if __name__ == "__main__":
    main()
