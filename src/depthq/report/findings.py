"""The paper's claims and depthq's deviations from it, as the report shows them: read from the
findings file beside the docs (docs/findings.json, docs/formats.md#findings). Words are written there
by hand; a claim's evidence is written by the experiment that measured it, so a new measurement edits
data, not code."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from depthq.configio import atomic_write_bytes, read_json
from depthq.errors import ConfigError

# The source checkout's docs/ (an editable install: the README's); an installed wheel has none.
FINDINGS = Path(__file__).resolve().parents[3] / "docs" / "findings.json"


@dataclass(frozen=True)
class Evidence:
    """One measurement behind a claim: what it says, and the command that wrote it."""

    text: str
    by: str


@dataclass(frozen=True)
class Claim:
    """A claim of the paper, whether it holds here (words), where it is measured, and the evidence."""

    id: str
    claim: str
    verdict: str
    where: str
    evidence: dict[str, Evidence]


@dataclass(frozen=True)
class Deviation:
    """What the paper did, what depthq does instead, why, and the docs section that measures it."""

    paper: str
    depthq: str
    why: str
    doc: str


@dataclass(frozen=True)
class Findings:
    claims: tuple[Claim, ...]
    deviations: tuple[Deviation, ...]

    def claim(self, claim_id: str) -> Claim:
        for claim in self.claims:
            if claim.id == claim_id:
                return claim
        known = ", ".join(c.id for c in self.claims)
        raise ConfigError(f"no claim {claim_id!r} in the findings; known: {known}")


def read_findings(path: Path = FINDINGS) -> Findings:
    """The findings file, checked field by field (a clear error names the bad entry)."""
    return _parse(read_json(path), path)


def _parse(raw: Any, path: Path) -> Findings:
    try:
        claims = tuple(
            Claim(c["id"], c["claim"], c["verdict"], c["where"],
                  {key: Evidence(e["text"], e["by"]) for key, e in c.get("evidence", {}).items()})
            for c in raw["claims"]
        )
        deviations = tuple(Deviation(d["paper"], d["depthq"], d["why"], d["doc"]) for d in raw["deviations"])
    except (KeyError, TypeError) as err:
        raise ConfigError(f"{path}: not a findings file (missing or malformed {err})") from None
    ids = [c.id for c in claims]
    if len(set(ids)) != len(ids):
        raise ConfigError(f"{path}: claim ids must be unique, got {ids}")
    return Findings(claims, deviations)


def record_evidence(claim_id: str, key: str, evidence: Evidence, path: Path = FINDINGS) -> None:
    """Write (or replace) one measurement behind claim `claim_id`, under `key` (what it measured, e.g.
    'hard/eval, 500 runs'); the rest of the file is kept as it is."""
    raw: dict[str, Any] = read_json(path)
    _parse(raw, path).claim(claim_id)  # an unknown claim or a malformed file: nothing written
    for claim in raw["claims"]:
        if claim["id"] == claim_id:
            claim.setdefault("evidence", {})[key] = {"text": evidence.text, "by": evidence.by}
    atomic_write_bytes(path, (json.dumps(raw, indent=2, ensure_ascii=False, allow_nan=False) + "\n").encode())
