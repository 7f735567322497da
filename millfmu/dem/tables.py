"""Stress-energy lookup tables: DEM results on a grid of operating points, cached on disk.

A DEM run takes minutes; a kinetics step takes microseconds. A table holds, for a grid of
operating points, what the detailed breakage model needs from the DEM, per zone (V1-V4 of
:mod:`millfmu.dem.zones`):

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

The kinetics reads the normal component ``tn`` by default: SE_tn = 1/2 m* v_n^2 is the
impact energy that compresses a particle caught between two beads, the quantity of the
stress-energy concept (Kwade) and the distribution seed 001 reports; the shear and
rotational parts mostly rub rather than break. ``total`` can be chosen instead.

Storage: plain arrays in a ``.npz`` (numpy, read with ``allow_pickle=False``) and a JSON
manifest (DEM scene, grid, kernel version, resolution, sha256 of each file). The cache
lives in ``$MILLFMU_CACHE_DIR``, else ``$XDG_CACHE_HOME/millfmu/tables``, else
``~/.cache/millfmu/tables``; each entry is a folder named by the sha256 of the canonical JSON
of (format, builder, DEM scene content, grid, kernel version). Entries are written into a
temporary folder and renamed into place under an exclusive ``fcntl.flock``; an entry that
fails any check (manifest checksum, file checksums and sizes, key, version, array shapes)
is rebuilt, never used.

This module imports no numba: the DEM is loaded only inside :class:`DemBuilder` calls.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import importlib.util
import itertools
import json
import math
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

FORMAT_VERSION = 1
TABLE_FILE = "table.npz"
MANIFEST_FILE = "manifest.json"
MANIFEST_SUM_FILE = "manifest.json.sha256"

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
#: Error estimates multiply the second-difference estimate of the linear-interpolation error
#: by this factor, because the curvature is taken at neighbouring nodes, not at the point.
ERROR_SAFETY = 2.0
#: Gridded axes along which ``similar_axes`` may extend a lookup beyond the grid by holding
#: the dimensionless fields at the nearest edge: energies over E_ref ~ v_t^2 and frequencies
#: over omega n_gb ~ v_t take out the leading tip-speed dependence (seed 000's stress model);
#: tests/tables and the default table's manifest show how far that holds. Not filling: the
#: bead fillings and collision densities change with it in ways no normalization removes.
EXTRAPOLABLE_AXES = ("tip_speed_m_s", "bead_diameter_m", "bead_density_kg_m3",
                     "viscosity_pa_s")
#: Relative tolerance for matching a single-valued axis (an axis the grid does not vary).
FIXED_AXIS_RTOL = 1e-9


class TableError(ValueError):
    """A table, grid, entry or lookup that is not allowed."""


class OutsideGridError(TableError):
    """A lookup point outside the grid; names the axis, the value and the bounds."""

    def __init__(self, axis: str, value: float, lo: float, hi: float, note: str = ""):
        self.axis, self.value, self.lo, self.hi = axis, value, lo, hi
        unit = f" {AXES[axis][2]}" if axis in AXES and AXES[axis][2] != "-" else ""
        bounds = (f"the table holds only {lo!r}{unit}" if lo == hi
                  else f"allowed {lo!r} to {hi!r}{unit}")
        #: What is allowed, in words (for errors that name the input or scene key instead).
        self.allowed = f"outside the stress-energy table's grid; {bounds}{note}"
        super().__init__(f"table lookup: {axis} = {value!r}{unit} is outside the grid; "
                         f"{bounds}{note}")


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


# ---- keys, versions, cache folder ---------------------------------------------------------
def canonical_json(obj) -> str:
    """JSON with sorted keys and no whitespace: equal content gives equal text."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)


def sha256_bytes(b: bytes) -> str:
    return hashlib.sha256(b).hexdigest()


#: A manifest's checksum of itself: sha256 of the canonical JSON of every other key. It
#: travels inside the file, so an exported table (PREFIX.npz, PREFIX.json) is covered too.
MANIFEST_SUM_KEY = "manifest_sha256"


def manifest_digest(m: dict) -> str:
    return sha256_bytes(canonical_json({k: v for k, v in m.items() if k != MANIFEST_SUM_KEY}).encode())


