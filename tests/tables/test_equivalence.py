"""A change of the DEM's sources that alters only round-off, accepted on the evidence of its
statistics (millfmu.dem.tables.equivalence; the runs and their command in a checkout's
validation.equivalence_runs): the scores, the reference and the accepted
changes in the evidence file, and the kernel version they give. The DEM is replaced by
runners that draw the statistics around the table's values."""

from __future__ import annotations

import json
import random
import subprocess
import sys
from pathlib import Path

import pytest

from millfmu.dem.tables import cache
from millfmu.dem.tables import equivalence as E
from validation import equivalence_runs as R

ROOT = Path(__file__).resolve().parents[2]
ZONES = ["V1", "V2", "V3", "V4"]
TABLE = {"filling_local": [0.2, 0.7, 0.9, 0.1], "collision_frequency_norm": [1.0, 7.0, 7.5, 0.5],
         "se_tn_q50_norm": [0.01, 0.02, 0.03, 0.04], "speed_over_tip_speed": [0.4, 0.3, 0.2, 0.1]}
SIGMA = {"filling_local": [0.02, 0.01, 0.005, 0.02],
         "collision_frequency_norm": [0.04, 0.02, 0.01, 0.02],
         "se_tn_q50_norm": [0.04, 0.02, 0.02, 0.04]}


def draw(seed: int, sd: float = 0.03, shift: float = 0.0, threads: int = 1) -> dict:
    """A realization: every value of TABLE times (1 + shift + sd N(0, 1))."""
    rng = random.Random(seed)
    return dict(threads=threads, values={k: [v * (1 + shift + sd * rng.gauss(0, 1)) for v in vs]
                                         for k, vs in TABLE.items()})


def test_same_distribution_passes_and_a_shift_fails():
    ref = [draw(s) for s in range(1, 4)]
    same = [draw(s, threads=s) for s in range(10, 14)]
    j = E.judge(TABLE, ref, same, SIGMA, ZONES)
    assert j["n"] == 12 and j["passed"], j["max_abs_score"]
    shifted = [draw(s, shift=0.2, threads=s) for s in range(10, 14)]
    j = E.judge(TABLE, ref, shifted, SIGMA, ZONES)
    assert not j["passed"] and j["max_abs_score"] > 5


def test_score_formula_by_hand():
    """One zone scored by hand: pooled sd about each group's mean, floored by sigma."""
    z = ["V1"]
    t = {k: v[:1] for k, v in TABLE.items()}
    sig = {k: [0.001] for k in SIGMA}
    ref = [dict(values={k: [v[0] * 1.02] for k, v in t.items()})]  # reference: 0, +0.02
    runs = [dict(threads=2, values={k: [v[0] * 1.05] for k, v in t.items()}),
            dict(threads=3, values={k: [v[0] * 1.07] for k, v in t.items()})]  # +0.05, +0.07
    j = E.judge(t, ref, runs, sig, z)
    c = j["comparisons"][0]
    sd = ((0.01 ** 2 * 2 + 0.01 ** 2 * 2) / 2) ** 0.5
    assert c["sd"] == pytest.approx(sd)
    assert c["diff"] == pytest.approx(0.06 - 0.01)
    assert c["score"] == pytest.approx(0.05 / (sd * (1 / 2 + 1 / 2) ** 0.5))
    # a floor where the realizations agree more closely than the law's sigma
    j = E.judge(t, ref, runs, {k: [0.5] for k in SIGMA}, z)
    assert j["comparisons"][0]["score"] == pytest.approx(0.05 / 0.5)


def test_identical_runs_are_noted():
    r = draw(5, threads=1)
    j = E.judge(TABLE, [draw(1)], [r, dict(r, threads=2)], SIGMA, ZONES)
    assert any("one sample, not two" in n for n in j["notes"])


@pytest.fixture
def evidence(tmp_path, monkeypatch):
    """An evidence file of its own; the installed sources' hash settable."""
    path = tmp_path / "dem_equivalence.json"
    monkeypatch.setattr(E, "EVIDENCE_PATH", path)
    from millfmu.stress_tables.table import read_table_ref

    version = read_table_ref("coupled").manifest["kernel_version"]
    state = {"hash": version}
    monkeypatch.setattr(cache, "kernel_source_hash", lambda: state["hash"])
    return path, state, version


def runner(shift=0.0, sd=0.02, seed0=0):
    def run_one(scene, point, threads):
        from millfmu.dem.tables.build import _check_fields
        from millfmu.stress_tables.table import read_table_ref

        tv = _check_fields(read_table_ref("coupled").lookup(point).values)
        rng = random.Random(seed0 + threads)
        return dict(threads=threads, values={k: [float(x) * (1 + shift + sd * rng.gauss(0, 1))
                                                 for x in v] for k, v in tv.items()})
    return run_one


