"""Throughput of the coupled DEM-CFD against the DEM alone on the same beads, measured in
one process, alternating, best of ``repeats``.

Scene: disc_slice (seed 001's PM-1 slice), 10 m/s, 80 % filling, 10 degree sector without
gravity, coupled fluid as the scene file sets it (axisymmetric grid of 0.75 mm cells,
k-epsilon, coupling every 10 DEM steps); or (``scene="full"``) the full 360-degree slice
with gravity, 32 theta cells and the pressure by FFT in theta (seed 001's case as ``dem run
disc_slice --theta-cells 32 --pressure-solver theta_fft`` runs it). The DEM steps on the
CPU's threads or (``device="gpu"``) on the GPU, the liquid on the CPU's threads. Beads and
fluid start turning at 0.1 of the stirrer's angular velocity (about the mean bead speed of
the stirred slice) and move for ``warm_s`` [s] coupled (compilation, and a stirred,
colliding bed rather than beads at rest, whose contact loop would cost the DEM less than in
a running mill); then each repeat times ``steps`` DEM steps alone (``run`` calls of a block
of 200 steps, as the DEM runs uncoupled) and the same number coupled (one exchange and one
10-step ``run`` per coupling interval), block after block in turn. The ratio is what the
fluid and the coupling add to the DEM's cost.

Where the beads are when they are timed: a bed that has just started turning has few
contacts (0.9 per bead 0.006 s after the start in the sector, 2.5 in the running mill from
about 0.35 s on, 3.5 at the spin-up's peak near 0.1 s), and its DEM steps cost 0.6-0.7 of
the running mill's. The sector row therefore starts by default from the running mill
(``start="running"``): the state after :data:`RUNNING_S` of coupled motion, made once
(about 2.5 minutes on 2 threads) and kept in the bench folder
(:func:`benchmarks.dem_peers.bench_dir`) for these sources and thread count;
``start="early"`` times the bed ``warm_s`` after the start, as this bench did before, and
the full slice (hours to spin up on 2 cores) always does. The coupling's share is not
smaller in the running mill (2 threads, two runs each: 30-31 % against 24-28 % early):
with 8-wide bead stencils an exchange there took 3.1-3.5 ms within the coupled run against
2.5 ms when exchanges ran back to back on the same beads, and the DEM's 10-step runs
between exchanges took 7 % (median of eight blocks, -2 to +16 %) longer than its 200-step
blocks alone, against 1 % for 10-step runs without exchanges between them. Most likely the
exchange's per-bead arrays (about 2.7 MB) and the DEM's beads and pairs (4-5 MB for 6,536
beads) push each other out of the cores' caches (512 kB of L2 each; not measured with
hardware counters). Measured later (CHANGELOG.md, "Where a coupled interval goes"): an
exchange after 15 ms of waiting took longer (2.8-3.0 ms) than one after ten DEM steps
(2.5) or back to back (2.1), so on this shared host it is mostly the time between two
exchanges, not the DEM's footprint, that costs; and ten DEM steps after an exchange took
2-4 % longer than ten steps after ten steps (the two kinds interleaved block by block).
With the axisymmetric grid's stencils 4 wide (half the stencils' memory) the exchanges took
2.4-2.5 ms inside the run and the DEM's 10-step runs 3-7 % longer; the row gave 27 % twice
(block-pair medians 21 and 22 %).
"""

from __future__ import annotations

import argparse
import hashlib
import pickle
import statistics
import sys
import time
from dataclasses import asdict, dataclass, field


@dataclass
class CoupledBenchResult:
    scene: str  # "sector" or "full"
    device: str  # where the DEM stepped
    beads: int
    fluid_cells: int
    steps: int
    coupling_steps: int
    threads: int
    dem_particle_steps_per_s: float  # best of the repeats
    coupled_particle_steps_per_s: float
    added_cost: float  # coupled time / DEM time - 1 (best of each)
    dem_times_s: list
    coupled_times_s: list
    threading_layer: str = ""  # numba's, which the liquid's parallel loops ran on
    start: str = "early"  # "running": from the running mill's state; "early": warm_s in
    start_s: float = 0.0  # [s] simulated time of the timed bed since the start
    # coupled block time / the DEM-alone block before it - 1, every block of every repeat
    # (their median is steadier than the ratio of the bests on a shared machine)
    block_added_costs: list = field(default_factory=list)
    # the DEM on the GPU: the same coupled blocks with the beads' side of the exchange and
    # the smoothing on the CPU (CfdDem.set_gpu_beads(False)), interleaved with the others;
    # empty on the CPU
    cpu_beads_times_s: list = field(default_factory=list)
    cpu_beads_particle_steps_per_s: float = 0.0

    @property
    def added_cost_median(self) -> float:
        v = self.block_added_costs
        return statistics.median(v) if v else float("nan")

    def as_dict(self) -> dict:
        return dict(asdict(self), added_cost_median=self.added_cost_median)


