"""Does a policy drive through ROS as it drives in `depthq evaluate`? A deployment fidelity check.

    python -m research.ros_fidelity CHECKPOINT --canyons hard/eval:0-4 --out runs/ros-fidelity

For each canyon: roscore, `depthq ros sim --canyon C` (the camera at --camera-hz, real time) and
`depthq ros drive --policy CHECKPOINT` as separate processes (`depthq.deploy.ros_graph`), one run; then
`depthq evaluate CHECKPOINT` in the same canyons. Written to OUT/ros_fidelity.json and printed per
canyon: the distance through ROS and in the evaluation, the end reasons, the node's decision rate and
median latency (frame stamp → command published, on the simulated clock). It drives `eval` canyons
by design: it measures the deployment, not a choice made on them (docs/robot.md#ros-fidelity).

    python -m research.ros_fidelity CHECKPOINT --replica --seeds 0,1 --out runs/ros-replica

measures where a difference comes from, without ROS and its timing: the same node core
(`RobotDriver`) and simulated robot (`CanyonRobot`) in lock-step on the simulated clock, the command
applied `latency` seconds after its decision, the frames given as JPEG (as through ROS) or raw (as
in the evaluation), with several sensor-noise seeds: one row per (latency, frames) setting.

    python -m research.ros_fidelity --paired runs/ros-fidelity3 runs/ros-fidelity-s3-8

reads finished measurements and prints docs/robot.md's table: per folder and all pooled, the mean
distances, their ratio, the paired difference (ROS − evaluate per canyon and seed) with its 95 %
interval, and the ends reached.
"""

from __future__ import annotations

import argparse
import json
import signal
import statistics
import sys
from pathlib import Path
from typing import Any

from depthq.configio import read_json, write_json
from depthq.deploy.canyon_robot import CanyonRobot, RobotSimConfig
from depthq.deploy.robot import DriverConfig, Frame, RobotDriver, robot_policy
from depthq.deploy.ros_graph import RosGraph, decisions, summary
from depthq.evaluate.online import EvalConfig, evaluate, parse_canyon_set
from depthq.policies.spec import PolicySpec
from depthq.report.cells import mean_interval


def ros_run(checkpoint: Path, canyon: str, folder: Path, camera_hz: float, seed: int = 0) -> dict[str, Any]:
    """One run through a real master: the sim's summary with the node's rate and latency."""
    with RosGraph(folder) as graph:
        graph.depthq("sim", "ros", "sim", "--canyon", canyon, "--camera-hz", str(camera_hz),
                     "--seed", str(seed), "--json")
        graph.wait_for(lambda: "ready" in graph.log("sim"), 120, "ros sim")
        graph.depthq("drive", "ros", "drive", "--policy", str(checkpoint), "--log-every", "1")
        result = summary(graph.finish("sim", 600))
        graph.stop("drive")
        count, rate, latency = decisions(graph.log("drive"))
    return {**result, "decisions": count, "decision_hz": rate, "latency_ms_median": latency}


def replica_run(
    policy, rate: float, canyon: str, seed: int, latency_s: float, jpeg: bool,
    time_limit_s: float | None = None, bump_hz: float | None = None,
) -> dict[str, Any]:
    """One run of the node's core on the simulated robot, lock-step: frames at 30 Hz, the core's checks
    at 50 Hz, each command applied `latency_s` after it was decided."""
    robot = CanyonRobot(RobotSimConfig(canyon=canyon, seed=seed, time_limit_s=time_limit_s, bump_hz=bump_hz))
    driver = RobotDriver(policy, DriverConfig(decision_hz=rate))
    every = round(1.0 / (driver.config.check_hz * robot.dt))
    pending: list[tuple[float, Any]] = []
    try:
        while True:
            tick = robot.tick()
            if tick.end_reason is not None:
                return robot.summary(wall_s=1.0)
            if tick.image is not None:
                height, width = tick.image.shape[:2]
                frame = (Frame(tick.time, tick.jpeg) if jpeg else
                         Frame(tick.time, tick.image.tobytes(), "rgb8", height, width, width * 3))
                driver.on_frame(frame, tick.time)
            if robot.steps % every == 0 and (command := driver.tick(tick.time)) is not None:
                pending.append((tick.time + latency_s, command.twist))
            while pending and pending[0][0] <= tick.time + 1e-9:
                robot.receive(pending.pop(0)[1])
    finally:
        robot.close()


def replica(
    checkpoint: Path, canyons: tuple[str, ...], seeds: list[int], out: Path,
    settings: list[tuple[float, bool]], bump_hz: float | None = None,
) -> dict[str, Any]:
    """Mean distance per (latency, JPEG frames) setting over canyons × seeds, and each run's."""
    policy, rate, _ = robot_policy(PolicySpec("checkpoint", checkpoint))
    rows = []
    for latency, jpeg in settings:
        runs = [replica_run(policy, rate, c, s, latency, jpeg, bump_hz=bump_hz)
                for s in seeds for c in canyons]
        rows.append({"latency_s": latency, "frames": "jpeg" if jpeg else "raw", "bump_hz": bump_hz,
                     "distance_mean": statistics.mean(r["distance"] for r in runs),
                     "bumps": sum(r["end_reason"] in ("bump", "contact") for r in runs),
                     "runs": [{k: r[k] for k in ("canyon", "distance", "end_reason")} for r in runs]})
        row = rows[-1]
        print(f"latency {1e3 * latency:3.0f} ms, {row['frames']:>4} frames: {row['distance_mean']:.2f} m "
              f"mean over {len(runs)} runs, {row['bumps']} collisions", flush=True)
    result = {"checkpoint": str(checkpoint), "seeds": seeds, "canyons": list(canyons), "rows": rows}
    write_json(out / f"replica_bump{bump_hz or 'default'}.json", result)
    return result


