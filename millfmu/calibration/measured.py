"""Measured batch data for a calibration: CSV text or files read and checked, and the error
every part of the calibration raises.

Columns: ``t_s`` [s] and either some of ``x10_m``/``x50_m``/``x90_m`` [m], or ``x_m`` [m]
and ``Q3`` [-], or ``disrupted_fraction`` [-]; rows at t_s = 0 describe the feed (the
scene's) and are not fitted.
"""

from __future__ import annotations

import csv
import hashlib
import io
import math
from dataclasses import dataclass, replace
from pathlib import Path

from ..scene import T_END_MAX_S
from ..text_files import NotUtf8, utf8_text

#: Measured quantities, by column: residual kind and unit.
SIZE_COLUMNS = ("x10_m", "x50_m", "x90_m")
#: a size later in a test that exceeds an earlier one of the same column by more than this
#: share is noted: breakage only makes particles finer (the scatter of a laser-diffraction
#: x50 between repeats is a few per cent)
RISE_NOTED = 0.10
#: Largest particle size [m] a bead mill's data may give: beyond it a value is taken to be
#: in another unit (a size of 25 meant as micrometres), since mills grind feeds below 1 cm.
MAX_SIZE_M = 0.01

#: How the Python API names what an error is about, by argument of
#: :func:`millfmu.calibration.calibrate` ("{}": what the argument gave; for "start", the
#: constant's key). Another interface passes its own to :meth:`CalibrationError.worded`.
API_WORDS = {"fit": "fit {}", "data": "data {}", "error_model": "error_model {}", "start": "start={{{!r}: VALUE}}"}


class CalibrationError(ValueError):
    """Data or a fit that cannot give the constants asked for: says which item, why and what
    to do instead. Nothing is written.

    The message speaks the Python API's terms: the argument of
    :func:`millfmu.calibration.calibrate` it is about (``argument``: "fit", "data" or
    "error_model"; None where the data's content or the scene is at fault) with what that
    argument gave (``subject``: a constant's scene key, a file), then ``reason``; where a
    start value would help, ``start_key`` names the constant. The command line words the
    same refusal with its options (:meth:`worded`)."""

    def __init__(self, reason: str, argument: str | None = None, subject: str = "", start_key: str | None = None):
        self.reason, self.argument, self.subject, self.start_key = reason, argument, subject, start_key
        super().__init__(self.worded())

    def worded(self, words: dict | None = None) -> str:
        """The message with the arguments named by ``words`` (default :data:`API_WORDS`)."""
        words = API_WORDS if words is None else words
        text = (words[self.argument].format(self.subject) + ": " if self.argument else "") + self.reason
        return text + (f" (or {words['start'].format(self.start_key)})" if self.start_key else "")


@dataclass(frozen=True)
class Data:
    """Measured batch data: ``kind`` 'sizes' (columns among x10_m, x50_m, x90_m), 'q3'
    (x_m [m] and Q3 [-] per time) or 'disrupted' (disrupted_fraction [-]); ``rows`` are
    (t_s, column, x_m or None, value). ``source``: the file (or 'data') and ``sha256`` its
    bytes; ``feed_rows`` counts rows at t = 0, which describe the feed and are not fitted."""

    kind: str
    rows: tuple
    source: str = "data"
    sha256: str = ""
    feed_rows: int = 0
    #: What the data's reader noticed that does not stop a fit (duplicate measurements).
    notes: tuple = ()
    #: The rows at t = 0 (the feed) as (0.0, column, x_m or None, value), checked as the
    #: others: what a fit compares with the scene's feed, not fits.
    feed: tuple = ()

    @property
    def times_s(self) -> list:
        return sorted({r[0] for r in self.rows})

    @property
    def n(self) -> int:
        return len(self.rows)


def _num(text, where: str, col: str) -> float:
    try:
        v = float(text)
    except (TypeError, ValueError):
        raise CalibrationError(f"{where}: column {col} = {text!r}: not a number") from None
    if not math.isfinite(v):
        raise CalibrationError(f"{where}: column {col} = {text!r}: must be finite")
    return v


def _check_metres(x: float, where: str, col: str):
    if x > MAX_SIZE_M:
        raise CalibrationError(f"{where}: column {col} = {x:g} m: larger than {MAX_SIZE_M:g} m, which no bead mill "
                               f"grinds; the column is in metres (if {x:g} is in micrometres, write {x * 1e-6:g})")


