"""Wet collisions of two beads and of a bead on a wall through the DEM, by its two laws,
against the closed form of its lubrication force and a published restitution curve of
immersed collisions.

    python -m validation.wet_collisions [--json validation/runs/wet_collisions.json]

Two equal beads of the coupled table's material (seed 001, Table 1: glass, 0.8 mm,
2510 kg/m3, Y 6.3e6 Pa, dry restitution 0.99) approach head-on in water (1.002e-3 Pa s)
through the engine (:class:`~millfmu.dem.engine.sim.DemSimulation`), with the table's
lubrication between beads (seed 001, section 2.1): F = -6 pi eta R*^2 v_n / max(h, h_min)
for gaps h below h_cut = 0.05 d, h_min = 5e-4 d. The run gives the effective restitution
e = -(v_n after) / (v_n before), the relative normal velocities beyond h_cut, over the
binary Stokes number St = m* v / (6 pi eta R*^2) (m*, R*: the pair's reduced mass and
radius; v: the approach speed).

Closed form of that force (integrated along the gap at the speed it slows, both ways): the
relative speed loses dv = (6 pi eta R*^2 / m*) (ln(h_cut / h_min) + 1) on the approach
(ln from h_cut to h_min, 1 from h_min to contact) and as much on the rebound, so
e = e_dry (1 - L / St) - L / St with L = ln(h_cut / h_min) + 1, zero below St_c = L (1 +
e_dry) / e_dry: 11.3 for the table's h_cut / h_min = 100.

Published: immersed sphere-wall collisions collapse onto e / e_dry = exp(-35 / St) (Legendre,
Zenit, Daniel and Guiraud 2006, Chem. Eng. Sci. 61, 3543, fitted to Joseph, Zenit, Hunt and
Rosenwinkel 2001, J. Fluid Mech. 433, 329, and Gondret, Lance and Petit 2002, Phys. Fluids
14, 643; St = m v / (6 pi eta a^2), which is the binary form above for a sphere on a wall,
m* = m, R* = a); Yang and Hunt (2006, Phys. Fluids 18, 121506) find head-on collisions of
two spheres on the same curve with the pair's reduced mass and radius. The published
critical Stokes number, where bouncing stops, is about 10 (Joseph et al. 2001).

The DEM's second law, ``[fluid] wet_collisions = "legendre2006"``
(:mod:`millfmu.dem.engine.legendre2006`), takes the published curve itself: a restitution
per contact from its approach's Stokes number, lubrication off. Its runs (two beads, and one
bead hitting a disc's face at the Stokes number of its own mass and radius, St = m v / (6 pi
eta a^2)) are checked against the curve; the lubrication law acts between beads only, so
its wall contacts stay dry.

The verdicts: the engine against the closed form of its lubrication law and against the
published curve with legendre2006 (the code does what each law says), and the lubrication
law's departure from the published curve at the Stokes number of the limestone example's
threshold at 10 um (2.7e-9 J, St 56).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from validation.run_summary import write_json

#: seed 001 Table 1 (glass, Y reduced by 1e4), water, and the table's lubrication gaps
MATERIAL = dict(density_kg_per_m3=2510.0, youngs_modulus_pa=6.3e6, poisson_ratio=0.25,
                restitution=0.99, friction=0.3)
RADIUS_M = 0.4e-3
VISCOSITY_PA_S = 1.002e-3
WATER_KG_PER_M3 = 998.2
H_CUT_M = 0.05 * 2.0 * RADIUS_M
H_MIN_M = 5e-4 * 2.0 * RADIUS_M
#: binary Stokes numbers run [-]
STOKES = (5.0, 8.0, 12.0, 16.0, 20.0, 30.0, 50.0, 80.0, 120.0, 200.0, 400.0, 1000.0)
#: the published fit's constant: e / e_dry = exp(-LEGENDRE_ST / St)
LEGENDRE_ST = 35.0
#: the engine against the closed form of its law, and legendre2006 against the published
#: curve (levels of 1/254 of e_dry; the Hertz contact damped by the linear spring's ratio):
#: |e_run - e_law| at most this
TOLERANCE = 0.01
SUMMARY = Path(__file__).resolve().parent / "runs" / "wet_collisions.json"


def _bead_mass_kg() -> float:
    from millfmu.dem.engine.params import bead_mass_kg

    return bead_mass_kg(2.0 * RADIUS_M, MATERIAL["density_kg_per_m3"])


def reduced():
    """(m* [kg], R* [m]) of two equal beads."""
    return 0.5 * _bead_mass_kg(), 0.5 * RADIUS_M


def speed_at(st: float) -> float:
    """Approach speed [m/s] of binary Stokes number ``st``."""
    m, r = reduced()
    return st * 6.0 * math.pi * VISCOSITY_PA_S * r * r / m


def stokes_of_energy(se_tn_j: float) -> float:
    """Binary Stokes number of a collision of normal energy 1/2 m* v^2 = ``se_tn_j`` [J]."""
    m, r = reduced()
    return m * math.sqrt(2.0 * se_tn_j / m) / (6.0 * math.pi * VISCOSITY_PA_S * r * r)


def closed_form(st: float, e_dry: float, h_cut: float = H_CUT_M, h_min: float = H_MIN_M) -> float:
    """The lubrication law's restitution [-] at binary Stokes number ``st`` (0 where the
    beads do not part)."""
    big_l = math.log(h_cut / h_min) + 1.0
    return max(0.0, e_dry * (1.0 - big_l / st) - big_l / st) if st > big_l else 0.0


def published(st: float, e_dry: float) -> float:
    """Legendre et al. (2006): e = e_dry exp(-35 / St)."""
    return e_dry * math.exp(-LEGENDRE_ST / st)


def _engine(lubrication: bool, wet_collisions: str):
    """(geometry, material, fluid, bead diameter [m]) of the runs: a disc's face far from the
    other walls, seed 001's beads without rolling friction, water."""
    from millfmu.dem.engine.params import BeadMaterial
    from millfmu.dem.engine.sim import FluidSettings
    from millfmu.dem.mills.geometry import MillGeometry

    d = 2.0 * RADIUS_M
    geo = MillGeometry(shaft_radius_m=5.0 * d, chamber_radius_m=80.0 * d, height_m=10.0 * d,
                       disc_radius_m=70.0 * d, disc_thickness_m=d, disc_z_m=0.0)
    mat = BeadMaterial(rolling_friction=0.0, **MATERIAL)
    fluid = FluidSettings(density_kg_per_m3=WATER_KG_PER_M3, viscosity_Pa_s=VISCOSITY_PA_S,
                          drag=False, lubrication=lubrication, lubrication_cutoff_m=H_CUT_M,
                          lubrication_min_gap_m=H_MIN_M, wet_collisions=wet_collisions)
    return geo, mat, fluid, d


