"""Scene files (TOML) read into validated, typed objects in SI units.

Every key carries its unit in its name (``_m``, ``_m_per_s``, ``_kg_per_m3``, ``_Pa``,
``_Pa_s``, ``_s``, ``_kg_per_s``, ``_J``); dimensionless keys have none. A missing,
mistyped, unknown or out-of-range value raises :class:`SceneError` naming the key, the value
and what is allowed. ``millfmu scene-keys`` lists every key with unit, default and bounds.
"""

from __future__ import annotations

import copy
import difflib
import json
import math
import sys
from dataclasses import MISSING, dataclass, field, fields, is_dataclass
from importlib import resources
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from .kinetics.stress import PHI_MAX_RCP
from .text_files import NotUtf8, utf8_text
from .unit_names import GivenTwice, read_as_current

#: [s] the longest run a scene may make (run.t_end_s), about 3.2 years
T_END_MAX_S = 1e8
#: the help of a command's scene argument
SCENE_ARG_HELP = ("scene file (TOML), or a shipped example's name (e.g. limestone_detailed; the list: "
                  "docs/scenes.md); omitted: the embedded default scene")

INF = math.inf


class SceneError(ValueError):
    """A scene value is missing, mistyped or out of range. ``key`` is the dotted key."""

    def __init__(self, key: str, value: Any, allowed: str, source: str | None = "scene"):
        self.key, self.value, self.allowed, self.source = key, value, allowed, source
        shown = "(missing)" if value is MISSING else repr(value)
        # source None: a command's own option, which the command line's prefix names
        super().__init__(f"{source + ': ' if source else ''}{key} = {shown}: {allowed}")


def _f(default=MISSING, *, unit="", lo=None, hi=None, lo_open=False, hi_open=False, choices=None, allow_inf=False,
       doc=""):
    """Field with unit, bounds and choices kept as metadata for validation and listing;
    allow_inf: the number may be infinite (e.g. "no maximum")."""
    md = dict(unit=unit, lo=lo, hi=hi, lo_open=lo_open, hi_open=hi_open, choices=choices, allow_inf=allow_inf, doc=doc)
    if isinstance(default, list):
        return field(default_factory=lambda d=default: list(d), metadata=md)
    if is_dataclass(default):
        return field(default_factory=lambda d=default: d, metadata=md)
    return field(default=default, metadata=md)


# ---------------------------------------------------------------------------------------
# Sections
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SceneInfo:
    name: str = _f("unnamed", doc="name of the scene")
    description: str = _f("", doc="free text")
    calibration: str = _f("",
                          doc="what the scene's fitted constants were fitted to (data and whether they are measured or "
                              "a stand-in, values with 95 % intervals); written by millfmu calibrate; carried into a "
                              "run's provenance and the FMU's description")
    fitted: list = _f([],
                      doc="the scene's fitted constants (dotted keys, e.g. material.f_mat_kg_per_J_m) whose 95 % "
                          "intervals the prediction band carries through the model; written by millfmu calibrate")
    fitted_ci95_low: list = _f([],
                               doc="the lower end of each fitted constant's 95 % interval, in the order of fitted and "
                                   "in its key's unit")
    fitted_ci95_high: list = _f([],
                                doc="the upper end of each fitted constant's 95 % interval, in the order of fitted and "
                                    "in its key's unit")


@dataclass(frozen=True)
class Mill:
    stirrer_radius_m: float = _f(0.036, unit="m", lo=0.0, hi=5.0, lo_open=True,
                                 doc="stirrer (disc) radius R; tip speed = omega R")
    chamber_volume_m3: float = _f(1.0e-3, unit="m3", lo=0.0, hi=100.0, lo_open=True, doc="grinding chamber volume")
    tip_speed_m_per_s: float = _f(10.0, unit="m/s", lo=0.0, hi=40.0, doc="stirrer tip speed v_t")
    bead_filling: float = _f(0.8, lo=0.0, hi=1.0, lo_open=True, hi_open=True,
                             doc="bead filling phi: bulk bead volume at rest over chamber volume")
    bead_porosity: float = _f(0.4, lo=0.2, hi=0.8, doc="porosity of the bead bulk at rest eps")
    n_discs: int = _f(5, lo=1, hi=1000, doc="number of stirrer discs (stirrer power)")
    power_number_laminar: float = _f(100.0, lo=0.0,
                                     doc="C_lam of Ne = C_lam/Re + C_turb (stirrer power characteristic; fit to the "
                                         "mill)")
    power_number_turbulent: float = _f(0.1, lo=0.0, doc="C_turb of Ne = C_lam/Re + C_turb")
    stress_frequency_factor: float = _f(1.0, lo=0.0,
                                        doc="simple model: k_c of n_c/t = k_c omega n_gb (Kwade's proportionality "
                                            "constant; the simple model's fitted constant)")


