"""Build any policy from its spec (`depthq.policies.spec`): 'heuristic', 'ou', a checkpoint folder or
'onnx:PATH' (a graph written by `depthq export`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from depthq.control.heuristic import DepthHeuristic
from depthq.control.ou import OUPolicy
from depthq.control.policy import Policy
from depthq.policies.onnx import OnnxPolicy
from depthq.policies.qnet import QNetPolicy
from depthq.policies.spec import PolicySpec


def make_policy(
    spec: str | PolicySpec,
    seed: int | None = None,
    weights: str | None = None,
    device: str = "cpu",
    acting: Mapping[str, Any] | None = None,
    threads: int | None = None,
) -> Policy:
    """The policy `spec` names (a string is parsed: `PolicySpec.parse`). A checkpoint's Q-net takes
    `weights` (`depthq.checkpoint.weights_stem`, None: the checkpoint's choice) and runs on
    torch `device`. `acting`: an evaluation's acting settings by network name (`EvalConfig.acting`;
    None: the defaults), of which a Q-net's network's own are used (how a Depth-Q-Net makes and
    scores its candidates: docs/design.md#lookahead-selection). `threads`: an ONNX session's
    (torch's are the process's, `torch.set_num_threads`)."""
    spec = PolicySpec.parse(spec)
    if spec.kind == "heuristic":
        return DepthHeuristic()
    if spec.kind == "ou":
        return OUPolicy(seed=seed)
    if spec.kind == "onnx":
        return OnnxPolicy(spec.path, threads=threads, acting=acting)
    return QNetPolicy.from_checkpoint(spec.path, weights=weights, device=device, acting=acting)
