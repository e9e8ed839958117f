"""The `depthq` command itself: every verb is there and explains itself."""

from __future__ import annotations

import re

import pytest

from depthq.cli import VERBS, main


@pytest.mark.parametrize("argv", [[], *([verb] for verb in VERBS)])
def test_help_of_the_command_and_of_every_verb(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    """argparse %-formats help texts: a verb whose summary says "95 %" once broke `depthq --help`."""
    with pytest.raises(SystemExit) as exit_:
        main([*argv, "--help"])
    assert exit_.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: depthq")
    if not argv:
        assert all(verb in out for verb in VERBS) and "95 % intervals" in out


def test_every_train_config_field_is_a_flag_with_its_default(capsys: pytest.CaptureFixture[str]) -> None:
    """The flags are made from TrainConfig: a field added there is a flag, its default the class's."""
    from dataclasses import MISSING, fields

    from depthq.cli import build_parser
    from depthq.configio import TAGGED
    from depthq.flags import config_from_args
    from depthq.train.config import TrainConfig

    with pytest.raises(SystemExit):
        main(["train", "--help"])
    out = capsys.readouterr().out
    names = [f.name for f in fields(TrainConfig) if TAGGED not in f.metadata]  # `settings`: --depth.*
    assert all(f"--{name.replace('_', '-')}" in out for name in [*names, "depth.lookahead"])
    args = build_parser("train").parse_args(["train", "--model", "depth", "--data", "d", "--out", "o"])
    assert config_from_args(TrainConfig, args) == TrainConfig(model="depth", data="d")
    for f in fields(TrainConfig):  # a flag not given sets nothing: the config takes the class's default
        assert not hasattr(args, f.name) or f.default is MISSING, f.name


def test_a_flag_sets_its_field_in_either_spelling() -> None:
    """--action-scale (one of the headline deviations) had no flag; dashes or underscores both work,
    and the old spellings (--depth-loss, --epochs, --lr, ...) still do."""
    from depthq.cli import build_parser
    from depthq.flags import config_from_args
    from depthq.train.config import TrainConfig

    argv = ["train", "--model", "depth", "--data", "d", "--out", "o", "--action-scale", "3", "--lr", "none",
            "--depth_loss", "valid_mean", "--epochs", "7", "--no-every-run-end", "--action_lag", "1"]
    config = config_from_args(TrainConfig, build_parser("train").parse_args(argv))
    assert (config.model, config.data, config.action_scale, config.lr) == ("depth", "d", 3.0, None)
    assert (config.settings.depth_loss, config.epochs) == ("valid_mean", 7)
    assert (config.samples.every_run_end, config.samples.action_lag) == (False, 1)


def test_renamed_flags_keep_their_old_spellings() -> None:
    """#33 renamed the weights flags (a checkpoint's own: train --weights, was --select; an override of
    them: evaluate, drive and export --weights, was --which): the old spellings still parse, for one
    release."""
    from depthq.cli import build_parser
    from depthq.flags import config_from_args
    from depthq.train.config import TrainConfig

    for flag in ("--weights", "--select"):
        argv = ["train", "--model", "coll", "--data", "d", "--out", "o", flag, "final"]
        assert config_from_args(TrainConfig, build_parser("train").parse_args(argv)).weights == "final"
    for verb, argv in (("evaluate", ["heuristic", "--out", "o"]), ("drive", ["--out", "o"]),
                       ("export", ["ckpt", "--out", "o"])):
        for flag in ("--weights", "--which"):
            assert build_parser(verb).parse_args([verb, *argv, flag, "epoch:3"]).weights == "epoch:3"


def test_sweep_set_takes_the_flag_names_too() -> None:
    from depthq.pipeline.sweep import parse_setting

    expected = ("action_scale", (1.0, 10.0))
    assert parse_setting("action-scale=1,10") == parse_setting("action_scale=1,10") == expected


@pytest.mark.parametrize(("argv", "named"), [
    (["--epochs", "ten"], "'ten'"),
    (["--every-run-end", "maybe"], "maybe"),
])
def test_a_bad_flag_value_is_named(argv: list[str], named: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["train", "--model", "depth", "--data", "d", "--out", "o", *argv])
    assert exit_.value.code == 2 and named in capsys.readouterr().err


def test_a_bad_config_value_exits_2_with_one_line(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["train", "--model", "depth", "--data", str(tmp_path), "--out", str(tmp_path / "o"),
                 "--dropout", "1.5"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "dropout" in err and "1.5" in err


def test_the_cli_reference_page_is_current() -> None:
    """docs/cli.md is generated from the parsers; a flag added or changed without regenerating it fails
    here, with the command that regenerates it."""
    from pathlib import Path

    from depthq.cli_reference import reference

    page = Path(__file__).parents[1] / "docs" / "cli.md"
    assert page.read_text() == reference(), "docs/cli.md is stale: python -m depthq.cli_reference docs/cli.md"
    assert "## `depthq train`" in page.read_text() and "--epochs" in page.read_text()


def _planned(printed: str) -> list[list[str]]:
    """The commands a dry run printed, each as its words after `depthq`."""
    import shlex

    return [shlex.split(line.partition("] depthq ")[2]) for line in printed.splitlines()
            if "] depthq " in line]


def test_a_dry_run_prints_the_commands_its_stages_are_and_writes_nothing(
    tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`depthq sweep --dry-run` (`lr=none`: the network's own rate, a variant equal to the preset's)
    writes nothing, not even a lock file; each command it prints builds the config its stage runs
    with; run, a command's stage reads as done; a folder of another setup is refused as a run would."""
    from depthq.cli import build_parser
    from depthq.data.recorder import CollectConfig, exploration_env
    from depthq.evaluate.online import EvalConfig, parse_canyon_set
    from depthq.flags import config_from_args
    from depthq.pipeline.presets import get_preset
    from depthq.pipeline.stages import _claim
    from depthq.pipeline.sweep import parse_setting, widened
    from depthq.train.config import TrainConfig

    out = tmp_path.resolve() / "X"  # the folder the commands name, as a run resolves it
    dry = ["sweep", "--preset", "smoke", "--set", "lr=none", "--dry-run", "--out", str(out)]
    assert main(dry) == 0
    assert list(tmp_path.iterdir()) == []
    printed = capsys.readouterr().out
    assert "smoke sweep: 4 models" in printed and "stages (13 of 13 to run)" in printed
    sweep = widened(get_preset("smoke"), grid=(parse_setting("lr=none"),))
    models = {m.name: m for m in sweep.models()}
    assert sorted(re.findall(r"^  (\S+_n\d+_s\d+\S*) ", printed, re.MULTILINE)) == sorted(models)
    commands = _planned(printed)
    assert [words[0] for words in commands] == ["collect", *["evaluate"] * 2, *["train", "evaluate"] * 4]
    for words in commands:
        args = build_parser(words[0]).parse_args(words)
        if words[0] == "collect":
            start = CollectConfig(env=exploration_env(family=getattr(args, "env.world.family", "paper")))
            assert config_from_args(CollectConfig, args, base=start) == sweep.collect
        elif words[0] == "train":
            assert args.out == out / "models" / args.out.name and args.data == str(out / "data")
            assert config_from_args(TrainConfig, args) == sweep.train_config(models[args.out.name], args.data)
        else:
            config = config_from_args(EvalConfig, args, canyons=parse_canyon_set(args.canyons))
            assert config == sweep.eval_config() and args.no_video

    assert main(["reproduce", "--preset", "smoke", "--dry-run", "--out", str(out)]) == 0
    assert capsys.readouterr().out.startswith("smoke: 4 models") and list(tmp_path.iterdir()) == []
    _claim(out, sweep)  # a folder of the smoke preset's setup
    assert main(["reproduce", "--preset", "quick", "--dry-run", "--out", str(out)]) == 2
    assert "runs 6 there, 200 here" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["reproduce.json"]


@pytest.mark.slow
def test_a_stage_run_by_the_command_a_dry_run_printed_reads_as_done(
    tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The reference heuristic's evaluation, run by its printed command in a sweep's folder: a dry run
    then marks that stage done, and only it."""
    from depthq.pipeline.presets import get_preset
    from depthq.pipeline.stages import _claim

    out = tmp_path.resolve() / "X"
    dry = ["reproduce", "--preset", "smoke", "--dry-run", "--out", str(out)]
    assert main(dry) == 0
    heuristic = _planned(capsys.readouterr().out)[1]
    assert heuristic[:2] == ["evaluate", "heuristic"]
    _claim(out, get_preset("smoke"))  # as a run starts
    assert main(heuristic) == 0
    capsys.readouterr()
    assert main(dry) == 0
    printed = capsys.readouterr().out
    assert "stages (12 of 13 to run)" in printed and "[done  ] depthq evaluate heuristic" in printed


def test_no_help_text_leaks_a_source_comments_directive() -> None:
    """Flags' help comes from the comments beside config fields (`depthq.flags.field_help`); a tool's
    directive there (`# type: ignore[...]`, `# noqa`) is not help. Every verb's and sub-command's help."""
    import re

    from depthq.cli_reference import reference
    from depthq.flags import field_help
    from depthq.sim.world import WorldConfig

    page = reference()
    assert "--family" in page and "--rule" in page  # the flags whose comments carry a directive
    leaks = [line for line in page.splitlines() if re.search(r"type:|noqa|pragma:", line)]
    assert not leaks, leaks
    assert field_help(WorldConfig)["family"].startswith("The canyon family")