@dataclass(frozen=True)
class Beads:
    diameter_m: float = _f(0.8e-3, unit="m", lo=1e-5, hi=0.05, doc="grinding bead diameter d_gb")
    density_kg_per_m3: float = _f(2510.0, unit="kg/m3", lo=500.0, hi=20000.0, doc="grinding bead density rho_gb")
    youngs_modulus_Pa: float = _f(63e9, unit="Pa", lo=0.0, lo_open=True,
                                  doc="Young's modulus of the beads Y_GM (elasticity factor)")


@dataclass(frozen=True)
class Suspension:
    liquid_density_kg_per_m3: float = _f(998.2, unit="kg/m3", lo=500.0, hi=3000.0, doc="liquid density")
    viscosity_Pa_s: float = _f(1.002e-3, unit="Pa s", lo=0.0, hi=100.0, lo_open=True,
                               doc="suspension viscosity eta_susp (Krieger-Dougherty base)")
    solids_mass_fraction: float = _f(0.2, lo=0.0, lo_open=True, hi=0.8, hi_open=True,
                                     doc="product solids mass fraction of the suspension (> 0: a suspension without "
                                         "solids has no product to grind, and its feed flow no volume)")


@dataclass(frozen=True)
class Breakage:
    phi: float = _f(0.5, lo=0.0, hi=1.0, doc="Austin breakage function B = phi r^gamma + (1-phi) r^beta")
    gamma: float = _f(0.9, lo=0.0, lo_open=True, hi=20.0, doc="Austin gamma (fines slope)")
    beta: float = _f(4.0, lo=0.0, lo_open=True, hi=20.0, doc="Austin beta (coarse slope)")


@dataclass(frozen=True)
class Selection:
    a_per_s: float = _f(1e-3, unit="1/s", lo=0.0, doc="Austin S = a (x/x0)^alpha / (1 + (x/mu)^Lambda)")
    x0_m: float = _f(1e-3, unit="m", lo=0.0, lo_open=True, doc="reference size x0")
    alpha: float = _f(1.0, lo=-10.0, hi=20.0, doc="exponent alpha")
    mu_m: float = _f(INF, unit="m", lo=0.0, lo_open=True, allow_inf=True, doc="size of the maximum term mu (inf: none)")
    Lambda: float = _f(0.0, lo=0.0, hi=20.0, doc="steepness Lambda of the maximum term")


@dataclass(frozen=True)
class Material:
    model: str = _f("mineral", choices=("mineral", "yeast", "austin"), doc="material model")
    density_kg_per_m3: float = _f(2710.0, unit="kg/m3", lo=100.0, hi=25000.0, doc="particle density rho_P")
    youngs_modulus_Pa: float = _f(70e9, unit="Pa", lo=0.0, lo_open=True,
                                  doc="particle Young's modulus Y_P (elasticity factor)")
    f_mat_kg_per_J_m: float = _f(1.0, unit="kg/(J m)", lo=0.0, lo_open=True, doc="mineral: Vogel-Peukert f_Mat")
    x_w_min_J_m_per_kg: float = _f(1.0, unit="J m/kg", lo=0.0, doc="mineral: Vogel-Peukert x W_m,min")
    burst_energy_median_J: float = _f(2e-5, unit="J", lo=0.0, lo_open=True, doc="yeast: median burst energy")
    burst_energy_sigma_ln: float = _f(1.0, lo=0.0, lo_open=True, hi=10.0,
                                      doc="yeast: std. deviation of ln(burst energy)")
    breakage: Breakage = _f(Breakage(), doc="breakage function (fragments; debris for yeast)")
    selection: Selection = _f(Selection(), doc="austin: selection function straight from the scene")


