"""``millfmu rates``: breakage rates of the simple and the detailed model against each
operating parameter, relative to a reference point (seed 000).

For a scene, whose operating point is the reference, the specific breakage rate S(x) at a
few sizes and, for cells, the initial disruption rate (the feed's mass-weighted S) of
Kwade's simple model and of the detailed model side by side, as each operating parameter
(tip speed, bead diameter, bead density, solids mass fraction, bead filling) moves away
from the reference with the others held. Each model keeps its own fitted constant
(``mill.stress_frequency_factor``, ``kinetics.energy_transfer``; :mod:`millfmu.calibration`),
so the curves are the models' predictions of the variations.

Along the detailed model's stress-energy source, each point says what it rests on:

- a DEM table along an axis it varies (tip speed, filling): interpolated on its grid
  (outside it only where the scene names the axis in ``similar_axes``; else the point is
  refused and left empty, never extrapolated silently);
- a DEM table along an axis it does not vary (bead diameter and density of the default
  table): the table's similarity scaling, energies over E_ref = pi/12 d^3 rho v_t^2 and
  collision frequencies over omega n_gb held at the table's values ("table, similarity
  assumed"), whose error docs/rates-and-calibration.md measures (bead density: energies within 10 %,
  frequencies 21-31 % lower at 6040 kg/m3; bead diameter 1.2 mm: energies 1.1-1.8 times,
  frequencies 0.65-1.13 times);
- the solids mass fraction is not a table axis: the DEM has no product particles, so only
  the capture probability and the particle number concentration change, as in the simple
  model;
- the log-normal source scales with SE and omega n_gb by construction.

Outputs per scene: ``rates_NAME.csv`` (one row per parameter value, model and quantity),
``rates_NAME.json`` (reference point, constants, sizes, sources) and ``rates_NAME.png``
(one panel per parameter). Without a scene, the shipped calibrated pairs of seed 000's
two materials (yeast cells, limestone) and their calibration (``calibration.csv``).

The text and the plot state each model's rate at the reference point [1/s]. Where one of
them is negligible (less than 1 % of a size class broken in the scene's run,
:data:`NEGLIGIBLE_FRACTION`), ratios to it would read 1e-10 or 1e9 for changes between no
breakage and next to none; then both show the rates themselves [1/s], the plot with the
negligible ones shaded, and say which reference is negligible and why.

(:mod:`millfmu.kinetics.rates` holds the rate formulas; this module only evaluates them.)
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
import stat
import sys
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .kinetics.rates import ENERGY_LIMITED_P
from .kinetics.stress_distribution import chamber_collision_rate_per_m3_s

#: Operating parameters: name -> (label, unit, scene section, scene key, OperatingPoint field,
#: stress-energy table axis or None).
PARAMETERS = {
    "tip_speed": ("tip speed", "m/s", "mill", "tip_speed_m_per_s", "tip_speed_m_per_s", "tip_speed_m_per_s"),
    "bead_diameter": ("bead diameter", "m", "beads", "diameter_m", "d_gb_m", "bead_diameter_m"),
    "bead_density": ("bead density", "kg/m3", "beads", "density_kg_per_m3", "rho_gb_kg_per_m3",
                     "bead_density_kg_per_m3"),
    "solids_mass_fraction": ("solids mass fraction", "-", "suspension", "solids_mass_fraction", "solids_mass_fraction",
                             None),
    "filling": ("bead filling", "-", "mill", "bead_filling", "filling", "filling"),
}
#: Default values of the variations around the reference (the reference value is added):
#: the shipped table's grid for tip speed and filling; bead sizes of lab disc mills; glass
#: (seed 001) to zirconia (seed 002); half to twice the reference's solids content.
DEFAULT_VALUES = {
    "tip_speed": (6.0, 8.0, 10.0, 12.0, 14.0),
    "bead_diameter": (0.4e-3, 0.6e-3, 0.8e-3, 1.0e-3, 1.2e-3),
    "bead_density": (2510.0, 4000.0, 6040.0),
    "solids_mass_fraction": None,  # reference x (0.5, 1, 1.5, 2)
    "filling": (0.5, 0.6, 0.7, 0.8, 0.9),
}
SOLIDS_FACTORS = (0.5, 1.0, 1.5, 2.0)
#: A rate S [1/s] is negligible where it breaks less than this fraction of a size class in
#: the scene's run (S t_end below it; first order: 1 - exp(-S t) ~ S t). A rate over such a
#: reference reads 1e-10 or 1e9 for changes between no breakage and next to none, so where a
#: reference rate is negligible the output gives the rates themselves instead of ratios.
NEGLIGIBLE_FRACTION = 0.01
MODELS = ("simple", "detailed")
#: ``value`` is in ``value_unit`` (the parameter's unit: m/s, m, kg/m3, 1); every other
#: column names its unit (``_m``, ``_per_s``, ``_J``) or is dimensionless (``_over_ref``, p_*).
CSV_COLUMNS = ("scene", "material", "parameter", "value", "value_unit", "value_over_ref", "model", "source", "quantity",
               "x_m", "rate_per_s", "rate_over_ref", "sf_per_s", "sf_over_ref", "p_break", "p_cap", "se_J",
               "se_over_ref", "se_product_J", "rate_band_low_per_s", "rate_band_high_per_s", "note")


@dataclass
class Curve:
    """Rates of one model along one parameter: ``values`` [parameter unit], per quantity
    ``rate`` [1/s] and ``sf`` [1/s] arrays (quantity: 'S(x)' at each size, or
    'disruption_rate'), ``sources`` and ``notes`` per value."""

    parameter: str
    model: str
    values: np.ndarray
    rates: dict
    sf: dict
    p_cap: dict
    se_J: np.ndarray
    se_product_J: np.ndarray
    sources: list
    notes: list
    #: Detailed model on a table: per quantity (lower, upper) rates [1/s] with every zone's
    #: collision frequency and median energy at the edges of the table's stated error
    #: (:func:`millfmu.runner.prediction_band`); empty otherwise.
    band: dict = field(default_factory=dict)


@dataclass
class RatesResult:
    """Everything ``millfmu rates`` computes for one scene."""

    name: str
    scene: object
    reference: dict
    sizes_m: tuple
    quantities: tuple
    curves: dict  # (parameter, model) -> Curve
    constants: dict
    source_description: dict
    #: The scene's run time [s], which sets :attr:`negligible_rate_per_s`.
    run_s: float = math.nan
    #: Whether the detailed model ran on its own scene (a calibrated pair's material
    #: constants) rather than on ``scene``'s.
    detailed_own_scene: bool = False

    @property
    def negligible_rate_per_s(self) -> float:
        """Below this rate [1/s] less than :data:`NEGLIGIBLE_FRACTION` of a size class
        breaks in the scene's run."""
        return NEGLIGIBLE_FRACTION / self.run_s

    def curve(self, parameter: str, model: str) -> Curve:
        return self.curves[(parameter, model)]

    def reference_rate(self, model: str, quantity: str) -> float:
        """The model's rate at the reference point [1/s] (the same point on every
        parameter's curve)."""
        p = next(iter(PARAMETERS))
        return float(self.curve(p, model).rates[quantity][self.reference_index(p)])

    def negligible_references(self) -> list:
        """(model, quantity, rate [1/s]) of every reference rate below
        :attr:`negligible_rate_per_s`."""
        out = []
        for m in MODELS:
            for q in self.quantities:
                r = self.reference_rate(m, q)
                if not r >= self.negligible_rate_per_s:
                    out.append((m, q, r))
        return out

    @property
    def absolute(self) -> bool:
        """Whether the output shows rates [1/s] rather than ratios to the reference: where
        a reference rate is negligible, ratios to it say nothing a process engineer can use."""
        return bool(self.negligible_references())

    def why_absolute(self) -> str:
        """In words: which reference rates are negligible, why, and what a ratio to them
        would read ('' where none is)."""
        neg = self.negligible_references()
        if not neg:
            return ""
        first = next(iter(PARAMETERS))
        sf = [self.curve(first, m).sf[q][self.reference_index(first)] for m, q, _ in neg]
        p = [r / f for (_, _, r), f in zip(neg, sf) if f > 0.0]
        models = [m for m in MODELS if any(n[0] == m for n in neg)]
        which = "; ".join(f"{m}: " + ", ".join(f"{_qlabel(q)} {r:.2g}" for n, q, r in neg if n == m) for m in models)
        txt = (f"the reference rates of the {' and the '.join(models)} model{'s' if len(models) > 1 else ''} are "
               f"negligible ({which} 1/s; below {self.negligible_rate_per_s:.2g} 1/s, under "
               f"{100 * NEGLIGIBLE_FRACTION:g} % of a size class broken in the scene's {self.run_s:g} s")
        if p:
            txt += (f"; breakage probability per stress at most {max(p):.1g}: the stresses hardly ever exceed "
                    "the material's breakage energy at these sizes")
        txt += ")."
        if not self.detailed_own_scene and self.scene.kinetics.model == "simple" and "detailed" in models:
            txt += (" The detailed model runs on this scene's material constants, set for the simple model; the "
                    "calibrated pairs (millfmu rates without a scene) give each model its own.")
        ratios = [v for q_ in PARAMETERS for m, q, _ in neg for v in self.relative(q_, m, q)]
        ratios = np.array([v for v in ratios if math.isfinite(v) and v > 0.0])
        if ratios.size and ratios.max() / ratios.min() > 1e3:
            txt += f" Ratios to these rates would run from {ratios.min():.0e} to {ratios.max():.0e}."
        return txt + " So the rates themselves are shown [1/s]."

    def reference_index(self, parameter: str) -> int:
        v = self.curves[(parameter, "simple")].values
        return int(np.argmin(np.abs(v - self.reference[parameter])))

    def relative(self, parameter: str, model: str, quantity: str) -> np.ndarray:
        """Rate over the same model's rate at the reference point [-] (NaN where refused or
        where the reference rate is zero)."""
        c = self.curve(parameter, model)
        r = c.rates[quantity]
        ref = r[self.reference_index(parameter)]
        with np.errstate(divide="ignore", invalid="ignore"):
            return r / ref if ref > 0.0 else np.full_like(r, math.nan)

    def p_break_at_reference(self) -> dict:
        """The detailed model's mean breakage probability per stress at the reference point
        [-], rate over stress frequency, per quantity (NaN without stresses)."""
        p = next(iter(PARAMETERS))
        c, i = self.curve(p, "detailed"), self.reference_index(p)
        return {q: float(c.rates[q][i] / c.sf[q][i]) if c.sf[q][i] > 0 else math.nan for q in self.quantities}

    def regime_note(self) -> str:
        """In words, where the detailed model's breakage probability per stress at the
        reference lies below :data:`ENERGY_LIMITED_P` (its trends then follow the collision
        power); '' where it does not."""
        low = {q: v for q, v in self.p_break_at_reference().items() if v < ENERGY_LIMITED_P}
        if not low:
            return ""
        which = ", ".join(f"{_qlabel(q)} {v:.2g}" for q, v in low.items())
        return (f"detailed model energy-limited: breakage probability per stress at the reference {which} "
                f"(below {ENERGY_LIMITED_P:g}); most collisions lie on the foot of the material's breakage "
                "curve, so its rate follows the collision power, not the collision frequency, and its trends along "
                "bead diameter and density leave the simple model's, whose captured stresses all break. Seed 000's "
                "measurements follow the simple model's trends; trust the detailed model's where this probability "
                "is near 1.")

    def band_relative(self, parameter: str, quantity: str) -> tuple:
        """The detailed model's band (lower, upper) over its rate at the reference point [-],
        or () without a band or a reference rate."""
        c = self.curve(parameter, "detailed")
        ref = c.rates[quantity][self.reference_index(parameter)]
        if quantity not in c.band or not ref > 0.0:
            return ()
        return tuple(b / ref for b in c.band[quantity])

    def rows(self):
        """CSV rows (dicts keyed by :data:`CSV_COLUMNS`)."""
        material = self.scene.material.model
        for (p, model), c in self.curves.items():
            unit = PARAMETERS[p][1]
            i_ref = self.reference_index(p)
            for q in self.quantities:
                rel = self.relative(p, model, q)
                sf = c.sf[q]
                for k, v in enumerate(c.values):
                    rate = c.rates[q][k]
                    yield {
                        "scene": self.name, "material": material, "parameter": p, "value_unit": unit,
                        "value": _g(v), "value_over_ref": _g(v / self.reference[p]), "model": model,
                        "source": c.sources[k], "quantity": "disruption_rate" if q == "disruption_rate" else "S(x)",
                        "x_m": "" if q == "disruption_rate" else _g(float(q.split("=")[1])),
                        "rate_per_s": _g(rate), "rate_over_ref": _g(rel[k]),
                        "sf_per_s": _g(sf[k]), "sf_over_ref": _g(sf[k] / sf[i_ref] if sf[i_ref] > 0 else math.nan),
                        "p_break": _g(rate / sf[k] if sf[k] > 0 else math.nan),
                        "p_cap": _g(c.p_cap[q][k]) if q in c.p_cap else "",
                        "se_J": _g(c.se_J[k]), "se_over_ref": _g(c.se_J[k] / c.se_J[i_ref]),
                        "se_product_J": _g(c.se_product_J[k]),
                        "rate_band_low_per_s": _g(c.band[q][0][k]) if q in c.band else "",
                        "rate_band_high_per_s": _g(c.band[q][1][k]) if q in c.band else "",
                        "note": c.notes[k],
                    }


