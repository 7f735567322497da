"""The DEM's contact law against closed forms, a published benchmark and LIGGGHTS 3.8 at
equal coefficients: one bead on a plane wall, run through the engine
(:class:`~millfmu.dem.engine.sim.DemSimulation`, the wall being a disc's face, so that the
wall-contact code is what is measured), and the same set-up in LIGGGHTS.

    python -m validation.contact_law [--out DIR] [--json validation/runs/contact_law.json]

DIR keeps LIGGGHTS' input and log files (a temporary folder without --out). Without the
``liggghts`` binary (Debian package ``liggghts``) its columns say "not installed".

The cases (seed 001's material for a, c, d: glass, 0.8 mm, 2510 kg/m3, Y 6.3e6 Pa,
nu 0.25, e 0.99, friction 0.3; gravity 9.81 m/s2 normal to the wall):

a. Sliding to rolling: a bead resting on a fixed wall, launched with a slip speed v0 (no
   spin). While it slides, the friction mu m g slows it at mu g and spins it up at
   (5/2) mu g / R; it rolls without slip from t1 = 2 v0 / (7 mu g) at 5/7 v0.
b. Oblique impacts on a fixed wall (Chung & Ooi 2011, Granular Matter 13:643, their Test 4:
   a 5 mm aluminium-oxide sphere, 3.8e11 Pa, nu 0.23, 4000 kg/m3, friction 0.092, at
   3.9 m/s against a rigid plane at incidence angles 5-85 degrees from the normal; e 0.98).
   The wall here is of the bead's material, so Y is doubled in both codes (Y* and G* of a
   sphere on a rigid plane: Y/(1 - nu^2) and Y/(2 (2 - nu)(1 + nu))). The closed form is
   rigid-body impact theory in the gross-sliding range, tan(theta) > 7/2 mu (1 + e_n):
   tangential restitution e_t = 1 - mu (1 + e_n) / tan(theta), rebound spin
   omega R = 5/2 mu (1 + e_n) v cos(theta), with e_n the run's own normal restitution;
   below it the tangential compliance (Maw, Barber & Fawcett 1976) governs and only the two
   codes are compared (the published curves are plots; no numbers are taken from them).
   Again at e = 0.5 at a few angles: LIGGGHTS adds the tangential damping only while the
   spring sticks and caps the spring force alone at mu |F_n|, our law caps spring and
   damping together, so strong damping separates the two where the contact sticks.
c. A bead on a moving wall (the disc's case): a bead at rest on the face of a disc that
   turns at omega, at radius r0 (surface speed V = omega r0). While it slips the friction
   is mu m g (acceleration mu g, spin-up (5/2) mu g / R); it rolls from t1 = 2 V / (7 mu g)
   at 2/7 V. In LIGGGHTS the wall is a square STL mesh whose surface turns about the axis
   (``surface_ang_vel``).
d. Rolling friction, constant directional torque (LIGGGHTS ``rolling_friction cdt``),
   |M_r| = mu_r k_n delta R* (R* = R at a wall), mu_r = 0.10: case a and case c again.
   Case a: while sliding, I dw/dt = (mu - mu_r) m g R, so the bead rolls from
   t1 = v0 / ((7/2 mu - 5/2 mu_r) g) at v1 = v0 - mu g t1; rolling, the static friction F
   and the torque satisfy m a = -F and (2/5) m R a = F R - mu_r m g R, so the bead slows
   at a = 5/7 mu_r g (the friction needed, 5/7 mu_r m g, stays below mu m g). Case c: the
   same in the wall's frame, t1 = V / ((7/2 mu - 5/2 mu_r) g), bead speed mu g t1, then
   the bead speeds up towards V at 5/7 mu_r g. Our law brakes w - w_wall, the rolling
   velocity relative to the turning disc, with its normal (torsion) part; LIGGGHTS brakes
   w (the wall's spin is not subtracted) without its normal part (``torsionTorque`` off),
   so the bead's spin about the disc's normal differs (listed, not a closed form).

Time step: 1/50 of the Hertz contact time at 1 m/s (a, c, d) or at the impact speed (b)
or less. Relative differences are (ours - other) / max(|other|, scale): scale 1 for the
tangential restitution (an absolute difference), v_t / R for the rebound spin (which nears
zero at small angles), the disc's angular velocity for the spin about the disc's normal,
0 otherwise. A comparison agrees when
every quantity lies within its tolerance (TOLERANCES); :func:`verdicts` recomputes them
from the numbers alone (the test of the shipped summary does).
"""