@dataclass(frozen=True)
class StressDistribution:
    source: str = _f("lognormal", choices=("lognormal", "table"),
                     doc="stress-energy source of the detailed model: log-normal, or a DEM table")
    table: str = _f("coupled",
                    doc="table: a shipped table by name ('coupled': the coupled DEM-CFD disc slice, the default "
                        "scene's; 'prescribed': the disc slice with a prescribed swirl, for comparison; 'accelerator'; "
                        "millfmu/data/NAME_table; 'default' names the default scene's) or PREFIX of "
                        "PREFIX.npz/PREFIX.json")
    component: str = _f("tn", choices=("tn", "total"), doc="table: stress-energy component (tn: normal impact energy)")
    collision_energy: str = _f("bead_mass", choices=("bead_mass", "reduced_mass"),
                               doc="table: a bead-bead collision's energy as seed 001 eq. 1 defines SE_tn, 1/2 m_GM "
                                   "v_rel^2 with the bead's mass (bead_mass; twice the pair's centre-of-mass energy "
                                   "for equal beads), or 1/2 m* v_rel^2 with the pair's reduced mass m* = m_GM/2, as "
                                   "the DEM records it (reduced_mass)")
    similar_axes: list = _f([], choices=("tip_speed_m_per_s", "bead_diameter_m", "bead_density_kg_per_m3",
                                         "viscosity_Pa_s"),
                            doc="table: axes along which similarity is assumed: an axis the table does not vary "
                                "(bead_diameter_m, bead_density_kg_per_m3, viscosity_Pa_s) may differ from the table's "
                                "value, and a value outside the grid (also tip_speed_m_per_s) uses the nearest edge's "
                                "dimensionless fields")
    on_outside: str = _f("refuse", choices=("refuse", "build"),
                         doc="table: operating point outside the grid: refuse, or build a covering table with the DEM "
                             "(only the missing points run; a point the table's DEM scene cannot run is refused when "
                             "the scene is loaded; an FMU carries the table build-fmu built and refuses outside it)")
    on_stale: str = _f("refuse", choices=("refuse", "rebuild", "accept"),
                       doc="table, on_outside = 'build': where the installed DEM's kernel version is not the table's "
                           "(the code changed since it was built): refuse the build (the message names the cost of the "
                           "full rebuild), rebuild every point with the installed DEM, or accept the table's points as "
                           "they are and run only the new ones (millfmu run --on-stale overrides)")
    median_fraction: float = _f(0.01, lo=0.0, hi=1.0, lo_open=True, doc="lognormal: median collision energy over SE")
    sigma_ln: float = _f(1.5, lo=0.0, hi=10.0, lo_open=True, doc="lognormal: std. deviation of ln(energy)")
    collision_factor: float = _f(1.0, lo=0.0, doc="lognormal: collisions per volume over omega n_gb")


@dataclass(frozen=True)
class Kinetics:
    model: str = _f("simple", choices=("simple", "detailed", "none"),
                    doc="stress model: Kwade simple, detailed (SE distribution), none (rates from the scene)")
    capture: str = _f("class", choices=("class", "psd"),
                      doc="number concentration in P_cap: per size class (rates frozen) or from the current PSD "
                          "(state-dependent)")
    energy_transfer: float = _f(1.0, lo=0.0, hi=1.0, lo_open=True,
                                doc="detailed model: share eta_E of a collision's energy that reaches a captured "
                                    "particle (before the elasticity factor); the detailed model's fitted constant, as "
                                    "mill.stress_frequency_factor is the simple model's")
    stress_distribution: StressDistribution = _f(StressDistribution(), doc="detailed model's stress-energy source")


@dataclass(frozen=True)
class Grid:
    x_min_m: float = _f(0.1e-6, unit="m", lo=1e-10, hi=1.0, doc="lower edge of the finest class")
    x_max_m: float = _f(200e-6, unit="m", lo=1e-9, hi=1.0,
                        doc="upper edge of the coarsest class (rounded up to whole classes)")
    classes_per_octave: float = _f(4.0, lo=0.25, hi=64.0, doc="classes per doubling of size")


@dataclass(frozen=True)
class PSD:
    kind: str = _f("lognormal", choices=("lognormal", "rrsb", "monodisperse", "table"),
                   doc="size distribution by name or table")
    x50_m: float = _f(None, unit="m", lo=0.0, lo_open=True, doc="lognormal: median size")
    sigma_ln: float = _f(None, lo=0.0, lo_open=True, hi=10.0, doc="lognormal: std. deviation of ln x")
    x63_m: float = _f(None, unit="m", lo=0.0, lo_open=True, doc="rrsb: size at Q3 = 0.632")
    n: float = _f(None, lo=0.0, lo_open=True, hi=50.0, doc="rrsb: uniformity exponent")
    x_m: float = _f(None, unit="m", lo=0.0, lo_open=True, doc="monodisperse: size")
    sizes_m: list = _f(None, unit="m", doc="table: sizes, ascending")
    Q3: list = _f(None, doc="table: cumulative mass fractions undersize at sizes_m, non-decreasing, last = 1")


