"""The checkpoint format: config.json (what was trained, for which policy, on which data), the weight
files and their digests, the sidecars, the format's version and its migrations. `depthq.checkpoint.training`
writes a folder of it, `depthq.checkpoint.acting` reads one back as the network that acts.

config.json (format version 3):

    format, format_version   "depthq-checkpoint", 3
    provenance               the package and version that wrote it
    host                     the machine and torch threads that trained it (`depthq.host`)
    train                    the full TrainConfig (`weights`: the weights a policy uses by default;
                             `snapshots`: epochs whose weights are kept as well; `lookahead`: the
                             steps a Depth-Q-Net predicts, also in `head`;
                             `feature_projection`: the size the feature is projected to, also
                             in `head`, its map stored with the head's weights; `samples`: which
                             frames were samples, their targets: `depthq.data.samples.SampleConfig`)
    head, trunk, trunk_frozen, input_size, learning_rate
                             the network, rebuilt from these
    dataset                  `DatasetRecord`: its absolute path, fingerprint and env config as its
                             manifest records it (null for a robot's recording), and the labeller
                             of its camera labels when it learnt from them
    policy                   `PolicyRecord`: decision rate, camera frame size, candidate actions,
                             the rule that picks one (`rule`) and depth bins

Weight files: best.safetensors (lowest validation loss), last.safetensors (the last epoch; after a
finished training, the final weights), epoch_0040.safetensors (a snapshot). Each carries the
SHA-256 of its tensor bytes in its own safetensors metadata ("sha256"), written in the same atomic
write as the tensors. Reading checks it, so a file whose bytes changed after it was written (a
flipped bit, a bad copy) fails with a message naming it instead of driving with wrong weights; a
truncated or malformed file fails as well. Files written before the digest was recorded still
load, with a warning that they cannot be verified. config.json and the weights' JSON sidecars
(best.json, ...: `write_sidecar`) carry their own SHA-256 (`depthq.checksum`): one edited after it was
written is refused; one written before checksums is read as it is. Weight files' headers are written
with sorted keys, so equal tensors and metadata give equal bytes in any process.

Older versions still load: `read_config` gives them version 3's shape through their version's
migration (`depthq.blocks.migrations`, one function per version): 1 (no digests), 2 (the layout before
`dataset` and `policy`), and version 3 as written before its later fields (added, renamed, moved).
A newer version is refused by name.
"""

from __future__ import annotations

import hashlib
import json
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError
from safetensors.torch import load as load_safetensors
from safetensors.torch import save as save_safetensors

from depthq.blocks.heads import HeadConfig, QNet
from depthq.blocks.migrations import migrate_checkpoint
from depthq.blocks.trunk import TRUNKS
from depthq.checksum import read_checked_json, write_checked_json
from depthq.configio import OMIT_DEFAULT, from_dict, provenance, to_dict
from depthq.errors import ConfigError, DataError
from depthq.host import host_fingerprint
from depthq.sim.canyon import PAPER

CONFIG = "config.json"
FORMAT = "depthq-checkpoint"
# 1: the first layout; 2: every weight file records its SHA-256; 3: config.json describes its
# policy and dataset (absolute path), and TrainConfig has `weights` (then `select`) and `snapshots`.
FORMAT_VERSION = 3
# TrainConfig.weights: the weights a checkpoint's policy uses by default
WEIGHTS = ("best", "final", "average")
DIGEST = "sha256"
# weights → weight file
_WEIGHT_FILE = {"best": "best", "last": "last", "final": "last", "average": "average"}
_SNAPSHOT = re.compile(r"epoch:([0-9]+)")
_FIX = "restore the checkpoint folder from a copy, or train it again (a config is never edited by hand)"
_HEADER_LENGTH = 8  # safetensors: u64 little-endian header size, JSON header, then the tensor bytes
@dataclass(frozen=True)
class DatasetRecord:
    """The dataset a checkpoint was trained on: where it was, what it held, how it was made."""

    path: str  # absolute
    fingerprint: str | None  # `depthq.data.manifest.Dataset.fingerprint`; None in a version-1 record
    env: dict[str, Any] | None  # the manifest's "env" block, verbatim; None for a robot's recording
    # The labeller of the camera labels it learnt from ({"name", "fingerprint"}, `TrainConfig.labels`
    # "camera"); absent when it learnt from the LiDAR, and in a record written before the field.
    labeller: dict[str, str] | None = field(default=None, metadata=OMIT_DEFAULT)

    @property
    def family(self) -> str | None:
        """The canyon family its runs drove in (the manifest leaves the paper's, the default, unset);
        None for a robot's recording."""
        return None if self.env is None else self.env.get("world", {}).get("family", PAPER)


@dataclass(frozen=True)
class PolicyRecord:
    """What driving with a checkpoint needs besides its weights, fixed by the data it learned from."""

    decision_hz: float  # one decision per camera frame, at the rate of its training data
    frame_size: tuple[int, int]  # (height, width) of its training data's camera frames
    actions: tuple[float, ...]  # the candidate actions scored per frame
    rule: str  # the rule that picks one (`depthq.control.action_selection.RULES`)
    bins: dict[str, Any] | None  # its data's depth bins (`depthq.sim.sensors.BinConfig`); None: unknown


def weights_stem(weights: str) -> str:
    """The weight file `weights` names: 'best', 'last' or 'final' (the same file: the weights after
    the last epoch), 'average' (the mean of the last epochs', `TrainConfig.average`) or 'epoch:N' (a
    snapshot, `TrainConfig.snapshots`)."""
    if weights in _WEIGHT_FILE:
        return _WEIGHT_FILE[weights]
    match = _SNAPSHOT.fullmatch(str(weights))
    if match is None or int(match.group(1)) < 1:
        raise ConfigError(
            f"checkpoint weights must be 'best', 'last', 'final', 'average' or 'epoch:N', got {weights!r}"
        )
    return snapshot_stem(int(match.group(1)))


