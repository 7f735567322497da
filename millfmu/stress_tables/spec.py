"""What a stress-energy table is and what names it: the grid axes, the per-zone fields and
the normalized energy bins (the file format), the normalization by E_ref and omega n_gb, and
:class:`TableSpec` (scene, grid, kernel version, builder), whose key names a cache entry,
with what a table's manifest states (:func:`manifest_for`, :func:`resolution_of`).

A table holds, for a grid of operating points, what the detailed breakage model needs from
the DEM, per zone (V1-V4 of :mod:`millfmu.dem.mills.zones`):

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
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..unit_names import modern_name, modernize, to_earlier
from .files import canonical_json, sha256_bytes

if TYPE_CHECKING:
    from .table import Table


#: The table and point format: 2 writes unit suffixes as :mod:`millfmu.unit_names` says.
FORMAT_VERSION = 2
#: The earlier format (its names in the earlier spelling), read for one release: a table or
#: point of it is checked against its own key and then read with the current names.
EARLIER_FORMAT = 1


#: Grid axes a table may have: name -> (scene section, scene key, unit, OperatingPoint field).
AXES = {
    "tip_speed_m_per_s": ("mill", "tip_speed_m_per_s", "m/s", "tip_speed_m_per_s"),
    "filling": ("beads", "filling", "-", "filling"),
    "bead_diameter_m": ("beads", "diameter_m", "m", "d_gb_m"),
    "bead_density_kg_per_m3": ("beads", "density_kg_per_m3", "kg/m3", "rho_gb_kg_per_m3"),
    "viscosity_Pa_s": ("fluid", "viscosity_Pa_s", "Pa s", "eta_susp_Pa_s"),
}
COMPONENTS = ("tn", "ts", "total")
QUANTILE_NAMES = ("q10", "q50", "q90")
# Normalized energy bins, log10(SE / E_ref): DEM energies span 1e-20 to 1 J (seed 001) and
# E_ref of 0.1-3 mm beads at 1-20 m/s lies between 1e-9 and 1e-1 J, so -16..2 holds what the
# DEM bins hold with room; 5 bins per decade as in millfmu.dem.analysis.stats.
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
#: of every DEM table's key, so it keeps the name the builder had when tables were one module
#: (an id, not an import path: the reader's move to millfmu.stress_tables left it, and with it
#: every shipped and cached table's key, as it was).
DEM_BUILDER_ID = "millfmu.dem.tables.DemBuilder"


class TableError(ValueError):
    """A table, grid, entry or lookup that is not allowed."""


def norm_log10_edges() -> np.ndarray:
    """Bin edges of log10(SE / E_ref) [-] shared by all tables."""
    n = int(round((NORM_LOG10_MAX - NORM_LOG10_MIN) * NORM_BINS_PER_DECADE))
    return np.linspace(NORM_LOG10_MIN, NORM_LOG10_MAX, n + 1)


def e_ref_J(d_gb_m: float, rho_gb_kg_per_m3: float, v_t_m_per_s: float) -> float:
    """Bead kinetic energy at tip speed, E_ref = 1/2 m v_t^2 = pi/12 d^3 rho v_t^2 [J]."""
    return math.pi / 12.0 * d_gb_m ** 3 * rho_gb_kg_per_m3 * v_t_m_per_s ** 2


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
    version and the builder's id. Its :meth:`key` names the cache entry.

    ``one_at_a_time`` (axis -> ascending values, axes not in the grid): axes varied one at
    a time from the scene's own operating point (the *anchor*: the scene's values of the
    grid axes) instead of over the whole grid, seed 000's way of presenting parameter
    variations. Each must include the scene's value (its reference). A lookup away from
    the reference scales the grid's fields by what the axis changes at the anchor
    (:meth:`Table.lookup`); it assumes that the axis's effect does not depend on the grid
    axes (separability), a stated assumption. 3 values per axis cost 2 runs instead of
    multiplying the grid by 3.

    ``across`` (one-at-a-time axis -> {grid axis: values}): where one axis's effect depends
    on the grid axes (a separability check off the anchor measured more than the stated
    error), that axis is run at each of its values across a coarse sub-grid of the grid's
    own nodes instead of at the anchor alone; a lookup then scales the grid's fields by
    the change interpolated over that sub-grid (held at its edges beyond it). At least 2
    values per listed grid axis; at the scene's value of the axis, a sub-grid point that is
    a node of the grid is that node. Absent: the axis is measured at the anchor. The sub-grid
    may also name the axis itself with some of its values (consecutive ones, the scene's
    among them): only those run across the sub-grid, the others at the anchor alone, and a
    lookup beyond the values run across reads the change at the anchor (separability
    assumed there), e.g. the bead diameter's 0.8 and 1.2 mm across tip speed and filling
    and its costly 0.5 mm at the anchor."""

    scene: dict
    grid: dict
    kernel_version: str
    builder_id: str = DEM_BUILDER_ID
    one_at_a_time: dict = field(default_factory=dict)
    across: dict = field(default_factory=dict)

    def __post_init__(self):
        if not self.grid:
            raise TableError("grid: no axes; give at least one of " + ", ".join(AXES))
        # names in an earlier release's spelling (a table of the earlier format) read as now
        object.__setattr__(self, "grid", _clean_axes({modern_name(k): v for k, v in self.grid.items()},
                                                     "grid axis"))
        json.loads(canonical_json(self.scene))  # plain JSON content only
        try:
            object.__setattr__(self, "scene", modernize(self.scene))
        except ValueError as e:
            raise TableError(f"scene: {e}") from None
        oat = _clean_axes({modern_name(k): v for k, v in (self.one_at_a_time or {}).items()},
                          "one-at-a-time axis")
        for name, vals in oat.items():
            if name in self.grid:
                raise TableError(f"one-at-a-time axis {name}: also a grid axis; give it "
                                 f"either way, not both")
            ref = self.scene_value(name)
            if not any(self._is_reference(name, v, ref) for v in vals):
                raise TableError(f"one-at-a-time axis {name} = {list(vals)!r}: must include "
                                 f"the scene's value {ref!r} (its reference)")
        if oat:
            self.anchor()  # the scene must name every grid axis
        object.__setattr__(self, "one_at_a_time", oat)
        object.__setattr__(self, "across", self._clean_across(self.across or {}))

    def _clean_across(self, across: dict) -> dict:
        """``across`` checked (one-at-a-time axes over values of grid axes), in the
        order of AXES, so that equal specifications give equal keys."""
        clean = {}
        for name, sub in across.items():
            name = modern_name(name)
            if name not in self.one_at_a_time:
                raise TableError(f"across: {name!r} is not a one-at-a-time axis of the table; "
                                 f"those are {list(self.one_at_a_time)}")
            if not isinstance(sub, dict) or not sub:
                raise TableError(f"across {name}: give grid axes and their values, e.g. "
                                 f"{{'tip_speed_m_per_s': [6, 10, 14]}}; got {sub!r}")
            sub = _clean_axes({modern_name(k): v for k, v in sub.items()}, f"across {name}: grid axis")
            if name in sub:
                own = self._across_values(name, sub[name])
                if own == tuple(self.one_at_a_time[name]):
                    del sub[name]  # every value across: the same table as without the list
                else:
                    sub[name] = own
            if not [ax for ax in sub if ax != name]:
                raise TableError(f"across {name}: give grid axes and their values besides its own, "
                                 f"e.g. {{'tip_speed_m_per_s': [6, 10, 14]}}; got {sub!r}")
            for ax, vals in sub.items():
                if ax == name:
                    continue
                if ax not in self.grid:
                    raise TableError(f"across {name}: {ax} is not a grid axis; the grid's are "
                                     f"{list(self.grid)}")
                if len(vals) < 2:
                    raise TableError(f"across {name}: {ax} = {list(vals)!r}: give at least 2 "
                                     f"values, e.g. of the grid's nodes {list(self.grid[ax])}")
            clean[name] = sub
        return {k: clean[k] for k in AXES if k in clean}

    def _across_values(self, name: str, vals: tuple) -> tuple:
        """The values of one-at-a-time axis ``name`` that its ``across`` sub-grid names,
        checked: values of the axis, consecutive, the scene's among them, at least 2."""
        have = list(self.one_at_a_time[name])
        idx = []
        for v in vals:
            hit = [i for i, h in enumerate(have) if math.isclose(v, h, rel_tol=1e-9)]
            if not hit:
                raise TableError(f"across {name}: value {v!r} is not one of the axis's values {have}")
            idx.append(hit[0])
        if len(idx) < 2 or idx != list(range(idx[0], idx[0] + len(idx))) or \
                not any(self._is_reference(name, have[i]) for i in idx):
            raise TableError(f"across {name}: values {list(vals)!r}: give at least 2 consecutive values of "
                             f"the axis {have}, the scene's value {self.scene_value(name)!r} among them")
        return tuple(have[i] for i in idx)

    @classmethod
    def from_manifest(cls, m: dict) -> TableSpec:
        """The specification a table's manifest records (KeyError where it lacks a part)."""
        return cls(scene=m["scene"], grid=m["grid"], kernel_version=m["kernel_version"],
                   builder_id=m["builder"], one_at_a_time=m.get("one_at_a_time") or {},
                   across=m.get("across") or {})

    def scene_value(self, axis: str) -> float:
        """The scene's own value of an axis [its unit in :data:`AXES`]."""
        sec, key = AXES[axis][0], AXES[axis][1]
        try:
            return float(self.scene[sec][key])
        except (KeyError, TypeError, ValueError):
            raise TableError(f"scene [{sec}] {key}: missing; a table with one-at-a-time "
                             f"axes needs the scene's value of {axis}") from None

    def anchor(self) -> dict:
        """The operating point one-at-a-time axes are varied from: the scene's values of
        the grid axes."""
        return {ax: self.scene_value(ax) for ax in self.grid}

    def _is_reference(self, name: str, v: float, ref: float | None = None) -> bool:
        ref = self.scene_value(name) if ref is None else ref
        return math.isclose(v, ref, rel_tol=1e-9)

    def point_along(self, name: str, v: float) -> dict:
        """The point a one-at-a-time axis ``name`` runs at value ``v``: the anchor itself at
        the scene's value, else the anchor with ``v``."""
        a = self.anchor()
        return a if self._is_reference(name, v) else dict(a, **{name: v})

    def side_axes(self, name: str) -> dict:
        """The axes of one-at-a-time axis ``name``'s side table: the axis itself (the values
        it is run across where ``across`` names some, else all), then the grid axes it is
        run across (``across``), in the grid's order."""
        sub = self.across.get(name, {})
        return {name: sub.get(name, self.one_at_a_time[name]),
                **{ax: sub[ax] for ax in self.grid if ax in sub}}

    def partly_across(self, name: str) -> bool:
        """Whether only some values of one-at-a-time axis ``name`` run across a sub-grid
        (``across`` names the axis's own values): the others have a side table of their
        own at the anchor (:meth:`anchor_side_axes`)."""
        return name in self.across.get(name, {})

    def anchor_side_axes(self, name: str) -> dict:
        """The axes of the side table at the anchor of an axis run partly across: the axis
        with all its values ({} where the axis is not run partly across)."""
        return {name: self.one_at_a_time[name]} if self.partly_across(name) else {}

    def sides(self, name: str) -> list[tuple]:
        """(at_anchor, axes, points) of each side table of one-at-a-time axis ``name``: for an
        axis run partly across first the one at the anchor (``Table.one_at_a_time_anchor``),
        then the one over its values run across (``Table.one_at_a_time``)."""
        out = [(False, self.side_axes(name), self.side_points(name))]
        if self.partly_across(name):
            out.insert(0, (True, self.anchor_side_axes(name), self.side_points(name, at_anchor=True)))
        return out

    def side_points(self, name: str, at_anchor: bool = False) -> list[dict]:
        """The points of ``name``'s side table in C order (last axis fastest): the anchor
        with ``name``'s value (:meth:`point_along`) and the sub-grid's values; at the scene's
        value these are points of the grid (or the anchor). ``at_anchor``: the points of the
        side table at the anchor of an axis run partly across ([] otherwise)."""
        axes = self.anchor_side_axes(name) if at_anchor else self.side_axes(name)
        if not axes:
            return []
        out = []
        for combo in itertools.product(*axes.values()):
            p = self.point_along(name, combo[0])
            p.update(zip(list(axes)[1:], combo[1:]))
            out.append(p)
        return out

    @property
    def shape(self) -> tuple:
        return tuple(len(v) for v in self.grid.values())

    def grid_points(self) -> list[dict]:
        """Grid points in C order (last axis fastest): axis -> value."""
        names = list(self.grid)
        return [dict(zip(names, combo)) for combo in itertools.product(*self.grid.values())]

    def points(self) -> list[dict]:
        """Every point the builder runs: the grid points (C order), then, with one-at-a-time
        axes, the anchor when it is not a grid point, then each such axis's values other
        than the scene's, at the anchor."""
        pts = self.grid_points()
        if not self.one_at_a_time:
            return pts
        a = self.anchor()
        if a not in pts:
            pts.append(a)
        for name in self.one_at_a_time:
            for _, _, side in self.sides(name):
                pts += [p for p in side if p not in pts]
        return pts

    def key_content(self) -> dict:
        out = {"format": FORMAT_VERSION, "builder": self.builder_id, "scene": self.scene,
               "grid": {k: list(v) for k, v in self.grid.items()},
               "kernel_version": self.kernel_version}
        if self.one_at_a_time:  # absent otherwise: keys of tables without it unchanged
            out["one_at_a_time"] = {k: list(v) for k, v in self.one_at_a_time.items()}
        if self.across:  # absent otherwise: keys of tables without it unchanged
            out["across"] = {k: {a: list(v) for a, v in sub.items()} for k, sub in self.across.items()}
        return out

    def key(self) -> str:
        return sha256_bytes(canonical_json(self.key_content()).encode())

    def earlier_key(self) -> str:
        """The key the earlier format (:data:`EARLIER_FORMAT`) gave this specification: its
        cache entry of that release."""
        return sha256_bytes(canonical_json(dict(to_earlier(self.key_content()), format=EARLIER_FORMAT)).encode())


