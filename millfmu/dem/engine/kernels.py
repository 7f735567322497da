"""Numba kernels of the bead DEM: neighbour lists, contact forces, walls, drag, integration.

Everything here works on plain arrays in SI units (m, kg, s, N, rad). The Python side
(:mod:`millfmu.dem.engine.sim`) owns the arrays and calls :func:`advance`.

Conventions
- The mill axis is z. The stirrer (shaft and discs) rotates about +z with angular
  velocity ``prm[P_OMEGA]`` [rad/s].
- Axial periodicity with period ``prm[P_LZ]`` [m] (minimum image in z).
- Optional angular sector ``[0, prm[P_SECTOR])`` [rad] with rotational periodicity:
  a partner bead may be an image of a real bead rotated by ``s * sector`` with
  ``s`` in {-1, 0, +1}; neighbour entries store ``s`` next to the partner index.
- Neighbour lists are *half* lists (Verlet lists with a skin, built from a cell grid):
  a pair is stored once, in the row of its lower bead index, with its tangential history
  and contact flag, and is evaluated once per step. The pairs of a chunk of beads are
  stored row after row in one region of flat pair arrays (no empty slots between rows:
  the force loop is bound by the memory traffic of the pair data). Beads are split into
  contiguous chunks, a fixed number for a given bead count (more than threads, so that
  a thread held up on a shared machine leaves its chunks to the others, and so that the
  results do not depend on the thread count); each chunk adds its forces into its own
  buffer (its beads and their higher-indexed partners), and a second pass sums the
  buffers and integrates: no atomic additions, no races. The threads take the chunks
  from counters (:mod:`millfmu.dem.engine.chunk_claims`: each thread its own contiguous
  region first). A contact is recorded once, at its first overlap.

Contact model (as in LIGGGHTS, see the project REFERENCE "DEM contact model"):
Hertz-Mindlin with k_n = 4/3 Y* sqrt(R* d_n), S_t = 8 G* sqrt(R* d_n), viscous damping
gamma = -2 sqrt(5/6) beta sqrt(S m*), beta = ln e / sqrt(ln^2 e + pi^2), Coulomb limit
on the tangential history spring, constant directional torque rolling friction
|M_r| = mu_r k_n d_n R*. Lubrication between beads not in contact,
F = -6 pi eta R*^2 v_n / max(h, h_min) for h < h_cut; or instead (prm[P_WET]) a restitution
per contact from the Stokes number of its approach, its damping ratio kept as a level in
the contact's flag (:mod:`millfmu.dem.engine.legendre2006`). Drag after Koch & Hill (2001)
in the CFDEM form ("model A", not divided by the void fraction;
:mod:`millfmu.dem.engine.koch_hill2001`).
"""

import math

import numpy as np
from numba import get_thread_id, prange

from millfmu.dem.engine._jit import contact, device, kernel, nonneg, serial
from millfmu.dem.engine.chunk_claims import claim, reset_claims
from millfmu.dem.engine.koch_hill2001 import beta_of_terms
from millfmu.dem.engine.legendre2006 import contact_level

# ---- layout of the parameter vector prm (float64) -------------------------------------
P_DT = 0  # time step [s]
P_YSTAR = 1  # effective Young's modulus Y* [Pa]
P_GSTAR = 2  # effective shear modulus G* [Pa]
P_BETA = 3  # damping ratio from restitution, ln e / sqrt(ln^2 e + pi^2) [-]
P_MU = 4  # Coulomb friction coefficient [-]
P_MUR = 5  # rolling friction coefficient [-]
P_LUB_ETA = 6  # lubrication viscosity [Pa s]; 0 switches lubrication off
P_LUB_HCUT = 7  # lubrication cutoff gap [m]
P_LUB_HMIN = 8  # lubrication minimum gap [m]
P_GX = 9  # effective (buoyancy-reduced) gravity, x [m/s2]
P_GY = 10
P_GZ = 11
P_LZ = 12  # axial period [m]
P_SECTOR = 13  # sector angle [rad]; 0 means the full circle
P_RSH = 14  # shaft radius [m]
P_RCH = 15  # chamber radius [m]
P_OMEGA = 16  # stirrer angular velocity about +z [rad/s]
P_RDISC = 17  # disc radius [m]; 0 means no disc
P_BDISC = 18  # disc thickness [m]
P_ZDISC = 19  # axial position of the disc mid-plane [m]
P_DRAG = 20  # 1 switches fluid drag on
P_MUF = 21  # fluid dynamic viscosity [Pa s]
P_EPSF = 22  # void fraction used in the drag law [-]
P_KCORE = 23  # swirl core rotation as a fraction of the stirrer's [-]
P_DELTA = 24  # boundary-layer thickness of the prescribed swirl [m]
P_RHOF = 25  # fluid density [kg/m3]
P_SKIN = 26  # neighbour-list skin [m]
P_KH_F0 = 27  # Koch-Hill F0 at the drag law's void fraction [-]
P_KH_F3 = 28  # Koch-Hill F3 at the drag law's void fraction [-]
# rotor with channels (accelerator rotors, :mod:`millfmu.dem.mills.accelerator`): two shroud
# slabs r_eye..R at |z - z_disc| in [h_ch / 2, b / 2] around a channel of height h_ch that
# holds n_vane radial vanes (r_sh..R, thickness t_vane, |z - z_disc| <= h_ch / 2)
P_REYE = 29  # inner radius of the rotor's slabs [m] (the disc: the shaft radius)
P_HCH = 30  # channel height between the shrouds [m]; 0: a solid disc
P_NVANE = 31  # number of vanes over the full circle; 0: none
P_TVANE = 32  # vane thickness [m]
P_ROTANG = 33  # rotor angle [rad] at the positions' time (first vane at this angle)
# stationary baffles (:class:`millfmu.dem.mills.geometry.MillGeometry`): n_baf radial plates
# on the chamber wall, r_baf..r_ch, thickness t_baf, |z - z_disc - L_z / 2| <= h_baf / 2
P_NBAF = 34  # number of baffles over the full circle; 0: none
P_TBAF = 35  # baffle thickness [m]
P_RBAF = 36  # inner radius of the baffles [m]
P_HBAF = 37  # axial height of the baffles [m]
P_ABAF = 38  # angle of the first baffle [rad]
# tangential history in a turning contact plane: 0 "rescaled" (projected, then its old
# length restored), 1 "projected" (projected only); see hertz_mindlin
P_THIST = 39
# wet collisions: 0 the lubrication force between close beads (P_LUB_*, seed 001), 1 a
# restitution per contact from its Stokes number (:mod:`millfmu.dem.engine.legendre2006`)
P_WET = 40
P_WET_ETA = 41  # viscosity of the contact's Stokes number [Pa s]
P_WET_ST = 42  # Stokes number scale of e / e_dry = exp(-scale / St) [-]
P_WTAB = 43  # 256 entries: damping ratio beta [-] of each contact level (legendre2006.beta_table)
P_MUW = P_WTAB + 256  # Coulomb friction coefficient of bead-wall contacts [-]
P_MURW = P_MUW + 1  # rolling friction coefficient of bead-wall contacts [-]
N_PRM = P_MURW + 1

# wall ids: 0 shaft (rotating), 1 chamber (fixed), 2 disc or shrouds (rotating), 3 vanes
# (rotating), 4 baffles (fixed)
NWALL = 5

# ---- layout of a recorded contact (float64 row) -------------------------------------
EV_TYPE = 0  # 0 bead-bead, 1 + wall id for bead-wall
EV_I = 1
EV_J = 2  # partner bead index, -1 for walls
EV_X = 3  # where: two beads, the middle of their overlap; a wall, the bead's centre [m]
EV_Y = 4
EV_Z = 5
EV_SETN = 6  # translational normal stress energy 1/2 m* v_n^2 [J]
EV_SETS = 7  # translational shear stress energy 1/2 m* |v_t,trans|^2 [J]
EV_SEROT = 8  # rotational stress energy 1/2 I* |w_i - w_j|^2 [J]
EV_VN = 9  # normal approach speed [m/s]
EV_STEP = 10  # step index within the advance() call
EV_NF = 11

SQRT56 = math.sqrt(5.0 / 6.0)


