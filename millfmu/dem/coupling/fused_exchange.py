"""One coupling interval of :class:`millfmu.dem.coupling.cfd_dem.CfdDem` in one compiled
call: the same kernels, in the same order, with the same arguments as the exchange's
thirteen calls from Python (beads in, deposit, smoothing, void fractions and exchange
coefficients, the liquid taking them, its substeps of predictor, pressure solve and
corrector, the interval's means, cell values, smoothing, held forces), so the same
results to the bit. One liberty with the order: the last substep's k-epsilon step, which
nothing before the next interval reads but the next stable substep, runs beside the
smoothing of the cell values (:func:`values_and_turbulence`), the two tasks on two
threads; each writes only its own arrays, so the results stay those of the calls. The
deposit, the totals' smoothing and their split onto the nodes run likewise as two tasks,
one per half of the six columns (:func:`beads_to_nodes`).

Why: each call of a numba kernel from Python checks the types of its arguments, and inside
the coupled run, where the DEM's ten steps come between two exchanges, that check is
several times slower than in a loop of calls: on the 10-degree disc sector the thirteen
calls' checks are a tenth of the exchange, and the Python between them (the liquid's
substep loop, reshapes, copies, the largest stiffness) more.

Taken where the exchange is of that form: the explicit smoothing sweeps (or none), the
pressure by ``direct_ldl``, no stator plates with theta faces (whose torque the liquid's
Python loop integrates per substep). Anything else runs the calls one by one.

:func:`coupled_intervals` goes one step further: a run of intervals, each such exchange and
the DEM's steps after it, in one call (where no contacts are recorded), so that neither
the Python between the exchange and ``DemSimulation.run`` nor their argument checks come
between two intervals.
"""

import math

import numpy as np
from numba import prange

from millfmu.dem.coupling.exchange_kernels import (beads_in, bead_forces, cells_to_eps_kd,
                                                   cells_to_exchange, cells_to_sd,
                                                   nodes_to_cell_values)
from millfmu.dem.coupling.projection import deposit, deposit_half, diffuse, diffuse_field
from millfmu.dem.engine._jit import kernel, serial, set_chunksize
from millfmu.dem.engine.kernels import advance
from millfmu.dem.fluid.step_kernels import (EPSC, EPSC0, KR, KTH, KZ, MGR, MGT, MGZ, MUR,
                                            MUT, MUZ, NUT, UR, UT, UZ, finish_interval,
                                            ldl_project, predict_velocities, predictor_sums,
                                            project, projection_rhs, stable_dt,
                                            start_interval, take_beads, turbulence)


