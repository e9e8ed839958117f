"""Privileged input (docs/oracle_gap.md#privileged): is it the camera's feature, or the learning, that
holds Depth-Q-Net back? The same heads, targets, losses and selection rules as `depthq train`, fed
the LiDAR the robot carries instead of the image feature: the current frame's 26 bins (what a perfect
monocular depth estimator would give within the camera's field of view) or the whole 360° scan. A net
that drives well on them says the learning is sound and the feature is the bottleneck.

Input `camera` closes the loop: a perception head learns the current frame's 26 bins from the cached
image feature (the LiDAR of the same frame as its target: no collision label), and the `bins` net's
head, trained on the true bins, acts on its estimate, so the policy needs the camera alone.

    python -m research.privileged run DATA OUT [--inputs bins,scan] [--nets depth,coll]

DATA is a dataset folder (`depthq collect`), OUT gets results.json; driven in the family's `val`
canyons (never `eval`), without a camera.

A finished investigation (research/, not in the wheel; run from a checkout's root). Its numbers in
docs/oracle_gap.md#privileged came from the code of commit 730cc4c (2026-11-25: the last change of that
page's tables).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from depthq.blocks.heads import HeadConfig
from depthq.blocks.optim import make_optimizer
from depthq.blocks.trunk import DEFAULT_TRUNK, build_trunk, preprocess
from depthq.configio import read_json, write_json
from depthq.control.action_selection import ACTIONS
from depthq.data.manifest import Dataset
from depthq.data.samples import bins_target
from depthq.data.views import run_then_frame, view_arrays
from depthq.errors import ConfigError
from depthq.evaluate.online import parse_canyon_set
from depthq.evaluate.oracle import env_config
from depthq.networks import build_head, get_network
from depthq.sim.env import COLLISIONS, CanyonEnv
from depthq.train.config import TrainConfig
from depthq.train.features import FeatureTable, load_features
from depthq.train.samples import FeatureSamples
from depthq.train.trainer import loss_function, train_step

INPUTS = ("bins", "scan", "camera")
SCAN_CLIP = 3.5  # the LiDAR's range: no return reads as far as it sees


def lidar_input(bins: np.ndarray, scan: np.ndarray, kind: str) -> np.ndarray:
    """A frame's privileged input: its 26 bins (invalid as the 2 m clip) or its 360 readings (clipped)."""
    if kind == "bins":
        return np.nan_to_num(bins, nan=2.0).astype(np.float32)
    return np.clip(np.nan_to_num(scan, posinf=SCAN_CLIP), 0.0, SCAN_CLIP).astype(np.float32)


def lidar_table(dataset: Dataset, kind: str) -> FeatureTable:
    """Every frame's privileged input in a feature table (the layout the feature cache has)."""
    rows, runs, first = [], {}, 0
    for entry in dataset.entries():
        run = dataset.read_run(entry, images=False)
        rows.append(lidar_input(run.bins, run.scans, kind))
        runs[entry.name] = (first, entry.n_frames)
        first += entry.n_frames
    return FeatureTable(np.concatenate(rows).astype(np.float16), runs, computed=True)


def train_head(dataset: Dataset, kind: str, net: str, config: TrainConfig) -> torch.nn.Module:
    """`config`'s head trained on `kind` input as `depthq train` trains one on cached features."""
    table = lidar_table(dataset, kind)
    network = get_network(net)
    arrays = view_arrays(dataset, "train", config.runs, type(network).target, config.samples)
    samples = FeatureSamples(arrays, table, "train")
    torch.manual_seed(config.seed)
    # One step, the action appended, the input unprojected.
    paper = HeadConfig(net, table.features.shape[1], hidden=config.hidden, dropout=0.0,
                       action_scale=config.action_scale, lookahead=1, feature_projection=0, form="concat",
                       output_bias=0.0, bin_gradient="relu")
    own = network.head_config(paper, config.settings)  # its bins' bias and gradient
    head = build_head(replace(own, lookahead=1, form="concat"))
    model = torch.nn.Module()
    model.head = head  # `train_step` runs the head on `samples.trunk_features(model, batch)`: the cached ones
    optimizer = make_optimizer(head, config.learning_rate, config.weight_decay, config.rho, config.eps)
    loss_fn, rng = loss_function(config), np.random.default_rng(config.seed)
    head.train()
    for _ in tqdm(range(config.epochs), desc=f"train {net} on {kind}", unit="epoch"):
        for _ in range(config.train_batches):
            batch = samples.batch(samples.draw(config.batch_size, rng))
            train_step(model, samples, batch, loss_fn, optimizer)
    return head.eval()


def train_perception(dataset: Dataset, config: TrainConfig) -> torch.nn.Module:
    """A head from the cached image feature to the current frame's 26 bins (invalid as the clip), L1
    over all bins, on the training runs' frames, with `config`'s optimizer and schedule."""
    table = load_features(dataset, config.trunk, config.input_size)
    arrays = view_arrays(dataset, "train", config.runs, bins_target, config.samples)
    current = lidar_table(dataset, "bins")
    rows = table.rows("train", arrays["run_id"], arrays["frame_id"])
    features = torch.from_numpy(table.features[rows])
    targets = torch.from_numpy(current.features[rows].astype(np.float32))
    torch.manual_seed(config.seed)
    dim = table.features.shape[1]
    net = torch.nn.Sequential(torch.nn.Linear(dim, config.hidden), torch.nn.ReLU(),
                              torch.nn.Linear(config.hidden, 26))
    optimizer = make_optimizer(net, config.learning_rate, config.weight_decay, config.rho, config.eps)
    rng = np.random.default_rng(config.seed)
    for _ in tqdm(range(config.epochs), desc="train perception", unit="epoch"):
        for _ in range(config.train_batches):
            idx = torch.from_numpy(run_then_frame(arrays["run_offsets"], config.batch_size, rng))
            loss = (net(features[idx].float()) - targets[idx]).abs().mean()
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
    return net.eval()