def snapshot_stem(epoch: int) -> str:
    return f"epoch_{epoch:04d}"


def policy_record(record: dict[str, Any]) -> PolicyRecord:
    return from_dict(PolicyRecord, record["policy"])


def dataset_record(record: dict[str, Any]) -> DatasetRecord:
    return from_dict(DatasetRecord, record["dataset"])


def _tensor_bytes(blob: bytes) -> bytes:
    header = int.from_bytes(blob[:_HEADER_LENGTH], "little")
    return blob[_HEADER_LENGTH + header :]


def weights_bytes(tensors: dict[str, torch.Tensor], metadata: dict[str, str] | None = None) -> bytes:
    """A safetensors file of `tensors` whose metadata records the SHA-256 of its tensor bytes."""
    metadata = dict(metadata or {})
    if DIGEST in metadata:
        raise ConfigError(f"weight metadata key {DIGEST!r} is reserved for the file's digest")
    digest = hashlib.sha256(_tensor_bytes(save_safetensors(tensors, metadata=metadata))).hexdigest()
    return _sorted_header(save_safetensors(tensors, metadata={**metadata, DIGEST: digest}))


def _sorted_header(blob: bytes) -> bytes:
    """`blob` with its header's keys sorted: safetensors writes its metadata in an order that varies
    from process to process, so equal tensors and metadata would not give equal bytes."""
    size = int.from_bytes(blob[:_HEADER_LENGTH], "little")
    header = json.loads(blob[_HEADER_LENGTH : _HEADER_LENGTH + size])
    text = json.dumps(header, sort_keys=True, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 8)  # safetensors pads its header with spaces to 8 bytes
    return len(text).to_bytes(_HEADER_LENGTH, "little") + text + _tensor_bytes(blob)


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


def write_record(
    folder: Path,
    train: dict[str, Any],
    head: HeadConfig,
    learning_rate: float,
    dataset: DatasetRecord,
    policy: PolicyRecord,
    threads: int | None = None,
) -> None:
    """Write `folder`/config.json in the current format (`train`: the TrainConfig as a dict;
    `threads`: the torch threads the training runs on, None: this process's)."""
    trunk = str(train["trunk"])
    write_checked_json(Path(folder) / CONFIG, {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "provenance": provenance(),
        "host": host_fingerprint(threads),
        "train": train,
        "head": to_dict(head),
        "trunk": trunk,
        "trunk_frozen": TRUNKS[trunk].frozen and not train.get("tune_stages"),
        "input_size": train["input_size"],
        "learning_rate": learning_rate,
        "dataset": to_dict(dataset),
        "policy": to_dict(policy),
    })


def read_config(folder: Path) -> dict[str, Any]:
    """A checkpoint folder's config.json in the current format's shape (an older one upgraded); a
    folder that holds none, another format or a newer version → ConfigError."""
    path = Path(folder) / CONFIG
    if not path.is_file():
        raise ConfigError(f"{folder}: not a checkpoint folder (no {CONFIG})")
    record = read_checked_json(path, _FIX)
    found = record.get("format") if isinstance(record, dict) else record
    if found != FORMAT:
        raise ConfigError(f"{path}: not a {FORMAT} config (format {found!r})")
    version = record.get("format_version", 1)
    if not isinstance(version, int) or isinstance(version, bool) or not 1 <= version <= FORMAT_VERSION:
        raise ConfigError(
            f"{path}: checkpoint format version {version!r}, but this depthq reads versions 1 to "
            f"{FORMAT_VERSION}; it was written by a newer depthq: upgrade depthq to read it"
        )
    return migrate_checkpoint(record, version)


def write_sidecar(folder: Path, stem: str, record: dict[str, Any]) -> None:
    """`folder`/`stem`.json: a weight file's epoch and metrics (best.json, ...), with its checksum."""
    write_checked_json(Path(folder) / f"{stem}.json", record)


def read_sidecar(folder: Path, stem: str) -> dict[str, Any]:
    """`folder`/`stem`.json (`write_sidecar`), its checksum checked."""
    return read_checked_json(Path(folder) / f"{stem}.json", _FIX)


def stored_parts(model: QNet) -> list[tuple[str, torch.nn.Module]]:
    """The modules a checkpoint stores: the head, plus the trunk's trained part (`Trunk.trained_part`:
    all of a trunk trained with the head, a tuned one's late stages)."""
    trunk = model.trunk.trained_part()
    return [("head", model.head)] + ([] if trunk is None else [("trunk", trunk)])


def trainable_state(model: QNet) -> dict[str, torch.Tensor]:
    """The weights a checkpoint stores of `model`, named "<part>.<parameter>" (`stored_parts`)."""
    return {
        f"{name}.{k}": t.detach().cpu().contiguous()
        for name, m in stored_parts(model) for k, t in m.state_dict().items()
    }


def load_trainable_state(model: QNet, tensors: dict[str, torch.Tensor], path: Path) -> None:
    """Put the "<part>.<parameter>" tensors of `path` into `model`'s stored parts."""
    try:
        for name, module in stored_parts(model):
            prefix = f"{name}."
            module.load_state_dict({k[len(prefix) :]: v for k, v in tensors.items() if k.startswith(prefix)})
    except RuntimeError as err:
        raise ConfigError(f"{path}: weights do not fit the network of its config.json ({err})") from err
