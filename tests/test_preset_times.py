"""Each preset's time is stated once (`depthq.pipeline.preset_times`), measured or estimated as
docs/benchmarks.md#preset-times says; every place that states a preset's time states that one:
`reproduce --help` (and so docs/cli.md), the README, Getting started, the benchmarks' table."""

from __future__ import annotations

import re
from pathlib import Path

from depthq.cli_reference import reference
from depthq.pipeline.preset_times import DEFAULT_PRESET, DURATIONS, presets_help
from depthq.pipeline.presets import PRESETS

ROOT = Path(__file__).parents[1]
NAME = "|".join(PRESETS)
# A preset named where a time may be said of it: `--preset quick`, preset "quick", a table's | quick |.
MENTION = re.compile(rf"--preset ({NAME})\b|preset \"({NAME})\"|^\| ({NAME}) \|")
# Anything that reads as a duration.
TIME = re.compile(r"[≈≤≥~]? ?\b\d+(?:\.\d+)? ?(?:s|min|h|hours?|minutes?)\b|\ba few (?:minutes|hours)\b"
                  r"|\babout an? (?:minute|hour)\b|\bunder an? (?:minute|hour)\b", re.I)


def test_every_preset_has_one_time_and_the_default_is_a_preset() -> None:
    assert list(DURATIONS) == list(PRESETS) and DEFAULT_PRESET in PRESETS
    assert str(DURATIONS["smoke"]) == "≈ 39 s" and str(DURATIONS["paper"]) == "≥ 90 min, estimated"


def test_reproduce_help_names_its_default_and_every_preset_with_its_time() -> None:
    page = " ".join(reference().split())
    assert " ".join(presets_help().split()) in page
    for name, duration in DURATIONS.items():
        assert f"{name} ({duration})" in presets_help()
    assert f"default: {DEFAULT_PRESET}" in presets_help()


def _stated(page: Path) -> list[tuple[str, str]]:
    """(preset, the line) for each line of `page` that names one preset and says a duration."""
    out = []
    for line in page.read_text().splitlines():
        names = {next(g for g in m.groups() if g) for m in MENTION.finditer(line)}
        if names and TIME.search(line):
            assert len(names) == 1, f"{page.name}: one preset's time per line: {line}"
            out.append((names.pop(), line))
    return out


def test_every_place_that_states_a_presets_time_agrees() -> None:
    for name in ("README.md", "docs/getting-started.md"):
        stated = _stated(ROOT / name)
        assert {preset for preset, _ in stated} >= {"smoke", "quick", "paper"}, name
        for preset, line in stated:
            said = {m.group(0).strip() for m in TIME.finditer(line)}
            assert str(DURATIONS[preset]) in line and all(s in str(DURATIONS[preset]) for s in said), line
    benchmarks = (ROOT / "docs" / "benchmarks.md").read_text()
    section = benchmarks.split("{#preset-times}")[1].split("\n#")[0]
    rows = {line.split("|")[1].strip(): line.split("|")[2].strip() for line in section.splitlines()
            if line.startswith("| ") and line.split("|")[1].strip() in PRESETS}
    assert rows == {name: str(duration) for name, duration in DURATIONS.items()}
