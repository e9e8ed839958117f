"""Where parallel work runs: processes on this machine, or a Ray cluster.

Two shapes of work:

`Executor.run`: many small independent tasks (a run to collect, a canyon to drive) served by
workers that keep an expensive state between tasks (a MuJoCo world with its EGL context, a loaded
policy). It takes a picklable `make_worker()` that builds that state and returns a callable
`worker(task) -> result` with a `close()`, and yields `(position, result)` as tasks finish:

- `local`: `workers` processes on this machine, forked from a server process that imported the
  workers' modules once (`worker_context`) and never rendered (EGL contexts do not survive a fork);
- `ray`: `workers` Ray actors of one CPU each, on the cluster at `address` (None: a Ray started on
  this machine); an actor whose node dies is restarted elsewhere and its task retried.

`Executor.run_jobs`: a pipeline's steps (`Job`s: collect, train a model, evaluate it). Locally,
each `remote` job runs in a process of its own pinned to one free core, started once the jobs it
reads from are done (one job per core: a training and an evaluation overlap on 2 cores), and the
others here, one after the other; on Ray, each `remote` job is a Ray task declaring its CPUs (and
GPU), started once the jobs it reads from are done, retried on another node if its node dies.

A task's result depends on the task alone (each carries its own seeds, and a job its own thread
count), so the results are the same whatever the executor and the number of workers or nodes.
"""

from __future__ import annotations

import importlib.util
import multiprocessing as mp
import multiprocessing.connection
import os
import pickle
import queue
import secrets
import shutil
import signal
import threading
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from depthq.errors import ConfigError, WorkerError

EXECUTORS = ("local", "ray")
_RESUME = "run the same command to resume"


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
        self,
        make_worker: Callable[[], Worker],
        tasks: Sequence[Any],
        workers: int,
        what: str,
        gpu: bool = False,
    ) -> Iterator[tuple[int, Any]]:
        """(position in `tasks`, result) for every task, in the order they finish. `gpu`: the workers
        share one GPU (on Ray, each actor reserves 1/`workers` of one)."""
        if workers < 1:
            raise ConfigError(f"--workers must be >= 1, got {workers}")
        if not tasks:
            return iter(())
        workers = min(workers, len(tasks))
        if self.kind == "ray":
            return _run_ray(make_worker, tasks, workers, what, self.address, gpu / workers)
        return _run_local(make_worker, tasks, workers, what)

    def run_jobs(self, jobs: Sequence[Job]) -> Iterator[tuple[str, float]]:
        """Run `jobs` (in an order where each comes after those it reads from); yields each job's
        name and measured seconds as it finishes."""
        if self.kind == "ray":
            return _run_jobs_ray(jobs, self.address)
        return _run_jobs_local(jobs)

    def check_shared(self, folder: Path) -> None:
        """Fail with a clear message unless every node of the cluster sees and can write `folder`
        (created if missing, and removed again if the check fails)."""
        if self.kind != "ray":
            return
        folder = Path(folder).resolve()
        created = not folder.exists()
        folder.mkdir(parents=True, exist_ok=True)
        try:
            _check_shared_ray(folder, self.address)
        except ConfigError:
            if created:
                shutil.rmtree(folder, ignore_errors=True)
            raise


@dataclass(frozen=True)
class Job:
    """A step of a pipeline. `remote`: may run on any node (it reads and writes only shared
    storage), with `cpus` CPUs and `gpus` GPUs reserved; otherwise it runs on the driver, after
    every remote job before it. `after`: the jobs whose outputs it reads."""

    name: str
    run: Callable[[], object]
    after: tuple[str, ...] = ()
    remote: bool = False
    cpus: int = 1
    gpus: float = 0.0


def _timed(run: Callable[[], object], *_inputs: Any) -> float:
    """Seconds `run()` took; `_inputs` are the results of the jobs it waited for (unused)."""
    start = time.perf_counter()
    run()
    return round(time.perf_counter() - start, 1)


def _die_with_parent() -> None:
    """In a local worker: exit at once when the process that started it ends, however it ends (kill -9
    included), rather than wait for tasks forever and keep the fork server alive (it lives while a
    worker holds its pipe). A daemon thread waits on the parent's sentinel, which the parent's death
    closes (Linux has no death signal for the parent here: a worker's parent is the fork server)."""
    parent = mp.parent_process()
    if parent is None:
        return

    def watch() -> None:
        mp.connection.wait([parent.sentinel])
        os._exit(1)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def _serve(make_worker: Callable[[], Worker], tasks, results) -> None:
    """A local worker process: build the state once, then serve tasks until the None sentinel. A
    failure is sent back as (position or None while starting, False, (exception, traceback))."""
    _die_with_parent()
    position = None
    try:
        worker = make_worker()
    except Exception as err:
        results.put((position, False, (_portable(err), traceback.format_exc())))
        return
    try:
        while (item := tasks.get()) is not None:
            position, task = item
            results.put((position, True, worker(task)))
    except Exception as err:
        results.put((position, False, (_portable(err), traceback.format_exc())))
    finally:
        worker.close()


