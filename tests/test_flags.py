"""The verbs' flags are made from their configs (`depthq.flags`): every field of every verb's configs,
nested ones included (dotted: --samples.horizon, --env.world.decision-hz), is a flag with a help text;
every other flag has one too; and the spellings the flags had before (#33) parse to the same config."""

from __future__ import annotations

import argparse
import dataclasses
import re
import typing
from pathlib import Path

import pytest

from depthq.cli import VERBS, build_parser
from depthq.configio import KEYED, TAGGED, Keyed, complete_keyed, from_dict, keyed, to_dict
from depthq.flags import build_config, config_from_args

# Each verb's configs: (verb path, config class, fields it leaves to a flag of its own or has no use
# for, and the fields it takes alone when it sets a few of a config it does not build itself).
VERB_CONFIGS = [
    (("train",), "depthq.train.config:TrainConfig", (), None),
    (("collect",), "depthq.data.recorder:CollectConfig", (), None),
    (("evaluate",), "depthq.evaluate.online:EvalConfig", ("canyons",), None),  # --canyons: a canyon set
    (("drive",), "depthq.evaluate.online:EvalConfig", ("canyons", "lockstep"), None),  # --canyon: one
    (("labeller",), "depthq.labellers.labeller:LabellerConfig", (), None),
    (("dataset", "stats"), "depthq.data:DataConfig", (), None),
    (("sweep",), "depthq.data.recorder:CollectConfig", (), ("runs", "env.world.decision_hz",
                                                            "env.world.family")),
    (("probe",), "depthq.sim.world:WorldConfig", (), ("family",)),
    # the networks' acting settings, the policies' timed
    (("bench", "policy"), "depthq.evaluate.online:EvalConfig", (), ("depth.rule", "depth.discount",
                                                                     "depth.switch")),
]


def _class(spec: str) -> type:
    module, _, name = spec.partition(":")
    return getattr(__import__(module, fromlist=[name]), name)


def _paths(cls: type, prefix: str = "") -> list[str]:
    """Every field of `cls`, nested configs' fields by dotted path, a tagged config's under each of its
    tag's values, a keyed field's under each of its names (read here, not from depthq.flags)."""
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        if TAGGED in f.metadata or KEYED in f.metadata:
            classes = f.metadata[TAGGED][1]() if TAGGED in f.metadata else f.metadata[KEYED]()
            out += [path for name, inner in classes.items() for path in _paths(inner, f"{prefix}{name}.")]
        elif dataclasses.is_dataclass(hints[f.name]):
            out += _paths(hints[f.name], f"{prefix}{f.name}.")
        else:
            out.append(prefix + f.name)
    return out


def _parser(path: tuple[str, ...]) -> argparse.ArgumentParser:
    """The parser of a verb (or of a verb's action, e.g. dataset stats)."""
    parser = build_parser(path[0])
    for name in path:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = sub.choices[name]
    return parser


def _all_parsers(parser: argparse.ArgumentParser, name: str) -> list[tuple[str, argparse.ArgumentParser]]:
    out = [(name, parser)]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                out += _all_parsers(sub, f"{name} {sub_name}")
    return out


@pytest.mark.parametrize(("verb", "spec", "exclude", "only"), VERB_CONFIGS,
                         ids=[" ".join(v[0]) for v in VERB_CONFIGS])
def test_every_field_of_a_verbs_configs_is_a_flag_with_help(verb, spec, exclude, only) -> None:
    parser = _parser(verb)
    options = parser._option_string_actions
    paths = _paths(_class(spec))
    assert set(exclude) <= set(paths) and set(only or ()) <= set(paths)
    for path in paths:
        if path in exclude or (only is not None and path not in only):
            continue
        flag = "--" + path.replace("_", "-")
        assert flag in options, f"{' '.join(verb)}: no flag {flag}"
        action = options[flag]
        assert action.dest == path and action.help and action.help != argparse.SUPPRESS, flag
        assert len(action.help.split("(default")[0].strip()) > 10, f"{flag}: {action.help!r} says nothing"


def test_every_flag_of_every_verb_says_what_it_does() -> None:
    """Options and positionals alike, of every verb and every verb's actions; a flag's other spelling
    (--field_name) is hidden, but the flag it spells has its help."""
    for verb in VERBS:
        for name, parser in _all_parsers(_parser((verb,)), verb):
            shown = {}
            for action in parser._actions:
                if isinstance(action, argparse._HelpAction | argparse._SubParsersAction):
                    continue
                if action.help != argparse.SUPPRESS:
                    shown.setdefault(action.dest, []).append(action.help)
            for action in parser._actions:
                if isinstance(action, argparse._HelpAction | argparse._SubParsersAction):
                    continue
                helps = shown.get(action.dest, [])
                assert helps and all(h and h.strip() for h in helps), f"{name}: {action.option_strings} " \
                    f"({action.dest}) has no help"


