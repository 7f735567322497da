"""The neighbour lists carried through a reordering of the beads
(:meth:`millfmu.dem.engine.sim.DemSimulation._sort`, every ``sort_every_steps`` steps):
each pair read out of the old lists with its owner and partner under the new names, then
written into the new rows, each row's pairs in the order they had, the rows of each chunk
one after the other in its region of the lists. A permutation: the same lists, in the
same order, as the numpy reference that tests/dem/test_reorder.py keeps, in three serial
loops instead of some thirty array passes and an unbuffered ``np.maximum.at`` (which cost
a few per cent of the DEM's time between two reorderings).

The spring of a pair whose owner changes (the lower new index) is turned to the other
bead's view by the caller, in numpy (its rotation's cosines are numpy's).
"""

import numpy as np

from millfmu.dem.engine._jit import serial


@serial
def flatten_pairs(nnb, pst, pj, pim, psh, pfl, inv, owner, partner, ps, sh, fl, swap):
    """Every pair of the lists (rows in bead order, each row's pairs in list order) with
    its beads renamed by inv (old index -> new): owner the lower new index, partner the
    higher, swap where the owner is the old partner; ps the image code, sh the spring [m],
    fl the flags, as stored."""
    m = 0
    for r in range(nnb.shape[0]):
        a = inv[r]
        p0 = pst[r]
        for q in range(nnb[r]):
            p = p0 + q
            b = inv[pj[p]]
            sw = a > b
            owner[m] = b if sw else a
            partner[m] = a if sw else b
            swap[m] = sw
            ps[m] = pim[p]
            sh[m, 0] = psh[p, 0]
            sh[m, 1] = psh[p, 1]
            sh[m, 2] = psh[p, 2]
            fl[m] = pfl[p]
            m += 1


@serial
def pair_counts(owner, cb, counts, per_chunk):
    """Pairs per owner (counts, zeroed here) and per chunk of owners (cb: the chunks' bead
    bounds)."""
    counts[:] = 0
    for m in range(owner.shape[0]):
        counts[owner[m]] += 1
    for c in range(cb.shape[0] - 1):
        s = 0
        for b in range(cb[c], cb[c + 1]):
            s += counts[b]
        per_chunk[c] = s


@serial
def place_pairs(owner, partner, ps, sh, fl, counts, cb, cap, fill, pst, nnb, pj, pim, psh,
                pfl, maxj):
    """The new lists: row b of chunk c starts at c cap plus the pairs of the rows before it
    in its chunk (pst), holds counts[b] pairs (nnb), each owner's pairs in their order in
    the flattened input; maxj[c] the highest partner of chunk c's rows (at least its own
    last bead). fill: a work array of the beads' count."""
    for c in range(cb.shape[0] - 1):
        s = c * cap
        for b in range(cb[c], cb[c + 1]):
            pst[b] = s
            s += counts[b]
            nnb[b] = counts[b]
            fill[b] = c  # the chunk of bead b, until the pairs are placed
        maxj[c] = cb[c + 1] - 1
    for m in range(owner.shape[0]):
        o = owner[m]
        c = fill[o]
        if partner[m] > maxj[c]:
            maxj[c] = partner[m]
    fill[:] = 0
    for m in range(owner.shape[0]):
        o = owner[m]
        k = pst[o] + fill[o]
        fill[o] += 1
        pj[k] = np.int32(partner[m])
        pim[k] = np.int8(ps[m])
        psh[k, 0] = sh[m, 0]
        psh[k, 1] = sh[m, 1]
        psh[k, 2] = sh[m, 2]
        pfl[k] = np.uint8(fl[m])
