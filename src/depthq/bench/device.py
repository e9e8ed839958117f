"""The whole speed picture on one device in one command (`depthq bench device`): a preset run with
its stage times, then the component benchmarks on what it made, into one JSON record; for the day a
GPU is lent (docs/benchmarks.md#gpu), and the same on a CPU."""

from __future__ import annotations

from pathlib import Path

from depthq.bench.features import bench_features
from depthq.bench.policy import bench_policy
from depthq.bench.sim import bench_sim
from depthq.bench.step import bench_step
from depthq.bench.train import bench_train
from depthq.blocks.device import resolve_device
from depthq.configio import write_json
from depthq.host import host_fingerprint
from depthq.parallel import cores
from depthq.pipeline.presets import get_preset
from depthq.pipeline.stages import run_stages
from depthq.sim.canyon import PAPER

RESULT = "bench.json"


def bench_device(out: Path, preset: str = "quick", device: str = "auto", seconds: float = 10.0,
                 steps: int = 200, progress: bool = True) -> dict:
    """Run (or resume) `preset` into OUT/sweep with its networks on `device`, then measure on its data
    and its first model: trunk features, head training (`seconds`), one decision, an evaluation
    step's parts, env steps/s on every core (`steps` each); writes OUT/bench.json and returns it."""
    sweep = get_preset(preset)
    where = str(resolve_device(device))  # a device torch cannot use fails here, before any work
    out = Path(out).resolve()
    stages = run_stages(sweep, out / "sweep", progress=progress, device=where)
    model = out / "sweep" / "models" / sweep.models()[0].name
    canyon = f"{sweep.collect.env.world.family}/val:1000".removeprefix(f"{PAPER}/")
    frames = min(1024, 64 * sweep.collect.runs)
    result = {
        "preset": preset,
        "device": where,
        "host": host_fingerprint(),
        "stages_s": stages,
        "stage_total_s": round(sum(stages.values()), 1),
        "features": bench_features(out / "sweep" / "data", n=frames, device=where),
        "train": bench_train(seconds, device=where),
        "policy": bench_policy([str(model)], device=where),
        "step": bench_step(str(model), canyon, device=where),
        "sim": bench_sim(steps, workers=cores(), family=sweep.collect.env.world.family),
    }
    write_json(out / RESULT, result)
    return result
