"""The smoke preset end to end: real collection, training, evaluation and report (a few minutes)."""

import csv
import json
import re
import shutil
from pathlib import Path

import pytest

from depthq.cli import main
from depthq.configio import read_json
from depthq.errors import ConfigError
from depthq.pipeline.presets import get_preset
from depthq.pipeline.stages import build_stages, record_stage_time
from depthq.report.build import findings_sections
from depthq.report.findings import FINDINGS, Evidence, read_findings, record_evidence
from depthq.report.reproduce import reproduce
from depthq.report.tables import interval


@pytest.mark.slow
def test_tables_hold_numbers_for_both_networks(smoke):
    with (smoke / "table1.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [r["runs"] for r in rows] == ["3", "6"]
    number = re.compile(r"^\d+\.\d+ \(–\)$")  # one seed: a mean, no spread, no interval
    for row in rows:
        for column in (
            "distance CQN",
            "distance DQN",
            "success CQN",
            "success DQN",
            "imitation CQN",
            "imitation DQN",
            "cross-entropy CQN",
            "abs diff DQN",
        ):
            assert number.match(row[column]), (column, row[column])
        assert re.match(r"^\d+% \(–\)$", row["circling CQN"]), row["circling CQN"]
    table1 = (smoke / "table1.md").read_text()
    assert "| heuristic |" in table1 and "| ou |" in table1
    table2 = (smoke / "table2.md").read_text()
    assert re.search(r"^\| 6 \| \d+ \| \d+ \|", table2, re.M)
    assert "| val |" in table2 and "paper: samples" in table2  # the paper's sizes are not in the smoke set


@pytest.mark.slow
def test_report_is_self_contained_and_references_only_existing_files(smoke):
    html = (smoke / "report.html").read_text()
    for ref in re.findall(r'(?:src|href)="([^"]+)"', html):
        inline = ref.startswith(("data:image/png;base64,", "data:video/mp4;base64,"))
        assert inline or (smoke / ref).is_file(), ref
    assert html.count("data:image/png;base64,") >= 4
    assert html.count("data:video/mp4;base64,") == 1  # Fig. 4 animated
    for name in ("fig4_qualitative.png", "fig5_convergence.png", "success_vs_runs.png", "fig4_video.mp4"):
        assert (smoke / name).stat().st_size > 5000
    assert "The paper&#x27;s claims here" in html or "The paper's claims here" in html


@pytest.mark.slow
def test_every_file_and_folder_has_the_mode_the_umask_gives(smoke):
    """Made under umask 022 (the fixture): report, JSON, CSV, safetensors, run files, video all 0o644,
    folders 0o755, as `open()` and `mkdir` give them (the atomic writes' temporaries were 0o600)."""
    paths = [smoke, *smoke.rglob("*")]
    wrong = {str(p.relative_to(smoke)): oct(p.stat().st_mode & 0o777) for p in paths
             if p.stat().st_mode & 0o777 != (0o755 if p.is_dir() else 0o644)}
    assert not wrong, wrong
    suffixes = {p.suffix for p in paths}
    assert {".html", ".json", ".csv", ".safetensors", ".h5", ".md", ".mp4"} <= suffixes, suffixes


def test_every_claim_and_deviation_of_the_report_points_at_an_existing_docs_page():
    findings = read_findings()
    root = Path(__file__).resolve().parents[1]
    anchors = [c.where for c in findings.claims] + [d.doc for d in findings.deviations]
    for where in anchors:
        pages = re.findall(r"docs/[\w/]+\.md", where)
        assert pages, where
        for page in pages:
            assert (root / page).is_file(), page
    for d in findings.deviations:  # a deviation names its section, which must exist
        page, _, anchor = d.doc.partition("#")
        assert "{#" + anchor + "}" in (root / page).read_text(), d.doc
    for c in findings.claims:  # so does each section a claim names ('docs/a.md#x and #y': both a.md's)
        page = None
        for named, anchor in re.findall(r"(docs/[\w/]+\.md)|#([\w-]+)", c.where):
            page = named or page
            if anchor:
                assert page and "{#" + anchor + "}" in (root / page).read_text(), (c.id, page, anchor)


def test_a_claims_evidence_is_written_and_read_back_and_bad_findings_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "findings.json"
    shutil.copy(FINDINGS, path)
    record_evidence("table-i", "somewhere, 4 Hz, 6 runs", Evidence("measured text", "a command"), path)
    record_evidence("table-i", "somewhere, 4 Hz, 6 runs", Evidence("measured again", "a command"), path)
    claim = read_findings(path).claim("table-i")
    assert claim.evidence["somewhere, 4 Hz, 6 runs"] == Evidence("measured again", "a command")
    before = path.read_bytes()
    with pytest.raises(ConfigError, match=r"no claim 'nope'.*table-i"):
        record_evidence("nope", "k", Evidence("t", "c"), path)
    assert path.read_bytes() == before  # nothing written
    raw = json.loads(before)
    del raw["claims"][0]["verdict"]
    path.write_text(json.dumps(raw))
    with pytest.raises(ConfigError, match=r"not a findings file.*verdict"):
        read_findings(path)
    sections = dict(findings_sections(tmp_path / "absent.json"))
    assert "source checkout" in sections["The paper's claims here"]


@pytest.mark.slow
def test_resume_after_a_deleted_stage_redoes_only_that_stage(smoke):
    stamps = {p: p.stat().st_mtime_ns for p in (smoke / "eval").glob("*/summary.json")}
    stamps |= {p: p.stat().st_mtime_ns for p in (smoke / "models").glob("*/last.safetensors")}
    shutil.rmtree(smoke / "eval" / "depth_n3_s0")
    times = reproduce("smoke", smoke, progress=False)
    redone = smoke / "eval" / "depth_n3_s0" / "summary.json"
    assert redone.is_file()
    for path, stamp in stamps.items():
        if path != redone:
            assert path.stat().st_mtime_ns == stamp, f"{path} was redone"
    assert set(read_json(smoke / "stages.json")) == set(times)


def test_two_sweeps_widening_one_folder_keep_each_others_stage_times(tmp_path):
    """Sweeps A and B run at once into one folder, each recording its stages as they end: A's
    later write must not drop the stage B recorded after A's previous write."""
    path = tmp_path / "stages.json"
    record_stage_time(path, "train depth_n6_s0", 1.5)  # A
    record_stage_time(path, "train depth_n6_s1", 2.5)  # B
    times = record_stage_time(path, "evaluate depth_n6_s0", 0.5)  # A again
    expected = {"train depth_n6_s0": 1.5, "train depth_n6_s1": 2.5, "evaluate depth_n6_s0": 0.5}
    assert times == expected and read_json(path) == expected


@pytest.mark.slow
def test_a_sweep_widens_a_folder_and_reuses_its_models(smoke, tmp_path, capsys):
    """More seeds and a setting's values on top of the smoke preset's folder: the preset's own
    models are kept (dropout=0.0 is its setting), the new ones trained, the tables show the
    variants with 95 % intervals; bad grids are refused before any work."""
    copy = tmp_path / "out"
    shutil.copytree(smoke, copy)
    kept = {p: p.stat().st_mtime_ns for p in (copy / "eval").glob("depth_n*_s0/summary.json")}
    args = ["sweep", "--preset", "smoke", "--nets", "depth", "--sizes", "6", "--seeds", "0-1",
            "--set", "dropout=0,0.5", "--out", str(copy)]
    assert main(args) == 0
    assert all(p.stat().st_mtime_ns == t for p, t in kept.items())
    models = sorted(p.name for p in (copy / "models").iterdir())
    assert {"depth_n6_s1", "depth_n6_s0_dropout0.5", "depth_n6_s1_dropout0.5"} <= set(models)
    assert not [m for m in models if "dropout0.0" in m]
    with (copy / "table1.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [(r["variant"], r["runs"], r["seeds DQN"]) for r in rows] == [("dropout=0.0", "6", "2"),
                                                                        ("dropout=0.5", "6", "2")]
    number = re.compile(r"^(-?\d+\.\d+) \((\d+\.\d+)\) \[(-?\d+\.\d+), (-?\d+\.\d+)\]$")
    for row in rows:
        mean, _, low, high = map(float, number.match(row["distance DQN"]).groups())
        assert low <= mean <= high
    assert "distance CQN" not in (copy / "table1.md").read_text()

    for bad, named in (
        (["--seeds", "0-x"], "0-x"),
        (["--set", "seed=1,2"], "seed"),
        (["--set", "dropout=0.5,2"], "2"),
        (["--set", "nothing=1"], "nothing"),
        (["--sizes", "7"], "7"),
        (["--sizes", "6,3"], "3,6"),  # refused before any work, not after it
        (["--runs", "5"], "--runs"),  # fewer runs collected than the largest size (6)
        (["--nets", "depth,lidar"], "lidar"),
    ):
        capsys.readouterr()
        out = tmp_path / "bad"
        assert main(["sweep", "--preset", "smoke", *bad, "--out", str(out)]) == 2, bad
        assert named in capsys.readouterr().err and not out.exists(), bad


def test_intervals_are_student_t_over_seeds():
    values = [1.0, 2.0, 3.0]  # mean 2, sample std 1, t(0.975, 2 dof) = 4.303
    low, high = interval(values)
    assert (low, high) == pytest.approx((2 - 4.3027 / 3**0.5, 2 + 4.3027 / 3**0.5), abs=1e-3)
    assert interval([5.0]) is None


@pytest.mark.slow
def test_bad_presets_and_foreign_folders_are_refused(smoke, tmp_path, capsys):
    assert main(["reproduce", "--preset", "huge", "--out", str(tmp_path / "x")]) == 2
    assert "huge" in capsys.readouterr().err
    assert main(["reproduce", "--preset", "smoke", "--device", "cuda:7", "--out", str(tmp_path / "x")]) == 2
    assert "cuda:7" in capsys.readouterr().err  # no GPU here, or not 8 of them
    assert not (tmp_path / "x").exists()
    assert main(["reproduce", "--preset", "quick", "--out", str(smoke)]) == 2
    err = capsys.readouterr().err
    assert "'smoke'" in err and "runs 6 there, 200 here" in err


def test_every_preset_names_every_training_setting():
    """A changed default changes no preset's models: each names every TrainConfig field but those its
    sweep sets itself (model, data, runs, seed)."""
    from depthq.flags import config_flags
    from depthq.pipeline.presets import PRESETS
    from depthq.pipeline.sweep import NOT_IN_GRID
    from depthq.train.config import TrainConfig

    fields = {f.path for f in config_flags(TrainConfig)} - set(NOT_IN_GRID)
    for name, sweep in PRESETS.items():
        assert set(dict(sweep.train)) == fields, name


def test_paper_stages_finish_seed_0_for_every_size_first(tmp_path):
    """An interrupted `paper` run (hours long) should already hold a whole one-seed table."""
    names = [stage.name for stage in build_stages(get_preset("paper"), tmp_path)]
    trained = [name.removeprefix("train ") for name in names if name.startswith("train ")]
    assert len(trained) == 6 * 3 * 2
    first_seed_1 = trained.index("depth_n50_s1")
    assert sorted(trained[:first_seed_1]) == sorted(
        f"{net}_n{n}_s0" for n in (50, 100, 200, 500, 700, 900) for net in ("depth", "coll")
    )
    assert names.index("evaluate coll_n900_s0") < names.index("train depth_n50_s1")


@pytest.mark.slow
def test_probe_runs_every_part_end_to_end(tmp_path, capsys):
    """`depthq probe`: Table II statistics, the oracle and a (one-epoch) Depth-Q-Net in a val canyon."""
    out = tmp_path / "probe"
    args = ["--hz", "4", "--stats-runs", "4", "--runs", "3", "--epochs", "1", "--canyons", "val:1000"]
    assert main(["probe", *args, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "paper" in printed and "oracle depth:1 at 4 Hz" in printed
    assert "Depth-Q-Net on 3 runs at 4 Hz" in printed
    result = read_json(out / "probe.json")
    oracle = result["oracle"][0]
    assert result["stats"][0]["runs"] == 4 and oracle["canyons"] == 1 and oracle["oracle"] == "depth:1"
    assert oracle["runs"][0]["canyon"] == "val:1000"
    assert result["dqn"]["4"]["runs"] == 1 and (out / "hz4" / "depth_n3" / "best.safetensors").is_file()


def test_fig5_draws_a_sweep_whose_only_variant_is_not_the_preset(tmp_path):
    """`--set depth.lookahead=3` alone: its models' folders carry the setting, and Fig. 5 reads them
    (it once looked for the preset's folder names and drew empty axes)."""
    from dataclasses import replace

    from depthq.pipeline.sweep import parse_setting
    from depthq.report.figures import plot_fig5

    sweep = replace(get_preset("smoke"), nets=("depth",), grid=(parse_setting("depth.lookahead=3"),))
    plot_fig5(tmp_path, sweep, tmp_path / "empty.png")
    for model in sweep.models():
        assert model.name.endswith("_lookahead3")
        folder = tmp_path / "models" / model.name
        folder.mkdir(parents=True)
        rows = "".join(f"{e},{1 / e},{2 / e},{0.1 / e},1.0\n" for e in range(1, 6))
        (folder / "metrics.csv").write_text("epoch,train_loss,val_loss,val_loss_std,seconds\n" + rows)
    plot_fig5(tmp_path, sweep, tmp_path / "drawn.png")
    assert (tmp_path / "drawn.png").read_bytes() != (tmp_path / "empty.png").read_bytes()


@pytest.mark.slow
def test_bench_device_times_a_preset_and_measures_on_what_it_made(smoke, tmp_path, capsys):
    """`depthq bench device` on a finished smoke folder: its stages resume (nothing reruns), then every
    component is measured on its data and model, into one JSON record; a bad preset is refused first."""
    out = tmp_path / "bench"
    shutil.copytree(smoke, out / "sweep")
    before = (out / "sweep" / "stages.json").read_bytes()
    argv = ["bench", "device", "--preset", "smoke", "--out", str(out), "--seconds", "1", "--steps", "20",
            "--device", "cpu"]
    assert main(argv) == 0
    assert "smoke on cpu:" in capsys.readouterr().out
    record = read_json(out / "bench.json")
    assert (out / "sweep" / "stages.json").read_bytes() == before
    assert record["stage_total_s"] == pytest.approx(sum(json.loads(before).values()), abs=0.2)
    assert record["features"]["precisions"]["fp32"]["frames_per_s"] > 0
    assert record["policy"]["policies"][0]["ms_median"] > 0 and record["sim"]["steps_per_s"] > 0
    assert main(["bench", "device", "--preset", "tiny", "--out", str(tmp_path / "no")]) == 2
    assert not (tmp_path / "no").exists()
