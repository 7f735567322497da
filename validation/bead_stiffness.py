"""The beads' Young's modulus against the collisions the detailed model reads.

Seed 001 ran its DEM with glass beads whose Young's modulus was reduced by 1e4 (Table 1:
6.3e6 Pa instead of 6.3e10 Pa), as the coupled table does, so that the time step can be
5e-6 s. A softer bead stays longer in contact (Hertz contact time ~ Y^(-2/5)) and, in a
dense sheared bed, separates and touches again at small speeds more often; every first
overlap counts as a collision (seed 001). The detailed model reads the table's collision
frequency and its collision energies, so what the reduction does to both bears on its
predictions (issue 58: the limestone's energies lie on the foot of the breakage curve and
the DEM counts several times Kwade's omega n_gb contacts).

This study runs the table's anchor point (disc slice, 10-degree sector without gravity,
coupled liquid, 10 m/s, 80 % filling, 0.8 mm glass beads) with Y times 1, 10 (and 100),
each with the time step scaled by the Hertz contact time, dt = 5e-6 s x factor^(-2/5),
and the DEM steps per coupling interval scaled so that the liquid keeps its 5e-5 s step
(dt x steps). The same protocol for every factor: started turning at 0.1 of the stirrer's
angular velocity, ``--spin-up`` (default 0.8 s) then ``--record`` (default 0.2 s), seed 1.

Per zone it reports the collision frequency per volume, the normal impact energy SE_tn
(seed 001 eq. 1, 1/2 m_GM v_rel,n^2 with the bead's mass, as the detailed examples read it
(``kinetics.stress_distribution.collision_energy = "bead_mass"``): twice the 1/2 m* v_rel,n^2
that a run's stats.json records with the pair's reduced mass) at its 10, 50 and 90 %
quantiles, the collision power,
and two readings of the detailed model over the zone-volume-weighted collisions: the rate
of collisions whose SE_tn exceeds an energy (the stand-in limestone's threshold at 10 um,
x W_m,min = 0.019 J m/kg, 2.7e-9 J, extrapolated from Cho & Austin's drop-weight tests; the
yeast's sourced median burst energy 2.8e-10 J), and the limestone example's mean breakage
probability per collision at x = 3 um (``examples/limestone_detailed.toml``: f_Mat 179.5
kg/(J m), threshold 0, eta_E = 1, elasticity factor (1 + Y_P/Y_GM)^-1 with the real moduli).

From a checkout's root:

    python -m validation.bead_stiffness run --out DIR [--factors 1,10] [--threads N]
    python -m validation.bead_stiffness table --out DIR [--json validation/runs/bead_stiffness.json]

``table`` prints the comparison and (``--json``) writes the run summary kept in the
repository; ``verdicts`` of that summary are recomputed from its numbers by the tests.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

#: Young's modulus of the table's beads [Pa] (seed 001 Table 1: glass reduced by 1e4)
Y_TABLE_PA = 6.3e6
#: the table's DEM step [s] and DEM steps per coupling interval (seed 001)
DT_TABLE_S = 5.0e-6
COUPLING_STEPS_TABLE = 10
#: the table's anchor: tip speed [m/s], filling [-]
ANCHOR = (10.0, 0.8)
INITIAL_ROTATION = 0.1
#: energies [J] whose exceedance rate is reported: the stand-in limestone's threshold at
#: 10 um (x W_m,min = 0.019 J m/kg, examples/limestone_detailed.toml) and the yeast's
#: sourced median burst energy (examples/yeast_disruption_detailed.toml)
LIMESTONE_THRESHOLD_10UM_J = 0.019 / 10e-6 * 2710.0 * math.pi / 6.0 * (10e-6) ** 3
YEAST_BURST_MEDIAN_J = 2.8e-10
#: SE_tn with the bead's mass over the stats.json's (the pair's reduced mass, m_GM / 2)
BEAD_MASS_FACTOR = 2.0
#: the limestone example's constants at the reference (examples/limestone_detailed.toml)
F_MAT_KG_PER_J_M = 179.5
RHO_LIMESTONE_KG_PER_M3 = 2710.0
ELASTICITY_FACTOR = 1.0 / (1.0 + 70e9 / 63e9)  # calcite on soda-lime glass
X_PROBE_M = 3.0e-6
#: a change counts as "moves" beyond this factor either way (the table's stated error at
#: the anchor is 19-26 % in collision frequency and 29-99 % in median SE_tn)
MOVES_FACTOR = 1.5


#: Points off the anchor for the trends (the trend study's, validation.trends_causes):
#: label -> (OperatingPoint field, value), or a tuple of such pairs for a point off the anchor
#: on two axes (the yeast pair's points at its own reference, 8 m/s); each runs at every
#: factor with the anchor's protocol
TREND_POINTS = {"v_t 14": ("tip_speed_m_per_s", 14.0), "d 1.2 mm": ("d_gb_m", 1.2e-3),
                "v_t 6": ("tip_speed_m_per_s", 6.0), "d 0.6 mm": ("d_gb_m", 0.6e-3),
                "rho 6040": ("rho_gb_kg_per_m3", 6040.0), "v_t 8": ("tip_speed_m_per_s", 8.0),
                "d 0.6 mm, 8 m/s": (("tip_speed_m_per_s", 8.0), ("d_gb_m", 0.6e-3)),
                "d 1.2 mm, 8 m/s": (("tip_speed_m_per_s", 8.0), ("d_gb_m", 1.2e-3)),
                "rho 6040, 8 m/s": (("tip_speed_m_per_s", 8.0), ("rho_gb_kg_per_m3", 6040.0))}


def point_pairs(point: str | None) -> tuple:
    """The (OperatingPoint field, value) pairs of trend point ``point`` (none for the anchor)."""
    if point is None:
        return ()
    v = TREND_POINTS[point]
    return (v,) if isinstance(v[0], str) else tuple(v)


def at_point(op, point: str | None):
    """Operating point ``op`` moved to trend point ``point``."""
    from validation import trends_causes as tc

    for field, value in point_pairs(point):
        op = tc.at(op, field, value)
    return op


def case_dir(out_dir, factor: float, point: str | None = None) -> Path:
    """``DIR/y<factor>`` for the anchor, ``DIR/<point>_y<factor>`` off it."""
    tag = "" if point is None else point.replace(" ", "").replace(".", "p").replace(",", "_").replace("/", "") + "_"
    return Path(out_dir) / f"{tag}y{factor:g}"


def scene_for(factor: float, spin_up_s: float, record_s: float, point: str | None = None):
    """The anchor scene (or the trend point ``point`` of :data:`TREND_POINTS`) with the beads'
    Young's modulus times ``factor``, dt scaled by the Hertz contact time and the coupling
    interval kept at the table's 5e-5 s."""
    from millfmu.dem.scene import load_scene

    pairs = dict(point_pairs(point))
    tip = pairs.get("tip_speed_m_per_s", ANCHOR[0])
    base = load_scene("disc_slice").with_overrides(
        fluid_mode="coupled", tip_speed_m_per_s=tip, filling=ANCHOR[1], sector_deg=10.0,
        gravity_m_per_s2=(0.0, 0.0, 0.0), spin_up_s=spin_up_s, record_s=record_s,
        sample_every_s=0.01, initial_rotation=INITIAL_ROTATION)
    if "d_gb_m" in pairs:
        base = replace(base, bead_diameter_m=pairs["d_gb_m"])
    if "rho_gb_kg_per_m3" in pairs:
        base = replace(base, material=replace(base.material, density_kg_per_m3=pairs["rho_gb_kg_per_m3"]))
    dt = DT_TABLE_S * factor ** -0.4
    steps = max(1, round(COUPLING_STEPS_TABLE * DT_TABLE_S / dt))
    return replace(base, name=f"disc_slice_{case_dir('', factor, point).name}",
                   material=replace(base.material, youngs_modulus_pa=Y_TABLE_PA * factor),
                   dt_s=dt, coupling=replace(base.coupling, steps=steps))


