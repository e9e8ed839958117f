"""Canyon families (#19): the paper's canyons as they were, the hard family's own seed streams, world,
end of canyon and metrics, and the family through ids, canyon sets, collection and sweeps."""

import hashlib
import json

import numpy as np
import pytest

from depthq.configio import read_json, to_dict
from depthq.errors import ConfigError
from depthq.sim.canyon import FAMILIES, CanyonId, eval_canyon_ids, generate_canyon

# sha256 of left + right + back wall vertices, computed with the generator before families existed
PAPER_HASHES = {
    "eval:0": "4e2663c437ca3cc7",
    "eval:19": "35da87c4d2aab494",
    "train:12": "d6c89859c36c3111",
    "val:1000": "242bc996064f66f9",
}


def _hash(canyon) -> str:
    walls = canyon.left.tobytes() + canyon.right.tobytes() + canyon.back.tobytes()
    return hashlib.sha256(walls).hexdigest()[:16]


def test_paper_canyons_are_unchanged():
    for name, expected in PAPER_HASHES.items():
        canyon = generate_canyon(CanyonId.parse(name))
        assert _hash(canyon) == expected and len(canyon.obstacles) == 0


def test_paper_configs_keep_their_bytes():
    """No new key in a paper config: manifests and setups written before families still match."""
    from depthq.data.recorder import CollectConfig, exploration_env

    text = json.dumps(to_dict(CollectConfig()))
    assert "family" not in text and "obstacles" not in text
    hard = to_dict(CollectConfig(env=exploration_env(family="hard")))["env"]["world"]
    assert hard["family"] == "hard" and hard["canyon"]["obstacles"]["count"] > 0


def test_hard_canyons_are_deterministic_and_disjoint_from_the_paper():
    a, b = generate_canyon(CanyonId.parse("hard/val:1000")), generate_canyon(CanyonId("val", 1000, "hard"))
    np.testing.assert_array_equal(a.left, b.left)
    np.testing.assert_array_equal(a.obstacles, b.obstacles)
    assert len(a.obstacles) > 0 and a.left.shape == (FAMILIES["hard"].canyon.n_segments + 2, 2)
    states = {
        (family, stream, i): tuple(CanyonId(stream, i, family).seed_sequence.generate_state(4))
        for family in FAMILIES
        for stream in ("train", "val", "eval")
        for i in range(20)
    }
    assert len(set(states.values())) == len(states)  # no two canyons of any family or stream share a seed
    hard_evals = {_hash(generate_canyon(c)) for c in eval_canyon_ids("hard")}
    assert len(hard_evals) == 20


def test_canyon_ids_name_their_family():
    assert str(CanyonId.parse("hard/eval:3")) == "hard/eval:3" and str(CanyonId.parse("eval:3")) == "eval:3"
    assert CanyonId.parse("eval:3").family == "paper"
    with pytest.raises(ConfigError, match="'easy'"):
        CanyonId.parse("easy/eval:3")
    with pytest.raises(ConfigError, match="out of range"):
        CanyonId.parse("hard/eval:20")


def test_canyon_sets_parse_families_and_refuse_bad_names():
    from depthq.evaluate.online import EvalConfig, parse_canyon_set

    assert parse_canyon_set("hard/val:1000-1002") == ("hard/val:1000", "hard/val:1001", "hard/val:1002")
    assert parse_canyon_set("hard/eval") == tuple(f"hard/eval:{i}" for i in range(20))
    assert parse_canyon_set("eval:0-1") == ("eval:0", "eval:1")
    for bad, word in (("easy/eval", "'easy'"), ("hard/train:3", "hard/train:3"), ("hard/val", "hard/val")):
        with pytest.raises(ConfigError, match=word):
            parse_canyon_set(bad)
    with pytest.raises(ConfigError, match="one family"):
        EvalConfig(canyons=("eval:0", "hard/eval:0"))
    config = EvalConfig(canyons=parse_canyon_set("hard/val:1000-1001"))
    assert config.env.time_limit_s == FAMILIES["hard"].time_limit_s and config.env.world.family == "hard"
    assert EvalConfig().env.time_limit_s == 45.0


