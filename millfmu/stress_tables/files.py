"""A table's files and checksums: canonical JSON (equal content, equal text), sha256 of bytes
and files, a manifest's checksum of itself, and writes that reach the disk before a rename
publishes them.

A cache entry is a folder with ``table.npz`` (plain arrays, read with
``allow_pickle=False``), ``manifest.json`` and ``manifest.json.sha256``; an exported table is
``PREFIX.npz`` and ``PREFIX.json``, its manifest covered by its own ``manifest_sha256``.

Part of what an FMU carries: standard library only.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path


TABLE_FILE = "table.npz"
MANIFEST_FILE = "manifest.json"
MANIFEST_SUM_FILE = "manifest.json.sha256"


def canonical_json(obj) -> str:
    """JSON with sorted keys and no whitespace: equal content gives equal text."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)


def sha256_bytes(b: bytes) -> str:
    return hashlib.sha256(b).hexdigest()


#: A manifest's checksum of itself: sha256 of the canonical JSON of every other key. It
#: travels inside the file, so an exported table (PREFIX.npz, PREFIX.json) is covered too.
MANIFEST_SUM_KEY = "manifest_sha256"


def manifest_digest(m: dict) -> str:
    return sha256_bytes(canonical_json({k: v for k, v in m.items() if k != MANIFEST_SUM_KEY}).encode())


def sha256_file(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def write_synced(path: Path, data: bytes):
    """Write ``data`` to ``path`` and fsync it."""
    with open(path, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())


def write_replacing(path: Path, data: bytes, prefix: str = ".tmp-"):
    """Write ``data`` to a temporary file beside ``path`` (mode 644, not mkstemp's 600),
    fsync it and rename it onto ``path``: a reader sees the old file or the whole new one.
    The temporary file is removed where anything fails."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=prefix, dir=path.parent)
    os.close(fd)
    try:
        os.chmod(tmp, 0o644)
        write_synced(Path(tmp), data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def fsync_dir(path: Path):
    """fsync a folder, so that a rename into it is on the disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
