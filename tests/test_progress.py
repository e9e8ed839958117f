"""Progress bars: on a terminal a collection's bar only moves forward, to its total (it once jumped from
100 % back to 38 % when short runs were collected again); without one (a log, CI) each bar is one line,
written when it ends, with no terminal control codes."""

from __future__ import annotations

import fcntl
import os
import re
import struct
import sys
import termios
import threading
from pathlib import Path

import pytest

from depthq.data.recorder import CollectConfig, collect
from depthq.progress import Bar

# Seed 0: training run 0 is too short to use, so the collection runs a second round for run 2.
SHORT_RUNS = CollectConfig(runs=2, val_runs=1, max_steps=40)


def _counts(text: str, desc: str, total: int) -> list[int]:
    return [int(n) for n in re.findall(rf"{desc}:[^|\n\r]*\|[^|]*\| *(\d+)/{total}\b", text)]


def test_on_a_terminal_a_collections_bar_never_goes_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    leader, follower = os.openpty()
    fcntl.ioctl(follower, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    chunks: list[bytes] = []

    def drain() -> None:
        while True:
            try:
                chunk = os.read(leader, 4096)
            except OSError:  # the terminal's other end closed
                return
            if not chunk:
                return
            chunks.append(chunk)

    reader = threading.Thread(target=drain, daemon=True)
    reader.start()
    with os.fdopen(follower, "w") as terminal:
        monkeypatch.setattr(sys, "stderr", terminal)
        dataset = collect(tmp_path / "data", SHORT_RUNS, workers=1, progress=True)
        monkeypatch.undo()
    reader.join(timeout=10)
    os.close(leader)
    assert len(list(dataset.entries())) > 3  # a short run was made up for: the case that went back
    counts = _counts(b"".join(chunks).decode(errors="replace"), "collect", 3)
    assert counts and counts == sorted(counts) and counts[-1] == 3, counts


def test_without_a_terminal_a_collection_writes_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    collect(tmp_path / "data", SHORT_RUNS, workers=1, progress=True)
    err = capsys.readouterr().err
    lines = [line.strip("\r") for line in err.split("\n") if line.strip()]
    assert len(lines) == 1 and _counts(lines[0], "collect", 3) == [3], err
    assert "\x1b" not in err


def test_without_a_terminal_nested_bars_write_one_line_each_as_they_end(
    capsys: pytest.CaptureFixture
) -> None:
    with Bar(total=2, desc="stages", unit="stage") as outer:
        for stage in range(2):
            with Bar(total=50, desc=f"stage {stage}", unit="step") as inner:
                for _ in range(50):
                    inner.update(1)
                    inner.set_postfix(loss=0.5)
            Bar.write(f"stage {stage} done", file=sys.stderr)
            outer.update(1)
    err = capsys.readouterr().err
    assert "\x1b" not in err
    lines = [line.strip("\r") for line in err.split("\n") if line]
    assert [line.split(":")[0] if "%" in line else line for line in lines] == [
        "stage 0", "stage 0 done", "stage 1", "stage 1 done", "stages"], lines
    assert _counts(err, "stage 0", 50) == [50] and _counts(err, "stages", 2) == [2]