@contact
def hertz_mindlin(nx, ny, nz, delta, vrx, vry, vrz, wsx, wsy, wsz, wrx, wry, wrz,
                  mstar, rstar, s0, s1, s2, sdn, sm0, sm1, ystar, gstar, beta, mu, mur, dt):
    """Hertz-Mindlin contact force on bead i, LIGGGHTS form (REFERENCE, DEM contact model).

    n: unit normal pointing from partner j to bead i; delta: overlap [m] (> 0);
    vr: v_i - v_j of the centres [m/s] (for a wall: minus the wall velocity at the contact
    point); ws = r_i w_i + r_j w_j [m/s] (lever-weighted angular velocities);
    wr = w_i - w_j [rad/s] (rolling); mstar [kg], rstar [m]; s: tangential history [m],
    with sdn = s.n [m], sm0 = |s|^2 and sm1 = |s - (s.n) n|^2 [m2] from
    :func:`history_frame` or :func:`history_frame_pair`.
    Returns the normal and tangential force on i [N], the rolling torque on i [N m],
    the updated history [m] and the elastic normal force k_n delta [N].

    The history is first brought into the current tangent plane: its normal part is
    removed and its old length restored (``"rescaled"``, prm[P_THIST] = 0, the default),
    or, when the caller passes sm1 = 0 (``"projected"``, prm[P_THIST] = 1), its normal
    part is removed only, as in LAMMPS' ``pair_style gran/hertz/history`` and
    LIGGGHTS' ``tangential history``. The rescaled form is the objective one: a pair
    that turns as a rigid body keeps its spring, where the projection shortens it by
    the factor cos(turn) of each step (Luding, Granular Matter 10 (2008) 235, eq. 17;
    LAMMPS' ``pair_style granular`` rescales for that reason). The two differ by terms
    of second order in the turn per step, so they agree as dt -> 0. On the DEM bench
    bed (1000 steps) the projected form changed the kinetic energy by about 1 %, within
    the spread of runs that differ by 1e-9 m in the start.
    """
    sq = math.sqrt(rstar * delta)
    kn = 4.0 / 3.0 * ystar * sq
    st = 8.0 * gstar * sq
    # gamma_n = -2 sqrt(5/6) beta sqrt(S_n m*) with S_n = 2 Y* sq, gamma_t the same with
    # S_t = 8 G* sq: one root of sq m* serves both
    rm = math.sqrt(sq * mstar)
    gn = -2.0 * SQRT56 * beta * math.sqrt(2.0 * ystar) * rm
    gt = -2.0 * SQRT56 * beta * math.sqrt(8.0 * gstar) * rm
    vn = vrx * nx + vry * ny + vrz * nz
    fel = kn * delta
    fnm = fel - gn * vn
    fnx = fnm * nx
    fny = fnm * ny
    fnz = fnm * nz
    # contact-point relative velocity: v_i - v_j - (r_i w_i + r_j w_j) x n, tangential part
    cx = wsy * nz - wsz * ny
    cy = wsz * nx - wsx * nz
    cz = wsx * ny - wsy * nx
    vtx = vrx - vn * nx - cx
    vty = vry - vn * ny - cy
    vtz = vrz - vn * nz - cz
    # history: rotate the old spring into the current tangent plane, keep its length
    # (the length ratio from the squared lengths: one root instead of two); sm1 = 0:
    # projected only
    s0 -= sdn * nx
    s1 -= sdn * ny
    s2 -= sdn * nz
    if sm1 > 0.0:
        sc = math.sqrt(sm0 / sm1)
        s0 *= sc
        s1 *= sc
        s2 *= sc
    s0 += vtx * dt
    s1 += vty * dt
    s2 += vtz * dt
    ftx = -st * s0 - gt * vtx
    fty = -st * s1 - gt * vty
    ftz = -st * s2 - gt * vtz
    ft2 = ftx * ftx + fty * fty + ftz * ftz
    fcap = mu * abs(fnm)
    if ft2 > fcap * fcap:
        ratio = fcap / math.sqrt(ft2)
        ftx *= ratio
        fty *= ratio
        ftz *= ratio
        # spring reset to the Coulomb cap (LIGGGHTS tangential_history)
        ist = 1.0 / st
        s0 = -(ftx + gt * vtx) * ist
        s1 = -(fty + gt * vty) * ist
        s2 = -(ftz + gt * vtz) * ist
    mrx = 0.0
    mry = 0.0
    mrz = 0.0
    if mur > 0.0:
        wrm = math.sqrt(wrx * wrx + wry * wry + wrz * wrz)
        if wrm > 1e-12:
            m = -mur * fel * rstar / wrm
            mrx = m * wrx
            mry = m * wry
            mrz = m * wrz
    return fnx, fny, fnz, ftx, fty, ftz, mrx, mry, mrz, s0, s1, s2, fel


@contact
def history_frame(s0, s1, s2, nx, ny, nz):
    """(s.n [m], |s|^2, |s - (s.n) n|^2 [m2]) of a tangential history s [m] against the
    unit normal n, for :func:`hertz_mindlin`."""
    sdn = s0 * nx + s1 * ny + s2 * nz
    p0 = s0 - sdn * nx
    p1 = s1 - sdn * ny
    p2 = s2 - sdn * nz
    return sdn, s0 * s0 + s1 * s1 + s2 * s2, p0 * p0 + p1 * p1 + p2 * p2


@contact
def history_frame_pair(s0, s1, s2, dx, dy, dz, ir2, ir):
    """:func:`history_frame` for a bead pair from its separation d [m] (ir2 = 1 / |d|^2
    [1/m2], ir = 1 / |d| [1/m]): |s - (s.n) n|^2 = |s|^2 - (s.d)^2 / |d|^2, which needs no
    root, so the length ratio's division and root wait for a division of |d|^2 only, not
    for the root of |d|^2 and a division after it (the longest chain of dependent operations in the
    contact law, which this form shortens). The two forms differ by round-off: the history lies in the previous step's tangent plane, so
    |s.n| << |s| and the difference does not cancel."""
    sm0 = s0 * s0 + s1 * s1 + s2 * s2
    sdd = s0 * dx + s1 * dy + s2 * dz
    return sdd * ir, sm0, sm0 - sdd * sdd * ir2


@device
def swirl_velocity(x, y, z, prm):
    """Prescribed swirl flow of the fluid [m/s] at (x, y, z) [m]; a stand-in until a coupled
    fluid model exists.

    Without a disc: circular Couette flow between the rotating shaft (speed omega r_sh)
    and the fixed chamber wall, u = A r + B / r.
    With a disc: between the discs (r <= R) the fluid rotates as a core at k_core times
    the stirrer's angular velocity, rising to the wall speed within a boundary layer of
    thickness delta at the disc faces and at the shaft, u = omega r [k + (1 - k)
    max(exp(-s/delta), exp(-(r - r_sh)/delta))] (s: axial distance from the disc face);
    outside the disc radius it falls linearly to zero at the chamber wall. Purely
    azimuthal: no radial or axial circulation (no vortices).
    """
    om = prm[P_OMEGA]
    rsh = prm[P_RSH]
    rch = prm[P_RCH]
    r = math.sqrt(x * x + y * y)
    if r <= 0.0:
        return 0.0, 0.0, 0.0
    rd = prm[P_RDISC]
    if rd <= 0.0:
        den = rch * rch - rsh * rsh
        a = -om * rsh * rsh / den
        b = om * rsh * rsh * rch * rch / den
        u = a * r + b / r
    else:
        lz = prm[P_LZ]
        zr = z - prm[P_ZDISC]
        zr -= lz * math.floor(zr / lz + 0.5)
        s = abs(zr) - 0.5 * prm[P_BDISC]
        if s < 0.0:
            s = 0.0
        k = prm[P_KCORE]
        dl = prm[P_DELTA]
        rr = min(r, rd)
        f = max(math.exp(-s / dl), math.exp(-(rr - rsh) / dl))
        u = om * rr * (k + (1.0 - k) * f)
        if r > rd:
            u *= max(rch - r, 0.0) / (rch - rd)
    return -u * y / r, u * x / r, 0.0


@device
def wall_gap(x, y, z, rad, w, prm):
    """Distance geometry of bead (x, y, z), radius rad [m], to wall w.

    Returns (dist, nx, ny, nz, ok): dist from the bead centre to the wall surface [m],
    unit normal from the wall towards the bead, ok = False if the wall does not exist
    or the bead is far from it.
    """
    r = math.sqrt(x * x + y * y)
    if r <= 1e-300:
        return 1.0, 1.0, 0.0, 0.0, False
    ex = x / r
    ey = y / r
    if w == 0:  # shaft, bead outside the cylinder
        return r - prm[P_RSH], ex, ey, 0.0, True
    if w == 1:  # chamber, bead inside the cylinder
        return prm[P_RCH] - r, -ex, -ey, 0.0, True
    rd = prm[P_RDISC]
    if rd <= 0.0:
        return 1.0, 1.0, 0.0, 0.0, False
    lz = prm[P_LZ]
    if w == 4:
        return baffle_gap(x, y, z, rad, r, prm)
    zr = z - prm[P_ZDISC]
    zr -= lz * math.floor(zr / lz + 0.5)
    hb = 0.5 * prm[P_BDISC]
    hc = 0.5 * prm[P_HCH]
    if w == 3:
        nv = prm[P_NVANE]
        if nv <= 0.0 or abs(zr) - hc > rad:
            return 1.0, 1.0, 0.0, 0.0, False
        return plate_gap(x, y, zr, prm[P_ROTANG], 2.0 * math.pi / nv, prm[P_RSH], rd,
                         0.5 * prm[P_TVANE], hc)
    # closest point of the disc (an annular slab r_in..R, |z| <= b/2) in the (r, z) plane,
    # or with a channel, of the nearer shroud (r_in..R, h_ch/2 <= |z| <= b/2)
    rin = max(prm[P_REYE], prm[P_RSH])
    rc = min(max(r, rin), rd)
    zlo = -hb
    zhi = hb
    if hc > 0.0:
        if zr >= 0.0:
            zlo = hc
        else:
            zhi = -hc
    zc = min(max(zr, zlo), zhi)
    dr = r - rc
    dz = zr - zc
    d = math.sqrt(dr * dr + dz * dz)
    if d > 1e-300:
        return d, dr / d * ex, dr / d * ey, dz / d, True
    # centre inside the slab (should not happen): push out through the nearest face
    zmid = 0.5 * (zlo + zhi)
    hh = 0.5 * (zhi - zlo)
    if rd - r < hh - abs(zr - zmid):
        return -(rd - r), ex, ey, 0.0, True
    sgn = 1.0 if zr >= zmid else -1.0
    return -(hh - abs(zr - zmid)), 0.0, 0.0, sgn, True


