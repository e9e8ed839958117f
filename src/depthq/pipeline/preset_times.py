"""How long each reproduction preset takes, stated once: `reproduce --help`, the README and the docs
say these (a test checks each place), and each figure's run or arithmetic is in
docs/benchmarks.md#preset-times. Apart from the presets themselves, so that `--help` imports no torch."""

from __future__ import annotations

from dataclasses import dataclass

DEFAULT_PRESET = "quick"


@dataclass(frozen=True)
class Duration:
    """A preset's wall time end to end on the dev host (2 CPU cores, no GPU, both idle): measured, or,
    where no end-to-end run has been timed, the sum of its stages' floors, which it takes at least
    (docs/benchmarks.md#preset-times gives each figure's run or arithmetic)."""

    seconds: float
    measured: bool

    def __str__(self) -> str:
        amount = f"{self.seconds:.0f} s" if self.seconds < 120 else f"{self.seconds / 60:.0f} min"
        return f"≈ {amount}" if self.measured else f"≥ {amount}, estimated"


DURATIONS: dict[str, Duration] = {
    "smoke": Duration(39, measured=True),
    "quick": Duration(24 * 60, measured=True),
    "paper": Duration(90 * 60, measured=False),
    "nominal": Duration(150 * 60, measured=False),
    "hard": Duration(55 * 60, measured=False),
}


def presets_help() -> str:
    """`--preset`'s help: every preset with its time, and the default."""
    listed = ", ".join(f"{name} ({duration})" for name, duration in DURATIONS.items())
    return (f"which preset to run, with its wall time on 2 CPU cores: {listed} "
            f"(docs/benchmarks.md#preset-times; default: {DEFAULT_PRESET})")