def _portable(err: BaseException) -> BaseException | None:
    """`err` if it survives pickling (to reach the main process intact: type, errno, filename), else
    None (the traceback text still names it)."""
    try:
        pickle.loads(pickle.dumps(err))
    except Exception:
        return None
    return err


# What a local worker imports (torch, MuJoCo, matplotlib: ~3 s a process), imported once per process
# in the fork server rather than again in every worker.
_PRELOAD = ["depthq.evaluate.online", "depthq.data.recorder"]


def worker_context() -> mp.context.BaseContext:
    """The start method of local workers: `forkserver`. The server is a fresh interpreter (as a spawned
    worker is: no EGL context, no threads of this process) that imports `_PRELOAD` once; each worker is
    a fork of it, so it starts in milliseconds instead of importing torch again. A worker sees this
    process's working directory and sys.path as it starts, and the environment the server started
    with."""
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(_PRELOAD)
    return ctx


def _run_local(make_worker, tasks, workers: int, what: str) -> Iterator[tuple[int, Any]]:
    ctx = worker_context()
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
                error, text = value
                where = "while starting" if position is None else f"on task {position}"
                raise WorkerError(f"a {what} worker failed {where}:\n{text}", error) from error
            yield position, value
    finally:
        for p in procs:
            p.join(timeout=10)
            if p.is_alive():
                p.terminate()


def _next(results, procs, what: str) -> Any:
    """The next item a worker put on `results`; an error instead of a hang when a worker died."""
    while True:
        try:
            return results.get(timeout=1)  # then, every second, whether a worker died
        except queue.Empty:
            for p in procs:
                if p.exitcode is not None and p.exitcode != 0:
                    raise WorkerError(_death(what, p.exitcode)) from None
            if not any(p.is_alive() for p in procs):
                raise WorkerError(f"all {what} workers died; {_RESUME}") from None


def _death(what: str, exitcode: int) -> str:
    """One line for a worker process that ended without a result, by its exit code."""
    if exitcode < 0:
        name = signal.Signals(-exitcode).name
        oom = " (the system's out-of-memory killer sends it)" if -exitcode == signal.SIGKILL else ""
        return f"a {what} worker process was killed by {name}{oom}; {_RESUME}"
    return f"a {what} worker process exited with status {exitcode}; {_RESUME}"


class _RayWorker:
    """A Ray actor around one worker: its state lives as long as the actor."""

    def __init__(self, make_worker: Callable[[], Worker]) -> None:
        self.worker = make_worker()

    def run(self, item: tuple[int, Any]) -> tuple[int, Any]:
        position, task = item
        return position, self.worker(task)


def _ray(address: str | None):
    """The `ray` module, connected to the cluster at `address` (or one started here)."""
    import ray  # the optional [ray] extra: only `--executor ray` needs it

    if not ray.is_initialized():
        # Workers render offscreen like this process; MUJOCO_GL must be set before mujoco is imported.
        env = {"MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
        ray.init(address=address, runtime_env={"env_vars": env}, include_dashboard=False,
                 log_to_driver=False, configure_logging=False)
    return ray


def _run_ray(
    make_worker, tasks, workers: int, what: str, address: str | None, gpus: float
) -> Iterator[tuple[int, Any]]:
    from ray.util import ActorPool  # the optional [ray] extra

    ray = _ray(address)
    actor = ray.remote(num_cpus=1, num_gpus=gpus, max_restarts=-1, max_task_retries=-1)(_RayWorker)
    actors = [actor.remote(make_worker) for _ in range(workers)]
    try:
        yield from ActorPool(actors).map_unordered(lambda a, item: a.run.remote(item), list(enumerate(tasks)))
    except ray.exceptions.RayError as err:
        raise WorkerError(f"a {what} task failed on Ray: {err}", _ray_cause(err)) from err
    finally:
        for a in actors:
            ray.kill(a)


def _ray_cause(err: BaseException) -> BaseException | None:
    """The task's own exception inside Ray's wrappers (a failed task, or an actor whose constructor
    failed), or None when Ray itself failed (a node lost for good)."""
    import ray  # the optional [ray] extra

    while isinstance(err, ray.exceptions.RayError):
        cause = getattr(err, "cause", None)
        if not isinstance(cause, BaseException):
            return None
        err = cause
    return err


def _run_jobs_ray(jobs: Sequence[Job], address: str | None) -> Iterator[tuple[str, float]]:
    ray = _ray(address)
    timed = ray.remote(max_retries=-1)(_timed)  # retried when its node dies; an error is not retried
    pending: dict[Any, str] = {}  # Ray object → job name
    refs: dict[str, Any] = {}

    def finished(wait_all: bool) -> Iterator[tuple[str, float]]:
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=None if wait_all else 0)
            if not ready:
                return
            name = pending.pop(ready[0])
            try:
                yield name, ray.get(ready[0])
            except ray.exceptions.RayError as err:
                raise WorkerError(f"job {name!r} failed on Ray: {err}", _ray_cause(err)) from err

    for job in jobs:
        if not job.remote:
            yield from finished(wait_all=True)
            yield job.name, _timed(job.run)
            continue
        inputs = [refs[name] for name in job.after if name in refs]
        options = {"num_cpus": job.cpus, "num_gpus": job.gpus, "name": job.name}
        refs[job.name] = timed.options(**options).remote(job.run, *inputs)
        pending[refs[job.name]] = job.name
        yield from finished(wait_all=False)
    yield from finished(wait_all=True)