def test_reference_then_a_change_then_its_version(evidence):
    path, state, version = evidence
    # a change needs the reference first
    state["hash"] = "sha256:" + "c" * 64
    with pytest.raises(E.EquivalenceError, match="no reference runs"):
        R.run_equivalence(threads=(1, 2), run_one=runner())
    with pytest.raises(E.EquivalenceError, match="not table coupled's kernel version"):
        R.run_equivalence(threads=(1, 2), reference=True, run_one=runner())
    # the table's own sources: reference runs, recorded in two goes
    state["hash"] = version
    with pytest.raises(E.EquivalenceError, match="nothing to judge"):
        R.run_equivalence(threads=(1, 2), run_one=runner())
    E.record(R.run_equivalence(threads=(1, 2), reference=True, run_one=runner()))
    E.record(R.run_equivalence(threads=(3,), reference=True, run_one=runner()))
    with pytest.raises(E.EquivalenceError, match="recorded already"):
        E.record(R.run_equivalence(threads=(3, 4), reference=True, run_one=runner()))
    ref = E.read_evidence()["reference"]
    assert [r["threads"] for r in ref["runs"]] == [1, 2, 3]
    assert ref["kernel_version"] == version and len(E.reference_lines(ref)) == 13
    # a change far off the reference: refused, nothing recorded, its hash its own version
    state["hash"] = "sha256:" + "d" * 64
    bad = R.run_equivalence(threads=(1, 2, 3), change="a real change", run_one=runner(0.3))
    assert not bad["judgement"]["passed"]
    with pytest.raises(E.EquivalenceError, match="did not pass"):
        E.record(bad)
    assert cache.dem_kernel_version() == state["hash"]
    # a change within the realizations' spread: recorded, and its hash takes the version
    ok = R.run_equivalence(threads=(4, 5, 6), change="round-off", run_one=runner(seed0=10))
    assert ok["judgement"]["passed"], E.change_lines(ok, ref)
    E.record(ok)
    assert E.accepted_versions() == {state["hash"]: version}
    assert cache.dem_kernel_version() == version
    # an entry edited to fail is ignored on reading
    data = json.loads(path.read_text())
    for r in data["accepted"][0]["runs"]:
        r["values"]["filling_local"] = [2 * x for x in r["values"]["filling_local"]]
    path.write_text(json.dumps(data))
    assert E.accepted_versions() == {}
    assert cache.dem_kernel_version() == state["hash"]


def test_reference_of_another_point_is_refused(evidence):
    path, state, version = evidence
    res = R.run_equivalence(threads=(1,), reference=True, run_one=runner())
    E.record(res)
    assert path.stat().st_mode & 0o777 == 0o644  # readable by all, as the shipped data
    assert [p.name for p in path.parent.iterdir()] == [path.name]  # no temporary left
    other = dict(res, point=dict(res["point"], tip_speed_m_per_s=6.0))
    with pytest.raises(E.EquivalenceError, match="another table, version or point"):
        E.record(other)
    assert len(E.read_evidence()["reference"]["runs"]) == 1  # nothing half-written


def test_bad_thread_counts_and_bad_files(evidence, tmp_path):
    with pytest.raises(E.EquivalenceError, match="distinct counts"):
        R.run_equivalence(threads=(2, 2), reference=True, run_one=runner())
    with pytest.raises(E.EquivalenceError, match="distinct counts"):
        R.run_equivalence(threads=(), reference=True, run_one=runner())
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(E.EquivalenceError, match="not readable JSON"):
        E.read_evidence(bad)
    assert E.accepted_versions(bad) == {}
    bad.write_text(json.dumps({"format": 99, "accepted": []}))
    with pytest.raises(E.EquivalenceError, match="format 99"):
        E.read_evidence(bad)


def test_a_table_of_another_scene_is_refused(evidence):
    with pytest.raises(E.EquivalenceError, match="scene 'disc_slice'; this table's scene is "
                                                 "'accelerator_slice'"):
        R.run_equivalence("accelerator", threads=(1,), reference=True, run_one=runner())


def test_cli_names_bad_thread_counts(tmp_path):
    """``python -m validation.equivalence_runs`` from the checkout's root (the former
    ``millfmu tables equivalence``, with its arguments)."""
    r = subprocess.run([sys.executable, "-m", "validation.equivalence_runs",
                        "--reference", "--threads", "2", "2", "--evidence",
                        str(tmp_path / "e.json")], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2 and "distinct counts" in r.stderr, r.stderr
    assert r.stderr.startswith("python -m validation.equivalence_runs: ")


def test_cli_shows_an_empty_evidence_file(tmp_path, capsys):
    assert R.main(["--show", "--evidence", str(tmp_path / "none.json")]) == 0
    assert capsys.readouterr().out == "no reference runs recorded\n"
    (tmp_path / "bad.json").write_text("[]")
    assert R.main(["--show", "--evidence", str(tmp_path / "bad.json")]) == 2
    assert "format None" in capsys.readouterr().err


def test_shipped_evidence_reads_and_its_changes_pass():
    data = E.read_evidence()
    ref = data.get("reference")
    for e in data["accepted"]:
        assert ref is not None and E.rejudge(e, ref)["passed"], e["source_hash"]
    if ref is not None:
        from millfmu.stress_tables.table import read_table_ref

        m = read_table_ref(ref["table"]).manifest
        assert (ref["kernel_version"], ref["table_key"]) == (m["kernel_version"], m["key"])


def test_report_shows_the_realizations(tmp_path, monkeypatch):
    from millfmu.report import _realizations

    html = _realizations()
    ref = E.read_evidence().get("reference")
    if ref is not None:
        assert html.count("<tr>") == 1 + 12 and "study's sigma" in html
    monkeypatch.setattr(E, "EVIDENCE_PATH", tmp_path / "none.json")
    assert "No realizations" in _realizations()
    (tmp_path / "none.json").write_text("[]")
    assert "Realizations:" in _realizations() and "format" in _realizations()


def test_work_precision_summary_is_the_studys():
    from millfmu.dem.analysis.precision import SUMMARY_PATH

    assert E.WORK_PRECISION_PATH == SUMMARY_PATH and SUMMARY_PATH.is_file()
