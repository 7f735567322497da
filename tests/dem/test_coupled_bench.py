"""The coupled bench row (benchmarks.coupled_bench): its structure, its cached running mill,
the coupled interval's profile (timings are printed, never asserted), and its command (the
bench's refusals: tests/dem/test_checkpoint.py)."""

import numpy as np
import pytest


@pytest.mark.bench
def test_coupled_bench_row_prints_its_ratio():
    pytest.importorskip("numba")
    from benchmarks.coupled_bench import run_coupled_bench

    r = run_coupled_bench(steps=200, repeats=1, start="early")
    print(r.as_dict())
    assert r.beads > 1000 and r.fluid_cells > 100 and r.coupling_steps == 10
    assert r.dem_particle_steps_per_s > 0 and r.coupled_particle_steps_per_s > 0
    assert r.start == "early" and len(r.block_added_costs) == 1
    assert r.as_dict()["added_cost_median"] == r.block_added_costs[0]


def test_coupled_bench_running_state_is_made_once_and_reloaded(tmp_path, monkeypatch):
    """The coupled row's running mill: made once in the bench folder, then loaded as it was
    left (the same beads, step count and liquid), for these sources and thread count; a
    start it cannot take is refused by name."""
    pytest.importorskip("numba")
    from benchmarks import coupled_bench as CB

    monkeypatch.setenv("MILLFMU_BENCH_DIR", str(tmp_path))
    said = []
    sim, cpl = CB.running_state(threads=1, running_s=2e-4, out=said.append)
    assert any("making the running coupled sector" in m for m in said)
    files = list(tmp_path.glob("coupled_sector_running_*.pkl"))
    assert len(files) == 1 and sim.step_count == 40 and cpl.intervals == 4
    said.clear()
    sim2, cpl2 = CB.running_state(threads=1, running_s=2e-4, out=said.append)
    assert not said and sim2.step_count == 40 and cpl2.intervals == 4
    assert np.array_equal(sim2.x, sim.x) and np.array_equal(cpl2.solver.ut, cpl.solver.ut)
    # another running time is another state
    CB.running_state(threads=1, running_s=1e-4, out=said.append)
    assert len(list(tmp_path.glob("coupled_sector_running_*.pkl"))) == 2
    with pytest.raises(ValueError, match="the sector on the CPU only"):
        CB.run_coupled_bench(steps=10, repeats=1, scene="full", start="running")
    with pytest.raises(ValueError, match="start = 'late'"):
        CB.run_coupled_bench(steps=10, repeats=1, start="late")


def test_coupled_interval_profile_names_every_part():
    """``python -m benchmarks.dem_peers --coupled --profile``: every part of a coupled interval timed inside the
    run, then the exchange in one compiled call, and the coupling's kernels, methods and
    choice of path given back afterwards."""
    pytest.importorskip("numba")
    from millfmu.dem.coupling import exchange_kernels as EK
    from millfmu.dem.fluid import step_kernels as SK
    from millfmu.dem.run import make_simulation
    from benchmarks import coupled_bench as CB

    sim, cpl = make_simulation(CB._scene("sector"), 1, "cpu")
    said = []
    res = CB.profile_coupled(steps=40, out=said.append, state=(sim, cpl))
    labels = [label for label, _, _ in CB.COUPLED_PARTS]
    assert list(res)[:len(labels)] == labels and "DEM alone, 10 steps" in res
    for label, (med, mean) in res.items():
        assert med > 0.0 and mean > 0.0, label
    # the parts of the exchange (not the liquid's substeps, within its whole interval)
    parts = sum(res[label][1] for label in labels[:5] + labels[8:12])
    assert parts <= res["exchange, whole"][1]
    assert any("against the DEM's interval alone: the exchange" in line for line in said)
    assert ", 10 deg sector, 6536 beads," in said[0]  # the heading names what it profiled
    assert cpl.EK is EK and cpl.solver.SK is SK
    assert "exchange" not in vars(cpl) and "run" not in vars(sim)
    assert "solve" not in vars(cpl.solver.pressure) and "advance" not in vars(cpl.solver)
    assert cpl.fused and res["exchange, whole, in one call"][0] > 0.0
    assert sim.step_count == 20 + 40 + 40 + 200  # compiled, profiled, one call, DEM alone
    with pytest.raises(ValueError, match="start = 'late'"):
        CB.profile_coupled(steps=10, start="late")


def test_coupled_bench_command_passes_its_options_to_the_bench(monkeypatch):
    """``python -m benchmarks.coupled_bench full --steps 40 ...`` is the bench's coupled
    row alone, with the same options."""
    from benchmarks import coupled_bench as CB
    from benchmarks import dem_peers

    got = []
    monkeypatch.setattr(dem_peers, "main", lambda argv: got.append(argv) or 0)
    assert CB.main(["full", "--steps", "40", "--cores", "2", "--coupled-start", "early", "--json"]) == 0
    assert got == [["--bed", "none", "--coupled", "full", "--steps", "40", "--coupled-start", "early",
                    "--cores", "2", "--json"]]
