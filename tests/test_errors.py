"""A machine that fails under a long job (disk full, permission denied, out of memory, no EGL) ends it
with one line naming the path or library and the cause, exit 1, the output consistent and resumable;
errors in worker processes arrive in the main process as themselves (type, errno, filename)."""

from __future__ import annotations

import errno
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from depthq.errors import WorkerError, explain
from depthq.parallel import Executor

TINY = ["--val-runs", "0", "--max-steps", "30", "--workers", "2"]  # workers last: TINY[:-1], "1" has one
ENV = {**os.environ, "MUJOCO_GL": "egl"}
PROGRESS = re.compile(r"\d+%\|")  # a tqdm progress bar
ENV.pop("DEPTHQ_DEBUG", None)


def depthq(*argv: str, env: dict[str, str] = ENV, user: str | None = None) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "depthq.cli", *argv]
    if user is not None:  # root ignores permissions: run as an unprivileged user
        cmd = ["setpriv", f"--reuid={user}", f"--regid={user}", "--clear-groups", *cmd]
    return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)


def said(stderr: str) -> list[str]:
    """What a command said on stderr, less its progress bars."""
    return [line for line in stderr.splitlines() if line.strip() and not PROGRESS.search(line)]


def assert_one_line(result: subprocess.CompletedProcess, *words: str) -> None:
    assert result.returncode == 1, result.stderr
    lines = said(result.stderr)
    assert len(lines) == 1 and all(w in lines[0] for w in words), result.stderr


def assert_clean(folder: Path) -> None:
    """Nothing half-written: no temporary file, and the dataset checks out."""
    assert not [p for p in folder.rglob("*.tmp")]
    assert depthq("dataset", "verify", str(folder)).returncode == 0


@pytest.fixture
def small_disk() -> Iterator[Path]:
    """A 1 MB tmpfs (the capability to mount one is needed: root in a container may lack it)."""
    folder = Path(tempfile.mkdtemp(prefix="depthq-full-"))
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(folder)],
                             capture_output=True, text=True)
    if mounted.returncode != 0:
        folder.rmdir()
        pytest.skip(f"cannot mount a small tmpfs here: {mounted.stderr.strip()}")
    yield folder
    subprocess.run(["umount", str(folder)], check=True)
    folder.rmdir()


@pytest.mark.slow  # collections in subprocesses: 10-35 s on this 2-core host
def test_disk_full_in_a_worker_is_one_line_and_resumes(small_disk: Path) -> None:
    out = small_disk / "d"
    full = depthq("collect", "--runs", "6", *TINY, "--out", str(out))
    assert_one_line(full, "disk full", str(out / "runs"))
    assert not list(out.rglob("*.tmp"))
    subprocess.run(["mount", "-o", "remount,size=16m", str(small_disk)], check=True)  # space freed
    resumed = depthq("collect", "--runs", "6", *TINY[:-1], "1", "--out", str(out))  # one worker: quicker
    assert resumed.returncode == 0, resumed.stderr
    assert "(6 usable)" in resumed.stdout
    assert_clean(out)


def _fill(disk: Path) -> None:
    """Leave one page free on `disk`, the lock file's (what a long job meets when another fills the disk)."""
    free = shutil.disk_usage(disk).free
    with open(disk / "filler", "wb") as f:
        f.write(b"\0" * (free - 4096))


def test_disk_full_in_evaluate_names_its_out_folder(small_disk: Path) -> None:
    """A write to an open file (the system names no path) is named by the folder the verb writes."""
    out = small_disk / "eval"
    _fill(small_disk)
    full = depthq("evaluate", "heuristic", "--canyons", "val:0", "--time-limit-s", "2", "--workers", "1",
                  "--out", str(out))
    assert_one_line(full, "disk full", f"device of {out} (what this command writes")
    assert not (out / "summary.json").exists()


@pytest.mark.slow  # the feature cache of the small dataset, then a training's first save
def test_disk_full_in_train_names_its_out_folder(small_disk: Path, small_dataset: Path) -> None:
    out = small_disk / "model"
    _fill(small_disk)
    full = depthq("train", "--model", "depth", "--data", str(small_dataset), "--epochs", "1",
                  "--train-batches", "2", "--val-batches", "1", "--batch-size", "16", "--out", str(out))
    assert_one_line(full, "disk full", f"device of {out} (what this command writes")


@pytest.fixture
def as_nobody() -> Iterator[tuple[str, Path]]:
    """An unprivileged user and a folder it can reach (pytest's own tmp folders are root's, 0700).
    Only for commands that fail before they start worker processes (see the read-only test)."""
    if shutil.which("setpriv") is None or os.geteuid() != 0:
        pytest.skip("needs root and setpriv to run a command as an unprivileged user")
    folder = Path(tempfile.mkdtemp(prefix="depthq-denied-"))
    folder.chmod(0o755)
    yield "65534", folder
    shutil.rmtree(folder)


