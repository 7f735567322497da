"""The DEM benchmark: a dense, sheared bead bed in an annulus, the same start for
millfmu.dem, LAMMPS and LIGGGHTS.

Scene: 0.8 mm glass beads (2510 kg/m3, Y = 6.3e6 Pa, nu = 0.25, e = 0.99, friction 0.3,
no rolling friction) between a shaft of r = 15 mm turning at 8 m/s surface speed and a
fixed chamber wall at r = 45 mm, axially periodic with height 4 mm; no gravity, no fluid;
dt = 5e-6 s, neighbour skin 0.3 mm.

The bed (:class:`BedRecipe`) is made once by millfmu's DEM: beads of a smaller radius on
random sites of an fcc lattice are grown to 0.8 mm with the shaft at rest (velocities
quenched after every stage) until they fill the annulus at a solid fraction of 0.62, then
the shaft turns for 0.02 s. The result (positions, velocities, spins) is written as a
LAMMPS data file (atom style sphere) in the user's cache folder, with a JSON sidecar
(recipe, sha256, coordination, overlaps). Every code starts from that file, so the
benchmark measures what real mill runs spend their time on: the contact loop with
tangential history in a bed where every bead touches several others, and neighbour-list
rebuilds paced by the fast beads at the shaft.

Throughput is particle-steps per second of the stepping loop (set-up and compilation
excluded, as LAMMPS' and LIGGGHTS' "Loop time").
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from millfmu.dem.engine.params import BeadMaterial
from millfmu.dem.mills.geometry import MillGeometry, place_beads

BENCH_DIAMETER_M = 0.8e-3
BENCH_TIP_SPEED_M_PER_S = 8.0
BENCH_DT_S = 5e-6
BENCH_STEPS = 1000
BENCH_SKIN_M = 0.3e-3  # 0.375 d, DemSimulation's default
BENCH_REPEATS = 3
BENCH_GEOMETRY = MillGeometry(shaft_radius_m=15e-3, chamber_radius_m=45e-3, height_m=4e-3)
BENCH_MATERIAL = BeadMaterial(density_kg_per_m3=2510.0, youngs_modulus_pa=6.3e6,
                              poisson_ratio=0.25, restitution=0.99, friction=0.3,
                              rolling_friction=0.0)
BENCH_OMEGA_RAD_PER_S = BENCH_TIP_SPEED_M_PER_S / BENCH_GEOMETRY.shaft_radius_m
#: half box width in x and y for LAMMPS and LIGGGHTS [m] (fixed boundaries)
BOX_HALF_M = 45.5e-3
HERE = Path(__file__).resolve().parent / "lammps"


@dataclass(frozen=True)
class BedRecipe:
    """How the bench bed is made (all steps of BENCH_DT_S)."""

    solid_fraction: float = 0.62  # bead volume over the annulus volume [-]
    start_radius_m: float = 0.37e-3  # radius on the lattice sites before growing [m]
    grow_stages: int = 10  # radius raised in equal stages, velocities zeroed after each
    steps_per_stage: int = 200
    relax_stages: int = 5  # further stages at the final radius
    spin_up_steps: int = 4000  # 0.02 s with the shaft turning
    seed: int = 1
    # dilute bed: random velocities of this rms speed [m/s] given after the growth (a
    # granular gas); 0 for the dense bed (left out of the key, which names its file)
    gas_speed_m_per_s: float = 0.0

    def key(self) -> str:
        """Content hash of the recipe and the scene: names the bed file."""
        rec = asdict(self)
        if not self.gas_speed_m_per_s:
            rec.pop("gas_speed_m_per_s")
        d = dict(recipe=rec, geometry=asdict(BENCH_GEOMETRY),
                 material=asdict(BENCH_MATERIAL), diameter_m=BENCH_DIAMETER_M,
                 tip_speed_m_per_s=BENCH_TIP_SPEED_M_PER_S, dt_s=BENCH_DT_S)
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:12]


#: the dense sheared bed (solid fraction 0.62, every bead in several contacts)
BED = BedRecipe()
#: the dilute bed: a fast granular gas at a solid fraction of 0.2 with 1 m/s random speeds
#: besides the shaft's shear (few contacts per bead, the neighbour lists rebuilt every few
#: tens of steps): the regime of seed 001's V1 and V4 zones and the accelerator's inner
#: zones, where the rebuilds, not the contacts, cost most
DILUTE_BED = BedRecipe(solid_fraction=0.3, grow_stages=4, relax_stages=1,
                       spin_up_steps=2000, gas_speed_m_per_s=1.0)
#: the beds by name (``--bed``)
BEDS = {"dense": BED, "dilute": DILUTE_BED}


# ---- the bed: LAMMPS data file -------------------------------------------------------------
@dataclass
class Bed:
    x: np.ndarray  # positions [m] (n, 3), z in [0, height)
    v: np.ndarray  # velocities [m/s]
    w: np.ndarray  # angular velocities [rad/s]
    diameter_m: float
    density_kg_per_m3: float


def write_data(path, bed: Bed, comment: str):
    """LAMMPS data file, atom style sphere: ``id type diameter density x y z`` and
    ``id vx vy vz wx wy wz`` (SI); read the same way by LIGGGHTS (atom style granular)."""
    n = bed.x.shape[0]
    h = BENCH_GEOMETRY.height_m
    z = np.mod(bed.x[:, 2], h)
    z[z >= h] = 0.0
    ids = np.arange(1, n + 1)
    head = (f"LAMMPS data file: {comment}\n\n{n} atoms\n1 atom types\n\n"
            f"{-BOX_HALF_M!r} {BOX_HALF_M!r} xlo xhi\n{-BOX_HALF_M!r} {BOX_HALF_M!r} ylo yhi\n"
            f"0.0 {h!r} zlo zhi\n\nAtoms # sphere\n\n")
    tmp = Path(str(path) + ".tmp")
    with open(tmp, "w") as fh:
        fh.write(head)
        cols = np.column_stack([ids, np.ones(n), np.full(n, bed.diameter_m),
                                np.full(n, bed.density_kg_per_m3), bed.x[:, 0], bed.x[:, 1], z])
        np.savetxt(fh, cols, fmt=["%d", "%d", "%.17g", "%.17g", "%.17g", "%.17g", "%.17g"])
        fh.write("\nVelocities\n\n")
        np.savetxt(fh, np.column_stack([ids, bed.v, bed.w]),
                   fmt=["%d"] + ["%.17g"] * 6)
    os.replace(tmp, path)


def read_data(path) -> Bed:
    """Read a data file written by :func:`write_data` (rows in id order)."""
    lines = Path(path).read_text().splitlines()
    n = next(int(s.split()[0]) for s in lines if s.strip().endswith("atoms"))
    a = lines.index(next(s for s in lines if s.startswith("Atoms")))
    b = lines.index("Velocities")
    atoms = np.array([s.split() for s in lines[a + 2:a + 2 + n]], dtype=float)
    vel = np.array([s.split() for s in lines[b + 2:b + 2 + n]], dtype=float)
    atoms = atoms[np.argsort(atoms[:, 0])]
    vel = vel[np.argsort(vel[:, 0])]
    return Bed(x=atoms[:, 4:7].copy(), v=vel[:, 1:4].copy(), w=vel[:, 4:7].copy(),
               diameter_m=float(atoms[0, 2]), density_kg_per_m3=float(atoms[0, 3]))


def contact_stats(x, radius_m: float, geometry: MillGeometry = BENCH_GEOMETRY) -> dict:
    """Bead-bead contacts (overlap > 0) of equal beads: mean coordination 2 C / N, median
    and 90th percentile of the overlaps [m], and the number of bead-wall contacts."""
    from scipy.spatial import cKDTree

    h = geometry.height_m
    big = 10.0 * geometry.chamber_radius_m
    pts = np.column_stack([x[:, 0] + big / 2, x[:, 1] + big / 2, np.mod(x[:, 2], h)])
    tree = cKDTree(pts, boxsize=[big, big, h])
    pairs = tree.query_pairs(2.0 * radius_m, output_type="ndarray")
    d = pts[pairs[:, 0]] - pts[pairs[:, 1]]
    d[:, 2] -= h * np.round(d[:, 2] / h)
    ov = 2.0 * radius_m - np.sqrt(np.einsum("ij,ij->i", d, d))
    r = np.hypot(x[:, 0], x[:, 1])
    walls = int(np.sum(r - geometry.shaft_radius_m < radius_m)
                + np.sum(geometry.chamber_radius_m - r < radius_m))
    return dict(coordination=2.0 * pairs.shape[0] / x.shape[0],
                overlap_median_m=float(np.median(ov)) if ov.size else 0.0,
                overlap_p90_m=float(np.quantile(ov, 0.9)) if ov.size else 0.0,
                wall_contacts=walls)


def make_bed(recipe: BedRecipe = BED, threads: int | None = None, out=None) -> Bed:
    """Make the bench bed with millfmu's DEM (see the module docstring)."""
    from millfmu.dem.engine.sim import DemSimulation

    g = BENCH_GEOMETRY
    r1 = 0.5 * BENCH_DIAMETER_M
    r0 = recipe.start_radius_m
    n = int(round(recipe.solid_fraction * g.free_volume_m3() / (math.pi / 6.0 *
                                                                 BENCH_DIAMETER_M ** 3)))
    x = place_beads(g, n, r0, seed=recipe.seed)
    # the skin covers the growth, so that the lists built for radius r0 stay valid
    grow = DemSimulation(g, BENCH_MATERIAL, x, r0, 0.0, BENCH_DT_S, threads=threads,
                         skin_m=BENCH_SKIN_M + 2.0 * (r1 - r0))
    stages = recipe.grow_stages + recipe.relax_stages
    for k in range(stages):
        grow.rad[:] = r0 + (r1 - r0) * min(k + 1, recipe.grow_stages) / recipe.grow_stages
        grow.run(recipe.steps_per_stage)
        grow.v[:] = 0.0
        grow.w[:] = 0.0
        if out:
            out(f"bed: stage {k + 1}/{stages} (radius {grow.rad[0] * 1e3:.4f} mm)")
    v0 = None
    if recipe.gas_speed_m_per_s:
        rng = np.random.default_rng(recipe.seed)
        v0 = rng.normal(0.0, recipe.gas_speed_m_per_s / math.sqrt(3.0), size=grow.x.shape)
    spin = DemSimulation(g, BENCH_MATERIAL, grow.x, r1, BENCH_OMEGA_RAD_PER_S, BENCH_DT_S,
                         threads=threads, skin_m=BENCH_SKIN_M, velocities_m_per_s=v0)
    left = recipe.spin_up_steps
    while left > 0:
        k = min(1000, left)
        spin.run(k)
        left -= k
        if out:
            out(f"bed: spin-up {recipe.spin_up_steps - left}/{recipe.spin_up_steps} steps")
    order = np.argsort(spin.ids)  # back to the initial bead order
    return Bed(x=spin.x[order].copy(), v=spin.v[order].copy(), w=spin.w[order].copy(),
               diameter_m=BENCH_DIAMETER_M, density_kg_per_m3=BENCH_MATERIAL.density_kg_per_m3)


