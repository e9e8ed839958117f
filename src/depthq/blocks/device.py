"""Where networks run: `--device auto|cpu|cuda|cuda:N|mps` on every verb that runs one.

`auto` takes CUDA when torch sees a GPU, then Apple's MPS, else the CPU. On the CPU every number
is what it always was (the determinism tests run there). A device that torch cannot use is a
ConfigError naming it, before any work starts.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from depthq.errors import ConfigError

if TYPE_CHECKING:
    import torch

DEVICE_HELP = "auto (CUDA if torch sees a GPU, then MPS, else CPU), cpu, cuda, cuda:N or mps"


def resolve_device(spec: str) -> torch.device:
    """The torch device `spec` names (see DEVICE_HELP); one torch cannot use → ConfigError."""
    import torch  # here, not at the top: the CLI imports DEVICE_HELP for its help text

    if spec == "auto":
        if torch.cuda.is_available():
            return torch.device("cuda")
        return torch.device("mps" if torch.backends.mps.is_available() else "cpu")
    try:
        device = torch.device(spec)
    except (RuntimeError, TypeError):
        raise ConfigError(f"--device {spec!r}: expected {DEVICE_HELP}") from None
    if device.type == "cpu":
        return device
    if device.type == "cuda":
        if not torch.cuda.is_available():
            raise ConfigError(f"--device {spec!r}: torch {torch.__version__} sees no CUDA GPU (a CPU build?)")
        if device.index is not None and device.index >= torch.cuda.device_count():
            raise ConfigError(f"--device {spec!r}: only {torch.cuda.device_count()} CUDA device(s)")
        return device
    if device.type == "mps":
        if not torch.backends.mps.is_available():
            raise ConfigError(f"--device {spec!r}: torch sees no MPS device")
        return device
    raise ConfigError(f"--device {spec!r}: expected {DEVICE_HELP}")