def shipped_pairs() -> tuple:
    """The yeast and the limestone :class:`RatesResult` of the shipped calibrated pairs, each
    model with its own scene's constants."""
    from .calibration import SHIPPED

    (ys, yd), (ls, ld) = (p.scenes() for p in SHIPPED)
    return compute(ys, "yeast", detailed_scene=yd), compute(ls, "limestone", detailed_scene=ld)


def trend_table(pairs=None) -> tuple[list, list]:
    """(header, rows) of both shipped calibrated pairs' rates along each parameter, each
    model's over its rate at the reference point [-], the detailed model's band in brackets:
    yeast the disruption rate, limestone S at the feed's x50 and x90. ``pairs``: the yeast
    and the limestone :class:`RatesResult` (computed when None). What docs/rates-and-
    calibration.md and the report show."""
    y, lime = shipped_pairs() if pairs is None else pairs
    sizes = list(lime.quantities)
    cols = [(y, "disruption_rate")] + [(lime, q) for q in sizes[1:]]

    def cell(r, p, m, q, k):
        v = r.relative(p, m, q)[k]
        star = "*" if k == r.reference_index(p) else ""
        if not math.isfinite(v):
            return "refused"
        txt = f"{v:.3g}{star}"
        band = r.band_relative(p, q) if m == "detailed" else ()
        if band and not star and all(math.isfinite(b[k]) for b in band):
            txt += f" ({band[0][k]:.3g}-{band[1][k]:.3g})"
        return txt

    # rates over the reference: dimensionless; a value is in its parameter's unit
    head = ["parameter", "value [parameter's unit]", "yeast simple [-]", "yeast detailed [-]"] + \
        [f"limestone {float(q.split('=')[1]) * 1e6:.3g} um {m} [-]" for q in sizes[1:] for m in MODELS]
    rows = []
    for p, (label, unit, *_rest) in PARAMETERS.items():
        vals = lime.curve(p, "simple").values
        for k, v in enumerate(vals):
            value = ("half", "ref", "1.5 x", "2 x")[k] if p == "solids_mass_fraction" else \
                f"{v * 1e3:g}" if p == "bead_diameter" else f"{v:g}"
            row = [f"{label} [{'mm' if p == 'bead_diameter' else unit}]" if k == 0 else "", value]
            for r, q in cols:
                has = k < len(r.curve(p, "simple").values)
                row += [cell(r, p, m, q, k) if has else "" for m in MODELS]
            rows.append(row)
    return head, rows


