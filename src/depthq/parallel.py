"""Where the parallel work of collection and evaluation runs: local processes or a Ray cluster.

Both jobs are a list of independent tasks (a run to collect, a canyon to drive) served by workers
that keep an expensive state between tasks (a MuJoCo world with its EGL context, a loaded policy).
`Executor.run` takes a picklable `make_worker()` that builds that state and returns a callable
`worker(task) -> result` with a `close()`, and yields `(position, result)` as tasks finish:

- `local`: `workers` spawned processes on this machine (spawned: EGL contexts do not survive a fork);
- `ray`: `workers` Ray actors of one CPU each, on the cluster at `address` (None: a Ray started on
  this machine); an actor whose node dies is restarted elsewhere and its task retried.

A task's result depends on the task alone (each carries its own seeds), so the results are the
same whatever the executor and the number of workers or nodes; callers order them by position.
"""

from __future__ import annotations

import importlib.util
import os
import queue
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from depthq.errors import ConfigError

EXECUTORS = ("local", "ray")


class Worker(Protocol):
    def __call__(self, task: Any) -> Any: ...

    def close(self) -> None: ...


def cores() -> int:
    """The CPU cores this process may run on (its affinity, not the machine's count)."""
    return len(os.sched_getaffinity(0))


@dataclass(frozen=True)
class Executor:
    """`kind` 'local' or 'ray'; `address` of a Ray cluster (e.g. 'ray://head:10001' or 'auto')."""

    kind: str = "local"
    address: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in EXECUTORS:
            raise ConfigError(f"--executor must be one of {EXECUTORS}, got {self.kind!r}")
        if self.address is not None and self.kind != "ray":
            raise ConfigError(f"--ray-address {self.address!r} needs --executor ray")
        if self.kind == "ray" and importlib.util.find_spec("ray") is None:  # before any work starts
            raise ConfigError('--executor ray needs Ray: pip install "depthq[ray]"')

    def run(
        self, make_worker: Callable[[], Worker], tasks: Sequence[Any], workers: int, what: str
    ) -> Iterator[tuple[int, Any]]:
        """(position in `tasks`, result) for every task, in the order they finish."""
        if workers < 1:
            raise ConfigError(f"--workers must be >= 1, got {workers}")
        if not tasks:
            return iter(())
        workers = min(workers, len(tasks))
        if self.kind == "ray":
            return _run_ray(make_worker, tasks, workers, what, self.address)
        return _run_local(make_worker, tasks, workers, what)


def _serve(make_worker: Callable[[], Worker], tasks, results) -> None:
    """A local worker process: build the state once, then serve tasks until the None sentinel."""
    worker = make_worker()
    try:
        while (item := tasks.get()) is not None:
            position, task = item
            try:
                results.put((position, True, worker(task)))
            except Exception:
                results.put((position, False, traceback.format_exc()))
                return
    finally:
        worker.close()


def _run_local(make_worker, tasks, workers: int, what: str) -> Iterator[tuple[int, Any]]:
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    task_queue, results = ctx.Queue(), ctx.Queue()
    for item in enumerate(tasks):
        task_queue.put(item)
    for _ in range(workers):
        task_queue.put(None)
    procs = [ctx.Process(target=_serve, args=(make_worker, task_queue, results), daemon=True)
             for _ in range(workers)]
    for p in procs:
        p.start()
    try:
        for _ in tasks:
            position, ok, value = _next(results, procs, what)
            if not ok:
                raise RuntimeError(f"a {what} worker failed on task {position}:\n{value}")
            yield position, value
    finally:
        for p in procs:
            p.join(timeout=10)
            if p.is_alive():
                p.terminate()


def _next(results, procs, what: str) -> Any:
    """The next item a worker put on `results`; an error instead of a hang when every worker died."""
    while True:
        try:
            return results.get(timeout=5)
        except queue.Empty:
            if not any(p.is_alive() for p in procs):
                raise RuntimeError(f"all {what} workers died; run the same command to resume") from None


class _RayWorker:
    """A Ray actor around one worker: its state lives as long as the actor."""

    def __init__(self, make_worker: Callable[[], Worker]) -> None:
        self.worker = make_worker()

    def run(self, item: tuple[int, Any]) -> tuple[int, Any]:
        position, task = item
        return position, self.worker(task)


def _run_ray(make_worker, tasks, workers: int, what: str, address: str | None) -> Iterator[tuple[int, Any]]:
    import ray
    from ray.util import ActorPool

    if not ray.is_initialized():
        # Workers render offscreen like this process; MUJOCO_GL must be set before mujoco is imported.
        env = {"MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
        ray.init(address=address, runtime_env={"env_vars": env}, include_dashboard=False,
                 log_to_driver=False, configure_logging=False)
    actor = ray.remote(num_cpus=1, max_restarts=-1, max_task_retries=-1)(_RayWorker)
    actors = [actor.remote(make_worker) for _ in range(workers)]
    try:
        yield from ActorPool(actors).map_unordered(lambda a, item: a.run.remote(item), list(enumerate(tasks)))
    except ray.exceptions.RayError as err:
        raise RuntimeError(f"a {what} task failed on Ray: {err}") from err
    finally:
        for a in actors:
            ray.kill(a)


LOCAL = Executor()  # the default: processes on this machine


def add_executor_arguments(parser: Any) -> None:
    """`--executor` and `--ray-address` for a verb whose work runs on an Executor."""
    parser.add_argument("--executor", default="local", help="local (processes here, default) or ray")
    parser.add_argument("--ray-address", default=None, help="a Ray cluster's address (default: start one)")


def executor_from(args: Any) -> Executor:
    return Executor(args.executor, args.ray_address)