def run_cases(out_dir, factors, spin_up_s, record_s, threads=None, progress=True, points=(), point_factors=None):
    """Run the anchor at each factor, then each trend point of ``points`` at each of
    ``point_factors`` (default: ``factors``), skipping runs that have a stats.json."""
    from millfmu.dem.run import run_scene

    for point in (None, *points):
        for f in (factors if point is None or point_factors is None else point_factors):
            d = case_dir(out_dir, f, point)
            if (d / "stats.json").exists():
                continue
            run_scene(scene_for(f, spin_up_s, record_s, point), d, progress=progress, threads=threads)


@dataclass
class RunSource:
    """A stress-energy source made of one DEM run's zones (stats.json): each zone's share of
    the cell's volume, its collision frequency per volume, and its SE_tn distribution with
    the bead's mass (as the detailed examples read a table), whatever the operating point
    asked (the run is that point)."""

    run_zones: list

    def zones(self, op):
        return self.run_zones


def run_source(st: dict) -> RunSource:
    from millfmu.kinetics.stress_distribution import Zone

    edges = np.asarray(st["se_bin_edges_j"], float) * BEAD_MASS_FACTOR
    dlog = np.diff(np.log10(edges))
    vol = sum(z["volume_m3"] for z in st["zones"])
    out = []
    for z in st["zones"]:
        w = np.asarray(z["se"]["tn"]["density_per_decade"], float) * dlog
        f = float(z["collision_frequency_per_m3_s"]) if w.sum() > 0 else 0.0
        w = w / w.sum() if w.sum() > 0 else np.full(w.size, 1.0 / w.size)
        out.append(Zone(z["name"], z["volume_m3"] / vol, f, edges, w))
    return RunSource(out)


