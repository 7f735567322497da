"""Issue 58: why the detailed model's trends along the operating parameters differ from the
simple model's, one candidate cause at a time.

For both shipped calibrated pairs (:data:`millfmu.calibration.SHIPPED`: yeast cells,
limestone) this study evaluates the rates of ``millfmu rates`` at five points off each
pair's reference (bead diameter 0.6 and 1.2 mm, bead density 6040 kg/m3, tip speed
14 m/s, filling 0.9), relative to the same model's rate at the reference, for

- the simple model (Kwade; its breakage probability is 1 at these sizes);
- the detailed model at the simple scene's operating point with the simple scene's
  constants ("simple_op": the yeast pair's detailed model then runs with the simple
  scene's ``kinetics.energy_transfer`` = 0.0302, not its own 1.0; ``millfmu rates`` gives
  each model its own constants);
- the detailed model as shipped (its own scene's eta_E);
- each candidate correction applied alone on top of the shipped detailed model, by
  wrapping the stress-energy source, the material or the operating point at run time
  (nothing in the model is edited). Where a correction changes the energy scale, the
  detailed model's one material constant is refitted at the reference point as the
  shipped calibration did (yeast: the median burst energy, so that the reference rate
  equals the simple model's, whose curve is the stand-in data; limestone: f_Mat, so that
  S(10 um) at the reference stays the shipped detailed model's), and the fitted value is
  printed: the yeast burst energy's sourced range is about 1-5e-10 J.

Run from a checkout's root: ``python -m validation.trends_causes`` (about half a minute). Prints the trend
table per pair, the breakage probability per stress at three bead sizes, and the stress
energies behind them (Kwade's SE against the table's medians).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import brentq

from millfmu import calibration as cal
from millfmu.kinetics import rates as krates
from millfmu.kinetics import stress as kstress
from millfmu.kinetics.stress_distribution import Zone, chamber_collision_rate_per_m3_s
from millfmu.mill import MillModel, psd_fractions

#: The points off the reference: (parameter, OperatingPoint field, value, label).
POINTS = (
    ("bead_diameter", "d_gb_m", 0.6e-3, "d 0.6 mm"),
    ("bead_diameter", "d_gb_m", 1.2e-3, "d 1.2 mm"),
    ("bead_density", "rho_gb_kg_per_m3", 6040.0, "rho 6040"),
    ("tip_speed", "tip_speed_m_per_s", 14.0, "v_t 14"),
    ("filling", "filling", 0.9, "fill 0.9"),
)
#: Sourced range of the yeast burst energy [J] (the project's reference, "Material data").
BURST_SOURCED_J = (1e-10, 5e-10)
#: Young's modulus of yttria-stabilised zirconia beads [Pa] (about 200-210 GPa), for the
#: bead-material variant of the elasticity factor.
Y_ZIRCONIA_PA = 210e9
#: "In line": the detailed model's change over the simple model's, at every point, within
#: this factor (and so in the same direction where the simple model's change exceeds it).
IN_LINE_FACTOR = 1.5


# ---- stress-energy source wrappers ---------------------------------------------------------
@dataclass
class ScaledEnergies:
    """A source whose zones' energies are the wrapped source's times ``factor(op)``."""

    inner: object
    factor: Callable

    def zones(self, op):
        f = float(self.factor(op))
        return [replace(z, energy_edges_J=z.energy_edges_J * f) for z in self.inner.zones(op)]


@dataclass
class DroppedZones:
    """A source without the collisions of the zones named in ``drop`` (their rate 0)."""

    inner: object
    drop: tuple

    def zones(self, op):
        return [replace(z, collision_rate_per_m3_s=0.0) if z.name in self.drop else z
                for z in self.inner.zones(op)]


@dataclass
class LubricatedApproach:
    """(g) Wet collisions: a source whose collisions lose the energy the liquid film takes
    as two beads close the gap down to the captured particle (size x).

    Rigid spheres under the lubrication force 6 pi mu R*^2 v / h slow down as
    v(h) = v0 (1 - ln(h0 / h) / St), St = m* v0 / (6 pi mu R*^2) = 2 rho_GM d_GM v0 / (9 mu)
    for two equal beads (reduced mass m* = m_GM / 2, reduced radius R* = d_GM / 4); Davis,
    Serayssol and Hinch (1986, J. Fluid Mech. 163:479) and Barnocky and Davis (1988, Phys.
    Fluids 31:1324). The film starts at h0 = R* and the particle is met at h = x, so a
    collision of energy E = 1/2 m_GM v0^2 (seed 001 eq. 1) reaches the particle with
    E (1 - ln(R*/x) / St)^2, and not at all for St <= ln(R*/x). Restitution from the same
    law, e/e_dry = (1 - St_c/St) - St_c/(e_dry St), has no rebound below St_c, about 10 in
    the experiments of Joseph et al. (2001, J. Fluid Mech. 433:329) and Gondret et al.
    (2002, Phys. Fluids 14:643)."""

    inner: object
    x_m: float

    def zones(self, op):
        mu, d, rho = op.eta_susp_Pa_s, op.d_gb_m, op.rho_gb_kg_per_m3
        m_gb = rho * math.pi / 6.0 * d ** 3
        st_c = math.log(max(0.25 * d / self.x_m, 1.0))
        out = []
        for z in self.inner.zones(op):
            e = z.energy_edges_J
            st = 2.0 * rho * d * np.sqrt(2.0 * e / m_gb) / (9.0 * mu)
            moved = e * np.clip(1.0 - st_c / st, 0.0, None) ** 2
            # a bin whose upper edge reaches no particle is lost; one that straddles the
            # threshold keeps half its weight
            keep = np.where(moved[1:] <= 0.0, 0.0, np.where(moved[:-1] > 0.0, 1.0, 0.5))
            w = z.energy_weights * keep
            if w.sum() <= 0.0:
                out.append(replace(z, collision_rate_per_m3_s=0.0))
                continue
            edges = np.maximum(moved, e[0] * 1e-30)
            edges = np.maximum.accumulate(edges * (1.0 + 1e-12 * np.arange(edges.size)))
            out.append(Zone(z.name, z.volume_fraction, z.collision_rate_per_m3_s * w.sum(), edges, w / w.sum()))
        return out


def similarity_source(src):
    """The table source without its one-at-a-time side tables: bead diameter and density
    by similarity alone (energies over E_ref = pi/12 d^3 rho v_t^2 and collision
    frequencies over omega n_gb held at the grid's values)."""
    t = src.table
    bare = replace(t, one_at_a_time={}, one_at_a_time_ref={}, anchor={}, one_at_a_time_anchor={})
    return replace(src, table=bare,
                   similar_axes=tuple(src.similar_axes) + ("bead_diameter_m", "bead_density_kg_per_m3"),
                   last_lookup=None, last_notes=[], similarity_seen={})


# ---- the pairs ------------------------------------------------------------------------------
@dataclass
class PairSetup:
    name: str
    simple: MillModel
    detailed: MillModel
    op_simple: object  # the simple scene's operating point (what millfmu rates uses)
    op_detailed: object  # the detailed scene's own
    x: np.ndarray  # size(s) of the quantity [m]
    w_feed: np.ndarray | None  # cells: the feed's mass fractions (disruption rate)
    constant: str  # the detailed model's refitted material field


def setups() -> list:
    out = []
    for pair in cal.SHIPPED:
        s_scene, d_scene = pair.scenes()
        sm = MillModel(cal.with_model(s_scene, "simple"))
        dm = MillModel(cal.with_model(d_scene, "detailed"))
        cells = s_scene.material.model == "yeast"
        w = psd_fractions(sm.grid, s_scene.feed)
        out.append(PairSetup(pair.material, sm, dm, sm.operating_point(sm.inputs), dm.operating_point(dm.inputs),
                             np.array([5e-6 if cells else 10e-6]), w if cells else None,
                             "burst_median_J" if cells else "f_mat_kg_per_J_m"))
    return out


def rate(model, material, source, op, ps: PairSetup) -> float:
    """The quantity of ``millfmu rates``: cells, the feed's disruption rate; minerals, S(10 um) [1/s]."""
    name = "detailed" if source is not None else "simple"
    if ps.w_feed is not None:
        s = krates.selection_per_s(name, material, op, model.operator.nodes_m, None, source)
        return float(ps.w_feed @ model.operator.class_rates(s))
    return float(krates.selection_per_s(name, material, op, ps.x, None, source)[0])


def mean_p_break(material, source, op, x) -> float:
    """Collision-weighted mean breakage probability of one stress at size x [-]."""
    num = den = 0.0
    for z in source.zones(op):
        c = z.volume_fraction * z.collision_rate_per_m3_s
        if c <= 0.0:
            continue
        p = material.breakage_probability(np.array([x])[..., None],
                                          z.energy_J * op.energy_transfer * op.elasticity_factor)
        num += c * float((p @ z.energy_weights)[0])
        den += c
    return num / den


def at(op, field, value, bead_y=False):
    op2 = replace(op, **{field: value})
    if bead_y and field == "rho_gb_kg_per_m3":
        op2 = replace(op2, y_gb_Pa=Y_ZIRCONIA_PA)
    return op2


@dataclass
class Variant:
    key: str
    label: str
    source: Callable = lambda src, ps: src  # (source, pair) -> source
    op: Callable = lambda ps: ps.op_detailed  # pair -> reference operating point
    refit: bool = True
    material: Callable = lambda mat, ps: mat  # (material, pair) -> material before any refit
    bead_y: bool = False  # bead density axis also changes the beads' Young's modulus (zirconia)


def _ef(op):
    return op.elasticity_factor


VARIANTS = (
    Variant("simple_op", "detailed with the simple scene's constants (eta_E 0.0302 for yeast)",
            op=lambda ps: ps.op_simple,
            refit=False),
    Variant("shipped", "detailed as shipped (own scene's eta_E)", refit=False),
    Variant("sourced", "yeast at the sourced burst energy 2.8e-10 J (no refit)", refit=False,
            material=lambda m, ps: replace(m, burst_median_J=2.8e-10) if ps.w_feed is not None else m),
    Variant("a_mGM", "(a) SE = 1/2 m_GM v_rel^2 (bead mass, seed 001 eq. 1): energies x 2",
            source=lambda s, ps: ScaledEnergies(s, lambda op: 2.0)),
    Variant("a_mGM_src", "(a) m_GM, yeast at 2.8e-10 J (no refit)", refit=False,
            source=lambda s, ps: ScaledEnergies(s, lambda op: 2.0),
            material=lambda m, ps: replace(m, burst_median_J=2.8e-10) if ps.w_feed is not None else m),
    Variant("a_tn", "(a) normal part SE_tn only", source=lambda s, ps: replace(s, component="tn")),
    Variant("a_total", "(a) whole collision SE_total", source=lambda s, ps: replace(s, component="total")),
    Variant("b_none", "(b) elasticity factor not applied in the detailed model",
            source=lambda s, ps: ScaledEnergies(s, lambda op: 1.0 / _ef(op))),
    Variant("b_twice", "(b) elasticity factor applied twice",
            source=lambda s, ps: ScaledEnergies(s, _ef)),
    Variant("b_ZrO2", "(b) 6040 kg/m3 beads with zirconia's Y_GM (210 GPa)", refit=False, bead_y=True),
    Variant("c_share", "(c) capture per DEM contact s = k_c / sum_z f_z c_z(ref) (the DEM's contacts per "
            "omega n_gb counted as Kwade's k_c stressing events; s the same at every point)",
            source=lambda s, ps: _captured_share(s, ps)),
    Variant("d_noV4", "(d) V4's collisions dropped (seed 001: V4's stress energy ~0)",
            source=lambda s, ps: DroppedZones(s, ("V4",))),
    Variant("d_noV1V4", "(d) V1's and V4's collisions dropped", source=lambda s, ps: DroppedZones(s, ("V1", "V4"))),
    Variant("e_similar", "(e) bead d and rho by similarity (no one-at-a-time side tables)",
            source=lambda s, ps: similarity_source(s)),
    Variant("g_wet", "(g) wet collisions: the energy left when the beads meet the particle after the lubrication "
            "film (Davis et al. 1986), none below St = ln(d/(4x))",
            source=lambda s, ps: LubricatedApproach(s, float(ps.x[0]))),
    Variant("kwade_E", "(f) energies at Kwade's SE scaling: each zone's distribution x SE(op)/SE(ref) (d^3 rho v_t^2)",
            source=lambda s, ps: _kwade_scaled(s, ps)),
)


@dataclass
class ScaledRates:
    """A source whose zones' collision rates are the wrapped source's times ``share``."""

    inner: object
    share: float

    def zones(self, op):
        return [replace(z, collision_rate_per_m3_s=z.collision_rate_per_m3_s * self.share)
                for z in self.inner.zones(op)]


def dem_collisions_per_omega_ngb(src, op) -> float:
    """The source's collisions per chamber volume over omega n_gb, sum_z f_z c_z [-]."""
    return chamber_collision_rate_per_m3_s(src, op) / (op.omega_rad_per_s * op.n_gb_per_m3)


def _captured_share(src, ps):
    ref = ps.op_detailed
    return ScaledRates(src, ps.op_simple.k_c / dem_collisions_per_omega_ngb(src, ref))


def _kwade_scaled(src, ps):
    """The reference point's distributions, moved with Kwade's SE ~ d^3 rho v_t^2 (the
    collision rates stay the table's at each point)."""
    ref = ps.op_detailed
    base = {z.name: z for z in src.zones(ref)}

    class _S:
        def zones(self, op):
            f = op.se_beads_J / ref.se_beads_J
            return [Zone(z.name, z.volume_fraction, z.collision_rate_per_m3_s, base[z.name].energy_edges_J * f,
                         base[z.name].energy_weights) for z in src.zones(op)]
    return _S()


def _refit(ps, material, source, op, target) -> tuple:
    """The material constant for which the detailed reference rate equals ``target``."""
    def f(lg):
        m = replace(material, **{ps.constant: 10.0 ** lg})
        return math.log(rate(ps.detailed, m, source, op, ps) / target)
    c0 = math.log10(getattr(material, ps.constant))
    lo, hi = c0 - 4.0, c0 + 4.0
    try:
        lg = brentq(f, lo, hi, xtol=1e-6)
    except ValueError:
        return material, math.nan
    return replace(material, **{ps.constant: 10.0 ** lg}), 10.0 ** lg


def trend_rows(ps: PairSetup) -> dict:
    """variant key -> dict(rel=[...], constant, p_ref, p_06, p_12); plus 'simple'."""
    rows = {}
    sm, dm = ps.simple, ps.detailed
    s_ref = rate(sm, sm.material, None, ps.op_simple, ps)
    rows["simple"] = {"rel": [rate(sm, sm.material, None, at(ps.op_simple, f, v), ps) / s_ref for _, f, v, _ in POINTS],
                          "constant": math.nan, "ref_rate": s_ref}
    d_ref_shipped = rate(dm, dm.material, dm.source, ps.op_detailed, ps)
    target = s_ref if ps.w_feed is not None else d_ref_shipped
    for v in VARIANTS:
        op0 = v.op(ps)
        src = v.source(dm.source, ps)
        mat = v.material(dm.material, ps)
        const = getattr(mat, ps.constant)
        if v.refit:
            mat, const = _refit(ps, mat, src, op0, target)
        ref = rate(dm, mat, src, op0, ps)
        rel = [rate(dm, mat, src, at(op0, f, val, v.bead_y), ps) / ref for _, f, val, _ in POINTS]
        pb = [mean_p_break(mat, src, replace(op0, d_gb_m=d), ps.x[0]) for d in (0.6e-3, 0.8e-3, 1.2e-3)]
        rows[v.key] = {"rel": rel, "constant": const, "ref_rate": ref, "p": pb}
    return rows


def in_line(rel, simple) -> float:
    """Largest factor between the detailed and the simple model's changes over the points."""
    return max(math.exp(abs(math.log(a / b))) for a, b in zip(rel, simple))


def p_cap_table(ps: PairSetup) -> list:
    out = []
    for _, f, val, lab in (("ref", "d_gb_m", ps.op_simple.d_gb_m, "ref"),) + POINTS:
        op = replace(ps.op_simple, **{f: val})
        npv = op.class_number_concentration_per_m3(ps.x) * kstress.active_volume_m3(ps.x, op.d_gb_m)
        out.append((lab, float(npv[0])))
    return out


def frequency_and_power(ps: PairSetup) -> list:
    """(label, collision frequency, collision power) of the shipped detailed source at each
    point over its value at the reference [-]: sum_z v_z f_z and sum_z v_z f_z <E>_z (v the
    zone's volume share, f its collision rate, <E> its mean collision energy). Where the
    breakage probability per stress is small the detailed rate follows the power; where it
    is near 1, the frequency."""
    src = ps.detailed.source

    def sums(op):
        zs = src.zones(op)
        return (sum(z.volume_fraction * z.collision_rate_per_m3_s for z in zs),
                sum(z.volume_fraction * z.collision_rate_per_m3_s * float(z.energy_J @ z.energy_weights) for z in zs))

    f0, p0 = sums(ps.op_detailed)
    out = []
    for _, fld, val, lab in POINTS:
        f, p = sums(at(ps.op_detailed, fld, val))
        out.append((lab, f / f0, p / p0))
    return out


def energies_table(ps: PairSetup) -> list:
    """(d [m], SE [J], SE_P [J], per zone median SE_tn and SE_total [J], collision-weighted medians [J])."""
    src = ps.detailed.source
    rows = []
    for d in (0.6e-3, 0.8e-3, 1.2e-3):
        op = replace(ps.op_detailed, d_gb_m=d)
        rec = {"d": d, "se": op.se_beads_J, "se_p": op.se_product_J}
        for comp in ("tn", "total"):
            zs = replace(src, component=comp).zones(op)
            rec[comp] = {z.name: z.median_energy_J for z in zs}
            # the collision-weighted median over all zones
            e = np.concatenate([z.energy_J for z in zs])
            w = np.concatenate([z.energy_weights * z.volume_fraction * z.collision_rate_per_m3_s for z in zs])
            o = np.argsort(e)
            c = np.cumsum(w[o]) / w.sum()
            rec[comp + "_all"] = float(e[o][np.searchsorted(c, 0.5)])
        rows.append(rec)
    return rows


def main(argv=None) -> int:
    """``python -m validation.trends_causes``: print the tables (no options)."""
    ap = argparse.ArgumentParser(prog="python -m validation.trends_causes",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--markdown", action="store_true", help="instead: the table of both pairs' "
                    "rates along each parameter with the detailed model's band, as "
                    "docs/rates-and-calibration.md shows it")
    if ap.parse_args(argv).markdown:
        print(markdown_trend_table())
        return 0
    heads = [lab for *_, lab in POINTS]
    for ps in setups():
        rows = trend_rows(ps)
        simple = rows["simple"]["rel"]
        print(f"\n=== {ps.name}: rate relative to the reference "
              f"(v_t {ps.op_simple.tip_speed_m_per_s:g} m/s, filling {ps.op_simple.filling:g}, "
              f"d {ps.op_simple.d_gb_m * 1e3:g} mm, rho {ps.op_simple.rho_gb_kg_per_m3:g}); quantity "
              f"{'disruption rate' if ps.w_feed is not None else 'S(10 um)'}; 'worst' is the largest factor "
              f"between detailed and simple over the points (in line: <= {IN_LINE_FACTOR})")
        cname = "burst E50 [J]" if ps.w_feed is not None else "f_Mat [kg/(J m)]"
        print(f"{'variant':10s} " + " ".join(f"{h:>9s}" for h in heads) +
              f" {'worst':>6s} {cname:>16s} {'P@0.6':>6s} {'P@0.8':>6s} {'P@1.2':>6s}")
        print(f"{'simple':10s} " + " ".join(f"{r:9.3f}" for r in simple))
        for v in VARIANTS:
            r = rows[v.key]
            c = r["constant"]
            flag = ""
            if v.refit and not math.isfinite(c):
                flag = " nofit"
            elif ps.w_feed is not None and math.isfinite(c):
                flag = " in" if BURST_SOURCED_J[0] <= c <= BURST_SOURCED_J[1] else " out"
            print(f"{v.key:10s} " + " ".join(f"{x:9.3f}" for x in r["rel"]) +
                  f" {in_line(r['rel'], simple):6.2f} {c:12.3g}{flag:6s} " +
                  " ".join(f"{p:6.3f}" for p in r["p"]))
        print("'nofit': the reference rate is out of reach (P_break <= 1), the constant is left as shipped; "
              "a constant decades from the shipped one means the fit ran the breakage probability into saturation")
        print("variants:")
        for v in VARIANTS:
            print(f"  {v.key:10s} {v.label}" + ("; material constant refitted at the reference" if v.refit else ""))
        print(f"collisions: DEM sum_z f_z c_z = {dem_collisions_per_omega_ngb(ps.detailed.source, ps.op_detailed):.3g} "
              f"omega n_gb at the reference, Kwade's fitted k_c = {ps.op_simple.k_c:g}; reference rates [1/s]: simple "
              f"{rows['simple']['ref_rate']:.4g}, detailed shipped {rows['shipped']['ref_rate']:.4g}, with the simple "
              f"scene's constants {rows['simple_op']['ref_rate']:.4g}")
        fp = frequency_and_power(ps)
        print("the table's collisions over the reference: frequency " +
              ", ".join(f"{lab} {f:.3g}" for lab, f, _ in fp) + "; power " +
              ", ".join(f"{lab} {p:.3g}" for lab, _, p in fp))
        print("capture: n_p V_act (P_cap = min(1, .)) at " +
              ", ".join(f"{lab} {val:.3g}" for lab, val in p_cap_table(ps)))
        print("energies at the detailed reference point along the bead diameter [J]:")
        for rec in energies_table(ps):
            print(f"  d {rec['d'] * 1e3:.1f} mm: SE {rec['se']:.3g}, SE_P {rec['se_p']:.3g}; median SE_tn "
                  + ", ".join(f"{k} {v:.2g}" for k, v in rec["tn"].items())
                  + f" (all {rec['tn_all']:.2g} = {rec['tn_all'] / rec['se']:.2g} SE); median SE_total "
                  + ", ".join(f"{k} {v:.2g}" for k, v in rec["total"].items())
                  + f" (all {rec['total_all']:.2g} = {rec['total_all'] / rec['se']:.2g} SE)")
    return 0


def markdown_trend_table() -> str:
    """The docs' table of ``millfmu rates`` for both shipped pairs
    (:func:`millfmu.rates.trend_table`) in Markdown."""
    from millfmu import rates as mrates

    head, rows = mrates.trend_table()
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])

if __name__ == "__main__":
    sys.exit(main())
