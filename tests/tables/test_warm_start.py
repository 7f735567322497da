"""Warm starts of DEM table points (millfmu.dem.tables.warm_start): the settled state kept
beside a point's result, read back only by its own layout and kernel version, scaled to a
new tip speed; which stored state a new point starts from; the start recorded in the
point's result and the table's manifest. The DEM parts run a few hundred steps of a small
coupled sector; the slow test compares a warm-started point with the table's cold one."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from millfmu.dem import tables as T
from millfmu.dem.tables import warm_start as W
from millfmu.dem.scene import scene_from_dict
from millfmu.stress_tables.spec import scene_at_point
from millfmu.stress_tables.table import read_table_ref
from tests.tables._builders import analytic_builder, spec
from tests._run_stats import stats_without_wall_clock


@pytest.fixture(scope="module")
def coupled():
    return read_table_ref("coupled")


def _scene(coupled, **point):
    base = {"tip_speed_m_per_s": 10.0, "filling": 0.8, "bead_diameter_m": 0.8e-3,
            "bead_density_kg_per_m3": 2510.0}
    return scene_at_point(coupled.spec().scene, {**base, **point})


def _arrays(n=5, shape=(3, 1, 4)):
    rng = np.random.default_rng(1)
    a = {"x_m": rng.normal(size=(n, 3)), "v_m_per_s": rng.normal(size=(n, 3)).astype(np.float32),
         "w_rad_per_s": rng.normal(size=(n, 3)).astype(np.float32),
         "fluid_at_bead": rng.normal(size=(n, 6)).astype(np.float32)}
    for k in W._LIQUID:
        a["liquid_" + k] = rng.normal(size=shape).astype(np.float32)
    return a


def test_scaling_by_the_tip_speed_ratio():
    a = _arrays()
    s = W.scaled(a, 1.5)
    np.testing.assert_array_equal(s["x_m"], a["x_m"])
    np.testing.assert_allclose(s["v_m_per_s"], 1.5 * a["v_m_per_s"], rtol=1e-6)
    np.testing.assert_allclose(s["w_rad_per_s"], 1.5 * a["w_rad_per_s"], rtol=1e-6)
    for k, p in (("ur", 1), ("ut", 1), ("uz", 1), ("p", 2), ("k", 2), ("e", 3), ("nu_t", 1),
                 ("eps_c", 0), ("eps_r", 0), ("eps_c_old", 0)):
        np.testing.assert_allclose(s["liquid_" + k], 1.5 ** p * a["liquid_" + k], rtol=1e-6)
    np.testing.assert_allclose(s["fluid_at_bead"][:, :3], 1.5 * a["fluid_at_bead"][:, :3], rtol=1e-6)
    np.testing.assert_allclose(s["fluid_at_bead"][:, 3:], 2.25 * a["fluid_at_bead"][:, 3:], rtol=1e-6)
    assert all(v.dtype == np.float64 for v in s.values())
    # the state itself is not changed
    assert W.scaled(a, 1.0)["v_m_per_s"] is not a["v_m_per_s"]


def test_a_state_reads_back_only_in_its_layout_and_kernel_version(tmp_path, coupled):
    sc = _scene(coupled)
    a = _arrays()
    path = W.save_state(W.state_file(tmp_path, sc, "kv-1"), a, {"scene": sc, "kernel_version": "kv-1",
                                                               "start": {"start": "cold"}})
    assert path.name.endswith(W.STATE_SUFFIX) and path.parent == tmp_path
    assert not list(tmp_path.glob(".tmp-state-*"))
    got, meta = W.read_state(path, "kv-1")
    assert meta["scene"] == sc and meta["format"] == W.STATE_FORMAT and meta["start"] == {"start": "cold"}
    for k, v in a.items():
        np.testing.assert_array_equal(got[k], v)
        assert got[k].dtype == v.dtype
    assert got["x_m"].dtype == np.float64
    # another kernel version: not used
    with pytest.raises(W.WarmStartError, match="kernel version kv-1, the installed DEM is kv-2"):
        W.read_state(path, "kv-2")
    # named by the scene at the point and the kernel version
    assert W.state_file(tmp_path, sc, "kv-2") != path
    assert W.state_file(tmp_path, _scene(coupled, tip_speed_m_per_s=12.0), "kv-1") != path
    # another layout, a damaged file: refused by name
    other = tmp_path / "other.state.npz"
    np.savez_compressed(other, meta=np.array(json.dumps({"format": 99})), **a)
    with pytest.raises(W.WarmStartError, match="state layout 99"):
        W.read_state(other)
    bad = tmp_path / "bad.state.npz"
    bad.write_bytes(path.read_bytes()[:200])
    with pytest.raises(W.WarmStartError, match="not a readable state"):
        W.read_state(bad)
    assert [p for p, _ in W.candidates_in(tmp_path)] == [path]  # the unreadable ones skipped
    assert W.candidates_in(tmp_path, names=[]) == []


def test_a_new_point_starts_from_the_nearest_state_with_the_same_beads(coupled):
    steel = _scene(coupled, bead_density_kg_per_m3=7800.0)
    kv = "kv"

    def cand(name, kernel=kv, **point):
        return (f"/s/{name}.state.npz", {"scene": _scene(coupled, **point), "kernel_version": kernel})

    glass = cand("a-glass")
    zirconia = cand("b-zirconia", bead_density_kg_per_m3=6040.0)
    fast_zirconia = cand("c-fast", bead_density_kg_per_m3=6040.0, tip_speed_m_per_s=14.0)
    small = cand("d-small", bead_diameter_m=0.5e-3, bead_density_kg_per_m3=7800.0)
    lower = cand("e-lower", filling=0.7, bead_density_kg_per_m3=7800.0)
    stale = cand("f-stale", kernel="other", bead_density_kg_per_m3=7700.0)
    own = cand("g-own", bead_density_kg_per_m3=7800.0)
    everything = [glass, zirconia, fast_zirconia, small, lower, stale, own]
    # the nearest in log density among the same beads, filling and kernel (not itself)
    assert W.choose_anchor(steel, everything, kv)[0] == zirconia[0]
    # (without the measured range: the nearest whatever its ratios; within it, the 14 m/s
    # state is too far for a 10 m/s point: test_a_warm_start_jumps_only_as_far_as_measured)
    assert W.choose_anchor(steel, [glass, fast_zirconia, small, lower, stale], kv, within=None)[0] == fast_zirconia[0]
    assert W.choose_anchor(steel, [glass, fast_zirconia, small, lower, stale], kv)[0] == glass[0]
    assert W.choose_anchor(steel, [glass, small, lower, stale], kv)[0] == glass[0]
    # another diameter or filling: another bead count, a cold start
    assert W.choose_anchor(steel, [small, lower, stale, own], kv) is None
    assert W.choose_anchor(_scene(coupled, bead_diameter_m=1.2e-3), everything, kv) is None
    assert W.choose_anchor(steel, [], kv) is None
    # distance over tip speed, density and viscosity together
    assert W.distance(fast_zirconia[1]["scene"], steel) == pytest.approx(
        math.hypot(math.log(14 / 10), math.log(6040 / 7800)))
    visc = dict(steel, fluid=dict(steel["fluid"], viscosity_Pa_s=0.01))
    assert W.compatible(visc, steel)
    assert W.distance(visc, steel) == pytest.approx(math.log(0.01 / steel["fluid"]["viscosity_Pa_s"]))
    # any other key of the scene: not the same run
    other_seed = dict(steel, run=dict(steel["run"], seed=2))
    assert not W.compatible(other_seed, glass[1]["scene"])
    # equal distances: the first by file name, whatever the order given
    slow = cand("h-slow", tip_speed_m_per_s=8.0, bead_density_kg_per_m3=7800.0)
    quick = cand("i-quick", tip_speed_m_per_s=12.5, bead_density_kg_per_m3=7800.0)
    assert W.distance(slow[1]["scene"], steel) == pytest.approx(W.distance(quick[1]["scene"], steel))
    assert W.choose_anchor(steel, [quick, slow], kv, within=None)[0] == slow[0]


def test_a_warm_start_jumps_only_as_far_as_measured(coupled, capsys):
    """WARM_RANGE: a state is used only where the point's tip speed is 1-1.2 times the
    state's, its bead density 1-3.11 times (7,800 / 2,510: steel from glass) and its viscosity
    the same; beyond, the point starts cold and its record and stderr say why."""
    kv = "kv"

    def cand(name, **point):
        return (f"/s/{name}.state.npz", {"scene": _scene(coupled, **point), "kernel_version": kv})

    glass = cand("a-glass")  # 2,510 kg/m3, 10 m/s
    # inside, at both ends of each measured jump (steel from glass: the shipped example)
    for point in ({"bead_density_kg_per_m3": 7800.0}, {"bead_density_kg_per_m3": 2510.0 * 1.0001},
                  {"tip_speed_m_per_s": 12.0}, {"tip_speed_m_per_s": 10.001},
                  {"tip_speed_m_per_s": 12.0, "bead_density_kg_per_m3": 7800.0}):
        assert W.pick_start(_scene(coupled, **point), [glass], kv) == (glass, None), point
    # beyond: heavier than measured, faster than measured, lighter or slower than the state
    # (never measured), another viscosity (never varied)
    beyond = {"bead_density_kg_per_m3 8000 against the state's 2510 (ratio 3.19; warm starts measured for 1 to 3.11)":
              {"bead_density_kg_per_m3": 8000.0},
              "tip_speed_m_per_s 12.5 against the state's 10 (ratio 1.25; warm starts measured for 1 to 1.2)":
              {"tip_speed_m_per_s": 12.5},
              "bead_density_kg_per_m3 2000 against the state's 2510 (ratio 0.797": {"bead_density_kg_per_m3": 2000.0},
              "tip_speed_m_per_s 8 against the state's 10 (ratio 0.8": {"tip_speed_m_per_s": 8.0}}
    for why, point in beyond.items():
        pick, got = W.pick_start(_scene(coupled, **point), [glass], kv)
        assert pick is None and got.startswith("the nearest stored state with the same beads is too far: " + why)
    sc = _scene(coupled)
    visc = dict(sc, fluid=dict(sc["fluid"], viscosity_Pa_s=2e-3))
    pick, why = W.pick_start(visc, [glass], kv)
    assert pick is None and "viscosity_Pa_s 0.002 against the state's 0.001002" in why and "measured for 1)" in why
    # a farther state within the range is taken before a nearer one beyond it
    heavier = cand("b-heavier", bead_density_kg_per_m3=6040.0)  # 5,000 from 6,040: lighter, beyond
    assert W.pick_start(_scene(coupled, bead_density_kg_per_m3=5000.0), [glass, heavier], kv) == (glass, None)
    # no state with the same beads: cold, nothing to say
    assert W.pick_start(_scene(coupled, bead_diameter_m=1.2e-3), [glass], kv) == (None, None)
    assert "why_cold" not in W.cold_record(scene_from_dict(sc))


def test_a_point_beyond_the_range_runs_cold_and_says_why(coupled, monkeypatch, capsys):
    """run_point with a compatible state beyond WARM_RANGE: the cold run (the scene's own
    spin-up), its start record naming why, the same on stderr (the DEM stubbed out)."""
    import millfmu.dem.run as R

    ran = []
    monkeypatch.setattr(R, "make_simulation", lambda scene, threads: ("sim", None))
    monkeypatch.setattr(R, "run_scene", lambda scene, out, **kw: ran.append(scene.spin_up_s) or "stats")
    monkeypatch.setattr(W, "_loop", lambda scene, sim: {})
    glass = ("/s/a-glass.state.npz", {"scene": _scene(coupled), "kernel_version": "kv"})
    light = _scene(coupled, bead_density_kg_per_m3=2000.0)
    stats, start = W.run_point(scene_from_dict(light), light, "/nowhere", candidates=[glass],
                               warm_spin_up_s=0.2, kernel_version="kv")
    assert stats == "stats" and ran == [1.5]
    assert start["start"] == "cold" and start["spin_up_s"] == 1.5
    assert "bead_density_kg_per_m3 2000 against the state's 2510 (ratio 0.797" in start["why_cold"]
    err = capsys.readouterr().err
    assert "table point {'tip_speed_m_per_s': 10.0, 'bead_density_kg_per_m3': 2000.0, 'viscosity_Pa_s': 0.001002} " \
           "starts cold: the nearest stored state with the same beads is too far" in err
    # cold without a state of its beads at hand, or without warm starts: nothing said
    for cands, su in (([], 0.2), ([glass], None)):
        assert W.run_point(scene_from_dict(light), light, "/nowhere", candidates=cands, warm_spin_up_s=su,
                           kernel_version="kv")[1] == {"start": "cold", "spin_up_s": 1.5}
    assert capsys.readouterr().err == ""


def test_the_builder_starts_warm_only_from_the_states_there_when_the_build_starts(tmp_path):
    (tmp_path / "one.state.npz").write_bytes(b"")
    (tmp_path / "two.state.npz").write_bytes(b"")
    (tmp_path / "a-point.json").write_text("{}")
    cold = T.DemBuilder(threads=1)
    warm = T.DemBuilder(threads=1, warm_spin_up_s=0.2)
    assert warm.with_states(tmp_path).warm_from == ("one.state.npz", "two.state.npz")
    assert warm.with_states(tmp_path).state_dir == str(tmp_path)
    assert warm.with_states(tmp_path, reuse=False).warm_from is None  # --force: all cold
    assert cold.with_states(tmp_path).warm_from is None  # the states kept, none used
    assert cold.with_states(tmp_path).state_dir == str(tmp_path)
    assert warm.with_states(tmp_path / "none").warm_from == ()  # the shipped ones only
    assert T.builder_id_of(warm.with_states(tmp_path)) == T.DemBuilder.builder_id
    assert W.warm_candidates(tmp_path, None) == []
    # the unreadable ones left out; the shipped ones always among them
    shipped = [p for p, _ in W.warm_candidates(tmp_path, ("one.state.npz",))]
    assert shipped == W.shipped_states()
    # an on-demand build's builder starts warm
    from millfmu.dem.tables.on_demand import default_builder

    assert default_builder(read_table_ref("coupled")).warm_spin_up_s == W.WARM_SPIN_UP_S


def test_the_package_ships_the_coupled_tables_anchor_state(tmp_path, coupled):
    """millfmu/data/coupled_anchor.state.npz: the settled state of the coupled table's anchor
    (0.8 mm glass, 10 m/s, 80 %) made by the table's kernels, among every warm build's
    candidates, so that a fresh install's first new point with those beads starts warm."""
    (path,) = [p for p in W.shipped_states() if p.name == "coupled_anchor.state.npz"]
    spec = coupled.spec()
    anchor = {**spec.anchor(), **{k: float(v) for k, v in coupled.one_at_a_time_ref.items()}}
    kv = coupled.manifest["kernel_version"]
    arrays, meta = W.read_state(path, kv)
    assert meta["scene"] == scene_at_point(spec.scene, anchor)
    assert meta["start"] == {"start": "cold", "spin_up_s": 1.5}
    assert arrays["x_m"].shape == (6536, 3) and path.stat().st_size < 600_000
    # beads heavier than glass but lighter than zirconia start from it (steel from the
    # zirconia state, nearer), the table's own points not
    cands = W.warm_candidates(tmp_path, ())
    light = _scene(coupled, bead_density_kg_per_m3=3000.0)
    assert W.choose_anchor(light, cands, kv)[0] == path
    assert W.starts_warm(light, tmp_path, (), kv)
    steel = _scene(coupled, bead_density_kg_per_m3=7800.0)
    assert not W.starts_warm(_scene(coupled), tmp_path, (), kv)
    assert not W.starts_warm(_scene(coupled, bead_diameter_m=1.4e-3), tmp_path, (), kv)
    assert not W.starts_warm(steel, tmp_path, (), "another-kernel")


