"""A checkpoint folder, written and read in one place: its format (`format`: config.json, the weight
files, their digests, the version), the folder a training writes epoch by epoch and resumes
(`training`), and which weights act and the network that acts with them (`acting`). It sits above
`depthq.networks` (it rebuilds a checkpoint's network) and below `depthq.policies` (which drive one)
and `depthq.train` (which calls it once per epoch), so a policy needs nothing from training, nor the
dataset: a checkpoint folder describes itself (docs/formats.md#checkpoint)."""

from depthq.checkpoint.acting import (
    AVERAGE_TOLERANCE_SE,
    average_fails,
    average_margin,
    chosen_weights,
    load_qnet,
    read_checkpoint,
)
from depthq.checkpoint.format import (
    CONFIG,
    DIGEST,
    FORMAT,
    FORMAT_VERSION,
    WEIGHTS,
    DatasetRecord,
    PolicyRecord,
    dataset_record,
    policy_record,
    read_config,
    read_sidecar,
    read_weights,
    snapshot_stem,
    weights_bytes,
    weights_stem,
    write_sidecar,
)
from depthq.checkpoint.training import (
    METRICS,
    TrainingCheckpoint,
    TrainState,
    epoch_seconds,
    read_metrics,
    saved_epoch,
    settings_differing,
)

__all__ = [
    "AVERAGE_TOLERANCE_SE", "CONFIG", "DIGEST", "FORMAT", "FORMAT_VERSION", "METRICS", "WEIGHTS",
    "DatasetRecord", "PolicyRecord", "TrainState", "TrainingCheckpoint", "average_fails", "average_margin",
    "chosen_weights", "dataset_record", "epoch_seconds", "load_qnet", "policy_record", "read_checkpoint",
    "read_config", "read_metrics", "read_sidecar", "read_weights", "saved_epoch", "settings_differing",
    "snapshot_stem", "weights_bytes", "weights_stem", "write_sidecar",
]
