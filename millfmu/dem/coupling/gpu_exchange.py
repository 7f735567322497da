"""The beads' side of a coupling interval on the GPU (numba.cuda), where the DEM steps there
(``DemSimulation(..., device="gpu")``, :mod:`millfmu.dem.engine.gpu`).

What runs on the GPU, one thread per bead unless said, on the DEM's device arrays (positions,
velocities, radii, masses, the held force):

- the beads' stencils, drag coefficients and deposit columns
  (:func:`millfmu.dem.coupling.exchange_kernels.beads_in`);
- the deposit of the six columns onto the cells
  (:func:`millfmu.dem.coupling.projection.deposit`), by atomic adds;
- the read-back of the smoothed cell values at the beads and the force each bead holds
  over the next interval (:func:`millfmu.dem.coupling.exchange_kernels.bead_forces`),
  written straight into the DEM's held force on the device;
- one thread per cell and field, the smoothing of the deposited totals and of the cell
  velocities (:class:`GpuSmoother`, where the Projector's is explicit diffusion).

The formulas are the CPU's: each bead's part of ``beads_in`` and ``bead_forces``
(:func:`~millfmu.dem.coupling.exchange_kernels.bead_in`,
:func:`~millfmu.dem.coupling.exchange_kernels.bead_force`), with the stencil, the Koch-Hill
drag and the held coefficient they call, is compiled for CUDA from its Python source
(:func:`millfmu.dem.engine._jit.gpu_device`); the smoothing's sweep is the CPU's in
gather form (:func:`diffuse_gather`). The rest of the cell side (void fractions, exchange
coefficients, the liquid) stays on the CPU: per interval the smoothed cell totals (6 x
cells) go to the host and the cell values (6 x cells) come back, instead of every bead's
position, velocity and held force.

Why: with the DEM on a GPU, the exchange on the CPU is eight ninths of a coupled full disc
slice's interval (docs/dem-gpu.md), and its per-bead part (stencils, deposit, forces) is
about half of the exchange on the CPU (the full slice's profile: docs/dem-performance.md);
the smoothing is another fifth to a quarter of it there, and runs one CPU thread per field.

Results agree with the CPU's exchange to round-off, not to the bit: the deposit's and the
held sums' atomic adds come in no fixed order, the smoothing sums each cell's fluxes in
another order, and a GPU fuses multiply-adds.
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


@cuda.jit(device=True)
def diffuse_gather(c, a, i, j, k, src, vol, ar, at, az, totals):
    """Cell (i, j, k) (flat index a) of field c after one sweep of
    :func:`millfmu.dem.coupling.projection.diffuse` from ``src`` (m, cells): the same face
    fluxes alpha (t_a - t_b), each cell gathering those through its own six faces instead
    of each face adding to its two cells (the sums in another order: round-off). totals:
    t = q / V and the fluxes move between the cells (sums conserved); else t = q and the
    cell moves by their sum over its volume. ar, at, az [m3]: the "+"-face coefficients of
    the Projector (0 at walls and solids), theta and z periodic as on the CPU."""
    nr, nt, nz = ar.shape
    ntz = nt * nz
    va = vol[i]
    qa = src[c, a]
    ta = qa / va if totals else qa
    s = 0.0
    if i + 1 < nr:
        al = ar[i, j, k]
        if al != 0.0:
            qb = src[c, a + ntz]
            s += al * ((qb / vol[i + 1] if totals else qb) - ta)
    if i > 0:
        al = ar[i - 1, j, k]
        if al != 0.0:
            qb = src[c, a - ntz]
            s += al * ((qb / vol[i - 1] if totals else qb) - ta)
    if nt > 1:
        jp = j + 1 if j + 1 < nt else 0
        jm = j - 1 if j > 0 else nt - 1
        al = at[i, j, k]
        if al != 0.0:
            qb = src[c, a + (jp - j) * nz]
            s += al * ((qb / va if totals else qb) - ta)
        al = at[i, jm, k]
        if al != 0.0:
            qb = src[c, a + (jm - j) * nz]
            s += al * ((qb / va if totals else qb) - ta)
    kp = k + 1 if k + 1 < nz else 0
    km = k - 1 if k > 0 else nz - 1
    al = az[i, j, k]
    if al != 0.0:
        qb = src[c, a + kp - k]
        s += al * ((qb / va if totals else qb) - ta)
    al = az[i, j, km]
    if al != 0.0:
        qb = src[c, a + km - k]
        s += al * ((qb / va if totals else qb) - ta)
    return qa + s if totals else qa + s / va


@gpu_kernel
def g_diffuse_sweep(src, dst, vol, ar, at, az, totals, ncols):
    """One explicit diffusion sweep (:func:`diffuse_gather`) of the first ``ncols`` fields
    of src (m, cells) into dst, one thread per field and cell; the other fields are copied."""
    t = cuda.grid(1)
    m, ncell = src.shape
    if t >= m * ncell:
        return
    c = t // ncell
    a = t - c * ncell
    if c >= ncols:
        dst[c, a] = src[c, a]
        return
    nr, nt, nz = ar.shape
    i = a // (nt * nz)
    jk = a - i * nt * nz
    j = jk // nz
    k = jk - j * nz
    dst[c, a] = diffuse_gather(c, a, i, j, k, src, vol, ar, at, az, totals)


class GpuSmoother:
    """The explicit-diffusion smoothing of a :class:`~millfmu.dem.coupling.projection.
    Projector` (``smoothing = 'explicit_diffusion'``) on the GPU, for cell fields of shape
    (6, cells) that are on the device already: its sweeps, one launch each, between the
    field's array and a second one of the same shape."""

    def __init__(self, pj, ncell: int, tpb: int):
        d = cuda.to_device
        self.sweeps = int(pj.sweeps)
        self.vol = d(pj._vol_r)
        self.ar, self.at, self.az = d(pj._ar), d(pj._at), d(pj._az)
        self.buf = cuda.device_array((6, ncell))
        self.tpb = tpb
        self.blocks = (6 * ncell + tpb - 1) // tpb

    def smooth(self, a, totals: bool, ncols: int):
        """Smooth the first ``ncols`` fields of the device array ``a`` (6, cells): cell
        totals (conservative) or intensive values (the transpose). Returns the device array
        that holds the result (``a`` or the second one), every field in it."""
        src, dst = a, self.buf
        for _ in range(self.sweeps):
            g_diffuse_sweep[self.blocks, self.tpb](src, dst, self.vol, self.ar, self.at, self.az,
                                                   totals, ncols)
            src, dst = dst, src
        if src is self.buf:
            self.buf = a  # the caller's array is now the spare one
        return src


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
        #: the smoothing of the totals and values on the device, where the Projector's is
        #: explicit diffusion (split_implicit's and none stay on the host)
        self.smoother = (GpuSmoother(pj, ncell, self.tpb)
                         if pj.sweeps and pj._implicit is None else None)
        # the DEM's held force is this side's from now on: not uploaded from the host
        # before each run (here once, for an exchange made on the host before)
        gpu.fext.copy_to_device(sim.fext)
        gpu.fext_on_device = True

    def upload_fluid_at_beads(self):
        """The host's fluid at the beads (set by a primed start) to the device."""
        self.fab.copy_to_device(self.cpl.sim.per_bead["fluid_at_bead"])

    def beads_in_and_deposit(self, eps_cells: np.ndarray, tot_host: np.ndarray,
                             smooth: bool = False) -> float:
        """Stencils, drag coefficients and deposit columns of every bead at the void
        fraction per cell ``eps_cells`` [-] (host), then their deposit onto the cells
        (smoothed on the device when ``smooth`` and :attr:`smoother` is set), copied into
        ``tot_host`` (6, cells); returns the largest interval c / m [-]."""
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
        if smooth and self.smoother is not None:
            self.tot = self.smoother.smooth(self.tot, True, 6)
        self.tot.copy_to_host(tot_host)
        return float(self.xmax.copy_to_host()[0])

    def bead_forces(self, cellv_host: np.ndarray, pf: float, now: bool, body_z: float,
                    smooth: bool = False):
        """The held forces from the cell values ``cellv_host`` (6, cells), smoothed before
        (or, with ``smooth`` and :attr:`smoother` set, their first three columns, the
        velocity, smoothed here on the device), on the device; returns the sums of T_z
        [N m] and F_z [N] over the beads."""
        gpu = self.gpu
        self.cellv.copy_to_device(cellv_host)
        if smooth and self.smoother is not None:
            self.cellv = self.smoother.smooth(self.cellv, False, 3)
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
