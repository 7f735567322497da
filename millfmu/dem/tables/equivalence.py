"""DEM source changes accepted by their statistics: a change that alters only round-off.

The DEM is chaotic. A change in the last bit of one force (a fused multiply-add, another
order of a sum) sends the beads along another trajectory within milliseconds, so a table
point run by the changed sources is another sample of the same statistics, never the same
numbers, and the bit-for-bit check behind :data:`~.cache.SAME_DEM_AS` cannot accept it.
Rebuilding the shipped coupled table for every such change costs 8 h of points.

This module accepts such a change as the shipped tables' kernel version on evidence
instead, at the operating point of the work-precision study (millfmu/data/
dem_work_precision.json, where the table's sampling noise was measured):

1. reference: realizations of the table's own version there, the table's point and runs
   of its sources on other thread counts (each count splits the 10-degree sector's beads
   into as many chunks, so each is another trajectory; a count repeated repeats its run
   to the bit). Their spread is the noise of one point as it is, from the spin-up to the
   end of the recording.
2. a change: runs of the changed sources there, judged against the reference for each
   statistic of :data:`GATED` (local filling, collision frequency, median normal stress
   energy) per zone, on values relative to the table's: score = (mean of the runs - mean
   of the reference) / (s sqrt(1/n + 1/m)), s the larger of the pooled standard
   deviation of both groups and the study's recording-length law sigma(T) (T the table's
   record_s; a floor where a few realizations happen to agree). Every |score| must lie
   within :data:`Z_LIMIT`.

What passes is a change of the statistics below the realizations' own spread: the table's
precision at that point, below which a change cannot be told from sampling. A change of
the physics (a contact law, a drag law, a smoothing kernel) is not round-off and needs a
rebuilt table, whatever the scores say.

The evidence (:data:`EVIDENCE_PATH`): the reference (the table's values at the point, the
law's sigmas, the runs' values) and the accepted changes (source hash, version accepted
as, runs); :func:`accepted_versions` recomputes every change's scores on reading and
ignores one that does not pass. Reading it needs no numba and no numpy, and this module
imports nothing of the DEM's (the cache reads it for the kernel version); the runs are made
from a checkout (``validation/equivalence_runs.py``, ``python -m validation.equivalence_runs``),
outside the installed package.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from ...stress_tables.files import write_replacing

#: Evidence of accepted source changes (JSON, shipped with millfmu).
EVIDENCE_PATH = Path(__file__).resolve().parents[2] / "data" / "dem_equivalence.json"
#: The work-precision study's summary shipped with millfmu (the file that
#: ``millfmu.dem.analysis.precision.SUMMARY_PATH`` names; named here, not imported: reading
#: the evidence needs no numpy, which that module loads)
WORK_PRECISION_PATH = Path(__file__).resolve().parents[2] / "data" / "dem_work_precision.json"

#: Table check field (:data:`~.build.CHECK_FIELDS`) -> the work-precision statistic whose
#: recording-length law gives its sampling error. The check's fourth field, the beads'
#: speed over the tip speed, has no measured law: reported, not gated.
GATED = {"filling_local": "filling", "collision_frequency_norm": "collision_frequency",
         "se_tn_q50_norm": "se_tn_q50"}

#: Largest accepted |score|. With s known, a change of round-off only would exceed it with
#: probability 0.27 % per comparison (Gaussian sampling errors); with s estimated from a
#: few realizations the score follows Student's t, |t| > 3 with 4 % probability at 4
#: degrees of freedom (3 runs against the table's point and 2 runs), less where the law's
#: sigma is the larger. The 12 comparisons are correlated (fillings and collision
#: frequencies move together): a sound change that fails is run again on more threads.
Z_LIMIT = 3.0

FORMAT = 1


class EquivalenceError(ValueError):
    """Evidence that cannot be produced or read (names the item and what is allowed)."""


def sampling_sigma(law: dict, statistic: str, zone: str, record_s: float) -> float | None:
    """Relative sampling error [-] of one recording of ``record_s`` [s]: the work-precision
    study's law at_1s T^slope (``law``: the summary's ``recording_law``); None where the
    law has no entry."""
    f = (law.get(statistic) or {}).get(zone)
    if not f:
        return None
    return float(f["at_1s"]) * float(record_s) ** float(f["slope"])


def _rel(values: dict, table_values: dict, field: str, zi: int):
    v, t = values[field][zi], table_values[field][zi]
    if v is None or t is None or t == 0 or not math.isfinite(v) or not math.isfinite(t):
        return None
    return v / t - 1.0


def judge(table_values: dict, reference_runs: list, runs: list, sigma: dict, zones,
          z_limit: float = Z_LIMIT) -> dict:
    """Scores of ``runs`` (the changed sources) against the reference: the table's point
    and ``reference_runs`` (both realizations of the table's kernel version).

    table_values: field -> value per zone at the point; runs and reference_runs: lists of
    dicts with ``values`` (field -> value per zone); sigma: field -> the work-precision law's
    relative sampling error per zone (None where unknown). For each :data:`GATED` field and
    zone, on values relative to the table's (v / table - 1): s = the larger of the
    realizations' pooled standard deviation (both groups about their own means) and sigma,
    and score = (mean of runs - mean of the reference) / (s sqrt(1/n_runs + 1/n_ref)).
    Returns ``comparisons`` (field, zone, n_runs, n_ref, mean difference, pooled sd, sigma,
    score), ``n``, ``max_abs_score``, ``passed`` (every |score| <= z_limit, at least one)
    and ``notes``."""
    ref = [dict(values=table_values)] + list(reference_runs)
    comps = []
    for f in GATED:
        sig = sigma.get(f) or [None] * len(zones)
        for zi, z in enumerate(zones):
            a = [x for x in (_rel(r["values"], table_values, f, zi) for r in runs)
                 if x is not None]
            b = [x for x in (_rel(r["values"], table_values, f, zi) for r in ref)
                 if x is not None]
            if not a or not b:
                continue
            ma, mb = sum(a) / len(a), sum(b) / len(b)
            dof = len(a) + len(b) - 2
            ss = sum((x - ma) ** 2 for x in a) + sum((x - mb) ** 2 for x in b)
            sd = math.sqrt(ss / dof) if dof > 0 else None
            law = sig[zi]
            s = max((x for x in (sd, law) if x), default=0.0)
            if not s:
                continue
            comps.append(dict(field=f, zone=z, n_runs=len(a), n_ref=len(b), diff=ma - mb,
                              sd=sd, sigma=law,
                              score=(ma - mb) / (s * math.sqrt(1 / len(a) + 1 / len(b)))))
    scores = [c["score"] for c in comps]
    notes = []
    for i, x in enumerate(runs):
        for y in runs[i + 1:]:
            if x["values"] == y["values"]:
                notes.append(f"the runs on {x.get('threads')} and {y.get('threads')} threads "
                             f"gave the same values: one sample, not two")
    return dict(n=len(comps), z_limit=z_limit,
                max_abs_score=max((abs(x) for x in scores), default=None),
                passed=bool(scores) and all(abs(x) <= z_limit for x in scores),
                comparisons=comps, notes=notes)


def read_evidence(path=None) -> dict:
    """The evidence file: ``reference`` (None before the first reference run is recorded)
    and ``accepted`` (a list); an empty evidence when the file does not exist."""
    p = Path(path) if path is not None else EVIDENCE_PATH
    if not p.is_file():
        return dict(format=FORMAT, reference=None, accepted=[])
    try:
        data = json.loads(p.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise EquivalenceError(f"{p}: not readable JSON ({e})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT or \
            not isinstance(data.get("accepted"), list):
        raise EquivalenceError(
            f"{p}: format {data.get('format') if isinstance(data, dict) else None!r}; "
            f"allowed: {{'format': {FORMAT}, 'reference': {{...}}, 'accepted': [...]}}")
    return data


def rejudge(entry: dict, reference: dict) -> dict:
    """:func:`judge` of an accepted entry, recomputed from what the evidence records."""
    return judge(reference["table_values"], reference["runs"], entry["runs"],
                 reference["sigma"], reference["zones"], entry.get("z_limit", Z_LIMIT))


def accepted_versions(path=None) -> dict:
    """Source hash -> the kernel version it is accepted as, for every accepted entry whose
    scores, recomputed against the recorded reference, pass. An unreadable file accepts
    nothing."""
    try:
        data = read_evidence(path)
    except EquivalenceError:
        return {}
    ref = data.get("reference")
    out = {}
    for e in data["accepted"] if ref else ():
        try:
            if e["accepted_as"] == ref["kernel_version"] and rejudge(e, ref)["passed"]:
                out[e["source_hash"]] = e["accepted_as"]
        except (KeyError, TypeError, IndexError, ZeroDivisionError):
            continue
    return out


def _write(data: dict, path=None) -> Path:
    """The evidence written beside its place and renamed onto it (a reader never sees half
    a file)."""
    p = Path(path) if path is not None else EVIDENCE_PATH
    write_replacing(p, (json.dumps(data, indent=1) + "\n").encode(), prefix=p.name + ".")
    return p


def record(result: dict, path=None) -> Path:
    """Add what ``run_equivalence`` (validation/equivalence_runs.py) gave to the evidence: reference
    runs to the reference (started with the first), an accepted change to ``accepted``
    (replacing an entry of the same source hash; refused unless it passed)."""
    data = read_evidence(path)
    if result["kind"] == "reference":
        ref = data.get("reference")
        if ref is None:
            data["reference"] = {k: v for k, v in result.items() if k != "kind"}
        else:
            same = ("kernel_version", "table_key", "point", "record_s", "zones")
            if any(ref[k] != result[k] for k in same):
                raise EquivalenceError(
                    "reference runs of another table, version or point than the recorded "
                    "reference's (" + ", ".join(f"{k} {ref[k]!r}" for k in same) + ")")
            had = sorted({r["threads"] for r in ref["runs"]} &
                         {r["threads"] for r in result["runs"]})
            if had:
                raise EquivalenceError(f"reference runs on {had} threads are recorded "
                                       f"already: the same sources on the same thread count "
                                       f"repeat a run, they add no realization")
            ref["runs"] = ref["runs"] + result["runs"]
    else:
        if not result["judgement"]["passed"]:
            raise EquivalenceError("the change did not pass: not recorded")
        entry = {k: v for k, v in result.items() if k != "kind"}
        data["accepted"] = [e for e in data["accepted"]
                            if e.get("source_hash") != entry["source_hash"]] + [entry]
    return _write(data, path)


def spread(ref: dict) -> list:
    """Per :data:`GATED` field and zone of the reference: (field, zone, [(threads, run /
    table - 1) per run], standard deviation of the realizations with the table's point
    (None for one), the law's sigma)."""
    out = []
    for f in GATED:
        for zi, z in enumerate(ref["zones"]):
            got = [(r.get("threads"), _rel(r["values"], ref["table_values"], f, zi))
                   for r in ref["runs"]]
            xs = [0.0] + [x for _, x in got if x is not None]
            m = sum(xs) / len(xs)
            sd = math.sqrt(sum((x - m) ** 2 for x in xs) / (len(xs) - 1)) if len(xs) > 1 else None
            out.append((f, z, got, sd, ref["sigma"][f][zi]))
    return out


def realization_entry(ref: dict) -> dict:
    """The table manifest's ``realization_spread`` from the evidence's reference: per
    :data:`GATED` field and zone the standard deviation of the realizations (the table's
    point and the reference runs) relative to the table's value [-], and the factor t
    sqrt(2) [-] (Student's t at 97.5 % on n - 1 degrees of freedom) that turns it into the
    95 % bound of the difference between the table's value and another run at a point:
    what a check measures. Measured at the work-precision point only."""
    from scipy.stats import t as student_t

    sd: dict = {}
    for f, _z, _got, s, _law in spread(ref):
        sd.setdefault(f, []).append(s)
    n = 1 + len(ref["runs"])
    if n < 3:
        raise EquivalenceError(f"reference: {n} realizations; a spread needs at least 3 (the "
                               f"table's point and 2 runs: python -m validation.equivalence_runs --reference --write)")
    return {"measure": "standard deviation of independent realizations (the table's point and "
                       "runs on other thread counts) relative to the table's value, per zone; "
                       "prediction_factor = t(0.975, n - 1) sqrt(2)",
            "point": ref["point"], "record_s": ref["record_s"], "realizations": n,
            "kernel_version": ref["kernel_version"], "relative_sd": sd,
            "prediction_factor": float(student_t.ppf(0.975, n - 1)) * math.sqrt(2.0)}


def write_realization_spread(table_ref: str, path=None) -> Path:
    """Record :func:`realization_entry` of the evidence's reference in the manifest of
    table ``table_ref`` (its key must be the reference's) and write the table's files again;
    returns the manifest's path."""
    from ...stress_tables.table import read_table_ref, table_ref_prefix

    ref = (read_evidence(path) or {}).get("reference")
    if not ref:
        raise EquivalenceError("no reference realizations in the evidence: run python -m validation.equivalence_runs "
                               "--reference --write first")
    table = read_table_ref(table_ref)
    if ref.get("table_key") != table.manifest.get("key"):
        raise EquivalenceError(f"table {table_ref!r}: key {table.manifest.get('key')} is not "
                               f"the reference's {ref.get('table_key')}")
    table.manifest = dict(table.manifest, realization_spread=realization_entry(ref))
    _npz, man = table.export(table_ref_prefix(table_ref))
    return man


def reference_lines(ref: dict) -> list:
    """Lines that show the reference: per statistic and zone the realizations relative to
    the table's point, their standard deviation and the law's sigma."""
    lines = [f"reference at {ref['point']}, recording {ref['record_s']:g} s: the table's point "
             f"and {len(ref['runs'])} run(s) of its version; values relative to the table's"]
    for f, z, got, sd, law in spread(ref):
        lines.append(f"  {f:24s} {z}: table 0, " +
                     ", ".join("-" if x is None else f"{t} thr {x:+.3f}" for t, x in got) +
                     (f"; sd {sd:.3f}" if sd is not None else "") +
                     (f", law sigma {law:.3f}" if law is not None else ", no law"))
    return lines


def change_lines(entry: dict, reference: dict) -> list:
    """Lines that show a change's scores per statistic and zone."""
    j = rejudge(entry, reference)
    lines = [f"score = (mean of the runs - mean of the reference) / (s sqrt(1/n + 1/m)), s the "
             f"larger of the pooled sd and the law's sigma; accepted within +-{j['z_limit']:g}"]
    for c in j["comparisons"]:
        sd = "-" if c["sd"] is None else f"{c['sd']:.3f}"
        law = "-" if c["sigma"] is None else f"{c['sigma']:.3f}"
        lines.append(f"  {c['field']:24s} {c['zone']}: runs - reference {c['diff']:+.3f} "
                     f"(n {c['n_runs']}, m {c['n_ref']}; sd {sd}, sigma {law}): "
                     f"score {c['score']:+.2f}")
    lines.append(f"{j['n']} scores, largest |score| {j['max_abs_score']:.2f}: "
                 f"{'PASSED' if j['passed'] else 'FAILED'}" if j["n"] else "no scores: FAILED")
    lines += [f"note: {n}" for n in j["notes"]]
    return lines
