"""DEM work-precision: the batch-means error of a recording of length T against closed-form
sampling statistics, and on a short coupled run (millfmu.dem.analysis.precision, what the
package needs); the study itself on a synthetic long run and its command
(validation.work_precision, run from a checkout)."""

import json
import math

import numpy as np
import pytest

from millfmu.dem.analysis import precision as P
from validation import work_precision as W


def _fake_run(path, rate_per_chunk=400.0, n_chunks=200, chunk_s=0.01, seed=3, t0_s=1.0):
    """A run folder with independent chunks: Poisson contact counts of mean
    ``rate_per_chunk`` per zone, SE_tn exponential with mean 1e-10 J, constant filling."""
    rng = np.random.default_rng(seed)
    zones, vols = ["V1", "V2"], np.array([1e-6, 2e-6])
    zone, chunk, se = [], [], []
    for c in range(n_chunks):
        for k in range(2):
            n = rng.poisson(rate_per_chunk)
            zone.append(np.full(n, k, np.int8))
            chunk.append(np.full(n, c, np.int32))
            se.append(rng.exponential(1e-10, n))
    se = np.concatenate(se)
    starts = t0_s + chunk_s * np.arange(n_chunks)
    path.mkdir(parents=True)
    np.savez_compressed(path / "contacts.npz", zone=np.concatenate(zone), chunk=np.concatenate(chunk),
                        se_tn_j=se, se_total_j=2 * se, chunk_start_s=starts,
                        chunk_s=np.full(n_chunks, chunk_s), zone_names=np.array(zones),
                        zone_volumes_m3=vols)
    lines = ["t_start_s,t_end_s,zone,filling,speed_over_tip_speed,collision_frequency_per_m3_s,"
             "se_tn_q50_j,se_tn_q90_j,collision_power_w"]
    for t in starts:
        for z in zones:
            lines.append(f"{t:.9g},{t + chunk_s:.9g},{z},0.5,0.1,1,1,1,1")
    (path / "windows.csv").write_text("\n".join(lines) + "\n")
    st = {"zones": [{"name": z, "volume_m3": v} for z, v in zip(zones, vols)], "beads": 100,
          "spin_up_s": t0_s, "record_s": n_chunks * chunk_s, "counts": {"wall_time_s": 10.0}}
    (path / "stats.json").write_text(json.dumps(st))
    return path


def test_batch_means_error_matches_poisson_and_median_sampling_statistics(tmp_path):
    rd = P.load(_fake_run(tmp_path / "run"))
    rows = P.recording_length_errors(rd, rd.recording_s, (0.01, 0.02, 0.05, 0.1, 0.2))
    assert [r["blocks"] for r in rows] == [200, 100, 40, 20, 10]
    for r in rows:
        n_contacts = 400.0 * r["record_s"] / 0.01
        # Poisson counts: relative error 1/sqrt(N); sample median of an exponential
        # distribution: standard error 1/(2 f(m) sqrt(N)) = 1/sqrt(N) of the scale, ln 2 the median
        for z in ("V1", "V2"):
            f = r["error"]["collision_frequency"][z] * math.sqrt(n_contacts)
            m = r["error"]["se_tn_q50"][z] * math.sqrt(n_contacts) * math.log(2.0)
            tol = 3.0 / math.sqrt(2 * r["blocks"]) + 0.05  # chi-square spread of the estimate
            assert abs(f - 1.0) < tol, (r["record_s"], z, f)
            assert abs(m - 1.0) < tol, (r["record_s"], z, m)
            assert r["error"]["filling"][z] == 0.0
    law = P.fit_sampling_law(rows)
    for s in ("collision_frequency", "se_tn_q50", "se_tn_q25", "collision_power"):
        for z in ("V1", "V2"):
            f = law[s][z]
            assert f["slope"] == pytest.approx(-0.5, abs=0.1), (s, z, f)
            assert f["predicted_slope"] == pytest.approx(-0.5, abs=0.05), (s, z, f)
            # independent contacts: the measured error is the predicted one
            assert f["inflation"] == pytest.approx(1.0, abs=0.3), (s, z, f)
    # the whole recording's statistics are the contacts' own
    whole = P.block_stats(rd)
    assert whole["se_tn_q50"]["V2"] == pytest.approx(
        np.median(rd.se_tn[1]), rel=1e-12)
    assert whole["collision_frequency"]["V1"] == pytest.approx(rd.se_tn[0].size / (1e-6 * 2.0))


