"""The fidelity probe (`depthq probe`): how close our exploration data and our world are to the
original's, fast. A calibration experiment, the one with a verb of its own.

Three parts, each on the `train` and `val` canyon streams only (the `eval` canyons are the test set):

- `stats`: OU exploration runs without a camera (the LiDAR decides when a run ends), at each
  candidate decision rate: frames per kept run, the share of runs kept, and the samples that
  Table II's sizes would get, next to the paper's. This is how the decision rate is calibrated.
- `oracle`: a perfect predictor of a training signal with its selection rule (`depthq.evaluate.oracle`:
  by default the true next bins of each candidate action, a perfect Depth-Q-Net), driven in `val`
  canyons: what the signal can reach at a rate, whatever the network.
- `agreement`: for evaluation folders, how often their policy took the oracle's action along its own
  runs (`depthq.evaluate.oracle.agreement`), with per-step arrays and a figure.
- `dqn`: a small dataset collected at a rate, one Depth-Q-Net trained on it and driven in `val`
  canyons (at the data's rate): the end-to-end check, in a few minutes.
- `dead`: for checkpoint folders, how many of a Depth-Q-Net's outputs are dead, 0 for every
  validation frame and candidate action (`depthq.train.dead_outputs`), from the feature cache.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from depthq.data.recorder import CollectConfig, collect, collect_run, exploration_env
from depthq.data.samples import HORIZON, MIN_FRAMES
from depthq.data.stats import PAPER_TABLE2
from depthq.errors import ConfigError
from depthq.evaluate.figures import plot_agreement
from depthq.evaluate.online import EvalConfig, evaluate, parse_canyon_set
from depthq.evaluate.oracle import Oracle, agreement, drive_oracle
from depthq.networks import DepthQNet
from depthq.parallel import worker_context
from depthq.policies.spec import PolicySpec
from depthq.progress import Bar
from depthq.sim.env import CanyonEnv
from depthq.train.config import DEFAULT_EPOCHS, TrainConfig
from depthq.train.dead_outputs import count_dead_outputs
from depthq.train.trainer import train

PARTS = ("stats", "oracle", "dqn", "agreement", "dead")
VAL_CANYONS = "val:1000-1019"  # far from the validation runs' canyons (val:0..89)
PAPER_FRAMES_PER_RUN = sum(s for s, _ in PAPER_TABLE2.values()) / sum(PAPER_TABLE2) + 1


def ou_statistics(
    decision_hz: float, runs: int, seed: int = 0, max_yaw_rate: float | None = None, family: str = "paper"
) -> dict:
    """Table II statistics of `runs` OU runs in the first `runs` training canyons of `family`, at
    `decision_hz`."""
    env_config = exploration_env(decision_hz, family=family)
    if max_yaw_rate is not None:
        env_config = replace(env_config, world=replace(env_config.world, max_yaw_rate=max_yaw_rate))
    config = CollectConfig(runs=runs, val_runs=0, env=env_config)
    env = CanyonEnv(env_config, camera=False)
    lengths, bumped = [], []
    try:
        for index in range(runs):
            run = collect_run(env, config, seed, "train", index)
            lengths.append(run.n_frames)
            bumped.append(run.meta.collision)
    finally:
        env.close()
    lengths = np.array(lengths)
    kept = lengths[lengths >= MIN_FRAMES]
    per_run = float(kept.mean() - 1) if len(kept) else 0.0  # samples: frames with an action
    return {
        "decision_hz": decision_hz,
        "max_yaw_rate": env_config.world.max_yaw_rate,
        "runs": runs,
        "kept_share": len(kept) / runs,
        "frames_per_kept_run": float(kept.mean()) if len(kept) else 0.0,
        "frames_per_kept_run_std": float(kept.std()) if len(kept) else 0.0,
        "bumped_share": float(np.mean(bumped)),
        "samples": {n: round(n * per_run) for n in PAPER_TABLE2},
        "samples_without_collision": {n: round(n * (per_run - HORIZON)) for n in PAPER_TABLE2},
    }


def small_dqn(
    decision_hz: float, out: Path, runs: int, canyons: str = VAL_CANYONS, epochs: int = DEFAULT_EPOCHS
) -> dict:
    """Collect `runs` OU runs at `decision_hz`, train a Depth-Q-Net on them, drive it in `canyons`."""
    data = out / "data"
    config = CollectConfig(runs=runs, val_runs=max(2, runs // 10), env=exploration_env(decision_hz))
    collect(data, config, workers=2)
    ckpt = train(TrainConfig(model=DepthQNet.name, data=str(data), runs=runs, epochs=epochs),
                 out / f"{DepthQNet.name}_n{runs}")
    config = EvalConfig(canyons=parse_canyon_set(canyons))
    summary = evaluate(PolicySpec("checkpoint", ckpt), out / "eval", config, video=False)
    return {**summary["summary"], "offline": summary.get("offline")}


def _parallel(fn, args_list: list[tuple]) -> list:
    with ProcessPoolExecutor(max_workers=2, mp_context=worker_context()) as pool:
        futures = [pool.submit(fn, *args) for args in args_list]
        return [f.result() for f in Bar(futures, desc=fn.__name__, unit="task")]


def probe(
    rates: tuple[float, ...],
    parts: tuple[str, ...],
    out: Path,
    stats_runs: int = 300,
    dqn_runs: int = 200,
    canyons: str = VAL_CANYONS,
    epochs: int = DEFAULT_EPOCHS,
    family: str = "paper",
    oracles: tuple[Oracle, ...] = (Oracle(),),
    evaluations: tuple[Path, ...] = (),
    predictions: bool = False,
    checkpoints: tuple[Path, ...] = (),
) -> dict[str, Any]:
    """Run the chosen parts at each rate; returns (and the CLI writes) everything measured. `family`:
    the canyon family of the OU statistics (the oracle and the small net drive in `canyons`);
    `oracles`: those the oracle and agreement parts use; `evaluations`: the agreement part's folders
    (`predictions`: with the checkpoint's own values re-predicted at every step); `checkpoints`: the
    dead part's."""
    unknown = sorted(set(parts) - set(PARTS))
    if unknown:
        raise ConfigError(f"unknown probe part(s) {unknown}; expected some of {PARTS}")
    if "dead" in parts and not checkpoints:
        raise ConfigError("probe part 'dead' needs checkpoint folders (--checkpoints)")
    result: dict[str, Any] = {"rates": list(rates)}
    if "stats" in parts:
        result["stats"] = _parallel(ou_statistics, [(hz, stats_runs, 0, None, family) for hz in rates])
    if "oracle" in parts:
        names = [str(c) for c in parse_canyon_set(canyons)]
        result["oracle"] = _parallel(drive_oracle, [(o, names, hz) for hz in rates for o in oracles])
    if "agreement" in parts:
        if not evaluations:
            raise ConfigError("probe part 'agreement' needs evaluation folders (--evals)")
        result["agreement"] = [measure_agreement(e, o, out, predictions)
                               for e in evaluations for o in oracles]
    if "dead" in parts:
        result["dead"] = [dead_record(folder) for folder in checkpoints]
    if "dqn" in parts:
        result["dqn"] = {
            f"{hz:g}": small_dqn(hz, out / f"hz{hz:g}", dqn_runs, canyons, epochs) for hz in rates
        }
    return result


def dead_record(folder: Path) -> dict[str, Any]:
    """A checkpoint's dead outputs on its validation frames (`count_dead_outputs`), as probe.json holds
    them; `dead_outputs` None for a net without depth bins."""
    found = count_dead_outputs(folder)
    return {"checkpoint": str(folder), "dead_outputs": None if found is None else list(found.dead),
            **({} if found is None else {k: getattr(found, k) for k in ("outputs", "frames", "candidates")}),
            "text": "no depth bins" if found is None else str(found)}


def agreement_file(out: Path, evaluation: str, oracle: Oracle, suffix: str) -> Path:
    """OUT/agreement/<evaluation>_<oracle><suffix>: an evaluation's per-step arrays (.npz) or figure
    (.png). Evaluation names hold dots (bootstrap0.5): the suffix is appended, never swapped in."""
    return out / "agreement" / f"{evaluation}_{str(oracle).replace(':', '-')}{suffix}"


def measure_agreement(folder: Path, oracle: Oracle, out: Path, predictions: bool = False) -> dict[str, Any]:
    """`agreement` of one evaluation; its per-step arrays and figure go to OUT/agreement/<name>_<oracle>."""
    summary, arrays = agreement(folder, oracle, predictions)
    arrays_path = agreement_file(out, Path(folder).name, oracle, ".npz")
    arrays_path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(arrays_path, **arrays)
    plot_agreement(arrays, summary, agreement_file(out, Path(folder).name, oracle, ".png"))
    return summary


def format_stats(rows: list[dict]) -> str:
    """The calibration table: each candidate rate's Table II statistics next to the paper's."""
    sizes = list(PAPER_TABLE2)
    head = f"{'Hz':>5} {'kept':>6} {'frames/run':>11} {'bumped':>7} " + " ".join(f"{n:>7}" for n in sizes)
    lines = [head]
    for r in rows:
        samples = " ".join(f"{r['samples'][n]:>7}" for n in sizes)
        lines.append(
            f"{r['decision_hz']:>5g} {r['kept_share']:>6.1%} {r['frames_per_kept_run']:>11.1f} "
            f"{r['bumped_share']:>7.1%} {samples}"
        )
    paper = " ".join(f"{PAPER_TABLE2[n][0]:>7}" for n in sizes)
    lines.append(f"{'paper':>5} {'':>6} {PAPER_FRAMES_PER_RUN:>11.1f} {'':>7} {paper}")
    return "\n".join(lines)
