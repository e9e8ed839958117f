"""Does a policy drive through ROS as it drives in `depthq evaluate`? A deployment fidelity check.

    python -m depthq.experiments.ros_fidelity CHECKPOINT --canyons hard/eval:0-4 --out runs/ros-fidelity

For each canyon: roscore, `depthq ros sim --canyon C` (the camera at --camera-hz, real time) and
`depthq ros drive --policy CHECKPOINT` as separate processes (`depthq.deploy.ros_graph`), one run; then
`depthq evaluate CHECKPOINT` in the same canyons. Written to OUT/ros_fidelity.json and printed per
canyon: the distance through ROS and in the evaluation, the end reasons, the node's decision rate and
median latency (frame stamp → command published, on the simulated clock). It drives `eval` canyons
by design: it measures the deployment, not a choice made on them (docs/robot.md#ros-fidelity).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path
from typing import Any

from depthq.configio import write_json
from depthq.deploy.ros_graph import RosGraph, decisions, summary
from depthq.evaluate.online import EvalConfig, evaluate, parse_canyon_set


def ros_run(checkpoint: Path, canyon: str, folder: Path, camera_hz: float) -> dict[str, Any]:
    """One run through a real master: the sim's summary with the node's rate and latency."""
    with RosGraph(folder) as graph:
        graph.depthq("sim", "ros", "sim", "--canyon", canyon, "--camera-hz", str(camera_hz), "--json")
        graph.wait_for(lambda: "ready" in graph.log("sim"), 120, "ros sim")
        graph.depthq("drive", "ros", "drive", "--policy", str(checkpoint), "--log-every", "1")
        result = summary(graph.finish("sim", 600))
        graph.stop("drive")
        count, rate, latency = decisions(graph.log("drive"))
    return {**result, "decisions": count, "decision_hz": rate, "latency_ms_median": latency}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("checkpoint", type=Path)
    parser.add_argument("--canyons", default="hard/eval:0-4", help="a canyon set, as evaluate's")
    parser.add_argument("--camera-hz", type=float, default=30.0)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    canyons = parse_canyon_set(args.canyons)
    checkpoint = args.checkpoint.resolve()
    ros = [ros_run(checkpoint, c, args.out / c.replace("/", "_").replace(":", "_"), args.camera_hz)
           for c in canyons]
    # what `depthq evaluate CHECKPOINT --canyons … --workers 1` drives: the checkpoint's own rate
    config = EvalConfig(canyons=canyons)
    runs = evaluate(str(checkpoint), args.out / "evaluate", config, workers=1, video=False)["runs"]
    rows = [{"canyon": c, "ros": r["distance"], "evaluate": e["distance"], "ros_end": r["end_reason"],
             "evaluate_end": e["end_reason"], "decision_hz": r["decision_hz"],
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
        print(f"{r['canyon']:>14}  ros {r['ros']:6.2f} m ({r['ros_end']:>10})  evaluate "
              f"{r['evaluate']:6.2f} m ({r['evaluate_end']:>10})  {r['decision_hz']:.2f} Hz  "
              f"{r['latency_ms_median']:.0f} ms  "
              f"×{r['real_time_factor']} real time")
    print(json.dumps({k: v for k, v in result.items() if k != "rows"}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
