"""A sweep's plan, as `depthq sweep --dry-run` and `depthq reproduce --dry-run` print it: its models,
the settings they train with where these differ from `depthq train`'s defaults, and each stage as
the `depthq` command that does the same work, marked done where the folder already holds it. Reads
the folder, writes nothing; a folder the sweep would refuse is refused here too."""

from __future__ import annotations

import dataclasses
import shlex
from pathlib import Path
from typing import Any

from depthq.data.recorder import CollectConfig, exploration_env
from depthq.evaluate.online import EvalConfig
from depthq.flags import build_config, config_flags, get_path
from depthq.pipeline.stages import REFERENCES, build_stages, check_claim
from depthq.pipeline.sweep import Sweep
from depthq.sim.canyon import PAPER
from depthq.train.config import TrainConfig

Flags = list[tuple[str, str | None]]  # (flag, its value as the flag takes it; None: a switch)


def flags_between(config: Any, base: Any, exclude: tuple[str, ...] = ()) -> Flags:
    """The flags (`depthq.flags`' spelling) that make `base` into `config`: one per field whose values
    differ, and one per required field (it has no default); none for the fields in `exclude`, nor for
    another network's own settings than `config`'s (`TrainConfig.settings`)."""
    out: Flags = []
    own = {flag.path for flag in config_flags(type(config), config)}
    for flag in config_flags(type(config)):
        if flag.path not in own:
            continue
        value = get_path(config, flag.path)
        required = flag.default is dataclasses.MISSING
        if flag.path in exclude or (not required and get_path(base, flag.path) == value):
            continue
        if flag.hint is bool:
            out.append((flag.name if value else f"--no-{flag.name[2:]}", None))
        else:
            out.append((flag.name, value_text(value)))
    return out


def value_text(value: Any) -> str:
    """A value as its flag takes it: none, true or false, a tuple's items joined by ','."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, tuple):
        return ",".join(map(str, value))
    return "none" if value is None else str(value)


def command(verb: str, *words: str, flags: Flags = ()) -> str:
    """`depthq VERB WORDS FLAGS`, quoted as a shell takes it."""
    given = [word for flag, value in flags for word in ((flag,) if value is None else (flag, value))]
    return shlex.join(["depthq", verb, *words, *given])


def collect_command(sweep: Sweep, data: Path) -> str:
    """`depthq collect` of the sweep's dataset, its flags on top of the collect verb's own start (the
    canyon family's exploration world)."""
    family = sweep.family
    base = CollectConfig(env=exploration_env(family=family))
    given: Flags = [] if family == PAPER else [("--env.world.family", family)]
    flags = given + flags_between(sweep.collect, base, exclude=("env.world.family",))
    return command("collect", flags=[("--out", str(data)), ("--workers", str(sweep.workers)), *flags])


def evaluate_command(policy: str, folder: Path, sweep: Sweep, workers: int, device: str) -> str:
    """`depthq evaluate` as a sweep's stage runs it (`Sweep.eval_config`), without a video."""
    config = sweep.eval_config()
    flags = flags_between(config, EvalConfig(canyons=config.canyons), exclude=("canyons",))
    return command("evaluate", policy, flags=[("--out", str(folder)), ("--canyons", sweep.canyons),
                                               ("--workers", str(workers)), ("--no-video", None),
                                               *_device(device), *flags])


def train_flags(config: TrainConfig) -> Flags:
    """`depthq train`'s flags for `config`: its network and data, and every setting that differs from
    that network's defaults."""
    return flags_between(config, build_config(TrainConfig, {"model": config.model, "data": config.data}))


def plan(sweep: Sweep, out: Path, device: str = "auto") -> str:
    """The text `--dry-run` prints for `sweep` into `out`."""
    out = Path(out).resolve()  # as `run_stages` names the folders
    check_claim(out, sweep)
    data = out / "data"
    models = list({m.name: m for m in sweep.models()}.values())  # a model in several variants runs once
    configs = {m.name: sweep.train_config(m, str(data)) for m in models}
    commands = {"collect": collect_command(sweep, data)}
    for ref in REFERENCES:
        commands[f"evaluate {ref}"] = evaluate_command(ref, out / "eval" / ref, sweep, sweep.workers, device)
    for name, config in configs.items():
        commands[f"train {name}"] = command("train", flags=[("--out", str(out / "models" / name)),
                                                           *_device(device), *train_flags(config)])
        commands[f"evaluate {name}"] = evaluate_command(str(out / "models" / name), out / "eval" / name,
                                                        sweep, 1, device)
    settings = {name: [f"{f}" if v is None else f"{f} {v}" for f, v in train_flags(config)
                       if f not in ("--model", "--data", "--runs", "--seed")]
                for name, config in configs.items()}
    shared = [s for s in next(iter(settings.values())) if all(s in own for own in settings.values())]
    stages = build_stages(sweep, out, device)
    todo = [stage.name for stage in stages if not stage.done()]
    lines = [
        f"{sweep.name}: {len(models)} models into {out}; a dry run, nothing written",
        f"dataset: {sweep.collect.runs} training and {sweep.collect.val_runs} validation runs in the "
        f"{sweep.family} canyons at {sweep.decision_hz:g} Hz; evaluated in {sweep.canyons}",
        f"every model trains with (where not depthq train's default): {' '.join(shared) or 'the defaults'}",
        "models: network, training runs, seed, the grid's setting (and what else differs from the above):",
    ]
    width = max(len(m.name) for m in models)
    for m in models:
        own = [s for s in settings[m.name] if s not in shared]
        variant = ", ".join(f"{k}={value_text(v)}" for k, v in m.settings) or "the preset's"
        lines.append(f"  {m.name:<{width}}  {m.net} {m.runs} {m.seed} {variant}"
                     + (f" ({' '.join(own)})" if own else ""))
    lines.append(f"stages ({len(todo)} of {len(stages)} to run), each as the command that does its work:")
    for stage in stages:
        mark = "to run" if stage.name in todo else "done  "
        what = commands.get(stage.name, f"# {stage.name}: {_WITHOUT_VERB.get(stage.name, '')}")
        lines.append(f"  [{mark}] {what}")
    lines.append("  then: the tables, figures and report.html of the folder (depthq.report.build)")
    return "\n".join(lines)


# The stages no verb runs alone, in words.
_WITHOUT_VERB = {
    "features": "the frozen trunk's features of every frame cached in the dataset (depthq train caches "
    "its own otherwise)",
    "video of the best Depth-Q-Net": "the first canyon driven again by the Depth-Q-Net that went "
    "farthest (once every evaluation is done), as its eval folder's video.mp4",
}


def _device(device: str) -> Flags:
    return [] if device == "auto" else [("--device", device)]
