"""The error of a DEM table point's statistics against its recording: what the product
needs of the DEM work-precision study (the study itself, its long run and separate runs, is
``validation/work_precision.py`` in a checkout, ``python -m validation.work_precision``).

- Batch means over one run's recording (:func:`load`, :func:`block_stats`,
  :func:`recording_length_errors`, :func:`fit_sampling_law`): the run's recording is cut
  into chunks of one sampling interval, with every bead-bead contact kept
  (``contacts.npz``), so that any part of it gives exact statistics; the error of a
  recording of length T is the root-mean-square deviation of the statistics of the run's
  consecutive, non-overlapping T-blocks from the whole window's, times sqrt(n / (n - 1))
  for n blocks (the standard error of one T-recording against the stationary value),
  beside the error independent contacts would give (Poisson counts, order statistics).
- The quick study (:func:`run_quick`, :func:`analyse_quick`): one short coupled run of the
  operating point and its recording-length errors, which ``millfmu report --quick`` runs.
- The study shipped with millfmu (:data:`SUMMARY_PATH`): the entry a DEM table's manifest
  quotes (:func:`manifest_entry`, with the expected error of the table's settings,
  :func:`expected_error`), and what ``millfmu report`` shows of it (:func:`plot`,
  :func:`table_rows`, :func:`slopes`, :func:`summary_text`).

Run times are the runs' CPU times on one thread (``cost.json``; the machine is shared, so
wall times would measure the other users too; wall time from ``stats.json`` for runs
without it).
"""

from __future__ import annotations

import csv
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from millfmu.dem.analysis.compare import ZONES, load_run
from millfmu.machine import machine

#: The operating point (``DemScene.with_overrides`` keys): seed 001's 10 m/s, 80 % case in
#: the coupled slice, started as seed 001's coupled protocol starts (beads and liquid at 0.1
#: of the stirrer's rotation; COUPLED_INITIAL_ROTATION of validation/seed001.py).
OPERATING_POINT = dict(tip_speed_m_per_s=10.0, filling=0.8, sector_deg=10.0,
                       gravity_m_per_s2=(0.0, 0.0, 0.0), fluid_mode="coupled",
                       initial_rotation=0.1)
#: Short study (``quick``): the same point, spun up briefly, sampled every ``sample_s``
#: [s]: the method on a real run for the tests and the quick report (about 30 s of CPU). It
#: is not stationary, so its errors say nothing about a table's.
QUICK = dict(spin_up_s=0.02, record_s=0.04, sample_s=0.002,
             lengths_s=(0.002, 0.004, 0.01, 0.02))

#: Tabulated statistics: SE_tn quantiles (the table holds q10, q50, q90; the quartiles
#: beside them), collision frequency, local filling, collision power density.
QUANTILES = {"q10": 0.10, "q25": 0.25, "q50": 0.50, "q75": 0.75, "q90": 0.90}
STATISTICS = tuple(f"se_tn_{q}" for q in QUANTILES) + ("collision_frequency", "filling",
                                                        "collision_power")


class WorkPrecisionError(ValueError):
    """A run folder the study cannot use (missing files, no contacts)."""


def base_scene():
    """The operating point's DEM scene (:class:`millfmu.dem.scene.DemScene`)."""
    from millfmu.dem.scene import load_scene

    return load_scene("disc_slice").with_overrides(**OPERATING_POINT)


def timed_run(fn, out_dir, *a, **kw):
    """Run ``fn`` and write its CPU time (this process, all threads) and wall time [s] to
    ``out_dir/cost.json``: on a shared machine the CPU time is the run's cost."""
    c0, w0 = time.process_time(), time.perf_counter()
    r = fn(*a, **kw)
    (Path(out_dir) / "cost.json").write_text(json.dumps(dict(
        cpu_s=time.process_time() - c0, wall_s=time.perf_counter() - w0,
        threads=kw.get("threads"))))
    return r


def run_quick(out_dir, threads: int | None = 1, progress: bool = False) -> Path:
    """The short run of the quick study (``QUICK``) into ``out_dir``; returns it."""
    from millfmu.dem.run import run_scene

    d = Path(out_dir)
    if not (d / "stats.json").exists():
        sc = base_scene().with_overrides(spin_up_s=QUICK["spin_up_s"],
                                         record_s=QUICK["record_s"],
                                         sample_every_s=QUICK["sample_s"])
        timed_run(run_scene, d, sc, d, progress=progress, threads=threads,
               window_s=QUICK["sample_s"], contacts=True)
    return d