def trends(out_dir, factors, points) -> dict:
    """The limestone pair's trend at each point: the detailed model on the runs (its f_Mat
    refitted at the anchor run of each factor so that the anchor's S(10 um) is the shipped
    detailed model's, as validation.trends_causes refits) and the simple model, each over
    its own rate at the anchor."""
    from validation import trends_causes as tc

    ps = next(p for p in tc.setups() if p.w_feed is None)  # limestone: S(10 um)
    dm = ps.detailed
    target = tc.rate(dm, dm.material, dm.source, ps.op_detailed, ps)
    runs = {p: p for p in points}
    out = {"simple": simple_trend(ps, runs)[1], "detailed": {}}
    for f in factors:
        const, rel, _ = detailed_trend(ps, target, out_dir, f, None, runs)
        out["detailed"][f"{f:g}"] = {"f_mat_kg_per_J_m": const, "relative_rate": rel}
    return out


def simple_trend(ps, runs: dict) -> tuple:
    """(the simple model's rate at the pair's reference [1/s], {label: its rate at the trend
    point ``runs[label]`` over it})."""
    from validation import trends_causes as tc

    sm = ps.simple
    s_ref = tc.rate(sm, sm.material, None, ps.op_simple, ps)
    return s_ref, {k: tc.rate(sm, sm.material, None, at_point(ps.op_simple, p), ps) / s_ref for k, p in runs.items()}


def detailed_trend(ps, target: float, out_dir, factor: float, ref_run: str | None, runs: dict) -> tuple:
    """The detailed model on the runs of ``out_dir``: its material constant refitted at run
    ``ref_run`` (None: the anchor) so that its rate there is ``target`` [1/s], then {label:
    its rate on the run of trend point ``runs[label]`` over its rate on ``ref_run``}. Returns
    (the constant, NaN where none reaches ``target``; those rates; the reference run's
    source)."""
    from validation import trends_causes as tc

    dm = ps.detailed
    src0 = run_source(_stats(case_dir(out_dir, factor, ref_run)))
    mat, const = tc._refit(ps, dm.material, src0, ps.op_detailed, target)
    ref = tc.rate(dm, mat, src0, ps.op_detailed, ps)
    rel = {k: tc.rate(dm, mat, run_source(_stats(case_dir(out_dir, factor, p))), at_point(ps.op_detailed, p), ps) / ref
           for k, p in runs.items()}
    return const, rel, src0