def test_the_package_ships_the_density_sub_grids_states(tmp_path, coupled):
    """millfmu/data/coupled_zirconia_*.state.npz: the settled states of the coupled table's
    zirconia points across its tip speeds and fillings (at 10 m/s and 80 % a later cold run
    of that point: the table's node there is older than the states kept), so that a new bead
    density above zirconia's starts every point of its sub-grid warm (up to 3.11 times
    zirconia's, the range warm starts were measured in)."""
    spec = coupled.spec()
    kv = coupled.manifest["kernel_version"]
    ships = {p.name: p for p in W.shipped_states() if p.name.startswith("coupled_zirconia_")}
    sub = spec.across["bead_density_kg_per_m3"]
    want = [{"tip_speed_m_per_s": v, "filling": f, "bead_density_kg_per_m3": 6040.0}
            for v in sub["tip_speed_m_per_s"] for f in sub["filling"]]
    assert len(want) == 12 and len(ships) == 12
    for p in want:
        name = f"coupled_zirconia_{p['tip_speed_m_per_s']:g}mps_{round(p['filling'] * 100)}pct.state.npz"
        arrays, meta = W.read_state(ships[name], kv)
        assert meta["scene"] == scene_at_point(spec.scene, {**p, "bead_diameter_m": 0.8e-3}), name
        assert meta["start"] == {"start": "cold", "spin_up_s": 1.5}
        assert ships[name].stat().st_size < 600_000
        carbide = _scene(coupled, **{**p, "bead_density_kg_per_m3": 14500.0})
        assert W.choose_anchor(carbide, W.warm_candidates(tmp_path, ()), kv)[0] == ships[name]
        steel = _scene(coupled, **{**p, "bead_density_kg_per_m3": 7800.0})
        assert W.choose_anchor(steel, W.warm_candidates(tmp_path, ()), kv)[0] == ships[name]


