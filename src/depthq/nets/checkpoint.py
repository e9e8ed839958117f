"""Reading a trained network back, verified: a checkpoint folder's config.json and weight files.

This sits below both `depthq.train` (which writes checkpoints, see `depthq.train.checkpoint` for
the folder's layout) and `depthq.control` (whose policies read them), so a policy needs nothing
from training. A network is rebuilt from what config.json records of it: the trunk's name and the
head's config.

Every weight file carries the SHA-256 of its tensor bytes in its own safetensors metadata
("sha256"), written in the same atomic write as the tensors. Reading checks it, so a file whose
bytes changed after it was written (a flipped bit, a bad copy) fails with a message naming it
instead of driving with wrong weights; a truncated or malformed file fails as well. Files written
before the digest was recorded still load, with a warning that they cannot be verified.
"""

from __future__ import annotations

import hashlib
import json
import warnings
from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError
from safetensors.torch import load as load_safetensors
from safetensors.torch import save as save_safetensors

from depthq.configio import from_dict, read_json
from depthq.errors import ConfigError, DataError
from depthq.nets.heads import HEAD_KINDS, HeadConfig, QNet, build_head
from depthq.nets.trunk import build_trunk

CONFIG = "config.json"
FORMAT = "depthq-checkpoint"
WHICH = ("best", "last")
DIGEST = "sha256"
_HEADER_LENGTH = 8  # safetensors: u64 little-endian header size, JSON header, then the tensor bytes


def _tensor_bytes(blob: bytes) -> bytes:
    header = int.from_bytes(blob[:_HEADER_LENGTH], "little")
    return blob[_HEADER_LENGTH + header :]


def weights_bytes(tensors: dict[str, torch.Tensor], metadata: dict[str, str] | None = None) -> bytes:
    """A safetensors file of `tensors` whose metadata records the SHA-256 of its tensor bytes."""
    metadata = dict(metadata or {})
    if DIGEST in metadata:
        raise ConfigError(f"weight metadata key {DIGEST!r} is reserved for the file's digest")
    digest = hashlib.sha256(_tensor_bytes(save_safetensors(tensors, metadata=metadata))).hexdigest()
    return save_safetensors(tensors, metadata={**metadata, DIGEST: digest})


def read_weights(path: Path) -> tuple[dict[str, torch.Tensor], dict[str, str]]:
    """The tensors and metadata of a weight file, after checking its SHA-256 (see module doc)."""
    path = Path(path)
    try:
        blob = path.read_bytes()
        tensors = load_safetensors(blob)
    except (SafetensorError, OSError) as err:
        raise DataError(f"{path}: not a readable safetensors file ({err})") from err
    metadata = _metadata(blob, path)
    recorded = metadata.get(DIGEST)
    if recorded is None:
        warnings.warn(f"{path}: no SHA-256 recorded (written by an older depthq): cannot verify it",
                      stacklevel=2)
    else:
        actual = hashlib.sha256(_tensor_bytes(blob)).hexdigest()
        if actual != recorded:
            raise DataError(
                f"{path}: corrupted weights: the SHA-256 of its tensor bytes is {actual[:16]}…, "
                f"it was written as {recorded[:16]}…; restore the file or train again"
            )
    return tensors, metadata


def _metadata(blob: bytes, path: Path) -> dict[str, str]:
    header = int.from_bytes(blob[:_HEADER_LENGTH], "little")
    try:
        return json.loads(blob[_HEADER_LENGTH : _HEADER_LENGTH + header]).get("__metadata__") or {}
    except (ValueError, AttributeError) as err:
        raise DataError(f"{path}: unreadable safetensors header ({err})") from err


def read_config(folder: Path) -> dict[str, Any]:
    """A checkpoint folder's config.json; a folder that holds none or another format → ConfigError."""
    path = Path(folder) / CONFIG
    if not path.is_file():
        raise ConfigError(f"{folder}: not a checkpoint folder (no {CONFIG})")
    record = read_json(path)
    found = record.get("format") if isinstance(record, dict) else record
    if found != FORMAT:
        raise ConfigError(f"{path}: not a {FORMAT} config (format {found!r})")
    return record


def stored_parts(model: QNet) -> list[tuple[str, torch.nn.Module]]:
    """The modules a checkpoint stores: the head, plus the trunk when it is trained."""
    return [("head", model.head)] + ([] if model.trunk.frozen else [("trunk", model.trunk)])


def load_trainable_state(model: QNet, tensors: dict[str, torch.Tensor], path: Path) -> None:
    """Put the "<part>.<parameter>" tensors of `path` into `model`'s stored parts."""
    try:
        for name, module in stored_parts(model):
            prefix = f"{name}."
            module.load_state_dict({k[len(prefix) :]: v for k, v in tensors.items() if k.startswith(prefix)})
    except RuntimeError as err:
        raise ConfigError(f"{path}: weights do not fit the network of its config.json ({err})") from err


def load_qnet(
    folder: Path, which: str = "best", model: str | None = None, trunk: str | None = None
) -> tuple[QNet, dict[str, Any]]:
    """The trained network in `folder` in eval mode, and its config.json.

    `which` is "best" (lowest validation loss) or "last". `model` / `trunk`, when given, must be what
    the folder holds. A missing, incomplete or corrupted folder, or one that does not match → an error
    naming the file.
    """
    folder = Path(folder)
    if which not in WHICH:
        raise ConfigError(f"checkpoint weights must be one of {WHICH}, got {which!r}")
    if not folder.is_dir():
        raise ConfigError(f"{folder}: no such checkpoint folder")
    record = read_config(folder)
    head = record.get("head")
    kind = head.get("kind") if isinstance(head, dict) else None
    if kind not in HEAD_KINDS:
        raise ConfigError(f"{folder / CONFIG}: unknown model kind {kind!r}")
    for asked, held, what in ((model, kind, "model"), (trunk, record.get("trunk"), "trunk")):
        if asked is not None and asked != held:
            raise ConfigError(f"{folder} holds a {what} {held!r}, not the {asked!r} asked for")
    path = folder / f"{which}.safetensors"
    if not path.is_file():
        raise ConfigError(f"{folder}: incomplete checkpoint, no {path.name} (no epoch finished yet?)")
    tensors, _ = read_weights(path)
    net = QNet(build_trunk(str(record.get("trunk"))), build_head(from_dict(HeadConfig, head)))
    load_trainable_state(net, tensors, path)
    return net.eval(), record
