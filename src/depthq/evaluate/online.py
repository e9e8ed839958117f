"""Drive a policy once in each evaluation canyon; metrics, trajectories, maps (docs/design.md#evaluation).

The canyons are driven in worker processes with one torch thread each, every worker its share in
lock-step (`depthq.evaluate.lockstep`) or one canyon at a time (`EvalConfig.lockstep`), with sensor
noise seeded by the canyon index, so the results are the same whatever the number of workers and
either way.
"""

from __future__ import annotations

import csv
import io
import time
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import torch

from depthq.blocks.device import resolve_device
from depthq.blocks.migrations import summary_config
from depthq.checkpoint import (
    CONFIG,
    chosen_weights,
    dataset_record,
    policy_record,
    read_config,
    weights_stem,
)
from depthq.configio import (
    OMIT_DEFAULT,
    Keyed,
    atomic_write_bytes,
    check_seed,
    complete_keyed,
    from_dict,
    keyed,
    provenance,
    read_json,
    to_dict,
    write_json,
)
from depthq.control.heuristic import DepthHeuristic
from depthq.errors import ConfigError
from depthq.evaluate.figures import plot_fig4, plot_trajectories
from depthq.evaluate.lockstep import Lane, drive_lockstep, lane_policies
from depthq.evaluate.metrics import summarize
from depthq.evaluate.run_record import FIG4_EVERY, RunRecord
from depthq.evaluate.video import write_video
from depthq.host import host_fingerprint
from depthq.networks import acting_classes
from depthq.parallel import LOCAL, Executor
from depthq.policies.onnx import OnnxPolicy
from depthq.policies.registry import make_policy
from depthq.policies.spec import PolicySpec
from depthq.progress import Bar
from depthq.sim.canyon import (
    FAMILIES,
    FRESH,
    N_EVAL_CANYONS,
    PAPER,
    CanyonId,
    eval_canyon_ids,
    eval_set,
    split_family,
)
from depthq.sim.env import CanyonEnv, EnvConfig, parse_canyon
from depthq.sim.world import DEFAULT_DECISION_HZ, WorldConfig, world_for

RUN_FIELDS = (
    "canyon",
    "distance",
    "path_length",
    "success",
    "end_reason",
    "steps",
    "imitation_loss",
    "decision_ms_median",
    "progress",
    "distance_to_collision",
    "closest",
    "canyon_length",
)

SUMMARY = "summary.json"  # written last: a folder with it holds a finished evaluation


@dataclass(frozen=True)
class EvalConfig:
    """How a policy is evaluated; stored in every summary."""

    # The canyons driven, one run each (ids such as 'eval:3', 'hard/val:1000'), all of one family.
    canyons: tuple[str, ...] = tuple(f"eval:{i}" for i in range(N_EVAL_CANYONS))
    # Seconds per run; none: the canyons' family's (45 s for the paper's).
    time_limit_s: float | None = None
    # Seeds the sensor noise and the OU policy: canyon i uses seed + i.
    seed: int = 0
    # A checkpoint's weights: best, last (= final), average or epoch:N; none: its own (`TrainConfig.weights`).
    weights: str | None = None
    # Decisions (camera frames) per second; none: the rate a checkpoint or ONNX file records, else the
    # default.
    decision_hz: float | None = None
    # Drive each worker's canyons together, one batched decision per step (docs/design.md#lockstep):
    # the runs of --no-lockstep, which drives them one after the other.
    lockstep: bool = True
    # Each network's own acting settings (`Network.Acting`), by its name: the evaluated policy's network
    # acts by its own (`--depth.rule`, ..., stored under its name in a summary), one without any by its
    # rule alone.
    acting: Keyed = field(default_factory=Keyed, metadata=keyed(acting_classes))
    # How the canyons look: flat, colours, textured, heldout, broad or a folder of images
    # (docs/design.md#looks); none: the family's own. Any policy drives in any look.
    look: str | None = field(default=None, metadata=OMIT_DEFAULT)

    def __post_init__(self) -> None:
        check_seed(self.seed)
        if not self.canyons:
            raise ConfigError("an evaluation drives at least one canyon; --canyons names none")
        repeated = sorted({c for c in self.canyons if self.canyons.count(c) > 1})
        if repeated:
            raise ConfigError(f"--canyons names {', '.join(repeated)} more than once; each is driven once")
        families = sorted({CanyonId.parse(c).family for c in self.canyons})
        if len(families) != 1:
            raise ConfigError(f"the canyons of one evaluation belong to one family, got {families}")
        _ = self.env  # checks the rate
        if self.time_limit_s is not None and not self.time_limit_s > 0:
            raise ConfigError(f"--time-limit must be > 0, got {self.time_limit_s}")
        if self.weights is not None:
            weights_stem(self.weights)
        complete_keyed(self)  # every network's acting settings, each checked by its own class

    @property
    def family(self) -> str:
        return CanyonId.parse(self.canyons[0]).family

    @property
    def env(self) -> EnvConfig:
        world = WorldConfig() if self.decision_hz is None else WorldConfig(decision_hz=self.decision_hz)
        limit = FAMILIES[self.family].time_limit_s if self.time_limit_s is None else self.time_limit_s
        world = world_for(world, self.family)
        world = world if self.look is None else replace(world, look=self.look)
        return EnvConfig(world=world, time_limit_s=limit)