@dataclass(frozen=True)
class Operation:
    mode: str = _f("batch", choices=("batch", "continuous"), doc="batch, or continuous through N equal tanks in series")
    n_tanks: int = _f(1, lo=1, hi=100, doc="continuous: tanks in series for the residence time distribution")
    feed_mass_flow_kg_per_s: float = _f(0.0, unit="kg/s", lo=0.0, hi=1e3, doc="continuous: solids feed mass flow")


@dataclass(frozen=True)
class Run:
    t_end_s: float = _f(1800.0, unit="s", lo=0.0, lo_open=True, hi=T_END_MAX_S, doc="end time")
    dt_s: float = _f(1.0, unit="s", lo=0.0, lo_open=True, doc="step size")
    output_interval_s: float = _f(60.0, unit="s", lo=0.0, lo_open=True, doc="time between outputs")
    integrator: str = _f("exact", choices=("exact", "adaptive"),
                         doc="exact step with frozen rates, or adaptive (rates varying within a step)")
    rtol: float = _f(1e-6, lo=1e-12, hi=0.1, doc="adaptive: relative tolerance")
    tip_speed_profile: list = _f(None, doc="optional [[t_s, v_t_m_per_s], ...], linear between points")


@dataclass(frozen=True)
class Scene:
    """A whole scene (SI units)."""

    scene: SceneInfo = _f(SceneInfo())
    mill: Mill = _f(Mill())
    beads: Beads = _f(Beads())
    suspension: Suspension = _f(Suspension())
    material: Material = _f(Material())
    kinetics: Kinetics = _f(Kinetics())
    grid: Grid = _f(Grid())
    feed: PSD = _f(PSD(kind="lognormal", x50_m=20e-6, sigma_ln=0.8), doc="feed (and, batch, initial) size distribution")
    initial: PSD = _f(None, doc="continuous: initial content of the mill (default: the feed)")
    operation: Operation = _f(Operation())
    run: Run = _f(Run())


# ---------------------------------------------------------------------------------------
# Loading and validation
# ---------------------------------------------------------------------------------------
def _bounds(md) -> str:
    """The bounds of a number with its unit, e.g. ">= 0 and <= 40 m/s" ("" if none)."""
    parts = []
    if md["lo"] is not None:
        parts.append((">" if md["lo_open"] else ">=") + f" {md['lo']:g}")
    if md["hi"] is not None:
        parts.append(("<" if md["hi_open"] else "<=") + f" {md['hi']:g}")
    unit = f" {md['unit']}" if md["unit"] else ""
    return " and ".join(parts) + unit if parts else unit.strip()


def _describe(md) -> str:
    if md["choices"]:
        return "one of " + ", ".join(repr(c) for c in md["choices"])
    b = _bounds(md)
    return "a number " + b if b else "a number"


def _check_value(key, v, ftype, md, source):
    if ftype in ("float", float):
        if isinstance(v, str) and v.strip().lower() in ("inf", "+inf", "infinity"):
            v = INF
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise SceneError(key, v, "must be " + _describe(md), source)
        v = float(v)
        if math.isnan(v):
            raise SceneError(key, v, "must be " + _describe(md), source)
    elif ftype in ("int", int):
        if isinstance(v, bool) or not isinstance(v, int):
            raise SceneError(key, v, ("must be an integer " + _bounds(md)).rstrip(), source)
    elif ftype in ("str", str):
        if not isinstance(v, str):
            raise SceneError(key, v, "must be " + (_describe(md) if md["choices"] else "a string"), source)
        if md["choices"] and v not in md["choices"]:
            raise SceneError(key, v, "must be " + _describe(md), source)
        return v
    elif ftype in ("list", list):
        if not isinstance(v, list):
            raise SceneError(key, v, "must be a list"
                             + (" of " + _describe(md)[len("one of "):] if md["choices"] else ""), source)
        for i, item in enumerate(v):
            if md["choices"] and item not in md["choices"]:
                raise SceneError(f"{key}[{i}]", item,
                                 "not an allowed entry; allowed: " + ", ".join(repr(c) for c in md["choices"]), source)
        return v
    lo, hi = md["lo"], md["hi"]
    if lo is not None and (v < lo or (md["lo_open"] and v == lo)):
        raise SceneError(key, v, "must be " + _describe(md), source)
    if hi is not None and (v > hi or (md["hi_open"] and v == hi)):
        raise SceneError(key, v, "must be " + _describe(md), source)
    if ftype in ("float", float) and math.isinf(v) and not md["allow_inf"]:
        raise SceneError(key, v, "must be finite", source)
    return v