def test_windows_outside_the_recording_and_runs_without_contacts_are_refused(tmp_path):
    rd = P.load(_fake_run(tmp_path / "run"))
    with pytest.raises(P.WorkPrecisionError, match=r"no recording chunk inside \[3, 4\] s"):
        P.block_stats(rd, 3.0, 4.0)
    (tmp_path / "run" / "contacts.npz").unlink()
    plain = P.load(tmp_path / "run")
    with pytest.raises(P.WorkPrecisionError, match="no contacts.npz"):
        P.block_stats(plain, 1.0, 1.5)


@pytest.mark.skipif(__import__("importlib").util.find_spec("numba") is None, reason="needs numba")
def test_short_coupled_run_recomputes_its_statistics_and_errors_exceed_independent_sampling(tmp_path):
    """The quick study's short run of the coupled disc slice (about 30 s on one core): the
    contacts reproduce stats.json exactly; the error independent contacts would give falls
    as T^-1/2, and the measured error of a T-recording is larger (contacts in a granular
    flow are correlated; the short run is not stationary either)."""
    run = P.run_quick(tmp_path / "quick")
    rd = P.load(run)
    whole = P.block_stats(rd)
    for z in rd.stats["zones"]:
        n = z["name"]
        assert whole["collision_frequency"][n] == pytest.approx(z["collision_frequency_per_m3_s"], rel=1e-12)
        assert whole["collision_power"][n] == pytest.approx(z["collision_power_w"] / z["volume_m3"], rel=1e-12)
        assert whole["filling"][n] == pytest.approx(z["filling"], rel=1e-12)
        for q in ("q10", "q50", "q90"):
            assert whole[f"se_tn_{q}"][n] == z["se"]["tn"]["quantiles_j"][q]
    res = P.analyse_quick(run)
    assert [r["blocks"] for r in res["recording"]] == [20, 10, 4, 2]
    for s in ("collision_frequency", "se_tn_q50", "collision_power"):
        for z in ("V2", "V3"):
            f = res["law"][s][z]
            assert f["predicted_slope"] == pytest.approx(-0.5, abs=0.1), (s, z, f)
            for r in res["recording"]:
                if r["blocks"] >= 4:
                    assert r["error"][s][z] > r["predicted"][s][z], (s, z, r["record_s"])
    assert json.loads((run / "cost.json").read_text())["cpu_s"] > 0


def test_study_of_a_stationary_synthetic_run_writes_table_choice_and_manifest_entry(tmp_path):
    """The whole study (analyse, choose, write, export, manifest_entry) on a long run of
    independent chunks: no spin-up bias beyond its noise, errors falling as T^-1/2, a
    choice, and the manifest's expected error for a table's settings."""
    n = int(round((W.LONG_END_S - W.LONG_START_S) / 0.01))
    _fake_run(tmp_path / "study" / "long", rate_per_chunk=800.0, n_chunks=n, t0_s=W.LONG_START_S)
    res = W.analyse(tmp_path / "study")
    assert [r["spin_up_s"] for r in res["spin_up"]] == list(W.SPIN_UPS_S)
    # stationary: the spin-up windows differ from the reference by their sampling noise
    z_scores = [abs(r["error"][s][z]) / (0.5 * r["noise_2sigma"][s][z]) for r in res["spin_up"]
                for s in ("collision_frequency", "se_tn_q50", "collision_power") for z in ("V1", "V2")]
    # |N(0, 1)| has median 0.67; the noise comes from a power law fitted to batch means of
    # few blocks at the longer recordings, so allow for it being off by a factor 3
    assert 0.2 < np.median(z_scores) < 2.0, z_scores
    sl = P.slopes(res)["collision_frequency"]  # T >= 0.05 s: 24 ... 3 blocks, so +-0.25
    assert sl["median"] == pytest.approx(-0.5, abs=0.25) and sl["inflation"] == pytest.approx(1.0, abs=0.4)
    c = res["choice"]
    assert c is not None and c["target"] == 0.05 and c["worst"] <= 0.05
    assert c["spin_up_s"] == min(W.SPIN_UPS_S)  # no bias: the shortest spin-up is cheapest
    files = W.write(res, tmp_path / "out")
    assert all(f.stat().st_size > 0 for f in files)
    assert "| recording 0.01 s (120 blocks) |" in (tmp_path / "out" / "work_precision.md").read_text()
    # what millfmu report --dem-runs reads of it
    assert P.read_study(tmp_path / "out") == json.loads(json.dumps(res))
    path = W.export(res, tmp_path / "wp.json")
    m = P.manifest_entry({"spin_up_s": 1.0, "record_s": 0.2, "dt_s": 5e-6, "sector_deg": 10.0}, path=path)
    assert m["choice"]["record_s"] == c["record_s"] and m["this_table"]["spin_up_used_s"] == 1.0
    e = m["this_table"]["expected_error"]["collision_frequency"]["V2"]
    assert e == pytest.approx(1.0 / math.sqrt(800.0 * 20), rel=0.5)  # Poisson at 0.2 s
    short = P.manifest_entry({"spin_up_s": 0.05, "record_s": 0.1}, path=path)
    assert short["this_table"]["expected_error"] is None and "below the shortest" in short["this_table"]["note"]
    assert P.manifest_entry({}, path=tmp_path / "none.json") is None
    pres = P.manifest_entry({"spin_up_s": 1.0, "record_s": 0.2, "fluid": "prescribed"}, path=path)
    assert pres["this_table"]["expected_error"] is None and "does not cover" in pres["this_table"]["note"]