def _stats(d: Path) -> dict:
    p = d / "stats.json"
    if not p.exists():
        raise FileNotFoundError(f"{p}: run it first (python -m validation.bead_stiffness run)")
    return json.loads(p.read_text())


def _zone_rates(st: dict) -> dict:
    """Zone-volume-weighted readings of one run's stats.json (see the module docstring), on
    its zones as the detailed model reads them (:func:`run_source`)."""
    m_p = RHO_LIMESTONE_KG_PER_M3 * math.pi / 6.0 * X_PROBE_M ** 3
    out = {"zones": [], "frequency_per_m3_s": 0.0, "above_limestone_threshold_per_m3_s": 0.0,
           "above_yeast_burst_per_m3_s": 0.0, "limestone_breaking_per_m3_s": 0.0,
           "power_W_per_m3": 0.0}
    for z, zone in zip(st["zones"], run_source(st).run_zones):
        f, share, e = zone.collision_rate_per_m3_s, zone.volume_fraction, zone.energy_J
        # a zone without collisions has no energies: no share of them above anything
        w = zone.energy_weights if f > 0.0 else np.zeros_like(e)
        p_lime = -np.expm1(-F_MAT_KG_PER_J_M * X_PROBE_M * e * ELASTICITY_FACTOR / m_p)
        q = {k: (None if v is None else BEAD_MASS_FACTOR * v) for k, v in z["se"]["tn"]["quantiles_j"].items()}
        row = {"zone": z["name"], "collision_frequency_per_m3_s": f,
               "se_tn_q10_J": q.get("q10"), "se_tn_q50_J": q.get("q50"), "se_tn_q90_J": q.get("q90"),
               "collision_power_W_per_m3": float(z["collision_power_w"]) / z["volume_m3"],
               "share_above_limestone_threshold": float(w[e > LIMESTONE_THRESHOLD_10UM_J].sum()),
               "share_above_yeast_burst": float(w[e > YEAST_BURST_MEDIAN_J].sum()),
               "limestone_p_break_3um": float((w * p_lime).sum()),
               "local_filling": float(z["filling"]), "speed_over_tip_speed": float(z["speed_over_tip_speed"])}
        out["zones"].append(row)
        out["frequency_per_m3_s"] += share * f
        out["above_limestone_threshold_per_m3_s"] += share * f * row["share_above_limestone_threshold"]
        out["above_yeast_burst_per_m3_s"] += share * f * row["share_above_yeast_burst"]
        out["limestone_breaking_per_m3_s"] += share * f * row["limestone_p_break_3um"]
        out["power_W_per_m3"] += share * row["collision_power_W_per_m3"]
    return out


CHAMBER_KEYS = ("frequency_per_m3_s", "above_limestone_threshold_per_m3_s", "above_yeast_burst_per_m3_s",
                "limestone_breaking_per_m3_s", "power_W_per_m3")


def _readings(d: Path, f: float) -> dict:
    st = _stats(d)
    r = _zone_rates(st)
    r.update(youngs_modulus_Pa=Y_TABLE_PA * f, dt_s=st["dt_s"], beads=st["beads"],
             spin_up_s=st["spin_up_s"], record_s=st["record_s"])
    return r


