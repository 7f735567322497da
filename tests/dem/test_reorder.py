"""The beads' reordering (DemSimulation._sort, engine.reorder): the neighbour lists it
carries over are those of the numpy passes it replaced, to the bit, and they name the same
pairs with the same springs as before the reordering."""

import pickle

import numpy as np
import pytest

pytest.importorskip("numba")


def _sort_numpy(self):
    """DemSimulation._sort as it was before engine.reorder (array passes; kept here as the
    reference)."""
    g = self.geometry
    cs = self.cutoff_m
    x = self.x
    n = self.n
    ix = np.floor((x[:, 0] + g.chamber_radius_m) / cs).astype(np.int64)
    iy = np.floor((x[:, 1] + g.chamber_radius_m) / cs).astype(np.int64)
    iz = np.floor(np.mod(x[:, 2], g.height_m) / cs).astype(np.int64)
    key = (ix * (iy.max() + 1) + iy) * (iz.max() + 1) + iz
    perm = np.argsort(key, kind="stable")
    inv = np.empty_like(perm)
    inv[perm] = np.arange(perm.size)
    nnb = self.nnb
    rows = np.repeat(np.arange(n), nnb)
    first = np.cumsum(nnb) - nnb
    pos = np.repeat(self.pst, nnb) + (np.arange(rows.size) - np.repeat(first, nnb))
    pj = self.pj[pos].astype(np.int64)
    ps = self.pim[pos].astype(np.int64)
    psh = self.psh[pos]
    pfl = self.pfl[pos]
    a = inv[rows]
    b = inv[pj]
    swap = a > b
    owner = np.where(swap, b, a)
    partner = np.where(swap, a, b)
    if swap.any():
        th = -ps[swap] * self.geometry.sector_rad
        c, sn = np.cos(th), np.sin(th)
        s0, s1 = psh[swap, 0].copy(), psh[swap, 1].copy()
        psh[swap, 0] = -(c * s0 - sn * s1)
        psh[swap, 1] = -(sn * s0 + c * s1)
        psh[swap, 2] = -psh[swap, 2]
        ps = np.where(swap, -ps, ps)
    for k in self._PER_BEAD:
        setattr(self, k, np.ascontiguousarray(getattr(self, k)[perm]))
    for k, arr in self.per_bead.items():
        arr[:] = arr[perm]
    counts = np.bincount(owner, minlength=n)
    before = np.cumsum(counts) - counts
    cb = self.cb
    nch = cb.size - 1
    chunk_of = np.repeat(np.arange(nch), np.diff(cb))
    per_chunk = np.add.reduceat(counts, cb[:-1]) if n else np.zeros(nch, np.int64)
    if per_chunk.max() > self.pair_capacity:
        self._alloc_lists(int(per_chunk.max() * 1.3) + 16)
    cap = self.pair_capacity
    pst = chunk_of * cap + before - before[cb[chunk_of]]
    order = np.argsort(owner, kind="stable")
    owner, partner, ps, psh, pfl = (owner[order], partner[order], ps[order], psh[order],
                                    pfl[order])
    slot = pst[owner] + np.arange(owner.size) - before[owner]
    self.pj[slot] = partner
    self.pim[slot] = ps
    self.psh[slot] = psh
    self.pfl[slot] = pfl
    self.pst[:] = pst
    self.nnb[:] = counts
    self.maxj[:] = cb[1:] - 1
    if owner.size:
        np.maximum.at(self.maxj, chunk_of[owner], partner)
    self._last_sort = self.step_count


def _copy(sim):
    """A copy of the simulation, as a checkpoint pickles it."""
    import io

    from millfmu.dem.run import _Pickler

    buf = io.BytesIO()
    _Pickler(buf, protocol=pickle.HIGHEST_PROTOCOL).dump(sim)
    return pickle.loads(buf.getvalue())


def _pairs(sim):
    """{(initial id i, initial id j, image code seen from i): (spring, flags)} of the lists."""
    out = {}
    for r in range(sim.n):
        for p in range(sim.pst[r], sim.pst[r] + sim.nnb[r]):
            out[(int(sim.ids[r]), int(sim.ids[sim.pj[p]]), int(sim.pim[p]))] = (
                tuple(sim.psh[p]), int(sim.pfl[p]))
    return out


def test_reorder_is_the_numpy_passes_to_the_bit():
    """A stirred 10-degree disc sector with contacts and image pairs across the periodic
    faces, its beads moved first so that many pairs change owner: the reordered lists,
    per-bead arrays and partner bounds equal the numpy passes' to the bit, on 2 threads'
    chunks; the pairs and their springs, seen from the bead that now owns them, are the
    same pairs."""
    from millfmu.dem.run import make_simulation
    from millfmu.dem.scene import load_scene

    sc = load_scene("disc_slice").with_overrides(
        sector_deg=10.0, gravity_m_per_s2=(0.0, 0.0, 0.0), fluid_mode="prescribed",
        initial_rotation=0.1)
    sim, _ = make_simulation(sc, 2)
    sim.run(150)
    assert sim.cb.size > 2 and np.any(sim.pim != 0)
    # beads moved along z (as if far since the last reordering): a new order
    rng = np.random.default_rng(3)
    sim.x[:, 2] = np.mod(sim.x[:, 2] + rng.uniform(0.0, 1e-3, sim.n), sc.geometry.height_m)
    a = _copy(sim)
    b = _copy(sim)
    before = _pairs(a)
    _sort_numpy(a)
    b._sort()
    swapped = 0
    for k in b._LISTS + b._PER_BEAD + ("maxj",):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k), err_msg=k)
    for k in b.per_bead:
        np.testing.assert_array_equal(a.per_bead[k], b.per_bead[k], err_msg=k)
    after = _pairs(b)
    assert len(after) == len(before) > 1000
    for (i, j, s), (sh, fl) in after.items():
        if (i, j, s) in before:
            assert before[(i, j, s)] == (sh, fl)
        else:
            swapped += 1
            shb, flb = before[(j, i, -s)]
            assert fl == flb and sh[2] == -shb[2]
    assert swapped > 100
