"""`millfmu rates`: breakage rates of both stress models along each operating parameter (seed 000).

- the simple model's rates follow Kwade's scaling laws exactly: SE with v_t^2, d^3 and rho,
  SF with omega n_gb P_cap / (n_p (1 - c_v)), S = SF P(x, SE_P);
- the detailed model moves with the simple one along tip speed and bead density;
- points the stress-energy table cannot resolve are labelled or left empty, never faked.
"""

import csv
import math
from dataclasses import replace
from importlib import resources

import numpy as np
import pytest

from millfmu import calibration as cal
from millfmu import rates as mrates
from millfmu.cli import main
from millfmu.kinetics.vogel_peukert2003 import breakage_probability

YEAST, LIMESTONE = cal.SHIPPED
#: Limestone sizes [m]: the feed's x50, and sizes where the simple model's breakage
#: probability is below one (60 um) and where the capture probability is (150 um).
MINERAL_SIZES = (10e-6, 60e-6, 150e-6)


@pytest.fixture(scope="module")
def limestone():
    simple, detailed = LIMESTONE.scenes()
    return mrates.compute(simple, "limestone", sizes_m=MINERAL_SIZES, detailed_scene=detailed)


@pytest.fixture(scope="module")
def yeast():
    simple, detailed = YEAST.scenes()
    return mrates.compute(simple, "yeast", detailed_scene=detailed)


def _kwade_sf(scene, x, v_t, d, rho_l_w, filling):
    """Kwade's stress frequency written out (seed 000 eqs. 2-5) [1/s], independently of the package."""
    s = scene
    w, rho_p, rho_l = rho_l_w, s.material.density_kg_per_m3, s.suspension.liquid_density_kg_per_m3
    rho_susp = 1.0 / (w / rho_p + (1.0 - w) / rho_l)
    c_p = w * rho_susp / rho_p  # solids volume fraction of the suspension
    n_p = c_p / (math.pi / 6.0 * x**3)  # class number concentration
    c_v = filling * (1.0 - s.mill.bead_porosity)
    n_gb = c_v / (math.pi / 6.0 * d**3)
    omega = v_t / s.mill.stirrer_radius_m
    p_cap = min(n_p * math.pi / 4.0 * x**2 * d, 1.0)
    return s.mill.stress_frequency_factor * omega * n_gb * p_cap / (n_p * (1.0 - c_v)), p_cap


@pytest.mark.parametrize("which", ["limestone", "yeast"])
def test_simple_model_follows_kwades_scaling_laws_exactly(which, limestone, yeast):
    r = limestone if which == "limestone" else yeast
    s, ref = r.scene, r.reference
    saw_partial_capture = False
    for p in mrates.PARAMETERS:
        c = r.curve(p, "simple")
        for k, v in enumerate(c.values):
            point = {**ref, p: v}
            expect_se = {"tip_speed": (v / ref[p]) ** 2, "bead_diameter": (v / ref[p]) ** 3,
                         "bead_density": v / ref[p]}.get(p, 1.0)
            assert c.se_J[k] / c.se_J[r.reference_index(p)] == pytest.approx(expect_se, rel=1e-13, abs=0.0)
            se = math.pi / 12.0 * point["bead_diameter"] ** 3 * point["bead_density"] * point["tip_speed"] ** 2
            assert c.se_J[k] == pytest.approx(se, rel=1e-13)
            se_p = se / (1.0 + s.material.youngs_modulus_Pa / s.beads.youngs_modulus_Pa)
            for x in r.sizes_m:
                q = mrates._size_key(x)
                sf, p_cap = _kwade_sf(s, x, point["tip_speed"], point["bead_diameter"], point["solids_mass_fraction"],
                                      point["filling"])
                saw_partial_capture |= p_cap < 1.0
                assert c.sf[q][k] == pytest.approx(sf, rel=1e-12)
                assert c.p_cap[q][k] == pytest.approx(p_cap, rel=1e-12)
                if s.material.model == "mineral":
                    m_p = s.material.density_kg_per_m3 * math.pi / 6.0 * x**3
                    p_break = float(breakage_probability(x, se_p / m_p, s.material.f_mat_kg_per_J_m,
                                                         s.material.x_w_min_J_m_per_kg))
                else:  # every stress carries SE_P, five decades above the cells' burst energy
                    p_break = 1.0
                assert c.rates[q][k] == pytest.approx(sf * p_break, rel=1e-12)
    if which == "limestone":
        # SF with the capture probability: at 150 um P_cap = n_p V_act < 1, so SF ~ omega n_gb V_act ~ d^-2
        # instead of d^-3 where P_cap = 1.
        assert saw_partial_capture
        c = r.curve("bead_diameter", "simple")
        d = c.values / r.reference["bead_diameter"]
        i = r.reference_index("bead_diameter")
        sf150, sf10 = c.sf[mrates._size_key(150e-6)], c.sf[mrates._size_key(10e-6)]
        assert np.allclose(sf10 / sf10[i], d**-3, rtol=1e-12)
        partial = c.p_cap[mrates._size_key(150e-6)] < 1.0
        assert partial[i] and partial.sum() >= 3
        assert np.allclose((sf150 / sf150[i])[partial], d[partial] ** -2, rtol=1e-12)