from __future__ import annotations

import argparse
import math
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

G_M_PER_S2 = 9.81
#: seed 001 Table 1 (glass, Y reduced by 1e4)
SEED001 = dict(density_kg_per_m3=2510.0, youngs_modulus_pa=6.3e6, poisson_ratio=0.25,
               restitution=0.99, friction=0.3)
SEED001_RADIUS_M = 0.4e-3
SEED001_ROLLING_FRICTION = 0.10
#: Chung & Ooi (2011) Test 4: aluminium oxide, Young's modulus doubled for a rigid plane
CHUNG_OOI = dict(density_kg_per_m3=4000.0, youngs_modulus_pa=2.0 * 3.8e11, poisson_ratio=0.23,
                 restitution=0.98, friction=0.092)
CHUNG_OOI_RADIUS_M = 2.5e-3
CHUNG_OOI_SPEED_M_PER_S = 3.9
CHUNG_OOI_ANGLES_DEG = (5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0)

#: case b again at e = 0.5, where the two codes' tangential damping differs
DAMPED_ANGLES_DEG = (5.0, 10.0, 20.0, 60.0)

SLIP_SPEED_M_PER_S = 0.1  # v0 of case a, V of case c
DISC_RADIUS_POSITION_M = 40e-3  # r0 of case c
#: relative tolerances of the comparisons
TOLERANCES = {"closed_form": 0.02, "liggghts": 0.01}
SAMPLE_STEPS = 10


# ---- the two codes ------------------------------------------------------------------------
def _material(mat: dict, rolling: float):
    from millfmu.dem.engine.params import BeadMaterial

    return BeadMaterial(rolling_friction=rolling, **mat)


def _mass_kg(mat: dict, radius_m: float) -> float:
    from millfmu.dem.engine.params import bead_mass_kg

    return bead_mass_kg(2.0 * radius_m, mat["density_kg_per_m3"])


def _ystar_pa(mat: dict) -> float:
    return _material(mat, 0.0).effective_youngs_pa


def _resting_overlap_m(mat: dict, radius_m: float) -> float:
    """Static Hertz overlap [m] of a bead's weight on a wall of its material."""
    w = _mass_kg(mat, radius_m) * G_M_PER_S2
    return (w / (4.0 / 3.0 * _ystar_pa(mat) * math.sqrt(radius_m))) ** (2.0 / 3.0)


def _contact_time_s(mat: dict, radius_m: float, speed_m_per_s: float) -> float:
    from millfmu.dem.engine.params import hertz_contact_time_s

    return hertz_contact_time_s(_mass_kg(mat, radius_m), radius_m, _ystar_pa(mat), speed_m_per_s)


def _disc_geometry(radius_m: float):
    """A disc whose upper face (z = b/2) is the plane wall; the bead sits far from the shaft,
    the rim and the next period's disc."""
    from millfmu.dem.mills.geometry import MillGeometry

    d = 2.0 * radius_m
    return MillGeometry(shaft_radius_m=5.0 * d, chamber_radius_m=80.0 * d, height_m=10.0 * d,
                        disc_radius_m=70.0 * d, disc_thickness_m=d, disc_z_m=0.0)