def test_a_warm_start_costs_its_shorter_spin_up(tmp_path, coupled):
    """The builder's cost estimate of a point it would start warm counts the warm spin-up
    (0.2 + 0.4 s against 1.5 + 0.4 s), and the on-demand plan says so; the table's points
    calibrate seconds per cost at their cold cost."""
    from millfmu.dem.tables import cache
    from millfmu.dem.tables.build import seconds_per_cost
    from millfmu.dem.tables.on_demand import default_builder, plan

    kv = coupled.manifest["kernel_version"]
    if cache.dem_kernel_version() != kv:
        pytest.skip("the installed DEM is not the coupled table's kernel version")
    spec = coupled.spec()
    steel = {**spec.anchor(), "bead_diameter_m": 0.8e-3, "bead_density_kg_per_m3": 7800.0}
    cold = T.DemBuilder()
    warm = T.DemBuilder(warm_spin_up_s=0.2).with_states(tmp_path / "points")
    assert warm.relative_cost(spec.scene, steel) == pytest.approx(cold.relative_cost(spec.scene, steel) * 0.6 / 1.9)
    big = dict(steel, bead_diameter_m=1.2e-3)
    assert warm.relative_cost(spec.scene, big) == cold.relative_cost(spec.scene, big)
    b = default_builder(coupled)
    pl = plan(coupled, {"bead_density_kg_per_m3": 7800.0}, b, kv, cache_dir=tmp_path, workers=2)
    # the density is run across 6/10/14 m/s x 50/60/80/90 %: steel at each of the 12, each warm
    # from a shipped state with its beads (the glass anchor's at 10 m/s, 80 %, the zirconia
    # sub-grid points' elsewhere)
    assert len(pl.todo) == 12 and all(how == "warm" for how, _ in pl.starts)
    (k,) = [i for i, p in enumerate(pl.todo)
            if p == {k_: v for k_, v in steel.items() if k_ != "bead_diameter_m"}]
    cold_costs = [cold.relative_cost(spec.scene, p) for p in pl.todo]
    assert pl.costs == [pytest.approx(c * 0.6 / 1.9) for c in cold_costs]
    # two points at once share the cores: each at the speed of its share of them
    from millfmu.dem.tables.build import builder_sharing_cores

    shared = builder_sharing_cores(cold, 2)
    assert pl.seconds_per_cost == pytest.approx(seconds_per_cost(coupled, shared))
    assert not list((tmp_path / "points").glob("*"))  # a plan writes nothing
    # the line says how the points start; started cold (a builder that starts none warm) they
    # cost the steps' ratio more
    assert pl.line().startswith("73 points, 61 already built, 12 to run, 12 started warm from stored settled "
                                "states (about ")
    pc = plan(coupled, {"bead_density_kg_per_m3": 7800.0}, cold, kv, cache_dir=tmp_path, workers=2)
    assert all(how == "cold" for how, _ in pc.starts) and ", all started cold (about " in pc.line()
    assert pl.runs_s() == pytest.approx(pc.runs_s() * 0.6 / 1.9)
    # calibrated on the installed DEM's runs of the point (MEASURED_SPEED: cold 280 s, warm
    # 103 s on 2 threads, 403 and 145 s on 1; the whole on-demand command 108 s), not on the
    # table's build, whose sources ran 3.2 times slower: within 15 % of each
    one = plan(coupled, {"bead_density_kg_per_m3": 7800.0}, b.with_threads(1), kv, cache_dir=tmp_path)
    two = plan(coupled, {"bead_density_kg_per_m3": 7800.0}, b.with_threads(2), kv, cache_dir=tmp_path)
    assert one.costs[k] * one.seconds_per_cost == pytest.approx(145.0, rel=0.15)
    assert two.costs[k] * two.seconds_per_cost == pytest.approx(103.0, rel=0.15)
    one_c = plan(coupled, {"bead_density_kg_per_m3": 7800.0}, cold.with_threads(1), kv, cache_dir=tmp_path)
    two_c = plan(coupled, {"bead_density_kg_per_m3": 7800.0}, cold.with_threads(2), kv, cache_dir=tmp_path)
    assert one_c.costs[k] * one_c.seconds_per_cost == pytest.approx(403.0, rel=0.15)
    assert two_c.costs[k] * two_c.seconds_per_cost == pytest.approx(280.0, rel=0.15)
    # lighter beads than the shipped state's: too far, cold, and the line says why
    pd = plan(coupled, {"bead_density_kg_per_m3": 2000.0}, b, kv, cache_dir=tmp_path, workers=2)
    assert "12 to run, all started cold (" in pd.line() and \
        "; 1 of them: the nearest stored state with the same beads is too far: bead_density_kg_per_m3 " \
        "2000 against the state's 2510 (ratio 0.797; warm starts measured for 1 to 3.11); " in pd.line()
    assert pd.costs == [pytest.approx(cold.relative_cost(spec.scene, p)) for p in pd.todo]


