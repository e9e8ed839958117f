"""The sweep runner: every stage of a sweep (`depthq.pipeline.stages`), resumed, then what is made of
its folder (the tables, figures and report: `depthq.report.build.build_report`, a layer above, which
the caller passes)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from depthq.parallel import LOCAL, Executor
from depthq.pipeline.stages import run_stages
from depthq.pipeline.sweep import Sweep

Finish = Callable[[Path, Sweep, dict[str, float]], None]  # (the folder, its sweep, seconds per stage)


def run_sweep(
    sweep: Sweep,
    out: Path,
    progress: bool = True,
    device: str = "auto",
    executor: Executor = LOCAL,
    finish: Finish | None = None,
) -> dict[str, float]:
    """Run (or resume) every stage of `sweep` into `out`, then `finish` the folder (e.g. write its
    report); returns the measured seconds per stage."""
    times = run_stages(sweep, out, progress, device, executor)
    if finish is not None:
        finish(Path(out).resolve(), sweep, times)
    return times