def test_no_flag_says_its_help_twice() -> None:
    """A flag's help is its field's once: a verb that adds words (`more_help`) adds other words, and no
    field is a flag twice (`depthq labeller --help` once printed --data's help twice over)."""
    for verb in VERBS:
        for name, parser in _all_parsers(_parser((verb,)), verb):
            dests = [a.dest for a in parser._actions if a.help != argparse.SUPPRESS]
            assert len(dests) == len(set(dests)), f"{name}: a flag listed twice"
            for action in parser._actions:
                parts = [_words(p) for p in str(action.help or "").split(";") if len(_words(p)) >= 4]
                for i, one in enumerate(parts):
                    for other in parts[i + 1:]:  # the same words again, however reworded
                        same = len(one & other) / min(len(one), len(other))
                        assert same < 0.6, f"{name}: {action.option_strings} says a part twice"


def _words(text: str) -> set[str]:
    return {w for w in re.findall(r"[a-z]+", text.lower()) if len(w) > 3}


def test_train_help_lists_nested_fields_as_dotted_flags(capsys: pytest.CaptureFixture[str]) -> None:
    from depthq.cli import main

    with pytest.raises(SystemExit):
        main(["train", "--help"])
    out = capsys.readouterr().out
    assert "TrainConfig.samples: SampleConfig (--samples.*)" in out
    for flag in ("--samples.horizon", "--samples.min-frames", "--samples.every-run-end",
                 "--no-samples.every-run-end", "--samples.action-clip", "--samples.action-lag"):
        assert flag in out, flag


def test_train_help_lists_the_choices_of_every_choice_valued_flag(capsys: pytest.CaptureFixture[str]) -> None:
    """Each choice-valued setting is a Literal whose choices come from what owns them (the trunks'
    registry, the losses, the head forms, ...): --help lists them, and a value outside them is refused
    by name, exit 2, on the command line as in a config built otherwise."""
    from depthq.blocks.heads import HEAD_FORMS
    from depthq.blocks.losses import DEPTH_LOSSES
    from depthq.blocks.trunk import TRUNKS
    from depthq.checkpoint import WEIGHTS
    from depthq.cli import main
    from depthq.errors import ConfigError
    from depthq.train.config import PRECISIONS, TrainConfig

    with pytest.raises(SystemExit):
        main(["train", "--help"])
    out = capsys.readouterr().out
    for flag, choices in (("--trunk", tuple(TRUNKS)), ("--depth.depth-loss", DEPTH_LOSSES),
                          ("--depth.head-form", (*HEAD_FORMS, "none")), ("--labels", ("lidar", "camera")),
                          ("--weights", (*WEIGHTS, "none")), ("--precision", PRECISIONS)):
        assert f"{flag} {{{','.join(choices)}}}" in out, flag
    for flag, path in (("--trunk", "train.trunk"), ("--depth.depth-loss", "depth.depth_loss"),
                       ("--precision", "train.precision")):
        with pytest.raises(SystemExit) as exit_:
            main(["train", "--model", "depth", "--data", "d", "--out", "o", flag, "nonesuch"])
        assert exit_.value.code == 2 and "got 'nonesuch'" in capsys.readouterr().err
        with pytest.raises(ConfigError, match=rf"{path} must be one of .*, got 'nonesuch'"):
            build_config(TrainConfig, {"model": "depth", "data": "d",
                                       path.removeprefix("train."): "nonesuch"})


def _train(argv: list[str]):
    from depthq.train.config import TrainConfig

    args = build_parser("train").parse_args(["train", "--model", "coll", "--data", "d", "--out", "o", *argv])
    return config_from_args(TrainConfig, args)


def test_the_flat_train_spellings_parse_to_the_same_config() -> None:
    """TrainConfig held its sample settings itself until #33: --horizon is --samples.horizon, for one
    release, in either spelling."""
    from depthq.data.samples import SampleConfig

    dotted = _train(["--samples.horizon", "3", "--samples.min-frames", "30", "--no-samples.every-run-end",
                     "--samples.action-clip", "0.5", "--samples.action-lag", "1"])
    assert dotted.samples == SampleConfig(horizon=3, min_frames=30, every_run_end=False, action_clip=0.5,
                                          action_lag=1)
    for flat in (["--horizon", "3", "--min-frames", "30", "--no-every-run-end", "--action-clip", "0.5",
                  "--action-lag", "1"],
                 ["--horizon", "3", "--min_frames", "30", "--no-every_run_end", "--action_clip", "0.5",
                  "--action_lag", "1"],
                 ["--samples.horizon", "3", "--samples.min_frames", "30", "--no-every-run-end",
                  "--action-clip", "0.5", "--samples.action_lag", "1"]):
        assert _train(flat) == dotted, flat
    assert _train([]).samples == SampleConfig()


