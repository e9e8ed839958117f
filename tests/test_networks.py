"""A network is one registered class (`depthq.networks`): a toy third one, defined here in a few lines
with a training setting and an acting setting of its own, trains, drives, is measured offline, drawn
and exported without any other module knowing of it."""

from __future__ import annotations

import argparse
import importlib.util
import json
from dataclasses import dataclass
from importlib.metadata import EntryPoint
from pathlib import Path

import numpy as np
import pytest

from depthq.blocks.heads import CollHead
from depthq.blocks.losses import DEPTH_CLIP
from depthq.configio import from_dict, to_dict
from depthq.control.action_selection import ACTIONS
from depthq.control.heuristic import DepthHeuristic
from depthq.data.manifest import Dataset
from depthq.data.samples import bins_target
from depthq.errors import ConfigError
from depthq.evaluate.figures import plot_fig4
from depthq.evaluate.online import EvalConfig, drive, parse_canyon_set
from depthq.evaluate.video import write_video
from depthq.flags import build_config, config_from_args
from depthq.networks import Network, ValuePlot, get_network, network_names, register_network, registry
from depthq.policies.registry import make_policy
from depthq.scripts.train import add_arguments
from depthq.sim.env import CanyonEnv, EnvConfig
from depthq.train.config import TrainConfig
from depthq.train.offline_metric import offline_metric
from depthq.train.trainer import train


@dataclass(frozen=True)
class ClearanceSettings:
    """Clearance-Net's own settings (`--clearance.reach`)."""

    reach: float = 2.0  # clearances beyond this many metres are learnt as this

    def __post_init__(self) -> None:
        if not self.reach > 0:
            raise ConfigError(f"clearance.reach must be > 0 m, got {self.reach!r}")


@dataclass(frozen=True)
class ClearanceActing:
    """Clearance-Net's own acting settings (`--clearance.floor`)."""

    floor: float = 0.0  # predicted clearances below this many metres count as none (0)

    def __post_init__(self) -> None:
        if not self.floor >= 0:
            raise ConfigError(f"clearance.floor must be >= 0 m, got {self.floor!r}")


class Clearance(Network[ClearanceSettings]):
    """A toy network: the clearance one step later (the nearest depth bin at t+1, from the data's bins
    target) up to its reach, one number per action, mean squared error, the highest wins (a clearance
    below its floor counting as none)."""

    name, title, label, colour, lr = "clearance", "Clearance-Net", "CLR", "tab:green", 0.1
    Settings, Acting, target = ClearanceSettings, ClearanceActing, bins_target
    metric, metric_title, loss_title = "mse", "mse", "squared error (m²)"
    rule, rule_text = "highest_clearance", "the action whose predicted clearance is highest"
    maximise, tie_tol, decisive, onnx_output = True, 1e-5, 0.01, "clearance"
    plot = ValuePlot("bars", "clearance at t+1 (m)", (0.0, 2.2))

    def build_head(self, config):
        return CollHead(config)  # one number per (frame, action)

    def samples(self, dataset, split, n_runs, config, labels=None):
        arrays = super().samples(dataset, split, n_runs, config, labels)
        bins = arrays["target"]  # (S, 26), NaN where no reading
        nearest = np.where(np.isfinite(bins), bins, DEPTH_CLIP).min(axis=1)
        return {**arrays, "target": np.minimum(nearest, config.settings.reach)}

    def loss_function(self, settings):
        def mse(pred, target):
            per_sample = (pred - target) ** 2
            return per_sample.mean(), per_sample

        return mse

    def scores(self, values, acting=None):
        floor = (acting or ClearanceActing()).floor
        return np.where(np.asarray(values, np.float64) < floor, 0.0, values)


@pytest.fixture
def clearance(monkeypatch: pytest.MonkeyPatch) -> Network:
    """`Clearance`, registered for one test."""
    monkeypatch.setattr(registry, "_NETWORKS", dict(registry._NETWORKS))  # unregistered after the test
    register_network(Clearance)
    return get_network("clearance")


def test_the_builtin_networks_are_registered_in_the_papers_order() -> None:
    assert network_names()[:2] == ("depth", "coll")
    assert get_network("coll").title == "Coll-Q-Net" and get_network("depth").maximise
    with pytest.raises(ConfigError, match="unknown network 'value'; one of"):
        get_network("value")
    with pytest.raises(ConfigError, match=r"train\.model must be one of"):
        TrainConfig(model="value", data="data")


