"""The paired comparison behind the README's headline (`python -m depthq.report.paired`), on the suite's
smoke run: both networks' Table I seed by seed, and the comparison written as a claim's evidence."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from depthq.report import paired
from depthq.report.findings import FINDINGS, read_findings


def test_paired_compares_the_networks_seed_by_seed_and_writes_the_claims_evidence(
    smoke: Path, tmp_path: Path
) -> None:
    # Paired by seed: the smoke run's own Table I, both networks at 3 and 6 runs (a seed 1 never ran).
    table = paired.paired(paired.paired_results(smoke, (3, 6), (0, 1))).splitlines()
    assert len(table) == 2 + 2 * len(paired.PAIRED)
    coll, depth = (json.loads((smoke / "eval" / f"{net}_n6_s0" / "summary.json").read_text())["summary"]
                   for net in ("coll", "depth"))
    first = (f"| 6 | 0 | to first collision (m) | {coll['distance_to_collision_mean']:.2f} | "
             f"{depth['distance_to_collision_mean']:.2f} | "
             f"{depth['distance_to_collision_mean'] - coll['distance_to_collision_mean']:.2f} |")
    assert first in table
    # The comparison as a claim's evidence in a copy of the findings file, in words made from the runs.
    findings = tmp_path / "findings.json"
    shutil.copy(FINDINGS, findings)
    args = [str(smoke), "--sizes", "6", "--seeds", "0", "--claim", "table-i",
            "--findings", str(findings)]
    assert paired.main(args) == 0
    canyons = json.loads((smoke / "reproduce.json").read_text())["sweep"]["canyons"]
    evidence = read_findings(findings).claim("table-i").evidence[f"{canyons}, 4 Hz, 6 runs"]
    assert f"Depth-Q-Net {depth['distance_to_collision_mean']:.2f} m" in evidence.text
    assert evidence.by == "python -m depthq.report.paired " + " ".join(args)
    assert paired.main([*args[:-4], "--claim", "no-such-claim", "--findings", str(findings)]) == 2
