"""numba.cuda path of the bead DEM: ``DemSimulation(..., device="gpu")``.

The same model as the CPU kernels (:mod:`millfmu.dem.engine.kernels`): the contact law, the wall
geometry, the body forces (gravity, held fluid force, drag), the lubrication force, the
recorded contact energies and the periodic wrap are the CPU's device functions compiled
for CUDA from their Python source (:func:`millfmu.dem.engine._jit.gpu_device`). What differs is
the bookkeeping, which follows the GPU:

- one thread per bead; half neighbour lists as on the CPU (each pair once, in the row of
  its lower bead index, with its tangential history), in fixed slots laid out
  [slot, bead] so that neighbouring threads read neighbouring addresses;
- the reaction on the partner, the wall torques and the recorded contacts go through
  atomic operations (float64 atomics: compute capability 6.0 or newer). The order of the
  sums varies from run to run, so results agree with the CPU's to round-off, not bit
  for bit, and contacts are recorded in no particular order;
- cells of a fixed capacity filled with atomic counters (enlarged when one overflows)
  instead of the CPU's counting sort; partners across the sector boundaries are found by
  searching around the bead's position rotated by -+sector (the CPU stores rotated
  image entries: the same pairs);
- beads are not reordered.

Per step: forces, then the kick (and drift; it zeroes the forces it has read); the host
reads four integers back (rebuild due, contacts recorded, cell and list overflow) to
decide on a neighbour build.
numba.cuda is imported only here, when a GPU run is requested; with
NUMBA_ENABLE_CUDASIM=1 the kernels run in numba's CUDA simulator (how the tests check
this path without a GPU).
"""

from __future__ import annotations

import math

import numpy as np
from numba import cuda

from millfmu.dem.engine import kernels as K
from millfmu.dem.engine import koch_hill2001 as KH
from millfmu.dem.engine._jit import gpu_device, gpu_kernel

axial_image = gpu_device(K.axial_image)
wall_stands = gpu_device(K.wall_stands)
_plate_gap = gpu_device(K.plate_gap)
hertz_mindlin = gpu_device(K.hertz_mindlin)
history_frame_pair = gpu_device(K.history_frame_pair)
pair_response = gpu_device(K.pair_response, hertz_mindlin=hertz_mindlin)
wall_response = gpu_device(K.wall_response, hertz_mindlin=hertz_mindlin,
                           wall_stands=wall_stands,
                           history_frame=gpu_device(K.history_frame),
                           wall_gap=gpu_device(
                               K.wall_gap, plate_gap=_plate_gap,
                               baffle_gap=gpu_device(K.baffle_gap, plate_gap=_plate_gap)))
body_force = gpu_device(K.body_force, swirl_velocity=gpu_device(K.swirl_velocity),
                        beta_of_terms=gpu_device(KH.beta_of_terms))
lubrication_force = gpu_device(K.lubrication_force)
write_event = gpu_device(K.write_event)
wrap_one = gpu_device(K.wrap_one)
release_wall = gpu_device(K.release_wall)

# flags (int64) read back by the host after each step
F_REBUILD = 0  # some bead moved more than half the skin since the last build
F_EVENTS = 1  # contacts recorded since the last drain (may exceed the buffer)
F_CELL = 2  # most beads found in one cell
F_NEED = 3  # longest neighbour row found by the last build
N_FLAGS = 4


@gpu_kernel
def g_kick(x, v, w, f, t, inv_m, inv_i, kick, dt, drift, xref, half_skin2, flags, zero):
    """v += kick F/m, w += kick T/I and, with drift, x += dt v; raise F_REBUILD when a bead
    has moved more than half the skin since the last neighbour build. With zero, the bead's
    force and torque are zeroed once read, for the next force kernel to sum into: no other
    thread touches row i during this kernel (the reactions' atomics are the force
    kernel's), and it saves a launch per step."""
    i = cuda.grid(1)
    if i >= x.shape[0]:
        return
    im = kick * inv_m[i]
    ii = kick * inv_i[i]
    for a in range(3):
        v[i, a] += f[i, a] * im
        w[i, a] += t[i, a] * ii
        if zero:
            f[i, a] = 0.0
            t[i, a] = 0.0
    if drift:
        dd = 0.0
        for a in range(3):
            x[i, a] += dt * v[i, a]
            d = x[i, a] - xref[i, a]
            dd += d * d
        if dd > half_skin2:
            flags[F_REBUILD] = 1