def bench_dir() -> Path:
    """Where the bed lives: $MILLFMU_BENCH_DIR, else $XDG_CACHE_HOME/millfmu/bench, else
    ~/.cache/millfmu/bench."""
    env = os.environ.get("MILLFMU_BENCH_DIR")
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg).expanduser() if xdg else Path.home() / ".cache") / "millfmu" / "bench"


def bed_file(recipe: BedRecipe = BED, regenerate: bool = False, threads=None,
             out=print) -> Path:
    """Path of the bed's data file, made first if missing (or with regenerate). The sidecar
    ``.json`` holds the recipe, the file's sha256 and its contact statistics."""
    d = bench_dir()
    d.mkdir(parents=True, exist_ok=True)
    path = d / f"annulus_bed_{recipe.key()}.data"
    if path.exists() and not regenerate:
        return path
    out(f"making the bench bed {path} (once; {recipe})")
    t0 = time.perf_counter()
    bed = make_bed(recipe, threads=threads, out=out)
    kind = (f"dilute granular gas ({recipe.gas_speed_m_per_s:g} m/s)" if recipe.gas_speed_m_per_s
            else "dense sheared")
    write_data(path, bed, f"millfmu.dem bench bed {recipe.key()}: {kind} annulus, "
                          f"0.8 mm beads, shaft 8 m/s (SI units)")
    stats = contact_stats(bed.x, 0.5 * bed.diameter_m)
    speed = np.linalg.norm(bed.v, axis=1)
    side = dict(recipe=asdict(recipe), beads=int(bed.x.shape[0]),
                sha256=hashlib.sha256(path.read_bytes()).hexdigest(),
                mean_speed_m_per_s=float(speed.mean()), max_speed_m_per_s=float(speed.max()),
                seconds_to_make=time.perf_counter() - t0, **stats)
    path.with_suffix(".json").write_text(json.dumps(side, indent=1) + "\n")
    out(f"bed: {side['beads']} beads, coordination {stats['coordination']:.2f}, median "
        f"overlap {stats['overlap_median_m']:.3g} m, mean speed {side['mean_speed_m_per_s']:.3g} m/s")
    return path


def bed_info(path) -> dict:
    return json.loads(Path(path).with_suffix(".json").read_text())