def _g(v) -> str:
    v = float(v)
    return "" if math.isnan(v) else f"{v:.10g}"


# ---- evaluation ----------------------------------------------------------------------------
def _size_key(x: float) -> str:
    return f"S(x)={x!r}"


@dataclass(frozen=True)
class _Coverage:
    """How the detailed model's stress-energy source covers one parameter: ``kind`` is
    'lognormal', 'gridded' (a table axis with a grid from ``lo`` to ``hi``), 'fixed' (the
    table holds the one value ``lo``), 'unstated' (a table axis its DEM scene does not
    state) or 'product' (not an axis of a table: the solids content); ``similar``: whether
    the model assumes similarity beyond what the table holds."""

    kind: str
    lo: float = math.nan
    hi: float = math.nan
    similar: bool = False

    def label(self, v: float) -> str:
        """The source of one point: 'lognormal', 'table' or 'table, similarity assumed'."""
        if self.kind == "lognormal":
            return "lognormal"
        inside = {"gridded": self.lo <= v <= self.hi,
                  "fixed": math.isclose(v, self.lo, rel_tol=1e-9),
                  "unstated": False, "product": True}[self.kind]
        return "table" if inside else "table, similarity assumed"


def _detailed_models(scene, MillModel):
    """Per parameter: the detailed model to evaluate it with (the scene's, or one whose table
    assumes similarity along an axis the table does not vary), how its source covers the
    parameter (:class:`_Coverage`) and that in words."""
    from .calibration import with_model

    det_scene = with_model(scene, "detailed")
    base = MillModel(det_scene)
    sd = scene.kinetics.stress_distribution
    table = getattr(base.source, "table", None)
    models, cover, desc = {}, {}, {}
    for p, (_label, _unit, _sec, _key, _field, tax) in PARAMETERS.items():
        models[p] = base
        if table is None:
            cover[p] = _Coverage("lognormal")
            desc[p] = (f"lognormal (median {sd.median_fraction:g} SE, sigma_ln {sd.sigma_ln:g}, collisions "
                       f"{sd.collision_factor:g} omega n_gb: Kwade's scaling by construction)")
            continue
        if tax is None:
            cover[p] = _Coverage("product")
            desc[p] = (f"DEM table {sd.table!r}; not an axis of a table: the DEM has no product particles, so only "
                       "the capture probability and the particle number change, as in the simple model")
            continue
        fixed = table.fixed_axis_values()
        if tax in table.axes and np.asarray(table.axes[tax]).size > 1:
            ax = np.asarray(table.axes[tax], dtype=float)
            cover[p] = _Coverage("gridded", float(ax[0]), float(ax[-1]), tax in sd.similar_axes)
            beyond = ("beyond it the edge's energies over E_ref and frequencies over omega n_gb (similarity, "
                      "the scene's similar_axes)") if tax in sd.similar_axes else "refused beyond it"
            desc[p] = f"DEM table {sd.table!r}, interpolated on its grid {ax[0]:g}-{ax[-1]:g}; {beyond}"
            continue
        oat = getattr(table, "one_at_a_time", {})
        if tax in oat:
            ax = table.one_at_a_time_values(tax)
            cover[p] = _Coverage("gridded", float(ax[0]), float(ax[-1]), tax in sd.similar_axes)
            beyond = "the edge's beyond it (similarity)" if tax in sd.similar_axes else "refused beyond it"
            sub = {a: v for a, v in oat[tax].axes.items() if a != tax}
            where = (f"across {', '.join(f'{a} ' + '/'.join(f'{x:g}' for x in v) for a, v in sub.items())}: "
                     f"its change interpolated there scales the grid's fields" if sub else
                     f"at {table.anchor}: its change there scales the grid's fields (separability assumed)")
            if tax in table.one_at_a_time_anchor:
                part = np.asarray(oat[tax].axes[tax], dtype=float)
                where = (f"(of which {part[0]:g}-{part[-1]:g} {where}; beyond {part[0]:g}-{part[-1]:g} at "
                         f"{table.anchor}: its change there scales the grid's fields, separability assumed)")
            desc[p] = f"DEM table {sd.table!r}, varied one at a time over {ax[0]:g}-{ax[-1]:g} {where}; {beyond}"
            continue
        value = float(np.asarray(table.axes[tax])[0]) if tax in table.axes else fixed.get(tax, math.nan)
        if tax not in sd.similar_axes:
            sim = replace(sd, similar_axes=list(sd.similar_axes) + [tax])
            models[p] = MillModel(replace(det_scene, kinetics=replace(det_scene.kinetics, stress_distribution=sim)))
        if math.isnan(value):
            cover[p] = _Coverage("unstated", similar=True)
            desc[p] = (f"DEM table {sd.table!r}, whose DEM scene does not state {tax}: similarity assumed "
                       "(energies over pi/12 d^3 rho v_t^2, collision frequencies over omega n_gb held)")
        else:
            cover[p] = _Coverage("fixed", value, value, similar=True)
            desc[p] = (f"DEM table {sd.table!r}, built at {tax} = {value:g} only: elsewhere similarity assumed "
                       "(energies over pi/12 d^3 rho v_t^2, collision frequencies over omega n_gb held)")
    return models, cover, desc


