"""A policy driving, as an MP4: Fig. 4 animated, one video frame per decision, in real time.

Left the camera frame the policy saw; middle what it predicted for each action (Depth-Q-Net: the
depth bins, over the true depth that followed; Coll-Q-Net: the collision probabilities; other
policies: the true depth alone); right the robot's place in the canyon and its path so far.
H.264 in MP4 (yuv420p), which browsers play, encoded by the ffmpeg binary that `imageio-ffmpeg`
ships in its wheel.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import imageio_ffmpeg
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from depthq.configio import temp_sibling
from depthq.evaluate.figures import ACTION_NAMES, DEPTH_PLOT, bin_bearings, value_plot
from depthq.sim.canyon import CanyonId, generate_canyon
from depthq.sim.topdown import draw_run

SIZE_PX = (1280, 400)  # width, height: multiples of 16, as H.264 wants
VIDEO_SCALE = 2  # camera frames are kept at half resolution (a 45 s run stays ≈ 17 MB in memory)


def write_video(
    frames: list[dict[str, Any]], run: dict[str, Any], policy: dict[str, Any], path: Path, fps: float
) -> None:
    """Encode `frames` (per decision: image, values or None, true_bins, pose, action) to `path`,
    atomically (a temporary sibling renamed when complete)."""
    actions = policy.get("actions", [-1.0, 0.0, 1.0])
    has_values = frames[0]["values"] is not None
    plot = value_plot(policy) if has_values else DEPTH_PLOT  # without values: the true depth alone
    bars_shown = plot.style == "bars"
    fig = plt.figure(figsize=(SIZE_PX[0] / 100, SIZE_PX[1] / 100), dpi=100)
    cam, pred, top = fig.subplots(1, 3, gridspec_kw={"width_ratios": [1.45, 1.6, 0.5]})
    image = cam.imshow(frames[0]["image"])
    cam.axis("off")
    bearings = bin_bearings()
    if bars_shown:
        bars = pred.bar([ACTION_NAMES.get(a, str(a)) for a in actions], frames[0]["values"], color="0.6")
        pred.set_ylim(*plot.limits)
        pred.set_ylabel(plot.label, fontsize=8)
    else:
        (truth,) = pred.plot(bearings, frames[0]["true_bins"], "r-o", ms=3, label="true depth at t+1")
        lines = []
        if has_values:
            lines = [
                pred.plot(bearings, v, "--", label=f"predicted, {ACTION_NAMES.get(a, a)}")[0]
                for a, v in zip(actions, frames[0]["values"], strict=True)
            ]
        pred.invert_xaxis()
        pred.set_ylim(*plot.limits)
        pred.set_xlabel("bearing (°, left → right)", fontsize=8)
        pred.set_ylabel(plot.label, fontsize=8)
        pred.legend(fontsize=7, loc="lower right")
    pred.tick_params(labelsize=7)
    poses = run["poses"]
    draw_run(top, generate_canyon(CanyonId.parse(run["canyon"])), None, span=float(poses[:, 1].max()) + 2)
    (path_line,) = top.plot([], [], color="tab:red", lw=1.2)
    (robot,) = top.plot([], [], "o", color="tab:blue", ms=5)
    clock = cam.set_title("", fontsize=9)
    fig.suptitle(
        f"{policy.get('policy')} in {run['canyon']}: {run['distance']:.1f} m, {run['end_reason']}", fontsize=9
    )
    fig.tight_layout()
    # Blitting: axes, ticks and walls are drawn once; each frame redraws only what moves (≈ 8× faster).
    moving = [image, clock, path_line, robot, *(bars if bars_shown else [truth, *lines])]
    for artist in moving:
        artist.set_animated(True)
    fig.canvas.draw()
    background = fig.canvas.copy_from_bbox(fig.bbox)

    path = Path(path)
    tmp = temp_sibling(path, ".mp4")
    writer = imageio_ffmpeg.write_frames(
        tmp,
        SIZE_PX,
        fps=fps,
        codec="libx264",
        pix_fmt_out="yuv420p",
        quality=None,
        output_params=["-crf", "28"],
        ffmpeg_log_level="error",
    )
    try:
        writer.send(None)
        for step, frame in enumerate(frames):
            fig.canvas.restore_region(background)
            image.set_data(frame["image"])
            clock.set_text(f"t = {step / fps:4.1f} s   action {frame['action']:+.0f}")
            chosen = int(np.argmin(np.abs(np.asarray(actions) - frame["action"])))
            if bars_shown:
                for k, (bar, v) in enumerate(zip(bars, frame["values"], strict=True)):
                    bar.set_height(v)
                    bar.set_color("tab:purple" if k == chosen else "0.6")
            else:
                truth.set_ydata(frame["true_bins"])
                for k, (line, v) in enumerate(zip(lines, frame["values"] if has_values else [], strict=True)):
                    line.set_ydata(v)
                    line.set_linewidth(2.5 if k == chosen else 1.0)
            path_line.set_data(poses[: step + 1, 0], poses[: step + 1, 1])
            robot.set_data(frame["pose"][:1], frame["pose"][1:2])
            for artist in moving:
                fig.draw_artist(artist)
            writer.send(np.ascontiguousarray(np.asarray(fig.canvas.buffer_rgba())[..., :3]))
        writer.close()
        os.replace(tmp, path)
    except BaseException:
        writer.close()
        Path(tmp).unlink(missing_ok=True)
        raise
    finally:
        plt.close(fig)
