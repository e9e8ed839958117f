"""The stages of `depthq reproduce` and `depthq sweep`: collect → features → train every model of the
sweep → evaluate it (the tables, figures and report are `depthq.report`'s).

Output folder:

    OUT/reproduce.json            the sweep (a preset, or a widened one) and package version of the folder
    OUT/data/                     the dataset (docs/formats.md#dataset) and its feature cache
    OUT/models/<model>/           checkpoints, e.g. models/depth_n200_s1 (see depthq.pipeline.layout and
                                  depthq.checkpoint)
    OUT/eval/<name>/              evaluations: summary.json, runs.csv, trajectories (+ heuristic, ou)
    OUT/stages.json               measured seconds of every stage
    OUT/table1.md|csv, table2.md, fig4_qualitative.png, fig5_convergence.png, success_vs_runs.png,
    OUT/report.html               the results, all generated from the runs above (depthq.report)

Every stage is skipped when its output is complete (a dataset with all its runs, a checkpoint at
its last epoch, an evaluation with its summary.json, driven with the weights its checkpoint acts with
now: `evaluation_done`) and redone otherwise, so running the same
command again after an interruption resumes where it stopped. The stages are `depthq.parallel`
jobs: here one after the other, or on a Ray cluster one task per training and per evaluation.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

from depthq.blocks.device import resolve_device
from depthq.blocks.migrations import sweep_setup
from depthq.blocks.trunk import TRUNKS
from depthq.checkpoint import read_config, saved_epoch, settings_differing
from depthq.configio import atomic_write_bytes, provenance, read_json, write_json
from depthq.data.manifest import Dataset
from depthq.data.recorder import CollectConfig, collect, collection_complete
from depthq.errors import ConfigError
from depthq.evaluate.online import EvalConfig, evaluate, evaluation_done
from depthq.networks import get_network
from depthq.parallel import LOCAL, Executor, Job
from depthq.pipeline.sweep import Sweep
from depthq.policies.spec import PolicySpec
from depthq.progress import Bar
from depthq.train.config import TrainConfig
from depthq.train.features import features_ready, load_features
from depthq.train.trainer import train

REFERENCES = ("heuristic", "ou")  # the reference policies every sweep evaluates: Table I's last rows


@dataclass(frozen=True)
class Stage:
    """A job of the pipeline and how to tell that its output is already complete."""

    done: Callable[[], bool]
    job: Job

    @property
    def name(self) -> str:
        return self.job.name


def _trained(config: TrainConfig, folder: Path) -> bool:
    """Whether `folder` holds this training to its last epoch; one trained otherwise (a folder of a
    sweep run before a default changed) is an error rather than a model reused under a wrong name."""
    if saved_epoch(folder) < config.epochs:
        return False
    differing = settings_differing(read_config(folder), config)
    if differing:
        raise ConfigError(
            f"{folder} was trained with other settings than this sweep's model of that name (differs in: "
            f"{', '.join(differing)}); a default changed since? Name the setting (--set) or use another --out"
        )
    return True


def _features_ready(data: Path, collect_config: CollectConfig, frozen: list[tuple[str, int]]) -> bool:
    if not collection_complete(data, collect_config):
        return False  # decided before any stage runs: the collection may be still to come
    return all(features_ready(Dataset.open(data), trunk, size) for trunk, size in frozen)


def _features(data: Path, frozen: list[tuple[str, int]], device: str) -> None:
    """The cached features of every frozen trunk the sweep trains on, computed before any training
    reads them (trainings run in parallel on Ray)."""
    for trunk, size in frozen:
        load_features(Dataset.open(data), trunk, size, device=device)


def build_stages(sweep: Sweep, out: Path, device: str = "cpu", executor: Executor = LOCAL) -> list[Stage]:
    """The pipeline as an ordered list of resumable stages. Networks run on `device`. Collection and
    the reference policies' evaluations run on `executor` from here; on Ray, every training and
    every model's evaluation is a task of its own (`depthq.parallel.Job`)."""
    data = out / "data"
    collect_config, eval_config = sweep.collect, sweep.eval_config()
    # A model in several variants (a Coll-Q-Net in a lookahead sweep, `Model.settings`) runs once.
    models = list({m.name: m for m in sweep.models()}.values())
    configs = {m: sweep.train_config(m, str(data)) for m in models}
    # (a tuned trunk's training computes its activation cache itself: none of these features)
    frozen = sorted({(c.trunk, c.input_size) for c in configs.values()
                     if TRUNKS[c.trunk].frozen and not c.tune_stages})
    stages = [
        Stage(
            partial(collection_complete, data, collect_config),
            Job("collect", partial(collect, data, collect_config, sweep.workers, executor=executor)),
        ),
        Stage(
            partial(_features_ready, data, collect_config, frozen),
            Job("features", partial(_features, data, frozen, device)),
        ),
    ]
    for ref in REFERENCES:
        folder = out / "eval" / ref
        drive = partial(evaluate, PolicySpec(ref), folder, eval_config, sweep.workers, video=False,
                        executor=executor)
        stages.append(Stage(partial(evaluation_done, folder), Job(f"evaluate {ref}", drive)))
    # Every model's training and evaluation is a job of one core (a process of its own, locally one
    # per free core: docs/design.md#overlap): a training on one thread, so its bytes depend on no
    # machine's core count (torch sums floats in an order that depends on the thread count), and an
    # evaluation in one worker, its canyons in lock-step.
    gpus = 1.0 if device.startswith("cuda") else 0.0
    for model in models:
        config, ckpt, ev = configs[model], out / "models" / model.name, out / "eval" / model.name
        fit = partial(train, config, ckpt, progress=False, device=device, threads=1)
        drive = partial(evaluate, PolicySpec("checkpoint", ckpt), ev, eval_config, 1, progress=False,
                        device=device, video=False, executor=LOCAL)
        stages += [
            Stage(
                partial(_trained, config, ckpt),
                Job(f"train {model.name}", fit, ("features",), True, 1, gpus),
            ),
            Stage(
                partial(evaluation_done, ev),
                Job(f"evaluate {model.name}", drive, (f"train {model.name}",), True, 1, gpus),
            ),
        ]
    # One video, of the model the report shows: its first canyon driven again (the same run). Which
    # model that is, is known once every evaluation is done.
    evaluations = [stage.done for stage in stages if stage.name.startswith("evaluate ")]
    stages.append(
        Stage(
            partial(_video_done, out, sweep, evaluations),
            Job("video of the best Depth-Q-Net", partial(_video_of_best, out, sweep, eval_config, device)),
        )
    )
    return stages


