"""The recorded contacts of a run, kept on disk instead of in memory.

A run records every new contact (rows of ``n_cols`` float64, layout ``engine.kernels.EV_*``)
once per sampling interval ("chunk"). A full slice records about 1,200 contacts per bead
per simulated second, 88 bytes each: 0.3 s of seed 001's 235 k-bead disc slice are 84 M
contacts, 7.4 GB, which in memory (and pickled whole into every checkpoint) took a 24 GB
machine's memory. Here each chunk is appended to one raw file; memory holds only the
chunks' row counts.

The file is written append-only and flushed to disk before a checkpoint names its
length (:meth:`ContactLog.state`), so that a run stopped after the checkpoint resumes
(:meth:`ContactLog.resume`) by cutting the rows appended after it, which the resumed run
records again. The chunks are read back as read-only memory maps of the file: the same
numbers, in the same C layout, as the in-memory arrays, so statistics computed from them
are identical to the digit, and the operating system pages them in and out as needed.

Imports no numba.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

#: the file in a run's output folder (removed once the run's outputs are written)
FILE = "recorded_contacts.f8"

_ITEM = np.dtype(np.float64).itemsize


class ContactLogError(ValueError):
    """The log file does not match the state a checkpoint names."""


class ContactLog:
    """Chunks of recorded contact rows (float64, ``n_cols`` columns) in ``path``."""

    def __init__(self, path, n_cols: int, rows=(), _new: bool = True):
        self.path = Path(path)
        self.n_cols = int(n_cols)
        #: rows of each chunk, in order
        self.rows = [int(r) for r in rows]
        self._starts = np.concatenate([[0], np.cumsum(self.rows, dtype=np.int64)])
        if _new:
            # a fresh recording: an older file of the same name is ours, from a run that
            # was stopped before any checkpoint named it
            self.path.write_bytes(b"")
        self._map = None

    @classmethod
    def resume(cls, path, n_cols: int, state: dict) -> ContactLog:
        """The log a checkpoint's ``state`` (:meth:`state`) names: the file cut to the
        length the checkpoint knew (rows appended after it are recorded again);
        ContactLogError naming the file where it is missing or shorter."""
        path = Path(path)
        if int(state["n_cols"]) != int(n_cols):
            raise ContactLogError(f"{path}: the checkpoint's contacts have {state['n_cols']} "
                                  f"columns; this version records {n_cols}")
        log = cls(path, n_cols, state["rows"], _new=False)
        need = log.total_rows * log.n_cols * _ITEM
        have = path.stat().st_size if path.exists() else None
        if have is None or have < need:
            raise ContactLogError(
                f"{path}: {'missing' if have is None else f'{have} bytes'}; the checkpoint "
                f"recorded {log.total_rows} contacts ({need} bytes) in it")
        if have > need:
            os.truncate(path, need)
        return log

    @classmethod
    def from_chunks(cls, path, n_cols: int, chunks) -> ContactLog:
        """A log written from in-memory chunks (a checkpoint of earlier sources kept them
        in memory)."""
        log = cls(path, n_cols)
        for c in chunks:
            log.append(c)
        return log

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def total_rows(self) -> int:
        return int(self._starts[-1])

    def append(self, rows: np.ndarray) -> None:
        """Append one chunk (an (n, n_cols) array, n may be 0)."""
        a = np.ascontiguousarray(rows, dtype=np.float64)
        if a.ndim != 2 or (a.size and a.shape[1] != self.n_cols):
            raise ValueError(f"a chunk of contacts must be (n, {self.n_cols}); got {a.shape}")
        with open(self.path, "ab") as fh:
            fh.write(a.tobytes())
        self.rows.append(int(a.shape[0]))
        self._starts = np.append(self._starts, self._starts[-1] + a.shape[0])
        self._map = None

    def state(self) -> dict:
        """What a checkpoint keeps: the file's chunks, after the file is on disk."""
        with open(self.path, "ab") as fh:
            os.fsync(fh.fileno())
        return dict(n_cols=self.n_cols, rows=list(self.rows))

    def _all(self) -> np.ndarray:
        if self._map is None:
            n = self.total_rows
            self._map = (np.memmap(self.path, dtype=np.float64, mode="r",
                                   shape=(n, self.n_cols)) if n else
                         np.zeros((0, self.n_cols)))
        return self._map

    def chunks(self, i0: int, i1: int) -> np.ndarray:
        """Rows of the chunks i0 .. i1 - 1, read-only (a view of the file)."""
        if not 0 <= i0 <= i1 <= len(self.rows):
            raise IndexError(f"chunks {i0}..{i1} of {len(self.rows)}")
        # a plain ndarray view (np.memmap's subclass would leak into every result)
        return np.asarray(self._all()[self._starts[i0]:self._starts[i1]])

    def __getitem__(self, i: int) -> np.ndarray:
        if i < 0:
            i += len(self.rows)
        return self.chunks(i, i + 1)

    def __iter__(self):
        for i in range(len(self.rows)):
            yield self[i]

    def remove(self) -> None:
        """Delete the file (the run's outputs are written)."""
        self._map = None
        try:
            self.path.unlink(missing_ok=True)
        except PermissionError:  # a system that keeps mapped files: left for the user
            pass