def test_points_run_at_once_share_the_cores():
    """A local build running several points at once gives each its share of the cores (each
    point on all of them oversubscribed them: on 2 cores two steel points ran 3.5 min where
    one thread each takes 2.4); a builder given a thread count, or one without threads,
    keeps it."""
    import os

    from millfmu.dem.tables.build import builder_sharing_cores

    cores = os.cpu_count() or 1
    assert builder_sharing_cores(T.DemBuilder(), 2).threads == max(1, cores // 2)
    assert builder_sharing_cores(T.DemBuilder(), 1).threads is None
    assert builder_sharing_cores(T.DemBuilder(threads=3), 2).threads == 3
    stand_in = analytic_builder
    assert builder_sharing_cores(stand_in, 4) is stand_in
    assert T.DemBuilder().with_threads(1) == T.DemBuilder(threads=1)


def test_the_measured_speed_calibrates_only_its_scene_and_kernel(coupled, monkeypatch):
    """MEASURED_SPEED: seconds per cost unit from its runs (summed wall time over summed
    cost) for the coupled table's scene with its DEM kernel version; another scene or
    another installed kernel version: the table's own points_wall_time_s."""
    from millfmu.dem.tables import cache
    from millfmu.dem.tables import dem_builder as D
    from millfmu.dem.tables.build import seconds_per_cost

    m = D.MEASURED_SPEED
    scene = coupled.manifest["scene"]

    def speed(threads):
        runs = [r for r in m["runs"] if r.get("threads", m["threads"]) == threads]
        assert len(runs) == 2
        return sum(r["wall_time_s"] for r in runs) / sum(D._cost(scene, r["point"], r["spin_up_s"]) for r in runs)

    want = speed(2)
    monkeypatch.setattr(cache, "dem_kernel_version", lambda: m["kernel_version"])
    assert D.measured_seconds_per_cost(coupled) == pytest.approx(want)
    assert seconds_per_cost(coupled, T.DemBuilder()) == pytest.approx(want)
    # one thread: its own runs, 1.43 times as long; a count not measured: the default's
    assert seconds_per_cost(coupled, T.DemBuilder(threads=1)) == pytest.approx(speed(1))
    assert speed(1) / want == pytest.approx((403 + 145) / (280 + 103))
    assert seconds_per_cost(coupled, T.DemBuilder(threads=8)) == pytest.approx(want)
    # the shipped table's points: 4.0 times as long per cost unit (28 of its 61 run by older,
    # slower sources of the same kernel version, the 11 across at 0.5 mm beside other runs)
    table_spc = coupled.manifest["points_wall_time_s"] / sum(
        T.DemBuilder().relative_cost(scene, p) for p in coupled.spec().points())
    assert table_spc / want == pytest.approx(4.0, abs=0.1)
    other = read_table_ref("prescribed")
    assert D.measured_seconds_per_cost(other) is None
    monkeypatch.setattr(cache, "dem_kernel_version", lambda: "sha256:another")
    assert D.measured_seconds_per_cost(coupled) is None
    assert seconds_per_cost(coupled, T.DemBuilder()) == pytest.approx(table_spc)


class _WarmStub:
    """A stand-in for the DEM builder's cost and start (no DEM): relative cost filling x tip
    speed x steps, the steps (spin-up + recording) 0.6 s warm and 1.9 s cold; after
    with_states it starts the 70 % points warm and says the 50 % ones are too far."""

    builder_id = T.DEM_BUILDER_ID

    def __init__(self, states=False):
        self.states = states

    def with_states(self, folder, reuse=True):
        return _WarmStub(states=reuse)

    def start_of(self, scene, point):
        if not self.states:
            return "cold", None
        return ("warm", None) if point["filling"] == 0.7 else ("cold", "too far")

    def relative_cost(self, scene, point):
        return self.cost_as_started(scene, point, {"start": self.start_of(scene, point)[0]})

    def cost_as_started(self, scene, point, start):
        return point["filling"] * point["tip_speed_m_per_s"] * (0.6 if start["start"] == "warm" else 1.9)

    def __call__(self, scene, point):
        out = analytic_builder(scene, point)
        out["wall_time_s"] = 2.0 * self.relative_cost(scene, point)  # 2 s per unit
        out["start"] = {"start": self.start_of(scene, point)[0]}
        return out


def test_the_estimate_follows_how_each_point_starts(tmp_path, monkeypatch):
    """The on-demand plan costs each point to run at the steps of its start (a warm one the
    step ratio 0.6 / 1.9 of a cold one) and its line says how they start."""
    import millfmu.dem.tables.cache as C
    from millfmu.dem.tables.on_demand import plan

    monkeypatch.setattr(C, "dem_kernel_version", lambda: "k")
    small = T.TableSpec(scene={"name": "analytic"}, grid={"tip_speed_m_per_s": [6.0, 10.0], "filling": [0.5, 0.7]},
                        kernel_version="k", builder_id=T.DEM_BUILDER_ID)
    done = T.get_table(small, _WarmStub(), cache_dir=tmp_path / "a", executor="serial", progress=False)
    assert done.manifest["point_starts"]["warm"] == 2  # its 70 % points: calibrated at their warm cost
    pl = plan(done, {"tip_speed_m_per_s": 14.0}, _WarmStub(), "k", cache_dir=tmp_path / "b", workers=1)
    assert [p["filling"] for p in pl.todo] == [0.5, 0.7]
    assert pl.starts == [("cold", "too far"), ("warm", None)]
    assert pl.costs == [pytest.approx(0.5 * 14 * 1.9), pytest.approx(0.7 * 14 * 0.6)]
    assert pl.seconds_per_cost == pytest.approx(2.0)  # the table's points, each at the cost of its start
    assert pl.line() == ("6 points, 4 already built, 2 to run, 1 started warm from stored settled states, "
                         "1 cold (1 of them: too far) (about 38 s of point runs, 38 s on 1 worker)")
    one = plan(done, {"tip_speed_m_per_s": 14.0, "filling": 0.7}, _WarmStub(), "k", cache_dir=tmp_path / "b")
    warm = [c for p, c in zip(one.todo, one.costs) if p["filling"] == 0.7 and p["tip_speed_m_per_s"] == 14.0]
    assert warm == [pytest.approx(0.7 * 14 * 1.9 * 0.6 / 1.9)]


class _StartingBuilder:
    """The analytic builder with the DEM builder's state hooks: records the folder it was
    given and says it started warm at 14 m/s."""

    seen = []

    def __init__(self, folder=None, warm_from=()):
        self.folder, self.warm_from = folder, warm_from

    def with_states(self, folder, reuse=True):
        _StartingBuilder.seen.append((str(folder), reuse))
        return _StartingBuilder(folder, ("x.state.npz",) if reuse else ())

    def __call__(self, scene, point):
        out = analytic_builder(scene, point)
        out["start"] = ({"start": "warm", "from": {"tip_speed_m_per_s": 10.0}, "spin_up_s": 0.2}
                        if point["tip_speed_m_per_s"] == 14.0 else {"start": "cold", "spin_up_s": 1.5})
        return out


def test_the_table_manifest_records_how_each_point_started(tmp_path):
    s = spec({"tip_speed_m_per_s": [10.0, 14.0], "filling": [0.7]})
    b = _StartingBuilder()
    b.builder_id = T.builder_id_of(analytic_builder)
    _StartingBuilder.seen.clear()
    t = T.get_table(s, b, cache_dir=tmp_path, executor="serial", progress=False)
    assert _StartingBuilder.seen == [(str(tmp_path / "points"), True)]
    st = t.manifest["point_starts"]
    assert st["warm"] == 1
    assert st["points"] == [
        {"point": {"tip_speed_m_per_s": 10.0, "filling": 0.7}, "start": "cold", "spin_up_s": 1.5},
        {"point": {"tip_speed_m_per_s": 14.0, "filling": 0.7}, "start": "warm",
         "from": {"tip_speed_m_per_s": 10.0}, "spin_up_s": 0.2}]
    # the point's stored result says so too
    store = T.PointStore(tmp_path / "points")
    assert store.get(s, {"tip_speed_m_per_s": 14.0, "filling": 0.7})["start"]["start"] == "warm"
    # a builder without the hooks, a table without starts: nothing recorded
    t2 = T.get_table(spec({"tip_speed_m_per_s": [6.0, 8.0], "filling": [0.7]}), analytic_builder,
                     cache_dir=tmp_path, executor="serial", progress=False)
    assert "point_starts" not in t2.manifest
    # a forced rebuild: no state used
    _StartingBuilder.seen.clear()
    T.get_table(s, b, cache_dir=tmp_path, executor="serial", progress=False, force=True)
    assert _StartingBuilder.seen == [(str(tmp_path / "points"), False)]


def test_clear_stale_drops_the_states_of_other_kernels(tmp_path, coupled):
    pts = tmp_path / "points"
    sc = _scene(coupled)
    keep = W.save_state(W.state_file(pts, sc, "kv-now"), _arrays(), {"scene": sc, "kernel_version": "kv-now"})
    drop = W.save_state(W.state_file(pts, sc, "kv-old"), _arrays(), {"scene": sc, "kernel_version": "kv-old"})
    (pts / f"junk{W.STATE_SUFFIX}").write_bytes(b"junk")
    removed = T.clear_cache(tmp_path, only_not_ok=True, kernel_version="kv-now")
    assert sorted(removed) == sorted([f"points/{drop.name}", f"points/junk{W.STATE_SUFFIX}"])
    assert keep.exists() and not drop.exists()
    T.clear_cache(tmp_path, kernel_version="kv-now")
    assert not keep.exists()


# ---- with the DEM: a small coupled sector --------------------------------------------------
def _small(coupled, **point):
    """The coupled table's scene in a 5 degree sector, 0.5 ms spin-up and recording."""
    d = _scene(coupled, **point)
    d["mill"]["sector_deg"] = 5.0
    d["run"].update(spin_up_s=5e-4, record_s=5e-4, sample_every_s=2.5e-4)
    return d


def test_a_cold_point_runs_as_run_scene_and_keeps_its_state(tmp_path, coupled):
    pytest.importorskip("numba")
    from millfmu.dem.run import run_scene
    from millfmu.dem.scene import scene_from_dict

    d = _small(coupled)
    s = scene_from_dict(d)
    run_scene(s, tmp_path / "plain", progress=False, threads=1, window_s=2.5e-4)
    stats, start = W.run_point(s, d, tmp_path / "point", threads=1, window_s=2.5e-4,
                               state_dir=tmp_path / "states", kernel_version="kv")
    assert start == {"start": "cold", "spin_up_s": 5e-4}
    # the same run to the bit (the resume path with make_simulation's objects)
    assert stats_without_wall_clock(tmp_path / "point") == stats_without_wall_clock(tmp_path / "plain")
    assert (tmp_path / "point" / "windows.csv").read_text() == (tmp_path / "plain" / "windows.csv").read_text()
    arrays, meta = W.read_state(W.state_file(tmp_path / "states", d, "kv"), "kv")
    assert meta["start"] == start and meta["scene"] == d
    n = len(arrays["x_m"])
    assert n > 1000 and arrays["v_m_per_s"].shape == (n, 3) and arrays["fluid_at_bead"].shape == (n, 6)
    assert np.abs(arrays["v_m_per_s"]).max() > 0.1 and np.abs(arrays["liquid_ut"]).max() > 0.1


def test_a_warm_simulation_takes_the_state_and_a_warm_point_records_it(tmp_path, coupled):
    pytest.importorskip("numba")
    from millfmu.dem.scene import scene_from_dict

    d10 = _small(coupled)
    s10 = scene_from_dict(d10)
    folder = tmp_path / "states"
    W.run_point(s10, d10, tmp_path / "a", threads=1, window_s=2.5e-4, state_dir=folder, kernel_version="kv")
    path = W.state_file(folder, d10, "kv")
    arrays, _ = W.read_state(path, "kv")
    # at 12 m/s: the beads where the state has them, velocities and the liquid scaled
    d12 = _small(coupled, tip_speed_m_per_s=12.0)
    s12 = scene_from_dict(d12)
    sim, cpl = W.warm_simulation(s12, W.scaled(arrays, 1.2), threads=1)
    rows = sim.ids  # the new simulation's rows -> the state's
    x, v = arrays["x_m"][rows], 1.2 * arrays["v_m_per_s"][rows].astype(float)
    # a bead that had left the sector is put back across its periodic side (turned by
    # the sector's angle, its velocity with it): radii, heights and speeds as they were
    same = np.all(sim.x == x, axis=1)
    assert same.mean() > 0.95
    np.testing.assert_allclose(np.hypot(sim.x[:, 0], sim.x[:, 1]), np.hypot(x[:, 0], x[:, 1]), rtol=1e-12)
    np.testing.assert_allclose(sim.x[:, 2], x[:, 2], atol=1e-15)
    np.testing.assert_allclose(sim.v[same], v[same], rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(sim.v, axis=1), np.linalg.norm(v, axis=1), rtol=1e-12)
    np.testing.assert_allclose(sim.w[same], 1.2 * arrays["w_rad_per_s"][rows][same].astype(float), rtol=1e-12)
    fab = arrays["fluid_at_bead"][rows].astype(float)
    np.testing.assert_allclose(sim.per_bead["fluid_at_bead"][:, :3], 1.2 * fab[:, :3], rtol=1e-12)
    np.testing.assert_allclose(sim.per_bead["fluid_at_bead"][:, 3:], 1.44 * fab[:, 3:], rtol=1e-12)
    np.testing.assert_allclose(cpl.solver.ut, 1.2 * arrays["liquid_ut"].astype(float), rtol=1e-12)
    np.testing.assert_allclose(cpl.solver.e, 1.2 ** 3 * arrays["liquid_e"].astype(float), rtol=1e-12)
    np.testing.assert_array_equal(cpl.solver.eps_c, arrays["liquid_eps_c"].astype(float))
    assert sim.omega_rad_per_s == pytest.approx(s12.omega_rad_per_s)
    # another bead count: refused by name
    with pytest.raises(W.WarmStartError, match="beads"):
        W.warm_simulation(scene_from_dict(_small(coupled, filling=0.7)), arrays, threads=1)
    # the point run warm: its start recorded, the shorter spin-up run, its own state kept
    stats, start = W.run_point(s12, d12, tmp_path / "b", threads=1, window_s=2.5e-4, state_dir=folder,
                               candidates=W.candidates_in(folder), warm_spin_up_s=2.5e-4,
                               kernel_version="kv")
    assert start == {"start": "warm", "from": {"tip_speed_m_per_s": 10.0, "bead_density_kg_per_m3": 2510.0,
                                               "viscosity_Pa_s": d10["fluid"]["viscosity_Pa_s"]},
                     "state": path.name, "spin_up_s": 2.5e-4, "speed_scale": pytest.approx(1.2)}
    assert stats.spin_up_s == pytest.approx(2.5e-4) and stats.record_s == pytest.approx(5e-4)
    assert sum(z.collision_count for z in stats.zones) > 0
    _, meta = W.read_state(W.state_file(folder, d12, "kv"), "kv")
    assert meta["start"]["start"] == "warm"
    # a state of another kernel version, or no warm spin-up: cold
    _, cold = W.run_point(s12, d12, tmp_path / "c", threads=1, window_s=2.5e-4,
                          candidates=W.candidates_in(folder), warm_spin_up_s=2.5e-4, kernel_version="other")
    assert cold["start"] == "cold"


# ---- slow: a warm-started point of the coupled table against a cold start ----------------
@pytest.mark.slow
def test_a_warm_started_point_lies_within_the_stated_error_of_a_cold_start(tmp_path, coupled):
    """The node at 12 m/s (0.8 mm glass, 80 %) started warm from the anchor's settled state
    (10 m/s; the shipped state, else the anchor run cold first) with WARM_SPIN_UP_S gives a
    collision frequency and median SE_tn per zone within the table's stated error there of
    the same point started cold (the full spin-up, the same threads): max(w/c, c/w) - 1 <= b,
    w the warm run's value, c the cold run's, b the stated relative error of the table's
    lookup at the node (as tests/tables/test_stated_error.py checks the table's checks).
    Measured (python -m validation.warm_start, docs/tables.md): at most 0.32 b. 2.5 simulated
    seconds of the coupled sector (the anchor's run 1.9 more where no state is shipped),
    about 10 min on 2 cores."""
    pytest.importorskip("numba")
    from millfmu.dem.tables.build import _check_fields
    from millfmu.dem.tables.cache import dem_kernel_version
    from millfmu.stress_tables.stress_source import TableStressSource

    spec = coupled.spec()
    anchor = {**spec.anchor(), **{k: float(v) for k, v in coupled.one_at_a_time_ref.items()}}
    node = dict(anchor, tip_speed_m_per_s=12.0)
    states = tmp_path / "points"
    kv = dem_kernel_version()
    if not W.starts_warm(scene_at_point(spec.scene, node), states, (), kv):
        # no shipped state of the installed kernels: the anchor run first, keeping its own
        T.DemBuilder(threads=2, state_dir=str(states))(spec.scene, anchor)
    warm = T.DemBuilder(threads=2, warm_spin_up_s=W.WARM_SPIN_UP_S).with_states(states)
    w = warm(spec.scene, node)
    assert w["start"]["start"] == "warm" and w["start"]["spin_up_s"] == W.WARM_SPIN_UP_S
    assert w["start"]["from"]["tip_speed_m_per_s"] == 10.0
    c = T.DemBuilder(threads=2)(spec.scene, node)
    assert c["start"] == {"start": "cold", "spin_up_s": 1.5}
    b = TableStressSource(coupled).relative_error(coupled.lookup(node))
    warm_f, cold_f = _check_fields(w), _check_fields(c)
    for key, fld in (("collision_frequency", "collision_frequency_norm"), ("se_median", "se_tn_q50_norm")):
        x, y = np.asarray(warm_f[fld], float), np.asarray(cold_f[fld], float)
        assert np.all(x > 0) and np.all(y > 0), (key, x, y)
        measured = np.maximum(x / y, y / x) - 1.0
        assert np.all(measured <= b[key]), (key, measured, b[key])


class _StubSim:
    """What run_point and capture read of a simulation (no DEM)."""

    def __init__(self):
        self.x = np.zeros((3, 3))
        self.v = np.zeros((3, 3), np.float32)
        self.w = np.zeros((3, 3), np.float32)


def test_tables_build_warm_starts_points_from_the_stored_states(tmp_path, monkeypatch, capsys):
    """``millfmu tables build --warm``: each new point starts warm from the nearest state of
    a point with its beads stored when the build starts, within WARM_RANGE; the manifest's
    point_starts records each start; without --warm every point starts cold. The DEM's run
    is stubbed out (run_point's choice and records are the real ones)."""
    import argparse

    import millfmu.dem.run as R
    from millfmu.dem.tables import cli as tables_cli
    from millfmu.dem.tables.cells import dem_scene_at_point

    monkeypatch.setattr(R, "make_simulation", lambda scene, threads: (_StubSim(), None))
    monkeypatch.setattr(R, "run_scene", lambda scene, out, **kw: "stats")
    monkeypatch.setattr(W, "_loop", lambda scene, sim: {})
    monkeypatch.setattr(W, "warm_simulation", lambda scene, arrays, threads=None: (_StubSim(), None))
    builders = []

    def call(self, scene, point):
        builders.append(self)
        sc = dem_scene_at_point(scene, point)
        _, start = W.run_point(scene_from_dict(sc), sc, str(tmp_path / "run"), **self.start_kw())
        return dict(analytic_builder(scene, point), start=start, wall_time_s=1.0)

    monkeypatch.setattr(T.DemBuilder, "__call__", call)

    def build(*argv):
        ap = argparse.ArgumentParser(prog="millfmu")
        tables_cli.register(ap.add_subparsers(dest="command"))
        args = ap.parse_args(["tables", "build", "--record", "0.3", "--executor", "serial", "--no-progress",
                              "--cache-dir", str(tmp_path / "cache"), *argv])
        rc = args.func(args)
        entry = max((tmp_path / "cache").glob("[0-9a-f]*/"), key=lambda d: d.stat().st_mtime)
        return rc, T.read_table(entry).manifest, capsys.readouterr()

    def starts(m):
        return {p["point"]["tip_speed_m_per_s"]: p for p in m["point_starts"]["points"]}

    # the first point: no state of its scene at hand (the shipped one records 0.4 s), cold
    rc, m, out = build("--warm", "--tip-speed", "10")
    assert rc == 0 and builders[-1].warm_spin_up_s == W.WARM_SPIN_UP_S
    assert starts(m)[10.0] == {"point": {"tip_speed_m_per_s": 10.0}, "start": "cold", "spin_up_s": 2.0}
    assert "point starts: 0 warm, 1 cold" in out.out
    # the next build: 11 m/s warm from the 10 m/s state (ratio 1.1), the 10 m/s point reused
    rc, m, out = build("--warm", "--tip-speed", "10,11")
    assert rc == 0 and m["points_run"] == 1 and m["point_starts"]["warm"] == 1
    st = starts(m)[11.0]
    assert st["start"] == "warm" and st["from"]["tip_speed_m_per_s"] == 10.0 and st["spin_up_s"] == 0.2
    assert st["speed_scale"] == pytest.approx(1.1)
    assert "point starts: 1 warm, 1 cold" in out.out
    # 8 m/s: every state with its beads is faster (never measured): cold, and says why
    rc, m, out = build("--warm", "--tip-speed", "8,10")
    st = starts(m)[8.0]
    assert st["start"] == "cold" and st["spin_up_s"] == 2.0
    assert st["why_cold"].startswith("the nearest stored state with the same beads is too far: tip_speed_m_per_s 8 "
                                     "against the state's 10 (ratio 0.8; warm starts measured for 1 to 1.2)")
    assert "starts cold: the nearest stored state with the same beads is too far" in out.err
    # without --warm: cold, from a fresh bed, although a state is at hand
    rc, m, out = build("--tip-speed", "10,11.5")
    assert rc == 0 and builders[-1].warm_spin_up_s is None
    assert starts(m)[11.5] == {"point": {"tip_speed_m_per_s": 11.5}, "start": "cold", "spin_up_s": 2.0}
    # another builder keeps no states: refused by name
    ap = argparse.ArgumentParser(prog="millfmu")
    tables_cli.register(ap.add_subparsers(dest="command"))
    args = ap.parse_args(["tables", "build", "--tip-speed", "10", "--warm", "--cache-dir", str(tmp_path / "c2"),
                          "--builder", "tests.tables._builders:analytic_builder"])
    assert args.func(args) == 2
    assert "--warm: the builder analytic_builder keeps no settled states" in capsys.readouterr().err
    # --help says the default and how the shipped tables are built
    with pytest.raises(SystemExit):
        ap.parse_args(["tables", "build", "--help"])
    assert "as the shipped tables are built" in " ".join(capsys.readouterr().out.split())