@torch.no_grad()
def drive(
    head: torch.nn.Module, net: str, kind: str, canyons: list[str], decision_hz: float,
    perception: torch.nn.Module | None = None,
) -> dict[str, Any]:
    """The head's greedy policy on the LiDAR input (`camera`: on `perception`'s estimate of the bins
    from the frame), driven in `canyons`."""
    env = CanyonEnv(env_config(canyons, decision_hz), camera=perception is not None)
    trunk = build_trunk(DEFAULT_TRUNK) if perception is not None else None
    actions, runs = torch.tensor(ACTIONS), []
    try:
        for k, canyon in enumerate(canyons):
            obs, info = env.reset(seed=k, options={"canyon": canyon})
            done = False
            while not done:
                if perception is not None:
                    estimate = perception(trunk(preprocess(obs["image"][None]))).clamp(min=0.0)
                    x = estimate.repeat(len(ACTIONS), 1)
                else:
                    x = torch.from_numpy(lidar_input(obs["bins"], obs["scan"], kind)).repeat(len(ACTIONS), 1)
                out = head(x, actions)
                values = get_network(net).output(out).numpy()
                action = get_network(net).choose(values, np.array(ACTIONS))
                obs, _, terminated, truncated, info = env.step([action])
                done = terminated or truncated
            runs.append({"canyon": canyon, "progress": info["progress"], "end_reason": info["end_reason"]})
    finally:
        env.close()
    return {
        "progress_mean": float(np.mean([r["progress"] for r in runs])),
        "reached_end": sum(r["end_reason"] == "end" for r in runs),
        "collisions": sum(r["end_reason"] in COLLISIONS for r in runs),
        "per_canyon": runs,
    }


def run(data: Path, out: Path, inputs: tuple[str, ...], nets: tuple[str, ...], canyons: str,
        runs: int | None = 500, seed: int = 0, epochs: int | None = None) -> dict[str, Any]:
    """Train and drive each (input, net); results.json in `out` keeps each finished pair (resumed)."""
    dataset = Dataset.open(data)
    hz = float(dataset.config["env"]["world"]["decision_hz"])
    names = [str(c) for c in parse_canyon_set(canyons)]
    path = out / "results.json"
    results: dict[str, Any] = read_json(path) if path.is_file() else {}
    for kind in inputs:
        if kind not in INPUTS:
            raise ConfigError(f"privileged input must be one of {INPUTS}, got {kind!r}")
        for net in nets:
            key = f"{net}_{kind}_n{runs}_s{seed}"
            if key in results:
                continue
            config = TrainConfig(model=net, data=str(data), runs=runs, seed=seed,
                                 **({"epochs": epochs} if epochs else {}))
            head = train_head(dataset, "bins" if kind == "camera" else kind, net, config)
            perception = train_perception(dataset, config) if kind == "camera" else None
            results[key] = {"net": net, "input": kind, "runs": runs, "seed": seed, "canyons": canyons,
                            **drive(head, net, kind, names, hz, perception)}
            out.mkdir(parents=True, exist_ok=True)
            write_json(path, results)
    return results


INPUT_NAMES = {"bins": "the current 26 bins (LiDAR)", "scan": "the current 360° scan (LiDAR)",
               "camera": "the current bins estimated from the camera"}


def table(folders: list[Path]) -> str:
    """Markdown: each finished (net, input) of the results.json in `folders`."""
    lines = ["| network | input | runs | seed | progress (m, mean) | ends reached /20 | collisions |",
             "|---|---|---|---|---|---|---|"]
    for folder in folders:
        for r in read_json(folder / "results.json").values():
            net = get_network(r["net"]).title
            lines.append(f"| {net} | {INPUT_NAMES[r['input']]} | {r['runs']} | {r['seed']} | "
                         f"{r['progress_mean']:.2f} | {r['reached_end']} | {r['collisions']} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.privileged",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("action", choices=("run", "table"))
    parser.add_argument("data", type=Path, help="run: a dataset folder; table: a results folder")
    parser.add_argument("out", type=Path, nargs="*",
                        help="run: the folder for results.json; table: more folders")
    parser.add_argument("--inputs", default="bins,scan", help="bins, scan or both")
    parser.add_argument("--nets", default="depth,coll", help="depth, coll or both")
    parser.add_argument("--canyons", default="hard/val:1000-1019", help="val canyons to drive in")
    parser.add_argument("--runs", type=int, default=500, help="training runs")
    parser.add_argument("--seed", type=int, default=0, help="training seed")
    args = parser.parse_args(argv)
    if args.action == "table":
        print(table([args.data, *args.out]))
        return 0
    if len(args.out) != 1:
        parser.error("run takes one output folder")
    results = run(args.data, args.out[0], tuple(args.inputs.split(",")), tuple(args.nets.split(",")),
                  args.canyons, args.runs, args.seed)
    for key, r in results.items():
        print(f"{key}: progress {r['progress_mean']:.2f} m, ends {r['reached_end']}/{len(r['runs'])}, "
              f"collisions {r['collisions']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
