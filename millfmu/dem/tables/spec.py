"""What a stress-energy table is and what names it: the grid axes, the per-zone fields and
the normalized energy bins (the file format), the normalization by E_ref and omega n_gb, and
:class:`TableSpec` (scene, grid, kernel version, builder), whose key names a cache entry,
with what a table's manifest states (:func:`manifest_for`, :func:`resolution_of`).

A table holds, for a grid of operating points, what the detailed breakage model needs from
the DEM, per zone (V1-V4 of :mod:`millfmu.dem.zones`):

- ``volume_fraction`` [-]: zone volume over the bead-accessible cell volume;
- ``filling_local`` [-]: time-averaged local bead filling (seed 001 eq. 2);
- ``speed_over_tip_speed`` [-]: mean bead speed over the stirrer tip speed;
- ``collision_frequency_norm`` [-]: bead-bead collisions per zone volume and time over
  omega n_gb (omega the stirrer angular velocity [rad/s], n_gb the chamber-mean bead number
  concentration [1/m3] at the grid point's filling, seed 000 eq. 3, the same reference as
  :class:`millfmu.kinetics.stress_distribution.LogNormalStressSource`);
- ``collision_power_norm`` [-]: collision power per zone volume over E_ref omega n_gb;
- ``se_density`` [1/decade]: number density over log10(SE / E_ref) on the fixed bins
  ``norm_log10_edges``, per component ``tn``, ``ts``, ``total``;
- ``se_quantiles_norm`` [-]: 10/50/90 % quantiles of SE / E_ref (NaN without collisions).

E_ref = 1/2 m_bead v_t^2 = pi/12 d^3 rho v_t^2 [J] is the bead's kinetic energy at tip speed
(Kwade's SE_GM, seed 000 eq. 1). Storing energies over E_ref and frequencies over
omega n_gb removes the leading dependence on tip speed, bead size and density; the
remaining dependence (Stokes number, filling) is what the grid resolves.

Part of what an FMU carries: numpy only.
"""

from __future__ import annotations

import itertools
import json
import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .files import canonical_json, sha256_bytes

if TYPE_CHECKING:
    from .table import Table


FORMAT_VERSION = 1


#: Grid axes a table may have: name -> (scene section, scene key, unit, OperatingPoint field).
AXES = {
    "tip_speed_m_s": ("mill", "tip_speed_m_s", "m/s", "tip_speed_m_per_s"),
    "filling": ("beads", "filling", "-", "filling"),
    "bead_diameter_m": ("beads", "diameter_m", "m", "d_gb_m"),
    "bead_density_kg_m3": ("beads", "density_kg_m3", "kg/m3", "rho_gb_kg_per_m3"),
    "viscosity_pa_s": ("fluid", "viscosity_pa_s", "Pa s", "eta_susp_Pa_s"),
}
COMPONENTS = ("tn", "ts", "total")
QUANTILE_NAMES = ("q10", "q50", "q90")
# Normalized energy bins, log10(SE / E_ref): DEM energies span 1e-20 to 1 J (seed 001) and
# E_ref of 0.1-3 mm beads at 1-20 m/s lies between 1e-9 and 1e-1 J, so -16..2 holds what the
# DEM bins hold with room; 5 bins per decade as in millfmu.dem.stats.
NORM_LOG10_MIN = -16.0
NORM_LOG10_MAX = 2.0
NORM_BINS_PER_DECADE = 5
#: Per-zone fields of a grid point and their trailing shape (Z zones, C components,
#: B bins, Q quantiles).
ZONE_FIELDS = ("volume_fraction", "filling_local", "speed_over_tip_speed",
               "collision_frequency_norm", "collision_power_norm", "collision_count")
FIELDS = ZONE_FIELDS + ("se_density", "se_quantiles_norm")
#: Per-zone columns of a DEM run's windows.csv whose drift between the halves of the
#: recording a table keeps (and its manifest summarizes as "stationarity").
DRIFT_FIELDS = ("filling", "speed_over_tip_speed", "collision_frequency_per_m3_s",
                "se_tn_q50_j")