@serial
def exchange_interval(beads, bead_prm, stencil, grid, smooth, nodes, liquid, liquid_prm,
                      factor, same_eps, dt_stable, time_s, tasks):
    """One coupling interval (:meth:`CfdDem.exchange`, the no-gap branch, and
    :meth:`FluidSolver.advance` with ``direct_ldl``), argument groups as
    :meth:`CfdDem._exchange_fused` packs them:

    - beads: x, v, rad, mass, fab (the fluid at each bead), fext, eps_cells;
    - bead_prm: body_z, pf, mu, rho, interval [s], model_b, now (the gradient timing);
    - stencil: idx, w, cyl, c, q, xmax;
    - grid: rc, rtab, rh, dth, nt, dz, nz, lz, solid, vc, vol_r (nodes), eps_min;
    - smooth: tot, cellv, svol, ar, at, az, tmp, sweeps;
    - nodes: eps_c, eps_r, eps_t, eps_z, kd_r, kd_t, kd_z, sd_r, sd_t, sd_z;
    - liquid: F, W, K, driven, acc, wall, wall_om, rf, rc, dr, vc;
    - liquid_prm: rho, nu, slip_s, omega, om_shaft, body_z, dth, dz, cfl, interval_s
      (the solver's), kturb, model_a, stress_force;
    - factor: cells, volume, volume_sum, lp, li, lx, inv_d, order, rhs, y, x, phi, div.

    same_eps: the liquid's previous void fraction taken as the new one (the first
    exchange). dt_stable: the liquid's last stable substep [s] (<= 0: none yet). time_s:
    the liquid's clock [s]. tasks: the two-task forms (:func:`beads_to_nodes`,
    :func:`solve_beside_sums`, :func:`values_and_turbulence`), for one or two threads; on
    more, the kernels' own loops over fields and rows use them all. Returns (clipped cells,
    largest stiffness ratio, substeps, the new stable substep [s], the new clock [s],
    velocities finite, T_z sum [N m], F_z sum [N])."""
    x, v, rad, mass, fab, fext, eps_cells = beads
    body_zb, pf, mu, rho_b, interval, model_b, now = bead_prm
    idx, w, cyl, c, q, xmax = stencil
    rcb, rtab, rh, dthb, nt, dzb, nz, lz, solid, vcb, vol_r, eps_min = grid
    tot, cellv, svol, ar, at, az, tmp, sweeps = smooth
    eps_c, eps_r, eps_t, eps_z, kd_r, kd_t, kd_z, sd_r, sd_t, sd_z = nodes
    F, W, K, driven, acc, wall, wall_om, rf, rc, dr, vc = liquid
    (rho, nu, slip_s, omega, om_sh, body_z, dth, dz, cfl, interval_s, kturb,
     model_a, stress_force) = liquid_prm
    cells, volume, volume_sum, lp, li, lx, inv_d, order, rhs, y, xs, phi, div = factor
    shapev = (cellv.shape[0], solid.shape[0], solid.shape[1], solid.shape[2])

    clipped = beads_to_grid(beads, bead_prm, stencil, grid, smooth, nodes, K, tasks)
    stiff = xmax.max() if xmax.size else 0.0
    # the liquid takes them (FluidSolver.set_beads)
    take_beads(F, K, driven, eps_c, eps_r, eps_t, eps_z, kd_r, kd_t, kd_z, sd_r, sd_t,
               sd_z, rc, rho, slip_s, omega)
    if same_eps:
        ec = F[EPSC0].reshape(-1)
        en = F[EPSC].reshape(-1)
        for n in range(ec.size):
            ec[n] = en[n]
    # FluidSolver.advance, its Python loop as it is there
    start_interval(F, acc)
    # flags as typed values, not constants: numba compiles a kernel once for each constant
    # a compiled caller passes; one turbulence for both forms and one diffuse for all the
    # calls (the liquid's own calls pass values) save those compilations, the same code
    on_threads = np.bool_(True)
    if dt_stable <= 0.0:
        dt_stable = stable_dt(F[UR], F[UT], F[UZ], F[NUT], rc, dr, dth, dz, nu, cfl)
    done = 0.0
    n = 0
    # the last substep's turbulence is left for later (see values_and_turbulence)
    deferred = False
    dt = 0.0
    while interval - done > 1e-12 * interval:
        if deferred:  # not reached: a substep of the whole rest ends the loop
            dt_stable = turbulence(F, W, K, wall, wall_om, rf, rc, dr, vc, dth, dz, nu,
                                   kturb, dt, cfl, on_threads)
            deferred = False
        rest = interval - done
        nsub = max(1, int(math.ceil(rest / dt_stable - 1e-9)))
        dt = rest / nsub
        predict_velocities(F, W, K, rf, rc, dr, vc, dth, dz, om_sh, rho, nu, kturb,
                           model_a, stress_force, body_z, dt)
        if tasks:
            solve_beside_sums(F, W, K, rf, rc, dr, vc, dth, dz, rho, dt, interval_s, acc,
                              div.reshape(-1), cells, volume, volume_sum, lp, li, lx, inv_d,
                              order, rhs, y, xs, phi.reshape(-1))
        else:
            predictor_sums(F, W, K, rf, rc, vc, dth, dz, dt, acc)
            projection_rhs(F, W, rf, dr, vc, dth, dz, rho, dt, interval_s)
            ldl_project(div.reshape(-1), cells, volume, volume_sum, lp, li, lx, inv_d, order,
                        rhs, y, xs, phi.reshape(-1))
        project(F, W, K, phi, rc, dr, dth, dz, rho, dt)
        if nsub == 1 and tasks:
            deferred = True
        else:
            dt_stable = turbulence(F, W, K, wall, wall_om, rf, rc, dr, vc, dth, dz, nu,
                                   kturb, dt, cfl, on_threads)
        done += dt
        n += 1
        time_s += dt
    finite = finish_interval(F, interval)
    if not finite:
        return clipped, stiff, n, dt_stable, time_s, False, 0.0, 0.0
    ecl = eps_cells
    ecn = eps_c.reshape(-1)
    for k in range(ecl.size):
        ecl[k] = ecn[k]
    # grid -> beads
    nodes_to_cell_values(F[MUR], F[MUT], F[MUZ], F[MGR], F[MGT], F[MGZ], K[KR], K[KTH], K[KZ],
                         solid, cellv)
    if deferred:
        dt_stable = values_and_turbulence(cellv.reshape(shapev), svol, ar, at, az, sweeps,
                                          tmp, F, W, K, wall, wall_om, rf, rc, dr, vc, dth,
                                          dz, nu, kturb, dt, cfl)
    elif sweeps:
        diffuse(cellv.reshape(shapev), svol, ar, at, az, sweeps, np.bool_(False), tmp,
                np.int64(3))
    ts, fs = bead_forces(idx, w, cellv, c, cyl, rad, fab, pf, now, body_zb, fext)
    return clipped, stiff, n, dt_stable, time_s, True, ts, fs


