"""The project's error types, and the one line the CLI prints for an error a user can act on."""

from __future__ import annotations

import errno
import os
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path


class ConfigError(ValueError):
    """Bad configuration or input value; the message names the value. CLI exit status 2."""


class DataError(RuntimeError):
    """A stored file is missing, truncated, corrupted or does not match its manifest. Exit status 1."""


class WorkerError(RuntimeError):
    """A task failed in a worker process (local or Ray); the message holds the worker's traceback.

    `error` is the worker's own exception, with its type, errno and filename, so that the CLI explains
    a full disk in a worker as it does in the main process; None when the worker died without one
    (killed by a signal, e.g. by the out-of-memory killer).
    """

    def __init__(self, message: str, error: BaseException | None = None) -> None:
        super().__init__(message)
        self.error = error


_DISK_FULL = (errno.ENOSPC, errno.EDQUOT)
_DENIED = (errno.EACCES, errno.EPERM, errno.EROFS)
# Where HDF5 (h5py) names the file in its OSError messages: "... filename = '/x/.r.h5.tmp', ...".
_HDF5_NAME = re.compile(r"\b(?:file)?name = '([^']+)'")
# MuJoCo's offscreen rendering (EGL, OSMesa) failing to load or start its OpenGL libraries.
# A missing libEGL shows as PyOpenGL's "'NoneType' object has no attribute 'eglQueryString'".
_GRAPHICS = re.compile(r"\b(EGL|OSMesa|OpenGL|gladLoadGL|libGL\S*|libEGL\S*|egl[A-Z]\w*|osmesa[A-Z]\w*)\b")
_RESUME = "run the same command to resume"


def explain(err: BaseException, writes: Sequence[Path] = ()) -> tuple[int | None, str]:
    """(exit status, one line naming the path or library and the cause) for bad input (2), bad data
    (1) or a failing machine (1: disk full, permission denied, out of memory, no OpenGL for MuJoCo),
    whether raised here or in a worker; (None, "") for anything else, a bug to show in full. `writes`:
    the folders the command writes, named when the system names no path (a write to an open file)."""
    if isinstance(err, WorkerError):
        if err.error is None:
            return 1, str(err).splitlines()[0]
        return explain(err.error, writes)
    if isinstance(err, ConfigError):
        return 2, f"error: {err}"
    if isinstance(err, DataError):
        return 1, f"data error: {err}"
    if isinstance(err, MemoryError) or (isinstance(err, OSError) and err.errno == errno.ENOMEM):
        what = str(err) or "MemoryError"
        return 1, f"out of memory ({what}); use fewer --workers or a smaller job, then {_RESUME}"
    graphics = _graphics(err)
    if graphics:
        return 1, graphics
    if isinstance(err, OSError) and err.errno in _DISK_FULL + _DENIED:
        where = _where(err, writes)
        if err.errno in _DISK_FULL:
            return 1, (f"disk full: no space left on the device of {where}; nothing half-written is kept: "
                       f"free space and {_RESUME}")
        return 1, (f"{os.strerror(err.errno).lower()}: cannot write {where}; make it writable (or "
                   f"choose another folder) and {_RESUME}")
    return None, ""


def _where(err: OSError, writes: Sequence[Path] = ()) -> str:
    """The path an OSError is about, as its nearest existing folder or file (a temporary file that
    failed is removed by then: its folder is what the user can act on); when the system names none,
    the folders the command writes (`writes`)."""
    name = err.filename
    if name is None:
        found = _HDF5_NAME.search(str(err))
        name = found.group(1) if found else None
    if name is None and writes:
        folders = ", ".join(_existing(Path(p)) for p in writes)
        return f"{folders} (what this command writes; the system named no file)"
    if name is None:
        return "(a path the system did not name)"
    return _existing(Path(os.fsdecode(name)))


def _existing(path: Path) -> str:
    """`path`, or its nearest existing parent."""
    while not path.exists() and path != path.parent:
        path = path.parent
    return str(path)


def _graphics(err: BaseException) -> str:
    """One line for MuJoCo's OpenGL (EGL, OSMesa) failing to load or start, else ''."""
    kinds = ImportError | OSError | RuntimeError | AttributeError
    if not isinstance(err, kinds) and type(err).__name__ != "FatalError":  # mujoco.FatalError
        return ""
    words = [a for a in err.args if isinstance(a, str)] or [str(err)]
    detail = ": ".join(dict.fromkeys(w.strip() for w in words if w.strip())).splitlines()
    if not detail or not _GRAPHICS.search(detail[0]):
        return ""
    if isinstance(err, AttributeError):
        detail[0] = f"its EGL/GL library did not load ({detail[0]})"
    backend = os.environ.get("MUJOCO_GL", "egl")
    return (f"MuJoCo cannot render offscreen (MUJOCO_GL={backend}): {detail[0]}; install EGL and Mesa "
            "(Debian: libegl1 libgl1-mesa-dri) or set MUJOCO_GL=osmesa, then " + _RESUME)


def guarded(prog: str, work: Callable[[], int]) -> int:
    """`work()`'s exit status, or the status and one line `explain` gives for what it raised: a module's
    command line (`python -m …`) answers bad input as the `depthq` verbs do; a bug is shown in full."""
    try:
        return work()
    except Exception as err:
        status, line = explain(err)
        if status is None:
            raise
        print(f"{prog}: {line}", file=sys.stderr)
        return status
