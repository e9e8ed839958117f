"""A ROS 1 graph on this machine for as long as a `with` block: roscore on a free port and the processes
started against it (`depthq ros sim`, `depthq ros drive`, `rosbag record`, …), each in a process group
of its own and each logging to a file, all stopped when the block ends, whatever happened (SIGINT,
then SIGKILL after a grace period; roscore last, and no master left answering on its port). The
closed-loop test and `research.ros_fidelity` drive through it."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from depthq.errors import ConfigError


class RosGraph:
    """roscore and its processes; logs in `folder` (NAME.log), ROS's own files in `folder`/ros."""

    def __init__(self, folder: Path, timeout_s: float = 30.0) -> None:
        self.folder = Path(folder).absolute()  # its processes run in it: ROS_HOME must not be relative
        self.folder.mkdir(parents=True, exist_ok=True)
        with socket.socket() as s:
            s.bind(("localhost", 0))
            self.port = s.getsockname()[1]
        ros = self.folder / "ros"
        self.env = {**os.environ, "ROS_MASTER_URI": f"http://localhost:{self.port}", "PYTHONUNBUFFERED": "1",
                    "ROS_HOME": str(ros), "ROS_LOG_DIR": str(ros / "log")}
        self.procs: dict[str, subprocess.Popen] = {}
        self.timeout_s = timeout_s

    def __enter__(self) -> RosGraph:
        try:
            self.start("roscore", ["roscore", "-p", str(self.port)])
        except FileNotFoundError:
            raise ConfigError("roscore is not installed: apt-get install ros-core (docs/robot.md)") from None
        try:
            self.wait_for(self.master_up, self.timeout_s, "roscore")
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def master_up(self) -> bool:
        with socket.socket() as s:
            return s.connect_ex(("localhost", self.port)) == 0

    def start(self, name: str, argv: list[str]) -> subprocess.Popen:
        """Start `argv` as process `name`, stdout and stderr to NAME.log."""
        with open(self.folder / f"{name}.log", "w") as log:
            self.procs[name] = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, env=self.env,
                                                cwd=self.folder, start_new_session=True, preexec_fn=_sigint)
        return self.procs[name]

    def depthq(self, name: str, *args: str) -> subprocess.Popen:
        """A `depthq` command of this environment's Python."""
        return self.start(name, [sys.executable, "-m", "depthq.cli", *args])

    def run(self, *argv: str, timeout: float = 30.0) -> subprocess.CompletedProcess:
        """A short ROS command against the master (`rosnode kill …`), its output captured."""
        return subprocess.run(argv, env=self.env, timeout=timeout, capture_output=True, text=True, check=True)

    def log(self, name: str) -> str:
        return (self.folder / f"{name}.log").read_text()

    def wait_for(self, ready: Callable[[], bool], timeout: float, what: str) -> None:
        """Until `ready()`; an error naming `what` and the logs' tails if a process fails or time runs out."""
        deadline = time.monotonic() + timeout
        while not ready():
            failed = [n for n, p in self.procs.items() if p.poll() not in (0, None)]
            if failed or time.monotonic() > deadline:
                why = f"{failed} failed" if failed else f"not within {timeout} s"
                tails = " | ".join(f"{n}: {self.log(n)[-1500:]}" for n in self.procs)
                raise RuntimeError(f"{what}: {why}; logs: {tails}")
            time.sleep(0.1)

    def finish(self, name: str, timeout: float) -> str:
        """Wait for process `name` to end by itself; its log."""
        self.procs[name].wait(timeout=timeout)
        return self.log(name)

    def stop(self, name: str, grace: float = 10.0) -> None:
        """SIGINT to process `name`'s group, SIGKILL if it has not ended after `grace` s. Returns once the
        whole group has ended: a child may outlive its parent (`rosbag record`'s recorder, which renames
        its .bag.active when it has closed the file)."""
        proc = self.procs[name]
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)
        deadline = time.monotonic() + grace
        while _group_alive(proc.pid) and time.monotonic() < deadline:
            proc.poll()  # reap the leader, so that only live members keep the group
            time.sleep(0.05)
        if _group_alive(proc.pid):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()

    def close(self) -> None:
        for name in reversed(list(self.procs)):  # roscore, started first, stopped last
            self.stop(name)
        if self.master_up():
            raise RuntimeError(f"a ROS master still answers on port {self.port}")


def _group_alive(pgid: int) -> bool:
    """Whether a process of group `pgid` still runs (a zombie, ended but not yet reaped, does not)."""
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()  # after "pid (comm)": state, ppid, pgrp
        except OSError:
            continue  # ended while we looked
        if int(fields[2]) == pgid and fields[0] != "Z":
            return True
    return False


def _sigint() -> None:
    """In the child: SIGINT stops it, even where this process was started with SIGINT ignored (in the
    background of a script), which the child would inherit."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def summary(log: str) -> dict[str, Any]:
    """The JSON line `depthq ros sim --json` printed last."""
    return json.loads(next(line for line in reversed(log.splitlines()) if line.startswith("{")))


def decisions(log: str) -> tuple[int, float, float]:
    """A `depthq ros drive` log's last statistics: decisions, their rate (Hz), median latency (ms)."""
    found = re.findall(r"(\d+) decisions at ([\d.na]+) Hz, latency frame→command median ([\d.na]+) ms", log)
    if not found:
        return 0, float("nan"), float("nan")
    return int(found[-1][0]), float(found[-1][1]), float(found[-1][2])
