"""Why Coll-Q-Net learns in one look and not in another (issue #57 item 5; docs/research/looks.md#coll).

    python -m research.coll_learning measure CHECKPOINT [CHECKPOINT ...] [--json OUT.json]
    python -m research.coll_learning run LIKE OUT [--variants pinned,final,dropout,mirror]
        [--canyons hard/val:1000-1019] [--look LOOK]

Per Coll-Q-Net checkpoint, on the validation samples of the dataset it was trained on (per look where
the dataset holds runs rendered again in other looks, `depthq dataset rerender`):

- how often a sample's target is a collision (`positives`), the cross-entropy of always predicting the
  training samples' rate (`constant`) and the net's own (`bce`): a net whose `bce` is not below
  `constant` has learnt nothing a look-blind guess does not know;
- how well its probability ranks the samples that collide above those that do not (`auc`, the
  Mann-Whitney area under the ROC curve; 0.5 is chance);
- the same area for a logistic regression on the net's own input (the trunk's feature and the scaled
  action), fitted on the training samples (`probe_auc`): what the feature itself tells about a coming
  collision. A low `probe_auc` blames the feature (the frozen trunk in that look); a high one beside a
  low `auc` blames the training;
- how far apart its candidates' probabilities are in a frame (`spread`, the mean over frames of the
  highest minus the lowest): what its policy acts on, where `auc` mostly measures how dangerous a frame
  is whatever the action;
- its validation loss at the first, best and last epoch (metrics.csv).

`measure` trains nothing but the probe (seconds); the checkpoints and their datasets are read only.
`run` gives Coll-Q-Net its chances on the data of checkpoint LIKE (its training config, varied by each of
VARIANTS): each variant trained into OUT/models/<variant> (resumed), driven in `--canyons` (never the
`eval` ones) in the data's look into OUT/eval/<variant>, or in `--look` into OUT/eval_<look>/<variant>
(the same trained variants), measured as above; then the table with each variant's distance to the
first collision (OUT/results.json).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy.stats import rankdata

from depthq.checkpoint import load_qnet, policy_record, read_config, read_metrics
from depthq.checksum import read_checked_json, write_checked_json
from depthq.configio import from_dict, read_json, write_json
from depthq.data.manifest import Dataset
from depthq.data.rerender import STRIDE, rendered_looks
from depthq.data.samples import collision_target
from depthq.errors import ConfigError, guarded
from depthq.evaluate.online import EvalConfig, evaluate, evaluation_done, parse_canyon_set
from depthq.lock import exclusive
from depthq.networks import get_network
from depthq.report.tables import markdown
from depthq.sim.canyon import split_family
from depthq.train.config import TrainConfig
from depthq.train.dead_outputs import candidates_of, net_features
from depthq.train.features import load_activations, load_features
from depthq.train.offline_metric import training_data
from depthq.train.trainer import train

FIX = "remove it and rerun `python -m research.coll_learning run` to measure it again"
PROBE_STEPS, PROBE_L2 = 200, 1e-3  # the probe's L-BFGS steps and L2 weight (on standardised inputs)


def auc(scores: np.ndarray, positive: np.ndarray) -> float:
    """The area under the ROC curve of `scores` for `positive` (ties halved); NaN with one class."""
    n_pos, n_neg = int(positive.sum()), int((~positive).sum())
    if not n_pos or not n_neg:
        return float("nan")
    ranks = rankdata(scores)
    return float((ranks[positive].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def look_of(dataset: Dataset) -> str | None:
    """The look a dataset's runs were collected in (None: the collector's default)."""
    return dataset.config.get("env", {}).get("world", {}).get("look")


def bce(p: np.ndarray, y: np.ndarray) -> float:
    p = np.clip(p, 1e-7, 1 - 1e-7)
    return float(-np.mean(y * np.log(p) + (1 - y) * np.log(1 - p)))


def probe(x_train: torch.Tensor, y_train: torch.Tensor, x_val: torch.Tensor) -> np.ndarray:
    """A logistic regression (L2 `PROBE_L2`) fitted on standardised training inputs → P on `x_val`."""
    mean, std = x_train.mean(0), x_train.std(0) + 1e-6
    x, xv = (x_train - mean) / std, (x_val - mean) / std
    torch.manual_seed(0)
    w = torch.zeros(x.shape[1], requires_grad=True)
    b = torch.zeros(1, requires_grad=True)
    optimiser = torch.optim.LBFGS([w, b], max_iter=PROBE_STEPS, line_search_fn="strong_wolfe")

    def closure() -> torch.Tensor:
        optimiser.zero_grad()
        fit = torch.nn.functional.binary_cross_entropy_with_logits(x @ w + b, y_train)
        loss = fit + PROBE_L2 * w.square().sum()
        loss.backward()
        return loss

    optimiser.step(closure)
    with torch.no_grad():
        return torch.sigmoid(xv @ w + b).numpy()


def measure(checkpoint: Path, weights: str | None = None) -> list[dict[str, Any]]:
    """One row per look of the checkpoint's validation samples (one row for a one-look dataset)."""
    record = read_config(checkpoint)
    train = from_dict(TrainConfig, record["train"])
    network = get_network(train.model)
    if type(network).target is not collision_target:  # the collision probability it outputs is measured
        raise ConfigError(f"{checkpoint}: a {network.title}, not a Coll-Q-Net")
    dataset = training_data(record, None)
    if dataset is None:
        raise ConfigError(f"{checkpoint}: its dataset is not found")
    net, _ = load_qnet(checkpoint, weights=weights)
    size = train.input_size  # the frozen trunk's features, or a tuned one's early activations, read once
    table = (load_activations(dataset, train.tune_stages, size, progress=False) if train.tune_stages
             else load_features(dataset, train.trunk, size, progress=False))
    inputs, targets = {}, {}
    for split in ("train", "val"):
        arrays = network.samples(dataset, split, train.runs if split == "train" else None, train)
        with torch.no_grad():
            feature = net_features(net, table.gather(split, arrays).float())
        action = torch.from_numpy(np.asarray(arrays["action"], np.float32))
        inputs[split] = (feature, action, arrays)
        targets[split] = np.asarray(arrays["target"], np.float32)
    feature, action, arrays = inputs["val"]
    with torch.no_grad():
        p_net = network.output(net.head(feature, action)).numpy().reshape(-1)
        candidates = candidates_of(net, policy_record(record).actions)
        each = [network.output(net.head(feature, torch.full_like(action, float(a)))).numpy().reshape(-1)
                for a in candidates]
    spread = np.ptp(np.stack(each), axis=0)  # per frame: the candidates' highest P − lowest
    train_feature, train_action, _ = inputs["train"]
    flat = train_feature.reshape(len(train_feature), -1)
    x_train = torch.cat([flat, train_action.reshape(len(flat), -1) * train.action_scale], 1)
    x_val = torch.cat([feature.reshape(len(feature), -1),
                       action.reshape(len(feature), -1) * train.action_scale], 1)
    p_probe = probe(x_train, torch.from_numpy(targets["train"]), x_val)
    rate = float(targets["train"].mean())
    looks = {0: look_of(dataset) or "collected"}
    looks.update({k: look for k, (look, _) in rendered_looks(dataset).items()})
    version = np.asarray(arrays["run_id"]) // STRIDE  # a run's index: v × STRIDE + its source's
    metrics = read_metrics(checkpoint)
    rows = []
    for v in sorted(set(version.tolist())):
        keep = version == v
        y = targets["val"][keep]
        rows.append({
            "checkpoint": str(checkpoint), "look": str(looks.get(v, v)), "samples": int(keep.sum()),
            "positives": float(y.mean()), "constant": bce(np.full_like(y, rate), y),
            "bce": bce(p_net[keep], y),
            "auc": auc(p_net[keep], y > 0.5), "probe_auc": auc(p_probe[keep], y > 0.5),
            "spread": float(spread[keep].mean()),
            "val_loss_first": float(metrics["val_loss"][0]),
            "val_loss_best": float(np.nanmin(metrics["val_loss"])),
            "val_loss_last": float(metrics["val_loss"][-1]),
        })
    return rows


