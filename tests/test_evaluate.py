"""Action selection, Table I metrics, and real evaluations in the evaluation canyons."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from conftest import assert_video, without_timing

from depthq.cli import main
from depthq.control import action_selection
from depthq.control.action_selection import depth_scores
from depthq.errors import ConfigError
from depthq.evaluate.metrics import distance_from_spawn, imitation_loss, path_length
from depthq.evaluate.online import EvalConfig, evaluate, parse_canyon_set
from depthq.networks import get_network
from depthq.sim.world import DEFAULT_DECISION_HZ

DEPTH = get_network("depth")
COLL = get_network("coll")

ACTIONS = np.array(action_selection.ACTIONS)  # the candidates, as the selection rules take them


def test_depth_selection_maximises_the_nearest_predicted_obstacle():
    pred = np.full((3, 26), 1.5)
    pred[0, 3] = 0.4  # right turn predicts a close obstacle
    pred[2, 10] = 0.9
    pred[1, 20] = 0.6
    assert DEPTH.choose(pred, ACTIONS) == 1.0


def test_depth_selection_ignores_bins_predicted_as_zero():
    pred = np.full((3, 26), 1.0)
    pred[2, :5] = 0.0  # "no prediction", not "wall at 0 m"
    pred[2, 5:] = 1.8
    np.testing.assert_allclose(depth_scores(pred), [1.0, 1.0, 1.8])
    assert DEPTH.choose(pred, ACTIONS) == 1.0
    assert depth_scores(np.zeros((1, 26)))[0] == 0.0


def test_ties_go_straight():
    assert DEPTH.choose(np.ones((3, 26)), ACTIONS) == 0.0
    assert COLL.choose(np.array([0.2, 0.2, 0.2]), ACTIONS) == 0.0
    assert COLL.choose(np.array([0.1, 0.3, 0.1]), ACTIONS) == -1.0  # straight not among the best
    assert COLL.choose(np.array([0.3, 0.2, 0.1]), ACTIONS) == 1.0


def test_distance_is_the_furthest_straight_line_from_the_spawn():
    poses = np.array([[0, 0, 0], [0, 3, 0], [4, 3, 0], [0, 1, 0]], float)
    assert distance_from_spawn(poses) == pytest.approx(5.0)
    assert path_length(poses) == pytest.approx(3 + 4 + np.hypot(4, 2))
    assert imitation_loss(np.array([1.0, 0.0]), np.array([-1.0, 0.0])) == pytest.approx(2.0)


def test_canyon_sets_parse_and_bad_ones_are_refused():
    assert parse_canyon_set("eval")[-1] == "eval:19"
    assert parse_canyon_set("eval:2-4") == ("eval:2", "eval:3", "eval:4")
    assert parse_canyon_set("eval:7,1") == ("eval:7", "eval:1")
    assert parse_canyon_set("val:1000-1001") == ("val:1000", "val:1001")  # design choices are made there
    for bad in ("train", "eval:a", "eval:25", "val", "train:0-3"):
        with pytest.raises(ConfigError):
            parse_canyon_set(bad)


@pytest.fixture(scope="module")
def heuristic_eval(tmp_path_factory):
    out = tmp_path_factory.mktemp("heuristic")
    config = EvalConfig(canyons=("eval:0", "eval:1"), time_limit_s=6.0)
    return out, evaluate("heuristic", out, config, workers=1, progress=False)


def test_heuristic_evaluation_gives_sane_metrics_and_files(heuristic_eval):
    out, result = heuristic_eval
    runs = result["runs"]
    assert [r["canyon"] for r in runs] == ["eval:0", "eval:1"]
    steps = round(6.0 * DEFAULT_DECISION_HZ)  # one decision per camera frame
    for r in runs:  # 6 s at 0.5 m/s: about 3 m, no collision, the expert imitates itself
        assert r["end_reason"] == "time_limit" and r["steps"] == steps
        assert 2.7 < r["distance"] <= r["path_length"] <= 3.01
        assert r["imitation_loss"] == 0.0 and not r["success"]
    assert result["summary"]["successes"] == 0
    saved = json.loads((out / "summary.json").read_text())
    assert saved["summary"] == result["summary"]
    assert (out / "runs.csv").read_text().count("\n") == 3
    with np.load(out / "trajectories.npz", allow_pickle=False) as z:
        assert z["eval_0_poses"].shape == (steps + 1, 3)
    assert (out / "trajectories.png").stat().st_size > 1000
    assert_video(out / "video.mp4", steps, DEFAULT_DECISION_HZ)


@pytest.mark.slow
def test_results_do_not_depend_on_the_number_of_workers(heuristic_eval, ou_evaluation_one_worker, tmp_path):
    config = EvalConfig(canyons=("eval:0", "eval:1"), time_limit_s=6.0)
    two = evaluate("heuristic", tmp_path, config, workers=2, progress=False)
    assert without_timing(two["runs"]) == without_timing(heuristic_eval[1]["runs"])
    config, ou_one = ou_evaluation_one_worker  # conftest's: 3 canyons, one worker
    ou_two = evaluate("ou", tmp_path / "b", config, workers=2, progress=False, video=False)
    assert without_timing(ou_two["runs"]) == without_timing(ou_one["runs"])


def test_cli_refuses_a_missing_checkpoint_and_an_unknown_canyon_set(tmp_path, capsys):
    assert main(["evaluate", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    assert "nope" in capsys.readouterr().err
    assert main(["evaluate", "heuristic", "--canyons", "mars", "--out", str(tmp_path / "o")]) == 2
    assert "mars" in capsys.readouterr().err
    assert main(["evaluate", "heuristic", "--device", "tpu", "--out", str(tmp_path / "o")]) == 2
    assert "'tpu'" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def _processes(group: int) -> list[str]:
    """The live processes of a process group (a command started in a session of its own), as `ps` shows
    them; not a zombie (ended, its exit status not yet collected by init, to which it fell)."""
    shown = subprocess.run(["ps", "-o", "stat=,pid=,args=", "-g", str(group)], capture_output=True, text=True)
    return [line.strip() for line in shown.stdout.splitlines() if line.strip() and not line.startswith("Z")]


def test_a_killed_evaluation_leaves_no_process_and_its_rerun_no_temporary(tmp_path):
    """kill -9 of `depthq evaluate` mid-run: its workers, fork server and resource tracker end with it
    (workers watch their parent); the rerun removes the half-written files the kill left."""
    out = tmp_path / "eval"
    argv = ["evaluate", "heuristic", "--canyons", "val:0-3", "--time-limit-s", "20", "--workers", "2"]
    proc = subprocess.Popen([sys.executable, "-m", "depthq.cli", *argv, "--out", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 60  # main, resource tracker, fork server, 2 workers
        while len(_processes(proc.pid)) < 5 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert len(_processes(proc.pid)) >= 5, _processes(proc.pid)
        time.sleep(1.0)  # the workers driving
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        deadline = time.monotonic() + 10  # a few seconds: the workers see it within 1 s on an idle host
        while _processes(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not _processes(proc.pid), _processes(proc.pid)
    finally:
        if _processes(proc.pid):
            os.killpg(proc.pid, signal.SIGKILL)
    assert not (out / "summary.json").exists()
    out.mkdir(exist_ok=True)
    stale = [out / ".video.mp4.k1ll3d.mp4", out / ".runs.csv.k1ll3d.tmp"]  # as a kill while writing leaves
    for path in stale:
        path.write_bytes(b"half")
    config = EvalConfig(canyons=("val:0",), time_limit_s=2.0)
    evaluate("heuristic", out, config, workers=1, progress=False)
    assert (out / "video.mp4").is_file() and (out / "summary.json").is_file()
    assert not [p for p in out.iterdir() if p.name.startswith(".")]
