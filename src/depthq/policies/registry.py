"""Build any policy from its name on the command line: 'heuristic', 'ou', a checkpoint folder or
'onnx:PATH' (a graph written by `depthq export`)."""

from __future__ import annotations

from pathlib import Path

from depthq.control.action_selection import Selection
from depthq.control.heuristic import DepthHeuristic
from depthq.control.ou import OUPolicy
from depthq.control.policy import Policy
from depthq.errors import ConfigError
from depthq.policies.onnx import OnnxPolicy
from depthq.policies.qnet import QNetPolicy

BUILTIN = ("heuristic", "ou")


def make_policy(
    spec: str,
    seed: int | None = None,
    which: str | None = None,
    device: str = "cpu",
    selection: Selection | None = None,
    threads: int | None = None,
) -> Policy:
    """`spec` is 'heuristic', 'ou', the path of a trained Depth-Q-Net / Coll-Q-Net checkpoint folder
    (`which` weights, `depthq.nets.checkpoint.weights_stem`, None: the checkpoint's choice; run on
    torch `device`) or 'onnx:PATH'. `selection`: how a Depth-Q-Net scores its candidates (None: the
    default rule; docs/design.md#lookahead-selection). `threads`: an ONNX session's (torch's are the
    process's, `torch.set_num_threads`)."""
    if spec == "heuristic":
        return DepthHeuristic()
    if spec == "ou":
        return OUPolicy(seed=seed)
    if spec.startswith("onnx:"):
        return OnnxPolicy(Path(spec.removeprefix("onnx:")), threads=threads, selection=selection)
    path = Path(spec)
    if path.is_dir():
        return QNetPolicy.from_checkpoint(path, which=which, device=device, selection=selection)
    raise ConfigError(
        f"unknown policy {spec!r}: expected one of {BUILTIN}, an existing checkpoint folder or onnx:PATH"
    )