def _values(parameter: str, ref: float, given=None) -> np.ndarray:
    if given is not None:
        vals = list(given)
    elif parameter == "solids_mass_fraction":
        vals = [ref * f for f in SOLIDS_FACTORS]
    else:
        vals = list(DEFAULT_VALUES[parameter])
    vals.append(ref)
    out = []
    for v in sorted(vals):
        if not out or not math.isclose(v, out[-1], rel_tol=1e-12):
            out.append(v)
    # the reference exactly, not a near-duplicate of it
    return np.array([ref if math.isclose(v, ref, rel_tol=1e-12) else v for v in out], dtype=float)


def _default_sizes(scene, model) -> tuple:
    """Feed x10, x50, x90 [m] for a mineral; the feed's x50 for cells."""
    from .kinetics import grid as kgrid
    from .mill import psd_fractions

    w = psd_fractions(model.grid, scene.feed)
    qs = (0.5,) if scene.material.model == "yeast" else (0.1, 0.5, 0.9)
    return tuple(float(f"{x:.3g}") for x in kgrid.characteristic_sizes_m(model.grid, w, qs))


def _check_value(parameter, v, scene):
    from .scene import SceneError

    lo = {"tip_speed": 0.0, "bead_diameter": 1e-5, "bead_density": 500.0, "solids_mass_fraction": 0.0,
          "filling": 0.0}[parameter]
    hi = {"tip_speed": 40.0, "bead_diameter": 0.05, "bead_density": 20000.0, "solids_mass_fraction": 0.8,
          "filling": min(1.0, 0.64 / (1.0 - scene.mill.bead_porosity))}[parameter]
    if not (math.isfinite(v) and lo < v < hi):
        unit = PARAMETERS[parameter][1]
        raise SceneError(f"--values {parameter}", v,
                         f"must lie in ({lo:g}, {hi:g})" + ("" if unit == "-" else f" {unit}"), None)