def at_policy_rate(config: EvalConfig, spec: PolicySpec) -> EvalConfig:
    """`config`, at the policy's decision rate (`decision_rate`) when it names none."""
    if config.decision_hz is not None:
        return config
    return replace(config, decision_hz=decision_rate(spec))


def decision_rate(spec: PolicySpec) -> float:
    """The decision rate a checkpoint or an exported graph records (its training data's); the default
    for any other policy, and for a graph that records none (an older export)."""
    if spec.kind == "onnx":  # the rate is in the graph's metadata (depthq.deploy.onnx_export)
        return OnnxPolicy(spec.path, threads=1).decision_hz or DEFAULT_DECISION_HZ
    if spec.checkpoint is None:
        return DEFAULT_DECISION_HZ
    return policy_record(read_config(spec.checkpoint)).decision_hz


def default_canyons(spec: PolicySpec) -> str:
    """The evaluation canyons of the family a checkpoint's or an exported graph's data was collected in
    ('eval' for the paper's, 'hard/eval', ...); the paper's for any other policy and for a robot's
    recording."""
    if spec.kind == "onnx":
        return eval_set(OnnxPolicy(spec.path, threads=1).family or PAPER)
    if spec.checkpoint is None:
        return "eval"
    return eval_set(dataset_record(read_config(spec.checkpoint)).family or PAPER)


def parse_canyon_set(text: str) -> tuple[str, ...]:
    """'eval' (all 20), 'eval:0-4' (a range), 'eval:2,7' (a list) or a range of `val` canyons
    ('val:1000-1019'; design choices are made there, the `eval` canyons are the test set) or of a
    fresh stream that no project code uses ('stream7:0-19'); a family other than the paper's in
    front: 'hard/eval', 'hard/val:1000-1019'."""
    family, rest = split_family(text)
    stream, colon, which = rest.partition(":")
    fresh = stream.startswith(FRESH)
    if (stream not in ("eval", "val") and not fresh) or (stream != "eval" and not which):
        raise ConfigError(
            f"unknown canyon set {text!r}: expected 'eval', 'eval:0-4', 'eval:2,7', 'val:1000-1019' "
            f"or '{FRESH}7:0-19', optionally after a family, e.g. 'hard/val:1000-1019'"
        )
    if not colon:
        return tuple(str(c) for c in eval_canyon_ids(family))
    try:
        if not which:
            raise ValueError
        if "-" in which:
            lo, hi = (int(v) for v in which.split("-"))
            indices = list(range(lo, hi + 1))
        else:
            indices = [int(v) for v in which.split(",")]
    except ValueError:
        raise ConfigError(f"unknown canyon set {text!r}: expected e.g. 'eval:0-4', 'val:1000-1019'") from None
    if not indices:
        raise ConfigError(f"canyon set {text!r} is empty")
    return tuple(str(CanyonId(stream, i, family)) for i in indices)


def drive(
    policy, env, expert, canyon: str, seed: int, keep_every: int = 0, video: bool = False
) -> dict[str, Any]:
    """One run, alone: the policy drives, the expert is asked on the same observations. `keep_every`
    keeps Fig. 4 snapshots; `video` keeps every decision (the camera frame at half size) for the MP4."""
    obs, info = env.reset(seed=seed, options={"canyon": parse_canyon(canyon)})
    policy.reset(seed)
    record, done = RunRecord(canyon, info, keep_every, video), False
    while not done:
        expert_action = expert.act(obs)
        t0 = time.perf_counter()
        action = float(np.clip(policy.act(obs), env.action_space.low[0], env.action_space.high[0]))
        ms = (time.perf_counter() - t0) * 1e3
        before = obs
        obs, _, terminated, truncated, info = env.step(np.array([action], np.float32))
        record.add(before, expert_action, action, ms, getattr(policy, "last_values", None), obs, info)
        done = terminated or truncated
    return record.result(info)