def run_collision(speed: float, lubrication: bool, wet_collisions: str = "lubrication") -> float:
    """Effective restitution [-] of a head-on collision of two beads at relative speed
    ``speed`` [m/s] through the engine, with the lubrication force or without, or with the
    restitution per contact of ``wet_collisions = "legendre2006"`` (0 where they have not parted after 100 times the
    approach's duration); measured once the gap has opened beyond h_cut again, where no
    force acts on the pair any more."""
    from millfmu.dem.engine.params import hertz_contact_time_s
    from millfmu.dem.engine.sim import DemSimulation

    geo, mat, fluid, d = _engine(lubrication, wet_collisions)
    m, r = reduced()
    tc = hertz_contact_time_s(m, r, mat.effective_youngs_pa, speed)
    gap0 = 2.0 * H_CUT_M
    # the step resolves the contact (1/50 of its time) and the film: the gap closes by at
    # most 1/20 of h_min per step near contact, where the approach has slowed
    dt = min(tc / 50.0, 0.05 * H_MIN_M / speed + tc / 200.0)
    y = 0.5 * (d + gap0)
    x = np.array([[40.0 * d, -y, 5.0 * d], [40.0 * d, y, 5.0 * d]])
    v = np.array([[0.0, 0.5 * speed, 0.0], [0.0, -0.5 * speed, 0.0]])
    sim = DemSimulation(geo, mat, x, RADIUS_M, 0.0, dt, fluid=fluid, velocities_m_per_s=v,
                        threads=1)
    t_max = 100.0 * (gap0 / speed + tc)
    chunk = max(1, int(0.02 * (gap0 / speed) / dt))
    touched = False
    while sim.step_count * dt < t_max:
        sim.run(chunk)
        gap = (sim.x[1, 1] - sim.x[0, 1]) - d
        vrel = sim.v[1, 1] - sim.v[0, 1]  # > 0: parting
        touched = touched or gap < 0.0
        if touched and gap > H_CUT_M and vrel > 0.0:
            return vrel / speed
    return 0.0