@gpu_kernel
def g_zero(f, t):
    i = cuda.grid(1)
    if i < f.shape[0]:
        for a in range(3):
            f[i, a] = 0.0
            t[i, a] = 0.0


@gpu_kernel
def g_wrap(x, v, w, shw, prm, wrapk):
    i = cuda.grid(1)
    if i < x.shape[0]:
        wrap_one(i, x, v, w, shw, prm, wrapk)


@cuda.jit(device=True)
def cell_of(x, i, lo0, lo1, cs, ncx, ncy, ncz, lz):
    """Cell of bead i (cells of size cs [m] in x and y, ncz cells over the period lz)."""
    ix = min(max(int((x[i, 0] - lo0) / cs), 0), ncx - 1)
    iy = min(max(int((x[i, 1] - lo1) / cs), 0), ncy - 1)
    zz = x[i, 2] - lz * math.floor(x[i, 2] / lz)
    iz = min(int(zz / (lz / ncz)), ncz - 1)
    return (ix * ncy + iy) * ncz + iz


@gpu_kernel
def g_unbin(x, count, lo0, lo1, cs, ncx, ncy, ncz, lz):
    """Empty the cells the beads were binned into (all beads of a cell write the same 0):
    only occupied cells are touched, not the whole grid."""
    i = cuda.grid(1)
    if i < x.shape[0]:
        count[cell_of(x, i, lo0, lo1, cs, ncx, ncy, ncz, lz)] = 0


@gpu_kernel
def g_bin(x, count, cells, lo0, lo1, cs, ncx, ncy, ncz, lz, flags):
    """Put bead i into its cell."""
    i = cuda.grid(1)
    if i >= x.shape[0]:
        return
    c = cell_of(x, i, lo0, lo1, cs, ncx, ncy, ncz, lz)
    slot = cuda.atomic.add(count, c, 1)
    if slot < cells.shape[1]:
        cells[c, slot] = i
    else:
        cuda.atomic.max(flags, F_CELL, slot + 1)