def compute(scene, name: str | None = None, sizes_m=None, values: dict | None = None,
            detailed_scene=None) -> RatesResult:
    """Rates of both models along every parameter for ``scene`` (its operating point is the
    reference). ``sizes_m``: sizes of S(x) [m] (default: feed x10/x50/x90, cells: x50);
    ``values``: parameter -> values to use instead of :data:`DEFAULT_VALUES`;
    ``detailed_scene``: the detailed model's own scene at the same point (a calibrated pair
    whose material constants differ), else ``scene`` with the detailed model."""
    from .kinetics import stress as kstress
    from .mill import MillModel, psd_fractions
    from .scene import SceneError, did_you_mean

    if scene.material.model not in ("mineral", "yeast"):
        raise SceneError("material.model", scene.material.model,
                         "must be 'mineral' or 'yeast' for millfmu rates: 'austin' takes its rates from the scene, "
                         "without a stress model", scene.scene.name)
    from .calibration import with_model

    simple = MillModel(with_model(scene, "simple"))
    detailed_models, coverage, desc = _detailed_models(scene if detailed_scene is None else detailed_scene, MillModel)
    op_ref = simple.operating_point(simple.inputs)
    reference = {p: float(getattr(op_ref, PARAMETERS[p][4])) for p in PARAMETERS}
    sizes = tuple(float(x) for x in (sizes_m if sizes_m is not None else _default_sizes(scene, simple)))
    if not sizes or any(not (math.isfinite(x) and x > 0.0) for x in sizes):
        raise SceneError("--sizes", ",".join(f"{x:g}" for x in sizes), "must be positive sizes in m", None)
    from .calibration.measured import MAX_SIZE_M

    if max(sizes) > MAX_SIZE_M:
        x = max(sizes)
        raise SceneError("--sizes", sizes, f"must be sizes in m up to {MAX_SIZE_M:g} m, which no bead mill grinds "
                         f"beyond (if {x:g} is in micrometres, write {x * 1e-6:g})", None)
    lo, hi = simple.grid.edges_m[0], simple.grid.edges_m[-1]
    outside = [x for x in sizes if not lo <= x <= hi]
    if outside:
        # S(x) is the model's on its classes: a size beyond them has no rate of the model
        raise SceneError("--sizes", ",".join(f"{x:g}" for x in outside),
                         f"must lie on the size grid of scene {scene.scene.name!r}, [{lo:.4g}, {hi:.4g}] m (widen its "
                         "[grid] x_min_m, x_max_m)", None)
    is_cells = scene.material.model == "yeast"
    quantities = tuple(_size_key(x) for x in sizes) + (("disruption_rate",) if is_cells else ())
    x = np.array(sizes)
    values = values or {}
    for p, vs in values.items():
        if p not in PARAMETERS:
            # a scene key, an operating point's or a table axis's name of a parameter
            alias = next((q for q, (_, _, sec, key, op_f, tax) in PARAMETERS.items()
                          if p in (key, f"{sec}.{key}", op_f, tax)), None)
            hint = f" (did you mean {alias}?)" if alias else did_you_mean(p, PARAMETERS)
            raise SceneError("--values", p, "unknown parameter" + hint + "; allowed: "
                             + ", ".join(PARAMETERS), None)
        for v in vs:
            _check_value(p, v, scene)
    w_feed = psd_fractions(simple.grid, scene.feed)

    curves = {}
    for p, (_label, _unit, _sec, _key, op_field, _tax) in PARAMETERS.items():
        vals = _values(p, reference[p], values.get(p))
        for model_name in MODELS:
            m = simple if model_name == "simple" else detailed_models[p]
            src = m.source
            # Each model at the one operating point with its own constants (k_c, eta_E): the
            # detailed scene's energy transfer is not the simple scene's.
            own = m.operating_point(m.inputs)
            base = replace(op_ref, k_c=own.k_c, energy_transfer=own.energy_transfer)
            n = len(vals)
            rates_q = {q: np.full(n, math.nan) for q in quantities}
            sf_q = {q: np.full(n, math.nan) for q in quantities}
            pcap_q = {q: np.full(n, math.nan) for q in quantities if q != "disruption_rate"}
            se, sep = np.empty(n), np.empty(n)
            sources, notes, band_q = [], [], {}
            for k, v in enumerate(vals):
                op = replace(base, **{op_field: float(v)})
                se[k], sep[k] = op.se_beads_J, op.se_product_J
                label = ("Kwade: SE_P per stress, SF = k_c omega n_gb P_cap / (n_p (1 - c_v))" if model_name == "simple"
                         else coverage[p].label(float(v)))
                try:
                    rate = _rates_at(model_name, m, op, x, sizes, w_feed if is_cells else None)
                    coll = None if model_name == "simple" else chamber_collision_rate_per_m3_s(src, op)
                except ValueError as e:  # a table that refuses the point (outside its grid)
                    sources.append("refused")
                    notes.append(f"refused: {e}")
                    continue
                sf_x = op.stress_frequency_per_s(x, None, coll)
                p_cap = kstress.capture_probability(op.class_number_concentration_per_m3(x),
                                                    kstress.active_volume_m3(x, op.d_gb_m))
                for i, xs in enumerate(sizes):
                    q = _size_key(xs)
                    sf_q[q][k], pcap_q[q][k] = sf_x[i], p_cap[i]
                if is_cells:
                    sf_nodes = op.stress_frequency_per_s(m.operator.nodes_m, None, coll)
                    sf_q["disruption_rate"][k] = float(w_feed @ m.operator.class_rates(sf_nodes))
                for q, r in rate.items():
                    rates_q[q][k] = r
                sources.append(label)
                notes.append("; ".join(getattr(src, "last_notes", []) or []) if model_name == "detailed" else "")
                if model_name == "detailed" and hasattr(src, "error_multiple"):
                    # the band: every zone at the lower and the upper edge of its stated error
                    for j, sign in enumerate((-1.0, 1.0)):
                        src.error_multiple = sign
                        try:
                            edge = _rates_at(model_name, m, op, x, sizes, w_feed if is_cells else None)
                        finally:
                            src.error_multiple = 0.0
                        for q, r in edge.items():
                            band_q.setdefault(q, (np.full(n, math.nan), np.full(n, math.nan)))[j][k] = r
                    # a zone with collisions but no stated error (no check measured it there)
                    # would enter the edges unmoved: no band rather than a narrower one
                    unstated = src.unstated_zones()
                    if unstated:
                        for lo_hi in band_q.values():
                            lo_hi[0][k] = lo_hi[1][k] = math.nan
                        notes[-1] = "; ".join(filter(None, [notes[-1], (
                            f"no band: zones {', '.join(unstated)} have collisions but no stated error here "
                            f"(no check of the table measured them)")]))
            curves[(p, model_name)] = Curve(p, model_name, vals, rates_q, sf_q, pcap_q, se, sep, sources, notes, band_q)
    constants = {"k_c": scene.mill.stress_frequency_factor,
                 "energy_transfer": (detailed_scene or scene).kinetics.energy_transfer}
    return RatesResult(name or scene.scene.name, scene, reference, sizes, quantities, curves, constants, desc,
                       run_s=float(scene.run.t_end_s), detailed_own_scene=detailed_scene is not None)


