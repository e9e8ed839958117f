"""The `depthq` command itself: every verb is there and explains itself."""

from __future__ import annotations

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