@pytest.mark.parametrize("which", ["limestone", "yeast"])
def test_detailed_model_moves_with_the_simple_one_for_tip_speed_and_bead_density(which, limestone, yeast):
    r = limestone if which == "limestone" else yeast
    for q in r.quantities:
        for p in ("tip_speed", "bead_density"):
            simple = r.curve(p, "simple").rates[q]
            det = r.curve(p, "detailed").rates[q]
            if q == mrates._size_key(150e-6):
                continue  # no collision of the table reaches a 150 um particle's threshold
            assert np.all(np.isfinite(det)) and np.all(det >= 0.0) and det[r.reference_index(p)] > 0.0, (p, q)
            ds, dd = np.diff(simple), np.diff(det)
            # Where the simple model rises, the detailed one rises too; where the simple model
            # stays (every stress already breaks: P(SE_P) = 1), the detailed one stays within a
            # factor 1.5 of its reference (yeast along bead density: 0.80 at 6040 kg/m3, the
            # table's collisions fewer with heavier beads while most stresses already break).
            rising = ds > 1e-9 * simple[:-1]
            assert np.all(dd[rising] > 0.0), (p, q, simple, det)
            flat = np.concatenate([[False], ~rising])
            i = r.reference_index(p)
            assert np.all(np.abs(np.log(det[flat] / det[i])) <= math.log(1.5)), (p, q, simple, det)
            if p == "tip_speed":
                assert np.all(rising), (q, simple)  # SF grows with omega
    if which == "limestone":
        # at 60 um the simple model's breakage probability is below one, so bead density raises it too
        s60 = r.curve("bead_density", "simple").rates[mrates._size_key(60e-6)]
        assert np.all(np.diff(s60) > 0.0)
    else:
        # cells: every stress of the simple model carries 1e5 times the burst energy, so bead density
        # changes nothing there; in the detailed model (its own eta_E = 1) 88 % of the stresses at
        # the reference break a cell, so denser beads gain little energy's worth and the table's
        # fewer collisions at 6040 kg/m3 take the rate to 0.79 of the reference's (the density's
        # change read at 8 m/s between its runs at 6 and 10 m/s)
        s_cells = r.curve("bead_density", "simple").rates["disruption_rate"]
        d_cells = r.curve("bead_density", "detailed").rates["disruption_rate"]
        assert np.all(s_cells == s_cells[0])
        assert d_cells[-1] / d_cells[0] == pytest.approx(0.791, abs=0.005)