def best_depth_eval(out: Path, sweep: Sweep) -> Path | None:
    """The evaluation with the longest mean distance of the featured network (`Network.featured`:
    Depth-Q-Net), for Fig. 4 and its video."""
    best, best_distance = None, -1.0
    for model in sweep.models():
        path = out / "eval" / model.name / "summary.json"
        if not get_network(model.net).featured or not path.is_file():
            continue
        if (distance := read_json(path)["summary"]["distance_mean"]) > best_distance:
            best, best_distance = path.parent, distance
    return best


def _video_done(out: Path, sweep: Sweep, evaluations: list[Callable[[], bool]]) -> bool:
    best = best_depth_eval(out, sweep)
    return all(done() for done in evaluations) and (best is None or (best / "video.mp4").is_file())


def _video_of_best(out: Path, sweep: Sweep, eval_config: EvalConfig, device: str) -> None:
    best = best_depth_eval(out, sweep)
    if best is None or (best / "video.mp4").is_file():
        return
    first = out / "video" / best.name
    config = replace(eval_config, canyons=eval_config.canyons[:1])
    spec = PolicySpec("checkpoint", out / "models" / best.name)
    evaluate(spec, first, config, workers=1, progress=False, device=device)
    atomic_write_bytes(best / "video.mp4", (first / "video.mp4").read_bytes())


def _claim(out: Path, sweep: Sweep) -> None:
    """Refuse a folder holding results of another setup (`check_claim`); mark it as this sweep's."""
    check_claim(out, sweep)
    write_json(out / "reproduce.json", {"sweep": sweep.record(), "provenance": provenance()})


def check_claim(out: Path, sweep: Sweep) -> None:
    """Refuse a folder holding results of another setup, writing nothing. The grid (networks, sizes,
    seeds, variants) may differ: models already there are reused. A folder holding only `data`
    (another sweep's dataset linked in, as the head-size experiment does) is claimed: the collection
    stage reuses it only if it holds the runs this sweep asks for."""
    marker = out / "reproduce.json"
    if marker.is_file():
        held = sweep_setup(read_json(marker))
        ours = sweep.setup()
        differ = [f"{k} {held.get(k)!r} there, {v!r} here" for k, v in ours.items() if held.get(k) != v]
        if differ:
            raise ConfigError(
                f"{out} holds results of {held.get('name')!r} with another setup ({'; '.join(differ)}); "
                f"use another --out for {sweep.name!r}"
            )
    elif out.exists() and any(p.name != "data" for p in out.iterdir()):
        raise ConfigError(f"{out} exists and is not a depthq reproduce folder; use another --out")


def run_stages(
    sweep: Sweep, out: Path, progress: bool = True, device: str = "auto", executor: Executor = LOCAL
) -> dict[str, float]:
    """Run (or resume) every stage of `sweep` into `out`, networks on `device`, the jobs on
    `executor`; returns the measured seconds per stage."""
    where = str(resolve_device(device))  # a device torch cannot use fails here, before any work
    out = Path(out).resolve()  # the same path on every node of a cluster
    executor.check_shared(out)
    _claim(out, sweep)
    times_path = out / "stages.json"
    times: dict[str, float] = read_json(times_path) if times_path.is_file() else {}
    stages = build_stages(sweep, out, where, executor)
    todo = [stage.job for stage in stages if not stage.done()]
    with Bar(
        total=len(stages),
        initial=len(stages) - len(todo),
        desc=sweep.name,
        unit="stage",
        position=0,
        disable=not progress,
        dynamic_ncols=True,
    ) as bar:
        for name, seconds in executor.run_jobs(todo):
            times = record_stage_time(times_path, name, seconds)
            bar.set_postfix_str(f"done: {name}")
            bar.update(1)
    return times


def record_stage_time(path: Path, name: str, seconds: float) -> dict[str, float]:
    """Add a stage's seconds to `path` (OUT/stages.json), merged with what the file holds now, not
    with what it held when this sweep started: two sweeps widening one folder at once (one per
    core) keep each other's times. Returns every stage's seconds."""
    times = read_json(path) if path.is_file() else {}
    times[name] = seconds
    write_json(path, times)
    return times