def _header(reader: list, source: str) -> tuple[list, set, str]:
    """The header's columns, the measured ones and the data's kind; refused by name."""
    header = [h.strip() for h in reader[0]]
    allowed = ("t_s",) + SIZE_COLUMNS + ("x_m", "Q3", "disrupted_fraction")
    unknown = [h for h in header if h not in allowed]
    if unknown or "t_s" not in header or len(set(header)) != len(header):
        # a spreadsheet's export in a comma-decimal locale separates by ';' (or tabs)
        sep = next((c for c in (";", "\t") if len(header) == 1 and c in header[0]), None)
        raise CalibrationError(f"{source}: header {','.join(header)!r}: needs t_s and either some of x10_m, x50_m, "
                               "x90_m, or x_m and Q3, or disrupted_fraction (each once)"
                               + (f"; unknown column(s) {unknown}" if unknown else "")
                               + (f"; the columns are separated by {sep!r}: separate them by commas, with '.' as "
                                  "the decimal point" if sep else ""))
    cols = set(header) - {"t_s"}
    kinds = {"sizes": cols <= set(SIZE_COLUMNS) and bool(cols), "q3": cols == {"x_m", "Q3"},
             "disrupted": cols == {"disrupted_fraction"}}
    kind = next((k for k, ok in kinds.items() if ok), None)
    if kind is None:
        raise CalibrationError(f"{source}: columns {sorted(cols)}: give either some of x10_m, x50_m, x90_m, or x_m "
                               "with Q3, or disrupted_fraction, not a mix")
    return header, cols, kind


def _row_values(cell: dict, kind: str, cols: set, where: str, t: float) -> list:
    """The measured values of one row after t = 0 as (t_s, column, x_m or None, value)."""
    if kind == "q3":
        x, q = _num(cell["x_m"], where, "x_m"), _num(cell["Q3"], where, "Q3")
        if x <= 0.0:
            raise CalibrationError(f"{where}: column x_m = {x:g}: must be > 0 m")
        _check_metres(x, where, "x_m")
        if not 0.0 <= q <= 1.0:
            raise CalibrationError(f"{where}: column Q3 = {q:g}: must lie in [0, 1]")
        return [(t, "Q3", x, q)]
    rows = []
    for col in sorted(cols):
        if cell[col] == "":
            continue
        v = _num(cell[col], where, col)
        if kind == "disrupted" and not 0.0 <= v <= 1.0:
            raise CalibrationError(f"{where}: column {col} = {v:g}: must lie in [0, 1]")
        if kind == "sizes" and v <= 0.0:
            raise CalibrationError(f"{where}: column {col} = {v:g}: must be > 0 m")
        if kind == "sizes":
            _check_metres(v, where, col)
        rows.append((t, col, None, v))
    if kind == "sizes":
        given = [(c, float(cell[c])) for c in SIZE_COLUMNS if c in cell and cell[c] != ""]
        for (c1, v1), (c2, v2) in zip(given, given[1:]):
            if v1 > v2:
                raise CalibrationError(f"{where}: {c1} = {v1:g} m is larger than {c2} = {v2:g} m: a size "
                                       "distribution's x10 <= x50 <= x90; check the columns' order in the header")
    return rows