def _key(canyon: str) -> str:
    """A canyon's name as part of an array's name in trajectories.npz: 'eval_3', 'hard_eval_3'."""
    return canyon.replace(":", "_").replace("/", "_")


class _EvalWorker:
    """One policy and its simulators, driving share after share of the canyons (a worker of
    `depthq.parallel`): a share's canyons in lock-step (`depthq.evaluate.lockstep`) or one by one."""

    def __init__(
        self, policy_spec: PolicySpec, config: EvalConfig, device: str = "cpu", video: bool = False
    ) -> None:
        # Same float sums in every process (results independent of W), and a batched decision's
        # values those of one frame alone (docs/design.md#lockstep).
        torch.set_num_threads(1)
        self.config, self.video = config, video
        self.make_policy = partial(
            make_policy, policy_spec, seed=config.seed, weights=config.weights, device=device,
            acting=config.acting, threads=1,  # an ONNX session's, for the same reasons
        )
        self.policy = self.make_policy()
        self.envs, self.expert = [CanyonEnv(config.env)], DepthHeuristic()

    def __call__(self, share: tuple[tuple[int, str], ...]) -> list[tuple[int, dict[str, Any]]]:
        # the first canyon keeps Fig. 4 snapshots and, when wanted, the video's frames
        lanes = [
            Lane(canyon, self.config.seed + CanyonId.parse(canyon).index, FIG4_EVERY if k == 0 else 0,
                 self.video and k == 0)
            for k, canyon in share
        ]
        if self.config.lockstep:
            while len(self.envs) < len(lanes):
                self.envs.append(CanyonEnv(self.config.env))
            policies = lane_policies(self.policy, self.make_policy, len(lanes))
            runs = drive_lockstep(policies, self.envs[: len(lanes)], self.expert, lanes)
        else:
            runs = [drive(self.policy, self.envs[0], self.expert, lane.canyon, lane.seed, lane.keep_every,
                          lane.video) for lane in lanes]
        return [(k, run) for (k, _), run in zip(share, runs, strict=True)]

    def close(self) -> None:
        for env in self.envs:
            env.close()


def shares(canyons: tuple[str, ...], lockstep: bool, workers: int) -> list[tuple[tuple[int, str], ...]]:
    """The canyons as the workers' tasks, (position, canyon) each: in lock-step one share per worker,
    dealt round-robin (their sizes differ by one at most); else a canyon per task, as workers free up."""
    tasks = tuple(enumerate(canyons))
    n = min(workers, len(tasks)) if lockstep else len(tasks)
    return [tasks[w::n] for w in range(n)]


def drive_canyons(
    policy_spec: PolicySpec,
    config: EvalConfig,
    workers: int = 2,
    progress: bool = False,
    device: str = "cpu",
    video: bool = False,
    executor: Executor = LOCAL,
) -> list[dict[str, Any]]:
    """Every canyon of `config` driven by `policy_spec` (a checkpoint by its absolute path) on torch
    `device`, in `executor`'s `workers`: the runs (`RunRecord.result`) in `config.canyons`' order."""
    runs: dict[int, dict[str, Any]] = {}
    make_worker = partial(_EvalWorker, policy_spec, config, device, video)
    with Bar(
        total=len(config.canyons),
        desc=f"evaluate {policy_spec.name}",
        unit="canyon",
        disable=not progress,
        dynamic_ncols=True,
    ) as bar:
        tasks, gpu = shares(config.canyons, config.lockstep, workers), device.startswith("cuda")
        for _, done in executor.run(make_worker, tasks, workers, "evaluation", gpu):
            runs.update(done)
            bar.update(len(done))
            bar.set_postfix(success=sum(r["success"] for r in runs.values()))
    return [runs[k] for k in sorted(runs)]