# --- reading runs ----------------------------------------------------------------------

@dataclass
class RunData:
    """One run folder: ``stats.json`` (plain dict), and where written, its per-chunk
    windows (``windows.csv`` at the sampling interval) and contacts (``contacts.npz``)."""

    path: Path
    stats: dict
    chunk_start_s: np.ndarray | None = None
    chunk_s: np.ndarray | None = None
    filling: np.ndarray | None = None  # (chunks, zones) local filling per chunk [-]
    zone_names: list = field(default_factory=list)
    volumes_m3: np.ndarray | None = None
    # per zone: SE_tn and SE_total [J] sorted by chunk, and the offsets of each chunk
    se_tn: list = field(default_factory=list)
    se_total: list = field(default_factory=list)
    offsets: list = field(default_factory=list)

    @property
    def has_contacts(self) -> bool:
        return self.chunk_start_s is not None

    @property
    def cost_s(self) -> float:
        """The run's cost [s]: its CPU time where ``cost.json`` has it (one thread: the
        cost on an idle core), else the wall time of ``stats.json``."""
        f = self.path / "cost.json"
        if f.is_file():
            return float(json.loads(f.read_text())["cpu_s"])
        return float(self.stats.get("counts", {}).get("wall_time_s", float("nan")))

    @property
    def simulated_s(self) -> float:
        return float(self.stats["spin_up_s"] + self.stats["record_s"])

    @property
    def recording_s(self) -> tuple:
        """(start, end) of the recording [s]."""
        return (float(self.stats["spin_up_s"]),
                float(self.stats["spin_up_s"] + self.stats["record_s"]))


def load(path) -> RunData:
    """Read a run folder (:class:`RunData`); contacts and windows where the run wrote them
    (``run_scene(..., window_s=sampling interval, contacts=True)``)."""
    path = Path(path)
    st = load_run(path)
    rd = RunData(path=path, stats=st, zone_names=[z["name"] for z in st["zones"]])
    cf = path / "contacts.npz"
    if not cf.is_file():
        return rd
    with np.load(cf) as c:
        zone, chunk = c["zone"], c["chunk"]
        rd.chunk_start_s, rd.chunk_s = c["chunk_start_s"], c["chunk_s"]
        rd.zone_names = [str(z) for z in c["zone_names"]]
        rd.volumes_m3 = c["zone_volumes_m3"]
        se_tn, se_tot = c["se_tn_j"], c["se_total_j"]
    n_chunks = rd.chunk_start_s.size
    for k in range(len(rd.zone_names)):
        m = zone == k
        o = np.argsort(chunk[m], kind="stable")
        ch = chunk[m][o]
        rd.se_tn.append(se_tn[m][o])
        rd.se_total.append(se_tot[m][o])
        rd.offsets.append(np.searchsorted(ch, np.arange(n_chunks + 1)))
    wf = path / "windows.csv"
    if not wf.is_file():
        raise WorkPrecisionError(f"run {str(path)!r}: contacts.npz without windows.csv")
    with open(wf, newline="") as fh:
        rows = list(csv.DictReader(fh))
    starts = sorted({float(r["t_start_s"]) for r in rows})
    if len(starts) != n_chunks or not np.allclose(starts, rd.chunk_start_s, atol=1e-9):
        raise WorkPrecisionError(f"run {str(path)!r}: windows.csv must have one window per "
                                 f"sampling interval ({n_chunks}), has {len(starts)}")
    idx = {t: i for i, t in enumerate(starts)}
    rd.filling = np.full((n_chunks, len(rd.zone_names)), np.nan)
    for r in rows:
        rd.filling[idx[float(r["t_start_s"])], rd.zone_names.index(r["zone"])] = float(r["filling"])
    return rd


def _chunk_range(rd: RunData, t0: float, t1: float) -> tuple[int, int]:
    ends = rd.chunk_start_s + rd.chunk_s
    tol = 1e-6 * float(rd.chunk_s.min())
    sel = np.flatnonzero((rd.chunk_start_s >= t0 - tol) & (ends <= t1 + tol))
    if sel.size == 0:
        raise WorkPrecisionError(f"run {str(rd.path)!r}: no recording chunk inside "
                                 f"[{t0:g}, {t1:g}] s (recorded {rd.recording_s})")
    return int(sel[0]), int(sel[-1]) + 1