def summarize(out_dir, factors, points=()) -> dict:
    """The run summary: each factor's readings at the anchor and their ratios to factor 1;
    with ``points``, their readings there and the limestone pair's trends (:func:`trends`)."""
    runs = {f"{f:g}": _readings(case_dir(out_dir, f), f) for f in factors}
    out = {"command": "python -m validation.bead_stiffness table --out DIR --json "
                      "validation/runs/bead_stiffness.json (runs: ... run --out DIR --factors "
                      + ",".join(f"{f:g}" for f in factors) + ")",
           "anchor": {"tip_speed_m_per_s": ANCHOR[0], "filling": ANCHOR[1], "bead_diameter_m": 0.8e-3},
           "moves_factor": MOVES_FACTOR, "runs": runs, "verdicts": verdicts(runs)}
    if points:
        # the trend points at the factors they ran at (a stiffer anchor alone may be run later)
        pf = [f for f in factors if all((case_dir(out_dir, f, p) / "stats.json").exists() for p in points)]
        if 1.0 not in pf or len(pf) < 2:
            raise FileNotFoundError(f"{out_dir}: the trend points {list(points)} need runs at factor 1 and at "
                                    f"least one other (python -m validation.bead_stiffness run --points ...)")
        out["point_factors"] = [float(f) for f in pf]
        out["command"] = out["command"][:-1] + (f' --points "{",".join(points)}" --point-factors '
                                                + ",".join(f"{f:g}" for f in pf) + ")")
        out["point_runs"] = {p: {f"{f:g}": _readings(case_dir(out_dir, f, p), f) for f in pf} for p in points}
        out["trends"] = trends(out_dir, pf, points)
    return out


def ratios(runs: dict) -> dict:
    """Each factor's chamber readings over factor 1's."""
    base = runs["1"]
    out = {}
    for k, r in runs.items():
        if k == "1":
            continue
        out[k] = {key: (r[key] / base[key] if base[key] > 0 else float("nan")) for key in CHAMBER_KEYS}
    return out


def verdicts(runs: dict) -> dict:
    """Per factor and chamber reading: "moves" where the ratio to factor 1 lies beyond
    MOVES_FACTOR either way, else "holds"."""
    return {k: {key: ("moves" if not (1.0 / MOVES_FACTOR <= v <= MOVES_FACTOR) else "holds")
                for key, v in rs.items()} for k, rs in ratios(runs).items()}


def markdown(summary: dict) -> str:
    runs = summary["runs"]
    keys = list(runs)
    lines = ["| reading | " + " | ".join(f"Y x {k}" for k in keys) + " |",
             "|---|" + "---|" * len(keys)]
    for key, label in (("frequency_per_m3_s", "collisions per chamber volume [1/(m3 s)]"),
                       ("above_limestone_threshold_per_m3_s", "of them SE_tn > 2.7e-9 J [1/(m3 s)]"),
                       ("above_yeast_burst_per_m3_s", "of them SE_tn > 2.8e-10 J [1/(m3 s)]"),
                       ("limestone_breaking_per_m3_s", "breaking a 3 um limestone particle [1/(m3 s)]"),
                       ("power_W_per_m3", "collision power (SE_total) [W/m3]")):
        lines.append(f"| {label} | " + " | ".join(f"{runs[k][key]:.3g}" for k in keys) + " |")
    for zi, z in enumerate(runs[keys[0]]["zones"]):
        name = z["zone"]
        lines.append(f"| {name}: collision frequency [1/(m3 s)] | "
                     + " | ".join(f"{runs[k]['zones'][zi]['collision_frequency_per_m3_s']:.3g}" for k in keys) + " |")
        lines.append(f"| {name}: SE_tn q10 / q50 / q90 [J] | " + " | ".join(
            "/".join("-" if runs[k]["zones"][zi][q] is None else f"{runs[k]['zones'][zi][q]:.2g}"
                     for q in ("se_tn_q10_J", "se_tn_q50_J", "se_tn_q90_J")) for k in keys) + " |")
    tr = summary.get("trends")
    if tr:
        lines += ["", "| limestone S(10 um) over the anchor's | simple | " +
                  " | ".join(f"detailed, Y x {k}" for k in tr["detailed"]) + " |",
                  "|---|---|" + "---|" * len(tr["detailed"])]
        for p in tr["simple"]:
            lines.append(f"| {p} | {tr['simple'][p]:.3g} | " + " | ".join(
                f"{d['relative_rate'][p]:.3g}" for d in tr["detailed"].values()) + " |")
        lines.append("| f_Mat refitted at the anchor [kg/(J m)] | | " + " | ".join(
            f"{d['f_mat_kg_per_J_m']:.4g}" for d in tr["detailed"].values()) + " |")
        for p, byf in summary["point_runs"].items():
            lines.append(f"| {p}: collisions per volume over the anchor's | | " + " | ".join(
                f"{byf[k]['frequency_per_m3_s'] / runs[k]['frequency_per_m3_s']:.3g}" for k in byf) + " |")
            lines.append(f"| {p}: of them above 2.7e-9 J, over the anchor's | | " + " | ".join(
                f"{byf[k]['above_limestone_threshold_per_m3_s'] / runs[k]['above_limestone_threshold_per_m3_s']:.3g}"
                for k in byf) + " |")
    lines.append("")
    for k, v in summary["verdicts"].items():
        lines.append(f"Y x {k} against Y x 1: " + ", ".join(
            f"{key} {ratios(runs)[k][key]:.2f} ({v[key]})" for key in CHAMBER_KEYS))
    return "\n".join(lines)