def test_points_the_table_does_not_resolve_are_labelled_or_refused(limestone):
    # bead diameter and density: the coupled table varies them one at a time (0.5-1.2 mm and
    # 2510-6040 kg/m3, each across a sub-grid of tip speeds and fillings); inside, the grid's
    # fields are scaled by the sub-grid's change, noted per point; a bead diameter beyond them
    # is refused, left empty, never faked
    for p, how in (("bead_diameter", "across tip_speed_m_per_s 6/10/14, filling 0.5/0.6/0.8/0.9"),
                   ("bead_density", "across tip_speed_m_per_s 6/10/14, filling 0.5/0.6/0.8/0.9")):
        c = limestone.curve(p, "detailed")
        i = limestone.reference_index(p)
        assert c.sources[i] == "table" and how in limestone.source_description[p]
        for k, v in enumerate(c.values):
            if k == i:
                continue
            if p == "bead_diameter" and v < 0.5e-3:
                assert c.sources[k] == "refused" and c.notes[k].startswith("refused")
                assert all(math.isnan(r[k]) for r in c.rates.values())
            else:
                assert c.sources[k] == "table" and "scaled" in c.notes[k], (p, v, c.notes[k])
    assert set(limestone.curve("tip_speed", "detailed").sources) == {"table"}
    # a filling outside the table's grid (0.5-0.9) is not an extrapolable axis: refused, left empty
    scene = LIMESTONE.scenes()[1]
    r = mrates.compute(scene, "limestone", sizes_m=(10e-6,), values={"filling": [0.4, 0.8]})
    det = r.curve("filling", "detailed")
    assert math.isnan(det.rates[mrates._size_key(10e-6)][0]) and det.notes[0].startswith("refused")
    assert r.curve("filling", "simple").rates[mrates._size_key(10e-6)][0] > 0.0
    # a scene that does not name the tip speed among its similar axes: 4 m/s is refused too
    no_sim = replace(scene,
                     kinetics=replace(scene.kinetics,
                                      stress_distribution=replace(scene.kinetics.stress_distribution, similar_axes=[])))
    r = mrates.compute(no_sim, "limestone", sizes_m=(10e-6,), values={"tip_speed": [4.0]})
    assert math.isnan(r.curve("tip_speed", "detailed").rates[mrates._size_key(10e-6)][0])


def test_solids_content_moves_both_models_alike(limestone):
    """The DEM has no product particles: along the solids mass fraction only n_p and P_cap change,
    in both models the same way."""
    for q in limestone.quantities[:2]:  # the detailed model breaks no 150 um particle
        a = limestone.relative("solids_mass_fraction", "simple", q)
        b = limestone.relative("solids_mass_fraction", "detailed", q)
        assert np.allclose(a, b, rtol=1e-12)