def block_stats(rd: RunData, t0: float | None = None, t1: float | None = None) -> dict:
    """The tabulated statistics of the recording between t0 and t1 [s] (whole chunks;
    default the whole recording): {statistic: {zone: value}}: SE quantiles [J], collision
    frequency [1/(m3 s)], filling [-], collision power per zone volume [W/m3] (per volume,
    as the table holds it, so that sectors of other sizes compare); None
    where a zone had no collision. Without contacts only the whole recording, from
    ``stats.json`` (the quartiles then None: it holds q10, q50, q90)."""
    if not rd.has_contacts:
        if t0 is not None and not math.isclose(t0, rd.recording_s[0], abs_tol=1e-9) or \
                t1 is not None and not math.isclose(t1, rd.recording_s[1], abs_tol=1e-9):
            raise WorkPrecisionError(f"run {str(rd.path)!r}: no contacts.npz, so only its "
                                     f"whole recording {rd.recording_s} can be used")
        out = {s: {} for s in STATISTICS}
        for z in rd.stats["zones"]:
            q = z["se"]["tn"]["quantiles_j"]
            for name in QUANTILES:
                out[f"se_tn_{name}"][z["name"]] = q.get(name)
            out["collision_frequency"][z["name"]] = z["collision_frequency_per_m3_s"]
            out["filling"][z["name"]] = z["filling"]
            out["collision_power"][z["name"]] = z["collision_power_w"] / z["volume_m3"]
        return out
    a, b = _chunk_range(rd, rd.recording_s[0] if t0 is None else t0,
                        rd.recording_s[1] if t1 is None else t1)
    dur = float(rd.chunk_s[a:b].sum())
    qs = list(QUANTILES.values())
    out = {s: {} for s in STATISTICS}
    for k, z in enumerate(rd.zone_names):
        i0, i1 = rd.offsets[k][a], rd.offsets[k][b]
        tn = rd.se_tn[k][i0:i1]
        qv = np.quantile(tn, qs) if tn.size else [None] * len(qs)
        for name, v in zip(QUANTILES, qv):
            out[f"se_tn_{name}"][z] = None if v is None else float(v)
        out["collision_frequency"][z] = tn.size / (float(rd.volumes_m3[k]) * dur)
        out["filling"][z] = float(np.mean(rd.filling[a:b, k]))
        out["collision_power"][z] = float(rd.se_total[k][i0:i1].sum()) / (float(rd.volumes_m3[k]) * dur)
    return out


def relative_difference(a, b):
    """Relative difference (a - b) / b, None where undefined."""
    if a is None or b is None or not b:
        return None
    return (a - b) / abs(b)


# --- the error of a recording ------------------------------------------------------------

def _predicted(tn, tot):
    """Relative errors [-] that independent contacts would give for one block: Poisson
    counts for the collision frequency, compound Poisson for the collision power, and for a
    quantile x_p of N energies half the distance between the quantiles p -+ sqrt(p (1 - p)
    / N) (the order statistics' standard error) over x_p."""
    n = tn.size
    out = {"collision_frequency": 1.0 / math.sqrt(n) if n else None,
           "collision_power": float(math.sqrt(np.sum(tot ** 2)) / np.sum(tot)) if n and np.sum(tot) > 0 else None,
           "filling": None}
    for name, p in QUANTILES.items():
        if n < 10:
            out[f"se_tn_{name}"] = None
            continue
        d = math.sqrt(p * (1.0 - p) / n)
        lo, mid, hi = np.quantile(tn, [max(p - d, 0.0), p, min(p + d, 1.0)])
        out[f"se_tn_{name}"] = float(0.5 * (hi - lo) / mid) if mid > 0 else None
    return out


