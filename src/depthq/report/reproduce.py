"""`depthq reproduce`: a preset's sweep run by `depthq.pipeline.runner`, then the tables, figures and
report of its folder (`build_report`); the folder's layout is in `depthq.pipeline.stages`."""

from __future__ import annotations

from pathlib import Path

from depthq.parallel import LOCAL, Executor
from depthq.pipeline.presets import get_preset
from depthq.pipeline.runner import run_sweep
from depthq.report.build import build_report


def reproduce(
    preset_name: str, out: Path, progress: bool = True, device: str = "auto", executor: Executor = LOCAL
) -> dict[str, float]:
    """Run (or resume) every stage of a preset (`depthq.pipeline.presets`) into `out`, then write its
    tables, figures and report; returns the measured seconds per stage."""
    return run_sweep(get_preset(preset_name), out, progress, device, executor, finish=build_report)