@device
def plate_gap(x, y, zp, a0, pitch, s_lo, s_hi, ht, hh):
    """:func:`wall_gap` for the nearest of a row of radial plates (the vanes, the baffles):
    the first at angle a0 [rad], one every ``pitch`` [rad], each from s_lo to s_hi [m]
    along its radial mid-line, half thickness ht and half height hh [m] about its axial
    mid-plane; zp [m] is the point's axial distance from that plane. For radial plates the
    nearest in angle is the nearest in distance."""
    ang = a0 + pitch * math.floor((math.atan2(y, x) - a0) / pitch + 0.5)
    ca = math.cos(ang)
    sa = math.sin(ang)
    s = x * ca + y * sa  # along the plate
    t = -x * sa + y * ca  # across it
    ds = s - min(max(s, s_lo), s_hi)
    dt_ = t - min(max(t, -ht), ht)
    dz = zp - min(max(zp, -hh), hh)
    d = math.sqrt(ds * ds + dt_ * dt_ + dz * dz)
    if d > 1e-300:
        return d, (ds * ca - dt_ * sa) / d, (ds * sa + dt_ * ca) / d, dz / d, True
    sgn = 1.0 if t >= 0.0 else -1.0  # centre inside the plate: out through its face
    return -(ht - abs(t)), -sgn * sa, sgn * ca, 0.0, True


@device
def baffle_gap(x, y, z, rad, r, prm):
    """:func:`wall_gap` for the nearest stationary baffle (wall 4): a plate from r_baf to
    the chamber wall along its radial mid-line at angle a, thickness t_baf, axial height
    h_baf centred half a period from the rotor's mid-plane; r = |(x, y)| [m]."""
    nb = prm[P_NBAF]
    if nb <= 0.0 or r - prm[P_RBAF] < -rad:
        return 1.0, 1.0, 0.0, 0.0, False
    lz = prm[P_LZ]
    zb = z - prm[P_ZDISC] - 0.5 * lz
    zb -= lz * math.floor(zb / lz + 0.5)
    hh = 0.5 * prm[P_HBAF]
    if abs(zb) - hh > rad:
        return 1.0, 1.0, 0.0, 0.0, False
    return plate_gap(x, y, zb, prm[P_ABAF], 2.0 * math.pi / nb, prm[P_RBAF], prm[P_RCH],
                     0.5 * prm[P_TBAF], hh)


@contact
def wall_stands(q):
    """Whether wall q stands still (chamber 1, baffles 4); the others turn with the
    stirrer at prm[P_OMEGA], and their torque is the stirrer's."""
    return q == 1 or q == 4


@contact
def axial_image(dz, lz):
    """Axial separation dz [m] reduced to the nearest periodic image (|dz| <= lz / 2 for
    separations below 1.5 lz)."""
    if dz > 0.5 * lz:
        return dz - lz
    if dz < -0.5 * lz:
        return dz + lz
    return dz


@contact
def pair_response(nx, ny, nz, delta, vrx, vry, vrz, wix, wiy, wiz, wjx, wjy, wjz, ri, rj,
                  mstar, rstar, s0, s1, s2, sdn, sm0, sm1, ystar, gstar, beta, mu, mur, dt):
    """Force [N] on bead i and torques [N m] on i and j of a bead-bead contact (partner j in
    i's frame, n from j to i): :func:`hertz_mindlin` with m* [kg] and R* = ri rj / (ri + rj)
    [m] from the caller, the tangential force acting at -ri n on i and at +rj n on j. Returns
    (F, T_i, T_j, new history [m])."""
    (fnx, fny, fnz, ftx, fty, ftz, mrx, mry, mrz, s0, s1, s2,
     fel) = hertz_mindlin(nx, ny, nz, delta, vrx, vry, vrz,
                          ri * wix + rj * wjx, ri * wiy + rj * wjy, ri * wiz + rj * wjz,
                          wix - wjx, wiy - wjy, wiz - wjz, mstar, rstar,
                          s0, s1, s2, sdn, sm0, sm1, ystar, gstar, beta, mu, mur, dt)
    # torque of F_t at -r_i n on i; on j, -F_t at +r_j n: -r_j n x F_t, the same sense
    cx = ny * ftz - nz * fty
    cy = nz * ftx - nx * ftz
    cz = nx * fty - ny * ftx
    return (fnx + ftx, fny + fty, fnz + ftz, -ri * cx + mrx, -ri * cy + mry, -ri * cz + mrz,
            -rj * cx - mrx, -rj * cy - mry, -rj * cz - mrz, s0, s1, s2)


@contact
def wall_response(xi, yi, zi, vix, viy, viz, wix, wiy, wiz, ri, mi, q, s0, s1, s2, prm,
                  ystar, gstar, beta, mu, mur, dt):
    """Contact of a bead (centre x [m], velocity v [m/s], spin w [rad/s]) with wall q
    (:func:`wall_gap`; the shaft, disc and vanes turn at prm[P_OMEGA], the chamber and the
    baffles stand):
    Hertz-Mindlin with R* = ri, m* = mi against the wall's surface velocity at the
    contact point p = x - ri n. Returns (touching, v - v_wall, n, wall spin about z [rad/s],
    force [N] and torque [N m] on the bead, new history [m], torque about +z on the
    wall [N m])."""
    dist, nx, ny, nz, ok = wall_gap(xi, yi, zi, ri, q, prm)
    delta = ri - dist
    if not ok or delta <= 0.0:
        return (False, 0.0, 0.0, 0.0, nx, ny, nz, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                0.0, 0.0, 0.0)
    px = xi - ri * nx
    py = yi - ri * ny
    om = 0.0 if wall_stands(q) else prm[P_OMEGA]
    vrx = vix + om * py
    vry = viy - om * px
    sdn, sm0, sm1 = history_frame(s0, s1, s2, nx, ny, nz)
    if prm[P_THIST] != 0.0:
        sm1 = 0.0  # "projected": no rescaling
    (fnx, fny, fnz, ftx, fty, ftz, mrx, mry, mrz, s0, s1, s2,
     fel) = hertz_mindlin(nx, ny, nz, delta, vrx, vry, viz, ri * wix, ri * wiy, ri * wiz,
                          wix, wiy, wiz - om, mi, ri, s0, s1, s2, sdn, sm0, sm1, ystar,
                          gstar, beta, mu, mur, dt)
    gx = fnx + ftx
    gy = fny + fty
    # reaction on the wall: -F at p, plus the rolling torque's reaction
    return (True, vrx, vry, viz, nx, ny, nz, om, gx, gy, fnz + ftz,
            -ri * (ny * ftz - nz * fty) + mrx, -ri * (nz * ftx - nx * ftz) + mry,
            -ri * (nx * fty - ny * ftx) + mrz, s0, s1, s2, -(px * gy - py * gx) - mrz)