def _rates_at(model_name, m, op, x, sizes, w_feed) -> dict:
    """The model's rate per quantity [1/s] at ``op`` with its source as it stands: S at each
    size of ``sizes`` (nodes ``x``), and with ``w_feed`` (cells) the feed's disruption rate."""
    from .kinetics import rates as krates

    s_x = krates.selection_per_s(model_name, m.material, op, x, None, m.source)
    out = {_size_key(xs): s_x[i] for i, xs in enumerate(sizes)}
    if w_feed is not None:
        s_nodes = krates.selection_per_s(model_name, m.material, op, m.operator.nodes_m, None, m.source)
        out["disruption_rate"] = float(w_feed @ m.operator.class_rates(s_nodes))
    return out


# ---- output ---------------------------------------------------------------------------------
def to_csv(result: RatesResult) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_COLUMNS, lineterminator="\n")
    w.writeheader()
    for row in result.rows():
        w.writerow(row)
    return buf.getvalue()


def to_json(result: RatesResult, calibration: dict | None = None) -> str:
    s = result.scene
    doc = {
        "scene": result.name,
        "material": s.material.model,
        "reference_point": {p: {"value": result.reference[p], "unit": PARAMETERS[p][1]} for p in PARAMETERS},
        "constants": {"simple: k_c (mill.stress_frequency_factor)": result.constants["k_c"],
                      "detailed: eta_E (kinetics.energy_transfer)": result.constants["energy_transfer"]},
        "sizes_m": list(result.sizes_m),
        "quantities": {"S(x)": "specific breakage rate at size x [1/s], P_cap from x's class concentration",
                       "disruption_rate": "initial disruption rate of the feed's cells, sum_i w_i S_i [1/s]"},
        "detailed_source": result.source_description,
        "values": {p: result.curve(p, "simple").values.tolist() for p in PARAMETERS},
        "reference_rates_per_s": {m: {_qlabel(q): result.reference_rate(m, q) for q in result.quantities}
                                  for m in MODELS},
        "negligible_rate_per_s": result.negligible_rate_per_s,
        "detailed_p_break_at_reference": {_qlabel(q): v for q, v in result.p_break_at_reference().items()},
        "detailed_regime": result.regime_note() or "frequency-limited: breakage probability per stress at the "
                           f"reference at least {ENERGY_LIMITED_P:g}",
        "shown": ("rates [1/s]: " + result.why_absolute()) if result.absolute else "rates over the reference rate [-]",
    }
    if calibration is not None:
        doc["calibration"] = calibration
    return json.dumps(doc, indent=1)


def _qlabel(q: str) -> str:
    if q == "disruption_rate":
        return "disruption rate"
    return f"S({float(q.split('=')[1]) * 1e6:.3g} um)"


def summary(result: RatesResult) -> str:
    """Text table: per parameter value, each model's rate relative to the reference, or the
    rates themselves [1/s] where a reference rate is negligible (:attr:`RatesResult.absolute`)."""
    qs = [q for q in result.quantities]
    refs = "; ".join(f"{_qlabel(q)}: simple {result.reference_rate('simple', q):.3g}, detailed "
                     f"{result.reference_rate('detailed', q):.3g}" for q in qs)
    lines = [f"{result.name} ({result.scene.material.model}): k_c = {result.constants['k_c']:g}, "
             f"eta_E = {result.constants['energy_transfer']:g}",
             f"rates at the reference point [1/s]: {refs}"]
    import textwrap

    if result.absolute:
        why = result.why_absolute()
        lines.append(textwrap.fill("Rates [1/s] below, not over the reference: " + why, 110))
    else:
        lines.append("rates over their value at the reference point [-] below")
    note = result.regime_note()
    if note:
        lines.append(textwrap.fill(note, 110))
    head = f"{'parameter':22s} {'value':>10s} " + " ".join(f"{_qlabel(q) + ' ' + m[:3]:>22s}" for q in qs
                                                           for m in MODELS)
    lines.append(head)
    for p in PARAMETERS:
        vals = result.curve(p, "simple").values
        rel = {(q, m): (result.curve(p, m).rates[q] if result.absolute else result.relative(p, m, q))
               for q in qs for m in MODELS}
        for k, v in enumerate(vals):
            mark = "*" if k == result.reference_index(p) else " "
            det_src = result.curve(p, "detailed").sources[k]
            flag = " (sim.)" if "similarity" in det_src else ""
            cells = " ".join(f"{_fmt(rel[(q, m)][k]) + (flag if m == 'detailed' else ''):>22s}" for q in qs
                             for m in MODELS)
            lines.append(f"{PARAMETERS[p][0]:22s} {v:>9.4g}{mark} {cells}")
    lines.append("* reference point; (sim.): detailed model on the table with similarity assumed along that axis")
    return "\n".join(lines)


