"""The beads' side of a coupling interval on the GPU (numba.cuda), where the DEM steps there
(``DemSimulation(..., device="gpu")``, :mod:`millfmu.dem.engine.gpu`).

What runs on the GPU, one thread per bead, on the DEM's device arrays (positions,
velocities, radii, masses, the held force):

- the beads' stencils, drag coefficients and deposit columns
  (:func:`millfmu.dem.coupling.exchange_kernels.beads_in`);
- the deposit of the six columns onto the cells
  (:func:`millfmu.dem.coupling.projection.deposit`), by atomic adds;
- the read-back of the smoothed cell values at the beads and the force each bead holds
  over the next interval (:func:`millfmu.dem.coupling.exchange_kernels.bead_forces`),
  written straight into the DEM's held force on the device.

The formulas are the CPU's: each bead's part of ``beads_in`` and ``bead_forces``
(:func:`~millfmu.dem.coupling.exchange_kernels.bead_in`,
:func:`~millfmu.dem.coupling.exchange_kernels.bead_force`), with the stencil, the Koch-Hill
drag and the held coefficient they call, is compiled for CUDA from its Python source
(:func:`millfmu.dem.engine._jit.gpu_device`). The cell
side (smoothing, void fractions, the liquid) stays on the CPU: per interval the cell totals
(6 x cells) go to the host and the cell values (6 x cells) come back, instead of every
bead's position, velocity and held force.

Why: with the DEM on a GPU, the exchange on the CPU is eight ninths of a coupled full disc
slice's interval (docs/dem-gpu.md), and its per-bead part (stencils, deposit, forces) is
about half of the exchange on the CPU (the full slice's profile: docs/dem-performance.md).

Results agree with the CPU's exchange to round-off, not to the bit: the deposit's and the
held sums' atomic adds come in no fixed order, and a GPU fuses multiply-adds.
numba.cuda is imported only here, when a coupled run steps its DEM on the GPU; with
NUMBA_ENABLE_CUDASIM=1 the kernels run in numba's CUDA simulator (how the tests check it).
"""

from __future__ import annotations

import numpy as np
from numba import cuda

from millfmu.dem.coupling import exchange_kernels as EK
from millfmu.dem.coupling import projection as PJ
from millfmu.dem.engine import koch_hill2001 as KH
from millfmu.dem.engine._jit import gpu_device, gpu_kernel
from millfmu.dem.fluid import vans_kernels as VK


@cuda.jit(device=True)
def _nonneg(i):
    """The CPU's ``nonneg`` (an LLVM assumption, no arithmetic) on the GPU: ``i``."""
    return i


_wrap = gpu_device(VK.wrap, nonneg=_nonneg)
_bead_cyl = gpu_device(PJ.bead_cyl, stencil_one=gpu_device(PJ.stencil_one, nonneg=_nonneg, wrap=_wrap))
bead_in = gpu_device(EK.bead_in, bead_cyl=_bead_cyl, at_bead=gpu_device(PJ.at_bead, nonneg=_nonneg),
                     beta=gpu_device(KH.beta, f0_f3=gpu_device(KH.f0_f3)),
                     held_coefficient=gpu_device(EK.held_coefficient))
bead_force = gpu_device(EK.bead_force, at_bead3=gpu_device(PJ.at_bead3, nonneg=_nonneg))


@gpu_kernel
def g_beads_in(x, v, rad, mass, fab, eps_cells, body_z, pf, model_b, mu, rho, interval, rc,
               rtab, rh, dth, nt, dz, nz, lz, solid, idx, w, cyl, c, q, xmax):
    """:func:`~millfmu.dem.coupling.exchange_kernels.beads_in` for bead ``cuda.grid(1)``;
    xmax[0] receives the largest interval c / m over the beads (atomic max)."""
    b = cuda.grid(1)
    if b >= x.shape[0]:
        return
    xx = bead_in(b, x, v, rad, mass, fab, eps_cells, body_z, pf, model_b, mu, rho, interval,
                 rc, rtab, rh, dth, nt, dz, nz, lz, solid, idx, w, cyl, c, q)
    cuda.atomic.max(xmax, 0, xx)


@gpu_kernel
def g_zero(a):
    """a[:] = 0 for a flat device array, one thread per entry."""
    i = cuda.grid(1)
    if i < a.shape[0]:
        a[i] = 0.0


@gpu_kernel
def g_deposit(idx, w, q, out):
    """:func:`~millfmu.dem.coupling.projection.deposit` for bead ``cuda.grid(1)``:
    out[m, cell] += w q[bead, m] by atomic adds (out zeroed before)."""
    b = cuda.grid(1)
    if b >= idx.shape[0]:
        return
    for s in range(idx.shape[1]):
        ww = w[b, s]
        if ww != 0.0:
            cc = idx[b, s]
            for m in range(q.shape[1]):
                cuda.atomic.add(out, (m, cc), ww * q[b, m])


@gpu_kernel
def g_bead_forces(idx, w, cellv, c, cyl, rad, fab, pf, now, body_z, fext, sums):
    """:func:`~millfmu.dem.coupling.exchange_kernels.bead_forces` for bead
    ``cuda.grid(1)``: the held force fext (F_r [N], T_z [N m], F_z [N]) and the fluid at
    the bead fab; sums[0], sums[1] receive T_z and F_z summed over the beads (atomic
    adds; zeroed before)."""
    b = cuda.grid(1)
    if b >= idx.shape[0]:
        return
    tz, fz = bead_force(b, idx, w, cellv, c, cyl, rad, fab, pf, now, body_z, fext)
    cuda.atomic.add(sums, 0, tz)
    cuda.atomic.add(sums, 1, fz)