def evaluate(
    policy_spec: str | PolicySpec,
    out: Path,
    config: EvalConfig = EvalConfig(),
    workers: int = 2,
    progress: bool = True,
    device: str = "auto",
    video: bool = True,
    executor: Executor = LOCAL,
    data: Path | None = None,
) -> dict[str, Any]:
    """Evaluate `policy_spec` (a string is parsed here, once: 'heuristic', 'ou', a checkpoint folder or
    'onnx:PATH') and write its files to `out`; a Q-net runs on `device` (`depthq.blocks.device`).
    `video`: the first canyon as video.mp4 (`depthq.evaluate.video`); the canyons are driven by
    `executor` (`depthq.parallel`).
    `data`: a checkpoint's dataset for the offline metrics, when it is no longer where it was
    (`depthq.train.offline_metric`)."""
    if workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {workers}")

    where = str(resolve_device(device))
    policy_spec = PolicySpec.parse(policy_spec)  # a bad spec fails here, before any worker starts
    description = make_policy(
        policy_spec, seed=config.seed, weights=config.weights, device=where, acting=config.acting
    ).describe()
    dataset = None  # a checkpoint's, for its offline metrics: found (or refused) before any drive
    if policy_spec.checkpoint is not None:  # which every worker loads: the same path on every node
        # the training stack (tensorboard included) only for a checkpoint, not in every worker
        from depthq.train.offline_metric import training_data

        policy_spec = policy_spec.resolved()
        executor.check_shared(policy_spec.checkpoint)
        dataset = training_data(read_config(policy_spec.checkpoint), data)
    config = at_policy_rate(config, policy_spec)
    (Path(out) / SUMMARY).unlink(missing_ok=True)  # an evaluation redone reads as not done until it is
    _remove_temporaries(Path(out))
    start = time.perf_counter()
    ordered = drive_canyons(policy_spec, config, workers, progress, where, video, executor)
    offline = None
    if dataset is not None:
        from depthq.train.offline_metric import offline_metric  # the training stack, as above

        offline = offline_metric(policy_spec.checkpoint, dataset, weights=config.weights)
    summary = {
        "policy": description,
        "config": to_dict(config),
        "look": config.env.world.look,
        "provenance": provenance(),
        "host": host_fingerprint(threads=1),  # every worker decides on one torch thread
        "summary": summarize(ordered),
        **({"offline": offline} if offline else {}),
        "runs": [{f: r[f] for f in RUN_FIELDS} for r in ordered],
        "seconds": round(time.perf_counter() - start, 2),
    }
    _write(out, summary, ordered, video_fps=config.env.world.decision_hz)
    return summary


def recorded_config(summary: dict[str, Any]) -> EvalConfig:
    """The config a summary (summary.json) records, one written by an older depthq read as today's
    (`depthq.blocks.migrations.summary_config`)."""
    return from_dict(EvalConfig, summary_config(summary["config"]))


def evaluation_done(folder: Path) -> bool:
    """Whether `folder` holds a finished evaluation (its summary.json) of its policy as the policy acts
    now: a checkpoint evaluated with its own default weights must have been driven with the weights it
    chooses today (`depthq.checkpoint.chosen_weights`: a weight average that fails its check acts
    with the final weights)."""
    path = Path(folder) / SUMMARY
    if not path.is_file():
        return False
    summary = read_json(path)
    checkpoint = Path(summary["policy"].get("checkpoint") or "-")
    if summary["config"].get("weights") is not None or not (checkpoint / CONFIG).is_file():
        return True  # weights chosen explicitly, or not a checkpoint (or no longer there to ask)
    acts = weights_stem(chosen_weights(read_config(checkpoint), None, checkpoint))
    return summary["policy"]["weights"] == acts


def _remove_temporaries(out: Path) -> None:
    """The temporary files a killed evaluation left in `out` half-written: its files' (`.NAME.*.tmp`) and
    its video's (`.video.mp4.*.mp4`, `depthq.evaluate.video`). Its one writer is this process: `depthq
    .lock` holds the folder for the verb, and for the sweep that runs it."""
    for tmp in (*out.glob(".*.tmp"), *out.glob(".*.mp4")):
        tmp.unlink(missing_ok=True)


def _write(out: Path, summary: dict[str, Any], runs: list[dict[str, Any]], video_fps: float) -> None:
    """summary.json last: a folder with a summary is complete."""
    out.mkdir(parents=True, exist_ok=True)
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=RUN_FIELDS)
    writer.writeheader()
    writer.writerows(summary["runs"])
    atomic_write_bytes(out / "runs.csv", text.getvalue().encode())
    buf = io.BytesIO()
    np.savez_compressed(
        buf,
        **{f"{_key(r['canyon'])}_poses": r["poses"] for r in runs},
        **{f"{_key(r['canyon'])}_actions": r["actions"] for r in runs},
    )
    atomic_write_bytes(out / "trajectories.npz", buf.getvalue())
    plot_trajectories(runs, out / "trajectories.png", title=summary["policy"]["policy"])
    snaps = runs[0]["snapshots"]
    if snaps:
        plot_fig4(snaps, runs[0], summary["policy"], out / "fig4_qualitative.png")
    if runs[0]["video"]:
        write_video(runs[0]["video"], runs[0], summary["policy"], out / "video.mp4", video_fps)
    write_json(out / SUMMARY, summary)