@gpu_kernel
def g_build(x, count, cells, lo0, lo1, cs, ncx, ncy, ncz, cut2, prm, wrapk, nb_o, img_o,
            nnb_o, sh_o, fl_o, nb, img, nnb, sh, fl, xref, flags):
    """Half neighbour list of bead i within sqrt(cut2) [m] into slots nb[:, i] (partners
    j > i, image code s: the partner is bead j rotated by s sectors), histories and
    flags carried over from the old lists as in :func:`millfmu.dem.engine.kernels.build_nlist`;
    F_NEED receives the longest row. Resets the displacement reference."""
    i = cuda.grid(1)
    if i >= x.shape[0]:
        return
    lz = prm[K.P_LZ]
    sec = prm[K.P_SECTOR]
    csz = lz / ncz
    cut = math.sqrt(cut2)
    m = nb.shape[0]
    xi = x[i, 0]
    yi = x[i, 1]
    zi = x[i, 2]
    ri = math.sqrt(xi * xi + yi * yi)
    th = math.atan2(yi, xi)
    zz = zi - lz * math.floor(zi / lz)
    iz = min(int(zz / csz), ncz - 1)
    n = 0
    for si in range(3):
        s = 0 if si == 0 else (1 if si == 1 else -1)
        qx = xi
        qy = yi
        if s != 0:
            if sec <= 0.0:
                continue
            # partner images R(s sec) x_j near x_i <=> x_j near R(-s sec) x_i; only
            # beads within the cutoff of the boundary ray have such partners
            if s == 1 and ri * math.sin(max(sec - th, 0.0)) >= cut:
                continue
            if s == -1 and ri * math.sin(max(th, 0.0)) >= cut:
                continue
            c = math.cos(-s * sec)
            sn = math.sin(-s * sec)
            qx = c * xi - sn * yi
            qy = sn * xi + c * yi
        ix = min(max(int((qx - lo0) / cs), 0), ncx - 1)
        iy = min(max(int((qy - lo1) / cs), 0), ncy - 1)
        for ax in range(max(ix - 1, 0), min(ix + 2, ncx)):
            for ay in range(max(iy - 1, 0), min(iy + 2, ncy)):
                for dzc in range(-1, 2):
                    cc = (ax * ncy + ay) * ncz + (iz + dzc) % ncz
                    for e in range(min(count[cc], cells.shape[1])):
                        j = cells[cc, e]
                        if j <= i:
                            continue
                        dx = qx - x[j, 0]
                        dy = qy - x[j, 1]
                        dz = axial_image(zi - x[j, 2], lz)
                        if dx * dx + dy * dy + dz * dz >= cut2:
                            continue
                        if n < m:
                            nb[n, i] = j
                            img[n, i] = s
                            fl[n, i] = 0
                            sh[n, i, 0] = 0.0
                            sh[n, i, 1] = 0.0
                            sh[n, i, 2] = 0.0
                            so = s - wrapk[i] + wrapk[j]  # same physical pair before the wrap
                            for k in range(nnb_o[i]):
                                if nb_o[k, i] == j and img_o[k, i] == so:
                                    if fl_o[k, i] != 0:
                                        fl[n, i] = fl_o[k, i]
                                        a0 = sh_o[k, i, 0]
                                        a1 = sh_o[k, i, 1]
                                        cr = math.cos(wrapk[i] * sec)
                                        sr = math.sin(wrapk[i] * sec)
                                        sh[n, i, 0] = cr * a0 - sr * a1
                                        sh[n, i, 1] = sr * a0 + cr * a1
                                        sh[n, i, 2] = sh_o[k, i, 2]
                                    break
                        n += 1
    nnb[i] = min(n, m)
    cuda.atomic.max(flags, F_NEED, n)
    for a in range(3):
        xref[i, a] = x[i, a]