# ---- contact constants for LAMMPS ------------------------------------------------------------
def lammps_constants(overlap_m: float) -> dict:
    """gran/hertz/history constants for the bench material [SI].

    LAMMPS' Hertz force is sqrt(R* d) (kn d - m* gamma_n v_n), so kn = 4/3 Y* and
    kt = 8 G* give exactly REFERENCE's k_n = 4/3 Y* sqrt(R* d) and S_t = 8 G* sqrt(R* d).
    Its damping, sqrt(R* d) m* gamma v, grows as d^(1/2) and m*, the LIGGGHTS form
    2 sqrt(5/6) |beta| sqrt(S m*) v (millfmu's) as d^(1/4) and m*^(1/2): the two agree
    only at one overlap and mass. gamma_n, gamma_t [1/(s m)] are matched at
    ``overlap_m`` (the bed's median overlap) for bead-bead (m* = m/2, R* = R/2) and,
    separately, for bead-wall contacts (m* = m, R* = R)."""
    mat = BENCH_MATERIAL
    ys, gs, beta = mat.effective_youngs_pa, mat.effective_shear_pa, abs(mat.damping_beta)
    r = 0.5 * BENCH_DIAMETER_M
    m = math.pi / 6.0 * BENCH_DIAMETER_M ** 3 * mat.density_kg_per_m3

    def gammas(mstar, rstar):
        q = (rstar * overlap_m) ** -0.25
        return (2.0 * math.sqrt(5.0 / 6.0) * beta * math.sqrt(2.0 * ys / mstar) * q,
                2.0 * math.sqrt(5.0 / 6.0) * beta * math.sqrt(8.0 * gs / mstar) * q)

    gn, gt = gammas(0.5 * m, 0.5 * r)
    gnw, gtw = gammas(m, r)
    return dict(kn=4.0 / 3.0 * ys, kt=8.0 * gs, gn=gn, gt=gt, gnw=gnw, gtw=gtw,
                mu=mat.friction)


# ---- runs ----------------------------------------------------------------------------------
@dataclass
class RunResult:
    code: str
    cores: int  # threads (ours) or MPI ranks
    device: str
    beads: int
    steps: int
    loop_s: float
    ke_trans_j: float  # after the run
    ke_rot_j: float
    coordination: float  # bead-bead contacts per bead after the run (2 C / N)
    extra: dict = field(default_factory=dict)

    @property
    def rate(self) -> float:
        """Particle-steps per second."""
        return self.beads * self.steps / self.loop_s


def run_ours(path, threads: int, steps: int = BENCH_STEPS, device: str = "cpu",
             record: bool = True) -> RunResult:
    """millfmu.dem on the bed at ``path``; contacts are recorded as in a mill run
    (LAMMPS and LIGGGHTS record none)."""
    from millfmu.dem.engine.sim import DemSimulation

    bed = read_data(path)
    kw = dict(velocities_m_per_s=bed.v, spins_rad_per_s=bed.w, skin_m=BENCH_SKIN_M, threads=threads)
    if device != "cpu":
        kw["device"] = device
    # compile (or load from the cache) outside the timed loop, with the same types (each
    # DemSimulation sets the thread count itself, after its kernels' module chose the layer)
    DemSimulation(BENCH_GEOMETRY, BENCH_MATERIAL, bed.x[:4000], 0.5 * bed.diameter_m,
                  BENCH_OMEGA_RAD_PER_S, BENCH_DT_S, **dict(kw, velocities_m_per_s=bed.v[:4000],
                                                        spins_rad_per_s=bed.w[:4000])
                  ).run(3, record=record)
    sim = DemSimulation(BENCH_GEOMETRY, BENCH_MATERIAL, bed.x, 0.5 * bed.diameter_m,
                        BENCH_OMEGA_RAD_PER_S, BENCH_DT_S, **kw)
    t0 = time.perf_counter()
    st = sim.run(steps, record=record)
    loop = time.perf_counter() - t0
    et, er = sim.kinetic_energy_j()
    return RunResult(code="millfmu.dem", cores=threads, device=device, beads=sim.n,
                     steps=steps, loop_s=loop, ke_trans_j=et, ke_rot_j=er,
                     coordination=contact_stats(sim.x, 0.5 * bed.diameter_m)["coordination"],
                     extra=dict(neighbour_builds=st.neighbour_builds,
                                contacts_recorded=int(st.events.shape[0])))


#: the GPU's large scene (issue 14): a million beads in the bench annulus on a simple cubic
#: lattice of 0.84 mm (7712 sites per layer between r = 15.5 and 44.5 mm), 130 layers
MILLION_LAYERS = 130
MILLION_SPACING_M = 0.84e-3


def run_gpu_million(steps: int = BENCH_STEPS) -> RunResult:
    """About a million beads (1,002,560) of the bench material in the bench annulus made 109 mm high, on a
    lattice with random velocities of 0.5 m/s (seed 1), shaft at 8 m/s, on the GPU: the
    throughput at a size where a GPU is full. A loose start (the CPU bed is too costly
    to make at this size); its contacts form during the run."""
    from millfmu.dem.engine.sim import DemSimulation
    from millfmu.dem.mills.geometry import simple_cubic_annulus

    h = MILLION_LAYERS * MILLION_SPACING_M
    geom = MillGeometry(shaft_radius_m=15e-3, chamber_radius_m=45e-3, height_m=h)
    x = simple_cubic_annulus(MILLION_SPACING_M, 15.5e-3, 44.5e-3, h)
    v = np.random.default_rng(1).normal(0.0, 0.5 / math.sqrt(3.0), size=x.shape)
    sim = DemSimulation(geom, BENCH_MATERIAL, x, 0.5 * BENCH_DIAMETER_M, BENCH_OMEGA_RAD_PER_S,
                        BENCH_DT_S, velocities_m_per_s=v, skin_m=BENCH_SKIN_M, device="gpu")
    sim.run(2, record=True)  # compiled and warm
    t0 = time.perf_counter()
    st = sim.run(steps, record=True)
    loop = time.perf_counter() - t0
    et, er = sim.kinetic_energy_j()
    return RunResult(code="millfmu.dem million", cores=1, device="gpu", beads=sim.n,
                     steps=steps, loop_s=loop, ke_trans_j=et, ke_rot_j=er,
                     coordination=contact_stats(sim.x, 0.5 * BENCH_DIAMETER_M,
                                                geom)["coordination"],
                     extra=dict(neighbour_builds=st.neighbour_builds))


def _mpirun(nproc: int) -> list[str]:
    # OpenMPI refuses root unless told; --bind-to none: the machine is shared, let the
    # kernel place the ranks; yield when idle: a rank waiting for the other gives up
    # its core instead of spinning (on a loaded machine, spinning ranks ran 2 ranks
    # slower than 1)
    return ["mpirun", "--allow-run-as-root", "--oversubscribe", "--bind-to", "none",
            "--mca", "mpi_yield_when_idle", "1", "-np", str(nproc)]


def _parse_log(text: str, code: str, nproc: int) -> RunResult:
    m = re.search(r"Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps with (\d+) atoms",
                  text)
    if not m:
        raise RuntimeError(f"{code}: no 'Loop time' in its log:\n{text[-2000:]}")
    # the last thermo row: step ke_trans ke_rot contacts-sum
    rows = re.findall(r"^\s*(\d+)\s+([0-9.eE+-]+)\s+([0-9.eE+-]+)\s+([0-9.eE+-]+)\s*$", text,
                      re.M)
    step, ket, ker, csum = rows[-1]
    atoms = int(m.group(4))
    return RunResult(code=code, cores=nproc, device="cpu", beads=atoms, steps=int(m.group(3)),
                     loop_s=float(m.group(1)), ke_trans_j=float(ket), ke_rot_j=float(ker),
                     coordination=float(csum) / atoms)


