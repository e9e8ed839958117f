"""One writer per output: an exclusive OS file lock on a folder a verb writes, held for the job's life.

The lock is `fcntl.flock` on a sibling file `.NAME.lock` beside the folder (so the folder itself
holds nothing but its outputs, and a folder not made yet can be locked). The kernel releases it when
the process ends, however it ends: a lock file left by a killed process never blocks. A second writer
is refused at once (ConfigError, CLI exit 2) with the holder's PID and verb, which the lock file
holds; a reader asks `writer` whether a folder is being written (a dataset being labelled).
"""

from __future__ import annotations

import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from depthq.errors import ConfigError


def lock_path(path: Path) -> Path:
    """The lock file of the folder (or file) `path`: `.NAME.lock` beside it."""
    path = Path(path).absolute()
    return path.parent / f".{path.name}.lock"


def _holder(text: str) -> tuple[str, str]:
    """(PID, verb) as a lock file holds them ("PID" or "PID VERB")."""
    pid, _, verb = text.strip().partition(" ")
    return pid or "unknown", verb


def _named(pid: str, verb: str) -> str:
    return f"PID {pid}" + (f", depthq {verb}" if verb else "")


def writer(path: Path) -> tuple[str, str] | None:
    """(PID, verb) of another process holding the lock of `path` (the folder is being written), or
    None: no lock, or this process's own."""
    lock = lock_path(path)
    try:
        fd = os.open(lock, os.O_RDONLY)
    except FileNotFoundError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        pid, verb = _holder(os.pread(fd, 64, 0).decode(errors="replace"))
        return None if pid == str(os.getpid()) else (pid, verb)
    finally:
        os.close(fd)  # releases the shared lock, if taken
    return None


@contextmanager
def exclusive(path: Path, flag: str = "--out", verb: str = "") -> Iterator[None]:
    """Hold the lock of `path` (`flag`: how the user named it; `verb`: the depthq verb that writes it)
    until the block ends. `path` naming an existing file, not a folder, or a folder another process
    holds → ConfigError, nothing written."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ConfigError(f"{flag} {path}: exists and is not a folder; name a folder")
    lock = lock_path(path)
    made = [p for p in (lock.parent, *lock.parent.parents) if not p.exists()]  # removed if left empty
    lock.parent.mkdir(parents=True, exist_ok=True)
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _holder(os.pread(fd, 64, 0).decode(errors="replace"))
            os.close(fd)
            for folder in made:
                folder.rmdir()
            raise ConfigError(
                f"{flag} {path}: another depthq process ({_named(*holder)}) is writing it; wait for it "
                "to finish or choose another folder"
            ) from None
        # The holder before us may have removed the file after we opened it: then lock the new one.
        try:
            same = os.fstat(fd).st_ino == os.stat(lock).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()} {verb}".strip().encode() + b"\n", 0)
        yield
    finally:
        lock.unlink(missing_ok=True)  # while still held: a waiting opener sees the inode change
        os.close(fd)
        for folder in made:
            try:
                folder.rmdir()
            except OSError:
                break  # not empty: the job wrote there