#: Optional per-point field: relative drift of :data:`DRIFT_FIELDS` per zone between the
#: halves of the point's DEM recording, trailing shape (len(DRIFT_FIELDS), Z); NaN where a
#: zone had nothing to compare. Tables without it (analytic builders) read as before.
OPTIONAL_FIELDS = ("recording_drift",)


#: Builder id of the DEM builder (:class:`millfmu.dem.tables.dem_builder.DemBuilder`): part
#: of every DEM table's key, so it keeps the name the builder had when tables were one module.
DEM_BUILDER_ID = "millfmu.dem.tables.DemBuilder"


class TableError(ValueError):
    """A table, grid, entry or lookup that is not allowed."""


def norm_log10_edges() -> np.ndarray:
    """Bin edges of log10(SE / E_ref) [-] shared by all tables."""
    n = int(round((NORM_LOG10_MAX - NORM_LOG10_MIN) * NORM_BINS_PER_DECADE))
    return np.linspace(NORM_LOG10_MIN, NORM_LOG10_MAX, n + 1)


def e_ref_J(d_gb_m: float, rho_gb_kg_m3: float, v_t_m_s: float) -> float:
    """Bead kinetic energy at tip speed, E_ref = 1/2 m v_t^2 = pi/12 d^3 rho v_t^2 [J]."""
    return math.pi / 12.0 * d_gb_m ** 3 * rho_gb_kg_m3 * v_t_m_s ** 2


def n_gb_per_m3(filling: float, porosity: float, d_gb_m: float) -> float:
    """Chamber-mean bead number concentration phi (1 - eps) / (pi d^3 / 6) [1/m3]."""
    return filling * (1.0 - porosity) / (math.pi * d_gb_m ** 3 / 6.0)


def builder_id_of(builder) -> str:
    """A builder's id for ``TableSpec.builder_id``: its ``builder_id`` attribute, else
    MODULE.QUALNAME."""
    bid = getattr(builder, "builder_id", None)
    if bid:
        return str(bid)
    return f"{builder.__module__}.{getattr(builder, '__qualname__', type(builder).__name__)}"


@dataclass(frozen=True)
class TableSpec:
    """What a table is built from: DEM scene content (the scene TOML as a dict, run settings
    included), grid (axis -> ascending values, axes from :data:`AXES`), the DEM kernel
    version and the builder's id. Its :meth:`key` names the cache entry."""

    scene: dict
    grid: dict
    kernel_version: str
    builder_id: str = DEM_BUILDER_ID

    def __post_init__(self):
        if not self.grid:
            raise TableError("grid: no axes; give at least one of " + ", ".join(AXES))
        clean = {}
        for name, vals in self.grid.items():
            if name not in AXES:
                raise TableError(f"grid axis {name!r}: unknown; allowed: {list(AXES)}")
            v = [float(x) for x in vals]
            if not v:
                raise TableError(f"grid axis {name}: no values")
            if not all(math.isfinite(x) and x > 0 for x in v):
                raise TableError(f"grid axis {name} = {v!r}: values must be finite and > 0")
            if any(b <= a for a, b in zip(v, v[1:])):
                raise TableError(f"grid axis {name} = {v!r}: values must be strictly ascending")
            clean[name] = tuple(v)
        # A fixed order (that of AXES) so that equal grids give equal keys.
        object.__setattr__(self, "grid", {k: clean[k] for k in AXES if k in clean})
        json.loads(canonical_json(self.scene))  # plain JSON content only

    @property
    def shape(self) -> tuple:
        return tuple(len(v) for v in self.grid.values())

    def points(self) -> list[dict]:
        """Grid points in C order (last axis fastest): axis -> value."""
        names = list(self.grid)
        return [dict(zip(names, combo)) for combo in itertools.product(*self.grid.values())]

    def key_content(self) -> dict:
        return {"format": FORMAT_VERSION, "builder": self.builder_id, "scene": self.scene,
                "grid": {k: list(v) for k, v in self.grid.items()},
                "kernel_version": self.kernel_version}

    def key(self) -> str:
        return sha256_bytes(canonical_json(self.key_content()).encode())