def test_a_third_networks_own_setting_is_its_flag_record_and_sweep_setting(clearance: Network) -> None:
    """Its setting is `--clearance.reach`, stored under its name, checked by its own class, refused for
    another network (and another's for it); swept, it names the third network's models alone."""
    from depthq.pipeline.presets import get_preset
    from depthq.pipeline.sweep import parse_setting, widened

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    assert "--clearance.reach REACH" in parser.format_help()
    args = parser.parse_args(["--model", "clearance", "--data", "d", "--out", "o",
                              "--clearance.reach", "1.5"])
    config = config_from_args(TrainConfig, args)
    assert config.settings == ClearanceSettings(reach=1.5) and to_dict(config)["clearance"] == {"reach": 1.5}
    assert from_dict(TrainConfig, to_dict(config)) == config
    assert TrainConfig(model="clearance", data="d").settings == ClearanceSettings()
    with pytest.raises(ConfigError, match=r"clearance\.reach must be > 0 m, got 0\.0"):
        build_config(TrainConfig, {"model": "clearance", "data": "d", "clearance.reach": 0.0})
    for model, path in (("depth", "clearance.reach"), ("clearance", "depth.lookahead")):
        with pytest.raises(ConfigError, match=rf"{path}: a setting of model '{path.partition('.')[0]}'"):
            build_config(TrainConfig, {"model": model, "data": "d", path: 1})

    smoke = get_preset("smoke")
    sweep = widened(smoke, nets=("depth", "coll", "clearance"), grid=(parse_setting("clearance.reach=1,2"),))
    names = sorted({m.name for m in sweep.models()})
    assert names == sorted({m.name for m in smoke.models()} | {f"clearance_n{n}_s0{reach}" for n in (3, 6)
                                                               for reach in ("", "_reach1.0")})
    reaches = {sweep.train_config(m, "d").settings.reach for m in sweep.models() if m.net == "clearance"}
    assert reaches == {1.0, 2.0}


def test_a_third_networks_acting_setting_is_its_evaluate_flag_and_record(clearance: Network) -> None:
    """Its acting setting is `--clearance.floor` on `depthq evaluate`, stored under its name in an
    evaluation's config beside Depth-Q-Net's, checked by its own class, and what its rule acts by."""
    from depthq.scripts.evaluate import add_arguments as add_evaluate_arguments

    parser = argparse.ArgumentParser()
    add_evaluate_arguments(parser)
    assert "--clearance.floor FLOOR" in parser.format_help()
    args = parser.parse_args(["pol", "--out", "o", "--clearance.floor", "1.5"])
    config = config_from_args(EvalConfig, args, canyons=("val:1000",))
    assert config.acting["clearance"] == ClearanceActing(floor=1.5)
    assert config.acting["depth"] == EvalConfig().acting["depth"]  # another network's stay as they were
    assert to_dict(config)["clearance"] == {"floor": 1.5} and from_dict(EvalConfig, to_dict(config)) == config
    with pytest.raises(ConfigError, match=r"clearance\.floor must be >= 0 m, got -1\.0"):
        build_config(EvalConfig, {"clearance.floor": -1.0})
    values = np.array([1.2, 1.0, 0.4])
    assert clearance.choose(values, np.asarray(ACTIONS)) == -1.0  # the highest clearance
    assert clearance.choose(values, np.asarray(ACTIONS), clearance.own_acting(config.acting)) == 0.0  # none


def test_a_packages_network_is_found_by_its_entry_point(monkeypatch: pytest.MonkeyPatch) -> None:
    """A package declares its network as an entry point (what every process, a worker too, finds)."""
    monkeypatch.setattr(registry, "_NETWORKS", dict(registry._NETWORKS))
    monkeypatch.setattr(registry, "_installed", False)
    point = EntryPoint("clearance", f"{__name__}:Clearance", registry.ENTRY_POINTS)
    monkeypatch.setattr(registry, "entry_points", lambda group: [point] if group == point.group else [])
    assert isinstance(get_network("clearance"), Clearance)
    assert network_names()[-1] == "clearance"
    monkeypatch.setattr(registry, "_installed", False)
    broken = EntryPoint("broken", "no_such_module:Net", registry.ENTRY_POINTS)
    monkeypatch.setattr(registry, "entry_points", lambda group: [broken])
    with pytest.raises(ConfigError, match=r"network 'broken' .* does not load"):
        get_network("broken")


def _preset_models() -> dict[str, list[str]]:
    """Each preset's models, the presets made now (their module run again, as a module of its own)."""
    spec = importlib.util.find_spec("depthq.pipeline.presets")
    presets = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(presets)
    return {name: [m.name for m in sweep.models()] for name, sweep in presets.PRESETS.items()}