def _env_one_thread() -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1", OMPI_ALLOW_RUN_AS_ROOT="1",
               OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return env


def run_lammps(path, nproc: int, steps: int = BENCH_STEPS) -> RunResult:
    """LAMMPS (``lmp``): pair gran/hertz/history, shaft as fix wall/gran/region on a
    rotating cylinder region, chamber as a fixed one (lammps/in.bench_bed)."""
    c = lammps_constants(bed_info(path)["overlap_median_m"])
    with tempfile.TemporaryDirectory() as tmp:
        args = _mpirun(nproc) + ["lmp", "-in", str(HERE / "in.bench_bed"), "-log",
                                 "log.lammps", "-screen", "none", "-nocite"]
        for k, v in dict(data=str(path), steps=steps, skin=BENCH_SKIN_M,
                         omega=BENCH_OMEGA_RAD_PER_S, r_shaft=BENCH_GEOMETRY.shaft_radius_m,
                         r_chamber=BENCH_GEOMETRY.chamber_radius_m, dt=BENCH_DT_S, **c).items():
            args += ["-var", k, repr(v) if isinstance(v, float) else str(v)]
        subprocess.run(args, cwd=tmp, env=_env_one_thread(), check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        text = (Path(tmp) / "log.lammps").read_text()
    return _parse_log(text, "LAMMPS", nproc)


def cylinder_stl(path, radius_m: float, height_m: float, segments: int = 2880):
    """ASCII STL of the lateral surface of a cylinder about z from z = 0 to height_m, normals
    outwards. 2880 segments: the facets lie within radius (1 - cos(pi/2880)) = 9 nm of the
    cylinder at r = 15 mm. With 720 segments (0.14 um, 2 % of the bed's median overlap)
    LIGGGHTS' kinetic energy after 100 steps was 6 % below LAMMPS' and millfmu's, with
    2880 within 1.2 %."""
    th = np.linspace(0.0, 2.0 * math.pi, segments + 1)
    lines = ["solid cylinder"]
    for k in range(segments):
        a, b = th[k], th[k + 1]
        pa = (radius_m * math.cos(a), radius_m * math.sin(a))
        pb = (radius_m * math.cos(b), radius_m * math.sin(b))
        nm = 0.5 * (a + b)
        nrm = f"{math.cos(nm):.17g} {math.sin(nm):.17g} 0"
        for tri in (((pa, 0.0), (pb, 0.0), (pb, height_m)),
                    ((pa, 0.0), (pb, height_m), (pa, height_m))):
            lines.append(f"facet normal {nrm}\nouter loop")
            lines += [f"vertex {p[0]:.17g} {p[1]:.17g} {z:.17g}" for p, z in tri]
            lines.append("endloop\nendfacet")
    lines.append("endsolid cylinder")
    Path(path).write_text("\n".join(lines) + "\n")


def run_liggghts(path, nproc: int, steps: int = BENCH_STEPS) -> RunResult:
    """LIGGGHTS (``liggghts``): granular model hertz, tangential history (REFERENCE's contact
    law, constants from Y, nu, e, mu), shaft as an STL mesh with surface_ang_vel, chamber as
    a primitive zcylinder (lammps/in.bench_bed.liggghts)."""
    with tempfile.TemporaryDirectory() as tmp:
        cylinder_stl(Path(tmp) / "shaft.stl", BENCH_GEOMETRY.shaft_radius_m,
                     BENCH_GEOMETRY.height_m)
        mat = BENCH_MATERIAL
        args = _mpirun(nproc) + ["liggghts", "-in", str(HERE / "in.bench_bed.liggghts"),
                                 "-log", "log.liggghts", "-screen", "screen.txt", "-nocite"]
        # (-screen none crashes LIGGGHTS 3.8 when it reports reading the STL file)
        for k, v in dict(data=str(path), steps=steps, skin=BENCH_SKIN_M,
                         omega=BENCH_OMEGA_RAD_PER_S, r_chamber=BENCH_GEOMETRY.chamber_radius_m,
                         dt=BENCH_DT_S, youngs=mat.youngs_modulus_pa, poisson=mat.poisson_ratio,
                         restitution=mat.restitution, friction=mat.friction).items():
            args += ["-var", k, repr(v) if isinstance(v, float) else str(v)]
        subprocess.run(args, cwd=tmp, env=_env_one_thread(), check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        text = (Path(tmp) / "log.liggghts").read_text()
    return _parse_log(text, "LIGGGHTS", nproc)


def gpu_available() -> bool:
    """A real CUDA GPU (not numba's simulator)."""
    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
        return False
    try:
        from numba import cuda
        return bool(cuda.is_available())
    except Exception:  # no driver, no toolkit: no GPU row
        return False


def gpu_name() -> str:
    """The current CUDA device's name (numba's simulator has none)."""
    try:
        from numba import cuda
        name = cuda.get_current_device().name
    except Exception:
        return "numba CUDA simulator"
    return name.decode() if isinstance(name, bytes) else str(name)


def _load() -> str:
    try:
        la = os.getloadavg()
        return f"load average {la[0]:.2f} {la[1]:.2f} {la[2]:.2f}"
    except OSError:
        return "load average unknown"


def threading_layer() -> str:
    """numba's threading layer in this process ("none" before any parallel launch or where
    numba was never loaded): the bench prints it, since it moves millfmu.dem's figures (the
    coupled 10-degree sector's DEM on 2 threads: 4.57 and 4.32 M particle-steps/s on TBB
    against 5.47 and 5.04 on OpenMP, two benches each, alternating)."""
    if "numba" not in sys.modules:
        return "none"
    import numba

    try:
        return numba.threading_layer()
    except ValueError:  # no parallel region ran
        return "none"


def bench(steps: int = BENCH_STEPS, repeats: int = BENCH_REPEATS, cores=(1, 2),
          others: bool = True, out=print, regenerate: bool = False,
          devices=("cpu", "gpu"), bed: str = "dense") -> list[RunResult]:
    """Run every code on the bed named ``bed`` (:data:`BEDS`), alternating (one run of each
    per round), ``repeats`` rounds; print each code's fastest run and the ratios.
    ``devices``: millfmu.dem's CPU rows (with LAMMPS and LIGGGHTS) and its GPU rows (the
    bed and a million beads), the latter only where a GPU is present. Returns all runs."""
    if bed not in BEDS:
        raise ValueError(f"bed = {bed!r}: allowed {list(BEDS)}")
    path = bed_file(BEDS[bed], regenerate=regenerate, out=out)
    info = bed_info(path)
    runners = []
    for nc in sorted(cores, reverse=True) if "cpu" in devices else ():
        runners.append((f"millfmu.dem {nc} thr", lambda nc=nc: run_ours(path, nc, steps)))
        if others and shutil.which("lmp") and shutil.which("mpirun"):
            runners.append((f"LAMMPS {nc} MPI", lambda nc=nc: run_lammps(path, nc, steps)))
        if others and shutil.which("liggghts") and shutil.which("mpirun"):
            runners.append((f"LIGGGHTS {nc} MPI", lambda nc=nc: run_liggghts(path, nc, steps)))
    if "gpu" in devices and gpu_available():
        runners.append(("millfmu.dem GPU", lambda: run_ours(path, 1, steps, device="gpu")))
        if bed == "dense":
            runners.append(("millfmu.dem GPU 1e6", lambda: run_gpu_million(steps)))
    elif "gpu" in devices:
        out("no CUDA GPU (numba.cuda.is_available() is False): no GPU rows")
    if not runners:
        return []
    out(f"DEM bench: {'dense sheared' if bed == 'dense' else 'dilute (granular gas)'} bed, "
        f"{info['beads']} beads (coordination "
        f"{info['coordination']:.2f}, median overlap {info['overlap_median_m']:.3g} m), "
        f"{steps} steps of {BENCH_DT_S:g} s, skin {BENCH_SKIN_M:g} m; {repeats} rounds, "
        f"codes alternating; {_load()} at the start")
    runs: dict[str, list[RunResult]] = {name: [] for name, _ in runners}
    for k in range(repeats):
        for name, fn in runners:
            r = fn()
            runs[name].append(r)
            out(f"  round {k + 1}: {name:20s} loop {r.loop_s:8.3f} s  "
                f"{r.rate / 1e6:7.2f} M particle-steps/s")
    out(f"{_load()} at the end; millfmu.dem's threading layer: {threading_layer()}")
    best = {name: min(rs, key=lambda r: r.loop_s) for name, rs in runs.items()}
    out(f"{'code':22s} {'cores':>5s} {'best loop s':>11s} {'M p-steps/s':>11s} "
        f"{'KE_trans J':>11s} {'KE_rot J':>10s} {'coord':>6s}")
    for name, r in best.items():
        out(f"{name:22s} {r.cores:5d} {r.loop_s:11.3f} {r.rate / 1e6:11.2f} "
            f"{r.ke_trans_j:11.4e} {r.ke_rot_j:10.3e} {r.coordination:6.3f}")
    for line in ratio_lines(runs, cores):
        out(line)
    for line in ke_table(best, steps):
        out(line)
    return [r for rs in runs.values() for r in rs]


def peer_figures(runs: list, cores) -> dict:
    """The CPU rows of one bed's runs (in the order they ran, :func:`bench`'s return) as
    figures: per core count n, millfmu.dem's fastest rate over the faster reference's fastest
    (``ratio_n_cores``), the median of the rounds' ratios (``round_median_n_cores``), and
    each code's fastest rate [M particle-steps/s]; {} where no reference ran."""
    by: dict[tuple, list] = {}
    for r in runs:
        if r.device == "cpu":
            by.setdefault((r.code, r.cores), []).append(r)
    out = {}
    for nc in sorted(cores):
        ours = by.get(("millfmu.dem", nc))
        refs = {c: rs for (c, n), rs in by.items() if n == nc and c != "millfmu.dem"}
        if not (ours and refs):
            continue
        best = {c: max(r.rate for r in rs) for c, rs in refs.items()}
        faster = max(best, key=best.get)
        mine = max(r.rate for r in ours)
        pairs = [a.rate / b.rate for a, b in zip(ours, refs[faster])]
        out[f"ratio_{nc}_cores"] = round(mine / best[faster], 2)
        out[f"round_median_{nc}_cores"] = round(float(np.median(pairs)), 2)
        out[f"ours_M_particle_steps_per_s_{nc}_cores"] = round(mine / 1e6, 2)
        for c, v in sorted(best.items()):
            out[f"{c.lower()}_M_particle_steps_per_s_{nc}_cores"] = round(v / 1e6, 2)
    return out


def ratio_lines(runs: dict, cores) -> list[str]:
    """Lines of the speed ratios: for each core count, millfmu.dem's fastest run against
    the faster reference's fastest, and the same ratio round by round (``runs``: name ->
    the runs of each round, in order) with its median."""
    best = {name: min(rs, key=lambda r: r.loop_s) for name, rs in runs.items() if rs}
    lines = []
    for nc in sorted(cores, reverse=True):
        ours = best.get(f"millfmu.dem {nc} thr")
        keys = [k for k in (f"LAMMPS {nc} MPI", f"LIGGGHTS {nc} MPI") if k in best]
        refs = [best[k] for k in keys]
        if not (ours and refs):
            continue
        ref = max(refs, key=lambda r: r.rate)
        ref_key = keys[refs.index(ref)]
        lines.append(f"on {nc} core(s): millfmu.dem / {ref.code} (the faster reference) = "
                     f"{ours.rate / ref.rate:.2f}" + "".join(
                         f"; / {r.code} = {ours.rate / r.rate:.2f}"
                         for r in refs if r is not ref))
        # each round's runs follow each other within seconds: their ratios see the same
        # machine, while the bests may come from rounds minutes apart on a shared one
        pairs = [a.rate / b.rate for a, b in zip(runs[f"millfmu.dem {nc} thr"], runs[ref_key])]
        lines.append(f"  per round, millfmu.dem / {ref.code}: "
                     f"{', '.join(f'{p:.2f}' for p in pairs)} "
                     f"(median {float(np.median(pairs)):.2f})")
    return lines


#: relative difference of a kinetic energy from a reference's that the bench flags
KE_FLAG_REL = 0.03


def ke_table(best: dict, steps: int) -> list[str]:
    """Lines of the kinetic-energy comparison: every run in ``best`` (name -> RunResult)
    with its translational and rotational kinetic energy after ``steps`` steps and their
    relative difference from each reference code's (LAMMPS, LIGGGHTS: its first run in
    ``best``) in %; a difference above :data:`KE_FLAG_REL` is flagged ``!``. No lines
    without a reference run.

    The energies after a fixed number of steps are single samples of a fluctuating,
    chaotic state: over 100-step samples the bed's kinetic energy moves by about 5 %,
    and runs from the same file that differ by 1e-9 m in the positions gave 1000-step
    energies with a spread (standard deviation) of about 2 % (ours and LAMMPS alike).
    Besides, a file carries no tangential history: LAMMPS and LIGGGHTS start every
    contact of the file without one, as millfmu.dem does now (DemSimulation's
    history_at_start "zero"); its earlier start ("advanced") added one step of sliding
    to every spring at construction. On this bed that start alone made the +16 % of
    issue 28: over four runs each (the file and three starts 1e-9 m off), the
    translational energy after 1000 steps was 1.49e-4 J (sd 0.03e-4) with the earlier
    start, 1.29e-4 J (sd 0.03e-4) with "zero", and LAMMPS' 1.29e-4 J (sd 0.02e-4). A flag
    says where to look, not that a contact law differs."""
    refs = {}
    for name, r in best.items():
        if r.code in ("LAMMPS", "LIGGGHTS") and r.code not in refs:
            refs[r.code] = r
    if not refs:
        return []

    def rel(a, b):
        d = (a - b) / b if b else float("nan")
        return f"{100.0 * d:+7.1f} %{'!' if abs(d) > KE_FLAG_REL else ' '}"

    head = f"  {'code':22s} {'KE_trans J':>11s}"
    head += "".join(f" {'vs ' + c:>11s}" for c in refs)
    head += f" {'KE_rot J':>11s}" + "".join(f" {'vs ' + c:>11s}" for c in refs)
    lines = [f"kinetic energy after {steps} steps, relative to the references "
             f"(! more than {100 * KE_FLAG_REL:g} % apart):", head]
    for name, r in best.items():
        row = f"  {name:22s} {r.ke_trans_j:11.4e}"
        row += "".join(f" {rel(r.ke_trans_j, q.ke_trans_j):>11s}" if q is not r else
                       f" {'':>11s}" for q in refs.values())
        row += f" {r.ke_rot_j:11.4e}"
        row += "".join(f" {rel(r.ke_rot_j, q.ke_rot_j):>11s}" if q is not r else
                       f" {'':>11s}" for q in refs.values())
        lines.append(row)
    return lines


# ---- profile ---------------------------------------------------------------------------------
PHASES = ("neighbour build: wrap, cell binning", "neighbour build: lists",
          "force loop (+ most kicks)", "event gather", "reduction + the other kicks")


def profile(path, threads: int, steps: int = BENCH_STEPS, out=print) -> dict:
    """Where millfmu.dem's stepping time goes on the bed: the steps of
    :func:`millfmu.dem.engine.kernels.advance` driven one kernel at a time from Python, each timed
    (wall clock and process CPU time [s]; on a shared machine the CPU time of a 1-thread
    profile is the steadier figure). Returns {phase: (wall, cpu)} plus 'total', 'builds'."""
    from millfmu.dem.engine.sim import DemSimulation

    bed = read_data(path)
    sim = DemSimulation(BENCH_GEOMETRY, BENCH_MATERIAL, bed.x, 0.5 * bed.diameter_m,
                        BENCH_OMEGA_RAD_PER_S, BENCH_DT_S, velocities_m_per_s=bed.v,
                        spins_rad_per_s=bed.w, skin_m=BENCH_SKIN_M, threads=threads)
    sim.run(2, record=True)  # compiled and warm
    return profile_sim(sim, steps, out=out)


def profile_sim(sim, steps: int, out=print) -> dict:
    """Profile ``steps`` steps of a DemSimulation (any scene) as :func:`profile` does; the
    simulation advances (recording contacts, which are discarded)."""
    import numba

    from millfmu.dem.engine._jit import use_threads

    use_threads(sim.threads)
    # as DemSimulation.run: chunks handed out one at a time
    with numba.parallel_chunksize(1):
        return _profile_sim(sim, steps, out)


def _profile_sim(sim, steps, out):
    from millfmu.dem.engine import kernels as K

    s = sim
    tm = {k: np.zeros(2) for k in PHASES}

    def clock():
        return np.array([time.perf_counter(), time.process_time()])

    dt = s.dt_s
    half_skin2 = (0.5 * s.prm[K.P_SKIN]) ** 2
    builds = 0
    t_start = clock()
    K.kick_drift(s.x, s.v, s.w, s.f, s.t, s.inv_m, s.inv_i, 0.5 * dt, dt, s.xref, s.cb, s.dmax)
    for step in range(steps):
        if s.dmax.max() > half_skin2:
            t0 = clock()
            K.wrap_periodic(s.x, s.v, s.w, s.shw, s.prm, s.wrapk, s.cb)
            ej, es, ex = K.make_entries(s.x, s.prm, s.cutoff_m)
            lz = s.prm[K.P_LZ]
            lo = np.array([ex[:, 0].min() - 1e-9, ex[:, 1].min() - 1e-9])
            cs = s.cutoff_m
            ncx = max(int((ex[:, 0].max() + 1e-9 - lo[0]) / cs) + 1, 1)
            ncy = max(int((ex[:, 1].max() + 1e-9 - lo[1]) / cs) + 1, 1)
            ncz = int(lz / cs)
            start, sj, ss, sx, cmax = K.bin_entries(ej, es, ex, lo, cs, ncx, ncy, ncz, lz)
            t1 = clock()
            K.build_nlist(s.x, sj, ss, sx, start, cmax, lo, cs, ncx, ncy, ncz, cs * cs, s.prm,
                          s.wrapk, s.pst, s.nnb, s.pj, s.pim, s.psh, s.pfl, s.pst_o, s.nnb_o,
                          s.pj_o, s.pim_o, s.psh_o, s.pfl_o, s.cb, s.need, s.maxj,
                          s.claims())
            s.xref[:, :] = s.x
            if s.need.max() > s.pj_o.shape[0] // (s.cb.size - 1):
                raise RuntimeError("profile: neighbour lists overflowed; run the bench once")
            s._swap_lists()
            builds += 1
            t2 = clock()
            tm[PHASES[0]] += t1 - t0
            tm[PHASES[1]] += t2 - t1
        last = step == steps - 1  # as advance: the last kick is a half kick, no drift
        t0 = clock()
        K.compute_forces(s.x, s.v, s.w, s.fb, s.tb, s.rad, s.mass, s.inertia, s.pst, s.nnb,
                         s.pj, s.pim, s.psh, s.pfl, s.shw, s.flw, s.prm, s.cb, s.maxj, True,
                         step, s.evc, s.evn, s.torq, s.fext, s.claims(), not last, dt,
                         s.inv_m, s.inv_i, s.xref, s.dmax)
        t1 = clock()
        s.evcount[0] = 0
        K.gather_events(s.evc, s.evn, s.evbuf, s.evcount, s.acc)
        t2 = clock()
        K.reduce_kick(s.fb, s.tb, s.cb, s.maxj, s.f, s.t, s.v, s.w, s.x, s.inv_m, s.inv_i,
                      0.5 * dt if last else dt, dt, not last, s.xref, s.dmax, s.claims(),
                      not last)
        t3 = clock()
        tm[PHASES[2]] += t1 - t0
        tm[PHASES[3]] += t2 - t1
        tm[PHASES[4]] += t3 - t2
    total = clock() - t_start
    s.step_count += steps
    out(f"profile of millfmu.dem, {s.threads} thread(s), {s.n} beads, {steps} steps, "
        f"{builds} neighbour builds; {_load()}")
    out(f"  {'phase':38s} {'wall s':>8s} {'share':>6s} {'CPU s':>8s} {'share':>6s} "
        f"{'CPU ns per particle-step':>25s}")
    for k, v in tm.items():
        out(f"  {k:38s} {v[0]:8.3f} {100 * v[0] / total[0]:5.1f}% {v[1]:8.3f} "
            f"{100 * v[1] / total[1]:5.1f}% {v[1] / (s.n * steps) * 1e9:25.1f}")
    out(f"  {'total (incl. Python between kernels)':38s} {total[0]:8.3f} {'':6s} {total[1]:8.3f}"
        f"  {s.n * steps / total[0] / 1e6:.2f} M particle-steps/s (wall)")
    return dict(tm, total=total, builds=builds)


GPU_PHASES = ("flags read back", "neighbour build", "contact drain", "force kernel",
              "kick (drift, zeroing)")


def profile_gpu(path, steps: int = BENCH_STEPS, out=print) -> dict:
    """Where the GPU path's step time goes on the bed at ``path``: the loop of
    :meth:`millfmu.dem.engine.gpu.GpuStepper.run` driven phase by phase with the device
    synchronised after each (wall clock [s], launch and kernel together). The
    synchronisations serialise what the plain loop overlaps (the host launching the next
    kernel while the device runs the last), so the phases' sum is compared with the same
    steps run plainly; ``launch_s`` is the host's cost of one kernel launch (200 zero-force
    launches, not synchronised, on a tiny grid). Returns {phase: s} plus 'total',
    'plain', 'launch_s', 'builds', 'dropped' (contacts the buffer could not hold)."""
    from numba import cuda

    from millfmu.dem.engine import gpu as G
    from millfmu.dem.engine.sim import DemSimulation

    bed = read_data(path)
    sim = DemSimulation(BENCH_GEOMETRY, BENCH_MATERIAL, bed.x, 0.5 * bed.diameter_m,
                        BENCH_OMEGA_RAD_PER_S, BENCH_DT_S, velocities_m_per_s=bed.v, spins_rad_per_s=bed.w,
                        skin_m=BENCH_SKIN_M, device="gpu")
    sim.run(2, record=True)  # compiled and warm
    g = sim._gpu
    dt = sim.dt_s
    tm = {k: 0.0 for k in GPU_PHASES}

    def timed(name, fn):
        t0 = time.perf_counter()
        r = fn()
        cuda.synchronize()
        tm[name] += time.perf_counter() - t0
        return r

    cuda.synchronize()
    t_start = time.perf_counter()
    g.fext.copy_to_device(sim.fext)
    timed(GPU_PHASES[4], lambda: g._kick(0.5 * dt, True, True))
    events: list = []
    dropped = builds = 0
    for step in range(steps):
        h = timed(GPU_PHASES[0], g._flags)
        if h[G.F_REBUILD]:
            timed(GPU_PHASES[1], lambda: g._build(wrap=True))
            builds += 1
        if h[G.F_EVENTS] > g.evbuf.shape[0] // 2:
            dropped = timed(GPU_PHASES[2], lambda: g._drain(events, dropped))
        timed(GPU_PHASES[3], lambda: g._forces(True, step))
        last = step == steps - 1
        timed(GPU_PHASES[4], lambda: g._kick(0.5 * dt if last else dt, not last, not last))
    dropped = timed(GPU_PHASES[2], lambda: g._drain(events, dropped))
    total = time.perf_counter() - t_start
    g.fetch()
    sim.step_count += steps
    t0 = time.perf_counter()
    sim.run(steps, record=True)
    plain = time.perf_counter() - t0
    one = cuda.to_device(np.zeros((1, 3)))
    G.g_zero[1, 1](one, one)
    cuda.synchronize()
    t0 = time.perf_counter()
    for _ in range(200):
        G.g_zero[1, 1](one, one)
    launch = (time.perf_counter() - t0) / 200
    cuda.synchronize()
    out(f"profile of millfmu.dem on the GPU ({gpu_name()}), "
        f"{sim.n} beads, {steps} steps, {builds} neighbour builds, "
        f"{sum(e.shape[0] for e in events)} contacts recorded ({dropped} dropped), "
        f"phases synchronised")
    out(f"  {'phase':24s} {'wall s':>8s} {'share':>6s} {'us per step':>12s}")
    for k, v in tm.items():
        out(f"  {k:24s} {v:8.4f} {100 * v / total:5.1f}% {v / steps * 1e6:12.1f}")
    out(f"  {'total, synchronised':24s} {total:8.4f} {'':6s} {total / steps * 1e6:12.1f}  "
        f"{sim.n * steps / total / 1e6:.1f} M particle-steps/s")
    out(f"  {'the same steps, plain':24s} {plain:8.4f} {'':6s} {plain / steps * 1e6:12.1f}  "
        f"{sim.n * steps / plain / 1e6:.1f} M particle-steps/s")
    out(f"  one kernel launch on the host: {launch * 1e6:.1f} us")
    return dict(tm, total=total, plain=plain, launch_s=launch, builds=builds,
                dropped=dropped)


# ---- the command: python -m benchmarks.dem_peers ------------------------------------------
def parser() -> argparse.ArgumentParser:
    """The bench's options."""
    b = argparse.ArgumentParser(
        prog="python -m benchmarks.dem_peers",
        description="The dense sheared bed: ours (1 and 2 threads), LAMMPS and LIGGGHTS when "
                    "installed, the GPU when present; ratios. Run from a checkout's root.")
    b.add_argument("--steps", type=int, default=None, help="steps per run (default 1000)")
    b.add_argument("--repeats", type=int, default=None,
                   help="rounds, codes alternating; each code's fastest run counts (default 3)")
    b.add_argument("--cores", type=int, nargs="+", default=None, metavar="N",
                   help="numba threads and MPI ranks to run (default: 1 2)")
    b.add_argument("--ours-only", action="store_true", help="do not run LAMMPS and LIGGGHTS")
    b.add_argument("--device", choices=("cpu", "gpu"), default=None,
                   help="only the CPU rows (with LAMMPS and LIGGGHTS) or only the GPU rows "
                        "(the bed and a million beads; numba.cuda); default: both, the "
                        "GPU rows where a GPU is present")
    b.add_argument("--profile", action="store_true",
                   help="instead: where millfmu.dem's time goes, per kernel (1 and 2 threads; "
                        "with --device gpu, or where a GPU is present, per GPU phase); with "
                        "--coupled, where a coupled interval's time goes, part by part, "
                        "inside the coupled run (the sector, or the full slice from the early "
                        "start; --bed none for it alone)")
    b.add_argument("--regenerate-bed", action="store_true",
                   help="make the bed again (it is made once and cached)")
    b.add_argument("--json", action="store_true", help="also print every run as JSON")
    b.add_argument("--record", metavar="FILE",
                   help="write the CPU rows' ratios against the faster of LAMMPS and LIGGGHTS as one "
                        "JSON record (commit, date, machine; one bed: --bed dense or dilute)")
    b.add_argument("--host", default="", help="the machine in words, for --record's record")
    b.add_argument("--bed", choices=("dense", "dilute", "both", "none"), default="dense",
                   help="the dense sheared bed (default), the dilute one (a granular gas: "
                        "few contacts, frequent neighbour rebuilds), both in turn, or none "
                        "(with --coupled: the coupled row alone)")
    b.add_argument("--coupled", nargs="?", const="sector", default=None,
                   choices=("sector", "full"),
                   help="also the coupled row (benchmarks.coupled_bench): disc_slice with the "
                        "coupled fluid against the DEM alone on the same beads, alternating, "
                        "best of 3 (on the largest of --cores threads; the DEM on the GPU with "
                        "--device gpu): the 10-degree sector (default) or 'full', the "
                        "360-degree slice with gravity and 32 theta cells (235 k beads)")
    b.add_argument("--coupled-start", choices=("running", "early"), default=None,
                   help="where the coupled row's beads start: 'running', the running mill "
                        "(the sector's default: after 0.4 s of coupled motion, made once and "
                        "cached beside the bench bed) or 'early', 0.01 s after the start at "
                        "0.1 of the stirrer's rotation, when the bed has about a third of "
                        "the running mill's contacts (the full slice and the GPU always)")
    return b


def _refusal(args) -> str | None:
    """Why these options cannot run together (None: they can)."""
    if args.bed == "none" and not args.coupled:
        return "--bed none: nothing to run without --coupled"
    if args.profile and args.coupled and args.device == "gpu":
        return "--profile --coupled: the DEM on the CPU (here --device gpu)"
    if args.coupled_start and not args.coupled:
        return (f"--coupled-start {args.coupled_start}: applies to the coupled row; add "
                f"--coupled")
    if args.coupled_start == "running" and (args.coupled == "full" or args.device == "gpu"):
        return (f"--coupled-start running: the 10-degree sector on the CPU only (here "
                f"--coupled {args.coupled}{', --device gpu' if args.device == 'gpu' else ''}; "
                f"the full slice takes hours to spin up on 2 cores): use --coupled-start early")
    if args.device == "gpu" and (args.profile or args.coupled) and not gpu_available():
        return ("--device gpu: numba.cuda finds no CUDA GPU (numba's simulator is for tests, "
                "not for timing)")
    return None


def main(argv=None) -> int:
    """``python -m benchmarks.dem_peers [OPTIONS]``: print the bench (see :func:`parser`)."""
    args = parser().parse_args(argv)
    why = _refusal(args)
    if why:
        print(f"python -m benchmarks.dem_peers: {why}", file=sys.stderr)
        return 2
    steps = args.steps or BENCH_STEPS
    cores = tuple(args.cores or (1, 2))
    beds = dict(both=("dense", "dilute"), none=()).get(args.bed, (args.bed,))
    if args.record:
        coupled_only = args.coupled and not beds
        if args.profile or (not coupled_only and (len(beds) != 1 or args.coupled or args.ours_only
                                                  or args.device == "gpu")):
            print("python -m benchmarks.dem_peers: --record: the CPU rows of one bed against the peers "
                  "(--bed dense or dilute, without --profile, --ours-only or --device gpu), or the coupled "
                  "row alone (--bed none --coupled)", file=sys.stderr)
            return 2
        from millfmu.runner import OutputError, check_record_file

        try:
            check_record_file(args.record, "--record")
        except OutputError as e:
            print(f"python -m benchmarks.dem_peers: {e}", file=sys.stderr)
            return 2
    if args.profile:
        if args.coupled:
            from benchmarks.coupled_bench import profile_coupled

            profile_coupled(steps=args.steps or 2000, threads=max(cores), scene=args.coupled,
                            start=args.coupled_start
                            or ("running" if args.coupled == "sector" else "early"))
        for bed in beds:
            path = bed_file(BEDS[bed], regenerate=args.regenerate_bed)
            if args.device != "gpu":
                for nc in cores:
                    profile(path, nc, steps)
            if args.device == "gpu" or (args.device is None and gpu_available()):
                profile_gpu(path, steps)
        return 0
    runs = []
    for bed in beds:
        runs += bench(steps=steps, repeats=args.repeats or BENCH_REPEATS, cores=cores,
                      others=not args.ours_only, regenerate=args.regenerate_bed,
                      devices=(args.device,) if args.device else ("cpu", "gpu"), bed=bed)
    out = {"runs": [dict(r.__dict__, rate=r.rate) for r in runs]}
    if args.coupled:
        from benchmarks.coupled_bench import row_line, run_coupled_bench

        out["coupled"] = run_coupled_bench(
            steps=steps, repeats=args.repeats or 3, threads=max(cores), scene=args.coupled,
            device="gpu" if args.device == "gpu" else "cpu",
            start=args.coupled_start).as_dict()
        print(row_line(out["coupled"]))
    if args.record:
        from millfmu.machine import write_record

        # the options that were not the defaults, as the record's command names them
        opts = "" if args.steps is None else f" --steps {steps}"
        opts += "" if args.repeats is None else f" --repeats {args.repeats}"
        opts += "" if cores == (1, 2) else " --cores " + " ".join(map(str, cores))
        if args.coupled:
            c = out["coupled"]
            figures = {"added_percent": round(100.0 * c["added_cost"]),
                       "block_pair_median_percent": round(100.0 * c["added_cost_median"]),
                       "dem_alone_M_particle_steps_per_s": round(c["dem_particle_steps_per_s"] / 1e6, 2),
                       "coupled_M_particle_steps_per_s": round(c["coupled_particle_steps_per_s"] / 1e6, 2)}
            command = ("python -m benchmarks.coupled_bench" + ("" if args.coupled == "sector" else f" {args.coupled}")
                       + opts + (f" --device {args.device}" if args.device else ""))
            aim = {"added_percent": 15}
            unit = (f"what the coupled liquid and exchange add to the DEM's time [%], {args.coupled}, {c['threads']} "
                    f"threads, beads from the {c['start']} start; best of {len(c['dem_times_s'])} rounds, and the "
                    f"median of {len(c['block_added_costs'])} block pairs")
        else:
            figures = peer_figures(runs, cores)
            if not figures:
                print("python -m benchmarks.dem_peers: --record: neither LAMMPS nor LIGGGHTS ran (lmp, liggghts "
                      "and mpirun on the PATH); nothing written", file=sys.stderr)
                return 1
            command = "python -m benchmarks.dem_peers" + ("" if args.bed == "dense" else f" --bed {args.bed}") + opts
            aim = {"ratio_2_cores": 1.5}
            unit = (f"millfmu.dem's particle-steps per second over the faster of LAMMPS and LIGGGHTS (fastest runs; "
                    f"and the median of the rounds' ratios), {args.bed} bed, {runs[0].beads} beads, {steps} steps, "
                    f"codes alternating in {args.repeats or BENCH_REPEATS} rounds")
        print(f"wrote {write_record(args.record, command, figures, host=args.host, aim=aim, unit=unit)}")
    if args.json:
        print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