# Coll-Q-Net's chances (`run`): training settings over LIKE's, and the weights it drives with (none:
# its own choice, the best validation loss).
VARIANTS: dict[str, tuple[dict[str, Any], str | None]] = {
    "pinned": ({}, None),
    "final": ({}, "final"),  # the pinned training driven with its last epoch's weights
    "dropout": ({"dropout": 0.5}, None),  # the paper's dropout
    "mirror": ({"mirror": True}, None),  # every sample mirrored with probability 1/2
    "dropout+mirror": ({"dropout": 0.5, "mirror": True}, None),
    "average": ({"average": 0.25, "weights": "average"}, None),  # the last quarter's mean, Depth-Q-Net's way
}


def run(like: Path, out: Path, variants: tuple[str, ...], canyons: str, look: str | None) -> int:
    """Every variant trained, driven and measured (each step resumed)."""
    if unknown := sorted(set(variants) - set(VARIANTS)):
        raise ConfigError(f"--variants {','.join(unknown)}: not one of {', '.join(VARIANTS)}")
    if any(split_family(c)[1].startswith("eval") for c in canyons.split(",")):
        raise ConfigError(f"--canyons {canyons!r}: the eval canyons are the test set; choose in val ones")
    base = read_config(like)
    train_config = from_dict(TrainConfig, base["train"])
    # Driven in the data's own look into eval/, in another look into eval_<its name>/ (keyed so too):
    # the same trained variants, a drive per look.
    evals = out / ("eval" if look is None else f"eval_{Path(look).name}")
    prefix = "" if look is None else f"{Path(look).name}/"
    look = look or look_of(Dataset.open(Path(train_config.data)))
    results_path = out / "results.json"
    results: dict[str, Any] = read_checked_json(results_path, FIX) if results_path.is_file() else {}
    for name in variants:
        settings, weights = VARIANTS[name]
        trained = "pinned" if not settings else name
        folder = out / "models" / trained
        train(replace(train_config, **settings), folder, progress=False)
        driven = evals / name
        config = EvalConfig(canyons=parse_canyon_set(canyons), look=look, weights=weights)
        if not evaluation_done(driven):
            evaluate(str(folder), driven, config, workers=1, progress=False, video=False)
        row = measure(folder, weights)[0]
        row["variant"] = name
        row["distance"] = read_json(driven / "summary.json")["summary"]["distance_to_collision_mean"]
        results[prefix + name] = row
        write_checked_json(results_path, results)
        print(f"{name} in the {look} look: {row['distance']:.2f} m, AUC {row['auc']:.3f}, "
              f"spread {row['spread']:.3f}", flush=True)
    print(table([results[prefix + name] for name in variants], first="variant"))
    return 0