def recording_length_errors(rd: RunData, window_s: tuple, lengths_s) -> list[dict]:
    """Batch-means error of a recording of each length T inside ``window_s`` of a run with
    contacts, for the lengths that give at least 2 blocks: {"record_s", "blocks", "error":
    {statistic: {zone: relative error}}, "predicted": {...}}. Error: sqrt(n / (n - 1)
    mean_b ((X_b - X) / X)^2) over the n consecutive T-blocks X_b, X the whole window's
    value: the error of one T-recording against the long reference, slow fluctuations and
    drift inside the window included. Predicted: what independent contacts would give
    (:func:`_predicted`, root mean square over the blocks), the sampling statistics' T^-1/2."""
    whole = block_stats(rd, *window_s)
    a, b = _chunk_range(rd, *window_s)
    chunk = float(np.median(rd.chunk_s[a:b]))
    rows = []
    for t in lengths_s:
        k = max(1, int(round(t / chunk)))
        n = (b - a) // k
        if n < 2:
            continue
        spans = [(a + i * k, a + i * k + k) for i in range(n)]
        blocks = [block_stats(rd, float(rd.chunk_start_s[c0]),
                              float(rd.chunk_start_s[c1 - 1] + rd.chunk_s[c1 - 1]))
                  for c0, c1 in spans]
        err, pred = {}, {}
        for s in STATISTICS:
            err[s] = {}
            for z in rd.zone_names:
                d = [relative_difference(bl[s][z], whole[s][z]) for bl in blocks]
                d = [x for x in d if x is not None]
                err[s][z] = math.sqrt(n / (n - 1) * float(np.mean(np.square(d)))) \
                    if len(d) == n else None
        per_zone = {}
        for kz, z in enumerate(rd.zone_names):
            ps = []
            for c0, c1 in spans:
                i0, i1 = rd.offsets[kz][c0], rd.offsets[kz][c1]
                ps.append(_predicted(rd.se_tn[kz][i0:i1], rd.se_total[kz][i0:i1]))
            per_zone[z] = ps
        for s in STATISTICS:
            pred[s] = {}
            for z in rd.zone_names:
                v = [x[s] for x in per_zone[z]]
                pred[s][z] = None if any(x is None for x in v) else \
                    float(math.sqrt(np.mean(np.square(v))))
        rows.append(dict(record_s=k * chunk, blocks=n, error=err, predicted=pred))
    return rows


def fit_sampling_law(rows: list[dict], t_min_s: float = 0.0) -> dict:
    """Per statistic and zone, over the rows with T >= t_min_s and at least 3 blocks: the
    measured power law error = at_1s T^slope (least squares in log-log, each row weighted
    by the square root of its degrees of freedom; T in s), and the
    slope of the independent-contacts prediction (-1/2 by construction where defined)."""
    use = [r for r in rows if r["record_s"] >= t_min_s - 1e-12 and r["blocks"] >= 3]
    out = {}
    for s in STATISTICS:
        out[s] = {}
        for z in (use[0]["error"][s] if use else {}):
            pts = [(r["record_s"], r["error"][s][z], r["blocks"]) for r in use
                   if r["error"][s][z] is not None and r["error"][s][z] > 0]
            if len(pts) < 2:
                out[s][z] = None
                continue
            t, e = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
            # log of a batch-means error from n blocks scatters by about 1 / sqrt(2 (n - 1))
            slope, icpt = np.polyfit(t, e, 1, w=np.sqrt([p[2] - 1.0 for p in pts]))
            f = dict(slope=float(slope), at_1s=float(np.exp(icpt)))
            pp = [(r["record_s"], r.get("predicted", {}).get(s, {}).get(z)) for r in use]
            pp = [x for x in pp if x[1]]
            if len(pp) >= 2:
                f["predicted_slope"] = float(np.polyfit(np.log([x[0] for x in pp]),
                                                        np.log([x[1] for x in pp]), 1)[0])
                f["inflation"] = float(np.exp(np.mean([math.log(r["error"][s][z] / x[1])
                                                       for r, x in zip(use, pp)
                                                       if r["error"][s][z]])))
            out[s][z] = f
    return out


#: Zones whose statistics the table-build choice holds to its target: V2-V4, the densely
#: filled zones that carry most collisions; V1 (half empty at 80 % filling, a tenth of the
#: collisions) is stated beside it.
TARGET_ZONES = ("V2", "V3", "V4")


def sampling_error(law, s, z, t_s, scale=1.0):
    """Error of statistic s in zone z for a recording of t_s [s] from the measured law
    (:func:`fit_sampling_law`; beyond the longest recording studied an extrapolation)."""
    f = law.get(s, {}).get(z)
    return None if f is None else scale * f["at_1s"] * t_s ** f["slope"]