def run_ours(mat: dict, rolling: float, radius_m: float, height_m: float, velocity_m_per_s,
             omega_rad_per_s: float, dt_s: float, gravity: bool, steps: int,
             every: int, x_m: float) -> dict:
    """One bead above the disc face (centre height_m over it, at x = x_m) through the engine;
    samples every ``every`` steps: t [s], position [m] relative to the face, v [m/s],
    w [rad/s]."""
    from millfmu.dem.engine.sim import DemSimulation

    geo = _disc_geometry(radius_m)
    face = 0.5 * geo.disc_thickness_m
    sim = DemSimulation(geo, _material(mat, rolling), [[x_m, 0.0, face + height_m]], radius_m,
                        omega_rad_per_s, dt_s,
                        gravity_m_per_s2=(0.0, 0.0, -G_M_PER_S2 if gravity else 0.0),
                        fluid=None, skin_m=0.25 * radius_m, velocities_m_per_s=[velocity_m_per_s],
                        threads=1)
    out = {"t_s": [0.0], "x_m": [sim.x[0].copy()], "v_m_per_s": [sim.v[0].copy()],
           "w_rad_per_s": [sim.w[0].copy()]}
    done = 0
    while done < steps:
        k = min(every, steps - done)
        sim.run(k)
        done += k
        out["t_s"].append(done * dt_s)
        out["x_m"].append(sim.x[0].copy())
        out["v_m_per_s"].append(sim.v[0].copy())
        out["w_rad_per_s"].append(sim.w[0].copy())
    res = {k: np.array(v) for k, v in out.items()}
    res["x_m"][:, 2] -= face
    return res


def liggghts_binary() -> str | None:
    return shutil.which("liggghts")