def _fmt(v) -> str:
    return "refused" if math.isnan(v) else f"{v:.3g}"


def plot(result: RatesResult, path):
    """One panel per parameter: each model's rate over its value at the reference point, or,
    where a reference rate is negligible (:attr:`RatesResult.absolute`), the rates
    themselves [1/s] above a band that marks the negligible ones."""
    import textwrap

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .plotstyle import plain_log_ticks

    absolute = result.absolute
    floor = result.negligible_rate_per_s
    qs = ("disruption_rate",) if "disruption_rate" in result.quantities else result.quantities
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    fig, axes = plt.subplots(2, 3, figsize=(13.5, 9.0 if absolute else 8.2))

    def shown_rates(p, m, q):
        return result.curve(p, m).rates[q] if absolute else result.relative(p, m, q)

    def shown_band(p, q):
        c = result.curve(p, "detailed")
        return tuple(c.band[q]) if absolute and q in c.band else () if absolute else result.band_relative(p, q)

    for ax, p in zip(axes.ravel(), PARAMETERS):
        label, unit = PARAMETERS[p][0], PARAMETERS[p][1]
        scale, shown_unit = (1e3, "mm") if unit == "m" else (1.0, unit)
        for j, q in enumerate(qs):
            c = colors[j % len(colors)]
            for m, style in zip(MODELS, ("-", "--")):
                cur = result.curve(p, m)
                rel = shown_rates(p, m, q)
                xv = cur.values * scale
                ax.plot(xv, rel, style, color=c, label=f"{m}, {_qlabel(q)}")
                band = shown_band(p, q) if m == "detailed" else ()
                if band:
                    ax.fill_between(xv, *band, color=c, alpha=0.15, lw=0,
                                    label=f"detailed, {_qlabel(q)}: table's stated error")
                if m == "detailed":
                    sim = np.array(["similarity" in s for s in cur.sources])
                    ax.plot(xv[~sim], rel[~sim], "s", color=c, ms=4)
                    ax.plot(xv[sim], rel[sim], "s", color=c, mfc="none", ms=6)
                else:
                    ax.plot(xv, rel, "o", color=c, ms=3)
        ax.axvline(result.reference[p] * scale, color="0.6", lw=0.8, ls=":")
        shown = np.concatenate([shown_rates(p, m, q) for q in qs for m in MODELS]
                               + [b for q in qs for b in shown_band(p, q)])
        shown = shown[np.isfinite(shown) & (shown > 0.0)]
        if absolute:
            ax.set_yscale("log")
            lo = min(shown.min(), floor) if shown.size else floor
            ax.axhspan(lo / 10.0, floor, color="0.88", lw=0, zorder=0,
                       label=f"negligible rates: under {100 * NEGLIGIBLE_FRACTION:g} % broken in {result.run_s:g} s")
            ax.set_ylabel("breakage rate [1/s]")
        else:
            ax.axhline(1.0, color="0.8", lw=0.6)
            if shown.size and shown.max() / shown.min() > 10.0:  # a decade or more: log scale
                ax.set_yscale("log")
            ax.set_ylabel("rate / rate at reference")
        ax.set_xlabel(f"{label} [{shown_unit}]")
        src = result.source_description[p]
        sim_any = any("similarity" in x for x in result.curve(p, "detailed").sources)
        short = "detailed: table, similarity assumed (open squares)" if sim_any else \
            ("detailed: log-normal source" if src.startswith("lognormal") else "detailed: DEM table")
        ax.set_title(f"{label}\n{short}", fontsize=9)
        ax.grid(True, which="both", alpha=0.25)
    info = axes.ravel()[-1]
    info.axis("off")
    handles, labels = axes.ravel()[0].get_legend_handles_labels()
    info.legend(handles, labels, loc="upper left", fontsize=8, frameon=False, borderaxespad=0.0)
    ref = result.reference
    refs = "\n".join(f"  {_qlabel(q)}: simple {result.reference_rate('simple', q):.2g}, detailed "
                     f"{result.reference_rate('detailed', q):.2g}" for q in qs)
    info.text(0.0, 0.0, f"rates at the reference point [1/s]:\n{refs}\nsimple: k_c = {result.constants['k_c']:g}; "
              f"detailed: eta_E = {result.constants['energy_transfer']:g}", fontsize=8, va="bottom",
              transform=info.transAxes)
    point = (f"reference point (dotted): {ref['tip_speed']:g} m/s, bead diameter {ref['bead_diameter'] * 1e3:g} mm, "
             f"bead density {ref['bead_density']:g} kg/m3, solids {ref['solids_mass_fraction']:g}, "
             f"filling {ref['filling']:g} ({result.scene.material.model})")
    if absolute:
        why = result.why_absolute()
        fig.suptitle(f"Breakage rates [1/s] along each operating parameter: {result.name}\n{point}\n"
                     + textwrap.fill("Rates, not ratios: " + why, 165),
                     fontsize=9.5)
    else:
        fig.suptitle(f"Breakage rates relative to the reference point: {result.name}\n{point}", fontsize=10)
    plain_log_ticks(fig)
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "scene"


