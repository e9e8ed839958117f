"""Names inside a reproduction folder, shared by the stages that write it and the report that reads it.

    OUT/models/<net>_n<N>_s<S>[_<field><value>…]/   one checkpoint per (network, training runs, seed,
                                                    variant of a sweep's grid, e.g. _dropout0.5)
    OUT/eval/<same name>/                           its evaluation (and OUT/eval/heuristic, OUT/eval/ou)

The data flow is one way: `reproduce` runs the stages, then `build` turns their files into tables,
figures and the report; neither the report nor its tables import the stage runner.
"""

from __future__ import annotations

from typing import Any

from depthq.blocks.migrations import FOLDER_KEYS


def model_name(net: str, runs: int, seed: int, variant: tuple[tuple[str, Any], ...] = ()) -> str:
    """e.g. depth_n200_s1, or depth_n200_s1_dropout0.5 in a sweep's variant (a tuple value's items
    joined by '+': depth_n200_s1_snapshots40+80; a renamed setting under its old name, `FOLDER_KEYS`; a
    network's own setting without its network's name: depth.lookahead is depth_n200_s1_lookahead3)."""
    keys = [FOLDER_KEYS.get(k, k.removeprefix(f"{net}.")) for k, _ in variant]
    settings = "".join(f"_{key}{setting_text(v)}" for key, (_, v) in zip(keys, variant, strict=True))
    return f"{net}_n{runs}_s{seed}{settings}"


def setting_text(value: Any) -> str:
    """A setting's value as a folder name shows it (and `--set` takes it): a tuple joined by '+'."""
    return "+".join(map(str, value)) if isinstance(value, tuple) else str(value)
