"""How the threads share out a step's chunks of beads (the CPU kernels' parallel loops).

The beads are cut into a fixed number of chunks (:class:`millfmu.dem.engine.sim.DemSimulation`),
each summing into buffers of its own, so a chunk's arithmetic does not depend on which
thread runs it and the results are the same on any schedule and thread count. The
chunks' work differs (their pairs, wall contacts), so they are not dealt out in equal
static blocks; handing them out one at a time as threads come free interleaves the
threads' chunks, and each thread then reads and writes beads all over the bed.

Here each thread first works through a contiguous region of the chunks, the same region
in every parallel loop of a step (the region of its thread number), as an MPI rank works
through its domain: the beads it sums forces for in the force loop, the buffers the
reduction reads and the rows the neighbour build writes stay in its own core's caches.
A thread whose region is done takes the other regions' remaining chunks, one at a time,
from their atomic counters, so that a thread held up on a shared machine still leaves its
work to the others. On the DEM bench's dense bed (52,312 beads, 12 chunks, 2 threads) a
typical block of steps runs a few per cent faster so than with the chunks handed out one
at a time, and the results are the same to the bit either way (docs/dem.md, "Each thread
its own region of the chunks").

The counters live in an int64 array of ``CLAIM_STRIDE`` slots per region (one cache line
each, so that two threads' counters never share a line); its length sets the number of
regions (:func:`claim_counters`, one per thread of the run). Each kernel resets them
(:func:`reset_claims`) before its parallel loop.
"""

import numpy as np
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from millfmu.dem.engine._jit import device

#: int64 slots per region's counter (64 bytes: one cache line)
CLAIM_STRIDE = 8


def claim_counters(threads: int) -> np.ndarray:
    """The counters' array for ``threads`` regions (at least one)."""
    return np.zeros(CLAIM_STRIDE * max(1, int(threads)), np.int64)


@intrinsic
def fetch_increment(typingctx, ary, i):
    """Atomically ``ary[i] += 1`` on an int64 array; returns the value before. (numba has
    no atomic operations on the CPU; an LLVM atomicrmw, monotonic ordering: the counter
    only has to hand each value out once, the chunks' results are read after the parallel
    loop's barrier.)"""
    sig = types.int64(ary, i)

    def codegen(context, builder, signature, args):
        aryty = signature.args[0]
        a = context.make_array(aryty)(context, builder, args[0])
        idx = context.cast(builder, args[1], signature.args[1], types.intp)
        ptr = cgutils.get_item_pointer(context, builder, aryty, a, [idx])
        one = context.get_constant(types.int64, 1)
        return builder.atomic_rmw("add", ptr, one, "monotonic")

    return sig, codegen


@device
def reset_claims(claims, nch):
    """Set every region's counter to its first chunk (region r: chunks r nch // R to
    (r + 1) nch // R - 1 of nch, R regions); returns R."""
    nreg = claims.shape[0] // CLAIM_STRIDE
    for r in range(nreg):
        claims[CLAIM_STRIDE * r] = (r * nch) // nreg
    return nreg


@device
def claim(claims, nch, r0):
    """The next chunk for a thread whose own region is r0: its region's next one, else the
    next of the following regions that has one left; -1 when none is left."""
    nreg = claims.shape[0] // CLAIM_STRIDE
    for k in range(nreg):
        r = r0 + k
        if r >= nreg:
            r -= nreg
        end = ((r + 1) * nch) // nreg
        if claims[CLAIM_STRIDE * r] < end:
            c = fetch_increment(claims, CLAIM_STRIDE * r)
            if c < end:
                return c
    return -1