def run_wall_collision(speed: float, wet_collisions: str = "lubrication") -> float:
    """Effective restitution [-] of one bead hitting a disc's face head-on at ``speed``
    [m/s] through the engine (the DEM's lubrication acts between beads only, so with
    ``"lubrication"`` the wall contact is dry)."""
    from millfmu.dem.engine.params import hertz_contact_time_s
    from millfmu.dem.engine.sim import DemSimulation

    geo, mat, fluid, d = _engine(wet_collisions == "lubrication", wet_collisions)
    tc = hertz_contact_time_s(_bead_mass_kg(), RADIUS_M, mat.effective_youngs_pa, speed)
    gap0 = 2.0 * H_CUT_M
    dt = tc / 50.0
    face = 0.5 * d
    sim = DemSimulation(geo, mat, [[40.0 * d, 0.0, face + RADIUS_M + gap0]], RADIUS_M, 0.0, dt,
                        fluid=fluid, velocities_m_per_s=[[0.0, 0.0, -speed]], threads=1)
    chunk = max(1, int(0.02 * (gap0 / speed) / dt))
    touched = False
    while sim.step_count * dt < 100.0 * (gap0 / speed + tc):
        sim.run(chunk)
        gap = sim.x[0, 2] - face - RADIUS_M
        touched = touched or gap < 0.0
        if touched and gap > 0.0 and sim.v[0, 2] > 0.0:
            return sim.v[0, 2] / speed
    return 0.0


def wall_speed_at(st: float) -> float:
    """Impact speed [m/s] of a bead on a wall at Stokes number ``st`` (its own mass and
    radius: St = m v / (6 pi eta a^2))."""
    return st * 6.0 * math.pi * VISCOSITY_PA_S * RADIUS_M ** 2 / _bead_mass_kg()


def run_study() -> dict:
    """Every Stokes number of :data:`STOKES`, with lubrication and dry; the summary."""
    rows = []
    for st in STOKES:
        v = speed_at(st)
        wet, dry = run_collision(v, True), run_collision(v, False)
        vw = wall_speed_at(st)
        rows.append({"stokes": st, "speed_m_per_s": v, "e_run": wet, "e_dry_run": dry,
                     "e_closed_form": closed_form(st, dry),
                     "e_published": published(st, dry),
                     "e_legendre2006_run": run_collision(v, False, "legendre2006"),
                     "wall_speed_m_per_s": vw,
                     "e_wall_lubrication_run": run_wall_collision(vw, "lubrication"),
                     "e_wall_legendre2006_run": run_wall_collision(vw, "legendre2006")})
    return {"note": ("head-on collisions of two beads in water through the DEM with the coupled "
                     "table's lubrication (seed 001 material), against the closed form of that "
                     "law and Legendre et al. (2006)'s e / e_dry = exp(-35 / St); St = m* v / "
                     "(6 pi eta R*^2)"),
            "command": "python -m validation.wet_collisions --json validation/runs/wet_collisions.json",
            "h_cut_m": H_CUT_M, "h_min_m": H_MIN_M, "viscosity_Pa_s": VISCOSITY_PA_S,
            "rows": rows,
            "stokes_at_energy": {f"{e:g} J": stokes_of_energy(e) for e in (5e-11, 2.8e-10, 2.7e-9)}}


