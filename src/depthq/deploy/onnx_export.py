"""`depthq export`: a trained Q-net as one ONNX graph, camera frame in, per-action values out.

The graph takes a uint8 camera frame (H, W, 3) of the size it was exported for (by default the
checkpoint's: its training data's frames) and the N candidate actions (N,) float32; it returns the
network's values (`Network.output`, named `Network.onnx_output`): the predicted depth bins (N, n_bins)
in metres ("bins", Depth-Q-Net) or the collision probabilities (N,) ("collision_probability",
Coll-Q-Net). A
Depth-Q-Net that looks K steps ahead takes candidate sequences (N, K) and returns (N, K, n_bins).
Resizing and scaling to [0, 1] are inside the graph, so a robot needs nothing but onnxruntime and
numpy. The resize is `depthq.blocks.trunk.preprocess`'s to the last bit: PyTorch resizes uint8
frames with Pillow's fixed-point algorithm (integer weights, a horizontal then a vertical pass,
each rounded to whole grey levels); the graph does the same arithmetic exactly, in float64, with
the weight matrices of the export's frame size. (A float resize differs by one grey level in ≈ 10 %
of the pixels, which moved the predicted bins by up to 0.18 m.)

The model's metadata (`metadata_props`) carries what acting needs:

    depthq.kind        the network's name (`depthq.networks`): "depth" or "coll"
    depthq.actions     the candidate actions, JSON, e.g. [-1.0, 0.0, 1.0]
    depthq.lookahead   K, the steps a Depth-Q-Net predicts (1: one step; Coll-Q-Net: 1)
    depthq.selection   the rule that turns the outputs into one action, in words (`Network.rule_text`)
    depthq.input_size  the side the frame is resized to
    depthq.frame_size  the frame the graph takes, JSON [height, width]
    depthq.config      the checkpoint's config.json, verbatim
    depthq.version     the package that wrote the file
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import torch
from torch import nn

from depthq import __version__
from depthq.blocks.heads import QNet
from depthq.checkpoint import load_qnet, policy_record
from depthq.configio import atomic_write_bytes
from depthq.control.action_selection import candidate_sequences
from depthq.deploy.resize import resize_weights
from depthq.errors import ConfigError
from depthq.networks import Network, get_network

OPSET = 18


class FrameResize(nn.Module):
    """uint8 frame (H, W, 3) → float (1, 3, S, S) in [0, 1], equal to `preprocess` for that frame size."""

    def __init__(self, frame_size: tuple[int, int], size: int) -> None:
        super().__init__()
        rows, row_bits = resize_weights(frame_size[0], size)
        cols, col_bits = resize_weights(frame_size[1], size)
        self.register_buffer("rows", torch.from_numpy(rows))  # (S, H) float64
        self.register_buffer("cols_t", torch.from_numpy(cols.T.copy()))  # (W, S)
        self.row_bits, self.col_bits = row_bits, col_bits

    @staticmethod
    def _round(total: torch.Tensor, bits: int) -> torch.Tensor:
        return torch.floor((total + float(1 << (bits - 1))) * (1.0 / (1 << bits))).clamp(0.0, 255.0)

    def forward(self, frame: torch.Tensor) -> torch.Tensor:
        image = frame.permute(2, 0, 1).to(torch.float64)  # (3, H, W)
        image = self._round(image @ self.cols_t, self.col_bits)  # horizontal pass: (3, H, S)
        image = self._round(self.rows @ image, self.row_bits)  # vertical pass: (3, S, S)
        return (image / 255.0).to(torch.float32).unsqueeze(0)


class FramePolicyGraph(nn.Module):
    """What the ONNX graph computes: (frame uint8 (H, W, 3), actions (N,) or sequences (N, K)) →
    per-candidate values."""

    def __init__(self, net: QNet, network: Network, input_size: int, frame_size: tuple[int, int]) -> None:
        super().__init__()
        self.resize = FrameResize(frame_size, input_size)
        self.trunk = net.trunk.net  # the bare network: no micro-batching or layout tricks to trace
        self.head = net.head
        self.network = network

    def forward(self, frame: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        feature = self.trunk.features(self.resize(frame))
        return self.network.output(self.head(feature.expand(actions.shape[0], -1), actions))


def export_onnx(
    checkpoint: Path,
    out: Path,
    weights: str | None = None,
    actions: tuple[float, ...] | None = None,
    frame_size: tuple[int, int] | None = None,
) -> Path:
    """Write `checkpoint`'s network to OUT/<checkpoint name>.onnx (atomically) and return its path.
    `weights` (None: the checkpoint's choice), `actions` and `frame_size` (None: the
    checkpoint's) as in `depthq.checkpoint`."""
    try:
        import onnx  # the optional [deploy] extra, as onnxscript: a missing one is a ConfigError
        import onnxscript  # noqa: F401  (what torch.onnx's exporter builds graphs with)
    except ImportError as err:
        missing = f"export needs the deploy extra ({err.name} is missing)"
        raise ConfigError(f'{missing}: pip install "depthq[deploy]"') from err

    checkpoint, out = Path(checkpoint), Path(out)
    net, record = load_qnet(checkpoint, weights=weights)  # checks the weights' SHA-256
    network = get_network(record["head"]["kind"])
    input_size = int(record["input_size"])
    policy = policy_record(record)
    frame_size = tuple(policy.frame_size if frame_size is None else frame_size)
    actions = policy.actions if actions is None else actions
    if len(frame_size) != 2 or min(frame_size) < input_size:
        raise ConfigError(f"frame size must be (height, width), each ≥ {input_size}, got {frame_size}")
    if not actions or any(not -1 <= a <= 1 for a in actions):
        raise ConfigError(f"candidate actions must be a non-empty list within [-1, 1], got {actions}")
    graph = FramePolicyGraph(net, network, input_size, frame_size).eval()
    frame = torch.zeros(*frame_size, 3, dtype=torch.uint8)
    lookahead = net.head.config.lookahead
    held = candidate_sequences(actions, lookahead)  # an example input: any N candidates run
    candidates = torch.tensor(held[:, 0] if lookahead == 1 else held, dtype=torch.float32)
    with torch.inference_mode(False), torch.no_grad():
        program = torch.onnx.export(
            graph,
            (frame, candidates),
            input_names=["frame", "actions"],
            output_names=[network.onnx_output],
            dynamic_shapes={"frame": {}, "actions": {0: torch.export.Dim("k", min=1)}},
            opset_version=OPSET,
            dynamo=True,
            verbose=False,
        )
    with tempfile.TemporaryDirectory() as tmp:
        program.save(Path(tmp) / "model.onnx")
        model = onnx.load(Path(tmp) / "model.onnx")
    metadata = {
        "depthq.kind": network.name,
        "depthq.actions": json.dumps([float(a) for a in actions]),
        "depthq.lookahead": str(lookahead),
        "depthq.selection": network.rule_text,
        "depthq.input_size": str(input_size),
        "depthq.frame_size": json.dumps(list(frame_size)),
        "depthq.config": json.dumps(record, sort_keys=True),
        "depthq.version": __version__,
    }
    onnx.helper.set_model_props(model, metadata)
    onnx.checker.check_model(model, full_check=True)
    path = out / f"{checkpoint.name}.onnx"
    atomic_write_bytes(path, model.SerializeToString())
    return path