@device
def body_force(xi, yi, zi, vix, viy, viz, ri, mi, fr, tzh, fzh, prm):
    """Force [N] on a bead from everything but contacts: gravity (buoyancy-reduced, prm
    P_GX..P_GZ), the held force of a coupled fluid (F_r [N], T_z [N m], F_z [N], in
    cylindrical components at the bead: F_r e_r + T_z / r e_theta + F_z e_z) and, with
    prm[P_DRAG], Koch-Hill drag from the prescribed swirl. Also returns the bead's
    distance from the axis [m]."""
    fx = mi * prm[P_GX]
    fy = mi * prm[P_GY]
    fz = mi * prm[P_GZ]
    rxy = math.sqrt(xi * xi + yi * yi)
    if rxy > 0.0:
        fx += (fr * xi - tzh * yi / rxy) / rxy
        fy += (fr * yi + tzh * xi / rxy) / rxy
    fz += fzh
    if prm[P_DRAG] > 0.0:
        ux, uy, uz = swirl_velocity(xi, yi, zi, prm)
        ux -= vix
        uy -= viy
        uz -= viz
        um = math.sqrt(ux * ux + uy * uy + uz * uz)
        bt = beta_of_terms(2.0 * ri, prm[P_EPSF], prm[P_MUF], prm[P_RHOF], um,
                           prm[P_KH_F0], prm[P_KH_F3])
        vp = 4.0 / 3.0 * math.pi * ri ** 3
        fx += vp * bt * ux
        fy += vp * bt * uy
        fz += vp * bt * uz
    return fx, fy, fz, rxy


@device
def lubrication_force(eta, rstar, vn, gap, hmin):
    """Normal lubrication force [N] on bead i, -6 pi eta R*^2 v_n / max(h, h_min)
    (REFERENCE, "Lubrication between beads"); vn: normal relative velocity [m/s]."""
    return -6.0 * math.pi * eta * rstar * rstar * vn / max(gap, hmin)


@device
def write_event(row, typ, i, j, px, py, pz, vrx, vry, vrz, nx, ny, nz, wrx, wry, wrz,
                mstar, istar, step):
    """Record a contact at its first overlap into ``row`` (layout EV_*): position p [m]
    (two beads: the middle of their overlap; a wall: the bead's centre), stress energies
    from the relative velocity vr [m/s] split along the normal n, and the relative spin
    wr [rad/s]: SE_tn = 1/2 m* v_n^2, SE_ts = 1/2 m* |v_t|^2, SE_rot = 1/2 I* |wr|^2 [J]
    (m* [kg], I* [kg m2]: reduced for two beads, the bead's own against a wall)."""
    vn = vrx * nx + vry * ny + vrz * nz
    vtx = vrx - vn * nx
    vty = vry - vn * ny
    vtz = vrz - vn * nz
    row[EV_TYPE] = typ
    row[EV_I] = i
    row[EV_J] = j
    row[EV_X] = px
    row[EV_Y] = py
    row[EV_Z] = pz
    row[EV_SETN] = 0.5 * mstar * vn * vn
    row[EV_SETS] = 0.5 * mstar * (vtx * vtx + vty * vty + vtz * vtz)
    row[EV_SEROT] = 0.5 * istar * (wrx * wrx + wry * wry + wrz * wrz)
    row[EV_VN] = -vn
    row[EV_STEP] = step


# ---- integration -----------------------------------------------------------------------

@kernel
def kick_drift(x, v, w, f, t, inv_m, inv_i, kick, dt, xref, cb, dmax):
    """v += kick F/m, w += kick T/I, x += dt v for all beads; dmax[c] = largest squared
    displacement [m2] since the last neighbour build within chunk c."""
    for c in prange(cb.shape[0] - 1):
        dm = 0.0
        for i0 in range(cb[c], cb[c + 1]):
            i = nonneg(i0)
            for k in range(3):
                v[i, k] += kick * f[i, k] * inv_m[i]
                w[i, k] += kick * t[i, k] * inv_i[i]
                x[i, k] += dt * v[i, k]
            d0 = x[i, 0] - xref[i, 0]
            d1 = x[i, 1] - xref[i, 1]
            d2 = x[i, 2] - xref[i, 2]
            dd = d0 * d0 + d1 * d1 + d2 * d2
            if dd > dm:
                dm = dd
        dmax[c] = dm


# ---- neighbour lists -------------------------------------------------------------------

@device
def wrap_one(i, x, v, w, shw, prm, wrapk):
    """Bring bead i back into [0, Lz) axially and into the sector [0, sector) angularly.

    A bead leaving the sector is rotated by -+sector together with its velocity, spin and
    wall-contact history; wrapk[i] receives the rotation applied in units of the sector
    (-1, 0, +1) so that pair histories can be carried over in :func:`build_nlist`.
    """
    lz = prm[P_LZ]
    sec = prm[P_SECTOR]
    x[i, 2] -= lz * math.floor(x[i, 2] / lz)
    wrapk[i] = 0
    if sec > 0.0:
        th = math.atan2(x[i, 1], x[i, 0])
        k = 0
        if th < 0.0:
            k = 1
        elif th >= sec:
            k = -1
        if k != 0:
            wrapk[i] = k
            c = math.cos(k * sec)
            s = math.sin(k * sec)
            for a in range(3):
                if a == 0:
                    arr = x
                elif a == 1:
                    arr = v
                else:
                    arr = w
                x0 = arr[i, 0]
                y0 = arr[i, 1]
                arr[i, 0] = c * x0 - s * y0
                arr[i, 1] = s * x0 + c * y0
            for q in range(NWALL):
                x0 = shw[i, q, 0]
                y0 = shw[i, q, 1]
                shw[i, q, 0] = c * x0 - s * y0
                shw[i, q, 1] = s * x0 + c * y0


@kernel
def wrap_periodic(x, v, w, shw, prm, wrapk, cb):
    """:func:`wrap_one` for every bead, the chunks cb on the threads (each bead's rows
    only: the same on any thread count)."""
    for c in prange(cb.shape[0] - 1):
        for i in range(cb[c], cb[c + 1]):
            wrap_one(nonneg(i), x, v, w, shw, prm, wrapk)


@serial
def make_entries(x, prm, cut):
    """Cell-list entries: every bead, plus rotated images of beads within ``cut`` [m] of a
    sector boundary. Returns (bead index, image code s, position [m])."""
    n = x.shape[0]
    sec = prm[P_SECTOR]
    cnt = n
    flag = np.zeros(n, np.int8)
    if sec > 0.0:
        for i in range(n):
            r = math.sqrt(x[i, 0] ** 2 + x[i, 1] ** 2)
            th = math.atan2(x[i, 1], x[i, 0])
            # distance to the two boundary rays (sector <= pi/2, so sin is monotone here)
            if r * math.sin(max(th, 0.0)) < cut:
                flag[i] |= 1
                cnt += 1
            if r * math.sin(max(sec - th, 0.0)) < cut:
                flag[i] |= 2
                cnt += 1
    ej = np.empty(cnt, np.int64)
    es = np.zeros(cnt, np.int8)
    ex = np.empty((cnt, 3))
    for i in range(n):
        ej[i] = i
        ex[i, 0] = x[i, 0]
        ex[i, 1] = x[i, 1]
        ex[i, 2] = x[i, 2]
    m = n
    if sec > 0.0:
        for i in range(n):
            for b in range(2):
                if flag[i] & (1 << b):
                    s = 1 if b == 0 else -1
                    c = math.cos(s * sec)
                    sn = math.sin(s * sec)
                    ej[m] = i
                    es[m] = s
                    ex[m, 0] = c * x[i, 0] - sn * x[i, 1]
                    ex[m, 1] = sn * x[i, 0] + c * x[i, 1]
                    ex[m, 2] = x[i, 2]
                    m += 1
    return ej, es, ex


@serial
def bin_entries(ej, es, ex, lo, cs, ncx, ncy, ncz, lz):
    """Counting sort of entries into cells of size cs [m] (z periodic with ncz cells over
    lz). Returns (cell_start, bead index, image code, position [m] by component (3,
    entries), highest bead index per cell) with the entries of each cell contiguous, so
    that the neighbour search streams through memory."""
    ne = ex.shape[0]
    ncell = ncx * ncy * ncz
    cid = np.empty(ne, np.int64)
    start = np.zeros(ncell + 1, np.int64)
    csz = lz / ncz
    # the cells first, in a loop of their own (its divisions on vector instructions), then
    # their counts
    for e in range(ne):
        ix = min(max(int((ex[e, 0] - lo[0]) / cs), 0), ncx - 1)
        iy = min(max(int((ex[e, 1] - lo[1]) / cs), 0), ncy - 1)
        zz = ex[e, 2] - lz * math.floor(ex[e, 2] / lz)
        iz = min(int(zz / csz), ncz - 1)
        cid[e] = (ix * ncy + iy) * ncz + iz
    for e in range(ne):
        start[nonneg(cid[e]) + 1] += 1
    for c in range(ncell):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    cmax = np.full(ncell, -1, np.int64)
    sj = np.empty(ne, np.int64)
    ss = np.empty(ne, np.int8)
    # coordinates by component (3, ne): the neighbour search tests a run of entries with
    # vector instructions (build_nlist)
    sx = np.empty((3, ne))
    for e in range(ne):
        c = nonneg(cid[e])
        q = nonneg(fill[c])
        sj[q] = ej[e]
        ss[q] = es[e]
        sx[0, q] = ex[e, 0]
        sx[1, q] = ex[e, 1]
        sx[2, q] = ex[e, 2]
        fill[c] += 1
        cmax[c] = max(cmax[c], ej[e])
    return start, sj, ss, sx, cmax