COLUMNS = {"look": "look", "samples": "val samples", "positives": "collide", "constant": "BCE, constant",
           "bce": "BCE, net", "auc": "AUC, net", "probe_auc": "AUC, linear probe",
           "spread": "P spread of candidates",
           "val_loss_first": "val loss, epoch 1", "val_loss_best": "best", "val_loss_last": "last"}


def table(rows: list[dict[str, Any]], first: str = "checkpoint") -> str:
    columns = {**COLUMNS, "distance": "m to first collision"} if first == "variant" else COLUMNS
    return markdown([{first: row[first], **{title: row[k] if isinstance(row[k], str) else (
        str(row[k]) if isinstance(row[k], int) else f"{row[k]:.3f}") for k, title in columns.items()}}
        for row in rows])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.coll_learning",
                                     description=(__doc__ or "").split("\n\n")[0])
    verbs = parser.add_subparsers(dest="verb", required=True)
    measuring = verbs.add_parser("measure", help="measure Coll-Q-Net checkpoints")
    measuring.add_argument("checkpoints", nargs="+", type=Path, help="Coll-Q-Net checkpoint folders")
    measuring.add_argument("--json", type=Path, help="also write the rows to this JSON file")
    running = verbs.add_parser("run", help="train, drive and measure Coll-Q-Net's variants")
    running.add_argument("like", type=Path, help="the Coll-Q-Net checkpoint whose data and config to vary")
    running.add_argument("out", type=Path)
    running.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated, of VARIANTS")
    running.add_argument("--canyons", default="hard/val:1000-1019", help="val canyons to drive in")
    running.add_argument("--look", help="the look to drive in (default: the data's)")
    args = parser.parse_args(argv)

    def work() -> int:
        if args.verb == "run":
            with exclusive(args.out, "OUT"):  # one writer per experiment folder
                return run(args.like, args.out, tuple(args.variants.split(",")), args.canyons, args.look)
        rows = [row for checkpoint in args.checkpoints for row in measure(checkpoint)]
        print(table(rows))
        if args.json:
            write_json(args.json, {"rows": rows})
        return 0

    return guarded("python -m research.coll_learning", work)


if __name__ == "__main__":
    sys.exit(main())