@serial
def to_nodes(idx, w, q, tot, shape4, svol, ar, at, az, sweeps, tmp, vc, eps_min, solid, K,
             vol_r, rc, nodes, tasks):
    """The deposit, the totals' smoothing and the split onto the nodes: as two tasks
    (:func:`beads_to_nodes`, tasks) or by the calls' kernels, the smoothing's six fields
    on as many threads; returns the clipped cells."""
    eps_c, eps_r, eps_t, eps_z, kd_r, kd_t, kd_z, sd_r, sd_t, sd_z = nodes
    tot4 = tot.reshape(shape4)
    if tasks:
        return beads_to_nodes(idx, w, q, tot, tot4, svol, ar, at, az, sweeps, tmp, vc,
                              eps_min, solid, K[KR], K[KTH], K[KZ], vol_r, rc, eps_c, eps_r,
                              eps_t, eps_z, kd_r, kd_t, kd_z, sd_r, sd_t, sd_z)
    deposit(idx, w, q, tot)
    if sweeps:
        diffuse(tot4, svol, ar, at, az, sweeps, np.bool_(True), tmp, tot.shape[0])
    return cells_to_exchange(tot4, vc, eps_min, solid, K[KR], K[KTH], K[KZ], vol_r, rc,
                             eps_c, eps_r, eps_t, eps_z, kd_r, kd_t, kd_z, sd_r, sd_t, sd_z)


@kernel
def beads_to_nodes(idx, w, q, tot, tot4, svol, ar, at, az, sweeps, tmp, vc, eps_min, solid,
                   kr, kt, kz, vol_r, rc, eps_c, eps_r, eps_t, eps_z, kd_r, kd_t, kd_z, sd_r,
                   sd_t, sd_z):
    """The beads' six deposited columns q to the liquid's nodes in two tasks, one per half
    of the columns: the deposit (:func:`~millfmu.dem.coupling.projection.deposit_half`),
    the smoothing of its three fields (``sweeps`` sweeps), and its part of the split onto
    the nodes (columns 0-2: void fractions and drag coefficients, :func:`cells_to_eps_kd`;
    3-5: sources, :func:`cells_to_sd`). Each output as the calls one after the other make
    it (deposit, diffuse, cells_to_exchange), to the bit; returns the clipped cells.

    Why: the three calls were three launches with the split on one thread, and each task
    now goes on with the columns it has just deposited and smoothed in its own cache."""
    clip = np.zeros(1, np.int64)
    for h in prange(2):
        deposit_half(h, idx, w, q, tot)
        if sweeps:
            for col in range(3 * h, 3 * h + 3):
                diffuse_field(col, tot4, svol, ar, at, az, sweeps, True, tmp)
        if h == 0:
            clip[0] = cells_to_eps_kd(tot4, vc, eps_min, solid, kr, kt, kz, vol_r, rc,
                                      eps_c, eps_r, eps_t, eps_z, kd_r, kd_t, kd_z)
        else:
            cells_to_sd(tot4, vc, solid, kr, kt, kz, vol_r, rc, sd_r, sd_t, sd_z)
    return clip[0]