@kernel
def build_nlist(x, ej, es, ex, start, cmax, lo, cs, ncx, ncy, ncz, cut2, prm, wrapk,
                pst_o, nnb_o, pj_o, pim_o, psh_o, pfl_o, pst, nnb, pj, pim, psh, pfl, cb,
                need, maxj, claims):
    """Half neighbour lists within sqrt(cut2) [m] from the binned entries of
    :func:`bin_entries` (ej, es, ex, start, cmax): bead i's partners j > i (each pair once,
    owned by its lower index, image pairs included) are pj[pst[i]:pst[i] + nnb[i]], with
    image code pim, tangential history psh and contact flag pfl. Chunk c stores its rows
    one after the other in its region [c cap, (c + 1) cap) of the pair arrays (cap = their
    length / chunks), so that the force loop streams through them without gaps.
    Histories and flags of pairs that existed before (lists pst_o ...) are carried over
    (rotated if a bead was wrapped into the sector). need[c] receives the pairs chunk c
    needs (more than cap: overflow, these lists are unusable), maxj[c] the highest partner
    index of the chunk's rows."""
    lz = prm[P_LZ]
    sec = prm[P_SECTOR]
    nch = cb.shape[0] - 1
    cap = pj.shape[0] // nch
    csz = lz / ncz
    occ = 0  # the fullest cell's entries: a row sees at most 27 cells' worth
    for cc in range(start.shape[0] - 1):
        occ = max(occ, start[cc + 1] - start[cc])
    # each thread its region's chunks first, then the others' left (chunk_claims)
    nreg = reset_claims(claims, nch)
    for _ in prange(nreg):
        own = get_thread_id() % nreg
        while True:
            c = claim(claims, nch, own)
            if c < 0:
                break
            c = nonneg(c)
            base = c * cap
            end = base + cap
            q = base
            hij = cb[c + 1] - 1
            hit = np.empty(27 * occ, np.int64)  # a row's entries in reach
            inr = np.empty(27 * occ, np.int64)  # 1 where a run's entry is in reach, else 0
            ex0 = ex[0]
            ex1 = ex[1]
            ex2 = ex[2]
            hit_o = np.empty(27 * occ, np.int64)  # their old index if in contact, or -1
            runs = np.empty((18, 2), np.int64)  # runs of stencil cells [first, end)
            for i0 in range(cb[c], cb[c + 1]):
                i = nonneg(i0)
                xi = x[i, 0]
                yi = x[i, 1]
                zi = x[i, 2]
                ix = min(max(int((xi - lo[0]) / cs), 0), ncx - 1)
                iy = min(max(int((yi - lo[1]) / cs), 0), ncy - 1)
                zz = zi - lz * math.floor(zi / lz)
                iz = min(int(zz / csz), ncz - 1)
                pst[i] = q
                ko = pst_o[i]
                ke = ko + nnb_o[i]
                # Two passes: the entries in reach are collected without a branch on the
                # distance (about one candidate in six is in reach, at random, and the
                # mispredicted branch cost more than the test: 12 % of the build on the bench
                # bed), then only they are stored.
                nh = 0
                # The stencil's cells as runs of consecutive cell indices (cells are numbered
                # z fastest): one run per (ax, ay) column, split in two where the axial
                # stencil wraps, and, when the stencil spans the whole axial period (ncz ==
                # 3), one run per ax over the three columns. Looping over cells one by one
                # cost a mispredicted loop exit per cell, more than the distance tests.
                nr = 0
                for ax in range(max(ix - 1, 0), min(ix + 2, ncx)):
                    ay0 = max(iy - 1, 0)
                    ay1 = min(iy + 2, ncy)
                    if ncz == 3:
                        runs[nr, 0] = (ax * ncy + ay0) * ncz
                        runs[nr, 1] = (ax * ncy + ay1) * ncz
                        nr += 1
                        continue
                    for ay in range(ay0, ay1):
                        cxy = (ax * ncy + ay) * ncz
                        # in cell order: the wrapped cell 0 of a top cell, the cells
                        # iz - 1 .. iz + 1 within the period, the wrapped top cell of cell 0
                        if iz == ncz - 1:
                            runs[nr, 0] = cxy
                            runs[nr, 1] = cxy + 1
                            nr += 1
                        runs[nr, 0] = cxy + max(iz - 1, 0)
                        runs[nr, 1] = cxy + min(iz + 2, ncz)
                        nr += 1
                        if iz == 0:
                            runs[nr, 0] = cxy + ncz - 1
                            runs[nr, 1] = cxy + ncz
                            nr += 1
                for r in range(nr):
                    c0 = runs[r, 0]
                    c1 = runs[r, 1]
                    # leading cells whose beads all have lower indices hold no partner of i
                    # (rows own j > i); with the beads sorted along the cells
                    # (DemSimulation._sort) that is about half of the stencil
                    while c0 < c1 and cmax[c0] <= i:
                        c0 += 1
                    e0 = start[c0]
                    e1 = start[c1]
                    # the run's tests first, in a loop without a carried dependency (vector
                    # instructions: the inlined axial_image's branches become selects), then
                    # the entries in reach collected
                    # (on views of the run, indexed from 0: with the run's offset in the
                    # index the compiler could not rule out a negative index, whose
                    # wraparound made every load a gather)
                    r0 = ex0[e0:e1]
                    r1 = ex1[e0:e1]
                    r2 = ex2[e0:e1]
                    rj = ej[e0:e1]
                    for t in range(e1 - e0):
                        dx = xi - r0[t]
                        dy = yi - r1[t]
                        dz = axial_image(zi - r2[t], lz)
                        inr[t] = (dx * dx + dy * dy + dz * dz < cut2) & (rj[t] > i)
                    for t in range(e1 - e0):
                        hit[nonneg(nh)] = e0 + t
                        nh += inr[t]
                # The pairs in contact at the last evaluation go first in the row, the others
                # after them: the force loop's branch on overlap then changes once per row
                # instead of at random (about 45 % of listed pairs overlap), which the
                # processor predicts, and contacts mostly keep their overlap until the next
                # build. First each pair's index in the old lists where it was in contact,
                # else -1.
                nc = 0
                for h in range(nh):
                    e = nonneg(hit[h])
                    j = nonneg(ej[e])
                    if j > hij:
                        hij = j
                    so = es[e] - wrapk[i] + wrapk[j]  # same physical pair before the wrap
                    old = -1
                    for k0 in range(ko, ke):
                        k = nonneg(k0)
                        if pj_o[k] == j and pim_o[k] == so:
                            if pfl_o[k] != 0:
                                old = k
                                nc += 1
                            break
                    hit_o[h] = old
                qc = q  # next slot for a contact
                qn = q + nc  # next slot for a pair not in contact
                for h in range(nh):
                    e = nonneg(hit[h])
                    k = hit_o[h]
                    if k >= 0:
                        qq = qc
                        qc += 1
                    else:
                        qq = qn
                        qn += 1
                    if qq < end:
                        pj[qq] = ej[e]
                        pim[qq] = es[e]
                        pfl[qq] = 0
                        psh[qq, 0] = 0.0
                        psh[qq, 1] = 0.0
                        psh[qq, 2] = 0.0
                        if k >= 0:
                            pfl[qq] = pfl_o[k]
                            a0 = psh_o[k, 0]
                            a1 = psh_o[k, 1]
                            if wrapk[i] != 0:
                                cr = math.cos(wrapk[i] * sec)
                                sr = math.sin(wrapk[i] * sec)
                                psh[qq, 0] = cr * a0 - sr * a1
                                psh[qq, 1] = sr * a0 + cr * a1
                            else:
                                psh[qq, 0] = a0
                                psh[qq, 1] = a1
                            psh[qq, 2] = psh_o[k, 2]
                q += nh
                nnb[i] = min(q, end) - pst[i]
            need[c] = q - base
            maxj[c] = hij


# ---- forces ----------------------------------------------------------------------------

@device
def _add3(buf, c, j, ax, ay, az, cr, sr):
    """buf[c, j] += (ax, ay, az) rotated about z by the angle with cosine cr, sine sr."""
    buf[c, j, 0] += cr * ax - sr * ay
    buf[c, j, 1] += sr * ax + cr * ay
    buf[c, j, 2] += az