# ---- command ---------------------------------------------------------------------------------
def test_rates_command_writes_csv_json_png(tmp_path, capsys):
    scene = cal.example_scene("yeast_disruption_detailed.toml")
    path = tmp_path / "y.toml"
    path.write_text(resources.files("millfmu.data").joinpath("examples", "yeast_disruption_detailed.toml").read_text())
    assert main(["rates", str(path), "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "bead density" in out and "similarity assumed" in out
    name = mrates._safe(scene.scene.name)
    rows = list(csv.DictReader((tmp_path / "out" / f"rates_{name}.csv").open()))
    assert set(rows[0]) == set(mrates.CSV_COLUMNS)
    # The value's unit stands beside it (issue 27): every row names it.
    header = next(csv.reader((tmp_path / "out" / f"rates_{name}.csv").open()))
    assert header[header.index("value") + 1] == "value_unit"
    assert {(r["parameter"], r["value_unit"]) for r in rows} == {(p, v[1]) for p, v in mrates.PARAMETERS.items()}
    assert {r["parameter"] for r in rows} == set(mrates.PARAMETERS)
    assert {r["quantity"] for r in rows} == {"S(x)", "disruption_rate"}
    ref = [r for r in rows if r["parameter"] == "tip_speed" and r["value"] == "8"
           and r["quantity"] == "disruption_rate"]
    assert {r["model"] for r in ref} == {"simple", "detailed"} and all(r["rate_over_ref"] == "1" for r in ref)
    assert (tmp_path / "out" / f"rates_{name}.png").stat().st_size > 10_000
    assert (tmp_path / "out" / f"rates_{name}.json").exists()


@pytest.mark.parametrize("argv, key", [
    (["--values", "tip_speed=50"], "--values tip_speed = 50.0: must lie in (0, 40) m/s"),
    (["--values", "filling=0.5,1.5"], "--values filling = 1.5: must lie in (0, 1)\n"),  # no unit '-' after it
    (["--values", "spin=1,2"], "--values"),
    (["--sizes", "0"], "--sizes = '0': must be positive sizes in m"),
    (["--sizes", "1e-9", "1e-6"],
     "--sizes = '1e-09': must lie on the size grid of scene 'pm1-limestone-batch', [2e-08, 0.0002317] m"),
    (["--sizes", "1e-3"], "--sizes = '0.001': must lie on the size grid of scene 'pm1-limestone-batch', ["),
    (["--values", "bead_filling=0.7"], "--values = 'bead_filling': unknown parameter (did you mean filling?)"),
    (["--values", "beads.diameter_m=0.001"], "unknown parameter (did you mean bead_diameter?)"),
])
def test_rates_command_refuses_bad_options(tmp_path, capsys, argv, key):
    scene = tmp_path / "s.toml"
    scene.write_text("")
    assert main(["rates", str(scene), "--out", str(tmp_path / "out"), "--no-plots", *argv]) == 2
    err = capsys.readouterr().err
    assert key in err
    assert not (tmp_path / "out").exists()


def test_rates_command_refuses_a_material_without_stress_model(tmp_path, capsys):
    austin = resources.files("millfmu.data").joinpath("examples", "austin_generic.toml")
    assert main(["rates", str(austin), "--out", str(tmp_path / "out")]) == 2
    assert "material.model" in capsys.readouterr().err


# ---- a negligible reference rate (issue 55) ---------------------------------------------------
def test_negligible_reference_rate_is_said_and_rates_are_shown(tmp_path, capsys, monkeypatch):
    """The default scene (simple model) run as the detailed model keeps the simple model's
    material constants: its rate at the reference point is about 1.6e-7 1/s at 10 um, so ratios to it
    ran from 1e-10 to 1e9 without a word. The output names the reference rates, says they
    are negligible and why, and gives (and draws) the rates themselves in 1/s."""
    import json

    from matplotlib.figure import Figure

    figs = []
    orig = Figure.savefig
    monkeypatch.setattr(Figure, "savefig", lambda self, *a, **k: (figs.append(self), orig(self, *a, **k))[1])
    import millfmu

    scene = tmp_path / "default.toml"
    scene.write_text(millfmu.default_scene_text())
    assert main(["rates", str(scene), "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    flat = " ".join(out.split())  # the explanation is wrapped
    assert "rates at the reference point [1/s]" in flat
    assert "negligible" in flat and "under 1 % of a size class broken in the scene's 1800 s" in flat
    assert "Rates [1/s] below, not over the reference" in flat
    # the table gives rates, not ratios: the detailed model's reference S(10 um) stands in it
    lines = [ln for ln in out.splitlines() if ln.startswith("tip speed") and "10*" in ln]
    assert lines and "1.55e-07" in lines[0]
    assert not any(ln.startswith("tip speed") and "8.19e-10" in ln for ln in out.splitlines())  # the old ratio
    doc = json.loads((tmp_path / "out" / "rates_pm1-limestone-batch.json").read_text())
    ref = doc["reference_rates_per_s"]["detailed"]["S(10 um)"]
    assert ref < doc["negligible_rate_per_s"] == pytest.approx(0.01 / 1800.0)
    assert doc["shown"].startswith("rates [1/s]")
    fig = figs[-1]
    panels = [ax for ax in fig.axes if ax.get_visible() and ax.axison]
    assert {ax.get_ylabel() for ax in panels} == {"breakage rate [1/s]"}
    assert "negligible" in fig._suptitle.get_text()


def test_calibrated_pair_keeps_ratios(yeast):
    """Where every reference rate breaks more than 1 % in the run, ratios stay."""
    assert not yeast.absolute and yeast.why_absolute() == ""
    assert yeast.reference_rate("detailed", "disruption_rate") > yeast.negligible_rate_per_s
    assert "rates over their value at the reference point" in mrates.summary(yeast)


def test_the_detailed_models_regime_is_stated(limestone, yeast):
    """The breakage probability per stress at the reference says which collisions the
    detailed model's rate follows: limestone's stand-in f_Mat puts S(10 um) on the foot of the
    breakage curve (P = 0.146, the trend study's figure; energy-limited, its rate follows the
    collision power), the yeast pair's sourced burst energy near its top (P = 0.88)."""
    p_lime = limestone.p_break_at_reference()[mrates._size_key(10e-6)]
    assert p_lime == pytest.approx(0.146, abs=0.005)
    note = limestone.regime_note()
    assert "energy-limited" in note and "S(10 um) 0.15" in note
    assert min(yeast.p_break_at_reference().values()) > mrates.ENERGY_LIMITED_P
    assert yeast.regime_note() == ""
    doc = __import__("json").loads(mrates.to_json(limestone))
    assert doc["detailed_p_break_at_reference"]["S(10 um)"] == pytest.approx(p_lime)
    assert doc["detailed_regime"].startswith("detailed model energy-limited")


def test_a_run_warns_where_its_detailed_model_is_energy_limited():
    """MillModel says it before anything runs: the detailed example (limestone, stand-in
    f_Mat) breaks 4.4 % of its stresses over the feed; the yeast pair's detailed scene most;
    the default scene (simple model) has no such regime."""
    from millfmu.mill import MillModel

    lime = MillModel(LIMESTONE.scenes()[1])
    assert lime.p_break_per_stress_of_feed() == pytest.approx(0.044, abs=0.003)
    assert any(w.startswith("detailed model energy-limited") for w in lime.warnings)
    cells = MillModel(YEAST.scenes()[1])
    assert cells.p_break_per_stress_of_feed() > 0.5
    assert not any("energy-limited" in w for w in cells.warnings)
    simple = MillModel(LIMESTONE.scenes()[0])
    assert math.isnan(simple.p_break_per_stress_of_feed()) and simple.regime_warning() is None


def test_a_zone_with_collisions_but_no_stated_error_gets_no_band(monkeypatch):
    """Where a zone that collides has no stated error (no check measured the axis there), the
    band's edges would leave it unmoved: the point gets no band and a note says why, instead
    of a band narrower than the table knows."""
    from tests._stated_error import density_unmeasured

    density_unmeasured(monkeypatch, "collision_frequency")
    simple, detailed = LIMESTONE.scenes()
    r = mrates.compute(simple, "limestone", sizes_m=MINERAL_SIZES, detailed_scene=detailed,
                       values={"bead_density": [2510.0, 6040.0]})
    c = r.curve("bead_density", "detailed")
    q = mrates._size_key(10e-6)
    lo, hi = c.band[q]
    assert lo[0] < c.rates[q][0] < hi[0]  # the reference: stated in every zone
    assert math.isnan(lo[1]) and math.isnan(hi[1]) and math.isfinite(c.rates[q][1])
    assert "no band: zones V1, V2, V3, V4 have collisions but no stated error here" in c.notes[1]