@gpu_kernel
def g_forces(x, v, w, f, t, rad, mass, inertia, nb, img, nnb, sh, fl, shw, flw, prm, fext,
             record, step, evbuf, flags, acc):
    """Forces [N] and torques [N m] on bead i (own contacts, walls, body forces) and the
    reactions on its partners (atomic adds into f, t, which the last kick zeroed); the torques
    on the stirrer and the chamber wall are added to acc[0], acc[1] [N m]; new contacts
    go to evbuf (row from the counter flags[F_EVENTS]). As
    :func:`millfmu.dem.engine.kernels.compute_forces`, with one thread per bead."""
    i = cuda.grid(1)
    if i >= x.shape[0]:
        return
    dt = prm[K.P_DT]
    ystar = prm[K.P_YSTAR]
    gstar = prm[K.P_GSTAR]
    beta = prm[K.P_BETA]
    mu = prm[K.P_MU]
    mur = prm[K.P_MUR]
    muw = prm[K.P_MUW]
    murw = prm[K.P_MURW]
    eta = prm[K.P_LUB_ETA]
    hcut = prm[K.P_LUB_HCUT]
    hmin = prm[K.P_LUB_HMIN]
    lz = prm[K.P_LZ]
    sec = prm[K.P_SECTOR]
    hproj = prm[K.P_THIST] != 0.0
    cs1 = math.cos(sec)
    sn1 = math.sin(sec)
    cap = evbuf.shape[0]
    xi = x[i, 0]
    yi = x[i, 1]
    zi = x[i, 2]
    ri = rad[i]
    mi = mass[i]
    fx, fy, fz, rxy = body_force(xi, yi, zi, v[i, 0], v[i, 1], v[i, 2], ri, mi, fext[i, 0],
                                 fext[i, 1], fext[i, 2], prm)
    tx = 0.0
    ty = 0.0
    tz = 0.0
    for k in range(nnb[i]):
        j = nb[k, i]
        s = img[k, i]
        cr = 1.0
        sr = 0.0
        if s != 0:
            cr = cs1
            sr = sn1 if s > 0 else -sn1
        # partner (its image for s != 0) in bead i's frame
        xj = cr * x[j, 0] - sr * x[j, 1]
        yj = sr * x[j, 0] + cr * x[j, 1]
        dx = xi - xj
        dy = yi - yj
        dz = axial_image(zi - x[j, 2], lz)
        rj = rad[j]
        rsum = ri + rj
        r2 = dx * dx + dy * dy + dz * dz
        lim = rsum + hcut
        if r2 >= lim * lim:
            if fl[k, i] != 0:
                fl[k, i] = 0
                sh[k, i, 0] = 0.0
                sh[k, i, 1] = 0.0
                sh[k, i, 2] = 0.0
            continue
        vjx = cr * v[j, 0] - sr * v[j, 1]
        vjy = sr * v[j, 0] + cr * v[j, 1]
        wjx = cr * w[j, 0] - sr * w[j, 1]
        wjy = sr * w[j, 0] + cr * w[j, 1]
        r = math.sqrt(r2)
        # 1/r from 1/r2, which does not wait for the root: a product after the root
        # instead of a division
        ir2 = 1.0 / r2
        ir = r * ir2
        nx = dx * ir
        ny = dy * ir
        nz = dz * ir
        delta = rsum - r
        vrx = v[i, 0] - vjx
        vry = v[i, 1] - vjy
        vrz = v[i, 2] - v[j, 2]
        mstar = mi * mass[j] / (mi + mass[j])
        if delta > 0.0:
            if record and fl[k, i] == 0:
                e = cuda.atomic.add(flags, F_EVENTS, 1)
                if e < cap:
                    lev = ri - 0.5 * delta
                    write_event(evbuf[e], 0.0, i, j, xi - lev * nx, yi - lev * ny,
                                zi - lev * nz, vrx, vry, vrz, nx, ny, nz, w[i, 0] - wjx,
                                w[i, 1] - wjy, w[i, 2] - w[j, 2], mstar,
                                inertia[i] * inertia[j] / (inertia[i] + inertia[j]), step)
            fl[k, i] = 1
            s0 = sh[k, i, 0]
            s1 = sh[k, i, 1]
            s2 = sh[k, i, 2]
            sdn, sm0, sm1 = history_frame_pair(s0, s1, s2, dx, dy, dz, ir2, ir)
            if hproj:
                sm1 = 0.0  # "projected": no rescaling
            (gx, gy, gz, tix, tiy, tiz, tjx, tjy, tjz, s0, s1,
             s2) = pair_response(nx, ny, nz, delta, vrx, vry, vrz, w[i, 0], w[i, 1], w[i, 2],
                                 wjx, wjy, w[j, 2], ri, rj, mstar, ri * rj / rsum, s0, s1,
                                 s2, sdn, sm0, sm1, ystar, gstar, beta, mu, mur, dt)
            sh[k, i, 0] = s0
            sh[k, i, 1] = s1
            sh[k, i, 2] = s2
            fx += gx
            fy += gy
            fz += gz
            tx += tix
            ty += tiy
            tz += tiz
            # reaction on j, rotated back into j's frame
            cuda.atomic.add(f, (j, 0), -(cr * gx + sr * gy))
            cuda.atomic.add(f, (j, 1), -(-sr * gx + cr * gy))
            cuda.atomic.add(f, (j, 2), -gz)
            cuda.atomic.add(t, (j, 0), cr * tjx + sr * tjy)
            cuda.atomic.add(t, (j, 1), -sr * tjx + cr * tjy)
            cuda.atomic.add(t, (j, 2), tjz)
        else:
            if fl[k, i] != 0:
                fl[k, i] = 0
                sh[k, i, 0] = 0.0
                sh[k, i, 1] = 0.0
                sh[k, i, 2] = 0.0
            if eta > 0.0:
                fm = lubrication_force(eta, ri * rj / rsum, vrx * nx + vry * ny + vrz * nz,
                                       -delta, hmin)
                fx += fm * nx
                fy += fm * ny
                fz += fm * nz
                cuda.atomic.add(f, (j, 0), -fm * (cr * nx + sr * ny))
                cuda.atomic.add(f, (j, 1), -fm * (-sr * nx + cr * ny))
                cuda.atomic.add(f, (j, 2), -fm * nz)
    # ---- walls ----
    for q in range(K.NWALL):
        (touch, vrx, vry, vrz, nx, ny, nz, wz_w, gx, gy, gz, tix, tiy, tiz, s0, s1, s2,
         twall) = wall_response(xi, yi, zi, v[i, 0], v[i, 1], v[i, 2], w[i, 0],
                                        w[i, 1], w[i, 2], ri, mi, q, shw[i, q, 0],
                                        shw[i, q, 1], shw[i, q, 2], prm, ystar, gstar, beta,
                                        muw, murw, dt)
        if not touch:
            release_wall(flw, shw, i, q)
            continue
        if record and flw[i, q] == 0:
            e = cuda.atomic.add(flags, F_EVENTS, 1)
            if e < cap:
                write_event(evbuf[e], 1.0 + q, i, -1.0, xi, yi, zi, vrx, vry, vrz, nx, ny,
                            nz, w[i, 0], w[i, 1], w[i, 2] - wz_w, mi, inertia[i], step)
        flw[i, q] = 1
        shw[i, q, 0] = s0
        shw[i, q, 1] = s1
        shw[i, q, 2] = s2
        fx += gx
        fy += gy
        fz += gz
        tx += tix
        ty += tiy
        tz += tiz
        cuda.atomic.add(acc, 1 if wall_stands(q) else 0, twall)
    cuda.atomic.add(f, (i, 0), fx)
    cuda.atomic.add(f, (i, 1), fy)
    cuda.atomic.add(f, (i, 2), fz)
    cuda.atomic.add(t, (i, 0), tx)
    cuda.atomic.add(t, (i, 1), ty)
    cuda.atomic.add(t, (i, 2), tz)