def test_hard_episode_renders_and_ends_at_the_canyon_end_with_its_metrics():
    """The heuristic expert in a hard val canyon, camera on (small frames): real pixels, the world of
    the canyon's family, and the new metrics of the run."""
    from depthq.control.heuristic import DepthHeuristic
    from depthq.evaluate.online import drive
    from depthq.sim.env import CanyonEnv, EnvConfig
    from depthq.sim.mjcf import CameraConfig
    from depthq.sim.world import WorldConfig

    env = CanyonEnv(EnvConfig(world=WorldConfig(camera=CameraConfig(width=64, height=48)), time_limit_s=75.0))
    expert = DepthHeuristic()
    try:
        obs, info = env.reset(seed=0, options={"canyon": "hard/val:1000"})
        assert env.world.config.family == "hard" and len(env.world.canyon.obstacles) > 0
        assert obs["image"].std() > 5 and info["progress"] == 0.0
        run = drive(expert, env, expert, "hard/val:1000", seed=1000)
        paper, _ = env.reset(seed=0, options={"canyon": "eval:0"})  # back to the paper's world
        assert env.world.config.family == "paper" and paper["image"].std() > 5
    finally:
        env.close()
    assert run["end_reason"] == "end" and run["success"]
    assert run["progress"] == pytest.approx(run["canyon_length"]) == run["distance_to_collision"]
    assert 0 < run["closest"] < 1.375  # nearer than the canyon's half width: it passed pillars
    assert run["steps"] < 75.0 * 4


def test_a_collision_ends_the_run_and_its_distance_to_collision_is_the_progress():
    from depthq.evaluate.metrics import distance_to_collision, run_success
    from depthq.sim.env import CanyonEnv

    env = CanyonEnv(camera=False)
    try:
        env.reset(seed=0, options={"canyon": "hard/val:1001"})
        done = False
        while not done:  # a wide left turn: into the wall
            _, _, terminated, truncated, info = env.step(np.full(1, 0.2, np.float32))
            done = terminated or truncated
    finally:
        env.close()
    assert info["end_reason"] in ("bump", "contact") and info["closest"] < 0.3
    to_collision = distance_to_collision(info["progress"], info["end_reason"], info["canyon_length"])
    assert to_collision == info["progress"] < info["canyon_length"]
    assert not run_success("end", 20.0, info["end_reason"]) and run_success("distance", 20.0, "bump")
    # a run that circles until the time limit hits nothing, but is credited only what it drove
    assert distance_to_collision(0.7, "time_limit", 24.8) == 0.7
    assert distance_to_collision(24.9, "end", 24.8) == 24.8


def test_collect_in_the_hard_family_records_it(tmp_path):
    from depthq.data.manifest import Dataset
    from depthq.data.recorder import CollectConfig, collect, exploration_env

    config = CollectConfig(runs=1, val_runs=0, max_steps=28, env=exploration_env(family="hard"))
    collect(tmp_path / "d", config, progress=False)
    dataset = Dataset.open(tmp_path / "d")
    assert dataset.config["env"]["world"]["family"] == "hard"
    entry = dataset.entries()[0]
    assert entry.canyon_seed == int(CanyonId("train", 0, "hard").seed_sequence.generate_state(1)[0])


def test_sweep_setup_records_the_family_and_refuses_another(tmp_path):
    from depthq.pipeline.presets import PRESETS
    from depthq.pipeline.stages import _claim
    from depthq.pipeline.sweep import retarget

    hard = PRESETS["hard"]
    assert hard.setup()["family"] == "hard" and hard.canyons == "hard/eval"
    assert PRESETS["smoke"].setup()["family"] == "paper"
    val = retarget(PRESETS["quick"], family="hard", canyons="hard/val:1000-1019", decision_hz=10.0)
    assert (val.family, val.canyons, val.decision_hz) == ("hard", "hard/val:1000-1019", 10.0)
    assert val.time_limit_s == FAMILIES["hard"].time_limit_s
    with pytest.raises(ConfigError, match="easy"):
        retarget(PRESETS["quick"], canyons="easy/val:1000-1019")
    # a folder written before sweeps had a family holds the paper's
    old = tmp_path / "old"
    old.mkdir()
    setup = PRESETS["smoke"].setup()
    del setup["family"]
    (old / "reproduce.json").write_text(json.dumps({"sweep": {"name": "smoke", **setup}}))
    _claim(old, PRESETS["smoke"])
    assert read_json(old / "reproduce.json")["sweep"]["family"] == "paper"
    with pytest.raises(ConfigError, match="family 'paper' there, 'hard' here"):
        _claim(old, retarget(PRESETS["smoke"], family="hard"))


