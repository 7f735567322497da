"""Seed 001's explanation of its secondary vortex, checked with millfmu's liquid solver.

Seed 001 (section 3.2) sees a secondary vortex between the disc tip and the chamber wall at
8-14 m/s and none at 6 m/s, and explains it with Gers et al.: in their CFD of a stirred media
mill with a Newtonian fluid the vortex appears at Re = 458 (none at 229). Seed 001 gives its
bed an equivalent fluid of rho_eff = 1724 kg/m3 and eta_eff = 0.225 Pa s (its eq. 4,
Krieger-Dougherty) and Reynolds numbers of 263, 351, 438, 526 and 614 at 6-14 m/s (its
eq. 3), and calls the two consistent.

This study fills the disc slice (seed 001's geometry, 10-degree sector, one theta cell, no
gravity) with that equivalent fluid and runs the liquid alone (laminar: Re below 10^3), as
the coupled liquid's solver does before beads go in (:meth:`CfdDem.prime`). It averages the
axial volume flux over ``T_START_S`` to ``T_END_S`` (samples every ``SAMPLE_S``) and takes
the census of the mean meridional flow that the DEM runs use
(:mod:`millfmu.dem.analysis.flow_structure`: vortices above 1 % of the strongest, a
"secondary" one turning against the main vortex with its centre between disc tip and wall),
on the coupled table's grid (0.75 mm) and a finer one (0.5 mm), over both halves of the
window to show that the mean is settled.

``python -m validation.seed001_equivalent_fluid run --out validation/runs/seed001_equivalent_fluid.json``
(about 5 minutes on one core); ``... table`` prints the rows from the kept summary.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

#: seed 001 section 3.2: the equivalent fluid's density [kg/m3] and viscosity [Pa s]
RHO_EFF = 1724.0
ETA_EFF = 0.225
#: seed 001 section 3.2: its Reynolds numbers (eq. 3) by tip speed [m/s]
PAPER_RE = {6.0: 263, 8.0: 351, 10.0: 438, 12.0: 526, 14.0: 614}
#: Gers et al. (seed 001 ref. 10): the vortex appears at this Reynolds number
ONSET_RE = 458
#: seed 001's statement: the tip speeds [m/s] with a secondary vortex
PAPER_WITH = (8.0, 10.0, 12.0, 14.0)
TIP_SPEEDS = (6.0, 8.0, 10.0, 12.0, 14.0)
#: the coupled table's liquid cells [m], and a finer grid
CELLS_M = (7.5e-4, 5e-4)
#: [s] the window the flux is averaged over, from rest (viscous time over half the disc
#: spacing: (10 mm)^2 rho_eff / eta_eff = 0.77 s); the census of each half of the window
#: shows whether the mean has settled
T_START_S = 1.0
T_END_S = 3.0
SAMPLE_S = 0.01
SUMMARY = Path(__file__).parent / "runs" / "seed001_equivalent_fluid.json"


def scene(tip_speed_m_per_s: float, cell_m: float):
    """The disc slice with seed 001's equivalent fluid, laminar, 10-degree sector, no
    gravity (:class:`~millfmu.dem.scene.DemScene`)."""
    from millfmu.dem.scene import load_scene_dict, scene_from_dict

    d = load_scene_dict("disc_slice")
    d["mill"].update(tip_speed_m_per_s=float(tip_speed_m_per_s), sector_deg=10.0)
    d["fluid"].update(density_kg_per_m3=RHO_EFF, viscosity_Pa_s=ETA_EFF)
    d["fluid"]["coupled"].update(turbulence="laminar", cell_m=float(cell_m))
    d["run"]["gravity_m_per_s2"] = [0.0, 0.0, 0.0]
    return scene_from_dict(d)


def case(tip_speed_m_per_s: float, cell_m: float, t_start_s: float = T_START_S, t_end_s: float = T_END_S,
         sample_s: float = SAMPLE_S) -> dict:
    """The liquid alone from rest to ``t_end_s``; the census of its mean flow over
    [t_start_s, t_end_s] and over each half of it."""
    from millfmu.dem.analysis import flow_structure as FS
    from millfmu.dem.run import _zeta_of_grid, make_simulation

    s = scene(tip_speed_m_per_s, cell_m)
    t0 = time.perf_counter()
    _, cpl = make_simulation(s, 1)
    g = s.geometry
    hb = 0.5 * g.disc_thickness_m
    zeta = _zeta_of_grid(cpl.grid, g)
    order = np.argsort(zeta)
    r_c = cpl.grid.r_centres_m
    dr = np.diff(cpl.grid.r_faces_m)

    def census(flux_z, eps) -> dict:
        psi = FS.stream_function(r_c, np.nan_to_num(flux_z[:, order]), dr)
        c = FS.vortex_summary(FS.vortices(psi, r_c, zeta[order], g.disc_radius_m, hb,
                                          valid=np.isfinite(eps[:, order]), tip_zone_top_m=hb + s.zones.v1_width_m))
        return {"large": c["large"], "secondary": c["disc_tip_to_wall"],
                "vortices": [{"r_mm": round(v["r_m"] * 1e3, 2), "zeta_mm": round(v["zeta_m"] * 1e3, 2),
                              "sign": v["sign"], "strength": round(v["strength"], 4), "region": v["region"]}
                             for v in c["vortices"]]}

    cpl.prime(t_start_s)
    n = int(round((t_end_s - t_start_s) / sample_s))
    sums = [None, None]
    for i in range(n):
        cpl.prime(sample_s)
        f = cpl.section_fields()
        h = 0 if i < n // 2 else 1
        sums[h] = f["flux_z"] if sums[h] is None else sums[h] + f["flux_z"]
    eps = f["eps"]
    halves = [census(a / (n // 2 if h == 0 else n - n // 2), eps) for h, a in enumerate(sums)]
    whole = census((sums[0] + sums[1]) / n, eps)
    return {"tip_speed_m_per_s": float(tip_speed_m_per_s), "cell_m": float(cell_m),
            "paper_reynolds": PAPER_RE.get(float(tip_speed_m_per_s)), "mean": whole,
            "halves": halves, "wall_s": round(time.perf_counter() - t0, 1)}


def verdict(summary: dict) -> str:
    """The study's finding in words, computed from its cases: per grid, the tip speeds whose
    mean flow has a secondary vortex in the whole window and in both its halves, against
    seed 001's 8-14 m/s; "matches" only where every grid gives seed 001's speeds."""
    parts, found = [], []
    for cell in sorted({c["cell_m"] for c in summary["cases"]}, reverse=True):
        both = [c for c in summary["cases"] if c["cell_m"] == cell and c["mean"]["secondary"]
                and all(h["secondary"] for h in c["halves"])]
        found.append(tuple(sorted(c["tip_speed_m_per_s"] for c in both)))
        s = ", ".join(f"{c['tip_speed_m_per_s']:g} m/s ({_strength(c):.1%})" for c in both) or "none"
        parts.append(f"{cell * 1e3:g} mm cells: {s}")
    match = all(f == tuple(PAPER_WITH) for f in found)
    return ("secondary vortex in the mean flow of the equivalent fluid, in both halves of the window: "
            + "; ".join(parts) + f" (seed 001: {', '.join(f'{v:g}' for v in PAPER_WITH)} m/s): "
            + ("matches" if match else "seed 001's explanation not reproduced in this geometry"))


def _strength(c: dict) -> float:
    return max((v["strength"] for v in c["mean"]["vortices"] if v["region"] == "disc tip to wall"
                and v["sign"] != c["mean"]["vortices"][0]["sign"]), default=0.0)


def run(out: Path, tip_speeds=TIP_SPEEDS, cells=CELLS_M, log=print) -> dict:
    cases = []
    for cell in cells:
        for v in tip_speeds:
            c = case(v, cell)
            cases.append(c)
            log(f"{v:g} m/s, {cell * 1e3:g} mm: secondary {c['mean']['secondary']} (halves "
                f"{[h['secondary'] for h in c['halves']]}), {c['wall_s']:.0f} s")
    summary = {"note": "seed 001's equivalent fluid in the disc slice, the liquid alone (millfmu's solver, laminar); "
                       "census of the mean meridional flow (validation.seed001_equivalent_fluid)",
               "protocol": {"rho_eff_kg_per_m3": RHO_EFF, "eta_eff_Pa_s": ETA_EFF, "sector_deg": 10.0,
                            "n_theta": 1, "gravity": False, "turbulence": "laminar", "t_start_s": T_START_S,
                            "t_end_s": T_END_S, "sample_s": SAMPLE_S, "census_threshold": 0.01},
               "cases": cases}
    summary["verdict"] = verdict(summary)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(summary, indent=1) + "\n")
    log(summary["verdict"])
    return summary


def table(summary: dict) -> str:
    rows = ["| tip speed [m/s] | seed 001's Re | cells [mm] | vortices in the mean flow (centre r, zeta [mm]; "
            "strength) | secondary: mean, halves |", "|---|---|---|---|---|"]
    for c in summary["cases"]:
        main_sign = c["mean"]["vortices"][0]["sign"]
        vs = "; ".join(f"{v['r_mm']:g}, {v['zeta_mm']:g} ({v['strength']:.3g}"
                       f"{', against' if v['sign'] != main_sign else ''})" for v in c["mean"]["vortices"])
        rows.append(f"| {c['tip_speed_m_per_s']:g} | {c['paper_reynolds']} | {c['cell_m'] * 1e3:g} | {vs} | "
                    f"{c['mean']['secondary']}, {', '.join(str(h['secondary']) for h in c['halves'])} |")
    return "\n".join(rows)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m validation.seed001_equivalent_fluid",
                                description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run the cases and write the summary")
    r.add_argument("--out", default=str(SUMMARY))
    sub.add_parser("table", help="the rows of the kept summary")
    a = p.parse_args(argv)
    if a.cmd == "run":
        run(Path(a.out))
    else:
        s = json.loads(SUMMARY.read_text())
        print(table(s))
        print(s["verdict"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