@pytest.mark.slow  # collections in subprocesses: 10-35 s on this 2-core host
def test_a_read_only_folder_in_a_worker_is_one_line(tmp_path: Path) -> None:
    """The dataset folder is writable (the manifest is written) but runs/, where the workers write,
    is a read-only bind mount: the workers' error is the line, naming runs/. (A worker cannot run as
    an unprivileged user here: it re-executes Python, which may live in root's home.)"""
    out = tmp_path / "d"
    runs = out / "runs"
    runs.mkdir(parents=True)
    bind = subprocess.run(["mount", "--bind", str(runs), str(runs)], capture_output=True, text=True)
    if bind.returncode != 0:
        pytest.skip(f"cannot bind-mount a folder read-only here: {bind.stderr.strip()}")
    try:
        subprocess.run(["mount", "-o", "remount,bind,ro", str(runs)], check=True)
        denied = depthq("collect", "--runs", "3", *TINY, "--out", str(out))
        assert_one_line(denied, "read-only file system", str(runs))
        assert not list(runs.iterdir())
    finally:
        subprocess.run(["umount", str(runs)], check=True)
    resumed = depthq("collect", "--runs", "3", *TINY[:-1], "1", "--out", str(out))
    assert resumed.returncode == 0, resumed.stderr


@pytest.mark.slow  # collections in subprocesses: 10-35 s on this 2-core host
def test_permission_denied_on_the_output_folder_is_one_line(as_nobody: tuple[str, Path]) -> None:
    user, folder = as_nobody
    denied = depthq("collect", "--runs", "3", *TINY, "--out", str(folder / "d"), user=user,
                    env={**ENV, "HOME": str(folder)})
    assert_one_line(denied, "permission denied", str(folder))
    assert not (folder / "d").exists()
    debug = depthq("--debug", "collect", "--runs", "3", *TINY, "--out", str(folder / "d"), user=user,
                   env={**ENV, "HOME": str(folder)})
    assert debug.returncode == 1 and "Traceback" in debug.stderr and "PermissionError" in debug.stderr
    assert said(debug.stderr)[-1] == said(denied.stderr)[0]


def test_no_egl_library_is_one_line(tmp_path: Path) -> None:
    """A machine without libEGL, in the main process and in spawned workers alike: a sitecustomize
    makes the dynamic loader refuse it, as it does where the library is not installed."""
    (tmp_path / "sitecustomize.py").write_text(
        "import ctypes\n"
        "_init = ctypes.CDLL.__init__\n"
        "def _no_egl(self, name, *args, **kwargs):\n"
        "    if name and 'libEGL' in str(name):\n"
        "        raise OSError(f'{name}: cannot open shared object file: No such file or directory')\n"
        "    _init(self, name, *args, **kwargs)\n"
        "ctypes.CDLL.__init__ = _no_egl\n"
    )
    env = {**ENV, "PYTHONPATH": os.pathsep.join([str(tmp_path), *sys.path])}
    result = depthq("collect", "--runs", "3", *TINY, "--out", str(tmp_path / "d"), env=env)
    assert_one_line(result, "MuJoCo cannot render offscreen", "EGL", "libegl1")


class Greedy:
    """A worker that asks for more memory than any machine has: a real MemoryError."""

    def __call__(self, task: int) -> int:
        return len(bytearray(1 << 60))

    def close(self) -> None:
        pass


class Killed:
    """A worker the system kills (as the out-of-memory killer does: SIGKILL, no exception)."""

    def __call__(self, task: int) -> int:
        os.kill(os.getpid(), signal.SIGKILL)
        return task

    def close(self) -> None:
        pass


class Full:
    """A worker whose disk is full."""

    def __call__(self, task: int) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), f"/nowhere/run{task}.h5")

    def close(self) -> None:
        pass


def test_a_worker_error_arrives_as_itself() -> None:
    with pytest.raises(WorkerError) as caught:
        list(Executor().run(Full, [0, 1], workers=1, what="demo"))
    error = caught.value.error
    assert isinstance(error, OSError) and (error.errno, error.filename) == (errno.ENOSPC, "/nowhere/run0.h5")
    assert explain(caught.value) == (1, explain(error)[1]) and "disk full" in explain(error)[1]


def test_out_of_memory_in_a_worker_is_one_line() -> None:
    with pytest.raises(WorkerError) as caught:
        list(Executor().run(Greedy, [0], workers=1, what="demo"))
    status, line = explain(caught.value)
    assert status == 1 and line.startswith("out of memory") and "\n" not in line


def test_a_killed_worker_is_one_line() -> None:
    with pytest.raises(WorkerError) as caught:
        list(Executor().run(Killed, [0, 1], workers=2, what="demo"))
    status, line = explain(caught.value)
    assert status == 1 and "killed by SIGKILL" in line and "out-of-memory" in line and "\n" not in line
