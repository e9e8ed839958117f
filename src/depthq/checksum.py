"""Checksums: the SHA-256 a file a result depends on carries, recorded where it is written and checked
where it is read, so a changed byte (a bad copy, a flipped bit, a hand edit) stops with a message
naming the file instead of silently changing a result (docs/formats.md#checksums).

A JSON record carries its own: the key "sha256" holds the SHA-256 of the record without that key,
serialised canonically (sorted keys, no spaces, strict JSON). A record written before checksums
(without the key) is read as it is, and gets one when it is next written.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from depthq.configio import read_json, write_json
from depthq.errors import ConfigError, DataError

KEY = "sha256"
_CHUNK = 1 << 20


def record_digest(record: dict[str, Any]) -> str:
    """The SHA-256 of `record` without its "sha256" key, serialised canonically."""
    body = {k: v for k, v in record.items() if k != KEY}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False, ensure_ascii=False)
    return hashlib.sha256(text.encode()).hexdigest()


def write_checked_json(path: Path, record: dict[str, Any]) -> None:
    """Write `record` as JSON (`depthq.configio.write_json`) with its checksum under "sha256"."""
    if KEY in record:
        raise ConfigError(f"{path}: key {KEY!r} is reserved for the record's checksum")
    write_json(path, {**record, KEY: record_digest(record)})


def read_checked_json(path: Path, fix: str) -> Any:
    """The JSON record in `path`, its checksum checked (a record without one is read as it is);
    a mismatch → DataError naming the file and `fix`, what to do. The "sha256" key is left out."""
    record = read_json(path)
    if not isinstance(record, dict) or KEY not in record:
        return record
    if record[KEY] != record_digest(record):
        raise DataError(f"{path}: changed after it was written (its SHA-256 does not match the one it "
                        f"records); {fix}")
    return {k: v for k, v in record.items() if k != KEY}


def file_sha256(path: Path) -> str:
    """The SHA-256 of a file's bytes, read in 1 MiB chunks."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()
