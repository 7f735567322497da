"""DEM work-precision: the error of the tabulated statistics against run time.

At one operating point of the coupled disc slice (10 m/s, 80 % filling, 10 degree sector,
no gravity; seed 001's protocol of :mod:`millfmu.dem.studies.seed001`) this measures how far each
statistic a stress-energy table holds (per zone: quantiles of SE_tn, collision frequency,
local filling, collision power) lies from a long reference run, as a function of

- the recording length T: from one long run whose recording is cut into chunks of one
  sampling interval, with every bead-bead contact kept (``contacts.npz``) so that any part
  of the recording gives exact statistics. The error of a recording of length T is the
  root-mean-square deviation of the statistics of the run's consecutive, non-overlapping
  T-blocks (inside the reference window) from the whole window's, times sqrt(n / (n - 1))
  for n blocks (batch means: the standard error of one T-recording against the stationary
  value). Sampling statistics predict that it falls as T^-1/2 once T exceeds the flow's
  correlation time; beside it, the error independent contacts would give (Poisson counts,
  order statistics), and a power law error = a T^b fitted to the measured errors;
- the spin-up s: the window [s, s + RECORD_S] of the same long run against the reference
  window (the run is deterministic, so this is the run a spin-up of s would have made);
- the sector angle, the DEM time step and the coupling interval: separate runs with one
  setting changed, each against the long run's window with the same spin-up and recording
  (the reference setting). Their trajectories separate within milliseconds, so each
  difference also holds the sampling error of two independent recordings, stated beside it
  as the 2-sigma noise from the recording-length law.

Run times are the runs' CPU times on one thread (``cost.json``, written by the study's
runs; the machine is shared, so wall times would measure the other users too; wall time
from ``stats.json`` for runs without it); a recording-length or spin-up row gives the time
a run of that spin-up and recording would take at the long run's cost per simulated
second.

``millfmu dem work-precision run --out DIR`` makes the runs (skipping those done),
``millfmu dem work-precision table --out DIR`` prints the table and writes
``work_precision.json``, ``work_precision.csv`` and ``work_precision.png``; ``--export
FILE`` also writes the summary a table manifest quotes (:func:`manifest_entry`).
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
from millfmu.dem.studies.seed001 import COUPLED_INITIAL_ROTATION, COUPLED_SPIN_UP_S, RECORD_S
from millfmu.machine import machine

#: The operating point (``DemScene.with_overrides`` keys): seed 001's 10 m/s, 80 % case in
#: the coupled slice with the seed001 protocol's start.
OPERATING_POINT = dict(tip_speed_m_s=10.0, filling=0.8, sector_deg=10.0,
                       gravity_m_s2=(0.0, 0.0, 0.0), fluid_mode="coupled",
                       initial_rotation=COUPLED_INITIAL_ROTATION)
#: Sampling interval [s] = chunk of the contacts file = window of windows.csv.
SAMPLE_S = 0.01
#: The long run: recording from LONG_START_S (the shortest spin-up studied) to LONG_END_S [s].
LONG_START_S = 0.2
LONG_END_S = 3.0
#: Reference window [s] of the long run, after every spin-up window studied. A first run to
#: 1.9 s showed the zones still changing after the protocol's 1.0 s (V1 filling 0.43 ->
#: 0.37 and V4 0.53 -> 0.45 by 1.6 s, then level), hence the later reference.
REFERENCE_WINDOW_S = (1.8, 3.0)
#: Recording lengths studied [s] (blocks inside the reference window).
RECORD_LENGTHS_S = (0.01, 0.02, 0.03, 0.05, 0.1, 0.2, 0.3, 0.4)
#: Spin-ups studied [s] (windows [s, s + RECORD_S] of the long run).
SPIN_UPS_S = (0.2, 0.35, 0.5, 0.565, 0.75, 1.0, 1.25, 1.5)
#: Separate runs: name -> (overrides of the long run's scene, coupling steps or None,
#: spin-up [s], what changes). dt variants keep the coupling interval (5e-5 s); the sector
#: run is 3 times the beads, so it spins up for 25 stirrer revolutions (0.565 s) as the
#: sector check of docs/validation-seed001.md did, and is compared with the 10 degree window of the same times.
VARIANTS = {
    "coupling_2.5e-5": (dict(), 5, COUPLED_SPIN_UP_S, "coupling interval 2.5e-5 s (5 steps)"),
    "coupling_1e-4": (dict(), 20, COUPLED_SPIN_UP_S, "coupling interval 1e-4 s (20 steps)"),
    "coupling_2e-4": (dict(), 40, COUPLED_SPIN_UP_S, "coupling interval 2e-4 s (40 steps)"),
    "dt_1e-5": (dict(dt_s=1e-5), 5, COUPLED_SPIN_UP_S, "DEM step 1e-5 s (coupling 5e-5 s)"),
    "dt_2.5e-6": (dict(dt_s=2.5e-6), 20, COUPLED_SPIN_UP_S,
                  "DEM step 2.5e-6 s (coupling 5e-5 s)"),
    "sector_30": (dict(sector_deg=30.0), None, 0.565, "30 degree sector (3 x the beads)"),
}
#: The variants run by default (coupling_2e-4 on request): with the long run about 1.6
#: CPU hours on one core (measured: long run 1541 s, dt_1e-5 409 s, coupling_1e-4 580 s,
#: coupling_2.5e-5 702 s, dt_2.5e-6 1114 s; sector_30 about 1300 s).
DEFAULT_VARIANTS = ("dt_1e-5", "coupling_1e-4", "coupling_2.5e-5", "dt_2.5e-6", "sector_30")
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


def _scene_of(name: str):
    from dataclasses import replace

    sc = base_scene()
    if name == "long":
        return sc.with_overrides(spin_up_s=LONG_START_S, record_s=LONG_END_S - LONG_START_S,
                                 sample_every_s=SAMPLE_S)
    over, steps, spin, _ = VARIANTS[name]
    sc = sc.with_overrides(spin_up_s=spin, record_s=RECORD_S, sample_every_s=SAMPLE_S, **over)
    if steps is not None:
        sc = replace(sc, coupling=replace(sc.coupling, steps=steps))
    return sc


def run_study(out_dir, variants=DEFAULT_VARIANTS, threads: int | None = 1,
              progress: bool = True, log=print) -> list[Path]:
    """Make the study's runs in ``out_dir`` (``long`` and each of ``variants``), skipping
    those with a ``stats.json``; returns the run folders. CPU time on one core: 26 minutes
    for the long run, 7-19 for a 10 degree variant (see :data:`DEFAULT_VARIANTS`)."""
    from millfmu.dem.run import run_scene

    bad = [v for v in variants if v not in VARIANTS]
    if bad:
        raise WorkPrecisionError(f"variants {bad}: allowed {sorted(VARIANTS)}")
    out = Path(out_dir)
    dirs = []
    for name in ("long",) + tuple(variants):
        d = out / name
        dirs.append(d)
        if (d / "stats.json").exists():
            continue
        log(f"work-precision: running {name} into {d}")
        _timed(run_scene, d, _scene_of(name), d, progress=progress, threads=threads,
               window_s=SAMPLE_S, contacts=True)
    return dirs


def _timed(fn, out_dir, *a, **kw):
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
        _timed(run_scene, d, sc, d, progress=progress, threads=threads,
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


def _rel(a, b):
    """Relative difference (a - b) / b, None where undefined."""
    if a is None or b is None or not b:
        return None
    return (a - b) / abs(b)


# --- the study -------------------------------------------------------------------------

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
                d = [_rel(bl[s][z], whole[s][z]) for bl in blocks]
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


#: Variants that are the more accurate setting of their axis: their row gives the error of
#: the reference setting against them; the other variants' rows give their own error
#: against the reference setting.
FINER = ("coupling_2.5e-5", "dt_2.5e-6", "sector_30")
#: Recording lengths below this [s] are left out of the power-law fit.
LAW_T_MIN_S = 0.05
#: Zones whose statistics the table-build choice holds to its target: V2-V4, the densely
#: filled zones that carry most collisions; V1 (half empty at 80 % filling, a tenth of the
#: collisions) is stated beside it.
TARGET_ZONES = ("V2", "V3", "V4")


def _sigma(law, s, z, t_s, scale=1.0):
    """Error of statistic s in zone z for a recording of t_s [s] from the measured law
    (:func:`fit_sampling_law`; beyond the longest recording studied an extrapolation)."""
    f = law.get(s, {}).get(z)
    return None if f is None else scale * f["at_1s"] * t_s ** f["slope"]


def analyse(study_dir) -> dict:
    """The study from the run folders in ``study_dir`` (``long`` and any of
    :data:`VARIANTS`): recording-length rows with the power-law fit, spin-up rows, variant
    rows, the table-build choice and its expected error. Plain JSON data."""
    study = Path(study_dir)
    if not (study / "long" / "stats.json").is_file():
        raise WorkPrecisionError(f"--out {str(study)!r}: no finished long run (long/stats.json); "
                                 f"make the runs with 'millfmu dem work-precision run --out "
                                 f"{study}'")
    long = load(study / "long")
    if not long.has_contacts:
        raise WorkPrecisionError(f"{study / 'long'}: the long run needs contacts.npz")
    rate = long.cost_s / long.simulated_s  # run seconds per simulated second
    zones = long.zone_names
    rec_window = REFERENCE_WINDOW_S
    rec_rows = recording_length_errors(long, rec_window, RECORD_LENGTHS_S)
    for r in rec_rows:
        r["run_s"] = rate * (COUPLED_SPIN_UP_S + r["record_s"])
    law = fit_sampling_law(rec_rows, LAW_T_MIN_S)
    ref_window = REFERENCE_WINDOW_S
    ref = block_stats(long, *ref_window)
    ref_len = ref_window[1] - ref_window[0]

    spin_rows = []
    for s in SPIN_UPS_S:
        if s + RECORD_S > long.recording_s[1] + 1e-9 or s < long.recording_s[0] - 1e-9:
            continue
        x = block_stats(long, s, s + RECORD_S)
        err, noise = {}, {}
        for st in STATISTICS:
            err[st], noise[st] = {}, {}
            for z in zones:
                err[st][z] = _rel(x[st][z], ref[st][z])
                a, b = _sigma(law, st, z, RECORD_S), _sigma(law, st, z, ref_len)
                noise[st][z] = None if a is None or b is None else 2.0 * math.hypot(a, b)
        spin_rows.append(dict(spin_up_s=s, record_s=RECORD_S, error=err, noise_2sigma=noise,
                              run_s=rate * (s + RECORD_S)))

    var_rows = []
    for name, (over, steps, spin, what) in VARIANTS.items():
        d = study / name
        if not (d / "stats.json").exists():
            continue
        rd = load(d)
        x = block_stats(rd)
        t0, t1 = rd.recording_s
        base = block_stats(long, t0, t1)
        finer = name in FINER
        beads = rd.stats["beads"] / long.stats["beads"]
        err, noise = {}, {}
        for st in STATISTICS:
            err[st], noise[st] = {}, {}
            for z in zones:
                err[st][z] = _rel(base[st][z], x[st][z]) if finer else _rel(x[st][z], base[st][z])
                a = _sigma(law, st, z, t1 - t0)
                b = _sigma(law, st, z, t1 - t0, 1.0 / math.sqrt(beads))
                noise[st][z] = None if a is None else 2.0 * math.hypot(a, b)
        pn_var = (rd.stats.get("flow", {}).get("power_number") or {}).get("value")
        var_rows.append(dict(
            name=name, what=what, finer=finer, spin_up_s=t0, record_s=t1 - t0,
            beads=rd.stats["beads"], error=err, noise_2sigma=noise, run_s=rd.cost_s,
            reference_run_s=rate * (t0 + (t1 - t0)) * beads,
            power_number=pn_var, contacts=rd.has_contacts))
    drift = dict(block_s=DRIFT_BLOCK_S, t_s=[], **{st: {z: [] for z in zones} for st in DRIFT_STATS})
    t = long.recording_s[0]
    while t + DRIFT_BLOCK_S <= long.recording_s[1] + 1e-9:
        x = block_stats(long, t, t + DRIFT_BLOCK_S)
        drift["t_s"].append(t + 0.5 * DRIFT_BLOCK_S)
        for st in DRIFT_STATS:
            for z in zones:
                drift[st][z].append(_rel(x[st][z], ref[st][z]))
        t += DRIFT_BLOCK_S
    res = dict(operating_point=dict(OPERATING_POINT, scene="disc_slice"), drift=drift,
               long_run=dict(recorded_s=list(long.recording_s), run_s=long.cost_s,
                             run_per_simulated_s=rate, beads=long.stats["beads"],
                             threads=long.stats.get("counts", {}).get("threads")),
               reference_window_s=list(ref_window), recording_window_s=list(rec_window),
               law_t_min_s=LAW_T_MIN_S, recording=rec_rows, law=law, spin_up=spin_rows,
               variants=var_rows, zones=zones, statistics=list(STATISTICS),
               machine=machine())
    res["choice"] = choose(res)
    return res


#: The long run's course: these statistics per block of DRIFT_BLOCK_S [s], relative to the
#: reference window.
DRIFT_STATS = ("filling", "collision_frequency", "se_tn_q50")
DRIFT_BLOCK_S = 0.1


def _bias(spin_row, st, z):
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
            sig = _sigma(res["law"], st, z, record_s)
            b = _bias(row, st, z)
            if sig is None or b is None:
                out[st][z] = None
                continue
            extra = sum(x * x for x in _resolution(res, st, z)) if resolution else 0.0
            out[st][z] = math.sqrt(sig ** 2 + b ** 2 + extra)
    return out


#: Error targets [-] tried in turn by :func:`choose`.
TARGETS = (0.05, 0.1, 0.15, 0.2, 0.3)
#: Recording lengths [s] :func:`choose` considers (beyond the longest studied the
#: recording-length law is extrapolated, which the choice states).
CHOICE_LENGTHS_S = (0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.75, 1.0)
#: Having found the cheapest setting, :func:`choose` lengthens its recording while the run
#: costs at most this much more: the spin-up dominates a point's cost, so a longer recording
#: is cheap and lowers the error further.
LENGTHEN_WITHIN = 1.25


def _worst_of(e, zones):
    return max((e[st][z] for st in STATISTICS for z in zones if e[st].get(z) is not None),
               default=None)


def choose(res, targets=TARGETS, zones=TARGET_ZONES) -> dict | None:
    """The table-build choice at the reference resolution (10 degree sector, DEM step
    5e-6 s, coupling every 5e-5 s): for the smallest target in ``targets`` that some
    studied spin-up with a recording of :data:`CHOICE_LENGTHS_S` meets (the error the
    recording and the spin-up add, :func:`expected_error` without the resolution part, at
    most the target for every statistic in ``zones``), the cheapest such setting, its
    recording then lengthened within :data:`LENGTHEN_WITHIN` of its cost (up to the
    longest recording studied). States that error and the total with the resolution part;
    None when no target is met."""
    rate = res["long_run"]["run_per_simulated_s"]
    longest = max((r["record_s"] for r in res["recording"] if r["blocks"] >= 3), default=0.0)
    for target in targets:
        best = None
        for r in res["spin_up"]:
            for t in CHOICE_LENGTHS_S:
                worst = _worst_of(expected_error(res, r["spin_up_s"], t, False), zones)
                if worst is None or worst > target:
                    continue
                cost = rate * (r["spin_up_s"] + t)
                if best is None or cost < best[2] - 1e-9:
                    best = (r["spin_up_s"], t, cost)
        if best is None:
            continue
        su, t, cost = best
        cheapest = dict(spin_up_s=su, record_s=t, run_s=cost)
        for t2 in CHOICE_LENGTHS_S:
            if t < t2 <= longest + 1e-9 and rate * (su + t2) <= LENGTHEN_WITHIN * cost:
                t = t2
        e_rec = expected_error(res, su, t, False)
        e = expected_error(res, su, t, True)
        return dict(spin_up_s=su, record_s=t, run_s=rate * (su + t),
                    worst=_worst_of(e_rec, zones), worst_total=_worst_of(e, zones),
                    expected_error=e, expected_error_recording_spin_up=e_rec,
                    extrapolated=t > longest + 1e-9, cheapest=cheapest, target=target,
                    target_zones=list(zones), sector_deg=OPERATING_POINT["sector_deg"],
                    dt_s=5e-6, coupling_interval_s=5e-5, sample_every_s=SAMPLE_S)
    return None


# --- output ----------------------------------------------------------------------------

#: Columns of the printed table: label -> statistics whose largest |error| it shows.
COLUMNS = {"median SE_tn": ("se_tn_q50",),
           "SE_tn q10, q25, q75, q90": ("se_tn_q10", "se_tn_q25", "se_tn_q75", "se_tn_q90"),
           "collision frequency": ("collision_frequency",),
           "local filling": ("filling",),
           "collision power": ("collision_power",)}


def _worst(d, stats, zones):
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


def markdown(res, zones=TARGET_ZONES) -> str:
    """The table (Markdown) with the measured slopes and the choice below it."""
    head = ["setting", "run time [s]"] + list(COLUMNS)
    lines = ["| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in table_rows(res, zones)]
    lines.append("")
    lines.append(summary_text(res))
    return "\n".join(lines)


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
        v1 = _worst(c["expected_error"], STATISTICS, ("V1",))
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


def write(res, out_dir) -> list[Path]:
    """Write ``work_precision.json``, ``.csv``, ``.md`` and ``.png`` into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = [out / "work_precision.json", out / "work_precision.csv", out / "work_precision.md",
             out / "work_precision.png"]
    files[0].write_text(json.dumps(res, indent=1))
    with open(files[1], "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["kind", "setting", "run_s", "statistic", "zone", "relative_error",
                    "noise_2sigma"])
        for kind, key in (("recording", "record_s"), ("spin_up", "spin_up_s"),
                          ("variants", "name")):
            for r in res[kind]:
                for s in STATISTICS:
                    for z in res["zones"]:
                        w.writerow([kind, r[key], r["run_s"], s, z, r["error"][s][z],
                                    r.get("noise_2sigma", {}).get(s, {}).get(z)])
    files[2].write_text(markdown(res) + "\n")
    plot(res, files[3])
    return files


