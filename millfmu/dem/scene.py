"""DEM scene files (TOML) -> validated, typed DemScene in SI units.

A scene names its geometry kind (``annulus``, ``disc_slice`` or ``accelerator_slice``,
:mod:`millfmu.dem.mills.accelerator`) and gives the mill,
bead, fluid, run and zone parameters; every key carries its unit in its name. The shipped
scenes live next to this module in ``scenes/``. Errors name the key, the value and what
is allowed.

The fluid is chosen by ``[fluid] mode``: ``coupled`` (the liquid solved on a grid and
coupled both ways, :mod:`millfmu.dem.coupling`; options in ``[fluid.coupled]``),
``prescribed`` (Koch-Hill drag towards the prescribed swirl of
:func:`millfmu.dem.engine.kernels.swirl_velocity`), or ``none``. A scene without ``mode`` (files
written before the coupled fluid) means ``prescribed``, or ``none`` with the old
``enabled = false``.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from millfmu.dem.coupling.settings import (BEAD_STRESS_FORCES, DPM_DRAG_LAWS,
                                           PRESSURE_GRADIENT_TIMINGS, SMOOTHINGS,
                                           CouplingSettings)
from millfmu.dem.engine.params import BeadMaterial
from millfmu.dem.engine.sim import DemSimulation, FluidSettings
from millfmu.dem.fluid.settings import DEFAULT_PRESSURE_SOLVER, PRESSURE_SOLVERS
from millfmu.dem.mills.accelerator import SevSpec
from millfmu.dem.mills.geometry import MillGeometry
from millfmu.dem.mills.zones import ZoneSpec
from millfmu.text_files import NotUtf8, utf8_text
from millfmu.unit_names import read_as_current

SCENE_DIR = Path(__file__).parent / "scenes"
KINDS = ("annulus", "disc_slice", "accelerator_slice")
#: rotor speeds of seed 002 are 800-1400 rpm (and 400 rpm in its section 3.2); the ranges
#: of each kind live in millfmu.dem.limits, which reads them without the engine
from millfmu.dem.limits import (ACCELERATOR_FILLING, ACCELERATOR_RPM_RANGE,  # noqa: E402
                                DISC_SLICE_FILLING, DISC_SLICE_TIP_SPEED_M_PER_S,
                                MAX_THETA_CELL_RAD, least_theta_cells)
FLUID_MODES = ("coupled", "prescribed", "none")
#: coupling schemes of the coupled fluid ([fluid.coupled] scheme): volume-averaged
#: Navier-Stokes (millfmu.dem.coupling.cfd_dem) or a dilute discrete phase model
#: (millfmu.dem.coupling.dpm)
COUPLING_SCHEMES = ("vans", "dpm")
#: the discrete phase model's drag laws as its description line names them
DPM_DRAG_NAMES = {"schiller_naumann": "Schiller-Naumann",
                  "koch_hill2001": "Koch-Hill (at the beads' void fraction)"}


class DemSceneError(ValueError):
    """A DEM scene file or value that is not allowed."""


@dataclass(frozen=True)
class DemScene:
    name: str
    kind: str
    geometry: MillGeometry
    material: BeadMaterial
    bead_diameter_m: float
    tip_speed_m_per_s: float  # disc tip (disc_slice) or shaft surface (annulus) speed
    placement: str  # "filling" or "lattice"
    filling: float | None
    bulk_porosity: float
    lattice_spacing_m: float | None
    lattice_r_range_m: tuple | None
    fluid: FluidSettings | None  # liquid properties and lubrication; None for mode "none"
    fluid_mode: str  # "coupled", "prescribed" or "none"
    coupling: CouplingSettings | None  # the coupled fluid's options (mode "coupled")
    gravity_m_per_s2: tuple
    dt_s: float
    spin_up_s: float
    record_s: float
    sample_every_s: float
    seed: int
    zones: ZoneSpec  # accelerator_slice: millfmu.dem.mills.accelerator.SevSpec
    map_bins_r: int
    map_bins_z: int
    # beads and coupled fluid start turning at this fraction of the stirrer's angular
    # velocity [-] (0: from rest); shortens the spin-up, the windows check decides
    initial_rotation: float = 0.0
    # coupled fluid: the liquid runs alone (bead-free) for this time [s] before the beads
    # are put in with its velocity at their centres (0: no primed start)
    primed_s: float = 0.0

    @property
    def omega_rad_per_s(self) -> float:
        """Stirrer angular velocity [rad/s]."""
        r = self.geometry.disc_radius_m if self.geometry.has_disc else \
            self.geometry.shaft_radius_m
        return self.tip_speed_m_per_s / r

    @property
    def rotor_speed_rpm(self) -> float:
        """Stirrer speed [1/min]."""
        return self.omega_rad_per_s * 60.0 / (2.0 * math.pi)

    def with_overrides(self, **kw) -> DemScene:
        """Copy with run-time overrides (tip_speed_m_per_s, filling, sector_deg, spin_up_s,
        record_s, dt_s, fluid_mode, initial_rotation, primed_s, n_theta: the coupled
        liquid's theta cells; smoothing_diameters: its exchange's smoothing length [bead
        diameters], >= 0; smoothing: its smoothing (SMOOTHINGS); pressure_solver: its
        pressure equation's solver (PRESSURE_SOLVERS); bead_stress_force: model A's beads'
        viscous-stress force (BEAD_STRESS_FORCES); vans_model: the volume-averaged liquid's
        model, 'A' or 'B'; ``baffles``: a dict of the [mill]
        baffle keys, BAFFLE_KEYS; wall_friction: the beads' [beads] wall_friction);
        validated like file values."""
        geo = self.geometry
        if kw.get("baffles") is not None:
            geo = _with_baffles(geo, kw["baffles"], "baffles")
        kw.pop("baffles", None)
        if kw.get("sector_deg") is not None:
            geo = _geometry_or_error(replace, geo, sector_deg=float(kw.pop("sector_deg")))
        kw.pop("sector_deg", None)
        mode = kw.pop("fluid_mode", None)
        n_theta = kw.pop("n_theta", None)
        smoothing_d = kw.pop("smoothing_diameters", None)
        smoothing = kw.pop("smoothing", None)
        pressure_solver = kw.pop("pressure_solver", None)
        bead_stress_force = kw.pop("bead_stress_force", None)
        vans_model = kw.pop("vans_model", None)
        wall_friction = kw.pop("wall_friction", None)
        if kw.get("filling") is not None and self.placement != "filling":
            raise DemSceneError(f"beads.filling = {kw['filling']!r}: this scene places its beads on a lattice "
                                f"(beads.placement = {self.placement!r}); a filling is used only with placement "
                                "'filling'")
        new = replace(self, geometry=geo, **{k: v for k, v in kw.items() if v is not None})
        if mode is not None and mode != self.fluid_mode:
            new = _with_fluid_mode(new, mode)
        if n_theta is not None:
            if isinstance(n_theta, bool) or not isinstance(n_theta, int) or n_theta < 1:
                raise DemSceneError(f"n_theta = {n_theta!r}: must be a whole number >= 1 "
                                    f"(theta cells of the coupled liquid)")
            if new.coupling is None:
                raise DemSceneError(f"n_theta = {n_theta}: theta cells are the coupled "
                                    f"liquid's; the fluid here is {new.fluid_mode!r}")
            new = replace(new, coupling=replace(new.coupling, n_theta=n_theta))
        if smoothing_d is not None:
            if (isinstance(smoothing_d, bool) or not isinstance(smoothing_d, (int, float))
                    or not (math.isfinite(smoothing_d) and smoothing_d >= 0.0)):
                raise DemSceneError(f"smoothing_diameters = {smoothing_d!r}: must be a number >= 0 (bead diameters "
                                    "over which the coupled exchange is smoothed; 0: none)")
            if new.coupling is None:
                raise DemSceneError(f"smoothing_diameters = {smoothing_d!r}: the coupled liquid's; the fluid "
                                    f"here is {new.fluid_mode!r}")
            new = replace(new, coupling=replace(new.coupling, smoothing_diameters=float(smoothing_d)))
        # the coupled liquid's choices by name: (key, value, allowed, its CouplingSettings field)
        for key, value, allowed, field in (
                ("smoothing", smoothing, SMOOTHINGS, "smoothing"),
                ("pressure_solver", pressure_solver, PRESSURE_SOLVERS, "pressure_solver"),
                ("bead_stress_force", bead_stress_force, BEAD_STRESS_FORCES, "bead_stress_force"),
                ("vans_model", vans_model, VANS_MODELS, "model")):
            if value is None:
                continue
            if value not in allowed:
                raise DemSceneError(f"{key} = {value!r}: allowed {list(allowed)}")
            if key == "vans_model" and (new.coupling is None or new.coupling.scheme != "vans"):
                raise DemSceneError(f"{key} = {value!r}: the volume-averaged coupled liquid's; "
                                    f"the fluid here is {new.fluid_mode!r}"
                                    + ("" if new.coupling is None else f", scheme {new.coupling.scheme!r}"))
            if new.coupling is None:
                raise DemSceneError(f"{key} = {value!r}: the coupled liquid's; the fluid "
                                    f"here is {new.fluid_mode!r}")
            new = replace(new, coupling=replace(new.coupling, **{field: value}))
        why = None if new.coupling is None else _stress_force_refusal(new.coupling)
        if why is not None:
            # name the override that broke the rule: a model named without the force keeps
            # the scene's force
            if vans_model is not None and bead_stress_force is None:
                raise DemSceneError(f"vans_model = {vans_model!r}: this scene's beads take model A's "
                                    f"viscous-stress force ({new.coupling.bead_stress_force!r}); {why} "
                                    f"(give bead_stress_force = 'none')")
            raise DemSceneError(f"bead_stress_force = {new.coupling.bead_stress_force!r}: {why}")
        if wall_friction is not None:
            if isinstance(wall_friction, bool) or not isinstance(wall_friction, (int, float)):
                raise DemSceneError(f"beads.wall_friction = {wall_friction!r}: must be a float")
            new = replace(new, material=replace(new.material, wall_friction=float(wall_friction)))
        _check_ranges(new)
        return new

    @property
    def fluid_description(self) -> str:
        """One line naming the fluid model, for every output."""
        if self.fluid_mode == "none" or self.fluid is None:
            return "no fluid (beads in vacuum)"
        if self.fluid_mode == "prescribed":
            return ("prescribed swirl flow (no CFD coupling): azimuthal fluid velocity between "
                    "the rotating stirrer and the fixed chamber wall as documented in "
                    "millfmu.dem.engine.kernels.swirl_velocity; no radial/axial circulation")
        c = self.coupling
        if c.scheme == "dpm":
            return (f"coupled CFD-DEM, dilute discrete phase model (dpm): no void fraction in "
                    f"the liquid, {DPM_DRAG_NAMES[c.dpm_drag]} drag only, updated every "
                    f"{c.steps} DEM steps ({c.steps * self.dt_s:.3g} s) in the liquid's field "
                    f"frozen over the CFD step and exchange interval of {c.cfd_step_s:g} s; "
                    f"turbulence {c.turbulence}, cylindrical grid of ~{c.cell_m * 1e3:g} mm cells, "
                    f"{c.n_theta} theta cell(s)")
        smoothing = (f", smoothing split_implicit in {c.smoothing_steps} step(s)"
                     if c.smoothing == "split_implicit" else "")
        if c.pressure_solver != DEFAULT_PRESSURE_SOLVER:
            smoothing += f", pressure by {c.pressure_solver}"
        timing = (" (pressure gradient of the interval just solved)"
                  if c.model == "A" and c.pressure_gradient == "this_interval" else "")
        if c.bead_stress_force != "none":
            timing += (" with the beads' viscous-stress force (Anderson & Jackson 1967, "
                       "CFDEM's viscForce)")
        return (f"coupled CFD-DEM: volume-averaged Navier-Stokes model {c.model}{timing}, "
                f"turbulence {c.turbulence}, Koch-Hill drag, cylindrical grid of "
                f"~{c.cell_m * 1e3:g} mm cells, {c.n_theta} theta cell(s), coupling every "
                f"{c.steps} DEM steps ({c.steps * self.dt_s:.3g} s), CFD step the coupling "
                f"interval or the part of it that CFL {c.cfl:g} allows{smoothing}")


#: the [mill] keys of stationary baffles between the rotors (all or none; see
#: :class:`millfmu.dem.mills.geometry.MillGeometry`)
BAFFLE_KEYS = ("baffle_count", "baffle_thickness_m", "baffle_inner_radius_m",
               "baffle_height_m", "baffle_angle_deg")


def scene_advice(s: DemScene) -> list[str]:
    """Notes for a user about to run ``s`` (printed by ``dem run``; the run is unchanged):
    a full circle with gravity whose coupled liquid has one theta cell cannot carry the
    asymmetry; with theta cells, the faster solvers chosen by name (docs/dem-full-slices.md)."""
    c = s.coupling
    if s.fluid_mode != "coupled" or c is None:
        return []
    out = []
    if s.geometry.sector_deg == 360.0 and any(s.gravity_m_per_s2) and c.n_theta == 1:
        out.append("the full circle with gravity and a liquid of one theta cell: the liquid "
                   "is axisymmetric and cannot carry gravity's asymmetry; --theta-cells 16 "
                   "or more (16 keep 99.4 % of the once-per-turn mode)")
    if c.n_theta > 1 and c.pressure_solver != "theta_fft" and not s.geometry.baffle_count:
        out.append("theta cells without baffles: --pressure-solver theta_fft solves the same "
                   "pressure equation (to round-off) at a fraction of the direct solvers' "
                   "cost (disc full slice: a few ms per solve instead of 60-64)")
    return out


def _with_baffles(geo, d: dict, path: str):
    """``geo`` with the stationary baffles of ``d`` (keys BAFFLE_KEYS; all but the angle
    required), validated."""
    for k in d:
        if k not in BAFFLE_KEYS:
            raise DemSceneError(f"{path}.{k}: unknown baffle key; allowed: {list(BAFFLE_KEYS)}")
    kw = {k: _get(d, k, path, int if k == "baffle_count" else float,
                  required=k != "baffle_angle_deg")
          for k in BAFFLE_KEYS if k != "baffle_angle_deg" or k in d}
    return _geometry_or_error(replace, geo, **kw)


def _geometry_or_error(fn, *a, **kw):
    try:
        return fn(*a, **kw)
    except ValueError as e:
        raise DemSceneError(str(e)) from None


def _get(d: dict, key: str, path: str, kind, default=None, required=False):
    if key not in d:
        if required:
            raise DemSceneError(f"{path}.{key}: missing (required)")
        return default
    v = d[key]
    if kind is float and isinstance(v, int) and not isinstance(v, bool):
        v = float(v)
    if not isinstance(v, kind) or (kind is not bool and isinstance(v, bool)):
        raise DemSceneError(f"{path}.{key} = {v!r}: must be a {kind.__name__}")
    return v


def _positive(name: str, v: float):
    if not (v > 0 and math.isfinite(v)):
        raise DemSceneError(f"{name} = {v!r}: must be a finite number > 0")


def _check_ranges(s: DemScene):
    if s.kind == "disc_slice":
        lo, hi = DISC_SLICE_TIP_SPEED_M_PER_S
        if not lo <= s.tip_speed_m_per_s <= hi:
            raise DemSceneError(f"mill.tip_speed_m_per_s = {s.tip_speed_m_per_s!r}: allowed {lo:g} to {hi:g} "
                                f"m/s for disc_slice (the range of seed 001)")
        lo, hi = DISC_SLICE_FILLING
        if s.filling is None or not lo <= s.filling <= hi:
            raise DemSceneError(f"beads.filling = {s.filling!r}: allowed {lo:g} to {hi:g} for "
                                f"disc_slice (the range of seed 001)")
    elif s.kind == "accelerator_slice":
        lo, hi = ACCELERATOR_RPM_RANGE
        if not lo - 1e-9 <= s.rotor_speed_rpm <= hi + 1e-9:
            raise DemSceneError(
                f"mill.rotor_speed_rpm = {s.rotor_speed_rpm:.6g}: allowed {lo:g} to {hi:g} "
                f"rpm for accelerator_slice (seed 002: 800-1400; tip speed "
                f"{s.tip_speed_m_per_s:.4g} m/s)")
        flo, fhi = ACCELERATOR_FILLING
        if s.filling is None or not flo <= s.filling <= fhi:
            raise DemSceneError(f"beads.filling = {s.filling!r}: allowed {flo:g} to {fhi:g} for "
                                f"accelerator_slice (seed 002: 0.6-0.9)")
    else:
        _positive("mill.tip_speed_m_per_s", s.tip_speed_m_per_s)
    for name, v in (("run.dt_s", s.dt_s), ("run.record_s", s.record_s),
                    ("run.sample_every_s", s.sample_every_s)):
        _positive(name, v)
    if s.spin_up_s < 0:
        raise DemSceneError(f"run.spin_up_s = {s.spin_up_s!r}: must be >= 0")
    c = s.coupling
    if s.fluid_mode == "coupled" and c is not None and c.n_theta > 1:
        sector = math.radians(s.geometry.sector_deg)
        if sector / c.n_theta > MAX_THETA_CELL_RAD:
            need = least_theta_cells(sector)
            raise DemSceneError(
                f"fluid.coupled.n_theta = {c.n_theta}: theta cells of "
                f"{sector / c.n_theta:.3g} rad over the {s.geometry.sector_deg:g} degree "
                f"sector, wider than the {MAX_THETA_CELL_RAD:g} rad the liquid's grid allows; "
                f"use 1 (axisymmetric with swirl) or at least {need}")
    if not 0.0 <= s.initial_rotation <= 1.0:
        raise DemSceneError(f"run.initial_rotation = {s.initial_rotation!r}: allowed 0 to 1 "
                            f"(a fraction of the stirrer's angular velocity)")
    if not 0.0 <= s.primed_s <= 10.0:
        raise DemSceneError(f"run.primed_s = {s.primed_s!r}: allowed 0 to 10 s (bead-free "
                            f"liquid time before the beads are put in)")
    if s.primed_s > 0.0 and s.fluid_mode != "coupled":
        raise DemSceneError(f"run.primed_s = {s.primed_s!r}: a primed start needs the coupled "
                            f"fluid (fluid.mode = 'coupled', not {s.fluid_mode!r})")
    m = s.material
    if not 0.0 < m.restitution <= 1.0:
        raise DemSceneError(f"beads.restitution = {m.restitution!r}: allowed 0 < e <= 1")
    if not -1.0 < m.poisson_ratio < 0.5:
        raise DemSceneError(f"beads.poisson_ratio = {m.poisson_ratio!r}: allowed -1 < nu < 0.5")
    for name, v in (("beads.friction", m.friction), ("beads.rolling_friction", m.rolling_friction),
                    ("beads.wall_friction", m.wall_friction),
                    ("beads.wall_rolling_friction", m.wall_rolling_friction)):
        if v is not None and not (v >= 0 and math.isfinite(v)):
            raise DemSceneError(f"{name} = {v!r}: must be a finite number >= 0")
    if s.geometry.sector_deg != 360.0 and any(s.gravity_m_per_s2):
        raise DemSceneError(
            f"run.gravity_m_per_s2 = {list(s.gravity_m_per_s2)!r}: an angular sector "
            f"(mill.sector_deg = {s.geometry.sector_deg}) is rotationally periodic only "
            f"without gravity; set gravity to [0, 0, 0] or use the full circle")


def load_scene_dict(name_or_path: str) -> dict:
    """A DEM scene's TOML content as a dict (``name`` defaulting to the file's stem): a
    shipped scene name (``annulus``, ``disc_slice``) or a .toml path. Not validated."""
    p = Path(name_or_path)
    if not p.suffix:
        cand = SCENE_DIR / f"{name_or_path}.toml"
        if not cand.exists():
            shipped = sorted(q.stem for q in SCENE_DIR.glob("*.toml"))
            raise DemSceneError(f"scene {name_or_path!r}: no such shipped scene; "
                                f"shipped: {shipped}, or give a .toml path")
        p = cand
    if not p.exists():
        raise DemSceneError(f"scene file {str(p)!r}: not found")
    try:
        raw = p.read_bytes()
    except OSError as e:
        raise DemSceneError(f"scene file {str(p)!r}: cannot be read ({e.strerror or e})") from None
    try:
        text = utf8_text(raw)
    except NotUtf8 as e:
        raise DemSceneError(f"scene file {str(p)!r}: not UTF-8 text at byte {e.start} (line {e.line}); save it as "
                            "UTF-8 (TOML)") from None
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise DemSceneError(f"scene file {str(p)!r}: not valid TOML ({e})") from None
    d.setdefault("name", p.stem)
    return current_spelling(d, f"scene file {str(p)!r}")


def current_spelling(d: dict, what: str = "DEM scene") -> dict:
    """``d`` with an earlier release's unit suffixes in its keys in the current spelling
    (:mod:`millfmu.unit_names`), with a note naming each (FutureWarning); a key given in
    both spellings is refused by name."""
    try:
        return read_as_current(d, what, stacklevel=3)
    except ValueError as e:
        raise DemSceneError(f"{what}: {e}") from None


def load_scene(name_or_path: str) -> DemScene:
    """Load a shipped scene by name (``annulus``, ``disc_slice``) or a TOML file path."""
    return scene_from_dict(load_scene_dict(name_or_path))


def scene_from_dict(d: dict, default_name: str = "scene") -> DemScene:
    """The scene of a scene file's tables (``d``: parsed TOML), validated: unknown keys,
    missing required values and values out of range are refused by name
    (DemSceneError)."""
    d = current_spelling(d)
    known = {"name", "kind", "mill", "beads", "fluid", "run", "zones", "output"}
    for k in d:
        if k not in known:
            raise DemSceneError(f"{k}: unknown top-level key; allowed: {sorted(known)}")
    kind = _get(d, "kind", "scene", str, required=True)
    if kind not in KINDS:
        raise DemSceneError(f"scene.kind = {kind!r}: allowed {list(KINDS)}")
    mill = d.get("mill", {})
    beads = d.get("beads", {})
    run = d.get("run", {})
    output = d.get("output", {})
    f = float
    for table, keys, allowed in (("beads", beads, BEAD_KEYS), ("mill", mill, mill_keys(kind)),
                                 ("run", run, RUN_KEYS), ("output", output, OUTPUT_KEYS)):
        for k in keys:
            if k not in allowed:
                raise DemSceneError(f"{table}.{k}: unknown key" + (f" for {kind}" if table == "mill" else "")
                                    + f"; allowed: {sorted(allowed)}")
    geo = _geometry_from_dict(kind, mill)
    dia = _get(beads, "diameter_m", "beads", f, 0.8e-3)
    _positive("beads.diameter_m", dia)
    mat = _material_from_dict(beads)
    placement, filling, spacing_m, r_range = _placement_from_dict(beads, dia, geo)
    mode, fl, cpl = _fluid_from_dict(d.get("fluid", {}), dia)
    grav = _get(run, "gravity_m_per_s2", "run", list, [0.0, 0.0, 0.0])
    if len(grav) != 3:
        raise DemSceneError(f"run.gravity_m_per_s2 = {grav!r}: must be a list of 3 numbers")
    zs = _zones_from_dict(kind, d.get("zones", {}))
    tip = _tip_speed(kind, mill, geo)
    s = DemScene(
        name=_get(d, "name", "scene", str, default_name), kind=kind, geometry=geo,
        material=mat, bead_diameter_m=dia,
        tip_speed_m_per_s=tip,
        placement=placement, filling=filling,
        bulk_porosity=_get(beads, "bulk_porosity", "beads", f, 0.4),
        lattice_spacing_m=spacing_m, lattice_r_range_m=r_range, fluid=fl,
        fluid_mode=mode, coupling=cpl, gravity_m_per_s2=tuple(float(g) for g in grav),
        dt_s=_get(run, "dt_s", "run", f, 5e-6),
        spin_up_s=_get(run, "spin_up_s", "run", f, 2.0),
        record_s=_get(run, "record_s", "run", f, 1.0),
        sample_every_s=_get(run, "sample_every_s", "run", f, 0.02),
        seed=_get(run, "seed", "run", int, 1), zones=zs,
        initial_rotation=_get(run, "initial_rotation", "run", f, 0.0),
        primed_s=_get(run, "primed_s", "run", f, 0.0),
        map_bins_r=_get(output, "map_bins_r", "output", int, 30),
        map_bins_z=_get(output, "map_bins_z", "output", int, 28))
    _check_ranges(s)
    return s


def _geometry_from_dict(kind: str, mill: dict) -> MillGeometry:
    """The mill's geometry of a ``[mill]`` table for a scene of ``kind`` (with its
    stationary baffles where the table names them)."""
    f = float
    rsh = _get(mill, "shaft_radius_m", "mill", f, 0.015)
    rch = _get(mill, "chamber_radius_m", "mill", f, 0.045)
    sector = _get(mill, "sector_deg", "mill", f, 360.0)
    if kind == "disc_slice":
        rd = _get(mill, "disc_radius_m", "mill", f, 0.036)
        bd = _get(mill, "disc_thickness_m", "mill", f, 0.008)
        spacing = _get(mill, "disc_spacing_m", "mill", f, 0.020)
        _positive("mill.disc_spacing_m", spacing)
        geo = _geometry_or_error(MillGeometry, rsh, rch, spacing + bd, rd, bd, 0.0, sector)
    elif kind == "accelerator_slice":
        rd = _get(mill, "rotor_radius_m", "mill", f, required=True)
        bd = _get(mill, "rotor_thickness_m", "mill", f, required=True)
        period = _get(mill, "rotor_pitch_m", "mill", f, required=True)
        _positive("mill.rotor_pitch_m", period)
        geo = _geometry_or_error(
            MillGeometry, rsh, rch, period, rd, bd, 0.0, sector,
            eye_radius_m=_get(mill, "eye_radius_m", "mill", f, required=True),
            channel_height_m=_get(mill, "channel_height_m", "mill", f, required=True),
            vane_count=_get(mill, "vane_count", "mill", int, required=True),
            vane_thickness_m=_get(mill, "vane_thickness_m", "mill", f, required=True))
    else:
        h = _get(mill, "height_m", "mill", f, 0.004)
        geo = _geometry_or_error(MillGeometry, rsh, rch, h, 0.0, 0.0, 0.0, sector)
    if any(k in mill for k in BAFFLE_KEYS):
        geo = _with_baffles(geo, {k: mill[k] for k in BAFFLE_KEYS if k in mill}, "mill")
    return geo


#: the keys of a scene's ``[mill]`` table for every kind, and those of each kind
MILL_KEYS = ("shaft_radius_m", "chamber_radius_m", "sector_deg", "tip_speed_m_per_s") + BAFFLE_KEYS
MILL_KIND_KEYS = {"disc_slice": ("disc_radius_m", "disc_thickness_m", "disc_spacing_m"),
                  "accelerator_slice": ("rotor_radius_m", "rotor_thickness_m", "rotor_pitch_m",
                                        "eye_radius_m", "channel_height_m", "vane_count",
                                        "vane_thickness_m", "rotor_speed_rpm"),
                  "annulus": ("height_m",)}
#: the keys of a scene's ``[run]`` and ``[output]`` tables
RUN_KEYS = ("gravity_m_per_s2", "dt_s", "spin_up_s", "record_s", "sample_every_s", "seed",
            "initial_rotation", "primed_s")
OUTPUT_KEYS = ("map_bins_r", "map_bins_z")
#: the keys of a disc mill's (and an annulus's) ``[zones]`` table: seed 001's V1-V4
DISC_ZONE_KEYS = ("v1_width_m", "r_v1_over_disc_radius", "r_v3_over_disc_radius")


def mill_keys(kind: str) -> tuple:
    """The keys a ``[mill]`` table of a scene of ``kind`` may hold."""
    return MILL_KEYS + MILL_KIND_KEYS.get(kind, ())


#: the keys of a scene's ``[beads]`` table
BEAD_KEYS = ("diameter_m", "density_kg_per_m3", "youngs_modulus_pa", "poisson_ratio",
             "restitution", "friction", "rolling_friction", "wall_friction",
             "wall_rolling_friction", "bulk_porosity", "placement", "filling",
             "lattice_spacing_m", "lattice_r_range_m")


def _material_from_dict(beads: dict) -> BeadMaterial:
    """The bead material of a ``[beads]`` table (defaults: seed 001's glass)."""
    f = float
    mat = BeadMaterial(
        density_kg_per_m3=_get(beads, "density_kg_per_m3", "beads", f, 2510.0),
        youngs_modulus_pa=_get(beads, "youngs_modulus_pa", "beads", f, 6.3e6),
        poisson_ratio=_get(beads, "poisson_ratio", "beads", f, 0.25),
        restitution=_get(beads, "restitution", "beads", f, 0.99),
        friction=_get(beads, "friction", "beads", f, 0.3),
        rolling_friction=_get(beads, "rolling_friction", "beads", f, 0.10),
        wall_friction=_get(beads, "wall_friction", "beads", f, None),
        wall_rolling_friction=_get(beads, "wall_rolling_friction", "beads", f, None))
    _positive("beads.density_kg_per_m3", mat.density_kg_per_m3)
    _positive("beads.youngs_modulus_pa", mat.youngs_modulus_pa)
    return mat


def _placement_from_dict(beads: dict, dia: float, geo: MillGeometry):
    """(placement, filling, lattice spacing [m], lattice radii (r_min, r_max) [m]) of a
    ``[beads]`` table: ``filling`` needs the filling, ``lattice`` its spacing (at least
    the bead diameter ``dia`` [m]) and radii between shaft and chamber."""
    f = float
    placement = _get(beads, "placement", "beads", str, "filling")
    if placement not in ("filling", "lattice"):
        raise DemSceneError(f"beads.placement = {placement!r}: allowed 'filling', 'lattice'")
    filling = _get(beads, "filling", "beads", f, None)
    spacing_m = r_range = None
    if placement == "filling":
        if filling is None:
            raise DemSceneError("beads.filling: missing (required with placement 'filling')")
        return placement, filling, spacing_m, r_range
    rsh, rch = geo.shaft_radius_m, geo.chamber_radius_m
    spacing_m = _get(beads, "lattice_spacing_m", "beads", f, required=True)
    r_range = _get(beads, "lattice_r_range_m", "beads", list, required=True)
    if len(r_range) != 2 or not rsh < float(r_range[0]) < float(r_range[1]) < rch:
        raise DemSceneError(f"beads.lattice_r_range_m = {r_range!r}: need [r_min, r_max] "
                            f"with shaft radius < r_min < r_max < chamber radius")
    r_range = (float(r_range[0]), float(r_range[1]))
    if spacing_m < dia:
        raise DemSceneError(f"beads.lattice_spacing_m = {spacing_m!r}: must be >= the "
                            f"bead diameter {dia}")
    return placement, filling, spacing_m, r_range


def _zones_from_dict(kind: str, zones: dict):
    """The zone set of a ``[zones]`` table: seed 002's SEV_1-4 bounds for an accelerator
    slice, else seed 001's V1-V4."""
    f = float
    if kind != "accelerator_slice":
        for k in zones:
            if k not in DISC_ZONE_KEYS:
                raise DemSceneError(f"zones.{k}: unknown key for {kind}; allowed: {sorted(DISC_ZONE_KEYS)}")
        return ZoneSpec(v1_width_m=_get(zones, "v1_width_m", "zones", f, 2.5e-3),
                        r_v1_over_disc_radius=_get(zones, "r_v1_over_disc_radius", "zones",
                                                   f, 0.55),
                        r_v3_over_disc_radius=_get(zones, "r_v3_over_disc_radius", "zones",
                                                   f, 0.80))
    for k in zones:
        if k not in ("sev_z1", "sev_z2", "sev_x3"):
            raise DemSceneError(f"zones.{k}: unknown key for accelerator_slice; allowed: "
                                f"['sev_x3', 'sev_z1', 'sev_z2']")
    zs = SevSpec(z1=_get(zones, "sev_z1", "zones", f, 0.39),
                 z2=_get(zones, "sev_z2", "zones", f, 0.69),
                 x3=_get(zones, "sev_x3", "zones", f, 0.40))
    if not 0.0 < zs.z1 < zs.z2 < 1.0 or not 0.0 < zs.x3 < 1.0:
        raise DemSceneError(f"zones.sev_z1 = {zs.z1!r}, sev_z2 = {zs.z2!r}, sev_x3 = "
                            f"{zs.x3!r}: need 0 < z1 < z2 < 1 and 0 < x3 < 1")
    return zs


def _tip_speed(kind: str, mill: dict, geo: MillGeometry) -> float:
    """The stirrer's tip speed [m/s]: ``mill.tip_speed_m_per_s``, or for an accelerator slice
    ``mill.rotor_speed_rpm`` at the rotor radius (one of the two, never both)."""
    f = float
    tip = _get(mill, "tip_speed_m_per_s", "mill", f, None)
    rpm = _get(mill, "rotor_speed_rpm", "mill", f, None) if kind == "accelerator_slice" \
        else None
    if rpm is not None:
        if tip is not None:
            raise DemSceneError(f"mill.rotor_speed_rpm = {rpm!r} and mill.tip_speed_m_per_s = "
                                f"{tip!r}: give one of them")
        _positive("mill.rotor_speed_rpm", rpm)
        tip = rpm * 2.0 * math.pi / 60.0 * geo.disc_radius_m
    if tip is None:
        raise DemSceneError("mill.tip_speed_m_per_s: missing (required" +
                            (", or mill.rotor_speed_rpm)" if kind == "accelerator_slice"
                             else ")"))
    return tip


_FLUID_KEYS = {"mode", "enabled", "density_kg_per_m3", "viscosity_Pa_s", "drag", "lubrication",
               "lubrication_cutoff_m", "lubrication_min_gap_m", "swirl_core_fraction",
               "swirl_layer_m", "void_fraction", "wet_collisions", "coupled"}
#: how collisions lose energy to the liquid ([fluid] wet_collisions): the simulation's names
WET_COLLISIONS = tuple(DemSimulation.WET_COLLISIONS)
_COUPLED_KEYS = {"vans_model": str, "turbulence": str, "coupling_steps": int, "cell_m": float,
                 "n_theta": int, "smoothing_diameters": float, "eps_min": float,
                 "cfl": float, "scheme": str, "cfd_step_s": float,
                 "pressure_gradient": str, "smoothing": str, "smoothing_steps": int,
                 "pressure_solver": str, "dpm_drag": str, "bead_stress_force": str}


def _fluid_from_dict(fluid: dict, dia: float):
    """(mode, FluidSettings or None, CouplingSettings or None) of a ``[fluid]`` table."""
    for k in fluid:
        if k not in _FLUID_KEYS:
            raise DemSceneError(f"fluid.{k}: unknown key; allowed: {sorted(_FLUID_KEYS)}")
    enabled = _get(fluid, "enabled", "fluid", bool, None)
    mode = _get(fluid, "mode", "fluid", str, None)
    if mode is None:
        mode = "none" if enabled is False else "prescribed"
    if mode not in FLUID_MODES:
        raise DemSceneError(f"fluid.mode = {mode!r}: allowed {list(FLUID_MODES)}")
    if enabled is not None and (enabled is False) != (mode == "none"):
        raise DemSceneError(f"fluid.enabled = {enabled!r} contradicts fluid.mode = {mode!r}; "
                            f"leave out 'enabled' (mode 'none' switches the fluid off)")
    if mode == "none":
        return mode, None, None
    f = float
    wet = _get(fluid, "wet_collisions", "fluid", str, "lubrication")
    if wet not in WET_COLLISIONS:
        raise DemSceneError(f"fluid.wet_collisions = {wet!r}: allowed {list(WET_COLLISIONS)} "
                            f"(the lubrication force between close beads, seed 001; or the "
                            f"restitution per contact of Legendre et al. 2006)")
    lub = _get(fluid, "lubrication", "fluid", bool, wet == "lubrication")
    if wet == "legendre2006" and lub:
        raise DemSceneError("fluid.lubrication = true with fluid.wet_collisions = "
                            "'legendre2006': the published restitution includes the liquid "
                            "film's damping; set lubrication = false or leave it out")
    fl = FluidSettings(
        density_kg_per_m3=_get(fluid, "density_kg_per_m3", "fluid", f, 998.2),
        viscosity_Pa_s=_get(fluid, "viscosity_Pa_s", "fluid", f, 1.002e-3),
        drag=_get(fluid, "drag", "fluid", bool, True) and mode == "prescribed",
        lubrication=lub, wet_collisions=wet,
        lubrication_cutoff_m=_get(fluid, "lubrication_cutoff_m", "fluid", f, 0.05 * dia),
        lubrication_min_gap_m=_get(fluid, "lubrication_min_gap_m", "fluid", f, 5e-4 * dia),
        swirl_core_fraction=_get(fluid, "swirl_core_fraction", "fluid", f, 0.25),
        swirl_layer_m=_get(fluid, "swirl_layer_m", "fluid", f, 0.7e-3),
        void_fraction=_get(fluid, "void_fraction", "fluid", f, 0.5))
    if not 0.0 < fl.void_fraction < 1.0:
        raise DemSceneError(f"fluid.void_fraction = {fl.void_fraction!r}: allowed 0 < "
                            f"eps < 1")
    _positive("fluid.density_kg_per_m3", fl.density_kg_per_m3)
    _positive("fluid.viscosity_Pa_s", fl.viscosity_Pa_s)
    _positive("fluid.swirl_layer_m", fl.swirl_layer_m)
    cpl = _coupling_from_dict(_get(fluid, "coupled", "fluid", dict, {}))
    return mode, fl, cpl if mode == "coupled" else None


#: the volume-averaged liquid's models: A (the beads feel the pressure gradient and the drag)
#: and B (the drag alone, over the void fraction)
VANS_MODELS = ("A", "B")


def _stress_force_refusal(c: CouplingSettings) -> str | None:
    """Why the coupling ``c`` cannot give its beads model A's viscous-stress force, or None
    where it can (or has none): the one place of this rule for scene files and overrides."""
    if c.bead_stress_force == "none" or (c.scheme == "vans" and c.model == "A"):
        return None
    return (f"only model A (vans_model = 'A', scheme 'vans') gives the beads the generalized "
            f"buoyancy; this liquid is scheme {c.scheme!r}, model {c.model!r} (model B's drag over "
            f"eps carries it, the discrete phase model has no stresses of the mixture)")


def _coupling_from_dict(c: dict) -> CouplingSettings:
    for k in c:
        if k not in _COUPLED_KEYS:
            raise DemSceneError(f"fluid.coupled.{k}: unknown key; allowed: "
                                f"{sorted(_COUPLED_KEYS)}")
    d = CouplingSettings()
    kw = {}
    for k, kind in _COUPLED_KEYS.items():
        kw[k] = _get(c, k, "fluid.coupled", kind, None)
    out = CouplingSettings(
        model=kw["vans_model"] if kw["vans_model"] is not None else d.model,
        turbulence=kw["turbulence"] if kw["turbulence"] is not None else d.turbulence,
        steps=kw["coupling_steps"] if kw["coupling_steps"] is not None else d.steps,
        cell_m=kw["cell_m"] if kw["cell_m"] is not None else d.cell_m,
        n_theta=kw["n_theta"] if kw["n_theta"] is not None else d.n_theta,
        smoothing_diameters=(kw["smoothing_diameters"] if kw["smoothing_diameters"]
                             is not None else d.smoothing_diameters),
        eps_min=kw["eps_min"] if kw["eps_min"] is not None else d.eps_min,
        cfl=kw["cfl"] if kw["cfl"] is not None else d.cfl,
        scheme=kw["scheme"] if kw["scheme"] is not None else d.scheme,
        cfd_step_s=kw["cfd_step_s"] if kw["cfd_step_s"] is not None else d.cfd_step_s,
        pressure_gradient=(kw["pressure_gradient"] if kw["pressure_gradient"] is not None
                           else d.pressure_gradient),
        smoothing=kw["smoothing"] if kw["smoothing"] is not None else d.smoothing,
        smoothing_steps=(kw["smoothing_steps"] if kw["smoothing_steps"] is not None
                         else d.smoothing_steps),
        pressure_solver=(kw["pressure_solver"] if kw["pressure_solver"] is not None
                         else d.pressure_solver),
        dpm_drag=kw["dpm_drag"] if kw["dpm_drag"] is not None else d.dpm_drag,
        bead_stress_force=(kw["bead_stress_force"] if kw["bead_stress_force"] is not None
                           else d.bead_stress_force))
    if out.pressure_solver not in PRESSURE_SOLVERS:
        raise DemSceneError(f"fluid.coupled.pressure_solver = {out.pressure_solver!r}: "
                            f"allowed {list(PRESSURE_SOLVERS)}")
    if out.smoothing not in SMOOTHINGS:
        raise DemSceneError(f"fluid.coupled.smoothing = {out.smoothing!r}: allowed "
                            f"{list(SMOOTHINGS)}")
    if not 1 <= out.smoothing_steps <= 64:
        raise DemSceneError(f"fluid.coupled.smoothing_steps = {out.smoothing_steps!r}: "
                            f"allowed 1 to 64")
    if kw["smoothing_steps"] is not None and out.smoothing != "split_implicit":
        raise DemSceneError(f"fluid.coupled.smoothing_steps = {out.smoothing_steps!r}: only "
                            f"smoothing = 'split_implicit' takes steps (the explicit sweeps "
                            f"are as many as the cells need); leave it out")
    if out.scheme not in COUPLING_SCHEMES:
        raise DemSceneError(f"fluid.coupled.scheme = {out.scheme!r}: allowed "
                            f"{list(COUPLING_SCHEMES)}")
    _positive("fluid.coupled.cfd_step_s", out.cfd_step_s)
    if out.dpm_drag not in DPM_DRAG_LAWS:
        raise DemSceneError(f"fluid.coupled.dpm_drag = {out.dpm_drag!r}: allowed "
                            f"{list(DPM_DRAG_LAWS)}")
    if kw["dpm_drag"] is not None and out.scheme != "dpm":
        raise DemSceneError(f"fluid.coupled.dpm_drag = {out.dpm_drag!r} with scheme "
                            f"{out.scheme!r}: only the discrete phase model (scheme 'dpm') "
                            f"takes a drag law by name (the volume-averaged scheme's is Koch "
                            f"and Hill's); leave it out")
    if out.scheme == "dpm" and kw["vans_model"] is not None:
        raise DemSceneError(f"fluid.coupled.vans_model = {out.model!r} with scheme 'dpm': "
                            f"the discrete phase model has no volume-averaged equations "
                            f"(drag only); leave out vans_model")
    if out.pressure_gradient not in PRESSURE_GRADIENT_TIMINGS:
        raise DemSceneError(f"fluid.coupled.pressure_gradient = {out.pressure_gradient!r}: "
                            f"allowed {list(PRESSURE_GRADIENT_TIMINGS)}")
    if kw["pressure_gradient"] is not None and (out.scheme == "dpm" or out.model != "A"):
        raise DemSceneError(f"fluid.coupled.pressure_gradient = {out.pressure_gradient!r}: "
                            f"only model A (vans_model = 'A', scheme 'vans') gives the beads a "
                            f"pressure-gradient force; leave it out")
    if out.model not in VANS_MODELS:
        raise DemSceneError(f"fluid.coupled.vans_model = {out.model!r}: allowed {list(VANS_MODELS)}")
    if out.bead_stress_force not in BEAD_STRESS_FORCES:
        raise DemSceneError(f"fluid.coupled.bead_stress_force = {out.bead_stress_force!r}: "
                            f"allowed {list(BEAD_STRESS_FORCES)}")
    why = _stress_force_refusal(out)
    if why is not None:
        raise DemSceneError(f"fluid.coupled.bead_stress_force = {out.bead_stress_force!r}: {why}")
    if out.turbulence not in ("k_epsilon", "laminar"):
        raise DemSceneError(f"fluid.coupled.turbulence = {out.turbulence!r}: allowed "
                            f"'k_epsilon', 'laminar'")
    if out.steps < 1:
        raise DemSceneError(f"fluid.coupled.coupling_steps = {out.steps!r}: must be >= 1")
    if out.n_theta < 1:
        raise DemSceneError(f"fluid.coupled.n_theta = {out.n_theta!r}: must be >= 1")
    _positive("fluid.coupled.cell_m", out.cell_m)
    if not out.smoothing_diameters >= 0.0:
        raise DemSceneError(f"fluid.coupled.smoothing_diameters = "
                            f"{out.smoothing_diameters!r}: must be >= 0")
    if not 0.1 <= out.eps_min < 0.9:
        raise DemSceneError(f"fluid.coupled.eps_min = {out.eps_min!r}: allowed 0.1 to 0.9")
    if not 0.0 < out.cfl <= 0.5:
        raise DemSceneError(f"fluid.coupled.cfl = {out.cfl!r}: allowed 0 < cfl <= 0.5")
    return out


def _with_fluid_mode(scene: DemScene, mode: str) -> DemScene:
    """The scene with another fluid mode (CLI/table override): liquid properties kept,
    the coupled options the scene's (or the defaults)."""
    if mode not in FLUID_MODES:
        raise DemSceneError(f"fluid mode = {mode!r}: allowed {list(FLUID_MODES)}")
    if mode == "none":
        return replace(scene, fluid=None, fluid_mode=mode, coupling=None)
    fl = scene.fluid if scene.fluid is not None else FluidSettings(
        lubrication_cutoff_m=0.05 * scene.bead_diameter_m,
        lubrication_min_gap_m=5e-4 * scene.bead_diameter_m)
    fl = replace(fl, drag=(mode == "prescribed"))
    cpl = (scene.coupling or CouplingSettings()) if mode == "coupled" else None
    return replace(scene, fluid=fl, fluid_mode=mode, coupling=cpl)