SCENES = ("sector", "full")
STARTS = ("running", "early")
#: [s] coupled motion from the start at 0.1 of the stirrer's rotation to the running mill
#: the sector row is timed in (contacts per bead settle at about 2.5 from 0.35 s on)
RUNNING_S = 0.4


def _scene(scene: str):
    from millfmu.dem.scene import load_scene

    sc = load_scene("disc_slice").with_overrides(fluid_mode="coupled", tip_speed_m_per_s=10.0,
                                                 filling=0.8, initial_rotation=0.1)
    if scene == "sector":
        return sc.with_overrides(sector_deg=10.0, gravity_m_per_s2=(0.0, 0.0, 0.0))
    return sc.with_overrides(n_theta=32, pressure_solver="theta_fft")


def running_state(threads: int | None = None, running_s: float = RUNNING_S, out=print):
    """(sim, coupling) of the 10-degree sector after ``running_s`` [s] of coupled motion
    from its start, loaded from the bench folder or made there once (atomically) and kept
    for these sources, thread count (the beads' chunks) and running_s."""
    import numba

    from millfmu.dem.run import _write_checkpoint, make_simulation
    from benchmarks.dem_peers import bench_dir
    from millfmu.dem.tables.cache import kernel_source_hash

    sc = _scene("sector")
    # the thread count DemSimulation takes for None (the sector has thousands of beads),
    # known without building the simulation that a cached state makes unnecessary
    nthr = int(threads) if threads is not None else numba.config.NUMBA_NUM_THREADS
    key = hashlib.sha256(f"{kernel_source_hash()} {sc!r} {nthr} {running_s!r}"
                         .encode()).hexdigest()[:12]
    path = bench_dir() / f"coupled_sector_running_{key}.pkl"
    if path.exists():
        try:
            with open(path, "rb") as fh:
                st = pickle.load(fh)
            return st["sim"], st["cpl"]
        except (OSError, pickle.UnpicklingError, EOFError, AttributeError, ImportError,
                KeyError) as e:
            out(f"{path}: not readable ({type(e).__name__}: {e}); making it again")
    sim, cpl = make_simulation(sc, nthr, "cpu")
    k = cpl.unit_steps
    n = k * max(1, int(round(running_s / (k * sc.dt_s))))
    out(f"making the running coupled sector {path} (once; {n * sc.dt_s:g} s of coupled "
        f"motion, {sim.n} beads, {sim.threads} threads)")
    t0 = time.perf_counter()
    blocks = 10
    for b in range(blocks):
        cpl.run(k * (n // k * (b + 1) // blocks - n // k * b // blocks))
        out(f"  {sim.step_count * sc.dt_s:.3f} s simulated, "
            f"{time.perf_counter() - t0:.0f} s wall")
    path.parent.mkdir(parents=True, exist_ok=True)
    _write_checkpoint(path, {"sim": sim, "cpl": cpl})
    return sim, cpl


def _start(scene: str, start: str, threads, device: str, warm_s: float, running_s: float,
           out):
    """(sim, coupling) where a timing begins: the running mill's state
    (:func:`running_state`) or ``warm_s`` [s] of coupled motion after the start."""
    from millfmu.dem.run import make_simulation

    if start == "running":
        return running_state(threads, running_s, out=out)
    sc = _scene(scene)
    sim, cpl = make_simulation(sc, threads, device)
    k = cpl.settings.steps
    cpl.run(k * max(1, int(round(warm_s / (k * sc.dt_s)))))
    return sim, cpl


def run_coupled_bench(steps: int = 2000, repeats: int = 3, threads: int | None = None,
                      warm_s: float = 0.01, block: int = 200, scene: str = "sector",
                      device: str = "cpu", start: str | None = None,
                      running_s: float = RUNNING_S, out=print) -> CoupledBenchResult:
    """``steps`` DEM steps alone and ``steps`` coupled per repeat, interleaved in blocks of
    ``block`` steps (DEM block, coupled block, ...), so that both see the same bed as it
    evolves (a stirred bed's cost per step drifts by 10-20 % over a few thousand steps,
    which timing one long run after the other mistakes for a cost of the coupling). The
    liquid takes the beads' present void fraction after each DEM-alone block (see
    ``CfdDem.exchange``). Best of ``repeats``. ``start``: "running" (the default for the
    sector on the CPU: from :func:`running_state`) or "early" (``warm_s`` after the start;
    the full slice and the GPU always). With the DEM on the GPU, each block is also run
    coupled with the beads' side of the exchange and the smoothing on the CPU
    (``CfdDem.set_gpu_beads``), right after the same block with them on the GPU: both forms
    timed on the same beads."""

    if scene not in SCENES:
        raise ValueError(f"scene = {scene!r}: allowed {SCENES}")
    if start is None:
        start = "running" if scene == "sector" and device == "cpu" else "early"
    if start not in STARTS:
        raise ValueError(f"start = {start!r}: allowed {STARTS}")
    if start == "running" and (scene != "sector" or device != "cpu"):
        raise ValueError(f"start = 'running': the sector on the CPU only (scene = {scene!r}, "
                         f"device = {device!r}; the full slice takes hours to spin up on "
                         f"2 cores): use start = 'early'")
    sc = _scene(scene)
    sim, cpl = _start(scene, start, threads, device, warm_s, running_s, out)
    k = cpl.settings.steps
    block = max(k, k * (block // k))
    nblocks = max(1, steps // block)
    steps = nblocks * block
    start_s = sim.step_count * sc.dt_s
    sim.run(k)  # compiled
    # on the GPU, also the beads' side of the exchange on the CPU, in the same run
    both = device == "gpu" and getattr(cpl, "_gpu_side", None) is not None
    if both:
        cpl.set_gpu_beads(False)
        cpl.run(k)  # compiled
        cpl.set_gpu_beads(True)
    td, tc, th, ratios = [], [], [], []
    for _ in range(repeats):
        a = b = h = 0.0
        for _ in range(nblocks):
            t0 = time.perf_counter()
            sim.run(block)
            t1 = time.perf_counter()
            cpl.run(block)
            t2 = time.perf_counter()
            a += t1 - t0
            b += t2 - t1
            ratios.append((t2 - t1) / (t1 - t0) - 1.0)
            if both:
                cpl.set_gpu_beads(False)
                t0 = time.perf_counter()
                cpl.run(block)
                h += time.perf_counter() - t0
                cpl.set_gpu_beads(True)
        td.append(a)
        tc.append(b)
        if both:
            th.append(h)
    bd, bc = min(td), min(tc)
    from benchmarks.dem_peers import threading_layer

    layer = threading_layer()
    return CoupledBenchResult(scene=scene, device=device, beads=sim.n,
                              fluid_cells=cpl.grid.describe()["fluid_cells"],
                              steps=steps, coupling_steps=k, threads=sim.threads,
                              dem_particle_steps_per_s=sim.n * steps / bd,
                              coupled_particle_steps_per_s=sim.n * steps / bc,
                              added_cost=bc / bd - 1.0, dem_times_s=td, coupled_times_s=tc,
                              threading_layer=layer, start=start, start_s=start_s,
                              block_added_costs=ratios, cpu_beads_times_s=th,
                              cpu_beads_particle_steps_per_s=(sim.n * steps / min(th)
                                                              if th else 0.0))


#: the parts of a coupled interval that :func:`profile_coupled` times, in the order they
#: run: (label, where the call is found, its name); "cpl" the CfdDem, "EK" / "PJ" / "SK" its
#: exchange, projection and liquid-step kernel modules, "proj" its projector, "solver" the
#: liquid, "pressure" its pressure solver, "sim" the DEM
COUPLED_PARTS = (
    ("beads in: stencils, drag coefficients", "EK", "beads_in"),
    ("deposit on the grid", "PJ", "deposit"),
    ("smoothing of the totals", "proj", "smooth_totals"),
    ("void fractions, exchange coefficients", "EK", "cells_to_exchange"),
    ("liquid takes the beads' fields", "solver", "set_beads"),
    ("liquid substep: predictor", "SK", "predictor"),
    ("liquid substep: pressure solve", "pressure", "solve"),
    ("liquid substep: corrector", "SK", "corrector"),
    ("liquid: whole interval", "solver", "advance"),
    ("cell values for the beads", "EK", "nodes_to_cell_values"),
    ("smoothing of the values", "proj", "smooth_values"),
    ("held forces on the beads", "EK", "bead_forces"),
    ("exchange, whole", "cpl", "exchange"),
    ("DEM steps of the interval", "sim", "run"),
)


def profile_coupled(steps: int = 2000, threads: int | None = None, start: str = "running",
                    running_s: float = RUNNING_S, warm_s: float = 0.01, out=print,
                    state=None, scene: str = "sector") -> dict:
    """Where a coupled interval's time goes, measured inside the coupled run (the sector
    row's scene): every call of :data:`COUPLED_PARTS` timed (wall clock) over ``steps``
    DEM steps, then as many DEM steps alone in blocks of 200 (the DEM's pace without the
    exchange between its runs). The grid's arrays are pushed out of the caches by the DEM's
    steps between two exchanges, so each part costs more here than called back to back (a
    10-degree sector on 2 threads: the pressure solve 0.40-0.57 ms against 0.11-0.19).
    The parts are timed as the exchange's calls from Python; where the exchange runs in one
    compiled call (:mod:`millfmu.dem.coupling.fused_exchange`), that exchange is then timed
    whole over as many intervals ("exchange, whole, in one call", which the closing line's
    shares take). Returns {label: (median [s], mean per interval [s])} with "DEM alone, 10
    steps".
    ``state``: a (sim, coupling) pair to profile as it is (start and warm_s are then not
    used): the sector, or another disc_slice such as the full slice, which the heading
    names. ``scene``: the row's scene otherwise, "sector" or "full" (the full slice from
    the early start only: it takes hours to spin up on 2 cores)."""
    import types

    if start not in STARTS:
        raise ValueError(f"start = {start!r}: allowed {STARTS}")
    if scene not in SCENES:
        raise ValueError(f"scene = {scene!r}: allowed {SCENES}")
    if state is None and scene == "full" and start == "running":
        raise ValueError("start = 'running': the sector only; the full slice from 'early'")
    sim, cpl = state if state is not None else _start(scene, start, threads, "cpu", warm_s,
                                                         running_s, out)
    k = cpl.settings.steps
    intervals = max(1, steps // k)
    cpl.run(2 * k)  # compiled
    owners = {"cpl": cpl, "proj": cpl.projector, "solver": cpl.solver,
              "pressure": cpl.solver.pressure, "sim": sim}
    # module-level kernels are timed through per-object stand-ins for their modules
    mods = {}
    for key, attr_owner, attr in (("EK", cpl, "EK"), ("PJ", cpl, "PJ"),
                                  ("SK", cpl.solver, "SK")):
        mod = getattr(attr_owner, attr)
        mods[key] = (attr_owner, attr, mod)
        owners[key] = types.SimpleNamespace(**{n: getattr(mod, n) for n in dir(mod)
                                               if not n.startswith("__")})
    times = {label: [] for label, _, _ in COUPLED_PARTS}
    # the parts are seen only as calls from Python: the exchange in one compiled call
    # (coupling.fused_exchange) is timed whole afterwards, over as many intervals
    fused = cpl.fused
    cpl.fused = False

    def timed(fn, label):
        def call(*a, **kw):
            t0 = time.perf_counter()
            try:
                return fn(*a, **kw)
            finally:
                times[label].append(time.perf_counter() - t0)
        return call

    for label, who, name in COUPLED_PARTS:
        setattr(owners[who], name, timed(getattr(owners[who], name), label))
    for key, (attr_owner, attr, _) in mods.items():
        setattr(attr_owner, attr, owners[key])
    try:
        cpl.run(intervals * k)
    finally:
        for label, who, name in COUPLED_PARTS:
            if who in mods:
                continue
            del owners[who].__dict__[name]  # the instance's stand-in: the method again
        for attr_owner, attr, mod in mods.values():
            setattr(attr_owner, attr, mod)
        cpl.fused = fused
    one_call = []
    if fused:
        for _ in range(intervals):
            t0 = time.perf_counter()
            cpl.exchange()
            one_call.append(time.perf_counter() - t0)
            sim.run(k)
    alone = []
    for _ in range(max(1, intervals * k // 200)):
        t0 = time.perf_counter()
        sim.run(200)
        alone.append((time.perf_counter() - t0) * k / 200)
    res = {label: (statistics.median(v), sum(v) / intervals) for label, v in times.items()}
    if one_call:
        res["exchange, whole, in one call"] = (statistics.median(one_call),
                                               sum(one_call) / len(one_call))
    res["DEM alone, 10 steps"] = (statistics.median(alone), sum(alone) / len(alone))
    deg = sim.geometry.sector_deg
    what = "full slice" if deg == 360.0 else f"{deg:g} deg sector"
    out(f"coupled interval profile: disc_slice 10 m/s, 80 %, {what}, {sim.n} beads, "
        f"{cpl.grid.describe()['fluid_cells']} fluid cells, {sim.threads} threads, "
        f"{intervals} intervals of {k} steps, {sim.step_count * sim.dt_s:.3f} s after the "
        f"start; per interval [ms]")
    out(f"  {'part':42s} {'median':>8s} {'mean':>8s}")
    for label, (med, mean) in res.items():
        out(f"  {label:42s} {1e3 * med:8.3f} {1e3 * mean:8.3f}")
    ex = res.get("exchange, whole, in one call", res["exchange, whole"])[1]
    dem = res["DEM steps of the interval"][1]
    base = res["DEM alone, 10 steps"][1]
    out(f"  against the DEM's interval alone: the exchange {ex / base:.0%}, the DEM's steps "
        f"between exchanges {dem / base - 1:+.0%}, {(ex + dem) / base - 1:.0%} in all")
    return res


def row_line(c: dict) -> str:
    """The coupled row as one line (``c``: :meth:`CoupledBenchResult.as_dict`)."""
    where = f"DEM on the GPU, liquid on {c['threads']} threads" if c["device"] == "gpu" \
        else f"{c['threads']} threads"
    where += f" ({c['threading_layer']})"
    return (f"coupled row (disc_slice 10 m/s, 80 %, "
            f"{'10 deg' if c['scene'] == 'sector' else '360 deg with gravity'}, "
            f"{c['beads']} beads, "
            f"{c['fluid_cells']} fluid cells, coupling every {c['coupling_steps']} steps, "
            f"{where}, best of {len(c['dem_times_s'])}): DEM alone "
            f"{c['dem_particle_steps_per_s']:.4g}, coupled "
            f"{c['coupled_particle_steps_per_s']:.4g} particle-steps/s; the fluid and the "
            f"coupling add {c['added_cost']:.0%} (median of the "
            f"{len(c['block_added_costs'])} block pairs {c['added_cost_median']:.0%}); "
            f"beads timed from {c['start_s']:.3f} s after the start "
            f"({'the running mill' if c['start'] == 'running' else 'early'})"
            + (f"; with the beads' side of the exchange and the smoothing on the CPU instead "
               f"(the same blocks, interleaved) {c['cpu_beads_particle_steps_per_s']:.4g} "
               f"particle-steps/s, "
               f"the GPU's side {c['coupled_particle_steps_per_s'] / c['cpu_beads_particle_steps_per_s']:.2f}x"
               if c.get("cpu_beads_times_s") else ""))


def main(argv=None) -> int:
    """``python -m benchmarks.coupled_bench [sector|full]``: the coupled row alone, what
    ``python -m benchmarks.dem_peers --bed none --coupled`` runs (its options, by the same
    names)."""
    from benchmarks.dem_peers import main as peers

    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.coupled_bench",
        description="The coupled DEM-CFD against the DEM alone on the same beads (disc_slice "
                    "10 m/s, 80 %), alternating: what the liquid and the coupling add. The "
                    "same as 'python -m benchmarks.dem_peers --bed none --coupled SCENE'.")
    ap.add_argument("scene", nargs="?", default="sector", choices=SCENES,
                    help="the 10-degree sector (default) or 'full', the 360-degree slice with "
                         "gravity and 32 theta cells (235 k beads)")
    ap.add_argument("--steps", type=int, default=None, help="DEM steps per repeat "
                    "(default 1000)")
    ap.add_argument("--repeats", type=int, default=None, help="rounds, best of (default 3)")
    ap.add_argument("--cores", type=int, nargs="+", default=None, metavar="N",
                    help="numba threads (the largest counts; default: 1 2)")
    ap.add_argument("--device", choices=("cpu", "gpu"), default=None,
                    help="where the DEM steps (the liquid stays on the CPU's threads)")
    ap.add_argument("--coupled-start", choices=STARTS, default=None,
                    help="where the beads start: the running mill (the sector's default) or "
                         "early (see 'python -m benchmarks.dem_peers --help')")
    ap.add_argument("--profile", action="store_true", help="instead: where a coupled "
                    "interval's time goes, part by part (the DEM on the CPU)")
    ap.add_argument("--json", action="store_true", help="also print the row as JSON")
    ap.add_argument("--record", metavar="FILE", help="write the row's figures as one JSON record (commit, date, "
                                                     "machine)")
    ap.add_argument("--host", default="", help="the machine in words, for --record's record")
    a = ap.parse_args(argv)
    args = ["--bed", "none", "--coupled", a.scene]
    for opt, v in (("--steps", a.steps), ("--repeats", a.repeats), ("--device", a.device),
                   ("--coupled-start", a.coupled_start)):
        if v is not None:
            args += [opt, str(v)]
    if a.cores:
        args += ["--cores", *map(str, a.cores)]
    args += ["--profile"] * a.profile + ["--json"] * a.json
    if a.record:
        args += ["--record", a.record, "--host", a.host]
    return peers(args)


if __name__ == "__main__":
    sys.exit(main())