@kernel
def solve_beside_sums(F, W, K, rf, rc, dr, vc, dth, dz, rho, dt, interval, acc, b_cells,
                      cells, volume, volume_sum, lp, li, lx, inv_d, order, rhs, y, x, out):
    """The predictor's end and the pressure solve as two tasks: the projection's
    right-hand side and the solve (:func:`~millfmu.dem.fluid.step_kernels.projection_rhs`,
    :func:`~millfmu.dem.fluid.step_kernels.ldl_project`) on one thread, the predictor's
    sums (:func:`~millfmu.dem.fluid.step_kernels.predictor_sums`: wall torques, the beads'
    impulses, the mean velocities) on another. Neither reads what the other writes.

    Why: the solve is serial, and a stretch of serial work longer than OpenMP's spinning
    (tens of microseconds with 1000 spins, :mod:`millfmu.dem.engine._jit`) lets the idle
    thread fall asleep, and the next parallel loop waits for it to wake. With the sums
    beside it, that stretch is shorter."""
    for h in prange(2):
        if h == 0:
            projection_rhs(F, W, rf, dr, vc, dth, dz, rho, dt, interval)
            ldl_project(b_cells, cells, volume, volume_sum, lp, li, lx, inv_d, order, rhs,
                        y, x, out)
        else:
            predictor_sums(F, W, K, rf, rc, vc, dth, dz, dt, acc)


@kernel
def values_and_turbulence(cellv, svol, ar, at, az, sweeps, tmp, F, W, K, wall, wall_om, rf,
                          rc, dr, vc, dth, dz, nu, kturb, dt, cfl):
    """The smoothing of the cell values' first three fields (the fluid velocities:
    :func:`~millfmu.dem.coupling.projection.diffuse`, ``sweeps`` sweeps) on one thread and
    the interval's last k-epsilon step (:func:`~millfmu.dem.fluid.step_kernels.turbulence`,
    kturb) on another, side by side: neither reads what the other writes, and each gives
    the same results as alone. Returns the liquid's new stable substep [s].

    Why: on two threads the values' three fields split two and one, and the turbulence's
    rows wait behind them; side by side the turbulence fills the idle thread."""
    out = np.zeros(1)
    for h in prange(2):
        if h == 0:
            for col in range(3 if sweeps else 0):
                diffuse_field(col, cellv, svol, ar, at, az, sweeps, False, tmp)
        else:
            # a typed value, as exchange_interval's calls (one compiled turbulence)
            out[0] = turbulence(F, W, K, wall, wall_om, rf, rc, dr, vc, dth, dz, nu, kturb,
                                dt, cfl, np.bool_(False))
    return out[0]


@serial
def beads_to_grid(beads, bead_prm, stencil, grid, smooth, nodes, K, tasks):
    """Beads -> grid (:meth:`CfdDem._deposit_and_split`): the beads' stencils, drag
    coefficients and deposit columns (:func:`beads_in`), then :func:`to_nodes`; argument
    groups as :func:`exchange_interval`'s, tasks as there. Returns the clipped cells."""
    x, v, rad, mass, fab, fext, eps_cells = beads
    body_zb, pf, mu, rho_b, interval, model_b, now = bead_prm
    idx, w, cyl, c, q, xmax = stencil
    rcb, rtab, rh, dthb, nt, dzb, nz, lz, solid, vcb, vol_r, eps_min = grid
    tot, cellv, svol, ar, at, az, tmp, sweeps = smooth
    shape4 = (tot.shape[0], solid.shape[0], solid.shape[1], solid.shape[2])
    beads_in(x, v, rad, mass, fab, eps_cells, body_zb, pf, model_b, mu, rho_b, interval,
             rcb, rtab, rh, dthb, nt, dzb, nz, lz, solid, idx, w, cyl, c, q, xmax)
    return to_nodes(idx, w, q, tot, shape4, svol, ar, at, az, sweeps, tmp, vcb, eps_min,
                    solid, K, vol_r, rcb, nodes, tasks)


