"""A pipeline's jobs on this machine (`Executor.run_jobs`, local): each remote job in a process pinned
to a core of its own, started once its inputs are done, overlapping others; a job that runs here waits
for every job before it; a failing job is named."""

from __future__ import annotations

import os
import time
from functools import partial
from pathlib import Path

import pytest

from depthq.errors import WorkerError
from depthq.parallel import Executor, Job


def _record(folder: Path, name: str, seconds: float = 0.0, fail: bool = False) -> None:
    """Write when the job ran and on which cores: `name.txt` = 'start end core,core'."""
    start = time.time()
    time.sleep(seconds)
    if fail:
        raise ValueError(f"{name} is bad")
    cores = ",".join(map(str, sorted(os.sched_getaffinity(0))))
    (folder / f"{name}.txt").write_text(f"{start} {time.time()} {cores}")


def _span(folder: Path, name: str) -> tuple[float, float, str]:
    start, end, cores = (folder / f"{name}.txt").read_text().split()
    return float(start), float(end), cores


@pytest.fixture
def two_cores():
    """This process on every core of the machine for the test (the suite pins each of its workers to
    a share of them), restored after."""
    held = os.sched_getaffinity(0)
    os.sched_setaffinity(0, range(os.cpu_count() or 1))
    if len(os.sched_getaffinity(0)) < 2:
        os.sched_setaffinity(0, held)
        pytest.skip("overlap needs two cores")
    yield
    os.sched_setaffinity(0, held)


def test_remote_jobs_overlap_one_per_core_after_their_inputs(tmp_path: Path, two_cores: None) -> None:
    run = partial(_record, tmp_path)
    jobs = [
        Job("prepare", partial(run, "prepare")),  # here, with every core
        Job("train a", partial(run, "train a", 1.0), ("prepare",), remote=True),
        Job("train b", partial(run, "train b", 1.0), ("prepare",), remote=True),
        Job("evaluate a", partial(run, "evaluate a"), ("train a",), remote=True),
        Job("report", partial(run, "report")),  # here, after all before it
    ]
    finished = [name for name, _ in Executor().run_jobs(jobs)]
    assert sorted(finished) == sorted(j.name for j in jobs) and finished[-1] == "report"
    spans = {j.name: _span(tmp_path, j.name) for j in jobs}
    every = ",".join(map(str, sorted(os.sched_getaffinity(0))))
    assert spans["prepare"][2] == every and spans["report"][2] == every
    assert spans["train a"][2] != spans["train b"][2] and "," not in spans["train a"][2] + spans["train b"][2]
    assert spans["train a"][0] < spans["train b"][1] and spans["train b"][0] < spans["train a"][1]  # overlap
    assert spans["evaluate a"][0] >= spans["train a"][1]
    assert spans["report"][0] >= max(end for _, end, _ in spans.values() if end != spans["report"][1])


def test_a_failing_job_is_named(tmp_path: Path) -> None:
    jobs = [Job("train a", partial(_record, tmp_path, "train a", 0.0, True), remote=True),
            Job("report", partial(_record, tmp_path, "report"))]
    with pytest.raises(WorkerError, match=r"(?s)job 'train a' failed.*ValueError: train a is bad"):
        list(Executor().run_jobs(jobs))
    assert not (tmp_path / "report.txt").exists()