def _elsewhere(name: str, prefix: str) -> str:
    """' here: it is a key of [SECTION] (write it there)' where ``name`` is a key of
    another section of a scene file than ``prefix`` (e.g. a tip speed written at the top)."""
    hits = [at for at, _, leaf in (k.rpartition(".") for k, *_ in iter_keys(default_obj=None))
            if leaf == name and at != prefix]
    if not hits:
        return ""
    return " here: it is a key of " + " and of ".join(f"[{h}]" for h in hits) + " (write it there)"


def _load_section(cls, table, prefix, source):
    if not isinstance(table, dict):
        raise SceneError(prefix, table, "must be a table", source)
    names = {f.name for f in fields(cls)}
    for k in table:
        if k not in names:
            raise SceneError(f"{prefix}.{k}" if prefix else k, table[k],
                             "unknown key" + (_elsewhere(k, prefix) or did_you_mean(k, names)) + "; allowed: "
                             + ", ".join(sorted(names)), source)
    kw = {}
    for f in fields(cls):
        key = f"{prefix}.{f.name}" if prefix else f.name
        md = f.metadata
        if f.name not in table:
            continue  # dataclass default
        v = table[f.name]
        sub = _section_type(f)
        if sub is not None:
            kw[f.name] = _load_section(sub, v, key, source)
        else:
            kw[f.name] = _check_value(key, v, f.type, md, source)
    return cls(**kw)


_SECTION_TYPES = {
    "SceneInfo": SceneInfo, "Mill": Mill, "Beads": Beads, "Suspension": Suspension,
    "Material": Material, "Breakage": Breakage, "Selection": Selection, "Kinetics": Kinetics,
    "StressDistribution": StressDistribution, "Grid": Grid, "PSD": PSD, "Operation": Operation,
    "Run": Run,
}


def closest(name, allowed) -> str | None:
    """The allowed name closest to a misspelt ``name`` (case aside; a name without its unit
    suffix is close to the one with it), or None where none is close."""
    if not isinstance(name, str):
        return None
    by_lower = {a.lower(): a for a in allowed if isinstance(a, str)}
    match = [a for a in by_lower if a.startswith(name.lower() + "_")]
    if len(match) != 1:
        match = difflib.get_close_matches(name.lower(), by_lower, n=1, cutoff=0.75)
    return by_lower[match[0]] if match else None


def did_you_mean(name, allowed) -> str:
    """" (did you mean X?)" with :func:`closest`, or "" where no allowed name is close."""
    match = closest(name, allowed)
    return f" (did you mean {match}?)" if match else ""


def _section_type(f):
    return _SECTION_TYPES.get(f.type if isinstance(f.type, str) else getattr(f.type, "__name__", ""))


def _check_psd(p: PSD, key: str, source: str):
    need = {"lognormal": ("x50_m", "sigma_ln"), "rrsb": ("x63_m", "n"), "monodisperse": ("x_m",),
            "table": ("sizes_m", "Q3")}
    for k in need[p.kind]:
        if getattr(p, k) is None:
            raise SceneError(f"{key}.{k}", MISSING, f"required for kind = {p.kind!r}", source)
    if p.kind == "table":
        s, q = p.sizes_m, p.Q3
        for name, arr in (("sizes_m", s), ("Q3", q)):
            for i, v in enumerate(arr):
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise SceneError(f"{key}.{name}[{i}]", v, "must be a finite number", source)
        if len(s) != len(q) or len(s) < 2:
            raise SceneError(f"{key}.Q3", q, f"must have as many entries as sizes_m ({len(s)}), at least 2", source)
        if any(v <= 0 for v in s) or any(b <= a for a, b in zip(s, s[1:])):
            raise SceneError(f"{key}.sizes_m", s, "must be positive and strictly ascending (m)", source)
        if any(v < 0 or v > 1 for v in q) or any(b < a for a, b in zip(q, q[1:])):
            raise SceneError(f"{key}.Q3", q, "must lie in [0, 1] and not decrease", source)
        if abs(q[-1] - 1.0) > 1e-6:
            raise SceneError(f"{key}.Q3", q, "must end at 1 (all mass below the largest size)", source)


def number_key(s: Scene, key: str) -> float | None:
    """The value of the number key SECTION.KEY of a scene (e.g. material.f_mat_kg_per_J_m),
    or None where the key names no number of the scene."""
    sec, _, name = str(key).partition(".")
    value = getattr(getattr(s, sec, None), name, None) if name and "." not in name else None
    return None if isinstance(value, bool) or not isinstance(value, (int, float)) else float(value)