class GpuStepper:
    """Owns the device copies of a :class:`millfmu.dem.engine.sim.DemSimulation`'s state and
    advances them; the simulation's host arrays (x, v, w, f, t) are refreshed after every
    run() call, its held force fext is uploaded before each (unless ``fext_on_device``)."""

    CELL_CAP = 16  # beads per cell to start with (a dense bed holds 3 to 4)

    def __init__(self, sim, max_neighbours: int):
        if not cuda.is_available():
            raise RuntimeError("device='gpu': numba.cuda finds no CUDA GPU (set "
                               "NUMBA_ENABLE_CUDASIM=1 to run the GPU kernels in numba's "
                               "simulator)")
        self.sim = sim
        n = sim.n
        # small grids for small systems: the simulator runs each thread in Python
        self.tpb = 128 if n >= 128 else max(n, 1)
        self.blocks = (n + self.tpb - 1) // self.tpb
        g = sim.geometry
        self.cs = sim.cutoff_m
        reach = max(g.chamber_radius_m, g.disc_radius_m) + self.cs
        self.lo = -reach
        self.ncx = self.ncy = int(2.0 * reach / self.cs) + 1
        self.ncz = int(g.height_m / self.cs)
        d = cuda.to_device
        self.x, self.v, self.w = d(sim.x), d(sim.v), d(sim.w)
        self.f, self.t = d(sim.f), d(sim.t)
        self.rad, self.mass, self.inertia = d(sim.rad), d(sim.mass), d(sim.inertia)
        self.inv_m, self.inv_i = d(sim.inv_m), d(sim.inv_i)
        self.xref = d(sim.x)
        self.wrapk = d(np.zeros(n, np.int8))
        self.shw = d(np.zeros((n, K.NWALL, 3)))
        self.flw = d(np.zeros((n, K.NWALL), np.uint8))
        self.fext = d(sim.fext)
        #: the held force is set on the device (a coupling's beads' side on the GPU,
        #: millfmu.dem.coupling.gpu_exchange), not uploaded from sim.fext before each run
        self.fext_on_device = False
        # the initial forces: with history_at_start "zero" no spring increment (dt 0 in the
        # contact law), as on the CPU
        p0 = sim.prm.copy()
        if sim.history_at_start == "zero":
            p0[K.P_DT] = 0.0
        self.prm = d(p0)
        self.flags = d(np.zeros(N_FLAGS, np.int64))
        self.acc = d(np.zeros(2))
        self.evbuf = cuda.device_array((max(65536, 4 * n), K.EV_NF))
        self.count = cuda.to_device(np.zeros(self.ncx * self.ncy * self.ncz, np.int64))
        self.cells = cuda.device_array((self.ncx * self.ncy * self.ncz, self.CELL_CAP),
                                       np.int32)
        self.lists = self._new_lists(max(int(max_neighbours), 1))
        self.spare = self._new_lists(max(int(max_neighbours), 1))
        self._build(wrap=True)
        self._launch(g_zero, self.f, self.t)
        self._forces(record=False, step=0)
        self.prm.copy_to_device(sim.prm)
        self.f.copy_to_host(sim.f)
        self.t.copy_to_host(sim.t)

    def _new_lists(self, m: int) -> dict:
        n = self.sim.n
        return dict(nb=cuda.device_array((m, n), np.int32),
                    img=cuda.device_array((m, n), np.int8),
                    nnb=cuda.to_device(np.zeros(n, np.int32)),
                    sh=cuda.device_array((m, n, 3)),
                    fl=cuda.device_array((m, n), np.uint8))

    def _launch(self, kern, *args):
        kern[self.blocks, self.tpb](*args)

    def _flags(self) -> np.ndarray:
        return self.flags.copy_to_host()

    def _set_flag(self, k: int, value: int):
        h = self._flags()
        h[k] = value
        self.flags.copy_to_device(h)

    def _build(self, wrap: bool):
        if wrap:
            self._launch(g_wrap, self.x, self.v, self.w, self.shw, self.prm, self.wrapk)
        grid = (self.lo, self.lo, self.cs, self.ncx, self.ncy, self.ncz,
                self.sim.geometry.height_m)
        while True:
            self._set_flag(F_CELL, 0)
            self._launch(g_bin, self.x, self.count, self.cells, *grid, self.flags)
            full = int(self._flags()[F_CELL])
            if full <= self.cells.shape[1]:
                break
            self._launch(g_unbin, self.x, self.count, *grid)
            self.cells = cuda.device_array((self.count.shape[0], 2 * full), np.int32)
        while True:
            self._set_flag(F_NEED, 0)
            a, b = self.lists, self.spare
            self._launch(g_build, self.x, self.count, self.cells, self.lo, self.lo, self.cs,
                         self.ncx, self.ncy, self.ncz, self.cs * self.cs, self.prm,
                         self.wrapk, a["nb"], a["img"], a["nnb"], a["sh"], a["fl"], b["nb"],
                         b["img"], b["nnb"], b["sh"], b["fl"], self.xref, self.flags)
            need = int(self._flags()[F_NEED])
            if need <= b["nb"].shape[0]:
                break
            # the current lists are untouched: enlarge the spare ones and build again
            self.spare = self._new_lists(int(need * 1.3) + 4)
        self._launch(g_unbin, self.x, self.count, *grid)
        self.lists, self.spare = self.spare, self.lists
        if self.spare["nb"].shape[0] < self.lists["nb"].shape[0]:
            self.spare = self._new_lists(self.lists["nb"].shape[0])
        self._set_flag(F_REBUILD, 0)

    def _forces(self, record: bool, step: int):
        a = self.lists
        self._launch(g_forces, self.x, self.v, self.w, self.f, self.t, self.rad, self.mass,
                     self.inertia, a["nb"], a["img"], a["nnb"], a["sh"], a["fl"], self.shw,
                     self.flw, self.prm, self.fext, record, step, self.evbuf, self.flags,
                     self.acc)

    def _kick(self, kick: float, drift: bool, zero: bool):
        sim = self.sim
        self._launch(g_kick, self.x, self.v, self.w, self.f, self.t, self.inv_m, self.inv_i,
                     kick, sim.dt_s, drift, self.xref, (0.5 * sim.skin_m) ** 2, self.flags,
                     zero)

    def _drain(self, out: list, dropped: int) -> int:
        """Move the recorded contacts to the host (appended to out); returns the dropped
        count so far."""
        h = self._flags()
        m = int(h[F_EVENTS])
        if m:
            keep = min(m, self.evbuf.shape[0])
            out.append(self.evbuf[:keep].copy_to_host())
            dropped += m - keep
            h[F_EVENTS] = 0
            self.flags.copy_to_device(h)
        return dropped

    def run(self, nsteps: int, record: bool):
        """Advance nsteps velocity-Verlet steps (as kernels.advance); returns (events with
        the step within this call, stirrer and chamber torque sums [N m x steps], dropped
        contacts, neighbour builds)."""
        if nsteps <= 0:  # as on the CPU: nothing moves, the forces stay
            return np.zeros((0, K.EV_NF)), 0.0, 0.0, 0, 0
        sim = self.sim
        dt = sim.dt_s
        if not self.fext_on_device:
            self.fext.copy_to_device(sim.fext)
        self.acc.copy_to_device(np.zeros(2))
        events: list = []
        dropped = 0
        builds = 0
        # every kick but a run's last zeroes the forces it has read (the host keeps a
        # run's last forces, which the next run's first half kick reads)
        self._kick(0.5 * dt, True, True)
        for step in range(nsteps):
            h = self._flags()
            if h[F_REBUILD]:
                self._build(wrap=True)
                builds += 1
            if record and h[F_EVENTS] > self.evbuf.shape[0] // 2:
                dropped = self._drain(events, dropped)
            self._forces(record, step)
            last = step == nsteps - 1
            self._kick(0.5 * dt if last else dt, not last, not last)
        if record:
            dropped = self._drain(events, dropped)
        self.fetch()
        acc = self.acc.copy_to_host()
        ev = np.concatenate(events) if events else np.zeros((0, K.EV_NF))
        return ev, float(acc[0]), float(acc[1]), dropped, builds

    def fetch(self):
        """Copy the beads' state and forces (x, v, w, f, t) to the simulation's host
        arrays."""
        for name in ("x", "v", "w", "f", "t"):
            getattr(self, name).copy_to_host(getattr(self.sim, name))

    def upload(self, names):
        """Copy the host arrays named (v, w) to the device."""
        for name in names:
            getattr(self, name).copy_to_device(getattr(self.sim, name))

    def pairs(self):
        """(i, j, s) of the current neighbour lists, on the host."""
        nnb = self.lists["nnb"].copy_to_host()
        nb = self.lists["nb"].copy_to_host()
        img = self.lists["img"].copy_to_host()
        slot = np.arange(nb.shape[0])[:, None] < nnb[None, :]
        k, i = np.nonzero(slot)
        return i, nb[k, i].astype(np.int64), img[k, i].astype(np.int64)
