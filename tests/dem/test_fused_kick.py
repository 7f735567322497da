"""The kick and drift done in the force loop (compute_forces(fuse=True)) for the beads that
only their own chunk's rows reach, the rest by reduce_kick(deferred=True): the same state
to the bit as the force loop followed by the full reduction."""

import numpy as np
import pytest

pytest.importorskip("numba")


def _sim(sector_deg, n):
    from millfmu.dem.engine.params import BeadMaterial
    from millfmu.dem.engine.sim import DemSimulation
    from millfmu.dem.mills.geometry import MillGeometry, place_beads

    geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.045, height_m=0.004,
                        sector_deg=sector_deg)
    x = place_beads(geom, n, 0.4e-3, seed=3)
    v = np.random.default_rng(4).normal(0.0, 1.0, size=x.shape)
    sim = DemSimulation(geom, BeadMaterial(), x, 0.4e-3, 500.0, 5e-6, velocities_m_per_s=v,
                        threads=1)
    sim.run(40)  # contacts with histories, beads sorted
    return sim


STATE = ("x", "v", "w", "dmax", "fb", "tb", "psh", "pfl", "shw", "flw")


def _step(sim, fuse):
    """One step's forces and kick with drift on a copy of the state; the copy's arrays."""
    from millfmu.dem.engine import kernels as K

    s = {k: getattr(sim, k).copy() for k in STATE}
    dt = sim.dt_s
    K.compute_forces(s["x"], s["v"], s["w"], s["fb"], s["tb"], sim.rad, sim.mass, sim.inertia,
                     sim.pst, sim.nnb, sim.pj, sim.pim, s["psh"], s["pfl"], s["shw"],
                     s["flw"], sim.prm, sim.cb, sim.maxj, False, 0, sim.evc, sim.evn,
                     sim.torq, sim.fext, sim.claims(), fuse, dt, sim.inv_m, sim.inv_i,
                     sim.xref, s["dmax"])
    K.reduce_kick(s["fb"], s["tb"], sim.cb, sim.maxj, sim.f.copy(), sim.t.copy(), s["v"],
                  s["w"], s["x"], sim.inv_m, sim.inv_i, dt, dt, True, sim.xref, s["dmax"],
                  sim.claims(), fuse)
    return s


@pytest.mark.parametrize("sector_deg,n", [(360.0, 17000), (90.0, 9000)])
def test_fused_kick_is_the_full_reduction_to_the_bit(sector_deg, n):
    from millfmu.dem.engine import kernels as K

    sim = _sim(sector_deg, n)
    nch = sim.cb.size - 1
    assert nch >= 2
    deferred = sum(K.deferred_end(sim.cb, sim.maxj, c) - sim.cb[c] for c in range(nch))
    # both paths of the fused step are taken: some beads deferred, most kicked in the loop,
    # and many beads in contact
    assert 0 < deferred < sim.n // 2
    moved = np.abs(sim.f).sum(axis=1) > 0
    assert moved.sum() > sim.n // 5
    a, b = _step(sim, False), _step(sim, True)
    for k in STATE:
        assert np.array_equal(a[k], b[k]), k
    assert not np.array_equal(a["x"], sim.x)
    assert not b["fb"].any() and not b["tb"].any()  # the buffers left zero for the next step


def test_deferred_end_is_past_every_earlier_chunks_partners():
    from millfmu.dem.engine import kernels as K

    cb = np.array([0, 10, 20, 30, 40])
    maxj = np.array([13, 25, 29, 39])
    assert [K.deferred_end(cb, maxj, c) for c in range(4)] == [0, 14, 26, 30]