def spin_up_bias(spin_row, st, z):
    """Spin-up bias [-]: the measured error less the two recordings' sampling errors."""
    e = spin_row["error"][st][z]
    n = spin_row["noise_2sigma"][st][z]
    if e is None or n is None:
        return None
    return math.sqrt(max(e * e - (0.5 * n) ** 2, 0.0))


def _resolution(res, st, z):
    """Resolution errors of the reference setting that exceed their 2-sigma noise: the
    rows of the finer variants (sector, DEM step, coupling interval) [-]."""
    out = []
    for r in res["variants"]:
        if r["finer"]:
            e, n = r["error"][st][z], r["noise_2sigma"][st][z]
            if e is not None and n is not None and abs(e) > n:
                out.append(abs(e))
    return out


def expected_error(res, spin_up_s, record_s, resolution: bool = True) -> dict:
    """Expected relative error [-] of each statistic and zone for a table point built
    with ``spin_up_s`` (one of the studied spin-ups) and ``record_s``: the root sum of
    squares of the recording-length error a T^b, the spin-up bias (measured error less the
    sampling noise) and, with ``resolution``, the reference setting's resolution
    differences (sector, DEM step, coupling interval) that exceed their noise."""
    row = min(res["spin_up"], key=lambda r: abs(r["spin_up_s"] - spin_up_s))
    if abs(row["spin_up_s"] - spin_up_s) > 1e-9:
        raise WorkPrecisionError(f"spin-up {spin_up_s} s: not studied "
                                 f"({[r['spin_up_s'] for r in res['spin_up']]})")
    out = {}
    for st in STATISTICS:
        out[st] = {}
        for z in res["zones"]:
            sig = sampling_error(res["law"], st, z, record_s)
            b = spin_up_bias(row, st, z)
            if sig is None or b is None:
                out[st][z] = None
                continue
            extra = sum(x * x for x in _resolution(res, st, z)) if resolution else 0.0
            out[st][z] = math.sqrt(sig ** 2 + b ** 2 + extra)
    return out


#: Error targets [-] the study's table-build choice tries in turn (``choose`` of
#: validation/work_precision.py; :func:`summary_text` names them).
TARGETS = (0.05, 0.1, 0.15, 0.2, 0.3)
#: Having found the cheapest setting, the choice lengthens its recording while the run
#: costs at most this much more: the spin-up dominates a point's cost, so a longer recording
#: is cheap and lowers the error further.
LENGTHEN_WITHIN = 1.25


# --- output ----------------------------------------------------------------------------

#: Columns of the printed table: label -> statistics whose largest |error| it shows.
COLUMNS = {"median SE_tn": ("se_tn_q50",),
           "SE_tn q10, q25, q75, q90": ("se_tn_q10", "se_tn_q25", "se_tn_q75", "se_tn_q90"),
           "collision frequency": ("collision_frequency",),
           "local filling": ("filling",),
           "collision power": ("collision_power",)}


def worst_abs(d, stats, zones):
    vals = [abs(d[s][z]) for s in stats for z in zones if d.get(s, {}).get(z) is not None]
    return max(vals) if vals else None


def _pct(v):
    return "n/a" if v is None else f"{100 * v:.2g} %" if v < 0.1 else f"{100 * v:.0f} %"


def _cell(row, stats, zones):
    """The largest |relative error| over ``stats`` and ``zones``, with the 2-sigma noise of
    that statistic and zone in brackets where the row has noise."""
    cand = [(abs(row["error"][s][z]), s, z) for s in stats for z in zones
            if row["error"].get(s, {}).get(z) is not None]
    if not cand:
        return "n/a"
    e, s, z = max(cand)
    out = _pct(e)
    if "noise_2sigma" in row:
        out += f" ({_pct(row['noise_2sigma'][s][z])})"
    return out