def test_the_old_verb_spellings_parse_to_the_same_config() -> None:
    """collect's --hz and --family, evaluate's and drive's --hz, --time-limit and --which: aliases of
    the flags made from the configs."""
    from depthq.data.recorder import CollectConfig, exploration_env
    from depthq.evaluate.online import EvalConfig
    from depthq.scripts.collect import run  # noqa: F401  (the verb's module builds its config as below)

    def collect(argv: list[str]) -> CollectConfig:
        args = build_parser("collect").parse_args(["collect", "--out", "o", *argv])
        family = getattr(args, "env.world.family", "paper")
        return config_from_args(CollectConfig, args, base=CollectConfig(env=exploration_env(family=family)))

    expected = CollectConfig(runs=3, env=exploration_env(10.0, family="hard"))
    assert collect(["--runs", "3", "--hz", "10", "--family", "hard"]) == expected
    assert collect(["--runs", "3", "--env.world.decision-hz", "10", "--env.world.family", "hard"]) == expected
    assert collect([]) == CollectConfig()
    assert collect(["--seed", "3"]) == CollectConfig(seed=3)  # the collection seed: a config field now
    for verb, argv in (("evaluate", ["heuristic", "--out", "o"]), ("drive", ["--out", "o"])):
        old = build_parser(verb).parse_args([verb, *argv, "--hz", "10", "--time-limit", "5",
                                             "--which", "last"])
        new = build_parser(verb).parse_args([verb, *argv, "--decision-hz", "10", "--time-limit-s", "5",
                                             "--weights", "last"])
        configs = [config_from_args(EvalConfig, a, canyons=("eval:0",)) for a in (old, new)]
        assert configs[0] == configs[1] == EvalConfig(canyons=("eval:0",), decision_hz=10.0,
                                                       time_limit_s=5.0, weights="last")


def test_sweep_settings_take_the_flat_and_the_dotted_names() -> None:
    """--set horizon=2 is --set samples.horizon=2, and the model folder keeps the name it had."""
    from depthq.pipeline.presets import get_preset
    from depthq.pipeline.sweep import parse_setting, widened

    assert parse_setting("horizon=2,5") == parse_setting("samples.horizon=2,5") == ("samples.horizon", (2, 5))
    sweep = widened(get_preset("smoke"), nets=("coll",), grid=(parse_setting("horizon=2,5"),))
    assert [m.name for m in sweep.models()] == ["coll_n3_s0_horizon2", "coll_n6_s0_horizon2", "coll_n3_s0",
                                                "coll_n6_s0"]
    assert sweep.train_config(sweep.models()[0], "d").samples.horizon == 2