#: Plain names of the statistics the drift panel shows.
_STAT_NAMES = {"filling": "local filling", "collision_frequency": "collision frequency",
               "se_tn_q50": "median SE_tn"}


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
                e = _worst(r["error"], STATISTICS, TARGET_ZONES)
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
                                 f"'millfmu dem work-precision run --quick --out DIR'")
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


#: The study's summary and data shipped with millfmu (``table --export``), which table
#: manifests quote and ``millfmu report`` shows.
SUMMARY_PATH = Path(__file__).resolve().parents[2] / "data" / "dem_work_precision.json"
RUN_COMMAND = ("millfmu dem work-precision run --out DIR && "
               "millfmu dem work-precision table --out DIR")


def summary(res) -> dict:
    """What a table manifest quotes (plain JSON): the operating point, the choice with its
    expected error, the recording-length law (error = at_1s T^slope), spin-up biases,
    resolution differences with their noise, where and when it was measured."""
    c = res.get("choice")
    return dict(
        operating_point=res["operating_point"],
        command=RUN_COMMAND,
        measured_on=res["machine"],
        long_run=res["long_run"],
        choice=None if c is None else {k: c[k] for k in (
            "spin_up_s", "record_s", "sector_deg", "dt_s", "coupling_interval_s",
            "sample_every_s", "run_s", "worst", "worst_total", "target", "target_zones",
            "extrapolated", "cheapest", "expected_error", "expected_error_recording_spin_up")},
        recording_law={s: {z: ({k: v[k] for k in ("at_1s", "slope")} if v else None)
                           for z, v in d.items()} for s, d in res["law"].items()},
        slopes=slopes(res),
        spin_up_bias={f"{r['spin_up_s']:g}": {s: {z: _bias(r, s, z) for z in res["zones"]}
                                               for s in STATISTICS}
                      for r in res["spin_up"]},
        resolution=[dict(name=r["name"], what=r["what"], finer=r["finer"],
                         worst_error=_worst(r["error"], STATISTICS, TARGET_ZONES),
                         worst_noise_2sigma=_worst(r["noise_2sigma"], STATISTICS, TARGET_ZONES),
                         run_s=r["run_s"], reference_run_s=r["reference_run_s"])
                    for r in res["variants"]],
        note="relative errors [-] of a DEM table point's statistics (per zone: SE_tn "
             "quantiles, collision frequency, local filling, collision power density) at the "
             "operating point only; other tip speeds and fillings were not measured")


def export(res, path) -> Path:
    """Write the study's summary (:func:`summary`) and its data to ``path`` (JSON): what
    :func:`manifest_entry` and ``millfmu report`` read."""
    path = Path(path)
    path.write_text(json.dumps({"summary": summary(res), "study": res}, indent=1) + "\n")
    return path


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