@kernel
def compute_forces(x, v, w, fb, tb, rad, mass, inertia, pst, nnb, pj, pim, psh, pfl, shw,
                   flw, prm, cb, maxj, record, step, evc, evn, torq, fext, claims, fuse,
                   kick, inv_m, inv_i, xref, dmax):
    """Forces [N] and torques [N m] from bead contacts, lubrication, walls, drag and
    gravity, accumulated per chunk: fb[c, i], tb[c, i] hold what chunk c's rows put on
    bead i (its own beads cb[c] <= i < cb[c + 1] and partners up to maxj[c]); the rows of
    chunk c are the half neighbour lists (:func:`build_nlist`), so each pair is evaluated
    once (Newton's third law) and no two chunks write the same buffer.
    :func:`reduce_kick` sums the chunks.

    New contacts (first overlap) go to evc[c, k, :] (layout EV_*) when record is true;
    torq[c, 0] receives the torque [N m] about +z that chunk c's beads exert on the stirrer
    (shaft and disc), torq[c, 1] the torque on the fixed chamber wall and baffles.

    fext[i] = (F_r [N], T_z [N m], F_z [N]) is a force held over the call (the coupled
    fluid's drag and pressure force, in cylindrical components at the bead's current
    position: F_r e_r + T_z / r e_theta + F_z e_z, so that its torque about z is exactly
    T_z); zeros without a coupled fluid.

    With fuse, the kick and drift of :func:`reduce_kick` (v += kick F/m, w += kick T/I,
    x += dt v, dmax[c] the largest squared displacement [m2] since the last build) are done
    here for each bead that no earlier chunk's rows reach (i > maxj of every chunk before
    c), as soon as its row is done: rows own only partners j > i, so by then every row of
    the chunk that puts a force on bead i has run, and no other chunk reads or writes it.
    The bead's state and buffer are still in cache, which spares the reduction's pass over
    memory; the sum is the one reduce_kick forms (0 + its one buffer), so the results are
    the same to the bit. The beads that earlier chunks reach are left to
    ``reduce_kick(..., deferred=True)``."""
    dt = prm[P_DT]
    ystar = prm[P_YSTAR]
    gstar = prm[P_GSTAR]
    beta = prm[P_BETA]
    mu = prm[P_MU]
    mur = prm[P_MUR]
    muw = prm[P_MUW]
    murw = prm[P_MURW]
    eta = prm[P_LUB_ETA]
    hcut = prm[P_LUB_HCUT]
    hmin = prm[P_LUB_HMIN]
    lz = prm[P_LZ]
    sec = prm[P_SECTOR]
    cap = evc.shape[1]
    cs1 = math.cos(sec)
    sn1 = math.sin(sec)
    rsh = prm[P_RSH]
    rch = prm[P_RCH]
    rdisc = prm[P_RDISC]
    has_disc = rdisc > 0.0
    hdisc = 0.5 * prm[P_BDISC]
    has_baffles = prm[P_NBAF] > 0.0
    has_vanes = prm[P_NVANE] > 0.0
    rbaf = prm[P_RBAF]
    zdisc = prm[P_ZDISC]
    hproj = prm[P_THIST] != 0.0
    wet = prm[P_WET] != 0.0
    weta = prm[P_WET_ETA]
    wst = prm[P_WET_ST]
    # Equal beads (one radius and mass, as in most mill runs): R*, m* and the partner's
    # radius are the same for every pair, computed once, as the general formulas give
    # them; this saves the pair loop two divisions per contact and a load per pair.
    # (counted without an early exit, so that the compiler vectorises this pass, which runs
    # serially before the threads start)
    nb = x.shape[0]
    r0 = rad[0] if nb > 0 else 0.0
    m0 = mass[0] if nb > 0 else 0.0
    same = 0
    for i in range(nb):
        same += (rad[i] == r0) & (mass[i] == m0)
    mono = nb > 0 and same == nb
    rstar0 = r0 * r0 / (r0 + r0)
    mstar0 = m0 * m0 / (m0 + m0)
    nch = cb.shape[0] - 1
    # each thread its region's chunks first, then the others' left (chunk_claims)
    nreg = reset_claims(claims, nch)
    for _ in prange(nreg):
        own = get_thread_id() % nreg
        while True:
            c = claim(claims, nch, own)
            if c < 0:
                break
            c = nonneg(c)
            ne = 0
            tq = 0.0
            tqc = 0.0
            dm = 0.0
            # the beads from here on are kicked in this loop when fused (see above)
            lo_kick = deferred_end(cb, maxj, c) if fuse else cb[c + 1]
            # fb, tb arrive all zero: reduce_kick zeroes every entry it sums (see there)
            for i0 in range(cb[c], cb[c + 1]):
                i = nonneg(i0)
                xi = x[i, 0]
                yi = x[i, 1]
                zi = x[i, 2]
                ri = rad[i]
                mi = mass[i]
                fx, fy, fz, rxy = body_force(xi, yi, zi, v[i, 0], v[i, 1], v[i, 2], ri, mi,
                                             fext[i, 0], fext[i, 1], fext[i, 2], prm)
                tx = 0.0
                ty = 0.0
                tz = 0.0
                # ---- bead-bead (half list: j > i) ----
                for k0 in range(pst[i], pst[i] + nnb[i]):
                    k = nonneg(k0)
                    j = nonneg(pj[k])
                    s = pim[k] if sec > 0.0 else 0
                    xj = x[j, 0]
                    yj = x[j, 1]
                    cr = 1.0
                    sr = 0.0
                    if s != 0:
                        cr = cs1
                        sr = sn1 if s > 0 else -sn1
                        xj, yj = cr * xj - sr * yj, sr * xj + cr * yj
                    dx = xi - xj
                    dy = yi - yj
                    dz = axial_image(zi - x[j, 2], lz)
                    rj = r0 if mono else rad[j]
                    rsum = ri + rj
                    r2 = dx * dx + dy * dy + dz * dz
                    lim = rsum + hcut
                    if r2 >= lim * lim:
                        release_pair(pfl, psh, k)
                        continue
                    vjx = v[j, 0]
                    vjy = v[j, 1]
                    wjx = w[j, 0]
                    wjy = w[j, 1]
                    if s != 0:
                        vjx, vjy = cr * vjx - sr * vjy, sr * vjx + cr * vjy
                        wjx, wjy = cr * wjx - sr * wjy, sr * wjx + cr * wjy
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
                    if delta > 0.0:
                        if mono:
                            mstar = mstar0
                            rstar = rstar0
                        else:
                            mstar = mi * mass[j] / (mi + mass[j])
                            rstar = ri * rj / rsum
                        first = pfl[k] == 0
                        if record and first:
                            if ne < cap:
                                lev = ri - 0.5 * delta
                                write_event(evc[c, ne], 0.0, i, j, xi - lev * nx, yi - lev * ny,
                                            zi - lev * nz, vrx, vry, vrz, nx, ny, nz,
                                            w[i, 0] - wjx, w[i, 1] - wjy, w[i, 2] - w[j, 2],
                                            mstar, inertia[i] * inertia[j] / (inertia[i] +
                                                                              inertia[j]),
                                            step)
                            ne += 1
                        # the contact's damping: the material's, or (wet restitution) that of
                        # the level its approach gave it, kept in its flag until it opens
                        bk = beta
                        if wet:
                            if first:
                                pfl[k] = contact_level(abs(vrx * nx + vry * ny + vrz * nz),
                                                       mstar, rstar, weta, wst)
                            bk = prm[P_WTAB + pfl[k]]
                        else:
                            pfl[k] = 1
                        s0 = psh[k, 0]
                        s1 = psh[k, 1]
                        s2 = psh[k, 2]
                        sdn, sm0, sm1 = history_frame_pair(s0, s1, s2, dx, dy, dz, ir2, ir)
                        if hproj:
                            sm1 = 0.0  # "projected": no rescaling
                        (gx, gy, gz, tix, tiy, tiz, tjx, tjy, tjz, s0, s1,
                         s2) = pair_response(nx, ny, nz, delta, vrx, vry, vrz, w[i, 0], w[i, 1],
                                             w[i, 2], wjx, wjy, w[j, 2], ri, rj, mstar, rstar, s0,
                                             s1, s2, sdn, sm0, sm1, ystar, gstar, bk, mu, mur,
                                             dt)
                        psh[k, 0] = s0
                        psh[k, 1] = s1
                        psh[k, 2] = s2
                        fx += gx
                        fy += gy
                        fz += gz
                        tx += tix
                        ty += tiy
                        tz += tiz
                        # reaction on j, rotated back into j's frame (image pairs)
                        _add3(fb, c, j, -gx, -gy, -gz, cr, -sr)
                        _add3(tb, c, j, tjx, tjy, tjz, cr, -sr)
                    else:
                        release_pair(pfl, psh, k)
                        if eta > 0.0:
                            fl_m = lubrication_force(eta, ri * rj / rsum,
                                                     vrx * nx + vry * ny + vrz * nz, -delta, hmin)
                            fx += fl_m * nx
                            fy += fl_m * ny
                            fz += fl_m * nz
                            _add3(fb, c, j, -fl_m * nx, -fl_m * ny, -fl_m * nz, cr, -sr)
                # ---- walls ----
                # quick rejection: most beads touch no wall
                near = rxy - rsh <= ri or rch - rxy <= ri
                if not near and has_disc:
                    zd = zi - zdisc
                    zd -= lz * math.floor(zd / lz + 0.5)
                    near = abs(zd) - hdisc <= ri and rxy - rdisc <= ri
                if not near and has_baffles:
                    near = rxy - rbaf >= -ri
                if not near:
                    for q in range(NWALL):
                        release_wall(flw, shw, i, q)
                for q in range(NWALL if near else 0):
                    # walls that wall_response would find out of reach or absent, decided as
                    # it decides (the same distance from the same radius; no disc: no rotor,
                    # vanes or baffles; no vanes or baffles of their own), skipped: a near
                    # bead is near one or two of the five
                    if ((q == 0 and rxy - rsh >= ri) or (q == 1 and rch - rxy >= ri)
                            or (q >= 2 and not has_disc) or (q == 3 and not has_vanes)
                            or (q == 4 and not has_baffles)):
                        release_wall(flw, shw, i, q)
                        continue
                    first = flw[i, q] == 0
                    bk = beta
                    if wet and not first:
                        bk = prm[P_WTAB + flw[i, q]]
                    (touch, vrx, vry, vrz, nx, ny, nz, wz_w, gx, gy, gz, tix, tiy, tiz, s0, s1,
                     s2, twall) = wall_response(
                        xi, yi, zi, v[i, 0], v[i, 1], v[i, 2], w[i, 0], w[i, 1], w[i, 2], ri, mi,
                        q, shw[i, q, 0], shw[i, q, 1], shw[i, q, 2], prm, ystar, gstar, bk, muw,
                        murw, dt)
                    if not touch:
                        release_wall(flw, shw, i, q)
                        continue
                    if wet and first:
                        # the level from this approach (a sphere on a wall: its own mass and
                        # radius), known once the wall's normal is: the contact's first step
                        # is damped as a dry one (its overlap less than one step's approach)
                        flw[i, q] = contact_level(abs(vrx * nx + vry * ny + vrz * nz), mi, ri,
                                                  weta, wst)
                    if record and first:
                        if ne < cap:
                            # recorded at the bead's centre: the contact point lies inside
                            # the wall by the overlap, outside every zone, and at an edge
                            # (disc rim and face, rotor rim) could not tell the bead's side
                            write_event(evc[c, ne], 1.0 + q, i, -1.0, xi, yi, zi, vrx, vry, vrz,
                                        nx, ny, nz, w[i, 0], w[i, 1], w[i, 2] - wz_w, mi,
                                        inertia[i], step)
                        ne += 1
                    if not wet:
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
                    if wall_stands(q):
                        tqc += twall
                    else:
                        tq += twall
                if i < lo_kick:
                    fb[c, i, 0] += fx
                    fb[c, i, 1] += fy
                    fb[c, i, 2] += fz
                    tb[c, i, 0] += tx
                    tb[c, i, 1] += ty
                    tb[c, i, 2] += tz
                    continue
                # reduce_kick's arithmetic for a bead of one buffer: 0 + (buffer + own row)
                b0, b1, b2, b3, b4, b5 = take_buffer(fb, tb, c, i)
                dd = kick_bead(i, 0.0 + (b0 + fx), 0.0 + (b1 + fy), 0.0 + (b2 + fz),
                               0.0 + (b3 + tx), 0.0 + (b4 + ty), 0.0 + (b5 + tz), v, w, x,
                               inv_m, inv_i, kick, dt, True, xref)
                if dd > dm:
                    dm = dd
            evn[c] = ne
            torq[c, 0] = tq
            torq[c, 1] = tqc
            if fuse:
                dmax[c] = dm