def write(out_dir, results: list, calibration: list | None = None, plots: bool = True) -> list:
    """Write every result's CSV, JSON and PNG (and the calibration table) into ``out_dir``;
    each file is written beside its place and moved there when complete."""
    from .runner import current_umask

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []

    def put(name, data: bytes | None = None, draw=None):
        fd, tmp = tempfile.mkstemp(prefix=f".{name}.", dir=out)
        try:
            # mkstemp's 0600 would stay with the file: give it the mode of the file it
            # replaces, or what the user's umask gives a new one.
            old = out / name
            os.chmod(tmp, stat.S_IMODE(old.stat().st_mode) if old.is_file() else 0o666 & ~current_umask())
            with os.fdopen(fd, "wb") as f:
                if data is not None:
                    f.write(data)
            if draw is not None:
                draw(tmp)
            os.replace(tmp, out / name)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        written.append(out / name)

    cal_by_material = {c["material"]: c for c in (calibration or [])}
    for r in results:
        base = f"rates_{_safe(r.name)}"
        put(base + ".csv", to_csv(r).encode())
        put(base + ".json", to_json(r, cal_by_material.get(r.name)).encode())
        if plots:
            put(base + ".png", draw=lambda p, r=r: plot(r, p))
    if calibration:
        buf = io.StringIO()
        cols = ("material", "quantity", "t_s", "datum", "simple", "detailed", "k_c", "k_c_fit", "energy_transfer",
                "detailed_key", "detailed_constant", "detailed_constant_fit", "detailed_ci95_low", "detailed_ci95_high",
                "detailed_data", "source")
        w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n", extrasaction="ignore")
        w.writeheader()
        for c in calibration:
            ci = c.get("detailed_constant_ci95") or [None, None]
            w.writerow({**c, "detailed_ci95_low": ci[0], "detailed_ci95_high": ci[1]})
        put("calibration.csv", buf.getvalue().encode())
    return written


# ---- command line ---------------------------------------------------------------------------
def _parse_values(items) -> dict:
    from .scene import SceneError

    out = {}
    for item in items or []:
        name, _, rest = item.partition("=")
        if name.strip() in out:
            raise SceneError("--values", item, f"{name.strip()} is given twice; give its values once, "
                             "PARAMETER=V1,V2,...", None)
        try:
            out[name.strip()] = [float(v) for v in rest.split(",") if v.strip()]
        except ValueError:
            raise SceneError("--values", item, "must be PARAMETER=V1,V2,... with numbers in SI units",
                             None) from None
        if not out[name.strip()]:
            raise SceneError("--values", item, "must be PARAMETER=V1,V2,... with at least one value", None)
    return out


def _cmd_rates(args) -> int:
    from . import calibration as cal
    from .runner import check_out_dir
    from .scene import load_scene

    values = _parse_values(args.values)
    if args.scene:
        jobs = [(None, load_scene(s), None) for s in args.scene]  # SceneError -> exit 2 before anything runs
    else:
        jobs = [(pair.material, *pair.scenes()) for pair in cal.SHIPPED]
    check_out_dir(args.out)
    results = [compute(scene, name=name, sizes_m=args.sizes, values=values, detailed_scene=det)
               for name, scene, det in jobs]
    calibration = None
    if not args.scene:
        calibration = [cal.check(pair) for pair in cal.SHIPPED]
    for r in results:
        print(summary(r))
        for p, d in r.source_description.items():
            print(f"  detailed model along {PARAMETERS[p][0]}: {d}")
        print()
    if calibration:
        print("calibration at each pair's reference point (stand-in data, not measurements): the simple model's k_c "
              "fitted to the datum, the detailed model's material constant to the stand-in curve with eta_E = 1:")
        for c in calibration:
            unit = "um" if c["quantity"] == "x50_m" else ""
            f = 1e6 if unit else 1.0
            ci = c["detailed_constant_ci95"]
            print(f"  {c['material']:9s} {c['quantity']} after {c['t_s']:g} s: datum {c['datum'] * f:.4g}{unit}, "
                  f"simple {c['simple'] * f:.4g}{unit} (k_c = {c['k_c']:g}, fit {c['k_c_fit']:.4g}), "
                  f"detailed {c['detailed'] * f:.4g}{unit} ({c['detailed_key']} = {c['detailed_constant']:g}, fit "
                  f"{c['detailed_constant_fit']:.4g}" + (f", 95 % [{ci[0]:.3g}, {ci[1]:.3g}]" if ci else "") + ")")
    files = write(args.out, results, calibration, plots=not args.no_plots)
    print("wrote " + ", ".join(str(f) for f in files))
    return 0


def register(sub):
    r = sub.add_parser("rates", help="breakage rates of the simple and the detailed model against each operating "
                                     "parameter, relative to the scene's operating point (CSV, PNG)")
    r.add_argument("scene", nargs="*",
                   help="scene files (TOML) or shipped examples' names; none: the shipped calibrated pairs of "
                        "yeast and limestone")
    r.add_argument("--out", default="out/rates", help="output folder (default: ./out/rates)")
    r.add_argument("--sizes", type=float, nargs="+", default=None,
                   help="sizes [m] of S(x) (default: the feed's x10, x50, x90; cells: x50)")
    r.add_argument("--values", action="append", metavar="PARAMETER=V1,V2,...",
                   help="values of one parameter instead of the defaults, SI units; parameters: "
                        f"{', '.join(PARAMETERS)}")
    r.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    r.set_defaults(func=_cmd_rates)


if __name__ == "__main__":  # pragma: no cover
    from .cli import main

    sys.exit(main(["rates", *sys.argv[1:]]))