def table_rows(res, zones=TARGET_ZONES) -> list[list[str]]:
    """Rows [setting, run time, one cell per :data:`COLUMNS`]: the largest relative error
    over ``zones`` and the statistics of the column; spin-up and variant rows add the 2-sigma
    sampling noise of that comparison (statistic and zone) in brackets."""
    rows = []
    for r in res["recording"]:
        rows.append([f"recording {r['record_s']:g} s ({r['blocks']} blocks)",
                     f"{r['run_s']:.0f}"] + [_cell(r, c, zones) for c in COLUMNS.values()])
    for r in res["spin_up"]:
        rows.append([f"spin-up {r['spin_up_s']:g} s, recording {r['record_s']:g} s",
                     f"{r['run_s']:.0f}"] + [_cell(r, c, zones) for c in COLUMNS.values()])
    for r in res["variants"]:
        label = (f"reference against {r['what']}" if r["finer"] else r["what"])
        rows.append([label, f"{r['run_s']:.0f} ({r['reference_run_s']:.0f})"] +
                    [_cell(r, c, zones) for c in COLUMNS.values()])
    return rows


def slopes(res, zones=ZONES) -> dict:
    """Per statistic, the median over ``zones`` (and the range) of the measured slope of
    log(error) against log(T); the median slope of what independent contacts would give and
    the median ratio of the measured error to it (where defined)."""
    out = {}
    for s in STATISTICS:
        fits = [res["law"][s][z] for z in zones if res["law"][s].get(z)]
        if not fits:
            continue
        v = [f["slope"] for f in fits]
        out[s] = dict(median=float(np.median(v)), min=float(min(v)), max=float(max(v)))
        for k in ("predicted_slope", "inflation"):
            w = [f[k] for f in fits if f.get(k) is not None]
            if w:
                out[s][k] = float(np.median(w))
    return out


def summary_text(res) -> str:
    sl = slopes(res)
    txt = ("Error against recording length falls as T^" +
           ", ".join(f"{v['median']:.2f} ({k})" for k, v in sl.items()) +
           f" (median over zones, T >= {res['law_t_min_s']:g} s; sampling statistics: -0.5).")
    if "choice" not in res:  # the quick study: no choice
        return txt
    c = res["choice"]
    if c:
        v1 = worst_abs(c["expected_error"], STATISTICS, ("V1",))
        txt += (f" Choice for table builds at the reference resolution: spin-up "
                f"{c['spin_up_s']:g} s, recording {c['record_s']:g} s ({c['run_s']:.0f} s per "
                f"point on one core of this machine): recording and spin-up add at most "
                f"{_pct(c['worst'])} in {', '.join(c['target_zones'])} (target "
                f"{_pct(c['target'])}, the smallest of {', '.join(_pct(t) for t in TARGETS)} "
                f"met; cheapest: recording {c['cheapest']['record_s']:g} s, lengthened while "
                f"the run costs at most {LENGTHEN_WITHIN:g} times as much); with the "
                f"resolution differences beyond their noise at most {_pct(c['worst_total'])} "
                f"(V1: {_pct(v1)})"
                + ("; the recording-length law extrapolated beyond the longest recording "
                   "studied" if c.get("extrapolated") else "") + ".")
    else:
        txt += f" No studied setting meets {_pct(TARGETS[-1])} in {', '.join(TARGET_ZONES)}."
    return txt


#: Plain names of the statistics the drift panel shows.
_STAT_NAMES = {"filling": "local filling", "collision_frequency": "collision frequency",
               "se_tn_q50": "median SE_tn"}