def _clean_axes(axes: dict, what: str) -> dict:
    """Axes checked (known names, finite ascending values > 0) in the order of AXES, so that
    equal grids give equal keys."""
    clean = {}
    for name, vals in axes.items():
        if name not in AXES:
            raise TableError(f"{what} {name!r}: unknown; allowed: {list(AXES)}")
        v = [float(x) for x in vals]
        if not v:
            raise TableError(f"{what} {name}: no values")
        if not all(math.isfinite(x) and x > 0 for x in v):
            raise TableError(f"{what} {name} = {v!r}: values must be finite and > 0")
        if any(b <= a for a, b in zip(v, v[1:])):
            raise TableError(f"{what} {name} = {v!r}: values must be strictly ascending")
        clean[name] = tuple(v)
    return {k: clean[k] for k in AXES if k in clean}


def scene_at_point(scene: dict, point: dict) -> dict:
    """Copy of the scene dict with the grid point's values put at their scene keys."""
    d = json.loads(canonical_json(scene))
    for axis, value in point.items():
        sec, key = AXES[axis][0], AXES[axis][1]
        d.setdefault(sec, {})[key] = float(value)
        if key == "tip_speed_m_per_s":
            # an accelerator scene may give its speed in rpm instead: the point's tip
            # speed replaces it
            d[sec].pop("rotor_speed_rpm", None)
    return d