def parser() -> argparse.ArgumentParser:
    s = argparse.ArgumentParser(prog="python -m validation.bead_stiffness",
                                description="The beads' Young's modulus against the table's collisions "
                                            "(run from a checkout's root).")
    s.add_argument("action", choices=("run", "table"))
    s.add_argument("--out", required=True, help="folder of the runs")
    s.add_argument("--factors", default="1,10", help="Young's modulus factors over 6.3e6 Pa (default 1,10)")
    s.add_argument("--spin-up", type=float, default=0.8, help="spin-up [s] (default 0.8)")
    s.add_argument("--record", type=float, default=0.2, help="recording [s] (default 0.2)")
    s.add_argument("--threads", type=int, help="numba threads (default: all cores)")
    s.add_argument("--points", default="",
                   help="trend points off the anchor, comma-separated, of " + ", ".join(repr(p) for p in TREND_POINTS)
                   + " (default none)")
    s.add_argument("--point-factors", default="",
                   help="the factors the trend points run at (default: --factors)")
    s.add_argument("--json", help="write the run summary here")
    return s


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    try:
        factors = [float(v) for v in args.factors.split(",") if v.strip()]
    except ValueError:
        print(f"python -m validation.bead_stiffness: --factors {args.factors!r}: numbers, comma-separated",
              file=sys.stderr)
        return 2
    if 1.0 not in factors or any(f < 1.0 for f in factors):
        print(f"python -m validation.bead_stiffness: --factors {args.factors!r}: must hold 1 (the table's "
              f"beads) and factors >= 1", file=sys.stderr)
        return 2
    points = [p.strip() for p in args.points.split(",") if p.strip()]
    bad = [p for p in points if p not in TREND_POINTS]
    if bad:
        print(f"python -m validation.bead_stiffness: --points {args.points!r}: allowed {list(TREND_POINTS)}",
              file=sys.stderr)
        return 2
    try:
        pf = [float(v) for v in args.point_factors.split(",") if v.strip()] or None
    except ValueError:
        print(f"python -m validation.bead_stiffness: --point-factors {args.point_factors!r}: numbers, "
              f"comma-separated", file=sys.stderr)
        return 2
    if pf is not None and (1.0 not in pf or not set(pf) <= set(factors)):
        print(f"python -m validation.bead_stiffness: --point-factors {args.point_factors!r}: must hold 1 and "
              f"only factors of --factors", file=sys.stderr)
        return 2
    if args.action == "run":
        run_cases(args.out, factors, args.spin_up, args.record, threads=args.threads, points=points,
                  point_factors=pf)
    summary = summarize(args.out, factors, points)
    print(markdown(summary))
    if args.json:
        Path(args.json).write_text(json.dumps(summary, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
