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
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass


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

    def as_dict(self) -> dict:
        return asdict(self)


SCENES = ("sector", "full")


def run_coupled_bench(steps: int = 2000, repeats: int = 3, threads: int | None = None,
                      warm_s: float = 0.01, block: int = 200, scene: str = "sector",
                      device: str = "cpu") -> CoupledBenchResult:
    """``steps`` DEM steps alone and ``steps`` coupled per repeat, interleaved in blocks of
    ``block`` steps (DEM block, coupled block, ...), so that both see the same bed as it
    evolves (a stirred bed's cost per step drifts by 10-20 % over a few thousand steps,
    which timing one long run after the other mistakes for a cost of the coupling). The
    liquid takes the beads' present void fraction after each DEM-alone block (see
    ``CfdDem.exchange``). Best of ``repeats``."""
    from millfmu.dem.run import make_simulation
    from millfmu.dem.scene import load_scene

    if scene not in SCENES:
        raise ValueError(f"scene = {scene!r}: allowed {SCENES}")
    sc = load_scene("disc_slice").with_overrides(fluid_mode="coupled", tip_speed_m_s=10.0,
                                                 filling=0.8, initial_rotation=0.1)
    if scene == "sector":
        sc = sc.with_overrides(sector_deg=10.0, gravity_m_s2=(0.0, 0.0, 0.0))
    else:
        sc = sc.with_overrides(n_theta=32, pressure_solver="theta_fft")
    sim, cpl = make_simulation(sc, threads, device)
    k = cpl.settings.steps
    block = max(k, k * (block // k))
    nblocks = max(1, steps // block)
    steps = nblocks * block
    cpl.run(k * max(1, int(round(warm_s / (k * sc.dt_s)))))
    sim.run(k)  # compiled
    td, tc = [], []
    for _ in range(repeats):
        a = b = 0.0
        for _ in range(nblocks):
            t0 = time.perf_counter()
            sim.run(block)
            a += time.perf_counter() - t0
            t0 = time.perf_counter()
            cpl.run(block)
            b += time.perf_counter() - t0
        td.append(a)
        tc.append(b)
    bd, bc = min(td), min(tc)
    import numba

    try:
        layer = numba.threading_layer()
    except ValueError:  # no parallel region ran
        layer = "none"
    return CoupledBenchResult(scene=scene, device=device, beads=sim.n,
                              fluid_cells=cpl.grid.describe()["fluid_cells"],
                              steps=steps, coupling_steps=k, threads=sim.threads,
                              dem_particle_steps_per_s=sim.n * steps / bd,
                              coupled_particle_steps_per_s=sim.n * steps / bc,
                              added_cost=bc / bd - 1.0, dem_times_s=td, coupled_times_s=tc,
                              threading_layer=layer)
