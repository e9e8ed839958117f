"""A policy spec is parsed once, into `PolicySpec`, whatever asks what it names."""

from __future__ import annotations

from pathlib import Path

import pytest

from depthq.control.heuristic import DepthHeuristic
from depthq.control.ou import OUPolicy
from depthq.errors import ConfigError
from depthq.evaluate.online import decision_rate, default_canyons
from depthq.policies.registry import make_policy
from depthq.policies.spec import PolicySpec
from depthq.sim.world import DEFAULT_DECISION_HZ


def test_a_spec_names_a_builtin_an_onnx_file_or_a_checkpoint_folder(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    Path("heuristic").mkdir()  # a folder of a built-in's name: the built-in still wins
    Path("run").mkdir()
    assert PolicySpec.parse("heuristic") == PolicySpec("heuristic")
    assert PolicySpec.parse("ou") == PolicySpec("ou")
    assert PolicySpec.parse("onnx:out/a.onnx") == PolicySpec("onnx", Path("out/a.onnx"))
    spec = PolicySpec.parse("run")
    assert spec == PolicySpec("checkpoint", Path("run")) and spec.checkpoint == Path("run")
    assert PolicySpec.parse(spec) is spec
    assert spec.resolved().checkpoint == tmp_path / "run" and spec.name == "run"
    onnx = PolicySpec.parse("onnx:a.onnx")
    assert onnx.checkpoint is None and onnx.resolved() == onnx and onnx.name == "a.onnx"
    assert PolicySpec("ou").resolved() == PolicySpec("ou") and PolicySpec("ou").name == "ou"
    with pytest.raises(ConfigError, match="unknown policy 'nowhere'"):
        PolicySpec.parse("nowhere")


def test_builtins_build_and_take_the_defaults() -> None:
    assert isinstance(make_policy("heuristic"), DepthHeuristic)
    assert isinstance(make_policy(PolicySpec("ou"), seed=3), OUPolicy)
    assert decision_rate(PolicySpec("heuristic")) == DEFAULT_DECISION_HZ
    assert default_canyons(PolicySpec("ou")) == "eval"
    with pytest.raises(ConfigError, match="unknown policy"):
        make_policy("nowhere")