def manifest_for(spec: TableSpec, table: Table, extra: dict | None = None,
                 work_precision=None) -> dict:
    """The manifest of a table built from ``spec``: the key content, key, creation
    time, resolution, (for a DEM table) the work-precision entry, build wall time,
    stationarity, the points run in a wider DEM cell than the scene's (``cells``), and
    ``extra``.

    ``work_precision``: the entry itself, or a function of the ``dem`` part of the
    resolution that gives it (the work-precision study's ``manifest_entry``), handed in by
    whoever builds the table; None when none is handed in. The tables never import the
    study (a campaign that uses them)."""
    m = dict(spec.key_content())
    m["key"] = spec.key()
    m["created_utc"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    m["resolution"] = resolution_of(spec)
    if "dem" in m["resolution"]:
        m["work_precision"] = (work_precision(m["resolution"]["dem"]) if callable(work_precision)
                               else work_precision)
    m["build_wall_time_s"] = table.manifest.get("build_wall_time_s")
    for k in ("points_run", "points_reused", "points_wall_time_s"):
        if k in table.manifest:
            m[k] = table.manifest[k]
    for k in ("stationarity", "cells", "point_starts"):
        if k in table.manifest:
            m[k] = table.manifest[k]
    if extra:
        m.update(extra)
    return m


#: Spin-up below which a table's manifest notes that the bead fillings still drift. With the
#: prescribed swirl flow, bead speeds and collision energies settle within 0.04 s, but the
#: beads keep moving outwards for longer than 0.4 s (disc_slice, 10 m/s, 80 %:
#: ``millfmu dem run disc_slice --windows``); seed 001 (coupled CFD) analyses after 2 s.
STEADY_SPIN_UP_S = 1.0
#: Spin-up [s] after which the coupled disc slice at 10 m/s and 80 % is stationary (measured
#: by the DEM work-precision study, docs/validation-seed001.md: bead speeds settle by 0.7 s from rest, but the
#: zone fillings, collision frequencies and V2's SE_tn quantiles keep changing until about
#: 1.5 s; after 1.0 s they are still 8-18 % off in V2-V4).
COUPLED_SPIN_UP_S = 1.5


def resolution_of(spec: TableSpec) -> dict:
    """What the manifest states as the table's resolution: grid, energy bins and, for DEM
    tables, the simulated sector, run times and time step of every grid point."""
    res = {"grid_points": int(np.prod(spec.shape)), "shape": list(spec.shape),
           "norm_log10_edges": [NORM_LOG10_MIN, NORM_LOG10_MAX, NORM_BINS_PER_DECADE]}
    if spec.one_at_a_time:
        res["one_at_a_time"] = {
            "axes": {k: list(v) for k, v in spec.one_at_a_time.items()},
            "anchor": spec.anchor(),
            "points": len(spec.points()) - int(np.prod(spec.shape)),
            "note": ("varied one at a time at the anchor; away from the scene's value a lookup "
                     "scales the grid's fields by the change at the anchor (rates and speeds "
                     "by their ratio, the energy distributions shifted by the change of their "
                     "median): separability assumed; a separability_check, where the manifest "
                     "has one, measures it off the anchor")}
        if spec.across:
            res["one_at_a_time"]["across"] = {k: {a: list(v) for a, v in sub.items()}
                                              for k, sub in spec.across.items()}
            res["one_at_a_time"]["note"] += (
                "; an axis named in 'across' is run at each of its values across that sub-grid "
                "of the grid's nodes (where its sub-grid names some of the axis's own values, "
                "those only, the others at the anchor), and the change is interpolated over it")
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
                           f"0.7 s, zone fillings and collision densities within about 1.5 s; "
                           f"see 'stationarity' for the "
                           f"measured drift; seed 001 analyses after 2 s")
        elif mode != "coupled" and res["dem"]["spin_up_s"] < STEADY_SPIN_UP_S:
            res["note"] = (f"spin-up {res['dem']['spin_up_s']} s < {STEADY_SPIN_UP_S} s: "
                           f"bead speeds and collision energies settle within about 0.04 s, "
                           f"the bead fillings keep drifting outwards (no secondary flow in "
                           f"the prescribed swirl); see 'stationarity' for the measured "
                           f"drift; seed 001 analyses after 2 s")
    return res