def test_sweep_settings_parse_as_the_train_flags_do(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--set parses each value through the flags' own parser: lr=none is `depthq train --lr none`, a
    choice outside a Literal's is refused naming it (exit 2, nothing written), and a Depth-Q-Net-only
    setting (depth_loss) gives each Coll-Q-Net one model under its own name, not one per value."""
    from depthq.cli import main
    from depthq.pipeline.presets import get_preset
    from depthq.pipeline.sweep import parse_setting, widened
    from depthq.train.config import TrainConfig

    assert parse_setting("lr=none,0.1") == ("lr", (None, 0.1))
    assert parse_setting("dropout=0,0.5") == ("dropout", (0.0, 0.5))
    # an int for a setting that may be unset names its folders as it always did (average0, not average0.0)
    assert parse_setting("average=0,0.25") == ("average", (0, 0.25))
    assert widened(get_preset("smoke"), grid=(parse_setting("average=0"),)).models()[0].name == \
        "depth_n3_s0_average0"
    sweep = widened(get_preset("smoke"), grid=(parse_setting("lr=none"),))
    args = build_parser("train").parse_args(["train", "--model", "depth", "--data", "d", "--out", "o",
                                             "--lr", "none"])
    model = sweep.models()[0]
    assert model.name == "depth_n3_s0"  # the preset's own model: lr none is the default
    assert sweep.train_config(model, "d") == config_from_args(
        TrainConfig, args, **{**dict(sweep.train), "runs": 3, "seed": 0})
    for setting, named in (("trunk=nonesuch", "'nonesuch'"), ("depth.depth_loss=original,l2", "'l2'"),
                           ("lr=fast", "'fast'"), ("depth.head_form=concat,none,wide", "'wide'")):
        assert main(["sweep", "--preset", "smoke", "--set", setting, "--out", str(tmp_path / "s")]) == 2
        err = capsys.readouterr().err
        assert f"--set {setting.partition('=')[0]}" in err and named in err, err
    assert not (tmp_path / "s").exists()

    sweep = widened(get_preset("smoke"), grid=(parse_setting("depth.depth_loss=original,relative"),))
    names = [m.name for m in sweep.models()]
    assert sorted({n for n in names if n.startswith("coll")}) == ["coll_n3_s0", "coll_n6_s0"]
    assert sorted({n for n in names if n.startswith("depth")}) == [
        "depth_n3_s0", "depth_n3_s0_depth_lossrelative", "depth_n6_s0", "depth_n6_s0_depth_lossrelative"]


def test_a_variant_names_each_networks_models_by_what_differs_from_its_own_default() -> None:
    """200 epochs, best weights (select=best, the setting's old name): Coll-Q-Net acts with its best
    weights by default, so only its epochs name its folders; Depth-Q-Net's (its weight average by
    default) name both. `python -m depthq.report.paired --set` finds a sweep's models by the same names."""
    from depthq.pipeline.presets import get_preset
    from depthq.pipeline.sweep import differing, parse_setting, widened
    from depthq.report import paired

    grid = (parse_setting("epochs=200"), parse_setting("select=best"))
    sweep = widened(get_preset("smoke"), grid=grid)
    assert sorted(m.name for m in sweep.models() if m.runs == 6) == [
        "coll_n6_s0_epochs200", "depth_n6_s0_epochs200_selectbest"]
    variant = (("epochs", 200), ("weights", "best"))
    assert differing("coll", variant) == (("epochs", 200),)
    assert differing("depth", variant, sweep.train) == variant
    assert paired.main(["runs/none", "--set", "epochs=100,200"]) == 2  # one value each
    assert paired.main(["runs/none", "--set", "epochs=100"]) == 2  # no sweep folder


def test_build_config_sets_nested_fields_by_path_and_names_an_unknown_one() -> None:
    from depthq.data.recorder import CollectConfig
    from depthq.errors import ConfigError

    config = build_config(CollectConfig, {"runs": 3, "env.world.decision_hz": 10.0, "data.min_frames": 30})
    assert (config.runs, config.env.world.decision_hz, config.data.min_frames) == (3, 10.0, 30)
    assert config.env.world.max_yaw_rate == CollectConfig().env.world.max_yaw_rate  # the enclosing default
    with pytest.raises(ConfigError, match="no setting nothing"):
        build_config(CollectConfig, {"env.nothing": 1})


@dataclasses.dataclass(frozen=True)
class _Near:
    """A toy name's config."""

    reach: float = 2.0  # metres


@dataclasses.dataclass(frozen=True)
class _Far:
    """Another toy name's config."""

    steps: int = 3  # steps


@dataclasses.dataclass(frozen=True)
class _Held:
    """A config with a keyed field: one config per name."""

    seed: int = 0  # a seed
    each: Keyed = dataclasses.field(default_factory=Keyed,
                                    metadata=keyed(lambda: {"near": _Near, "far": _Far}))

    def __post_init__(self) -> None:
        complete_keyed(self)


def test_a_keyed_field_holds_a_config_per_name_spelled_by_the_name() -> None:
    """Its configs are flags, record keys and field paths by their names; each absent one at its
    defaults; frozen and hashable; a name of no class, or a config of another's, refused."""
    from depthq.errors import ConfigError
    from depthq.flags import config_flags, get_path

    held = _Held()
    assert held.each == {"near": _Near(), "far": _Far()} and hash(held) == hash(_Held())
    assert [f.path for f in config_flags(_Held)] == ["seed", "near.reach", "far.steps"]
    built = build_config(_Held, {"far.steps": 5, "seed": 1})
    assert built.each == {"near": _Near(), "far": _Far(steps=5)} and get_path(built, "far.steps") == 5
    assert build_config(_Held, {"near.reach": 1.0}, built).each == {"near": _Near(1.0), "far": _Far(5)}
    assert to_dict(built) == {"seed": 1, "near": {"reach": 2.0}, "far": {"steps": 5}}
    assert from_dict(_Held, to_dict(built)) == built and from_dict(_Held, {"seed": 1}) == _Held(seed=1)
    with pytest.raises(TypeError):
        built.each["far"] = _Far()  # type: ignore[index]
    with pytest.raises(ConfigError, match="'mid' has no settings here"):
        _Held(each={"mid": _Near()})
    with pytest.raises(ConfigError, match=r"each\['far'\] must be a _Far"):
        _Held(each={"far": _Near()})
    with pytest.raises(ConfigError, match="unknown field"):
        from_dict(_Held, {"mid": {}})


def test_collect_offers_only_what_changes_the_data(capsys: pytest.CaptureFixture[str]) -> None:
    """A training's sample settings are TrainConfig.samples' alone: collect's --help offers none of
    them (nor Table II's subsets), and a dataset's manifest written when it held them (before #48)
    reads without them, so the same collection resumes it."""
    from depthq.cli import main
    from depthq.data.manifest import upgrade_config
    from depthq.data.recorder import CollectConfig
    from depthq.data.samples import SampleConfig

    with pytest.raises(SystemExit):
        main(["collect", "--help"])
    out = capsys.readouterr().out
    training_only = [f.name for f in dataclasses.fields(SampleConfig) if f.name != "min_frames"]
    for name in (*training_only, "subsets"):
        assert f"--data.{name.replace('_', '-')}" not in out and f"--{name.replace('_', '-')} " not in out
    assert "--data.min-frames" in out and "--data.jpeg-quality" in out
    recorded = CollectConfig(runs=3).recorded()
    old = {**recorded, "data": {**recorded["data"], "horizon": 2, "every_run_end": True, "action_clip": 1.0,
                                "action_lag": 0, "subsets": [50, 100]}}
    assert upgrade_config(old) == recorded


def test_no_setting_is_declared_twice() -> None:
    """TrainConfig holds a SampleConfig instead of mirroring its fields, and a sweep its stages' configs:
    none of their fields is a field of the sweep (its `canyons` is the canyon set evaluate's --canyons
    takes, which EvalConfig holds as the canyons it names). HeadConfig has no default for a setting
    TrainConfig holds (a second default could disagree), and `TrainConfig.head` passes each on."""
    from depthq.blocks.heads import HeadConfig
    from depthq.data.recorder import CollectConfig
    from depthq.data.samples import SampleConfig
    from depthq.evaluate.online import EvalConfig
    from depthq.networks import DepthSettings
    from depthq.pipeline.sweep import Sweep
    from depthq.train.config import TrainConfig

    def names(cls: type) -> set[str]:
        return {f.name for f in dataclasses.fields(cls)}

    assert not names(TrainConfig) & names(SampleConfig)
    assert not names(Sweep) & (names(CollectConfig) | names(TrainConfig) | names(EvalConfig) - {"canyons"})

    in_train = {"kind": "model", "form": "head_form"}  # HeadConfig's names that TrainConfig spells otherwise
    own = names(TrainConfig) | names(DepthSettings)  # a network's head settings may be its own
    shared = {f.name: in_train.get(f.name, f.name) for f in dataclasses.fields(HeadConfig)
              if in_train.get(f.name, f.name) in own}
    assert {"hidden", "dropout", "action_scale", "lookahead", "feature_projection", "form"} <= set(shared)
    defaulted = [f.name for f in dataclasses.fields(HeadConfig) if f.name in shared
                 and (f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING)]
    assert not defaulted, f"HeadConfig declares a default for TrainConfig's {defaulted}"
    train = TrainConfig(model="depth", data="-", hidden=8, dropout=0.25, action_scale=3.0,
                        feature_projection=5, settings=DepthSettings(lookahead=2))
    owner = {of: train.settings if of in names(DepthSettings) else train for of in shared.values()}
    assert all(getattr(train.head(), name) == getattr(owner[of], of) for name, of in shared.items())


def test_verbs_are_found_here(tmp_path: Path) -> None:
    """Every verb with a config class is in VERB_CONFIGS (a verb given one later is checked too)."""
    import ast
    import inspect

    import depthq.scripts

    root = Path(inspect.getfile(depthq.scripts)).parent
    listed = {v[0][0] for v in VERB_CONFIGS}
    for verb, module in VERBS.items():
        source = (root / f"{module}.py").read_text()
        calls = [n for n in ast.walk(ast.parse(source)) if isinstance(n, ast.Call)
                 and getattr(n.func, "id", "") == "add_config_arguments"]
        assert not calls or verb in listed, verb
