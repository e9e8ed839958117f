"""A two-node Ray cluster on this machine (`ray start --head` plus a second `ray start --address`,
each with its own temp folder and 2 CPUs): the smoke preset's trainings and evaluations, each a Ray
task, run on both nodes, as Ray's task records show, and killing the second node mid-run still gives
the tables of the local executor, to the byte (this is also the suite's test that Ray and local
processes give the same tables: a second, one-node run would cost 80 s of the 10-minute budget). The
reference policies' evaluations are the local run's (their Ray actors: tests/test_parallel.py)."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import tempfile
import threading
from pathlib import Path

import pytest

from depthq.parallel import Executor
from depthq.report.reproduce import reproduce

ray = pytest.importorskip("ray")
state = pytest.importorskip("ray.util.state")

pytestmark = [pytest.mark.slow, pytest.mark.ray, pytest.mark.cluster]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _raylets(port: int) -> list[int]:
    """Process ids of the raylet serving node-manager `port`."""
    pids = []
    for proc in Path("/proc").iterdir():
        try:
            cmd = (proc / "cmdline").read_bytes().replace(b"\0", b" ")
        except OSError:
            continue
        if proc.name.isdigit() and b"raylet" in cmd and f"--node_manager_port={port}".encode() in cmd:
            pids.append(int(proc.name))
    return pids


@pytest.fixture
def cluster():
    """Head and worker node, 2 CPUs each; yields (address, dashboard address, worker's node-manager
    port). Short temp folders: Ray's socket paths must fit in 107 bytes."""
    # Token authentication (conftest.py sets it for this process, the driver): the nodes and the
    # driver share one token through ~/.ray/auth_token.
    env = os.environ | {"RAY_AUTH_MODE": "token", "RAY_USAGE_STATS_ENABLED": "0"}
    port, dashboard, worker_port = _free_port(), _free_port(), _free_port()
    temp = Path(tempfile.mkdtemp(prefix="ray", dir="/tmp"))
    ray_bin = shutil.which("ray")
    assert ray_bin
    common = ["--num-cpus", "2", "--disable-usage-stats"]
    head = [ray_bin, "start", "--head", "--port", str(port), "--temp-dir", str(temp / "head"),
            "--include-dashboard", "true", "--dashboard-port", str(dashboard), *common]
    worker = [ray_bin, "start", "--address", f"127.0.0.1:{port}", "--temp-dir", str(temp / "worker"),
              "--node-manager-port", str(worker_port), *common]
    try:
        # the token every node and the driver read (kept if there is one: Ray made it on an earlier start)
        subprocess.run([ray_bin, "get-auth-token", "--generate"], env=env, check=True, capture_output=True)
        for cmd in (head, worker):
            subprocess.run(cmd, env=env, check=True, capture_output=True, timeout=120)
        yield f"127.0.0.1:{port}", f"http://127.0.0.1:{dashboard}", worker_port
    finally:
        ray.shutdown()
        subprocess.run([ray_bin, "stop", "--force"], env=env, capture_output=True, timeout=120)
        shutil.rmtree(temp, ignore_errors=True)


def test_a_two_node_cluster_runs_the_smoke_preset_and_survives_losing_a_node(smoke, tmp_path, cluster):
    address, dashboard, worker_port = cluster
    copy = tmp_path / "out"
    copy.mkdir()
    shutil.copytree(smoke / "data", copy / "data")
    shutil.copyfile(smoke / "reproduce.json", copy / "reproduce.json")
    # The reference policies' evaluations too: they run before any model job, one after the other, in
    # Ray actors that tests/test_parallel.py checks against local processes; here only the models'.
    for ref in ("heuristic", "ou"):
        shutil.copytree(smoke / "eval" / ref, copy / "eval" / ref)
    seen: dict[str, set[str]] = {}  # node id → names of the jobs it finished, from Ray's task records
    killed: list[str] = []  # the node id of the worker, once stopped
    finished = threading.Event()

    def watch() -> None:
        """Record where jobs finish; kill the worker node once it has finished two of them."""
        while not finished.wait(1) and not killed:
            tasks = state.list_tasks(address=dashboard, limit=1000, raise_on_missing_output=False)
            for task in tasks:
                if task.state == "FINISHED" and task.name.startswith(("train ", "evaluate ")):
                    seen.setdefault(task.node_id, set()).add(task.name)
            worker = [node for node in seen if ray.is_initialized() and node != head_node()]
            if worker and len(seen[worker[0]]) >= 2:
                for pid in _raylets(worker_port):
                    os.kill(pid, signal.SIGKILL)
                killed.append(worker[0])

    def head_node() -> str:
        return ray.get_runtime_context().get_node_id()

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    reproduce("smoke", copy, progress=False, executor=Executor("ray", address))
    finished.set()
    watcher.join(timeout=30)

    assert killed, f"the worker node never finished two jobs: {seen}"
    assert len(seen) == 2 and seen[head_node()], seen  # jobs finished on both nodes
    for name in ("table1.csv", "table1.md", "table2.md"):
        assert (copy / name).read_bytes() == (smoke / name).read_bytes(), name