#: The long run's course (the study's ``drift``, drawn by :func:`plot`): these statistics
#: per block, relative to the reference window.
DRIFT_STATS = ("filling", "collision_frequency", "se_tn_q50")
def plot(res, path, title=None) -> None:
    """Error of the median SE_tn and of the collision frequency against recording length per
    zone, with what independent contacts would give (dashed) and T^-1/2; the largest error
    against run time of every row; and the long run's drift in blocks."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from millfmu.plotstyle import label_points, plain_log_ticks

    wp = bool(res.get("spin_up") or res.get("variants"))
    dr = res.get("drift")
    n = 2 + wp + bool(dr)
    # At most two panels a row: four in one row are too small to read in a report.
    rows_, cols = (n + 1) // 2, min(n, 2)
    fig, ax = plt.subplots(rows_, cols, figsize=(7.6 * cols, 4.9 * rows_), squeeze=False)
    ax = list(ax.ravel())
    for extra in ax[n:]:
        extra.set_visible(False)
    ax = ax[:n]
    rows = res["recording"]
    t = np.array([r["record_s"] for r in rows])
    for a, s, label in ((ax[0], "se_tn_q50", "median SE_tn"),
                        (ax[1], "collision_frequency", "collision frequency")):
        measured, independent = [], []
        for z, col in zip(res["zones"], ("C0", "C1", "C2", "C3")):
            e = [r["error"][s][z] for r in rows]
            pr = [r.get("predicted", {}).get(s, {}).get(z) for r in rows]
            if all(v is not None for v in e):
                measured += a.loglog(t, e, "o-", color=col, label=f"{z}: measured")
            if all(v is not None for v in pr):
                independent += a.loglog(t, pr, "--", color=col, lw=1, label=f"{z}: independent contacts")
        law = []
        if t.size:
            law = a.loglog(t, 0.5 * min(r["error"][s][z] or 1 for r in rows[:1] for z in res["zones"])
                           * np.sqrt(t[0] / t), "k:", lw=1.5, label="slope of T^-1/2")
        a.set(xlabel="recording length T [s]", ylabel="relative error (batch means)",
              title=f"{label}: error against recording length")
        # measured first, then what independent contacts would give: the zones in the same order
        a.legend(handles=measured + independent + law, fontsize=7, loc="upper left",
                 bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)  # beside the curves
    if title:
        fig.suptitle(title)
    labels = []
    if wp:
        a = ax[2]
        kinds = (("recording", "o-", "C0", "recording length T (one run)"),
                 ("spin_up", "s-", "C1", "spin-up time"),
                 ("variants", "D", "C3", "resolution: sector, DEM step, coupling interval"))
        for kind, style, col, name in kinds:
            pts = []
            for r in res.get(kind, []):
                e = worst_abs(r["error"], STATISTICS, TARGET_ZONES)
                if e is None:
                    continue
                text = {"recording": f"T {r.get('record_s', 0):g} s",
                        "spin_up": f"{r.get('spin_up_s', 0):g} s",
                        "variants": r.get("what", r.get("name", "")).split(" (")[0]}[kind]
                pts.append((r["run_s"], e, text))
            if not pts:
                continue
            pts.sort()
            a.loglog([p[0] for p in pts], [p[1] for p in pts], style, color=col, lw=0.8, ms=5, label=name)
            # the recording lengths crowd at nearly one run time: their ends only (the table
            # has every row); elsewhere every point, the series' ends first
            inner = [] if kind == "recording" else list(range(1, len(pts) - 1))
            labels.append((a, [pts[i] for i in dict.fromkeys([0, len(pts) - 1] + inner)]))
        a.set(xlabel="run time [s] (CPU, 1 thread)",
              ylabel=f"largest relative error, {', '.join(TARGET_ZONES)}",
              title="work-precision: error against run time")
        a.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    if dr:
        a = ax[-1]
        for st, ls in zip(DRIFT_STATS, ("-", "--", ":")):
            for z, col in zip(res["zones"], ("C0", "C1", "C2", "C3")):
                a.plot(dr["t_s"], [np.nan if v is None else 100 * v for v in dr[st][z]], ls,
                       color=col, label=f"{_STAT_NAMES.get(st, st)} {z}")
        w = res["reference_window_s"]
        a.axvspan(w[0], w[1], color="0.9")
        a.set(xlabel="t [s] (block centre)", ylabel="relative to the reference window [%]",
              title=f"the long run in blocks of {dr['block_s']:g} s (grey: reference)")
        a.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    for a in ax:
        a.grid(alpha=0.3, which="both")
    plain_log_ticks(fig)
    fig.tight_layout(rect=(0, 0, 1, 0.94) if title else None)
    for a, pts in labels:  # placed in pixels: after the layout
        label_points(a, [p[:2] for p in pts], [p[2] for p in pts], fontsize=7)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def analyse_quick(run_dir) -> dict:
    """The recording-length part of the study on one short run with contacts
    (:func:`run_quick`): rows over its whole recording and the fitted law (all lengths
    with at least 3 blocks)."""
    if not (Path(run_dir) / "stats.json").is_file():
        raise WorkPrecisionError(f"{str(run_dir)!r}: no finished short run; make it with "
                                 f"run_quick (from a checkout: 'python -m "
                                 f"validation.work_precision run --quick --out DIR')")
    rd = load(run_dir)
    if not rd.has_contacts:
        raise WorkPrecisionError(f"{run_dir}: the run needs contacts.npz")
    rate = rd.cost_s / rd.simulated_s
    rows = recording_length_errors(rd, rd.recording_s, QUICK["lengths_s"])
    for r in rows:
        r["run_s"] = rate * (rd.recording_s[0] + r["record_s"])
    return dict(operating_point=dict(OPERATING_POINT, scene="disc_slice"), quick=True,
                long_run=dict(recorded_s=list(rd.recording_s), run_s=rd.cost_s,
                              run_per_simulated_s=rate, beads=rd.stats["beads"]),
                recording_window_s=list(rd.recording_s), law_t_min_s=0.0, recording=rows,
                law=fit_sampling_law(rows, 0.0), spin_up=[], variants=[],
                zones=rd.zone_names, statistics=list(STATISTICS), machine=machine())


#: The study's summary and data shipped with millfmu (``python -m validation.work_precision table --export``),
#: which table manifests quote and ``millfmu report`` shows.
SUMMARY_PATH = Path(__file__).resolve().parents[2] / "data" / "dem_work_precision.json"
#: The command that makes the study, from a checkout's root (the study is not installed
#: with millfmu).
RUN_COMMAND = ("python -m validation.work_precision run --out DIR && "
               "python -m validation.work_precision table --out DIR")

def read_study(study_dir) -> dict:
    """A full study made from a checkout: ``DIR/work_precision.json``, which ``python -m
    validation.work_precision table --out DIR`` writes (plain JSON data, the study's rows,
    law and choice), for ``millfmu report --dem-runs DIR``."""
    p = Path(study_dir) / "work_precision.json"
    if not p.is_file():
        raise WorkPrecisionError(f"{str(study_dir)!r}: no work_precision.json; make the study "
                                 f"from a checkout with 'python -m validation.work_precision "
                                 f"run --out DIR', then '... table --out DIR'")
    try:
        res = json.loads(p.read_text())
    except (OSError, ValueError) as e:
        raise WorkPrecisionError(f"{p}: not readable JSON ({e})") from None
    if not isinstance(res, dict) or res.get("quick") or not res.get("spin_up"):
        raise WorkPrecisionError(f"{p}: not a full study's result (the quick study's has no "
                                 f"spin-up rows)")
    return res


def manifest_entry(dem_resolution: dict | None = None, path=None) -> dict | None:
    """The work-precision entry of a DEM table's manifest: the study's choice and its
    expected error and, for a table built with ``dem_resolution`` (the ``dem`` part of the
    manifest's resolution: spin_up_s, record_s, dt_s, sector_deg, fluid), the expected error
    of its settings (:func:`expected_error` at the longest studied spin-up not above the
    table's; none for a fluid other than the coupled one). None when no study is shipped
    (``path``: default :data:`SUMMARY_PATH`)."""
    p = Path(path) if path is not None else SUMMARY_PATH
    if not p.is_file():
        return None
    data = json.loads(p.read_text())
    s, res = data["summary"], data["study"]
    out = {k: s[k] for k in ("operating_point", "command", "measured_on", "choice", "note")}
    fluid = (dem_resolution or {}).get("fluid")
    if fluid not in (None, "coupled"):
        out["this_table"] = dict(expected_error=None, note=(
            f"this table's fluid is {fluid!r}; the study is of the coupled slice and does not "
            f"cover it"))
        return out
    if dem_resolution and dem_resolution.get("record_s") and \
            dem_resolution.get("spin_up_s") is not None:
        t, su = float(dem_resolution["record_s"]), float(dem_resolution["spin_up_s"])
        studied = [r["spin_up_s"] for r in res["spin_up"] if r["spin_up_s"] <= su + 1e-9]
        this = dict(record_s=t, spin_up_s=su, matches_choice=bool(s.get("choice")) and all(
            math.isclose(float(dem_resolution.get(k, math.nan)), s["choice"][k], rel_tol=1e-9)
            for k in ("spin_up_s", "record_s", "dt_s", "sector_deg")))
        if studied:
            this["spin_up_used_s"] = max(studied)
            this["expected_error"] = expected_error(res, max(studied), t)
        else:
            this["expected_error"] = None
            this["note"] = (f"spin-up {su} s is below the shortest studied "
                            f"({min(r['spin_up_s'] for r in res['spin_up'])} s)")
        out["this_table"] = this
    return out