def liggghts_version() -> str:
    """LIGGGHTS' banner line (its version), or "not installed"."""
    exe = liggghts_binary()
    if exe is None:
        return "not installed"
    with tempfile.TemporaryDirectory() as tmp:
        Path(tmp, "in.v").write_text("units si\n")
        subprocess.run([exe, "-in", "in.v", "-log", "log.v", "-screen", "screen.txt", "-nocite"],
                       cwd=tmp, check=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        log = Path(tmp, "log.v")
        first = log.read_text().splitlines()[0] if log.exists() else ""
    m = re.search(r"\((Version[^)]*)\)", first)
    return m.group(1) if m else first.strip() or "unknown"


def square_stl(path, half_m: float):
    """ASCII STL of the square |x|, |y| <= half_m at z = 0 (two facets, normal +z)."""
    a = half_m
    tris = (((-a, -a), (a, -a), (a, a)), ((-a, -a), (a, a), (-a, a)))
    lines = ["solid square"]
    for tri in tris:
        lines += ["facet normal 0 0 1", "outer loop"]
        lines += [f"vertex {x:.17g} {y:.17g} 0" for x, y in tri]
        lines += ["endloop", "endfacet"]
    lines.append("endsolid square")
    Path(path).write_text("\n".join(lines) + "\n")


def run_liggghts(mat: dict, rolling: float, radius_m: float, height_m: float, velocity_m_per_s,
                 omega_rad_per_s: float, dt_s: float, gravity: bool, steps: int, every: int,
                 x_m: float, workdir: Path, name: str) -> dict | None:
    """The same bead in LIGGGHTS 3.8 (``granular model hertz tangential history``, with
    ``rolling_friction cdt`` where mu_r > 0): the wall a primitive zplane, or with omega a
    square mesh at z = 0 whose surface turns about the z axis. None without LIGGGHTS."""
    exe = liggghts_binary()
    if exe is None:
        return None
    workdir.mkdir(parents=True, exist_ok=True)
    d = 2.0 * radius_m
    half = 100.0 * d
    model = "model hertz tangential history" + (" rolling_friction cdt" if rolling > 0 else "")
    if omega_rad_per_s:
        square_stl(workdir / f"{name}.stl", half)
        wall = (f"fix wallmesh all mesh/surface file {name}.stl type 1 surface_ang_vel "
                f"origin 0. 0. 0. axis 0. 0. 1. omega {omega_rad_per_s!r}\n"
                f"fix wall all wall/gran {model} mesh n_meshes 1 meshes wallmesh\n")
    else:
        wall = f"fix wall all wall/gran {model} primitive type 1 zplane 0.0\n"
    vx, vy, vz = (float(c) for c in velocity_m_per_s)
    grav = f"fix grav all gravity {G_M_PER_S2!r} vector 0 0 -1\n" if gravity else ""
    rollprop = (f"fix m5 all property/global coefficientRollingFriction peratomtypepair 1 {rolling!r}\n"
                if rolling > 0 else "")
    hard = "hard_particles yes\n" if mat["youngs_modulus_pa"] > 1e9 else ""
    text = f"""units si
{hard}atom_style granular
atom_modify map array
boundary f f f
newton off
communicate single vel yes
region box block {-half!r} {half!r} {-half!r} {half!r} {-10 * d!r} {10 * d!r} units box
create_box 1 box
neighbor {0.25 * radius_m!r} bin
neigh_modify delay 0
fix m1 all property/global youngsModulus peratomtype {mat['youngs_modulus_pa']!r}
fix m2 all property/global poissonsRatio peratomtype {mat['poisson_ratio']!r}
fix m3 all property/global coefficientRestitution peratomtypepair 1 {mat['restitution']!r}
fix m4 all property/global coefficientFriction peratomtypepair 1 {mat['friction']!r}
{rollprop}pair_style gran {model}
pair_coeff * *
timestep {dt_s!r}
{wall}create_atoms 1 single {x_m!r} 0 {height_m!r} units box
set atom 1 diameter {d!r} density {mat['density_kg_per_m3']!r}
velocity all set {vx!r} {vy!r} {vz!r} units box
{grav}fix integ all nve/sphere
variable t equal time
"""
    cols = ["v_t"]
    for q in ("x", "y", "z", "vx", "vy", "vz", "omegax", "omegay", "omegaz"):
        text += f"variable q{q} equal {q}[1]\n"
        cols.append(f"v_q{q}")
    text += (f"thermo_style custom step {' '.join(cols)}\nthermo_modify format float %.17g\n"
             f"thermo {every}\nrun {steps}\n")
    (workdir / f"in.{name}").write_text(text)
    # (-screen none crashes LIGGGHTS 3.8 when it reports reading an STL file)
    subprocess.run([exe, "-in", f"in.{name}", "-log", f"log.{name}", "-screen", f"screen.{name}",
                    "-nocite"], cwd=workdir, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.PIPE)
    rows = []
    reading = False
    for line in (workdir / f"log.{name}").read_text().splitlines():
        if line.strip().startswith("Step"):
            reading = True
            continue
        if reading:
            if line.startswith("Loop time"):
                break
            rows.append([float(c) for c in line.split()])
    a = np.array(rows)
    return {"t_s": a[:, 1], "x_m": a[:, 2:5], "v_m_per_s": a[:, 5:8], "w_rad_per_s": a[:, 8:11]}


# ---- measurements -------------------------------------------------------------------------
def slip_m_per_s(run: dict, radius_m: float, omega_rad_per_s: float) -> np.ndarray:
    """Velocity (x, y) of the bead's lowest point against the wall's surface there [m/s] (the
    wall turning about the z axis at omega)."""
    v, w, x = run["v_m_per_s"], run["w_rad_per_s"], run["x_m"]
    sx = v[:, 0] - radius_m * w[:, 1] + omega_rad_per_s * x[:, 1]
    sy = v[:, 1] + radius_m * w[:, 0] - omega_rad_per_s * x[:, 0]
    return np.stack([sx, sy], axis=1)


def roll_onset(run: dict, slip: np.ndarray, v_slip0: float):
    """(t1 [s], sample index) where the slip speed first falls below 1e-3 v_slip0, from the
    straight line through the last two samples above it."""
    s = np.hypot(slip[:, 0], slip[:, 1])
    k = int(np.argmax(s < 1e-3 * v_slip0))
    if k == 0:
        raise RuntimeError("the bead never stops slipping")
    t = run["t_s"]
    # the slip falls linearly: extrapolate the two samples before onset to zero
    t1 = t[k - 1] + s[k - 1] * (t[k - 1] - t[k - 2]) / (s[k - 2] - s[k - 1])
    return float(t1), k


def _slope(t, y, lo, hi) -> float:
    m = (t >= lo) & (t <= hi)
    return float(np.polyfit(t[m], y[m], 1)[0])


def slide_roll_quantities(run: dict, radius_m: float, v0: float, omega: float, t_end: float,
                          mu: float, mur: float) -> dict:
    """Case a/c/d figures of one run (v0: the initial slip speed, along +x for a fixed wall,
    +y for the turning disc)."""
    slip = slip_m_per_s(run, radius_m, omega)
    t1, k = roll_onset(run, slip, v0)
    t = run["t_s"]
    axis = 1 if omega else 0
    speed = run["v_m_per_s"][:, axis]
    # the friction spins the bead about +y (fixed wall, bead along +x) or +x (disc: the wall
    # moves along +y under it)
    spin = run["w_rad_per_s"][:, 0] if omega else run["w_rad_per_s"][:, 1]
    q = {
        "roll onset t1 [s]": t1,
        "speed at t1 [m/s]": float(np.interp(t1, t, speed)),
        "slip deceleration / (mu g)": abs(_slope(t, speed, 0.1 * t1, 0.9 * t1)) / (mu * G_M_PER_S2),
        "spin-up rate R / ((mu - mu_r) g)": _slope(t, spin, 0.1 * t1, 0.9 * t1) * radius_m
        / ((mu - mur) * G_M_PER_S2),
    }
    if mur > 0:
        lo = t1 + 0.1 * (t_end - t1)
        q["rolling acceleration / (mu_r g)"] = abs(_slope(t, speed, lo, t_end)) / (mur * G_M_PER_S2)
    else:
        q["speed at 2 t1 [m/s]"] = float(np.interp(min(2.0 * t1, t[-1]), t, speed))
    if omega:
        q["spin about the wall normal at the end [rad/s]"] = float(run["w_rad_per_s"][-1, 2])
    return q


def slide_roll_closed_form(v0: float, mu: float, mur: float, moving_wall: bool, omega: float) -> dict:
    t1 = v0 / ((3.5 * mu - 2.5 * mur) * G_M_PER_S2)
    v1 = mu * G_M_PER_S2 * t1 if moving_wall else v0 - mu * G_M_PER_S2 * t1
    q = {"roll onset t1 [s]": t1, "speed at t1 [m/s]": v1, "slip deceleration / (mu g)": 1.0,
         "spin-up rate R / ((mu - mu_r) g)": 2.5}
    if mur > 0:
        q["rolling acceleration / (mu_r g)"] = 5.0 / 7.0
    else:
        q["speed at 2 t1 [m/s]"] = v1
    if moving_wall:
        q["spin about the wall normal at the end [rad/s]"] = None
    return q


def case_slide_roll(moving_wall: bool, mur: float, workdir: Path | None, mat: dict | None = None) -> dict:
    """Cases a, c and d on seed 001's bead (or the material ``mat``, BeadMaterial's keys; mur
    its bead-bead rolling friction). The bead touches only the wall, so the closed forms and
    LIGGGHTS take the bead-wall coefficients (``wall_friction``, ``wall_rolling_friction``
    where ``mat`` gives them, else the bead-bead ones)."""
    mat, r = (SEED001 if mat is None else mat), SEED001_RADIUS_M
    mu = mat.get("wall_friction", mat["friction"])
    mur_bead, mur = mur, mat.get("wall_rolling_friction", mur)
    v0 = SLIP_SPEED_M_PER_S
    dt = _contact_time_s(mat, r, 1.0) / 100.0
    t1 = v0 / ((3.5 * mu - 2.5 * mur) * G_M_PER_S2)
    if mur > 0:
        v1 = mu * G_M_PER_S2 * t1 if moving_wall else v0 - mu * G_M_PER_S2 * t1
        left = (v0 - v1) if moving_wall else v1
        # half the rolling phase on the fixed wall; on the disc a quarter, while the bead's
        # path (about 1 mm) turns the disc's surface velocity under it by under 3 %
        t_end = t1 + (0.25 if moving_wall else 0.5) * left / (5.0 / 7.0 * mur * G_M_PER_S2)
    else:
        t_end = 2.0 * t1
    steps = int(math.ceil(t_end / dt / SAMPLE_STEPS)) * SAMPLE_STEPS
    t_end = steps * dt
    h = r - _resting_overlap_m(mat, r)
    omega = v0 / DISC_RADIUS_POSITION_M if moving_wall else 0.0
    vel = (0.0, 0.0, 0.0) if moving_wall else (v0, 0.0, 0.0)
    x0 = DISC_RADIUS_POSITION_M
    args = (mat, mur_bead, r, h, vel, omega, dt, True, steps, SAMPLE_STEPS)
    ours = slide_roll_quantities(run_ours(*args, x0), r, v0, omega, t_end, mu, mur)
    lig = None
    if workdir is not None:
        name = ("c" if moving_wall else "a") + ("_rolling" if mur else "")
        x_l = x0 if moving_wall else 0.0
        # one coefficient for every contact there: the bead-wall ones
        lig_mat = dict({k: v for k, v in mat.items() if not k.startswith("wall_")}, friction=mu)
        run = run_liggghts(lig_mat, mur, *args[2:], x_l, workdir, name)
        if run is not None:
            lig = slide_roll_quantities(run, r, v0, omega, t_end, mu, mur)
    closed = slide_roll_closed_form(v0, mu, mur, moving_wall, omega)
    # the spin about the normal relative to the disc's angular velocity
    scale = {"spin about the wall normal at the end [rad/s]": omega}
    return _table(ours, lig, closed, scale, dict(dt_s=dt, steps=steps, mu_r=mur,
                                               slip_speed_m_per_s=v0, omega_rad_per_s=omega))


def impact_quantities(run: dict, radius_m: float, speed: float, theta: float) -> dict:
    v, w = run["v_m_per_s"][-1], run["w_rad_per_s"][-1]
    if run["x_m"][-1, 2] <= radius_m:
        raise RuntimeError("the bead is still in contact at the end of the run")
    return {"e_n": v[2] / (speed * math.cos(theta)), "e_t": v[0] / (speed * math.sin(theta)),
            "spin [rad/s]": float(w[1])}


def case_oblique(workdir: Path | None, restitution: float | None = None,
                 angles_deg=CHUNG_OOI_ANGLES_DEG) -> dict:
    """Case b: Chung & Ooi's Test 4 (with another restitution where given)."""
    mat, r, u = CHUNG_OOI, CHUNG_OOI_RADIUS_M, CHUNG_OOI_SPEED_M_PER_S
    if restitution is not None:
        mat = dict(mat, restitution=restitution)
    mu = mat["friction"]
    dt = _contact_time_s(mat, r, u) / 100.0
    ours, lig, closed, scale = {}, {}, {}, {}
    for deg in angles_deg:
        th = math.radians(deg)
        vn = u * math.cos(th)
        gap = 1e-3 * r
        steps = int(math.ceil((2.0 * gap / vn + 1.5 * _contact_time_s(mat, r, vn)) / dt))
        args = (mat, 0.0, r, r + gap, (u * math.sin(th), 0.0, -vn), 0.0, dt, False, steps, steps)
        o = impact_quantities(run_ours(*args, 0.5 * _disc_geometry(r).disc_radius_m), r, u, th)
        lq = None
        if workdir is not None:
            run = run_liggghts(*args, 0.0, workdir, f"b_e{mat['restitution']:g}_{deg:g}")
            lq = None if run is None else impact_quantities(run, r, u, th)
        # rigid-body theory where the contact slides throughout (with our e_n)
        en = o["e_n"]
        sliding = math.tan(th) > 3.5 * mu * (1.0 + en)
        for k in o:
            key = f"{k} at {deg:g} deg"
            ours[key] = o[k]
            if lq is not None:
                lig[key] = lq[k]
            # e_t: an absolute difference; the spin relative to v_t / R (it nears zero at
            # small angles)
            scale[key] = 1.0 if k == "e_t" else (u * math.sin(th) / r if k.startswith("spin") else 0.0)
            closed[key] = None
            if sliding and k == "e_t":
                closed[key] = 1.0 - mu * (1.0 + en) / math.tan(th)
            elif sliding and k.startswith("spin"):
                closed[key] = 2.5 * mu * (1.0 + en) * vn / r
    return _table(ours, lig if workdir is not None and liggghts_binary() else None, closed, scale,
                  dict(dt_s=dt, speed_m_per_s=u, sliding_from_deg=math.degrees(
                      math.atan(3.5 * mu * (1.0 + mat["restitution"])))))


# ---- the summary --------------------------------------------------------------------------
def rel_diff(a, b, scale: float = 0.0):
    if a is None or b is None:
        return None
    den = max(abs(b), scale)
    return (a - b) / den if den > 0 else None


def _table(ours: dict, lig: dict | None, closed: dict, scale: dict, settings: dict) -> dict:
    rows = {}
    for k, v in ours.items():
        lv = None if lig is None else lig.get(k)
        c = closed.get(k)
        s = scale.get(k, 0.0)
        v = float(v)
        lv = None if lv is None else float(lv)
        c = None if c is None else float(c)
        rows[k] = {"ours": v, "liggghts": lv if lig is not None else "not installed",
                   "closed_form": c, "scale": s,
                   "ours_vs_closed": rel_diff(v, c, s), "ours_vs_liggghts": rel_diff(v, lv, s),
                   "liggghts_vs_closed": rel_diff(lv, c, s)}
    return {"settings": settings, "quantities": rows}


def verdicts(cases: dict, tolerances: dict) -> dict:
    """Per case and comparison: "agree" (every relative difference within the tolerance),
    "differ" (the quantities outside listed) or "not compared"; recomputed from the values
    (the relative differences are recomputed too, not read)."""
    out = {}
    for name, case in cases.items():
        v = {}
        for comp, a, b, tol in (("ours_vs_closed", "ours", "closed_form", "closed_form"),
                                ("ours_vs_liggghts", "ours", "liggghts", "liggghts"),
                                ("liggghts_vs_closed", "liggghts", "closed_form", "closed_form")):
            bad, n = [], 0
            for q, row in case["quantities"].items():
                x, y = row[a], row[b]
                if not isinstance(x, float) or not isinstance(y, float):
                    continue
                n += 1
                d = rel_diff(x, y, row["scale"])
                if d is None or abs(d) > tolerances[tol]:
                    bad.append(q)
            v[comp] = "not compared" if n == 0 else ("agree" if not bad else
                                                     "differ: " + "; ".join(bad))
        out[name] = v
    return out


CASES = {
    "a sliding to rolling (fixed wall)": dict(moving_wall=False, mur=0.0),
    "b oblique impacts (Chung & Ooi Test 4)": None,
    "b oblique impacts at e = 0.5 (tangential damping)": "e0.5",
    "c bead on a turning disc face": dict(moving_wall=True, mur=0.0),
    "d rolling friction cdt, fixed wall": dict(moving_wall=False, mur=SEED001_ROLLING_FRICTION),
    "d rolling friction cdt, turning disc face": dict(moving_wall=True, mur=SEED001_ROLLING_FRICTION),
}


def run_study(workdir: Path | None, command: str) -> dict:
    cases = {}
    for name, kw in CASES.items():
        print(f"{name} ...", file=sys.stderr, flush=True)
        if kw is None:
            cases[name] = case_oblique(workdir)
        elif kw == "e0.5":
            cases[name] = case_oblique(workdir, restitution=0.5, angles_deg=DAMPED_ANGLES_DEG)
        else:
            cases[name] = case_slide_roll(workdir=workdir, **kw)
    return {"command": command, "liggghts": liggghts_version(), "tolerances": dict(TOLERANCES),
            "cases": cases, "verdicts": verdicts(cases, TOLERANCES)}


def _fmt(x) -> str:
    if x is None:
        return "-"
    if isinstance(x, str):
        return x
    return f"{x:.6g}"


def report(summary: dict) -> str:
    lines = [f"LIGGGHTS: {summary['liggghts']}"]
    for name, case in summary["cases"].items():
        lines.append(f"\n{name}")
        for q, row in case["quantities"].items():
            d1, d2 = row["ours_vs_closed"], row["ours_vs_liggghts"]
            lines.append(f"  {q:48s} ours {_fmt(row['ours']):>13s}  LIGGGHTS {_fmt(row['liggghts']):>13s}"
                         f"  closed {_fmt(row['closed_form']):>13s}"
                         f"  d_closed {'-' if d1 is None else f'{d1:+.2e}':>9s}"
                         f"  d_LIGGGHTS {'-' if d2 is None else f'{d2:+.2e}':>9s}")
        for comp, v in summary["verdicts"][name].items():
            lines.append(f"  {comp}: {v}")
    return "\n".join(lines)


def main(argv=None) -> int:
    import json

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=None, help="folder for LIGGGHTS' inputs and logs")
    p.add_argument("--json", type=Path, default=None, help="write the run summary here")
    a = p.parse_args(argv)
    command = "python -m validation.contact_law" + (f" --json {a.json}" if a.json else "")
    if liggghts_binary() is None:
        summary = run_study(None, command)
    elif a.out is not None:
        summary = run_study(a.out, command)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            summary = run_study(Path(tmp), command)
    print(report(summary))
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps(summary, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
