"""Write every table, figure and the HTML report of a reproduction folder from its files."""

from __future__ import annotations

import shutil
from pathlib import Path

from depthq.configio import atomic_write_bytes, provenance, read_json
from depthq.data import DataConfig
from depthq.data.manifest import Dataset
from depthq.data.stats import dataset_stats
from depthq.pipeline.stages import best_depth_eval
from depthq.pipeline.sweep import Sweep
from depthq.report import html as page
from depthq.report.figures import plot_fig5, plot_success_vs_runs
from depthq.report.findings import FINDINGS, read_findings
from depthq.report.tables import (
    csv_text,
    markdown,
    per_seed_rows,
    reaches_end_goal,
    reference_rows,
    table1_rows,
    table2_rows,
)

SUCCESS_TEXT = {
    False: "more than 15 m from the spawn",
    True: "the canyon's end reached without a collision; 'to collision': progress along the canyon "
    "until the first bump or contact, or the time limit (the canyon's length if it reached the end), "
    "'closest': the smallest LiDAR-axis "
    "distance to a wall or pillar (docs/hard_canyons.md)",
}


def _trunks(out: Path) -> list[str]:
    """The trunks the folder's checkpoints were trained with, as their config.json records them."""
    return sorted({read_json(p)["trunk"] for p in (out / "models").glob("*/config.json")})


def build_report(out: Path, sweep: Sweep, stage_seconds: dict[str, float]) -> None:
    t1 = table1_rows(out, sweep)
    seeds = per_seed_rows(out, sweep)
    ends = reaches_end_goal(sweep)
    refs = reference_rows(out, ends)
    stats = dataset_stats(Dataset.open(out / "data"), DataConfig(subsets=sweep.subsets))
    t2 = table2_rows(stats, sweep.subsets)
    note = (
        f"mean (std) over the seeds evaluated so far (columns 'seeds'; the sweep has {len(sweep.seeds)}), "
        "and for distance and success the 95 % Student-t interval of that mean [low, high]; "
        f"{sweep.canyons} canyons, {sweep.decision_hz:g} decisions/s, {sweep.time_limit_s:.0f} s "
        f"per run; success = {SUCCESS_TEXT[ends]}. Trunk: {', '.join(_trunks(out)) or '–'} "
        f"(see the deviations) instead of the paper's MobileNet-v1-0.25.\n"
    )
    atomic_write_bytes(
        out / "table1.md",
        (
            "# Table I\n\n" + note + "\n" + markdown(t1) + "\n## Per seed\n\n" + markdown(seeds)
            + "\n## Reference policies "
            "(mean (std) over canyons)\n\n" + markdown(refs)
        ).encode(),
    )
    atomic_write_bytes(out / "table1.csv", csv_text(t1).encode())
    atomic_write_bytes(out / "table2.md", ("# Table II\n\n" + markdown(t2)).encode())
    plot_fig5(out, sweep, out / "fig5_convergence.png")
    plot_success_vs_runs(out, sweep, out / "success_vs_runs.png")
    best = best_depth_eval(out, sweep)
    for name, copy in (("fig4_qualitative.png", "fig4_qualitative.png"), ("video.mp4", "fig4_video.mp4")):
        if best is not None and (best / name).is_file():
            shutil.copyfile(best / name, out / copy)
    figures = [
        (out / "eval" / name / "trajectories.png", f"trajectories: {name}") for name in ("heuristic", "ou")
    ]
    if best is not None:
        figures.append((best / "trajectories.png", f"trajectories: {best.name} (best Depth-Q-Net)"))
    html_text = page.render(
        f"depthq reproduction — {sweep.name}",
        [
            (
                "Table I",
                f"<p>{note}</p>" + page.table(t1) + "<h3>Per seed</h3>" + page.table(seeds)
                + "<h3>Reference policies</h3>" + page.table(refs),
            ),
            ("Success rate against training runs", page.img(out / "success_vs_runs.png", "success vs runs")),
            ("Table II", page.table(t2)),
            (
                "Fig. 4: Depth-Q-Net predictions",
                page.img(out / "fig4_qualitative.png", "Fig. 4")
                + page.video(
                    out / "fig4_video.mp4",
                    f"Fig. 4 animated: {best.name if best else ''} in the first canyon, one frame per "
                    "decision, real time",
                ),
            ),
            ("Fig. 5: convergence", page.img(out / "fig5_convergence.png", "Fig. 5")),
            ("Trajectories", "".join(page.img(p, alt) for p, alt in figures)),
            *findings_sections(),
            (
                "Measured stage times (s)",
                page.table([{"stage": k, "seconds": f"{v:.1f}"} for k, v in stage_seconds.items()]),
            ),
            (
                "Configuration",
                page.pre(
                    {
                        "sweep": sweep.record(),
                        "provenance": provenance(),
                        "dataset": {k: stats[k] for k in ("collected", "usable", "frames", "kb_per_frame")},
                    }
                ),
            ),
        ],
    )
    atomic_write_bytes(out / "report.html", html_text.encode())


def findings_sections(path: Path = FINDINGS) -> list[tuple[str, str]]:
    """The paper's claims (with the evidence the experiments wrote) and the deviations, from the
    findings file; a note where the installation has none (a wheel carries no docs/)."""
    if not path.is_file():
        note = f"<p><em>{path} is part of depthq's source checkout; see docs/deviations.md there.</em></p>"
        return [("The paper's claims here", note)]
    found = read_findings(path)
    claims = [
        {"claim": c.claim, "here": c.verdict,
         "measured": " ".join(f"{key}: {e.text} ({e.by})" for key, e in c.evidence.items()) or "–",
         "measured in": c.where}
        for c in found.claims
    ]
    deviations = [{"original": d.paper, "ours": d.depthq, "why": d.why, "measured in": d.doc}
                  for d in found.deviations]
    intro = "<p>What depthq's own measurements say (not this run's: see the pages named).</p>"
    return [("The paper's claims here", intro + page.table(claims)),
            ("Deviations from the paper", page.table(deviations))]
