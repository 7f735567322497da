"""The DEM benchmark of issue 3: the ``annulus`` scene in its benchmark form.

0.8 mm glass beads (2510 kg/m3) on a simple cubic lattice of spacing 0.84 mm filling the
annulus between r = 15.5 and 44.5 mm, axial period 4 mm (about 38,500 beads); shaft
(r = 15 mm) surface speed 8 m/s, fixed chamber wall at 45 mm; no gravity, no fluid;
Y = 6.3e6 Pa, nu = 0.25, Hertz with tangential history, friction 0.3, restitution 0.99,
no rolling friction; dt = 5e-6 s, 2000 steps. Throughput is reported in particle-steps per
second of the stepping loop (set-up and compilation excluded, as LAMMPS's "Loop time").
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

from millfmu.dem.geometry import MillGeometry, simple_cubic_annulus
from millfmu.dem.params import BeadMaterial

BENCH_DIAMETER_M = 0.8e-3
BENCH_SPACING_M = 0.84e-3
BENCH_R_LATTICE_M = (15.5e-3, 44.5e-3)
BENCH_HEIGHT_M = 4e-3
BENCH_TIP_SPEED_M_S = 8.0
BENCH_DT_S = 5e-6
BENCH_STEPS = 2000
BENCH_GEOMETRY = MillGeometry(shaft_radius_m=15e-3, chamber_radius_m=45e-3,
                              height_m=BENCH_HEIGHT_M)
BENCH_MATERIAL = BeadMaterial(density_kg_m3=2510.0, youngs_modulus_pa=6.3e6,
                              poisson_ratio=0.25, restitution=0.99, friction=0.3,
                              rolling_friction=0.0)


@dataclass
class BenchResult:
    beads: int
    steps: int
    threads: int
    loop_time_s: float
    particle_steps_per_s: float
    neighbour_builds: int
    contacts_recorded: int


def bench_positions():
    """Initial bead centres [m] of the benchmark (LAMMPS-style sc lattice, origin 0)."""
    return simple_cubic_annulus(BENCH_SPACING_M, *BENCH_R_LATTICE_M, BENCH_HEIGHT_M)


def run_bench(steps: int = BENCH_STEPS, threads: int | None = None,
              skin_m: float | None = None, record: bool = False) -> BenchResult:
    """Run the benchmark and time its stepping loop."""
    import numba

    from millfmu.dem.sim import DemSimulation

    x = bench_positions()
    omega = BENCH_TIP_SPEED_M_S / BENCH_GEOMETRY.shaft_radius_m
    if threads is None:
        threads = numba.config.NUMBA_NUM_THREADS
    # compile (or load from the cache) outside the timed loop, with the same types
    warm = DemSimulation(BENCH_GEOMETRY, BENCH_MATERIAL, x[:50], 0.5 * BENCH_DIAMETER_M,
                         omega, BENCH_DT_S, threads=threads)
    warm.run(2, record=record)
    sim = DemSimulation(BENCH_GEOMETRY, BENCH_MATERIAL, x, 0.5 * BENCH_DIAMETER_M, omega,
                        BENCH_DT_S, skin_m=skin_m, threads=threads)
    t0 = time.perf_counter()
    st = sim.run(steps, record=record)
    dt = time.perf_counter() - t0
    return BenchResult(beads=sim.n, steps=steps, threads=sim.threads, loop_time_s=dt,
                       particle_steps_per_s=sim.n * steps / dt,
                       neighbour_builds=st.neighbour_builds,
                       contacts_recorded=int(st.events.shape[0]))


def main(threads: int | None = None, steps: int = BENCH_STEPS) -> dict:
    res = run_bench(steps=steps, threads=threads)
    return asdict(res)