@serial
def present_void_fraction(beads, bead_prm, stencil, grid, smooth, nodes, K, tasks):
    """The first pass of an exchange after a gap (the DEM advanced alone): the beads'
    present void fraction per cell into eps_cells (:func:`beads_to_grid`), which the
    exchange that follows then takes for the drag (:meth:`CfdDem.exchange`'s first
    ``_deposit_and_split``), in one call instead of four; argument groups as
    :func:`exchange_interval`'s, tasks as there."""
    beads_to_grid(beads, bead_prm, stencil, grid, smooth, nodes, K, tasks)
    eps_cells = beads[6]
    ecn = nodes[0].reshape(-1)
    for k in range(eps_cells.size):
        eps_cells[k] = ecn[k]


#: columns of :func:`coupled_intervals`' record per interval: the eight returns of
#: :func:`exchange_interval`, the liquid's five impulses after it (its acc), the DEM's
#: stirrer and chamber torque sums [N m steps], contacts dropped, neighbour builds
PER_INTERVAL = 17


@serial
def coupled_intervals(m, k, groups, dt_stable, time_s, dem, dem_swapped, evcount, acc,
                      chunk, per, tasks):
    """``m`` coupling intervals of ``k`` DEM steps: each :func:`exchange_interval` (no gap,
    not the first exchange) and then the DEM's ``advance`` (no contacts recorded), as
    :meth:`CfdDem.exchange` and ``DemSimulation.run`` make them one after the other, the
    same kernels on the same arrays in the same order (the same results to the bit),
    without returning to Python in between, whose code and argument checks between the
    calls cost a noticeable part of a short interval.

    groups: the exchange's nine argument groups (``CfdDem._fused_groups``); dt_stable [s],
    time_s [s]: the liquid's last stable substep and clock; dem, dem_swapped: ``advance``'s
    arguments after the step count with the neighbour lists as they are and swapped (the
    DEM's ``advance`` swaps them at each build); evcount, acc: the event count and the
    accumulator among those arguments, zeroed before each run; chunk: numba's parallel
    chunk size for the exchange's loops (the DEM's run with chunk size 1, as ``run`` sets
    it). per (m, PER_INTERVAL) receives each interval's record; tasks: as for
    :func:`exchange_interval`. Returns (intervals done, the steps
    and the status of the interval whose ``advance`` stopped early (status 1: its new
    neighbour lists overflowed; 3: the liquid's velocities not finite, before the DEM's
    steps), 0 and 0 when all were done, the parity of the lists' swaps)."""
    beads, bead_prm, stencil, grid, smooth, nodes, liquid, liquid_prm, factor = groups
    acc_l = liquid[4]
    par = 0
    for i in range(m):
        set_chunksize(chunk)
        # np.bool_: the type of CfdDem's call, whose compiled exchange this reuses (a
        # constant would compile a second one, about 9 s on 2 cores)
        r = exchange_interval(beads, bead_prm, stencil, grid, smooth, nodes, liquid,
                              liquid_prm, factor, np.bool_(False), dt_stable, time_s, tasks)
        per[i, 0] = r[0]
        per[i, 1] = r[1]
        per[i, 2] = r[2]
        per[i, 3] = r[3]
        per[i, 4] = r[4]
        per[i, 5] = 1.0 if r[5] else 0.0
        per[i, 6] = r[6]
        per[i, 7] = r[7]
        for c in range(5):
            per[i, 8 + c] = acc_l[c]
        dt_stable = r[3]
        time_s = r[4]
        if not r[5]:
            return i, 0, 3, par
        evcount[0] = 0
        acc[:] = 0.0
        set_chunksize(1)
        if par:
            kk, status, parity = advance(k, *dem_swapped)
        else:
            kk, status, parity = advance(k, *dem)
        set_chunksize(chunk)
        par ^= parity
        per[i, 13] = acc[0]
        per[i, 14] = acc[4]
        per[i, 15] = acc[3]
        per[i, 16] = acc[2]
        if status != 0:
            return i, kk, status, par
    return m, 0, 0, par
