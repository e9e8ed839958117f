"""Names inside a reproduction folder, shared by the stages that write it and the report that reads it.

    OUT/models/<net>_n<N>_s<S>/   one checkpoint per (network, training runs, seed)
    OUT/eval/<net>_n<N>_s<S>/     its evaluation (and OUT/eval/heuristic, OUT/eval/ou)

The data flow is one way: `reproduce` runs the stages, then `build` turns their files into tables,
figures and the report; neither the report nor its tables import the stage runner.
"""

from __future__ import annotations

NETS = ("depth", "coll")


def model_name(net: str, runs: int, seed: int) -> str:
    """e.g. depth_n200_s1."""
    return f"{net}_n{runs}_s{seed}"