def test_shipped_study_gives_the_choice_and_a_coupled_tables_expected_error():
    m = P.manifest_entry({"sector_deg": 10.0, "spin_up_s": 1.5, "record_s": 0.4, "dt_s": 5e-6,
                          "fluid": "coupled"})
    assert m is not None, "millfmu/data/dem_work_precision.json is shipped"
    c = m["choice"]
    assert (c["spin_up_s"], c["record_s"]) == (1.5, 0.4) and m["this_table"]["matches_choice"]
    assert c["worst"] <= c["target"] and c["worst_total"] >= c["worst"]
    e = m["this_table"]["expected_error"]
    assert set(e) == set(P.STATISTICS) and all(set(v) == {"V1", "V2", "V3", "V4"} for v in e.values())


def test_cli_refuses_a_folder_without_runs_and_unknown_variants(tmp_path, capsys):
    """``python -m validation.work_precision``: the former ``millfmu dem work-precision``
    with its arguments."""
    assert W.main(["table", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("python -m validation.work_precision: ") and "no finished long run" in err
    assert W.main(["run", "--out", str(tmp_path), "--variants", "dt_7"]) == 2
    assert "variants ['dt_7']: allowed" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())  # nothing written


def test_the_operating_point_starts_as_seed_001s_coupled_protocol():
    """The product's operating point names seed 001's start as a number (the package does not
    import the campaign); it is the campaign's, and the study's spin-up is the protocol's."""
    from validation import seed001

    assert P.OPERATING_POINT["initial_rotation"] == seed001.COUPLED_INITIAL_ROTATION
    assert W.VARIANTS["dt_1e-5"][2] == seed001.COUPLED_SPIN_UP_S
    assert P.RUN_COMMAND.startswith("python -m validation.work_precision run --out DIR")


def test_report_refuses_a_folder_without_a_full_study_before_it_starts(tmp_path):
    """``millfmu report --dem-runs DIR`` reads the study that the checkout's command made;
    a folder without one, or with the quick study's result, is refused by name before the
    report's minutes of work."""
    from millfmu.report import build_report

    with pytest.raises(P.WorkPrecisionError, match="no work_precision.json; make the study"):
        build_report(tmp_path / "report", dem_runs=tmp_path / "none")
    (tmp_path / "quick").mkdir()
    (tmp_path / "quick" / "work_precision.json").write_text(json.dumps({"quick": True, "spin_up": []}))
    with pytest.raises(P.WorkPrecisionError, match="not a full study's result"):
        build_report(tmp_path / "report", dem_runs=tmp_path / "quick")
    assert not (tmp_path / "report" / "report.html").exists()