def _check_fitted(s: Scene, source: str):
    """scene.fitted names numeric scene keys, each with a 95 % interval (low <= high). A value
    set outside its interval afterwards is no error: the band then leaves that interval out
    and says so (:func:`millfmu.runner.prediction_band`)."""
    info = s.scene
    keys, lo, hi = info.fitted, info.fitted_ci95_low, info.fitted_ci95_high
    if not (len(keys) == len(lo) == len(hi)):
        raise SceneError("scene.fitted_ci95_low", lo,
                         f"and scene.fitted_ci95_high {hi!r} must give one value for each key of "
                         f"scene.fitted {keys!r}", source)
    for i, k in enumerate(keys):
        if number_key(s, k) is None:
            raise SceneError(f"scene.fitted[{i}]", k, "must name a number key of the scene as SECTION.KEY "
                             "(e.g. material.f_mat_kg_per_J_m)", source)
        a, b = lo[i], hi[i]
        if any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
               for v in (a, b)) or not a <= b:
            raise SceneError(f"scene.fitted_ci95_low[{i}]", a,
                             f"and scene.fitted_ci95_high[{i}] = {b!r} must be finite "
                             f"numbers, low <= high ({k})", source)


def _cross_check(s: Scene, source: str):
    _check_fitted(s, source)
    if s.grid.x_max_m <= s.grid.x_min_m * 2 ** (1.0 / s.grid.classes_per_octave):
        raise SceneError("grid.x_max_m", s.grid.x_max_m,
                         f"must exceed x_min_m = {s.grid.x_min_m:g} m by at least one class", source)
    n = math.ceil(s.grid.classes_per_octave * math.log2(s.grid.x_max_m / s.grid.x_min_m) - 1e-9)
    if n > 1000:
        raise SceneError("grid.classes_per_octave", s.grid.classes_per_octave,
                         f"gives {n} classes; at most 1000 allowed", source)
    if s.material.model == "austin" and s.kinetics.model != "none":
        raise SceneError("kinetics.model", s.kinetics.model,
                         "must be 'none' for material.model = 'austin' (rates straight from the scene)", source)
    if s.material.model != "austin" and s.kinetics.model == "none":
        raise SceneError("kinetics.model", s.kinetics.model,
                         f"must be 'simple' or 'detailed' for material.model = {s.material.model!r}; 'none' needs "
                         "material.model = 'austin'", source)
    if s.material.model == "austin":
        _check_austin_selection(s, source)
    c_v = s.mill.bead_filling * (1.0 - s.mill.bead_porosity)
    if c_v >= PHI_MAX_RCP:
        raise SceneError("mill.bead_filling", s.mill.bead_filling,
                         f"with bead_porosity {s.mill.bead_porosity:g} gives a bead volume fraction {c_v:.3f}; must "
                         f"stay below {PHI_MAX_RCP} (random close packing)", source)
    _check_psd(s.feed, "feed", source)
    if s.initial is not None:
        if s.operation.mode != "continuous":
            raise SceneError("initial", "[initial] section",
                             f"only for operation.mode = 'continuous' (this scene is {s.operation.mode!r}): "
                             "a batch mill starts with its feed distribution; give it as [feed]", source)
        _check_psd(s.initial, "initial", source)
    if s.run.dt_s > s.run.t_end_s:
        raise SceneError("run.dt_s", s.run.dt_s, f"must not exceed run.t_end_s = {s.run.t_end_s:g} s", source)
    if s.run.t_end_s / s.run.dt_s > 1e7:
        raise SceneError("run.dt_s", s.run.dt_s, f"gives {s.run.t_end_s / s.run.dt_s:.3g} steps; at most 1e7", source)
    prof = s.run.tip_speed_profile
    if prof is not None:
        ok = len(prof) >= 1 and all(isinstance(p, list) and len(p) == 2
                                    and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                                            for v in p) for p in prof)
        if not ok or any(b[0] <= a[0] for a, b in zip(prof, prof[1:])) or any(p[1] < 0 or p[1] > 40 for p in prof):
            raise SceneError("run.tip_speed_profile", prof,
                             "must be [[t_s, v_t_m_per_s], ...] with ascending times and 0 <= v_t <= 40 m/s", source)


#: Largest selection rate an Austin scene may reach on its size grid [1/s]: a class broken
#: in 1e-20 s is broken at once; above it (tried up to 1e40) the step's exponential loses
#: the masses to overflow and round-off (non-finite or negative).
S_MAX_PER_S = 1e20