@pytest.mark.slow
def test_a_checkpoint_is_evaluated_in_its_own_familys_canyons_by_default(tmp_path):
    """A network trained on hard canyons is tested in hard ones unless told otherwise."""
    from depthq.data.recorder import CollectConfig, collect, exploration_env
    from depthq.evaluate.online import default_canyons
    from depthq.policies.spec import PolicySpec
    from depthq.train.config import TrainConfig
    from depthq.train.trainer import train

    config = CollectConfig(runs=2, val_runs=1, max_steps=60, env=exploration_env(family="hard"))
    collect(tmp_path / "d", config, progress=False)
    settings = TrainConfig(model="depth", data=str(tmp_path / "d"), epochs=1, train_batches=1, val_batches=1)
    checkpoint = train(settings, tmp_path / "ckpt", progress=False)
    assert default_canyons(PolicySpec("checkpoint", checkpoint)) == "hard/eval"
    assert default_canyons(PolicySpec("heuristic")) == "eval"


def test_fresh_streams_are_test_sets_no_project_code_draws_from(tmp_path):
    """`stream7:0-19`: canyons of a stream no dataset, choice or table uses, in either family,
    disjoint from train/val/eval; a stream that aliases one of those, or is unknown, is refused by name."""
    from depthq.evaluate.online import EvalConfig, evaluate, parse_canyon_set

    assert parse_canyon_set("hard/stream7:0-1") == ("hard/stream7:0", "hard/stream7:1")
    assert parse_canyon_set("stream3:4,2") == ("stream3:4", "stream3:2")
    fresh = {_hash(generate_canyon(CanyonId("stream7", i, f))) for f in FAMILIES for i in range(20)}
    known = {_hash(generate_canyon(c)) for f in FAMILIES for c in eval_canyon_ids(f)}
    known |= {_hash(generate_canyon(CanyonId(s, i, f))) for f in FAMILIES for s in ("train", "val")
              for i in range(20)}
    assert len(fresh) == 2 * 20 and not fresh & known
    for bad in ("stream2:0", "stream:0", "streamx:0", "test:0"):
        with pytest.raises(ConfigError, match=repr(bad.partition(":")[0])):
            CanyonId.parse(bad)
    with pytest.raises(ConfigError, match="stream7"):
        parse_canyon_set("hard/stream7")  # a fresh stream has no default set: name its indices
    result = evaluate("heuristic", tmp_path, EvalConfig(canyons=("hard/stream7:0",), time_limit_s=2.0),
                      workers=1, progress=False)
    assert [r["canyon"] for r in result["runs"]] == ["hard/stream7:0"] and result["runs"][0]["steps"] > 0


def test_a_folder_holding_only_data_is_claimed_and_one_with_more_is_refused(tmp_path):
    """The head-size experiment links one sweep's data into another's folder before the sweep runs."""
    from depthq.pipeline.presets import PRESETS
    from depthq.pipeline.stages import _claim

    linked = tmp_path / "coll"
    linked.mkdir()
    (tmp_path / "depth_data").mkdir()
    (linked / "data").symlink_to(tmp_path / "depth_data")
    _claim(linked, PRESETS["smoke"])
    assert read_json(linked / "reproduce.json")["sweep"]["name"] == "smoke"
    other = tmp_path / "other"
    other.mkdir()
    (other / "data").mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(ConfigError, match="not a depthq reproduce folder"):
        _claim(other, PRESETS["smoke"])
    assert not (other / "reproduce.json").exists()