def scene_at_point(scene: dict, point: dict) -> dict:
    """Copy of the scene dict with the grid point's values put at their scene keys."""
    d = json.loads(canonical_json(scene))
    for axis, value in point.items():
        sec, key = AXES[axis][0], AXES[axis][1]
        d.setdefault(sec, {})[key] = float(value)
        if key == "tip_speed_m_s":
            # an accelerator scene may give its speed in rpm instead: the point's tip
            # speed replaces it
            d[sec].pop("rotor_speed_rpm", None)
    return d


def manifest_for(spec: TableSpec, table: Table, extra: dict | None = None) -> dict:
    """The manifest of a table built from ``spec``: the key content, key, creation
    time, resolution, build wall time and stationarity, and ``extra``."""
    m = dict(spec.key_content())
    m["key"] = spec.key()
    m["created_utc"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    m["resolution"] = resolution_of(spec)
    m["build_wall_time_s"] = table.manifest.get("build_wall_time_s")
    if "stationarity" in table.manifest:
        m["stationarity"] = table.manifest["stationarity"]
    if extra:
        m.update(extra)
    return m


#: Spin-up below which a table's manifest notes that the bead fillings still drift. With the
#: prescribed swirl flow, bead speeds and collision energies settle within 0.04 s, but the
#: beads keep moving outwards for longer than 0.4 s (disc_slice, 10 m/s, 80 %:
#: ``millfmu dem run disc_slice --windows``); seed 001 (coupled CFD) analyses after 2 s.
STEADY_SPIN_UP_S = 1.0
#: Spin-up [s] after which the coupled disc slice at 10 m/s and 80 % is stationary (measured,
#: see the README's coupled-fluid section: bead speeds settle by 0.7 s from rest, the beads'
#: move from V1 to V2, which sets the zones' collision densities, takes about 1 s).
COUPLED_SPIN_UP_S = 1.0


def resolution_of(spec: TableSpec) -> dict:
    """What the manifest states as the table's resolution: grid, energy bins and, for DEM
    tables, the simulated sector, run times and time step of every grid point."""
    res = {"grid_points": int(np.prod(spec.shape)), "shape": list(spec.shape),
           "norm_log10_edges": [NORM_LOG10_MIN, NORM_LOG10_MAX, NORM_BINS_PER_DECADE]}
    if spec.builder_id == DEM_BUILDER_ID:
        mill, run = spec.scene.get("mill", {}), spec.scene.get("run", {})
        res["dem"] = {"sector_deg": mill.get("sector_deg", 360.0),
                      "spin_up_s": run.get("spin_up_s", 2.0),
                      "record_s": run.get("record_s", 1.0),
                      "sample_every_s": run.get("sample_every_s", 0.02),
                      "dt_s": run.get("dt_s", 5e-6)}
        mode = spec.scene.get("fluid", {}).get("mode")
        if mode is None:  # files without a mode (older tables) meant the prescribed swirl
            mode = "none" if spec.scene.get("fluid", {}).get("enabled") is False else \
                "prescribed"
        res["dem"]["fluid"] = mode
        if mode == "coupled" and res["dem"]["spin_up_s"] < COUPLED_SPIN_UP_S:
            res["note"] = (f"spin-up {res['dem']['spin_up_s']} s < {COUPLED_SPIN_UP_S} s: in the "
                           f"coupled slice at 10 m/s and 80 %, bead speeds settle within about "
                           f"0.7 s, zone fillings and collision densities within about 1 s; "
                           f"see 'stationarity' for the "
                           f"measured drift; seed 001 analyses after 2 s")
        elif mode != "coupled" and res["dem"]["spin_up_s"] < STEADY_SPIN_UP_S:
            res["note"] = (f"spin-up {res['dem']['spin_up_s']} s < {STEADY_SPIN_UP_S} s: "
                           f"bead speeds and collision energies settle within about 0.04 s, "
                           f"the bead fillings keep drifting outwards (no secondary flow in "
                           f"the prescribed swirl); see 'stationarity' for the measured "
                           f"drift; seed 001 analyses after 2 s")
    return res