@contact
def release_pair(pfl, psh, k):
    """Listed pair k out of contact: its contact flag and tangential history [m] cleared
    (where set)."""
    if pfl[k] != 0:
        pfl[k] = 0
        psh[k, 0] = 0.0
        psh[k, 1] = 0.0
        psh[k, 2] = 0.0


@contact
def release_wall(flw, shw, i, q):
    """Bead i out of contact with wall q: its contact flag and tangential history [m]
    cleared (where set)."""
    if flw[i, q] != 0:
        flw[i, q] = 0
        shw[i, q, 0] = 0.0
        shw[i, q, 1] = 0.0
        shw[i, q, 2] = 0.0


@contact
def deferred_end(cb, maxj, c):
    """One past the last bead of chunk c that the rows of an earlier chunk reach (their
    partners j <= maxj): at least cb[c], at most cb[c + 1]."""
    e = cb[c]
    for c2 in range(c):
        if maxj[c2] + 1 > e:
            e = maxj[c2] + 1
    return min(e, cb[c + 1])


@contact
def take_buffer(fb, tb, c, i):
    """Chunk c's force and torque on bead i (fb[c, i], tb[c, i]), zeroed as they are read,
    while in cache, for the next force evaluation (compute_forces accumulates into them
    without a pass of its own)."""
    b0 = fb[c, i, 0]
    b1 = fb[c, i, 1]
    b2 = fb[c, i, 2]
    b3 = tb[c, i, 0]
    b4 = tb[c, i, 1]
    b5 = tb[c, i, 2]
    fb[c, i, 0] = 0.0
    fb[c, i, 1] = 0.0
    fb[c, i, 2] = 0.0
    tb[c, i, 0] = 0.0
    tb[c, i, 1] = 0.0
    tb[c, i, 2] = 0.0
    return b0, b1, b2, b3, b4, b5


@contact
def kick_bead(i, f0, f1, f2, t0, t1, t2, v, w, x, inv_m, inv_i, kick, dt, drift, xref):
    """v[i] += kick F/m, w[i] += kick T/I and, with drift, x[i] += dt v[i]; returns the
    squared displacement [m2] since the last build (0 without drift)."""
    im = kick * inv_m[i]
    ii = kick * inv_i[i]
    v[i, 0] += f0 * im
    v[i, 1] += f1 * im
    v[i, 2] += f2 * im
    w[i, 0] += t0 * ii
    w[i, 1] += t1 * ii
    w[i, 2] += t2 * ii
    if not drift:
        return 0.0
    x[i, 0] += dt * v[i, 0]
    x[i, 1] += dt * v[i, 1]
    x[i, 2] += dt * v[i, 2]
    a0 = x[i, 0] - xref[i, 0]
    a1 = x[i, 1] - xref[i, 1]
    a2 = x[i, 2] - xref[i, 2]
    return a0 * a0 + a1 * a1 + a2 * a2


@kernel
def reduce_kick(fb, tb, cb, maxj, f, t, v, w, x, inv_m, inv_i, kick, dt, drift, xref,
                dmax, claims, deferred):
    """f = sum of the chunks' force buffers (t likewise), then v += kick f/m,
    w += kick t/I and, with drift, x += dt v; dmax[c] receives the largest squared
    displacement [m2] since the last neighbour build of chunk c's beads. f and t are
    stored only without drift (a run's last step, finish_step): within a run the next step
    needs the sums only for this kick, and the two arrays' stores would be a quarter of
    this memory-bound pass's traffic on the dilute bench bed. With deferred (after
    ``compute_forces(..., fuse=True)``, which kicked the other beads), only the beads that
    an earlier chunk's rows reach, and dmax[c] keeps the larger of its value and theirs."""
    nch = cb.shape[0] - 1
    # each thread its region's chunks first, then the others' left (chunk_claims)
    nreg = reset_claims(claims, nch)
    for _ in prange(nreg):
        own = get_thread_id() % nreg
        while True:
            c = claim(claims, nch, own)
            if c < 0:
                break
            c = nonneg(c)
            dm = 0.0
            # the first chunk whose partners reach this chunk's beads (without sector images
            # usually c - 1): the chunks before it are not visited bead by bead
            first = 0
            while first < c and maxj[first] < cb[c]:
                first += 1
            end = deferred_end(cb, maxj, c) if deferred else cb[c + 1]
            for i0 in range(cb[c], end):
                i = nonneg(i0)
                f0 = 0.0
                f1 = 0.0
                f2 = 0.0
                t0 = 0.0
                t1 = 0.0
                t2 = 0.0
                # chunks c2 <= c write bead i (partners have higher indices than their rows)
                for c20 in range(first, c + 1):
                    c2 = nonneg(c20)
                    if c2 == c or maxj[c2] >= i:
                        b0, b1, b2, b3, b4, b5 = take_buffer(fb, tb, c2, i)
                        f0, f1, f2 = f0 + b0, f1 + b1, f2 + b2
                        t0, t1, t2 = t0 + b3, t1 + b4, t2 + b5
                if not drift:
                    f[i, 0] = f0
                    f[i, 1] = f1
                    f[i, 2] = f2
                    t[i, 0] = t0
                    t[i, 1] = t1
                    t[i, 2] = t2
                dd = kick_bead(i, f0, f1, f2, t0, t1, t2, v, w, x, inv_m, inv_i, kick, dt,
                               drift, xref)
                if dd > dm:
                    dm = dd
            if drift:
                dmax[c] = max(dm, dmax[c]) if deferred else dm


