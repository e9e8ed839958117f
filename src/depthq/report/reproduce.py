"""`depthq reproduce`: collect → train every (network, subset, seed) → evaluate → tables, figures, report.

Output folder:

    OUT/reproduce.json            the preset and package version this folder belongs to
    OUT/data/                     the dataset (see README "Dataset on disk") and its feature cache
    OUT/models/<net>_n<N>_s<S>/   checkpoints, e.g. models/depth_n200_s1 (see depthq.train.checkpoint)
    OUT/eval/<name>/              evaluations: summary.json, runs.csv, trajectories (+ heuristic, ou)
    OUT/stages.json               measured seconds of every stage
    OUT/table1.md|csv, table2.md, fig4_qualitative.png, fig5_convergence.png, success_vs_runs.png,
    OUT/report.html               the results, all generated from the runs above

Every stage is skipped when its output is complete (a dataset with all its runs, a checkpoint at
its last epoch, an evaluation with its summary.json) and redone otherwise, so running the same
command again after an interruption resumes where it stopped.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from tqdm import tqdm

from depthq.configio import atomic_write_bytes, provenance, read_json, to_dict, write_json
from depthq.errors import ConfigError
from depthq.parallel import LOCAL, Executor
from depthq.report.build import best_depth_eval, build_report
from depthq.report.layout import NETS, model_name
from depthq.report.presets import Preset, get_preset

if TYPE_CHECKING:
    from depthq.evaluate.evaluate import EvalConfig


@dataclass(frozen=True)
class Stage:
    name: str
    done: Callable[[], bool]
    run: Callable[[], object]


def _eval_done(folder: Path) -> bool:
    return (folder / "summary.json").is_file()


def build_stages(preset: Preset, out: Path, device: str = "cpu", executor: Executor = LOCAL) -> list[Stage]:
    """The pipeline as an ordered list of resumable stages; networks run on `device`, collection
    and evaluation tasks on `executor` (training runs here, one model after the other)."""
    from depthq.data.collect import CollectConfig, collect, collection_complete, exploration_env
    from depthq.data.manifest import Dataset
    from depthq.evaluate.evaluate import EvalConfig, evaluate, parse_canyon_set
    from depthq.nets.trunk import DEFAULT_TRUNK, INPUT_SIZE
    from depthq.train.checkpoint import saved_epoch
    from depthq.train.config import TrainConfig
    from depthq.train.features import features_ready, load_features
    from depthq.train.trainer import train

    data = out / "data"
    collect_config = CollectConfig(
        runs=preset.runs,
        val_runs=preset.val_runs,
        max_steps=preset.max_steps,
        env=exploration_env(preset.decision_hz),
    )
    eval_config = EvalConfig(
        canyons=parse_canyon_set(preset.canyons),
        time_limit_s=preset.time_limit_s,
        decision_hz=preset.decision_hz,
    )
    stages = [
        Stage(
            "collect",
            lambda: collection_complete(data, collect_config),
            lambda: collect(data, collect_config, seed=0, workers=preset.workers, executor=executor),
        ),
        Stage(
            "features",
            lambda: features_ready(Dataset.open(data), DEFAULT_TRUNK, INPUT_SIZE),
            lambda: load_features(Dataset.open(data), DEFAULT_TRUNK, INPUT_SIZE, device=device),
        ),
    ]
    for ref in ("heuristic", "ou"):
        folder = out / "eval" / ref
        stages.append(
            Stage(
                f"evaluate {ref}",
                lambda f=folder: _eval_done(f),
                lambda r=ref, f=folder: evaluate(
                    r, f, eval_config, preset.workers, video=False, executor=executor
                ),
            )
        )
    extra = {} if preset.epochs is None else {"epochs": preset.epochs}
    # Seed-major: an interrupted or still-running `paper` already holds a whole table for seed 0.
    for seed in preset.seeds:
        for n in preset.subsets:
            for net in NETS:
                name = model_name(net, n, seed)
                config = TrainConfig(
                    model=net,
                    data=str(data),
                    runs=n,
                    seed=seed,
                    train_batches=preset.train_batches,
                    val_batches=preset.val_batches,
                    **extra,
                )
                ckpt, ev = out / "models" / name, out / "eval" / name
                stages.append(
                    Stage(
                        f"train {name}",
                        lambda c=config, f=ckpt: saved_epoch(f) >= c.epochs,
                        lambda c=config, f=ckpt: train(c, f, device=device),
                    )
                )
                stages.append(
                    Stage(
                        f"evaluate {name}",
                        lambda f=ev: _eval_done(f),
                        lambda f=ev, c=ckpt: evaluate(
                            str(c), f, eval_config, preset.workers, device, video=False, executor=executor
                        ),
                    )
                )
    # One video, of the model the report shows: its first canyon driven again (the same run).
    stages.append(
        Stage(
            "video of the best Depth-Q-Net",
            lambda: (best := best_depth_eval(out, preset)) is None or (best / "video.mp4").is_file(),
            lambda: _video_of_best(out, preset, eval_config, device),
        )
    )
    return stages


def _video_of_best(out: Path, preset: Preset, eval_config: EvalConfig, device: str) -> None:
    from depthq.evaluate.evaluate import evaluate

    best = best_depth_eval(out, preset)
    first = out / "video" / best.name
    config = replace(eval_config, canyons=eval_config.canyons[:1])
    evaluate(str(out / "models" / best.name), first, config, workers=1, progress=False, device=device)
    atomic_write_bytes(best / "video.mp4", (first / "video.mp4").read_bytes())


def _claim(out: Path, preset: Preset) -> None:
    """Refuse a folder holding another preset's results; mark a new one as this preset's."""
    marker = out / "reproduce.json"
    if marker.is_file():
        held = read_json(marker).get("preset", {})
        if held != json.loads(json.dumps(to_dict(preset))):
            raise ConfigError(
                f"{out} holds results of preset {held.get('name')!r} with another configuration; "
                f"use another --out for preset {preset.name!r}"
            )
    elif out.exists() and any(out.iterdir()):
        raise ConfigError(f"{out} exists and is not a depthq reproduce folder; use another --out")
    write_json(marker, {"preset": to_dict(preset), "provenance": provenance()})


def reproduce(
    preset_name: str, out: Path, progress: bool = True, device: str = "auto", executor: Executor = LOCAL
) -> dict[str, float]:
    """Run (or resume) the whole pipeline, networks on `device`, collection and evaluation on
    `executor`; returns the measured seconds per stage."""
    from depthq.nets.device import resolve_device

    where = str(resolve_device(device))  # a device torch cannot use fails here, before any work
    preset = get_preset(preset_name)
    out = Path(out)
    _claim(out, preset)
    times_path = out / "stages.json"
    times: dict[str, float] = read_json(times_path) if times_path.is_file() else {}
    stages = build_stages(preset, out, where, executor)
    with tqdm(
        total=len(stages),
        desc=f"reproduce {preset.name}",
        unit="stage",
        position=0,
        disable=not progress,
        dynamic_ncols=True,
    ) as bar:
        for stage in stages:
            if stage.done():
                bar.update(1)
                continue
            bar.set_postfix_str(stage.name)
            start = time.perf_counter()
            stage.run()
            times[stage.name] = round(time.perf_counter() - start, 1)
            write_json(times_path, times)
            bar.update(1)
    start = time.perf_counter()
    build_report(out, preset, times)
    times["report"] = round(time.perf_counter() - start, 1)
    write_json(times_path, times)
    return times