def _check_austin_selection(s: Scene, source: str):
    """Austin's S = a (x/x0)^alpha / (1 + (x/mu)^Lambda) over the size grid (taken in
    logarithms, so that no value overflows here) must stay finite and below S_MAX_PER_S."""
    sel = s.material.selection
    if sel.a_per_s == 0.0:
        return
    lo, hi = math.log(s.grid.x_min_m), math.log(s.grid.x_max_m)
    worst, at = -INF, s.grid.x_min_m
    for k in range(201):
        lx = lo + (hi - lo) * k / 200
        ls = math.log(sel.a_per_s) + sel.alpha * (lx - math.log(sel.x0_m))
        if math.isfinite(sel.mu_m) and sel.Lambda > 0.0:
            z = sel.Lambda * (lx - math.log(sel.mu_m))
            ls -= z + math.log1p(math.exp(-z)) if z > 0 else math.log1p(math.exp(z))
        if ls > worst:
            worst, at = ls, math.exp(lx)
    if worst > math.log(S_MAX_PER_S):
        raise SceneError("material.selection.a_per_s", sel.a_per_s,
                         f"with x0_m = {sel.x0_m:g} m and alpha = {sel.alpha:g} gives S = "
                         f"10^{worst / math.log(10):.1f} 1/s at x = {at:.3g} m on the size grid ({s.grid.x_min_m:g} "
                         f"... {s.grid.x_max_m:g} m); S must stay below {S_MAX_PER_S:g} 1/s (a class broken in 1e-20 "
                         "s): lower a_per_s or alpha, or raise x0_m",
                         source)


#: Sections taken whole, not key by key, when a scene gives them with another ``kind`` than
#: the default scene's (a log-normal's x50_m means nothing to an RRSB distribution).
_KIND_SECTIONS = ("feed", "initial")


def _merged(base: dict, over: dict, path: str = "") -> dict:
    out = copy.deepcopy(base)
    for k, v in over.items():
        key = f"{path}.{k}" if path else k
        b = out.get(k)
        if isinstance(v, dict) and isinstance(b, dict) and not (key in _KIND_SECTIONS
                                                                and v.get("kind", b.get("kind")) != b.get("kind")):
            out[k] = _merged(b, v, key)
        else:
            out[k] = copy.deepcopy(v)
    return out


def _default_dict() -> dict:
    global _DEFAULT_DICT
    if _DEFAULT_DICT is None:
        _DEFAULT_DICT = tomllib.loads(default_scene_text())
    return _DEFAULT_DICT


_DEFAULT_DICT = None


def resolve_dict(d: dict) -> dict:
    """The scene dict with every key left out taken from the embedded default scene (one set
    of defaults: a key missing from both has its listed default, ``millfmu scene-keys``)."""
    if not isinstance(d, dict):
        raise SceneError("(scene)", d, "must be a table of sections")
    out = _merged(_default_dict(), d)
    # The default scene's calibration record describes its own material and kinetics: a
    # scene that sets its own, without a record of its own, has none.
    own = d.get("scene") if isinstance(d.get("scene"), dict) else {}
    mill = d.get("mill") if isinstance(d.get("mill"), dict) else {}  # not a table: refused by name below
    own_constants = bool(d.get("material") or d.get("kinetics") or "stress_frequency_factor" in mill)
    if "calibration" not in own and own_constants:
        out.setdefault("scene", {})["calibration"] = ""
    if "calibration" in own or own_constants:
        # The fitted constants' intervals go with the record they belong to: the scene's own.
        info = out.setdefault("scene", {})
        for k in ("fitted", "fitted_ci95_low", "fitted_ci95_high"):
            info[k] = own.get(k, [])
    return out


def scene_from_dict(d: dict, source: str = "scene") -> Scene:
    """Validate a scene given as a dict (as read from TOML); keys left out take the embedded
    default scene's values (:func:`resolve_dict`)."""
    s = _load_section(Scene, resolve_dict(_current_spelling(d, source)), "", source)
    _cross_check(s, source)
    return s


def _current_spelling(d: dict, source: str) -> dict:
    """``d`` with an earlier release's unit suffixes (keys, and the axis names of
    ``similar_axes``) in the current spelling, with a note naming each (FutureWarning)."""
    try:
        return read_as_current(d, source, value_keys=("similar_axes",), stacklevel=3)
    except GivenTwice as e:
        raise SceneError(e.where, e.value, e.allowed, source) from None


def scene_to_dict(s: Scene) -> dict:
    """Every key of a scene with its value (sections as dicts; unset values left out): the
    resolved scene, e.g. for a result's provenance or to write it back as TOML."""

    def plain(obj):
        if is_dataclass(obj):
            return {f.name: plain(getattr(obj, f.name)) for f in fields(obj) if getattr(obj, f.name) is not None}
        if isinstance(obj, (list, tuple)):
            return [plain(v) for v in obj]
        return obj

    return plain(s)


