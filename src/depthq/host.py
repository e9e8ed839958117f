"""The host fingerprint: what about a machine decides a result's last bits (docs/design.md#determinism).

Canyons, exploration data, labels and Table II are the same on every machine; trained weights and
driving metrics are the same only for the same CPU kernels and thread count, because torch's sums
run in an order that depends on both. So every checkpoint, feature cache and evaluation records the
machine that made it: CPU model and SIMD flags, the BLAS libraries and versions of numpy and torch,
torch's CPU capability, its threads, mujoco. `depthq host` prints it.
"""

from __future__ import annotations

import platform
import re
from pathlib import Path
from typing import Any

# The CPU flags that choose a BLAS or convolution kernel (x86 SIMD widths and matrix units, arm's).
KERNEL_FLAGS = re.compile(r"^(sse4_2|avx|avx2|fma|f16c|avx512\w*|amx\w*|asimd\w*|sve\w*|sme(?!p)\w*|neon)$")


def _cpu() -> dict[str, Any]:
    """CPU model and the kernel-relevant flags, from /proc/cpuinfo where it exists (Linux)."""
    model, flags = platform.processor() or platform.machine(), set()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        for line in cpuinfo.read_text(errors="replace").splitlines():
            key, _, value = line.partition(":")
            key = key.strip().lower()
            if key in ("model name", "cpu model", "hardware") and value.strip():
                model = value.strip()
            elif key in ("flags", "features"):
                flags |= set(value.split())
    return {"model": model, "machine": platform.machine(),
            "kernel_flags": sorted(f for f in flags if KERNEL_FLAGS.match(f))}


def _torch(threads: int | None) -> dict[str, Any]:
    import torch  # the base layer loads torch only when a fingerprint is asked for

    config = torch.__config__.show()
    found = {name: re.search(pattern, config) for name, pattern in (
        ("mkl", r"Math Kernel Library Version ([\w.\-]+)"),
        ("onednn", r"MKL-DNN v([\w.]+)"),
        ("openblas", r"OpenBLAS ([\w.]+)"),
    )}
    return {
        "version": torch.__version__,
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        **{name: match.group(1) for name, match in found.items() if match},
        "threads": torch.get_num_threads() if threads is None else threads,
    }


def _numpy() -> dict[str, Any]:
    import numpy as np

    config = np.show_config(mode="dicts")
    blas = config.get("Build Dependencies", {}).get("blas", {})
    simd = config.get("SIMD Extensions", {})
    return {"version": np.__version__, "blas": f"{blas.get('name', '?')} {blas.get('version', '?')}",
            "simd": simd.get("found", [])}


def host_fingerprint(threads: int | None = None) -> dict[str, Any]:
    """This machine's fingerprint as a JSON-ready dict; `threads`: the torch threads that made the
    artifact (None: this process's current setting)."""
    import mujoco

    return {
        "cpu": _cpu(),
        "python": platform.python_version(),
        "numpy": _numpy(),
        "torch": _torch(threads),
        "mujoco": mujoco.__version__,
    }