def parse_data(text: str, source: str = "data") -> Data:
    """Data from CSV text: a header row, then one row per time (per time and size for Q3).

    Columns: ``t_s`` [s] and either some of ``x10_m``/``x50_m``/``x90_m`` [m], or ``x_m`` [m]
    and ``Q3`` [-], or ``disrupted_fraction`` [-]. Lines starting with '#' are comments; an
    empty cell is a value not measured. Rows at t_s = 0 are the feed (the scene's) and are
    not fitted. Raises :class:`CalibrationError` naming the line and column."""
    text = text.removeprefix("\ufeff")  # a byte-order mark, as spreadsheet programs write UTF-8
    lines = [(i + 1, ln) for i, ln in enumerate(text.splitlines()) if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise CalibrationError(f"{source}: no header and no data rows")
    reader = list(csv.reader(io.StringIO("\n".join(ln for _, ln in lines))))
    header, cols, kind = _header(reader, source)
    if len(lines) == 1:
        raise CalibrationError(f"{source}: a header and no data rows (one row per time: t_s and the "
                               f"measured values)")
    rows, feed, feed_values, q3_lines, empty = [], 0, [], [], []
    for (lineno, _), rec in zip(lines[1:], reader[1:]):
        where = f"{source} line {lineno}"
        if len(rec) != len(header):
            raise CalibrationError(f"{where}: {len(rec)} cells, the header has {len(header)}")
        cell = dict(zip(header, (c.strip() for c in rec)))
        t = _num(cell["t_s"], where, "t_s")
        if t < 0.0:
            raise CalibrationError(f"{where}: column t_s = {t:g}: must be >= 0 s")
        # a time no run reaches (the longest a scene may make: run.t_end_s)
        if t > T_END_MAX_S:
            raise CalibrationError(f"{where}: column t_s = {t:g}: must be <= {T_END_MAX_S:g} s (about "
                                   f"{T_END_MAX_S / 3.15576e7:.1f} years, the longest run a scene may make); "
                                   "t_s is in seconds")
        got = _row_values(cell, kind, cols, where, t)
        if not got:
            empty.append(f"{where}: t_s = {t:g} has no measured value (an empty cell is a value not "
                         "measured); the row is left out")
        if kind == "q3":
            q3_lines += [(lineno, r) for r in got]
        if t == 0.0:
            feed += 1
            feed_values += got
            continue
        rows += got
    if not rows:
        raise CalibrationError(f"{source}: no measured values after t_s = 0")
    _check_q3_rises(q3_lines, source)
    seen, dup = set(), []
    for t, col, x, _ in rows:
        key = (t, col, x)
        if key in seen and key not in dup:
            dup.append(key)
        seen.add(key)
    notes = tuple(empty) + tuple(
        f"{source}: {col}{'' if x is None else f' at x_m = {x:g}'} at t_s = {t:g} is given more than once; "
        "each is fitted as an independent measurement (average repeats first if they are one sample's)"
        for t, col, x in dup) + _rises(kind, rows, source)
    return Data(kind, tuple(rows), source, hashlib.sha256(text.encode()).hexdigest(), feed, notes,
                tuple(feed_values))


def _rises(kind: str, rows: list, source: str) -> tuple:
    """Notes on size columns that rise with time by more than :data:`RISE_NOTED` over their
    smallest earlier value: grinding makes particles only finer, so the model cannot follow
    such a rise (agglomeration, samples mixed up, a value in another unit)."""
    if kind != "sizes":
        return ()
    out = []
    for col in SIZE_COLUMNS:
        series = sorted((t, v) for t, c, _, v in rows if c == col)
        low = None
        for t, v in series:
            if low is not None and v > low[1] * (1.0 + RISE_NOTED):
                out.append(f"{source}: {col} rises from {low[1]:.4g} m at t_s = {low[0]:g} to {v:.4g} m at "
                           f"t_s = {t:g}: breakage makes particles only finer, so no constant of the model "
                           "follows this rise (agglomeration? samples mixed up? a value in another unit?)")
                break
            if low is None or v < low[1]:
                low = (t, v)
    return tuple(out)


def _check_q3_rises(q3_lines: list, source: str):
    """Refuse a Q3 that falls with size at one time: a cumulative distribution does not.
    ``q3_lines``: (line number, (t_s, 'Q3', x_m, Q3)) in the file's order."""
    by_t = {}
    for lineno, (t, _c, x, q) in q3_lines:
        by_t.setdefault(t, []).append((x, q, lineno))
    for t, pts in by_t.items():
        pts.sort()
        for (x1, q1, l1), (x2, q2, l2) in zip(pts, pts[1:]):
            if q2 < q1:
                raise CalibrationError(f"{source} line {l2}: Q3 = {q2:g} at x_m = {x2:g} m is below Q3 = {q1:g} at "
                                       f"x_m = {x1:g} m (line {l1}), both at t_s = {t:g}: Q3 is a cumulative "
                                       "distribution and must not fall with size")


def read_data(path) -> Data:
    """:func:`parse_data` of a CSV file (UTF-8); the error names the file."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as e:
        hint = ""
        if not p.exists() and str(p) == p.name:  # a bare name: perhaps a shipped example misspelt
            from ..scene import closest, example_files

            near = closest(p.name, [n for n in example_files() if n.endswith(".csv")])
            hint = f"; did you mean {near}, a shipped example?" if near else ""
        raise CalibrationError(f"cannot be read ({e.strerror or e}{hint})", "data", str(p)) from None
    try:
        text = utf8_text(raw)
    except NotUtf8 as e:
        raise CalibrationError(f"not UTF-8 text (byte {e.start})", "data", str(p)) from None
    d = parse_data(text, str(p))
    return replace(d, sha256=hashlib.sha256(raw).hexdigest())