def load_scene(path: str | Path | None = None) -> Scene:
    """Read and validate a scene file; ``None`` gives the embedded default scene."""
    if path is None:
        text = default_scene_text()
        source = "default scene"
    else:
        p = Path(path)
        source = str(p)
        try:
            raw = p.read_bytes()
        except OSError as e:
            example = closest(p.name if p.suffix else p.name + ".toml", example_files()) \
                if isinstance(e, FileNotFoundError) and str(p) == p.name else None
            hint = f" (did you mean {example}, a shipped example?)" if example else ""
            raise SceneError("(file)", str(p), f"cannot be read: {e.strerror or e}{hint}", source) from None
        try:
            text = utf8_text(raw)
        except NotUtf8 as e:
            raise SceneError("(encoding)", e.bytes.hex(" "),
                             f"the file must be UTF-8 text (TOML); byte offset {e.start} (line {e.line}) is not UTF-8 "
                             f"({e.reason}); save it as UTF-8", source) from None
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneError("(syntax)", str(e), "the file must be valid TOML", source) from None
    return scene_from_dict(d, source)


def example_files() -> dict[str, Path]:
    """The shipped examples (millfmu/data/examples): file name -> path, wherever the package
    is installed. Scenes (``.toml``) and the stand-in batch data the calibration fits to
    (``.csv``)."""
    base = resources.files(__name__.rpartition(".")[0] + ".data").joinpath("examples")
    return {p.name: Path(str(p)) for p in sorted(base.iterdir(), key=lambda p: p.name)
            if p.is_file() and p.name.endswith((".toml", ".csv"))}


def shipped_file(arg, files: dict):
    """The file a command-line file argument stands for: ``arg`` itself where it exists, has
    a folder in it or is None; else the file of that name (``.toml`` optional) in ``files``
    (file name -> path: the shipped examples, the shipped flowsheets); else ``arg``
    unchanged, whose command then reports the missing file. A file of the user's wins over a
    shipped one of the same name."""
    if arg is None or Path(arg).exists() or Path(arg).name != str(arg):
        return arg
    return files.get(str(arg)) or files.get(f"{arg}.toml") or arg


def example_path(name: str) -> Path:
    """Path of a shipped example file (millfmu/data/examples/NAME: a scene, ``.toml``
    optional, or stand-in batch data such as ``limestone_standin_batch.csv``), wherever the
    package is installed; SceneError listing the examples for another name."""
    files = example_files()
    file = name if name in files else name + ".toml"
    if file not in files:
        raise SceneError("(example)", name, "not a shipped example; the examples: " + ", ".join(files), "example_path")
    return files[file]


def default_scene_text() -> str:
    """The embedded default scene (TOML). Read relative to this package, so that a copy of
    the package under another name (inside an FMU) reads its own."""
    return resources.files(__name__.rpartition(".")[0] + ".data").joinpath("default_scene.toml").read_text()


def iter_keys(cls=Scene, prefix="", default_obj=MISSING):
    """Yield (dotted key, unit, default, allowed, doc) for every scene key; the default is the
    embedded default scene's value where it sets the key."""
    if default_obj is MISSING:
        default_obj = scene_from_dict({}, "default scene")
    for f in fields(cls):
        key = f"{prefix}.{f.name}" if prefix else f.name
        sub = _section_type(f)
        value = getattr(default_obj, f.name, None) if default_obj is not None else None
        if sub is not None:
            yield from iter_keys(sub, key,
                                 value if value is not None else f.default if f.default is not MISSING else None)
            continue
        md = f.metadata
        default = value
        allowed = _describe(md) if f.type in ("float", "int", float, int) or md["choices"] else str(f.type)
        yield key, md.get("unit", ""), default, allowed, md.get("doc", "")


def toml_value(v) -> str:
    """A scene value as TOML (numbers, strings, booleans, infinities, lists of them)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, float) and v in (float("inf"), float("-inf")):
        return "inf" if v > 0 else "-inf"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    return repr(v)


def toml_text(d: dict) -> str:
    """TOML text of a scene dict (tables, numbers, strings, booleans, lists of numbers)."""
    lines: list = []

    def table(prefix, t):
        if prefix:
            lines.append(f"[{prefix}]")
        lines.extend(f"{k} = {toml_value(v)}" for k, v in t.items() if not isinstance(v, dict))
        for k, v in t.items():
            if isinstance(v, dict):
                table(f"{prefix}.{k}" if prefix else k, v)

    table("", d)
    return "\n".join(lines) + "\n"
