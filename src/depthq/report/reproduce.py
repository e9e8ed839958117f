"""`depthq reproduce` and `depthq sweep`: the pipeline's stages (`depthq.pipeline.stages`), then the
tables, figures and report of the folder (`build_report`); the folder's layout is in
`depthq.pipeline.stages`."""

from __future__ import annotations

from pathlib import Path

from depthq.parallel import LOCAL, Executor
from depthq.pipeline.presets import get_preset
from depthq.pipeline.stages import run_stages
from depthq.pipeline.sweep import Sweep
from depthq.report.build import build_report


def run_sweep(
    sweep: Sweep, out: Path, progress: bool = True, device: str = "auto", executor: Executor = LOCAL
) -> dict[str, float]:
    """Run (or resume) every stage of `sweep` into `out`, then write its tables, figures and report;
    returns the measured seconds per stage."""
    times = run_stages(sweep, out, progress, device, executor)
    build_report(Path(out).resolve(), sweep, times)
    return times


def reproduce(
    preset_name: str, out: Path, progress: bool = True, device: str = "auto", executor: Executor = LOCAL
) -> dict[str, float]:
    """`run_sweep` of a preset (`depthq.pipeline.presets`)."""
    return run_sweep(get_preset(preset_name), out, progress, device, executor)