def paired(folders: list[Path]) -> str:
    """docs/robot.md's table of finished measurements (`ros_fidelity.json` in each folder): a row per
    folder, then one of all their runs pooled."""
    groups = [(str(f), read_json(Path(f) / "ros_fidelity.json")["rows"]) for f in folders]
    lines = ["| runs | n | `depthq evaluate` | through ROS | ROS / evaluate | paired (m) | ends, evaluate "
             "/ ROS |", "|---|---|---|---|---|---|---|"]
    pooled = [r for _, group in groups for r in group]
    for name, rows in [*groups, ("all", pooled)]:
        ros, ev = statistics.mean(r["ros"] for r in rows), statistics.mean(r["evaluate"] for r in rows)
        ends = [sum(r[f"{side}_end"] == "end" for r in rows) for side in ("evaluate", "ros")]
        diff = mean_interval([r["ros"] - r["evaluate"] for r in rows], "+.2f")
        lines.append(f"| {name} | {len(rows)} | {ev:.2f} m | {ros:.2f} m | {ros / ev:.0%} | {diff} | "
                     f"{ends[0]} / {ends[1]} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.ros_fidelity",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("checkpoint", type=Path, nargs="?")
    parser.add_argument("--canyons", default="hard/eval:0-4", help="a canyon set, as evaluate's")
    parser.add_argument("--camera-hz", type=float, default=30.0)
    parser.add_argument("--out", type=Path)
    parser.add_argument("--replica", action="store_true", help="the ROS-free replica's settings instead")
    parser.add_argument("--settings", default="0:raw,0:jpeg,0.06:jpeg",
                        help="the replica's LATENCY_S:raw|jpeg settings, comma-separated [%(default)s]")
    parser.add_argument("--bump-hz", type=float, default=None,
                        help="the replica's bump checks per second [the evaluation's: the decision rate]")
    parser.add_argument("--seeds", default="0",
                        help="sensor-noise seeds, e.g. 0,1,2: one run per canyon and seed on each side")
    parser.add_argument("--paired", type=Path, nargs="+", metavar="FOLDER",
                        help="print the paired table of finished measurements (their --out folders) and stop")
    args = parser.parse_args(argv)
    if args.paired:
        print(paired(args.paired))
        return 0
    if args.checkpoint is None or args.out is None:
        parser.error("a CHECKPOINT and --out are needed to measure (or --paired FOLDER … to read)")
    # Ctrl-C and kill end the runs through RosGraph's cleanup, even in a script's background
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    canyons = parse_canyon_set(args.canyons)
    seeds = [int(s) for s in args.seeds.split(",")]
    if args.replica:
        pairs = (x.split(":") for x in args.settings.split(","))
        settings = [(float(latency), kind == "jpeg") for latency, kind in pairs]
        replica(args.checkpoint, canyons, seeds, args.out, settings, args.bump_hz)
        return 0
    checkpoint = args.checkpoint.resolve()
    rows = []
    for seed in seeds:
        folder = args.out / f"seed{seed}"
        ros = [ros_run(checkpoint, c, folder / c.replace("/", "_").replace(":", "_"), args.camera_hz, seed)
               for c in canyons]
        # what `depthq evaluate CHECKPOINT --canyons … --seed S --workers 1` drives: the checkpoint's rate
        config = EvalConfig(canyons=canyons, seed=seed)
        runs = evaluate(str(checkpoint), folder / "evaluate", config, workers=1, video=False)["runs"]
        rows += [{"canyon": c, "seed": seed, "ros": r["distance"], "evaluate": e["distance"],
                  "ros_end": r["end_reason"], "evaluate_end": e["end_reason"],
                  "decision_hz": r["decision_hz"],
                  "latency_ms_median": r["latency_ms_median"], "real_time_factor": r["real_time_factor"]}
                 for c, r, e in zip(canyons, ros, runs, strict=True)]
    total = {"ros": sum(r["ros"] for r in rows), "evaluate": sum(r["evaluate"] for r in rows)}
    result = {"checkpoint": str(args.checkpoint), "camera_hz": args.camera_hz, "rows": rows,
              "ros_distance_mean": total["ros"] / len(rows),
              "evaluate_distance_mean": total["evaluate"] / len(rows),
              "ratio": total["ros"] / total["evaluate"],
              "decision_hz_median": statistics.median(r["decision_hz"] for r in rows),
              "latency_ms_median": statistics.median(r["latency_ms_median"] for r in rows)}
    write_json(args.out / "ros_fidelity.json", result)
    for r in rows:
        print(f"{r['canyon']:>14} seed {r['seed']}  ros {r['ros']:6.2f} m ({r['ros_end']:>10})  evaluate "
              f"{r['evaluate']:6.2f} m ({r['evaluate_end']:>10})  {r['decision_hz']:.2f} Hz  "
              f"{r['latency_ms_median']:.0f} ms  "
              f"×{r['real_time_factor']} real time")
    print(json.dumps({k: v for k, v in result.items() if k != "rows"}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