def _on_core(core: int, name: str, run: Callable[[], object], results) -> None:
    """A local job's process: pinned to `core`, it runs the job and sends back its seconds or its error."""
    _die_with_parent()
    os.sched_setaffinity(0, {core})
    try:
        results.put((name, True, _timed(run)))
    except Exception as err:
        results.put((name, False, (_portable(err), traceback.format_exc())))


def _run_jobs_local(jobs: Sequence[Job]) -> Iterator[tuple[str, float]]:
    """Each remote job in a process on a free core of this process's own, once its inputs are done;
    every other job here, once all before it are done (`Executor.run_jobs`)."""
    ctx = worker_context()
    results = ctx.Queue()
    free = sorted(os.sched_getaffinity(0))
    todo, waiting = list(jobs), []
    running: dict[str, tuple[Any, int]] = {}  # job name → (its process, its core)
    done: set[str] = set()
    names = {job.name for job in jobs}  # an input not among them was done before this call

    def finish_one() -> tuple[str, float]:
        name, ok, value = _next(results, [p for p, _ in running.values()], "pipeline job")
        process, core = running.pop(name)
        process.join()
        free.append(core)
        if not ok:
            error, text = value
            raise WorkerError(f"job {name!r} failed:\n{text}", error) from error
        done.add(name)
        return name, value

    try:
        while todo or waiting or running:
            while todo and todo[0].remote:  # up to the next job that runs here
                waiting.append(todo.pop(0))
            for job in [w for w in waiting if all(a in done or a not in names for a in w.after)]:
                if not free:
                    break
                waiting.remove(job)
                core = free.pop(0)
                process = ctx.Process(target=_on_core, args=(core, job.name, job.run, results))
                process.start()
                running[job.name] = (process, core)
            if running:
                yield finish_one()
            elif waiting:
                raise WorkerError(f"jobs wait on inputs that never ran: {[w.name for w in waiting]}")
            elif todo:
                job = todo.pop(0)
                yield job.name, _timed(job.run)
                done.add(job.name)
    finally:
        for process, _ in running.values():
            process.terminate()
            process.join()


def _probe_shared(token: str, node: str) -> str:
    """On one node: '' if it sees the driver's `token` file and can write next to it, else why not."""
    if not Path(token).is_file():
        return f"does not see {Path(token).parent}"
    try:
        Path(f"{token}-{node}").write_text(node)
    except OSError as err:
        return f"cannot write to {Path(token).parent}: {err}"
    return ""


def _check_shared_ray(folder: Path, address: str | None) -> None:
    """From each alive node: `folder` holds the driver's token file, and a file that node writes
    there is seen here."""
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy  # the optional [ray] extra

    ray = _ray(address)
    token = folder / f".shared-check-{secrets.token_hex(4)}"
    token.write_text("driver")
    nodes = [n for n in ray.nodes() if n["Alive"] and n["Resources"].get("CPU", 0) > 0]
    probe = ray.remote(num_cpus=0)(_probe_shared)
    answers = [
        probe.options(scheduling_strategy=NodeAffinitySchedulingStrategy(n["NodeID"], soft=False)).remote(
            str(token), n["NodeID"])
        for n in nodes
    ]
    try:
        for node, problem in zip(nodes, ray.get(answers), strict=True):
            written = Path(f"{token}-{node['NodeID']}")
            if not problem and not written.is_file():
                problem = f"wrote {written}, which this machine does not see"
            if problem:
                raise ConfigError(
                    f"Ray node {node['NodeManagerAddress']} {problem}; the output folder must be on "
                    "storage that every node mounts at the same path (e.g. NFS)"
                )
            written.unlink()
    finally:
        token.unlink(missing_ok=True)


LOCAL = Executor()  # the default: processes on this machine


def add_executor_arguments(parser: Any) -> None:
    """`--executor` and `--ray-address` for a verb whose work runs on an Executor."""
    parser.add_argument("--executor", default="local", help="local (processes here, default) or ray")
    parser.add_argument("--ray-address", default=None, help="a Ray cluster's address (default: start one)")


def executor_from(args: Any) -> Executor:
    return Executor(args.executor, args.ray_address)