# ---- driver ----------------------------------------------------------------------------

@serial
def gather_events(evc, evn, evbuf, evcount, acc):
    """Append the chunks' new contacts (evc[c, :evn[c]]) to evbuf after its evcount[0] rows;
    what does not fit is counted in acc[3] (dropped)."""
    m = evcount[0]
    for c in range(evn.shape[0]):
        k = evn[c]
        if k > evc.shape[1]:
            acc[3] += k - evc.shape[1]
            k = evc.shape[1]
        for e in range(k):
            if m < evbuf.shape[0]:
                for a in range(EV_NF):
                    evbuf[m, a] = evc[c, e, a]
                m += 1
            else:
                acc[3] += 1.0
    evcount[0] = m



@serial
def rebuild(x, v, w, shw, xref, prm, wrapk, cutoff, do_wrap, pst, nnb, pj, pim, psh, pfl,
            pst_n, nnb_n, pj_n, pim_n, psh_n, pfl_n, cb, need, maxj, claims):
    """Wrap beads into the periodic cell and build new half neighbour lists (pst_n ...)
    from the current ones (pst ...), carrying the tangential history over; reset the
    displacement reference. Returns the pairs the fullest chunk needs: more than the
    new lists' capacity per chunk (pj_n.shape[0] // chunks) means they overflowed (the
    current ones are untouched; enlarge and call again with do_wrap false, which keeps
    the beads and wrapk as they are)."""
    if do_wrap:
        wrap_periodic(x, v, w, shw, prm, wrapk, cb)
    ej, es, ex = make_entries(x, prm, cutoff)
    lz = prm[P_LZ]
    lo = np.empty(2)
    lo[0] = ex[:, 0].min() - 1e-9
    lo[1] = ex[:, 1].min() - 1e-9
    hx = ex[:, 0].max() + 1e-9
    hy = ex[:, 1].max() + 1e-9
    cs = cutoff
    ncx = max(int((hx - lo[0]) / cs) + 1, 1)
    ncy = max(int((hy - lo[1]) / cs) + 1, 1)
    ncz = int(lz / cutoff)
    start, sj, ss, sx, cmax = bin_entries(ej, es, ex, lo, cs, ncx, ncy, ncz, lz)
    build_nlist(x, sj, ss, sx, start, cmax, lo, cs, ncx, ncy, ncz, cutoff * cutoff, prm,
                wrapk, pst, nnb, pj, pim, psh, pfl, pst_n, nnb_n, pj_n, pim_n, psh_n, pfl_n,
                cb, need, maxj, claims)
    xref[:, :] = x
    return need.max()


@serial
def advance_rotor(prm, dt):
    """Turn the rotor angle prm[P_ROTANG] [rad] by omega dt, kept within one vane pitch
    (only the vanes' pattern matters, and a small angle keeps its round-off small)."""
    a = prm[P_ROTANG] + prm[P_OMEGA] * dt
    if prm[P_NVANE] > 0.0:
        pitch = 2.0 * math.pi / prm[P_NVANE]
        a -= pitch * math.floor(a / pitch)
    prm[P_ROTANG] = a


@serial
def advance(nsteps, x, v, w, f, t, rad, mass, inertia, inv_m, inv_i, xref, prm, wrapk,
            cutoff, pst, nnb, pj, pim, psh, pfl, pst_o, nnb_o, pj_o, pim_o, psh_o, pfl_o,
            shw, flw, cb, need, maxj, dmax, record, evc, evn, evbuf, evcount, acc, fb, tb,
            torq, fext, claims):
    """Advance ``nsteps`` velocity-Verlet steps of dt = prm[P_DT] [s] (nsteps >= 1).

    Velocities are synchronous with positions on entry and exit; the forces f, t must be
    those of the entry state. Each step is two parallel passes: forces on the half
    neighbour lists into per-chunk buffers fb, tb, with the leapfrog kick and drift of the
    beads that only their own chunk's rows reach, then the sum of the buffers with the
    kick and drift of the others (a run's last step: the sum, kick and store of all).
    Recorded contacts are appended to evbuf (evcount[0] rows used); acc accumulates
    [0] stirrer torque x steps [N m], [1] steps, [2] neighbour builds, [3] contacts
    dropped for lack of chunk buffer space, [4] chamber-wall torque x steps [N m]; torq
    (chunks, 2) is the per-chunk scratch of compute_forces, fext the held external force
    (see compute_forces). The two sets of neighbour lists (pst ... and pst_o ...)
    alternate at every build. Returns (steps done, status, list parity):
    parity 1 means the caller must swap its list references. Status 0 done; 1 new
    neighbour lists too short (positions advanced, velocities half a step ahead: enlarge,
    rebuild, finish_step); 2 event buffer nearly full (stopped early, synchronous state).
    """
    dt = prm[P_DT]
    half_skin2 = (0.5 * prm[P_SKIN]) ** 2
    nch = cb.shape[0] - 1
    parity = 0
    kick_drift(x, v, w, f, t, inv_m, inv_i, 0.5 * dt, dt, xref, cb, dmax)
    for step in range(nsteps):
        # the positions are now a step further: so is the rotor (its vanes)
        advance_rotor(prm, dt)
        if dmax.max() > half_skin2:
            # np.bool_: the type of DemSimulation's call (a constant would compile a
            # second rebuild for it; see finish_step)
            needed = rebuild(x, v, w, shw, xref, prm, wrapk, cutoff, np.bool_(True), pst,
                             nnb, pj, pim, psh, pfl, pst_o, nnb_o, pj_o, pim_o, psh_o, pfl_o,
                             cb, need, maxj, claims)
            acc[2] += 1.0
            if needed > pj_o.shape[0] // nch:
                return step, 1, parity
            # the new lists become the current ones (no copying)
            pst, pst_o = pst_o, pst
            nnb, nnb_o = nnb_o, nnb
            pj, pj_o = pj_o, pj
            pim, pim_o = pim_o, pim
            psh, psh_o = psh_o, psh
            pfl, pfl_o = pfl_o, pfl
            parity ^= 1
        last = step == nsteps - 1
        if record and evcount[0] > evbuf.shape[0] - 2 * evc.shape[1] * nch:
            last = True
        # within the run, the kick and drift of most beads go with their force rows
        compute_forces(x, v, w, fb, tb, rad, mass, inertia, pst, nnb, pj, pim, psh, pfl,
                       shw, flw, prm, cb, maxj, record, step, evc, evn, torq, fext, claims,
                       not last, dt, inv_m, inv_i, xref, dmax)
        tq = 0.0
        tqc = 0.0
        for c in range(nch):
            tq += torq[c, 0]
            tqc += torq[c, 1]
        acc[0] += tq
        acc[4] += tqc
        acc[1] += 1.0
        if record:
            gather_events(evc, evn, evbuf, evcount, acc)
        if last:
            reduce_kick(fb, tb, cb, maxj, f, t, v, w, x, inv_m, inv_i, 0.5 * dt, dt, False,
                        xref, dmax, claims, False)
            return step + 1, (0 if step == nsteps - 1 else 2), parity
        reduce_kick(fb, tb, cb, maxj, f, t, v, w, x, inv_m, inv_i, dt, dt, True, xref, dmax,
                    claims, True)
    return nsteps, 0, parity


@serial
def finish_step(x, v, w, f, t, rad, mass, inertia, inv_m, inv_i, prm, pst, nnb, pj, pim,
                psh, pfl, shw, flw, cb, maxj, record, evc, evn, torq, xref, dmax, fb, tb,
                kick, fext, claims):
    """Forces at the current positions, then v += kick F/m: with kick = dt/2 this closes
    a step after the neighbour lists were enlarged in the middle of it; with kick = 0 it
    only fills f, t. New contacts are left in evc/evn for the caller to collect."""
    # the step and fuse as typed values, not constants: numba compiles a kernel once for
    # each constant a compiled caller passes (types Literal[int](0), Literal[bool](False)),
    # and advance passes these two as values; one compute_forces for both saves its
    # compilation (about 11 s on 2 cores), the same code either way
    compute_forces(x, v, w, fb, tb, rad, mass, inertia, pst, nnb, pj, pim, psh, pfl, shw,
                   flw, prm, cb, maxj, record, np.int64(0), evc, evn, torq, fext, claims,
                   np.bool_(False), kick, inv_m, inv_i, xref, dmax)
    reduce_kick(fb, tb, cb, maxj, f, t, v, w, x, inv_m, inv_i, kick, prm[P_DT], False,
                xref, dmax, claims, False)