class GpuBeadSide:
    """The device arrays of a :class:`~millfmu.dem.coupling.cfd_dem.CfdDem`'s beads (its
    stencils, drag coefficients, deposit columns, the fluid at each bead) beside the DEM's
    :class:`~millfmu.dem.engine.gpu.GpuStepper`, and the three steps of an interval that
    use them. The host copies of the fluid at the beads and of the held force
    (``sim.per_bead["fluid_at_bead"]``, ``sim.fext``) are refreshed by :meth:`to_host`; the
    device's are the state."""

    def __init__(self, cpl):
        sim, g = cpl.sim, cpl.grid
        gpu = sim._gpu
        self.cpl = cpl
        self.gpu = gpu
        ns = cpl._idx.shape[1]
        ncell = int(np.prod(g.shape))
        d = cuda.to_device
        # set by every exchange's beads_in before anything reads them: not uploaded
        self.idx = cuda.device_array(cpl._idx.shape, cpl._idx.dtype)
        self.w = cuda.device_array(cpl._w.shape)
        self.cyl = cuda.device_array(cpl._cyl.shape)
        self.c = cuda.device_array(cpl._c.shape)
        self.q = cuda.device_array(cpl._q.shape)
        self.fab = d(sim.per_bead["fluid_at_bead"])
        self.eps_cells = d(np.ones(ncell))
        self.tot = cuda.device_array((6, ncell))
        self.cellv = cuda.device_array((6, ncell))
        self.xmax = d(np.zeros(1))
        self.sums = d(np.zeros(2))
        pj = cpl.projector
        self.rc, self.rtab, self.solid = d(pj.rc), d(pj.rtab), d(g.solid)
        self.tpb = gpu.tpb
        self.blocks = gpu.blocks
        self.cell_blocks = (6 * ncell + self.tpb - 1) // self.tpb
        self.ns = ns
        # the DEM's held force is this side's from now on: not uploaded from the host
        # before each run (here once, for an exchange made on the host before)
        gpu.fext.copy_to_device(sim.fext)
        gpu.fext_on_device = True

    def upload_fluid_at_beads(self):
        """The host's fluid at the beads (set by a primed start) to the device."""
        self.fab.copy_to_device(self.cpl.sim.per_bead["fluid_at_bead"])

    def beads_in_and_deposit(self, eps_cells: np.ndarray, tot_host: np.ndarray) -> float:
        """Stencils, drag coefficients and deposit columns of every bead at the void
        fraction per cell ``eps_cells`` [-] (host), then their deposit onto the cells,
        copied into ``tot_host`` (6, cells); returns the largest interval c / m [-]."""
        cpl, gpu = self.cpl, self.gpu
        g, s = cpl.grid, cpl.solver
        nr, nt, nz = g.shape
        pj = cpl.projector
        self.eps_cells.copy_to_device(eps_cells)
        self.xmax.copy_to_device(np.zeros(1))
        g_beads_in[self.blocks, self.tpb](
            gpu.x, gpu.v, gpu.rad, gpu.mass, self.fab, self.eps_cells, s.body_z,
            0.0 if cpl.model_b else 1.0, cpl.model_b, s.fluid.viscosity_Pa_s, s.rho,
            cpl.interval_s, self.rc, self.rtab, pj.rh, g.dtheta_rad, nt, g.dz_m, nz,
            g.height_m, self.solid, self.idx, self.w, self.cyl, self.c, self.q, self.xmax)
        flat = self.tot.reshape(self.tot.size)
        g_zero[self.cell_blocks, self.tpb](flat)
        g_deposit[self.blocks, self.tpb](self.idx, self.w, self.q, self.tot)
        self.tot.copy_to_host(tot_host)
        return float(self.xmax.copy_to_host()[0])

    def bead_forces(self, cellv_host: np.ndarray, pf: float, now: bool, body_z: float):
        """The held forces from the smoothed cell values ``cellv_host`` (6, cells), on the
        device; returns the sums of T_z [N m] and F_z [N] over the beads."""
        gpu = self.gpu
        self.cellv.copy_to_device(cellv_host)
        self.sums.copy_to_device(np.zeros(2))
        g_bead_forces[self.blocks, self.tpb](
            self.idx, self.w, self.cellv, self.c, self.cyl, gpu.rad, self.fab, pf, now,
            body_z, gpu.fext, self.sums)
        ts, fs = self.sums.copy_to_host()
        return float(ts), float(fs)

    def to_host(self):
        """Copy the state the device holds, the fluid at the beads and the held force, to
        the host arrays (``sim.per_bead["fluid_at_bead"]``, ``sim.fext``), for what reads
        them there (a table point's settled state, the CPU's exchange after a switch)."""
        sim = self.cpl.sim
        self.fab.copy_to_host(sim.per_bead["fluid_at_bead"])
        self.gpu.fext.copy_to_host(sim.fext)

    def stencils_to_host(self):
        """Copy the stencils of the last exchange to the host's (``cpl._idx``, ``cpl._w``),
        for the void fraction read at the beads."""
        self.idx.copy_to_host(self.cpl._idx)
        self.w.copy_to_host(self.cpl._w)