def test_a_registered_network_changes_no_preset(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Presets name their networks: made with a third network registered, each trains the models it
    trains without it; a sweep that names none (an ad-hoc one, `depthq sweep` without --nets) trains
    every registered network."""
    from depthq.cli import main
    from depthq.pipeline.presets import get_preset
    from depthq.pipeline.sweep import Sweep

    before = _preset_models()
    monkeypatch.setattr(registry, "_NETWORKS", dict(registry._NETWORKS))  # unregistered after the test
    register_network(Clearance)
    assert _preset_models() == before
    assert len(before["paper"]) == 6 * 3 * 2
    smoke = get_preset("smoke")
    ad_hoc = Sweep("ad hoc", smoke.collect, smoke.subsets, smoke.seeds, smoke.train, smoke.canyons)
    assert ad_hoc.nets == ("depth", "coll", "clearance")
    assert {m.name for m in ad_hoc.models()} == {*before["smoke"], "clearance_n3_s0", "clearance_n6_s0"}
    for given, trained in (([], True), (["--nets", "depth,coll"], False)):
        assert main(["sweep", "--preset", "smoke", *given, "--dry-run", "--out", str(tmp_path / "x")]) == 0
        assert ("  clearance_n3_s0 " in capsys.readouterr().out) == trained, given


@pytest.mark.slow
def test_a_third_network_trains_drives_and_exports(
    clearance: Network, small_dataset: Path, tmp_path: Path
) -> None:
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    assert "--model {depth,coll,clearance}" in parser.format_help()  # the flag lists the registry

    fast = {"epochs": 2, "train_batches": 4, "val_batches": 1, "batch_size": 16}
    folder = train(TrainConfig(model="clearance", data=str(small_dataset), **fast), tmp_path / "clr",
                   progress=False)
    record = json.loads((folder / "config.json").read_text())
    assert record["head"]["kind"] == "clearance" and record["policy"]["rule"] == "highest_clearance"
    losses = [float(line.split(",")[2]) for line in (folder / "metrics.csv").read_text().splitlines()[1:]]
    assert len(losses) == 2 and all(np.isfinite(losses))
    metric = offline_metric(folder, Dataset.open(small_dataset))
    assert metric["metric"] == "mse" and metric["value"] >= 0 and metric["samples"] > 0

    # Driven in this process (a worker process would not know the network: `depthq.networks.registry`).
    policy = make_policy(str(folder), threads=1)
    assert policy.network is clearance and policy.name.startswith("CLR:")
    assert policy.acting == ClearanceActing()  # its own acting settings, its defaults when none are given
    env = CanyonEnv(EnvConfig(time_limit_s=3.0))
    try:
        canyon = parse_canyon_set("val:1000")[0]
        run = drive(policy, env, DepthHeuristic(), canyon, seed=0, keep_every=3, video=True)
        obs, _ = env.reset(seed=0, options={"canyon": canyon})
        action = policy.act(obs)
    finally:
        env.close()
    assert run["steps"] > 0 and set(np.asarray(run["actions"]).tolist()) <= set(ACTIONS)
    values = policy.last_values
    assert values.shape == (3,) and action == ACTIONS[int(np.argmax(values))]  # the highest wins
    # An evaluation's acting settings reach its rule: below a floor past every clearance, all tie: straight.
    acting = build_config(EvalConfig, {"clearance.floor": 99.0}).acting
    floored = make_policy(str(folder), threads=1, acting=acting)
    assert floored.acting == ClearanceActing(floor=99.0) and floored.act(obs) == 0.0
    described = policy.describe()
    write_video(run["video"], run, described, tmp_path / "video.mp4", fps=5.0)
    plot_fig4(run["snapshots"], run, described, tmp_path / "fig4.png")
    assert (tmp_path / "video.mp4").stat().st_size > 0 and (tmp_path / "fig4.png").stat().st_size > 0

    onnx = pytest.importorskip("onnx")
    from depthq.deploy.onnx_export import export_onnx
    from depthq.policies.onnx import OnnxPolicy

    path = export_onnx(folder, tmp_path / "onnx")
    model = onnx.load(path)
    meta = {p.key: p.value for p in model.metadata_props}
    assert meta["depthq.kind"] == "clearance" and meta["depthq.selection"] == clearance.rule_text
    assert [o.name for o in model.graph.output] == ["clearance"]
    exported = OnnxPolicy(path, threads=1)
    np.testing.assert_allclose(exported.values(obs["image"]), values, atol=1e-4)
    assert exported.act(obs) == action
