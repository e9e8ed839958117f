"""Keep freed memory in the process heap while networks run on the CPU.

glibc hands large freed blocks back to the operating system (mmap'ed chunks, and trimming the top
of the heap). A convolutional trunk frees and re-allocates tens of MB of activations per call, so
every call then touches fresh pages: on the 2-core reference machine EfficientNet-Lite0 took
~130,000 page faults per 128 frames and ran at ~320 instead of ~570 frames/s. Raising both
thresholds keeps those pages mapped and reused. This changes no numbers, only speed; on a C library
other than glibc it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import platform

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD = 32 << 20  # glibc's largest allowed value on 64-bit: blocks below it come from the heap
TRIM_THRESHOLD = 1 << 30  # give memory back only when more than 1 GB is free at the top of the heap


@functools.cache
def keep_freed_memory() -> bool:
    """Ask glibc to reuse freed memory instead of returning it (once per process); whether it did."""
    if platform.libc_ver()[0] != "glibc":
        return False
    libc = ctypes.CDLL(ctypes.util.find_library("c"))
    # Both are needed: fixing the trim threshold alone also freezes glibc's adaptive mmap threshold
    # at its small default, which made the trunk 3x slower still.
    mmap_set = libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)
    return bool(mmap_set and libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
