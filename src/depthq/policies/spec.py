"""A policy as the command line names it, parsed once: 'heuristic', 'ou', a checkpoint folder or
'onnx:PATH' (a graph written by `depthq export`). Building the policy, finding a checkpoint's rate and
canyons, and giving workers its absolute path all ask the parsed spec, not the string."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

from depthq.errors import ConfigError

BUILTIN = ("heuristic", "ou")
ONNX_PREFIX = "onnx:"


@dataclass(frozen=True)
class PolicySpec:
    """Which policy: a built-in one (`path` None), a checkpoint folder or an ONNX file (`path`)."""

    kind: Literal["heuristic", "ou", "checkpoint", "onnx"]
    path: Path | None = None

    @classmethod
    def parse(cls, spec: str | PolicySpec) -> PolicySpec:
        """A built-in name first, then 'onnx:PATH', then an existing folder (a checkpoint); anything
        else → ConfigError. A PolicySpec is returned as it is."""
        if isinstance(spec, PolicySpec):
            return spec
        if spec in BUILTIN:
            return cls(spec)  # type: ignore[arg-type]  # one of BUILTIN's literals
        if spec.startswith(ONNX_PREFIX):
            return cls("onnx", Path(spec.removeprefix(ONNX_PREFIX)))
        if Path(spec).is_dir():
            return cls("checkpoint", Path(spec))
        raise ConfigError(
            f"unknown policy {spec!r}: expected one of {BUILTIN}, an existing checkpoint folder or onnx:PATH"
        )

    @property
    def checkpoint(self) -> Path | None:
        """The checkpoint folder; None for any other policy."""
        return self.path if self.kind == "checkpoint" else None

    @property
    def name(self) -> str:
        """The folder's or file's name, or the built-in's (for progress bars and records)."""
        return self.kind if self.path is None else self.path.name

    def resolved(self) -> PolicySpec:
        """The same policy, a checkpoint by its absolute path (what every worker loads, on every node)."""
        return self if self.checkpoint is None else replace(self, path=self.checkpoint.resolve())
