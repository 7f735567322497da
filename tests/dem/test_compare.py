"""millfmu dem compare: quantities read from stats.json, differences against the first run."""

import json

import pytest

from millfmu.dem.analysis import compare as C


def _stats(speed_v1, freq):
    zones = [dict(name=n, volume_m3=v, filling=0.5, speed_over_tip_speed=speed_v1 * (i + 1),
                  collision_frequency_per_m3_s=freq * (i + 1),
                  se={"tn": {"quantiles_j": {"q50": 1e-10}}})
             for i, (n, v) in enumerate((("V1", 1.0), ("V2", 1.0), ("V3", 2.0), ("V4", 0.0)))]
    return dict(beads=100, sector_deg=10.0, spin_up_s=0.5, record_s=0.3, zones=zones,
                flow={"power_number": {"value": 0.04},
                      "torque": {"stirrer_fluid_shear_nm": 3.0, "stirrer_total_nm": 4.0}})


def _write(d, st):
    d.mkdir()
    (d / "stats.json").write_text(json.dumps(st))
    return d


def test_rows_and_relative_differences(tmp_path):
    a = _write(tmp_path / "a", _stats(0.1, 1e12))
    b = _write(tmp_path / "b", _stats(0.11, 2e12))
    rows = {r[0]: r[1:] for r in C.compare_rows([a, b])}
    assert rows["bead speed / tip speed V1 [-]"] == ["0.1", "0.11 (+10.0 %)"]
    # chamber density: volume-weighted (1 + 2 + 3 * 2) / 4 = 2.25 e12, doubled in b
    assert rows["collision density, chamber [1/(m3 s)]"] == ["2.25e+12", "4.5e+12 (+100.0 %)"]
    assert rows["stirrer torque: fluid shear share [-]"][0] == "0.75"
    assert "first bead layer / disc angular velocity [-]" not in rows  # absent in both
    assert "rising / falling half (full slice with gravity) [-]" not in rows
    # a full slice with gravity: its budget and circumferential figures
    st = _stats(0.1, 1e12)
    st["flow"]["angular_momentum_budget"] = dict(stirrer_drive_nms=0.028,
                                                 gravity_nms=-8.4e-4, closure_rel=-7.7e-5)
    st["flow"]["circumferential"] = dict(rising_over_falling_half=1.056,
                                         upper_over_lower_half=0.99,
                                         centroid_rising_m=[7e-4, 8e-4],
                                         centroid_up_m=[-2e-4, -3e-4])
    full = _write(tmp_path / "full", st)
    rows = {r[0]: r[1:] for r in C.compare_rows([full, a])}
    assert rows["weight's angular impulse / stirrer drive [-]"] == ["-0.03", "n/a"]
    assert rows["angular-momentum budget closure [-]"] == ["-7.7e-05", "n/a"]
    assert rows["rising / falling half (full slice with gravity) [-]"] == ["1.056", "n/a"]
    assert rows["beads' centroid towards the rising side, time mean [m]"][0] == "0.00075"
    assert rows["beads' centroid upwards, time mean [m]"][0] == "-0.00025"
    md = C.markdown([a, b])
    assert md.splitlines()[0] == "| quantity | a | b |"


def test_bad_folder_is_named(tmp_path):
    with pytest.raises(C.CompareError, match="nope.*no stats.json"):
        C.load_run(tmp_path / "nope")
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "stats.json").write_text("{not json")
    with pytest.raises(C.CompareError, match="unreadable"):
        C.load_run(tmp_path / "x")