def sha256_file(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


#: Modules whose source decides the DEM's numbers: contact laws and integration (kernels,
#: sim), the coupled fluid (fluid, coupling), the run loop (run) and what is measured
#: (stats, zones). Their source hash is the kernel version.
KERNEL_MODULES = ("millfmu.dem.kernels", "millfmu.dem.sim", "millfmu.dem.stats",
                  "millfmu.dem.zones", "millfmu.dem.run", "millfmu.dem.fluid.grid",
                  "millfmu.dem.fluid.vans_kernels", "millfmu.dem.fluid.k_epsilon",
                  "millfmu.dem.fluid.pressure", "millfmu.dem.fluid.solver",
                  "millfmu.dem.coupling.projection", "millfmu.dem.coupling.koch_hill2001",
                  "millfmu.dem.coupling.cfd_dem", "millfmu.dem.coupling.settings")


def dem_kernel_version() -> str:
    """sha256 over the source files of :data:`KERNEL_MODULES` (read, not imported: no numba)."""
    h = hashlib.sha256()
    for mod in KERNEL_MODULES:
        spec = importlib.util.find_spec(mod)
        if spec is None or spec.origin is None:
            raise TableError(f"DEM kernel version: module {mod} not found")
        h.update(mod.encode() + b"\0" + Path(spec.origin).read_bytes() + b"\0")
    return "sha256:" + h.hexdigest()


def default_cache_dir() -> Path:
    """The tables cache folder: $MILLFMU_CACHE_DIR, else $XDG_CACHE_HOME/millfmu/tables,
    else ~/.cache/millfmu/tables."""
    env = os.environ.get("MILLFMU_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "millfmu" / "tables"


def resolve_cache_dir(cache_dir=None) -> Path:
    """``cache_dir`` if given (CLI --cache-dir), else :func:`default_cache_dir`."""
    return Path(cache_dir).expanduser() if cache_dir else default_cache_dir()


# ---- specification -------------------------------------------------------------------------
def _builder_id(builder) -> str:
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
    builder_id: str = "millfmu.dem.tables.DemBuilder"

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
    return d


# ---- the table -----------------------------------------------------------------------------
@dataclass
class Lookup:
    """Interpolated fields at one point (``values``), their interpolation-error estimates
    (``error``, same shapes; NaN where an axis has too few points to estimate curvature)
    and the sampling standard deviation carried over from the DEM nodes (``sigma``)."""

    point: dict
    values: dict
    error: dict
    notes: list = field(default_factory=list)
    sigma: dict = field(default_factory=dict)

    def bound(self, name: str, k_sigma: float = 2.0) -> np.ndarray:
        """Interpolation error plus ``k_sigma`` sampling standard deviations of a field."""
        return self.error[name] + k_sigma * self.sigma.get(name, 0.0)


@dataclass
class Table:
    """Grid axes, zone names and the fields of :data:`FIELDS` as arrays of shape
    grid shape + field shape; plus per grid point the references ``e_ref_J`` [J],
    ``omega_rad_s`` [rad/s] and ``n_gb_per_m3`` [1/m3] used to normalize."""

    axes: dict
    zone_names: tuple
    data: dict
    refs: dict
    manifest: dict = field(default_factory=dict)

    # -- geometry of the grid
    @property
    def shape(self) -> tuple:
        return tuple(len(v) for v in self.axes.values())

    @property
    def edges_log10(self) -> np.ndarray:
        return norm_log10_edges()

    def check_shapes(self):
        """Raise TableError unless every array has the shape the grid and zones imply."""
        z, c, b, q = len(self.zone_names), len(COMPONENTS), norm_log10_edges().size - 1, \
            len(QUANTILE_NAMES)
        want = {k: (z,) for k in ZONE_FIELDS}
        want.update(se_density=(c, z, b), se_quantiles_norm=(c, z, q))
        if "recording_drift" in self.data:
            want["recording_drift"] = (len(DRIFT_FIELDS), z)
        for k, tail in want.items():
            if k not in self.data:
                raise TableError(f"table: field {k!r} missing")
            if self.data[k].shape != self.shape + tail:
                raise TableError(f"table: field {k} has shape {self.data[k].shape}, "
                                 f"expected {self.shape + tail}")
        for k in ("e_ref_J", "omega_rad_s", "n_gb_per_m3"):
            if k not in self.refs or self.refs[k].shape != self.shape:
                raise TableError(f"table: reference {k!r} missing or of wrong shape")

    # -- lookup
    def axis_value(self, name: str, x: float, similar=()) -> tuple:
        """The value a lookup uses on axis ``name`` for ``x``, and a note (or None); raises
        :class:`OutsideGridError` where :meth:`lookup` refuses (see there): round-off at an
        edge is the edge; a similar axis keeps a single node's value, and an extrapolable
        one holds the nearest edge outside the grid."""
        ax = self.axes[name]
        lo, hi = float(ax[0]), float(ax[-1])
        if ax.size == 1:
            if abs(x - lo) <= FIXED_AXIS_RTOL * abs(lo):
                return lo, None
            if name in similar:
                return lo, (f"{name} = {x!r}: table holds {lo!r} only; dimensionless "
                            f"fields used unchanged (similarity assumed)")
            raise OutsideGridError(name, x, lo, hi, note="; the axis is not varied in "
                                   "this table (allow it with similar_axes to assume "
                                   "similarity)")
        if not math.isfinite(x):
            raise OutsideGridError(name, x, lo, hi)
        # Round-off at an edge (a filling computed as 0.8000000000000002) is on the edge.
        tol = FIXED_AXIS_RTOL * max(abs(lo), abs(hi))
        if lo - tol <= x < lo or hi < x <= hi + tol:
            return (lo if x < lo else hi), None
        if lo <= x <= hi:
            return x, None
        if name not in similar or name not in EXTRAPOLABLE_AXES:
            raise OutsideGridError(name, x, lo, hi)
        edge = lo if x < lo else hi
        return edge, (f"{name} = {x!r} outside the grid [{lo!r}, {hi!r}]: "
                      f"dimensionless fields held at {edge!r} (similarity assumed)")

    def lookup(self, point: dict, similar_axes: Iterable[str] = ()) -> Lookup:
        """Multilinear interpolation of all fields at ``point`` (axis -> value).

        Every axis of the table must be given. Axes with one value must match it (relative
        tolerance 1e-9) unless named in ``similar_axes``: then the value is accepted and the
        table's dimensionless fields are used as they are, which assumes similarity in that
        axis (a stated assumption, recorded in the notes). A value outside an axis's range
        raises :class:`OutsideGridError` naming the axis, the value and the bounds, unless
        the axis is in :data:`EXTRAPOLABLE_AXES` and named in ``similar_axes``: then the
        fields of the nearest grid edge are used (noted), the similarity the table's
        normalization rests on.

        Error estimate per field: for each axis with at least 3 points, the linear
        interpolation error t (1 - t) h^2 / 2 |f''| with f'' from the second divided
        difference at the interval's end nodes (the larger), summed over axes and multiplied
        by ERROR_SAFETY, plus 16 ulps of the value for rounding; zero at grid points; NaN
        when an axis with 2 points has t in (0, 1). This is the error of interpolating
        between the stored values. The DEM's own sampling noise is separate:
        ``Lookup.sigma`` (see :meth:`node_sigma`) propagated through the weights,
        sqrt(sum w_c^2 sigma_c^2); :meth:`Lookup.bound` combines the two.
        """
        similar = set(similar_axes)
        idx, ts, notes = [], [], []
        for name, ax in self.axes.items():
            if name not in point:
                raise TableError(f"table lookup: axis {name} missing from the point "
                                 f"{point!r}; the table's axes: {list(self.axes)}")
            x, note = self.axis_value(name, float(point[name]), similar)
            if note:
                notes.append(note)
            if ax.size == 1:
                idx.append(0), ts.append(0.0)
                continue
            i = int(np.searchsorted(ax, x, side="right") - 1)
            i = min(max(i, 0), ax.size - 2)
            t = (x - ax[i]) / (ax[i + 1] - ax[i])
            # Snap to the node so that grid points are reproduced exactly.
            if t == 1.0:
                i, t = i + 1, 0.0
            if i == ax.size - 1:
                i, t = i - 1, 1.0
            idx.append(i), ts.append(float(t))
        values, errors, sigmas = {}, {}, {}
        at_node = all(t in (0.0, 1.0) for t in ts)
        node_sigma = self.node_sigma()
        for k, arr in self.data.items():
            values[k] = _multilinear(arr, idx, ts)
            errors[k] = self._error(arr, idx, ts)
            if not at_node:
                # rounding of the weighted sum: a few ulps of the value
                errors[k] = errors[k] + 16.0 * np.finfo(float).eps * np.abs(values[k])
            var = None
            for corner, w in _corners(idx, ts):
                v = (w * node_sigma[k][corner]) ** 2
                var = v if var is None else var + v
            sigmas[k] = np.sqrt(var) if var is not None else np.array(node_sigma[k], float)
        return Lookup(point=dict(point), values=values, error=errors, notes=notes,
                      sigma=sigmas)

    def node_sigma(self) -> dict:
        """Sampling standard deviation of each stored value, from the recorded collision
        count N of its zone (Poisson / binomial statistics; collisions treated as
        independent, so a lower bound where the same beads collide repeatedly):
        collision frequency f/sqrt(N); collision power P sqrt(<e^2>)/(<e> sqrt(N)) with the
        moments of the SE_total bins; bin density sqrt(w (1 - w) / N) / dlog10; quantile
        q_p: q ln10 sqrt(p (1 - p) / N) / g, g the density per decade at q_p. Fields
        without a count model (volume fraction, local filling, speed) get 0.
        Tables that keep ``recording_drift`` (DEM tables) add half the relative change
        between the halves of each point's recording times the value, in quadrature, to
        the local filling, speed, collision frequency and power and to the SE quantiles:
        the slow drift of the bead motion that the counts cannot see.
        Against held-back DEM points (tests/tables) the quantiles and the frequencies of
        well-sampled zones stay within error + 2 sigma; zones that (almost) empty during a
        run (V4 below 70 % filling) do not: treat these sigmas as lower bounds there."""
        if getattr(self, "_node_sigma", None) is not None:
            return self._node_sigma
        U = norm_log10_edges()
        dU = np.diff(U)
        n = self.data["collision_count"]  # (..., Z)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(n > 0, 1.0 / np.sqrt(np.maximum(n, 1.0)), np.inf)
            out = {k: np.zeros_like(v, dtype=float) for k, v in self.data.items()}
            out["collision_frequency_norm"] = np.abs(self.data["collision_frequency_norm"]) * inv
            dens = self.data["se_density"]  # (..., C, Z, B)
            w = dens * dU
            out["se_density"] = np.sqrt(np.clip(w * (1.0 - w), 0.0, None)) \
                * inv[..., None, :, None] / dU
            e = 10.0 ** (0.5 * (U[:-1] + U[1:]))
            wt = w[..., COMPONENTS.index("total"), :, :]
            m1, m2 = (wt * e).sum(-1), (wt * e * e).sum(-1)
            rel = np.where(m1 > 0, np.sqrt(m2) / m1, 0.0)
            out["collision_power_norm"] = np.abs(self.data["collision_power_norm"]) * rel * inv
            q = self.data["se_quantiles_norm"]  # (..., C, Z, Q)
            p = np.array([0.1, 0.5, 0.9])
            b = np.clip(np.searchsorted(U, np.log10(np.where(q > 0, q, 1.0))) - 1, 0,
                        U.size - 2)
            g = np.take_along_axis(dens, b, axis=-1)
            sq = q * math.log(10.0) * np.sqrt(p * (1 - p))[None] * inv[..., None, :, None] / g
            out["se_quantiles_norm"] = np.where(np.isfinite(sq), sq, np.abs(q))
        if "recording_drift" in self.data:
            # The collision counts miss the slow changes of the bead motion over a run:
            # the change between the halves of the recording, |drift| / 2 of the value,
            # is added in quadrature (the energy scale's drift to every quantile).
            d = 0.5 * np.abs(np.nan_to_num(self.data["recording_drift"], nan=0.0))
            fi = {f: i for i, f in enumerate(DRIFT_FIELDS)}
            for k, f in (("filling_local", "filling"),
                         ("speed_over_tip_speed", "speed_over_tip_speed"),
                         ("collision_frequency_norm", "collision_frequency_per_m3_s"),
                         ("collision_power_norm", "collision_frequency_per_m3_s")):
                out[k] = np.hypot(out[k], np.abs(self.data[k]) * d[..., fi[f], :])
            dq = d[..., fi["se_tn_q50_j"], :][..., None, :, None]
            out["se_quantiles_norm"] = np.hypot(out["se_quantiles_norm"],
                                                np.abs(self.data["se_quantiles_norm"]) * dq)
        self._node_sigma = out
        return out

    def _error(self, arr, idx, ts) -> np.ndarray:
        tail = arr.shape[len(self.axes):]
        err = np.zeros(tail)
        for a, (name, ax) in enumerate(self.axes.items()):
            t = ts[a]
            if ax.size == 1 or t == 0.0 or t == 1.0:
                continue
            if ax.size < 3:
                err = err + np.nan
                continue
            i = idx[a]
            h = ax[i + 1] - ax[i]
            curv = np.zeros(tail)
            # Second divided differences at the nodes i and i+1 where they exist; the
            # other axes at the corners of the interpolation cell (their max).
            for c in (i, i + 1):
                if 1 <= c <= ax.size - 2:
                    hl, hr = ax[c] - ax[c - 1], ax[c + 1] - ax[c]
                    f = [np.take(arr, c + d, axis=a) for d in (-1, 0, 1)]
                    d2 = 2.0 * ((f[2] - f[1]) / hr - (f[1] - f[0]) / hl) / (hl + hr)
                    sub_idx = idx[:a] + idx[a + 1:]
                    sub_ts = ts[:a] + ts[a + 1:]
                    curv = np.maximum(curv, _corner_max(np.abs(d2), sub_idx, sub_ts))
            err = err + ERROR_SAFETY * t * (1.0 - t) * h * h / 2.0 * curv
        return err

    def fixed_axis_values(self) -> dict:
        """Values of the axes of :data:`AXES` that the grid does not vary, as the table's
        DEM scene (manifest) gives them; axes the scene does not name are left out."""
        scene = self.manifest.get("scene", {})
        out = {}
        for ax, (sec, key, _, _) in AXES.items():
            if ax not in self.axes and isinstance(scene.get(sec), dict) and key in scene[sec]:
                out[ax] = float(scene[sec][key])
        return out

    def spec(self) -> "TableSpec":
        """The specification this table was built from (from its manifest)."""
        m = self.manifest
        try:
            return TableSpec(scene=m["scene"], grid=m["grid"],
                             kernel_version=m["kernel_version"], builder_id=m["builder"])
        except KeyError as e:
            raise TableError(f"table: manifest lacks {e}; not a cached or exported table") \
                from None

    def subset(self, bounds: dict) -> "Table":
        """The slice of the grid that a scene needs: for each axis named in ``bounds``
        (axis -> (lo, hi)), the nodes from the last one <= lo to the first one >= hi.
        Lookups inside the bounds give the same values as on the full table (their error
        estimates can be NaN when fewer than 3 nodes remain). The slice's manifest is that
        of a table built on the sliced grid, with ``slice_of`` naming the full table."""
        idx = []
        for name, ax in self.axes.items():
            if name not in bounds:
                idx.append(np.arange(ax.size))
                continue
            lo, hi = (float(x) for x in bounds[name])
            if lo > hi:
                raise TableError(f"subset: {name} bounds ({lo!r}, {hi!r}): lo > hi")
            for x in (lo, hi):
                if not ax[0] <= x <= ax[-1]:
                    raise OutsideGridError(name, x, float(ax[0]), float(ax[-1]))
            i0 = int(np.searchsorted(ax, lo, side="right") - 1)
            i1 = int(np.searchsorted(ax, hi, side="left"))
            idx.append(np.arange(i0, i1 + 1))
        sel = np.ix_(*idx)
        axes = {k: ax[i] for (k, ax), i in zip(self.axes.items(), idx)}
        data = {k: v[sel] for k, v in self.data.items()}
        refs = {k: v[sel] for k, v in self.refs.items()}
        sub = Table(axes=axes, zone_names=self.zone_names, data=data, refs=refs)
        if "scene" in self.manifest:
            old = self.spec()
            spec = TableSpec(scene=old.scene, grid={k: list(v) for k, v in axes.items()},
                             kernel_version=old.kernel_version, builder_id=old.builder_id)
            sub.manifest = manifest_for(spec, sub, {"slice_of": self.manifest.get("key")})
        return sub

    def export(self, prefix) -> tuple[Path, Path]:
        """Write ``PREFIX.npz`` and ``PREFIX.json`` (the manifest, with the .npz checksum),
        e.g. for the package data or an FMU's resources; returns the two paths."""
        if "key" not in self.manifest:
            raise TableError("export: the table has no manifest (build it with get_table)")
        prefix = Path(prefix)
        prefix.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=prefix.parent) as tmp:
            m = {k: v for k, v in self.manifest.items() if k != "files"}
            self.save(tmp, m)
            npz, man = Path(str(prefix) + ".npz"), Path(str(prefix) + ".json")
            os.replace(Path(tmp) / TABLE_FILE, npz)
            os.replace(Path(tmp) / MANIFEST_FILE, man)
        read_table(npz=npz, manifest_path=man)
        return npz, man

    # -- files
    def arrays(self) -> dict:
        out = {f"axis_{k}": np.asarray(v, float) for k, v in self.axes.items()}
        out.update({k: np.asarray(v) for k, v in self.data.items()})
        out.update({f"ref_{k}": np.asarray(v, float) for k, v in self.refs.items()})
        out["norm_log10_edges"] = norm_log10_edges()
        return out

    def save(self, folder, manifest: dict) -> dict:
        """Write ``table.npz``, ``manifest.json`` (with the table file's size and sha256)
        and ``manifest.json.sha256`` into ``folder``, each fsync'ed; returns the manifest."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        tp = folder / TABLE_FILE
        with open(tp, "wb") as fh:
            np.savez_compressed(fh, **self.arrays())
            fh.flush()
            os.fsync(fh.fileno())
        m = dict(manifest)
        m["files"] = {TABLE_FILE: {"bytes": tp.stat().st_size, "sha256": sha256_file(tp)}}
        m["zone_names"] = list(self.zone_names)
        m["components"] = list(COMPONENTS)
        m["quantiles"] = list(QUANTILE_NAMES)
        m["axes"] = {k: [float(x) for x in v] for k, v in self.axes.items()}
        m[MANIFEST_SUM_KEY] = manifest_digest(m)
        text = json.dumps(m, indent=1, sort_keys=True, allow_nan=False).encode()
        _write_synced(folder / MANIFEST_FILE, text)
        _write_synced(folder / MANIFEST_SUM_FILE, (sha256_bytes(text) + "\n").encode())
        self.manifest = m
        return m


def _write_synced(path: Path, data: bytes):
    with open(path, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())


def _corners(idx, ts):
    """(index tuple, weight) of the 2^d corners of a cell; zero-weight corners skipped."""
    for bits in itertools.product((0, 1), repeat=len(idx)):
        w = 1.0
        for b, t in zip(bits, ts):
            w *= t if b else (1.0 - t)
        if w != 0.0:
            yield tuple(i + b for i, b in zip(idx, bits)), w


def _multilinear(arr, idx, ts) -> np.ndarray:
    if not idx:
        return np.array(arr, float)
    out = None
    for corner, w in _corners(idx, ts):
        v = w * arr[corner].astype(float) if w != 1.0 else arr[corner].astype(float)
        out = v if out is None else out + v
    return out


def _corner_max(arr, idx, ts) -> np.ndarray:
    if not idx:
        return np.array(arr, float)
    out = None
    for bits in itertools.product((0, 1), repeat=len(idx)):
        corner = tuple(min(i + b, arr.shape[k] - 1) for k, (i, b) in enumerate(zip(idx, bits)))
        v = np.nan_to_num(arr[corner].astype(float), nan=0.0)
        out = v if out is None else np.maximum(out, v)
    return out


# ---- reading and verifying files ------------------------------------------------------------
def read_table(folder=None, *, npz=None, manifest_path=None, expect_key: str | None = None,
               expect_kernel: str | None = None) -> Table:
    """Read and verify a table; raise TableError saying what is wrong.

    Either ``folder`` (a cache entry: table.npz, manifest.json, manifest.json.sha256) or
    ``npz`` and ``manifest_path`` (a shipped table such as millfmu/data/default_table.*).
    Checks: manifest checksum (when its .sha256 file exists, always in cache entries),
    format version, key = sha256 of the manifest's key content (and = ``expect_key``),
    kernel version (= ``expect_kernel`` when given), the table file's size and sha256, the
    array shapes. Arrays are loaded with allow_pickle=False.
    """
    if folder is not None:
        folder = Path(folder)
        npz, manifest_path = folder / TABLE_FILE, folder / MANIFEST_FILE
        sum_path = folder / MANIFEST_SUM_FILE
        if not sum_path.exists():
            raise TableError(f"{sum_path}: missing (entry incomplete)")
    else:
        npz, manifest_path = Path(npz), Path(manifest_path)
        sum_path = Path(str(manifest_path) + ".sha256")
    if not manifest_path.exists():
        raise TableError(f"{manifest_path}: missing")
    text = manifest_path.read_bytes()
    if sum_path.exists():
        want = sum_path.read_text().strip()
        if sha256_bytes(text) != want:
            raise TableError(f"{manifest_path}: sha256 {sha256_bytes(text)[:16]}... does not "
                             f"match {sum_path.name} ({want[:16]}...): corrupted")
    try:
        m = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise TableError(f"{manifest_path}: not valid JSON ({e})") from None
    if not isinstance(m, dict):
        raise TableError(f"{manifest_path}: not a JSON object: corrupted")
    if MANIFEST_SUM_KEY in m:
        if m[MANIFEST_SUM_KEY] != manifest_digest(m):
            raise TableError(f"{manifest_path}: content does not match its {MANIFEST_SUM_KEY}: edited or corrupted")
    elif not sum_path.exists():
        raise TableError(f"{manifest_path}: no checksum ({MANIFEST_SUM_KEY} or {sum_path.name}): "
                         f"written by an older millfmu; export the table again")
    if m.get("format") != FORMAT_VERSION:
        raise TableError(f"{manifest_path}: format = {m.get('format')!r}, this millfmu "
                         f"reads format {FORMAT_VERSION}: stale")
    try:
        spec = TableSpec(scene=m["scene"], grid=m["grid"], kernel_version=m["kernel_version"],
                         builder_id=m["builder"])
    except KeyError as e:
        raise TableError(f"{manifest_path}: key {e} missing") from None
    except (TypeError, ValueError) as e:
        raise TableError(f"{manifest_path}: {e}") from None
    if not isinstance(m.get("zone_names"), list):
        raise TableError(f"{manifest_path}: zone_names missing")
    key = spec.key()
    if m.get("key") != key:
        raise TableError(f"{manifest_path}: key {m.get('key')!r} does not match its content "
                         f"({key}): corrupted or edited")
    if expect_key is not None and key != expect_key:
        raise TableError(f"{manifest_path}: key {key} is not the expected {expect_key}: stale")
    if expect_kernel is not None and m["kernel_version"] != expect_kernel:
        raise TableError(f"{manifest_path}: built with DEM kernel version "
                         f"{m['kernel_version']}, current is {expect_kernel}: stale")
    info = (m.get("files") or {}).get(TABLE_FILE)
    if not isinstance(info, dict) or not {"bytes", "sha256"} <= set(info):
        raise TableError(f"{manifest_path}: no checksum for {TABLE_FILE}")
    if not npz.exists():
        raise TableError(f"{npz}: missing")
    size = npz.stat().st_size
    if size != info["bytes"]:
        raise TableError(f"{npz}: {size} bytes, manifest says {info['bytes']}: truncated "
                         f"or extended")
    digest = sha256_file(npz)
    if digest != info["sha256"]:
        raise TableError(f"{npz}: sha256 {digest[:16]}... does not match the manifest "
                         f"({info['sha256'][:16]}...): corrupted")
    try:
        with np.load(npz, allow_pickle=False) as f:
            arrs = {k: f[k] for k in f.files}
    except Exception as e:  # a zip/npy error: the file is not a table
        raise TableError(f"{npz}: cannot be read as .npz ({type(e).__name__}: {e})") from None
    axes = {}
    for name in spec.grid:
        a = arrs.get(f"axis_{name}")
        if a is None or not np.array_equal(a, np.asarray(spec.grid[name])):
            raise TableError(f"{npz}: axis {name} missing or differs from the manifest grid")
        axes[name] = a
    t = Table(axes=axes, zone_names=tuple(m["zone_names"]),
              data={k: arrs[k] for k in FIELDS + OPTIONAL_FIELDS if k in arrs},
              refs={k[4:]: v for k, v in arrs.items() if k.startswith("ref_")}, manifest=m)
    t.check_shapes()
    return t


# ---- building ------------------------------------------------------------------------------
def assemble(spec: TableSpec, results: list[dict]) -> Table:
    """Stack per-point builder results (grid order, see :meth:`TableSpec.points`)."""
    if len(results) != len(spec.points()):
        raise TableError(f"assemble: {len(results)} results for {len(spec.points())} points")
    zn = tuple(results[0]["zone_names"])
    for r in results:
        if tuple(r["zone_names"]) != zn:
            raise TableError(f"assemble: zone names differ between points: {zn} vs "
                             f"{tuple(r['zone_names'])}")
    shape = spec.shape
    data = {k: np.stack([np.asarray(r[k], float) for r in results]).reshape(
        shape + np.asarray(results[0][k]).shape) for k in FIELDS}
    if all("drift" in r for r in results):
        data["recording_drift"] = np.array(
            [[r["drift"][f] for f in DRIFT_FIELDS] for r in results], float).reshape(
            shape + (len(DRIFT_FIELDS), len(zn)))
    refs = {k: np.array([float(r[k]) for r in results]).reshape(shape)
            for k in ("e_ref_J", "omega_rad_s", "n_gb_per_m3")}
    t = Table(axes={k: np.asarray(v, float) for k, v in spec.grid.items()}, zone_names=zn,
              data=data, refs=refs)
    t.check_shapes()
    return t


def run_points(spec: TableSpec, builder: Callable, executor: str = "processes",
               workers: int | None = None, scheduler: str | None = None,
               progress: bool = True) -> list[dict]:
    """Evaluate ``builder(scene, point)`` at every grid point; results in grid order.

    executor: ``serial``; ``processes`` (a local process pool of ``workers`` processes,
    default all cores); ``dask`` (a Dask LocalCluster on 127.0.0.1 with ``workers``
    single-threaded worker processes, or the existing cluster at ``scheduler``, e.g.
    ``tcp://host:8786``, when given). A tqdm bar counts finished grid points.
    """
    points = spec.points()
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(points), unit="point", desc=f"table {spec.key()[:10]}")
    results: list = [None] * len(points)
    try:
        if scheduler is not None or executor == "dask":
            _run_dask(spec, builder, points, results, workers, scheduler, bar)
        elif executor == "serial" or len(points) == 1:
            for i, p in enumerate(points):
                results[i] = builder(spec.scene, p)
                if bar is not None:
                    bar.update(1)
        elif executor == "processes":
            from concurrent.futures import ProcessPoolExecutor, as_completed
            n = min(workers or os.cpu_count() or 1, len(points))
            with ProcessPoolExecutor(max_workers=n) as pool:
                futs = {pool.submit(builder, spec.scene, p): i for i, p in enumerate(points)}
                for f in as_completed(futs):
                    results[futs[f]] = f.result()
                    if bar is not None:
                        bar.update(1)
        else:
            raise TableError(f"executor = {executor!r}: allowed 'serial', 'processes', 'dask'")
    finally:
        if bar is not None:
            bar.close()
    return results


def _run_dask(spec, builder, points, results, workers, scheduler, bar):
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise TableError("executor 'dask' / --scheduler: needs the packages dask and "
                         "distributed (pip install dask distributed)") from None
    with contextlib.ExitStack() as stack:
        if scheduler is not None:
            client = stack.enter_context(Client(scheduler))
        else:
            cluster = stack.enter_context(LocalCluster(
                n_workers=min(workers or os.cpu_count() or 1, len(points)),
                threads_per_worker=1, processes=True, host="127.0.0.1",
                dashboard_address=None))
            client = stack.enter_context(Client(cluster))
        futs = client.map(builder, [spec.scene] * len(points), points, pure=False)
        where = {f.key: i for i, f in enumerate(futs)}
        for f in as_completed(futs):
            results[where[f.key]] = f.result()
            if bar is not None:
                bar.update(1)


def build_table(spec: TableSpec, builder: Callable, **run_kw) -> Table:
    """Run the builder over the grid and assemble the table (not cached)."""
    t0 = time.perf_counter()
    results = run_points(spec, builder, **run_kw)
    table = assemble(spec, results)
    table.manifest = {"build_wall_time_s": time.perf_counter() - t0}
    st = stationarity_summary(results, table.zone_names)
    if st is not None:
        table.manifest["stationarity"] = st
    return table


def manifest_for(spec: TableSpec, table: Table, extra: dict | None = None) -> dict:
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
    if spec.builder_id == DemBuilder.builder_id:
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


@contextlib.contextmanager
def _locked(path: Path):
    with open(path, "a+") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)


def entry_dir(spec: TableSpec, cache_dir=None) -> Path:
    return resolve_cache_dir(cache_dir) / spec.key()


def load_cached(spec: TableSpec, cache_dir=None) -> Table | None:
    """The cached table of ``spec`` if its entry passes every check, else None."""
    d = entry_dir(spec, cache_dir)
    if not d.exists():
        return None
    try:
        return read_table(d, expect_key=spec.key(), expect_kernel=spec.kernel_version)
    except TableError:
        return None


def get_table(spec: TableSpec, builder: Callable, cache_dir=None, force: bool = False,
              log: Callable[[str], None] | None = None, **run_kw) -> Table:
    """The table of ``spec``: from the cache if its entry verifies, else built and cached.

    Concurrent callers serialize on ``<cache>/<key>.lock`` (fcntl.flock); the second finds
    the first one's entry. A new entry is written into a temporary folder in the cache and
    renamed into place, so readers see either no entry or a complete one; an entry that
    fails verification is replaced. ``force`` rebuilds even a good entry.
    """
    root = resolve_cache_dir(cache_dir)
    key = spec.key()
    if not force:
        t = load_cached(spec, root)
        if t is not None:
            return t
    root.mkdir(parents=True, exist_ok=True)
    with _locked(root / f"{key}.lock"):
        if not force:
            t = load_cached(spec, root)  # built by another process while we waited
            if t is not None:
                return t
        final = root / key
        if final.exists() and log is not None:
            try:
                read_table(final, expect_key=key, expect_kernel=spec.kernel_version)
            except TableError as e:
                log(f"rebuilding cache entry {key[:12]}: {e}")
        table = build_table(spec, builder, **run_kw)
        tmp = Path(tempfile.mkdtemp(prefix=f".tmp-{key[:16]}-", dir=root))
        try:
            table.save(tmp, manifest_for(spec, table))
            if final.exists():
                trash = Path(tempfile.mkdtemp(prefix=f".old-{key[:16]}-", dir=root))
                os.rename(final, trash / "entry")
                shutil.rmtree(trash, ignore_errors=True)
            os.rename(tmp, final)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        _fsync_dir(root)
        return read_table(final, expect_key=key, expect_kernel=spec.kernel_version)


def _fsync_dir(path: Path):
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def cache_entries(cache_dir=None, kernel_version: str | None = None) -> list[dict]:
    """Every entry of the cache with its state: ``ok``, ``stale`` (older kernel version or
    format) or ``bad`` (fails a check), the reason, scene name, grid shape and size [bytes]."""
    root = resolve_cache_dir(cache_dir)
    out = []
    if not root.exists():
        return out
    kv = kernel_version if kernel_version is not None else dem_kernel_version()
    for d in sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")):
        info = {"key": d.name, "path": str(d),
                "bytes": sum(f.stat().st_size for f in d.iterdir() if f.is_file())}
        try:
            t = read_table(d, expect_key=d.name)
            m = t.manifest
            info.update(scene=m["scene"].get("name", "?"), shape=list(t.shape),
                        axes=list(t.axes), builder=m["builder"])
            if m["builder"] == DemBuilder.builder_id and m["kernel_version"] != kv:
                info.update(state="stale", reason="built with DEM kernel version "
                            f"{m['kernel_version'][:19]}..., current {kv[:19]}...")
            else:
                info.update(state="ok", reason="")
        except TableError as e:
            info.update(state="stale" if "stale" in str(e) else "bad", reason=str(e))
        out.append(info)
    return out


def clear_cache(cache_dir=None, only_not_ok: bool = False,
                kernel_version: str | None = None) -> list[str]:
    """Remove cache entries (all, or only stale and bad ones) and leftover temporary
    folders; returns the removed keys. Takes each entry's lock so that no build is cut."""
    root = resolve_cache_dir(cache_dir)
    removed = []
    if not root.exists():
        return removed
    for e in cache_entries(root, kernel_version):
        if only_not_ok and e["state"] == "ok":
            continue
        with _locked(root / f"{e['key']}.lock"):
            shutil.rmtree(e["path"], ignore_errors=True)
        (root / f"{e['key']}.lock").unlink(missing_ok=True)
        removed.append(e["key"])
    for p in root.glob(".tmp-*"):
        key16 = p.name[5:21]
        locks = list(root.glob(f"{key16}*.lock"))
        if not locks:
            shutil.rmtree(p, ignore_errors=True)
            continue
        with open(locks[0], "a+") as fh:  # skip folders of a build in progress
            try:
                fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                continue
            shutil.rmtree(p, ignore_errors=True)
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
    return removed


# ---- the DEM builder -----------------------------------------------------------------------
def rebin_density(dem_edges_J: np.ndarray, density_per_decade: np.ndarray,
                  e_ref: float) -> np.ndarray:
    """Number density over log10(SE) on the DEM's bins -> density over log10(SE / E_ref)
    on :func:`norm_log10_edges` [1/decade]. The density is taken constant within a DEM bin
    (the cumulative distribution linear in log10 SE); mass beyond the normalized range goes
    to the end bins, as the DEM statistics do with theirs."""
    u = np.log10(np.asarray(dem_edges_J, float)) - math.log10(e_ref)
    dens = np.asarray(density_per_decade, float)
    mass = dens * np.diff(u)
    total = mass.sum()
    U = norm_log10_edges()
    if total <= 0.0:
        return np.zeros(U.size - 1)
    cdf = np.concatenate([[0.0], np.cumsum(mass)]) / total
    F = np.interp(U, u, cdf, left=0.0, right=1.0)
    w = np.diff(F)
    w[0] += F[0]
    w[-1] += 1.0 - F[-1]
    return w / np.diff(U)


def normalize_stats(stats, scene) -> dict:
    """Per-point table fields from DEM statistics (:class:`millfmu.dem.stats.DemStats`) of
    a run of ``scene`` (:class:`millfmu.dem.scene.DemScene`, placement 'filling')."""
    d, rho = scene.bead_diameter_m, scene.material.density_kg_m3
    eref = e_ref_J(d, rho, scene.tip_speed_m_s)
    omega = scene.omega_rad_s
    ngb = n_gb_per_m3(scene.filling, scene.bulk_porosity, d)
    vols = np.array([z.volume_m3 for z in stats.zones])
    edges = np.asarray(stats.se_bin_edges_j)
    out = {
        "zone_names": [z.name for z in stats.zones],
        "volume_fraction": vols / vols.sum(),
        "filling_local": np.array([z.filling for z in stats.zones]),
        "speed_over_tip_speed": np.array([z.speed_over_tip_speed for z in stats.zones]),
        "collision_frequency_norm": np.array([z.collision_frequency_per_m3_s
                                              for z in stats.zones]) / (omega * ngb),
        "collision_power_norm": np.array([z.collision_power_w for z in stats.zones])
        / (vols * eref * omega * ngb),
        "collision_count": np.array([z.collision_count for z in stats.zones], float),
        "se_density": np.array([[rebin_density(edges, z.se[c].density_per_decade, eref)
                                 for z in stats.zones] for c in COMPONENTS]),
        "se_quantiles_norm": np.array([[[np.nan if z.se[c].quantiles_j[q] is None
                                         else z.se[c].quantiles_j[q] / eref
                                         for q in QUANTILE_NAMES] for z in stats.zones]
                                       for c in COMPONENTS]),
        "e_ref_J": eref, "omega_rad_s": omega, "n_gb_per_m3": ngb,
    }
    return out


@dataclass(frozen=True)
class DemBuilder:
    """Builder of one grid point: runs millfmu's DEM (:func:`millfmu.dem.run.run_scene`) on
    the scene with the point's values and returns the normalized fields. ``threads``: numba
    threads per run (1 when grid points run in parallel)."""

    threads: int | None = None
    builder_id = "millfmu.dem.tables.DemBuilder"

    def __call__(self, scene: dict, point: dict) -> dict:
        from .run import run_scene
        from .scene import scene_from_dict

        s = scene_from_dict(scene_at_point(scene, point))
        if s.placement != "filling":
            raise TableError(f"scene {s.name}: beads.placement = {s.placement!r}; tables "
                             f"need placement 'filling'")
        with tempfile.TemporaryDirectory(prefix="millfmu-table-point-") as tmp:
            t0 = time.perf_counter()
            # Two windows, the halves of the recording: their difference shows whether the
            # recorded state is stationary (manifest "stationarity").
            stats = run_scene(s, tmp, progress=False, threads=self.threads,
                              window_s=0.5 * s.record_s)
            out = normalize_stats(stats, s)
            out["drift"] = recording_drift(Path(tmp) / "windows.csv", out["zone_names"])
        out["wall_time_s"] = time.perf_counter() - t0
        return out




def recording_drift(windows_csv, zone_names) -> dict:
    """Relative change [-] of each of :data:`DRIFT_FIELDS` per zone from the first to the
    last window of a DEM run's ``windows.csv``: (last - first) / mean of the two."""
    import csv

    with open(windows_csv, newline="") as fh:
        rows = list(csv.DictReader(fh))
    starts = sorted({float(r["t_start_s"]) for r in rows})
    first = {r["zone"]: r for r in rows if float(r["t_start_s"]) == starts[0]}
    last = {r["zone"]: r for r in rows if float(r["t_start_s"]) == starts[-1]}
    out = {}
    for f in DRIFT_FIELDS:
        vals = []
        for z in zone_names:
            a, b = float(first[z][f]), float(last[z][f])
            m = 0.5 * (a + b)
            vals.append((b - a) / m if math.isfinite(m) and m > 0.0 else float("nan"))
        out[f] = vals
    return out


def stationarity_summary(results: list[dict], zone_names) -> dict | None:
    """Largest |drift| over the grid points per field and zone (None without drift data)."""
    if not all("drift" in r for r in results):
        return None
    out = {"measure": "relative change from the first to the second half of each grid "
                      "point's recording, largest magnitude over the grid points"}
    for f in DRIFT_FIELDS:
        arr = np.abs(np.array([r["drift"][f] for r in results], float))
        out[f] = {z: round(float(np.nanmax(arr[:, k])), 4) for k, z in enumerate(zone_names)}
    return out


def dem_spec(scene_name_or_path: str, grid: dict, overrides: dict | None = None) -> TableSpec:
    """Spec for a DEM table: the scene file's content (TOML -> dict) with ``overrides``
    (section -> {key: value}, e.g. {"run": {"spin_up_s": 0.05}}) merged in, validated."""
    from .scene import load_scene_dict

    d = load_scene_dict(scene_name_or_path)
    for sec, kv in (overrides or {}).items():
        d.setdefault(sec, {}).update(kv)
    spec = TableSpec(scene=d, grid=grid, kernel_version=dem_kernel_version())
    for p in (spec.points()[0], spec.points()[-1]):  # validate the corners early
        _validate_scene_dict(scene_at_point(d, p))
    return spec


def _validate_scene_dict(d: dict):
    from .scene import scene_from_dict

    scene_from_dict(d)


def rebuild_including(table: Table, point: dict, builder: Callable | None = None,
                      cache_dir=None, progress: bool = True, **run_kw) -> Table:
    """Build (or find in the cache) a table like ``table`` whose grid also covers ``point``:
    each axis whose value lies outside gets that value as a new end node. Every grid point
    of the new table is built (the cache holds whole tables). ``builder``: default the DEM
    (:class:`DemBuilder`, with the installed kernel version)."""
    old = table.spec()
    grid = {}
    for ax, vals in old.grid.items():
        x = float(point[ax])
        grid[ax] = sorted(set(vals) | ({x} if not vals[0] <= x <= vals[-1] else set()))
    if builder is None:
        builder = DemBuilder()
        kv = dem_kernel_version()
    else:
        kv = old.kernel_version
    spec = TableSpec(scene=old.scene, grid=grid, kernel_version=kv,
                     builder_id=_builder_id(builder))
    return get_table(spec, builder, cache_dir=cache_dir, progress=progress, **run_kw)


# ---- the kinetics' interface ---------------------------------------------------------------
@dataclass
class TableStressSource:
    """Stress-energy source of the detailed model read from a table
    (:class:`millfmu.kinetics.stress_distribution.StressEnergySource`).

    ``zones(op)`` interpolates the table at (tip speed, filling, and bead diameter, bead
    density, viscosity where the table has them as axes) and scales back with the operating
    point's own E_ref (= op.se_beads_J) and omega n_gb: energies [J] = table bins x E_ref,
    collision rate [1/(m3 s)] = collision_frequency_norm x omega n_gb. ``component``: 'tn'
    (default, see the module docstring) or 'total'.

    Axes the table does not vary (e.g. bead diameter, bead density, viscosity of the
    default table) must match the table's DEM scene (relative tolerance 1e-9), unless
    named in ``similar_axes``: then the dimensionless fields are used unchanged, i.e.
    similarity in that axis is assumed (recorded in ``last_notes``); millfmu's tests show
    the scaling only along the tip speed, so this is an explicit choice of the scene.
    ``tip_speed_m_s`` in ``similar_axes`` lets tip speeds outside the grid (a ramp from
    standstill, a controller's excursion) use the nearest edge's dimensionless fields.
    A point outside the grid raises :class:`OutsideGridError` unless
    ``on_outside='build'``: then ``rebuild(table, point)`` (default :func:`rebuild_including`
    with the DEM) builds and caches a table whose grid covers the point, progress shown.
    At tip speed 0 (stirrer at rest) there are no collisions: zones with zero rate.
    """

    table: Table
    component: str = "tn"
    similar_axes: tuple = ()
    on_outside: str = "refuse"
    rebuild: Callable | None = None  # (table, point) -> Table covering the point
    last_lookup: Lookup | None = None
    last_notes: list = field(default_factory=list)

    def __post_init__(self):
        if self.component not in COMPONENTS:
            raise TableError(f"component = {self.component!r}: allowed {list(COMPONENTS)}")
        if self.on_outside not in ("refuse", "build"):
            raise TableError(f"on_outside = {self.on_outside!r}: allowed 'refuse', 'build'")
        self.similar_axes = tuple(self.similar_axes)
        for ax in self.similar_axes:
            if ax not in EXTRAPOLABLE_AXES:
                raise TableError(f"similar_axes: {ax!r} not allowed; allowed: "
                                 f"{', '.join(EXTRAPOLABLE_AXES)}")

    def point_of(self, op) -> dict:
        return {ax: float(getattr(op, AXES[ax][3])) for ax in self.table.axes}

    def _check_fixed_axes(self, op) -> list:
        """Notes for the axes the table does not vary whose op value differs (similarity
        assumed); OutsideGridError for such an axis not named in ``similar_axes``."""
        notes = []
        for ax, v in self.table.fixed_axis_values().items():
            x = float(getattr(op, AXES[ax][3]))
            if abs(x - v) <= FIXED_AXIS_RTOL * abs(v):
                continue
            if ax not in self.similar_axes:
                raise OutsideGridError(ax, x, v, v, note=" (its DEM scene's value; the "
                                       "table does not vary it; name it in similar_axes "
                                       "to assume similarity)")
            notes.append(f"{ax} = {x!r}: table scene has {v!r}; similarity assumed")
        return notes

    def check(self, op):
        """Raise :class:`OutsideGridError` if :meth:`zones` would refuse ``op`` (a point
        outside the grid with ``on_outside='refuse'``); cheap: the axes' bounds only, by
        the same rules as the lookup (:meth:`Table.axis_value`), no interpolation."""
        self._check_fixed_axes(op)
        if self.on_outside == "build":
            return
        for ax, x in self.point_of(op).items():
            if ax == "tip_speed_m_s" and not x > 0.0:
                continue  # the stirrer at rest: no collisions, nothing to look up
            self.table.axis_value(ax, x, self.similar_axes)

    def zones(self, op):
        from ..kinetics.stress_distribution import Zone

        names = self.table.zone_names
        U = norm_log10_edges()
        if not op.tip_speed_m_per_s > 0.0:
            # Stirrer at rest: no collisions carry energy.
            edges = np.array([1e-300, 2e-300])
            vf = self._volume_fractions()
            return [Zone(n, float(v), 0.0, edges, np.array([1.0])) for n, v in zip(names, vf)]
        notes = self._check_fixed_axes(op)
        point = self.point_of(op)
        try:
            lk = self.table.lookup(point, self.similar_axes)
        except OutsideGridError:
            if self.on_outside != "build":
                raise
            rebuild = self.rebuild or rebuild_including
            self.table = rebuild(self.table, point)
            lk = self.table.lookup(point, self.similar_axes)
        self.last_lookup = lk
        self.last_notes = notes + lk.notes
        eref = float(op.se_beads_J)
        scale = float(op.omega_rad_per_s * op.n_gb_per_m3)
        edges = eref * 10.0 ** U
        ci = COMPONENTS.index(self.component)
        vf = lk.values["volume_fraction"]
        vf = vf / vf.sum()
        out = []
        for k, n in enumerate(names):
            w = np.clip(lk.values["se_density"][ci, k], 0.0, None) * np.diff(U)
            rate = max(float(lk.values["collision_frequency_norm"][k]), 0.0) * scale
            if w.sum() <= 0.0:
                # No recorded collisions here: no rate, and a placeholder bin at the bottom.
                w = np.zeros_like(w)
                w[0] = 1.0
                rate = 0.0
            out.append(Zone(n, float(vf[k]), rate, edges, w / w.sum()))
        return out

    def _volume_fractions(self):
        # The geometry fixes the zone volumes; take them at the first grid point.
        vf = self.table.data["volume_fraction"].reshape(-1, len(self.table.zone_names))[0]
        return vf / vf.sum()


# ---- shipped default table -----------------------------------------------------------------
DEFAULT_TABLE_NPZ = "default_table.npz"
DEFAULT_TABLE_MANIFEST = "default_table.json"


def default_table_paths() -> tuple[Path, Path]:
    """Paths of the shipped default table (millfmu/data/default_table.npz, .json)."""
    base = Path(importlib.util.find_spec("millfmu").origin).parent / "data"
    return base / DEFAULT_TABLE_NPZ, base / DEFAULT_TABLE_MANIFEST


def read_table_ref(ref: str) -> Table:
    """The table a scene names: "default" (the shipped one) or PREFIX of PREFIX.npz/PREFIX.json."""
    if ref == "default":
        return read_default_table()
    return read_table(npz=ref + ".npz", manifest_path=ref + ".json")


def read_default_table() -> Table:
    """The shipped default table, verified (checksums, key, shapes; its kernel version is
    recorded in its manifest and not required to match the installed DEM)."""
    npz, man = default_table_paths()
    if not npz.exists():
        raise TableError(f"default table {npz.name}: not shipped in this installation")
    return read_table(npz=npz, manifest_path=man)