def verdicts(summary: dict) -> dict:
    """From the numbers alone: whether the engine gives its law's closed form at every
    Stokes number (within :data:`TOLERANCE`), the law's critical Stokes number, and the
    law's restitution over the published one at the limestone threshold's Stokes number."""
    rows = summary["rows"]
    worst = max(abs(r["e_run"] - r["e_closed_form"]) for r in rows)
    worst_pub = max(max(abs(r["e_legendre2006_run"] - r["e_published"]),
                        abs(r["e_wall_legendre2006_run"] - r["e_published"])) for r in rows)
    worst_dry_wall = max(abs(r["e_wall_lubrication_run"] - r["e_dry_run"]) for r in rows)
    e_dry = rows[-1]["e_dry_run"]
    big_l = math.log(summary["h_cut_m"] / summary["h_min_m"]) + 1.0
    st_lime = summary["stokes_at_energy"]["2.7e-09 J"]
    return {"engine_matches_closed_form": worst <= TOLERANCE, "worst_difference": worst,
            "legendre2006_matches_published": worst_pub <= TOLERANCE,
            "worst_difference_legendre2006": worst_pub,
            "walls_dry_under_lubrication": worst_dry_wall <= 1e-3,
            "critical_stokes_law": big_l * (1.0 + e_dry) / e_dry,
            "critical_stokes_published": "about 10 (Joseph et al. 2001)",
            "stokes_at_limestone_threshold": st_lime,
            "e_law_at_threshold": closed_form(st_lime, e_dry, summary["h_cut_m"], summary["h_min_m"]),
            "e_published_at_threshold": published(st_lime, e_dry)}


def report(summary: dict) -> str:
    lines = ["| St [-] | approach speed [m/s] | e, lubrication law, engine [-] | e, its closed "
             "form [-] | e, Legendre et al. 2006 [-] | e, legendre2006, engine: two beads [-] | "
             "bead on a wall [-] | e, lubrication law, bead on a wall [-] | e dry, engine [-] |",
             "|---" * 9 + "|"]
    for r in summary["rows"]:
        lines.append(f"| {r['stokes']:g} | {r['speed_m_per_s']:.3g} | {r['e_run']:.3f} | "
                     f"{r['e_closed_form']:.3f} | {r['e_published']:.3f} | "
                     f"{r['e_legendre2006_run']:.3f} | {r['e_wall_legendre2006_run']:.3f} | "
                     f"{r['e_wall_lubrication_run']:.3f} | {r['e_dry_run']:.3f} |")
    v = verdicts(summary)
    lines += ["", f"legendre2006 against the published curve: worst "
              f"{v['worst_difference_legendre2006']:.4f} "
              f"({'within' if v['legendre2006_matches_published'] else 'beyond'} {TOLERANCE}); "
              f"walls under the lubrication law {'dry' if v['walls_dry_under_lubrication'] else 'not dry'}",
              f"engine against the closed form: worst {v['worst_difference']:.4f} "
              f"({'within' if v['engine_matches_closed_form'] else 'beyond'} {TOLERANCE}); "
              f"critical St of the law {v['critical_stokes_law']:.1f} (published about 10); at "
              f"the limestone threshold (2.7e-9 J, St {v['stokes_at_limestone_threshold']:.0f}) "
              f"e {v['e_law_at_threshold']:.2f} by the law, {v['e_published_at_threshold']:.2f} "
              f"by the published curve"]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m validation.wet_collisions",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", help="also write the run summary to this file")
    args = ap.parse_args(argv)
    summary = run_study()
    print(report(summary))
    if args.json:
        write_json(args.json, summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
