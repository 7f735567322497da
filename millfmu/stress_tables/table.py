"""The stress-energy table and its lookup: :class:`Table` (multilinear interpolation with
error estimates and sampling standard deviations, slices, export), :func:`read_table`, which
verifies a table's files before it is used, and the shipped default table.

Part of what an FMU carries (with :mod:`.spec`, :mod:`.files`, :mod:`.stress_source` and
:mod:`.rules`): numpy only, no DEM, no numba.
"""

from __future__ import annotations

import importlib.util
import itertools
import json
import math
import os
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from collections.abc import Iterable

import numpy as np

from ..unit_names import modern_name, modernize
from .files import (MANIFEST_FILE, MANIFEST_SUM_FILE, MANIFEST_SUM_KEY, TABLE_FILE,
                    manifest_digest, sha256_bytes, sha256_file, write_synced)
from .spec import (AXES, COMPONENTS, DRIFT_FIELDS, EARLIER_FORMAT, FIELDS, FORMAT_VERSION, OPTIONAL_FIELDS,
                   QUANTILE_NAMES, ZONE_FIELDS, TableError, TableSpec, manifest_for,
                   norm_log10_edges)


#: Error estimates multiply the second-difference estimate of the linear-interpolation error
#: by this factor, because the curvature is taken at neighbouring nodes, not at the point.
ERROR_SAFETY = 2.0
#: Gridded axes along which ``similar_axes`` may extend a lookup beyond the grid by holding
#: the dimensionless fields at the nearest edge: energies over E_ref ~ v_t^2 and frequencies
#: over omega n_gb ~ v_t take out the leading tip-speed dependence (seed 000's stress model);
#: tests/tables and the default table's manifest show how far that holds. Not filling: the
#: bead fillings and collision densities change with it in ways no normalization removes.
EXTRAPOLABLE_AXES = ("tip_speed_m_per_s", "bead_diameter_m", "bead_density_kg_per_m3",
                     "viscosity_Pa_s")
#: Manifest entries that a table's stated error reads besides its grid's own interpolation
#: error and sampling sigma (the checks against the DEM off the nodes, the spread of
#: independent realizations): a slice of the table and a table extended from it keep them.
STATED_ERROR_ENTRIES = ("interpolation_check", "separability_check", "realization_spread")
#: Relative tolerance for matching a single-valued axis (an axis the grid does not vary).
FIXED_AXIS_RTOL = 1e-9
#: Prefix of a one-at-a-time axis's arrays in table.npz: ``oat__<axis>__<array>``.
ONE_AT_A_TIME_PREFIX = "oat__"
#: Upper limit of a Poisson mean where a count of 0 was observed, at the confidence of one
#: Gaussian sigma (84.13 %, one-sided): -ln(1 - 0.8413) = 1.841 (Gehrels 1986, ApJ 303:336,
#: Table 1). The sampling sigma of a zone's collision frequency where its run counted none.
ZERO_COUNT_SIGMA = 1.841
#: Prefix of the arrays of an axis's side table at the anchor, where it was run partly across.
ONE_AT_A_TIME_ANCHOR_PREFIX = "oat_anchor__"


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


# ---- the table -----------------------------------------------------------------------------
@dataclass
class Lookup:
    """Interpolated fields at one point (``values``), their interpolation-error estimates
    (``error``, same shapes) and the sampling standard deviation carried over from the DEM
    nodes (``sigma``); ``cell``: the grid nodes the values were interpolated from, as
    (grid index, weight) pairs; ``similar``: the axes whose value lay beyond what the table
    resolves, where similarity was assumed (each also has a note)."""

    point: dict
    values: dict
    error: dict
    notes: list = field(default_factory=list)
    sigma: dict = field(default_factory=dict)
    cell: list = field(default_factory=list)
    similar: set = field(default_factory=set)

    def bound(self, name: str, k_sigma: float = 2.0) -> np.ndarray:
        """Interpolation error plus ``k_sigma`` sampling standard deviations of a field."""
        return self.error[name] + k_sigma * self.sigma.get(name, 0.0)


@dataclass
class Table:
    """Grid axes, zone names and the fields of :data:`FIELDS` as arrays of shape
    grid shape + field shape; plus per grid point the references ``e_ref_J`` [J],
    ``omega_rad_per_s`` [rad/s] and ``n_gb_per_m3`` [1/m3] used to normalize."""

    axes: dict
    zone_names: tuple
    data: dict
    refs: dict
    manifest: dict = field(default_factory=dict)
    #: One-at-a-time axes (:class:`TableSpec`): axis -> a 1-D table along it at the anchor,
    #: the scene's value among its nodes.
    one_at_a_time: dict = field(default_factory=dict)
    #: Reference (the scene's value) of each one-at-a-time axis, and the anchor (the scene's
    #: values of the grid axes) they are varied from.
    one_at_a_time_ref: dict = field(default_factory=dict)
    anchor: dict = field(default_factory=dict)
    #: Axes run partly across a sub-grid (:meth:`TableSpec.partly_across`): axis -> a 1-D
    #: table along all its values at the anchor, read beyond the values run across
    #: (:meth:`side_of`); ``one_at_a_time`` holds those values across the sub-grid.
    one_at_a_time_anchor: dict = field(default_factory=dict)

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
        for k in ("e_ref_J", "omega_rad_per_s", "n_gb_per_m3"):
            if k not in self.refs or self.refs[k].shape != self.shape:
                raise TableError(f"table: reference {k!r} missing or of wrong shape")
        if set(self.one_at_a_time_ref) != set(self.one_at_a_time) or (
                self.one_at_a_time and set(self.anchor) != set(self.axes)):
            raise TableError("table: one-at-a-time axes without their reference or anchor")
        for name, side in self.one_at_a_time.items():
            if list(side.axes)[:1] != [name] or not set(list(side.axes)[1:]) <= set(self.axes) \
                    or side.zone_names != self.zone_names:
                raise TableError(f"table: one-at-a-time axis {name}: its table has axes "
                                 f"{list(side.axes)} and zones {side.zone_names}")
            side.check_shapes()
        for name, side in self.one_at_a_time_anchor.items():
            if name not in self.one_at_a_time or list(side.axes) != [name] or side.zone_names != self.zone_names:
                raise TableError(f"table: one-at-a-time axis {name}: its table at the anchor has axes "
                                 f"{list(side.axes)} and zones {side.zone_names}")
            side.check_shapes()

    def side_of(self, name: str, x: float | None = None) -> Table:
        """The side table of one-at-a-time axis ``name`` that a lookup at its value ``x``
        reads: the one in ``one_at_a_time``, except for an axis run partly across
        (``one_at_a_time_anchor``) with ``x`` beyond the values run across: then its table
        at the anchor."""
        side = self.one_at_a_time[name]
        outer = self.one_at_a_time_anchor.get(name)
        if outer is None or x is None:
            return side
        a = side.axes[name]
        inside = float(a[0]) * (1.0 - FIXED_AXIS_RTOL) <= x <= float(a[-1]) * (1.0 + FIXED_AXIS_RTOL)
        return side if inside else outer

    def one_at_a_time_values(self, name: str) -> np.ndarray:
        """Every value one-at-a-time axis ``name`` was run at (across a sub-grid or at the
        anchor) [the axis's unit]."""
        side = self.one_at_a_time_anchor.get(name, self.one_at_a_time[name])
        return np.asarray(side.axes[name], float)

    def check_values(self, where: str = "table"):
        """Raise TableError unless the contents are what a DEM run gives: finite (nan only
        where a zone had no collisions), non-negative, normalized fields below NORM_MAX,
        positive references, energy densities integrating to 1; one-at-a-time tables too."""
        _check_values(self, where)
        for name, side in self.one_at_a_time.items():
            _check_values(side, f"{where} (one-at-a-time axis {name})")
        for name, side in self.one_at_a_time_anchor.items():
            _check_values(side, f"{where} (one-at-a-time axis {name} at the anchor)")

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
        by ERROR_SAFETY, plus 16 ulps of the value for rounding; zero at grid points; on an
        axis with 2 points, where no curvature can be estimated, the field is taken as
        monotone between them: max(t, 1 - t) |f1 - f0|. This is the error of interpolating
        between the stored values. The DEM's own sampling noise is separate:
        ``Lookup.sigma`` (see :meth:`node_sigma`) propagated through the weights,
        sqrt(sum w_c^2 sigma_c^2); :meth:`Lookup.bound` combines the two.
        """
        similar = set(similar_axes)
        idx, ts, notes, assumed, used = [], [], [], set(), {}
        for name, ax in self.axes.items():
            if name not in point:
                raise TableError(f"table lookup: axis {name} missing from the point "
                                 f"{point!r}; the table's axes: {list(self.axes)}")
            x, note = self.axis_value(name, float(point[name]), similar)
            used[name] = x
            if note:
                notes.append(note)
                assumed.add(name)
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
        lk = Lookup(point=dict(point), values=values, error=errors, notes=notes,
                    sigma=sigmas, cell=list(_corners(idx, ts)), similar=assumed)
        shift, d_err, d_sig = 0.0, 0.0, 0.0
        for name in self.one_at_a_time:
            if name not in point:
                raise TableError(f"table lookup: one-at-a-time axis {name} missing from the "
                                 f"point {point!r}; the table's axes: {list(self.axes)} and "
                                 f"one at a time {list(self.one_at_a_time)}")
            s_, e_, g_ = self._apply_one_at_a_time(lk, name, float(point[name]), similar, used)
            shift, d_err, d_sig = shift + s_, d_err + e_, np.hypot(d_sig, g_)
        if np.any(shift != 0.0):
            # one shift for all axes: successive shifts would each smear by a bin
            for d in (lk.values, lk.error, lk.sigma):
                d["se_density"] = shift_log_density(np.asarray(d["se_density"], float), shift)
            # the shift's own uncertainty [decades] moves the density by |d rho/du| delta
            v = lk.values["se_density"]
            for d, delta in ((lk.error, d_err), (lk.sigma, d_sig)):
                delta = np.broadcast_to(np.asarray(delta, float), v.shape[:-1])
                moved = shift_log_density(v, np.nan_to_num(delta))
                extra = np.where(np.isnan(delta)[..., None], np.nan, np.abs(moved - v))
                d["se_density"] = d["se_density"] + extra if d is lk.error else \
                    np.hypot(d["se_density"], extra)
        return lk

    def _apply_one_at_a_time(self, lk: Lookup, name: str, x: float, similar, at_grid: dict):
        """Scale the grid's fields at ``lk`` by what axis ``name`` changes at the anchor,
        from its reference (the scene's value) to ``x`` (separability assumed); where the
        axis was run across a sub-grid of the grid axes (``TableSpec.across``: its side
        table has those axes too), by the change interpolated there at the lookup's values
        of them, ``at_grid`` (held at the sub-grid's edges beyond it); for an axis run partly
        across, beyond the values run across by the change at the anchor (:meth:`side_of`):

        - local filling, speed, collision frequency and power: times S(x) / S(ref), S the
          side table's value per zone (unchanged where S(ref) = 0);
        - SE quantiles and densities: shifted in log10(SE / E_ref) by the change of the
          side table's median, log10 q50(x) / q50(ref), per component and zone; the shape
          of the distribution stays the grid's;
        - volume fractions (geometry), collision counts and recording drift: unchanged.

        Errors: the grid's scaled, plus the value times the side's relative interpolation
        error; sigma: the grid's scaled, with the side's relative sigmas at x and at the
        reference in quadrature. Returns the shift [decades] per (component, zone) that the
        caller applies to the densities, and that shift's interpolation error and sigma
        [decades] (0.0 each at the reference)."""
        side = self.side_of(name, x)
        xu, note = side.axis_value(name, x, similar)
        if note:
            lk.notes.append(note)
            lk.similar.add(name)
        ref = self.one_at_a_time_ref[name]
        if math.isclose(xu, ref, rel_tol=FIXED_AXIS_RTOL):
            return 0.0, 0.0, 0.0
        across = {ax: v for ax, v in self._side_point(name, {**at_grid, name: xu}).items() if ax != name}
        at = side.lookup({name: xu, **across})
        r0 = side.lookup({name: ref, **across})
        if across:
            where = ", ".join(f"{ax} = {v:g}" for ax, v in across.items())
            lk.notes.append(f"{name} = {x!r}: the grid's fields scaled by the change from "
                            f"{ref!r} interpolated at {where} over the sub-grid it was run "
                            f"across (one-at-a-time axis)")
        else:
            lk.notes.append(f"{name} = {x!r}: the grid's fields scaled by the change from "
                            f"{ref!r} at the anchor {self.anchor} (one-at-a-time axis; "
                            f"separability assumed)")

        def rel(a, b):
            with np.errstate(divide="ignore", invalid="ignore"):
                return np.where(np.abs(b) > 0, np.abs(a) / np.abs(b), 0.0)

        for k in ("filling_local", "speed_over_tip_speed", "collision_frequency_norm",
                  "collision_power_norm"):
            s_x, s_0 = at.values[k], r0.values[k]
            with np.errstate(divide="ignore", invalid="ignore"):
                f = np.where(s_0 > 0, s_x / s_0, 1.0)
            if np.any(s_0 <= 0):
                lk.notes.append(f"{name}: {k} is 0 at the anchor in zones "
                                f"{[z for z, b in zip(self.zone_names, s_0 <= 0) if b]}: "
                                f"left unscaled there")
            v = lk.values[k] * f
            lk.error[k] = lk.error[k] * f + np.abs(v) * rel(at.error[k], s_x)
            lk.sigma[k] = np.hypot(lk.sigma.get(k, 0.0) * f, np.abs(v) * np.hypot(
                rel(at.sigma[k], s_x), rel(r0.sigma[k], s_0)))
            lk.values[k] = v
        qi = QUANTILE_NAMES.index("q50")
        q_x, q_0 = at.values["se_quantiles_norm"][..., qi], r0.values["se_quantiles_norm"][..., qi]
        ok = (q_x > 0) & (q_0 > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            shift = np.where(ok, np.log10(q_x / q_0), 0.0)  # (C, Z)
        if not np.all(ok):
            lk.notes.append(f"{name}: no median SE at x or at the anchor in zones "
                            f"{sorted({self.zone_names[z] for z in np.nonzero(~ok)[1]})}: "
                            f"their energy distributions left unshifted")
        f = (10.0 ** shift)[..., None]
        k = "se_quantiles_norm"
        v = lk.values[k] * f
        relq = np.hypot(rel(at.sigma[k][..., qi], q_x), rel(r0.sigma[k][..., qi], q_0))
        lk.error[k] = lk.error[k] * f + np.abs(v) * rel(at.error[k][..., qi], q_x)[..., None]
        lk.sigma[k] = np.hypot(lk.sigma.get(k, 0.0) * f, np.abs(v) * relq[..., None])
        lk.values[k] = v
        ln10 = math.log(10.0)
        return shift, rel(at.error[k][..., qi], q_x) / ln10, relq / ln10


    def separability_error(self, point: dict) -> dict:
        """Relative error [-] per zone that scaling the grid by the one-at-a-time axes' change
        at the anchor adds at ``point``, from the manifest's separability checks (DEM runs
        off the anchor), for ``collision_frequency`` and ``se_median`` (SE_tn's median).

        A check c of axis A measured b_c = max(l/r, r/l) - 1 per zone (l the lookup, r the
        run; the factor the band's edges (1 + b)^(+-1) must span). At a point where A is off
        its reference and the grid axes are off where A was measured, the error is taken to
        grow with both distances: b = max_c b_c (g / g_c) (h / h_c), g the largest distance
        over the grid axes from where A was run (the anchor; on an axis A was run across,
        the nearest of those values), in units of each axis's range, h = |ln(x / x_ref)| on
        A; summed over the axes off their reference. 0 where A was run and on the
        references. NaN in every zone for an axis off its reference away from where it was
        run that no check measured, and in a zone that every check of the axis found empty.
        A check at a node of the axis's side table (g_c = 0: another realization of it) adds
        its b_c there, carried to nearby points by the side table's interpolation weights.
        For an axis run partly across, a point reads the checks of the side table it is
        looked up on (:meth:`side_of`): across the sub-grid or at the anchor."""
        names = self.zone_names
        out = {"collision_frequency": np.zeros(len(names)), "se_median": np.zeros(len(names))}
        if not self.one_at_a_time:
            return out
        checks = (self.manifest.get("separability_check") or {}).get("points") or []
        for name, ref in self.one_at_a_time_ref.items():
            h = abs(math.log(float(point.get(name, ref)) / ref))
            if h <= FIXED_AXIS_RTOL:
                continue
            g = self._measured_distance(name, point)
            side = self.side_of(name, float(point.get(name, ref)))
            worst = {k: np.full(len(names), np.nan) if g > 0.0 else np.zeros(len(names)) for k in out}
            at_nodes = {k: np.zeros(len(names)) for k in out}
            weights = None
            for c in checks:
                hc = abs(math.log(float(c["point"].get(name, ref)) / ref))
                if hc <= FIXED_AXIS_RTOL or self.side_of(name, float(c["point"].get(name, ref))) is not side:
                    continue
                gc = self._measured_distance(name, c["point"])
                if gc > 0.0 and g == 0.0:
                    continue
                if gc == 0.0:  # another realization of a node of the axis's side table
                    if weights is None:
                        weights = self._side_weights(name, point)
                    w = weights.get(side._node_of(self._side_point(name, c["point"])), 0.0)
                    if w == 0.0:
                        continue
                for key, fld in (("collision_frequency", "collision_frequency_norm"),
                                 ("se_median", "se_tn_q50_norm")):
                    r = np.array([np.nan if v is None else float(v)
                                  for v in c[fld]["lookup_rel_diff"]])
                    with np.errstate(divide="ignore", invalid="ignore"):
                        b = np.maximum(1.0 + r, 1.0 / (1.0 + r)) - 1.0
                    if gc == 0.0:
                        at_nodes[key] = at_nodes[key] + w * np.nan_to_num(b)
                    else:
                        worst[key] = np.fmax(worst[key], b * (g / gc) * (h / hc))
            for k in out:
                out[k] = out[k] + worst[k] + at_nodes[k]
        return out

    def _side_point(self, name: str, point: dict) -> dict:
        """Where ``name``'s side table (:meth:`side_of` at the point's value) is read for
        ``point``: the axis's value and, on the grid axes it was run across, the point's
        values held within that sub-grid."""
        side = self.side_of(name, float(point.get(name, self.one_at_a_time_ref[name])))
        q = {}
        for ax, a in side.axes.items():
            x = float(point.get(ax, self.one_at_a_time_ref[name] if ax == name else self.anchor.get(ax, a[0])))
            q[ax] = min(max(x, float(a[0])), float(a[-1]))
        return q

    def _side_weights(self, name: str, point: dict) -> dict:
        """Interpolation weight of each node of ``name``'s side table at ``point`` (index ->
        weight)."""
        side = self.side_of(name, float(point.get(name, self.one_at_a_time_ref[name])))
        return {idx: w for idx, w in side.lookup(self._side_point(name, point)).cell}

    def node_check_error(self, lk: Lookup) -> dict:
        """Relative error [-] per zone from the checks that ran the DEM again at a grid node
        (the one-at-a-time axes at their references): another realization of that node. At
        each such node the measured difference |l - r| (l the node's value, r the check's
        run) is taken as the node's error and carried to the lookup ``lk`` through its
        interpolation weights (``lk.cell``), sum_c w_c |l - r|_c, over the grid's own interpolant there;
        for ``collision_frequency`` and ``se_median`` (SE_tn's median). Zeros where no
        node of the point's cell was checked. Where a zone does not settle to one state in
        a run (a slice's outer zone at 60 % filling, filled in one realization and empty in
        another), this is what states it."""
        names = self.zone_names
        out = {"collision_frequency": np.zeros(len(names)), "se_median": np.zeros(len(names))}
        checks = (self.manifest.get("interpolation_check") or {}).get("points") or []
        nodes = {}
        for c in checks:
            at = self._node_of(c["point"])
            if at is not None:
                nodes[at] = c
        if not nodes:
            return out
        ci = COMPONENTS.index("tn")
        qi = QUANTILE_NAMES.index("q50")
        for key, fld in (("collision_frequency", "collision_frequency_norm"),
                         ("se_median", "se_tn_q50_norm")):
            num, den = np.zeros(len(names)), np.zeros(len(names))
            for corner, w in lk.cell:
                node = self.data["collision_frequency_norm"][corner] if key == "collision_frequency" \
                    else self.data["se_quantiles_norm"][corner][ci, :, qi]
                node = np.nan_to_num(np.asarray(node, float))
                den = den + w * np.abs(node)
                c = nodes.get(corner)
                if c is not None:
                    run = np.array([np.nan if v is None else float(v) for v in c[fld]["run"]])
                    num = num + w * np.nan_to_num(np.abs(node - run))
            with np.errstate(divide="ignore", invalid="ignore"):
                out[key] = np.where(den > 0.0, num / den, np.where(num > 0.0, np.inf, 0.0))
        return out

    def _node_of(self, point: dict):
        """The grid index of ``point`` if it is a node with every one-at-a-time axis at its
        reference, else None."""
        for name, ref in self.one_at_a_time_ref.items():
            if name in point and not math.isclose(float(point[name]), ref, rel_tol=FIXED_AXIS_RTOL):
                return None
        idx = []
        for name, ax in self.axes.items():
            if name not in point:
                return None
            hit = np.nonzero(np.isclose(ax, float(point[name]), rtol=FIXED_AXIS_RTOL, atol=0.0))[0]
            if hit.size == 0:
                return None
            idx.append(int(hit[0]))
        return tuple(idx)

    def realization_error(self) -> dict:
        """Relative error [-] per zone from the spread of independent DEM realizations of one
        point, the manifest's ``realization_spread`` (measured at the work-precision point
        by the kernel-equivalence reference runs): its relative standard deviation times its
        ``prediction_factor``, t(0.975, n - 1) sqrt(2), the 95 % bound of the difference
        between the table's value and another run; for ``collision_frequency`` and
        ``se_median`` (SE_tn's median). Zeros where the manifest has none. The table's
        sampling sigma counts collisions as independent; realizations differ by more where
        the same beads collide again and again."""
        names = self.zone_names
        rs = self.manifest.get("realization_spread") or {}
        k = float(rs.get("prediction_factor") or 0.0)
        out = {}
        for key, fld in (("collision_frequency", "collision_frequency_norm"),
                         ("se_median", "se_tn_q50_norm")):
            sd = (rs.get("relative_sd") or {}).get(fld)
            out[key] = (k * np.array([np.nan if v is None else float(v) for v in sd])
                        if sd and len(sd) == len(names) else np.zeros(len(names)))
        return out

    def _measured_distance(self, name: str, point: dict) -> float:
        """Largest distance of ``point`` over the grid axes from where one-at-a-time axis
        ``name`` was run, in units of each axis's range [-]: from the anchor's value, or on a
        grid axis its side table spans (``across``), from the nearest of its values there;
        and, where the side table holds ``name`` itself at several values (run across), along
        ``name`` from the nearest of them in units of their range: a value between them is
        interpolated as the grid axes are."""
        x_a = float(point.get(name, self.one_at_a_time_ref[name]))
        side = self.side_of(name, x_a)
        d = 0.0
        for ax, a in self.anchor.items():
            grid = self.axes.get(ax)
            if grid is None or grid.size < 2 or ax not in point:
                continue
            x = float(point[ax])
            near = side.axes[ax] if ax in side.axes else np.array([float(a)])
            d = max(d, float(np.min(np.abs(near - x))) / float(grid[-1] - grid[0]))
        own = side.axes.get(name)
        if own is not None and own.size >= 2:
            d = max(d, float(np.min(np.abs(own - x_a))) / float(own[-1] - own[0]))
        return d

    def node_sigma(self) -> dict:
        """Sampling standard deviation of each stored value, from the recorded collision
        count N of its zone (Poisson / binomial statistics; collisions treated as
        independent, so a lower bound where the same beads collide repeatedly):
        collision frequency f/sqrt(N), and in a zone that recorded none (N = 0) the frequency
        of ZERO_COUNT_SIGMA collisions there, the one-sided 1-sigma upper limit of a Poisson
        count of 0 (from the frequency per collision of the point's other zones, f_j vf_j /
        N_j, over the zone's volume fraction); collision power P sqrt(<e^2>)/(<e> sqrt(N)) with the
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
            # f = N / (T V_z omega n_gb): one collision's share f_j vf_j / N_j is the same in
            # every zone of a point, so an empty zone's count sigma is known from the others
            vf = self.data["volume_fraction"]
            per = np.where(n > 0, np.abs(self.data["collision_frequency_norm"]) * vf / np.maximum(n, 1.0), np.nan)
            share = np.nanmax(np.where(np.isfinite(per), per, -np.inf), axis=-1, keepdims=True)
            empty = (n <= 0) & np.isfinite(share) & (share > 0) & (vf > 0)
            out["collision_frequency_norm"] = np.where(
                empty, ZERO_COUNT_SIGMA * share / np.where(vf > 0, vf, 1.0), out["collision_frequency_norm"])
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
            i = idx[a]
            if ax.size < 3:
                # Two nodes hold no curvature: the field is taken as monotone between them,
                # so the truth lies between the nodes' values and the linear interpolant is
                # off by at most max(t, 1 - t) |f1 - f0| (the other axes at the cell's corners).
                step = np.abs(np.take(arr, i + 1, axis=a) - np.take(arr, i, axis=a))
                err = err + max(t, 1.0 - t) * _corner_max(step, idx[:a] + idx[a + 1:],
                                                         ts[:a] + ts[a + 1:])
                continue
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
            if ax not in self.axes and ax not in self.one_at_a_time and \
                    isinstance(scene.get(sec), dict) and key in scene[sec]:
                out[ax] = float(scene[sec][key])
        return out

    def spec(self) -> TableSpec:
        """The specification this table was built from (from its manifest)."""
        try:
            return TableSpec.from_manifest(self.manifest)
        except KeyError as e:
            raise TableError(f"table: manifest lacks {e}; not a cached or exported table") \
                from None

    def subset(self, bounds: dict) -> Table:
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
        sub = Table(axes=axes, zone_names=self.zone_names, data=data, refs=refs,
                    one_at_a_time=dict(self.one_at_a_time),
                    one_at_a_time_ref=dict(self.one_at_a_time_ref), anchor=dict(self.anchor),
                    one_at_a_time_anchor=dict(self.one_at_a_time_anchor))
        if "scene" in self.manifest:
            old = self.spec()
            spec = replace(old, grid={k: list(v) for k, v in axes.items()})
            sub.manifest = manifest_for(spec, sub, {"slice_of": self.manifest.get("key")},
                                        work_precision=self.manifest.get("work_precision"))
            # what the stated error reads from the full table's manifest
            for k in STATED_ERROR_ENTRIES:
                if k in self.manifest:
                    sub.manifest[k] = self.manifest[k]
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
        for name, side in self.one_at_a_time.items():
            pre = f"{ONE_AT_A_TIME_PREFIX}{name}__"
            out.update({pre + k: v for k, v in side.arrays().items()
                        if k != "norm_log10_edges"})
            out[pre + "reference"] = np.float64(self.one_at_a_time_ref[name])
        for name, side in self.one_at_a_time_anchor.items():
            pre = f"{ONE_AT_A_TIME_ANCHOR_PREFIX}{name}__"
            out.update({pre + k: v for k, v in side.arrays().items()
                        if k != "norm_log10_edges"})
        out.update({f"anchor_{k}": np.float64(v) for k, v in self.anchor.items()})
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
        write_synced(folder / MANIFEST_FILE, text)
        write_synced(folder / MANIFEST_SUM_FILE, (sha256_bytes(text) + "\n").encode())
        self.manifest = m
        return m


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


def shift_log_density(density: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """Densities over log10(SE / E_ref) [1/decade] on :func:`norm_log10_edges`, trailing
    shape (..., B), moved by ``shift`` [decades] (shape (...)): the cumulative distribution
    F(u) becomes F(u - shift), linear within a bin; what moves beyond the ends goes to the
    end bins, so the total is kept."""
    U = norm_log10_edges()
    dU = np.diff(U)
    out = np.empty_like(density)
    flat_d = density.reshape(-1, density.shape[-1])
    flat_s = np.broadcast_to(shift, density.shape[:-1]).reshape(-1)
    for i, (row, sh) in enumerate(zip(flat_d, flat_s)):
        w = row * dU
        total = w.sum()
        if sh == 0.0 or not np.isfinite(sh) or total == 0.0:
            out.reshape(-1, density.shape[-1])[i] = row
            continue
        F = np.concatenate([[0.0], np.cumsum(w)])
        Fn = np.interp(U - sh, U, F, left=0.0, right=total)
        wn = np.diff(Fn)
        wn[0] += Fn[0]
        wn[-1] += total - Fn[-1]
        out.reshape(-1, density.shape[-1])[i] = wn / dU
    return out


# ---- reading and verifying files ------------------------------------------------------------
def read_table(folder=None, *, npz=None, manifest_path=None, expect_key: str | None = None,
               expect_kernel: str | None = None) -> Table:
    """Read and verify a table; raise TableError saying what is wrong.

    Either ``folder`` (a cache entry: table.npz, manifest.json, manifest.json.sha256) or
    ``npz`` and ``manifest_path`` (a shipped table such as millfmu/data/coupled_table.*).
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
    m = _read_manifest(manifest_path, sum_path)
    spec = _manifest_spec(m, manifest_path, expect_key, expect_kernel)
    arrs = _read_arrays(npz, m, manifest_path)
    if m["format"] == EARLIER_FORMAT:
        m, arrs = _current_names(m, arrs, spec)
    t = _table_from_arrays(arrs, spec, m, npz)
    t.check_shapes()
    t.check_values(str(npz))
    return t


def _read_manifest(manifest_path: Path, sum_path: Path) -> dict:
    """The manifest, checked against its checksum (the .sha256 file or the one it holds) and
    the format version."""
    if not manifest_path.exists():
        raise TableError(f"{manifest_path}: missing")
    try:
        text = manifest_path.read_bytes()
        want = sum_path.read_text(errors="replace").strip() if sum_path.exists() else None
    except OSError as e:  # a folder of that name, no permission
        raise TableError(f"{e.filename}: cannot be read ({e.strerror or e})") from None
    if want is not None:
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
    if m.get("format") not in (FORMAT_VERSION, EARLIER_FORMAT):
        raise TableError(f"{manifest_path}: format = {m.get('format')!r}, this millfmu "
                         f"reads formats {FORMAT_VERSION} and {EARLIER_FORMAT}: stale")
    return m


def _current_names(m: dict, arrs: dict, spec: TableSpec) -> tuple[dict, dict]:
    """A table of the earlier format with its names in the current spelling
    (:mod:`millfmu.unit_names`): the manifest (its key and format now the current ones, its
    checksum of itself recomputed) and the arrays."""
    cur = modernize({k: v for k, v in m.items() if k != MANIFEST_SUM_KEY})
    cur.update(format=FORMAT_VERSION, key=spec.key())
    cur[MANIFEST_SUM_KEY] = manifest_digest(cur)
    return cur, {modern_name(k): v for k, v in arrs.items()}


def _manifest_spec(m: dict, manifest_path: Path, expect_key: str | None, expect_kernel: str | None) -> TableSpec:
    """The manifest's TableSpec, its key checked against its content (and ``expect_key``) and
    its kernel version against ``expect_kernel``."""
    try:
        spec = TableSpec.from_manifest(m)
    except KeyError as e:
        raise TableError(f"{manifest_path}: key {e} missing") from None
    except (TypeError, ValueError) as e:
        raise TableError(f"{manifest_path}: {e}") from None
    if not isinstance(m.get("zone_names"), list):
        raise TableError(f"{manifest_path}: zone_names missing")
    key = spec.key()
    own = spec.earlier_key() if m.get("format") == EARLIER_FORMAT else key
    if m.get("key") != own:
        raise TableError(f"{manifest_path}: key {m.get('key')!r} does not match its content "
                         f"({own}): corrupted or edited")
    if expect_key is not None and expect_key not in (key, own):
        raise TableError(f"{manifest_path}: key {key} is not the expected {expect_key}: stale")
    if expect_kernel is not None and m["kernel_version"] != expect_kernel:
        raise TableError(f"{manifest_path}: built with DEM kernel version "
                         f"{m['kernel_version']}, current is {expect_kernel}: stale")
    return spec


def _read_arrays(npz: Path, m: dict, manifest_path: Path) -> dict:
    """The table file's arrays, after its size and sha256 matched the manifest's."""
    info = (m.get("files") or {}).get(TABLE_FILE)
    if not isinstance(info, dict) or not {"bytes", "sha256"} <= set(info):
        raise TableError(f"{manifest_path}: no checksum for {TABLE_FILE}")
    if not npz.exists():
        raise TableError(f"{npz}: missing")
    if not npz.is_file():
        raise TableError(f"{npz}: not a file")
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
            return {k: f[k] for k in f.files}
    except Exception as e:  # a zip/npy error: the file is not a table
        raise TableError(f"{npz}: cannot be read as .npz ({type(e).__name__}: {e})") from None


def _table_from_arrays(arrs: dict, spec: TableSpec, m: dict, npz: Path) -> Table:
    """The Table of the arrays: axes as the manifest's grid, the one-at-a-time tables and the
    anchor as its scene says."""
    axes = {}
    for name in spec.grid:
        a = arrs.get(f"axis_{name}")
        if a is None or not np.array_equal(a, np.asarray(spec.grid[name])):
            raise TableError(f"{npz}: axis {name} missing or differs from the manifest grid")
        axes[name] = a
    t = _table_of(arrs, axes, tuple(m["zone_names"]))
    t.manifest = m
    for name in spec.one_at_a_time:
        pre = f"{ONE_AT_A_TIME_PREFIX}{name}__"
        sub = {k[len(pre):]: v for k, v in arrs.items() if k.startswith(pre)}
        side_axes = {}
        for ax, vals in spec.side_axes(name).items():
            a = sub.get(f"axis_{ax}")
            if a is None or not np.array_equal(a, np.asarray(vals)) or "reference" not in sub:
                raise TableError(f"{npz}: one-at-a-time axis {name} missing or differs from the "
                                 f"manifest" + (f" (its sub-grid axis {ax}, the manifest's across)"
                                                if ax != name else ""))
            side_axes[ax] = a
        t.one_at_a_time[name] = _table_of(sub, side_axes, t.zone_names)
        t.one_at_a_time_ref[name] = float(sub["reference"])
        if spec.partly_across(name):
            pre = f"{ONE_AT_A_TIME_ANCHOR_PREFIX}{name}__"
            sub = {k[len(pre):]: v for k, v in arrs.items() if k.startswith(pre)}
            vals = spec.anchor_side_axes(name)[name]
            a = sub.get(f"axis_{name}")
            if a is None or not np.array_equal(a, np.asarray(vals)):
                raise TableError(f"{npz}: one-at-a-time axis {name} at the anchor missing or differs from "
                                 f"the manifest (its values {list(vals)}, the manifest's one_at_a_time)")
            t.one_at_a_time_anchor[name] = _table_of(sub, {name: a}, t.zone_names)
    if spec.one_at_a_time:
        t.anchor = {k: float(arrs[f"anchor_{k}"]) for k in axes if f"anchor_{k}" in arrs}
        if t.anchor != spec.anchor():
            raise TableError(f"{npz}: anchor {t.anchor} differs from the manifest scene's "
                             f"{spec.anchor()}")
    return t


#: Largest value a normalized (dimensionless) field of a table may hold: the shipped tables'
#: largest is 30 (collision frequency over omega n_gb); 1e6 leaves room and keeps products
#: of them finite.
NORM_MAX = 1e6


def _check_field(where: str, name: str, v: np.ndarray, nan_ok=False, lo=0.0, hi=NORM_MAX, lo_tol=1e-12):
    v = np.asarray(v, float)
    bad = np.isinf(v) | (np.isnan(v) if not nan_ok else False)
    why = "a non-finite value (inf or nan)" if nan_ok is False else "an infinite value"
    if not bad.any():
        w = np.nan_to_num(v, nan=lo if lo is not None else 0.0)
        if lo is not None and (w < lo - lo_tol).any():
            bad, why = w < lo - lo_tol, f"a value below {lo:g}"
        elif hi is not None and (np.abs(w) > hi).any():
            bad, why = np.abs(w) > hi, f"a value beyond {hi:g}"
    if bad.any():
        i = tuple(int(k) for k in np.argwhere(bad)[0])
        raise TableError(f"{where}: field {name} holds {why} ({float(v[i])!r} at index {i}): not values a DEM "
                         f"run gives; the table's contents are refused (damaged or edited)")


def _check_values(t: Table, where: str):
    d = t.data
    for k in ZONE_FIELDS:
        hi = {"volume_fraction": 1.0 + 1e-9, "filling_local": 2.0, "collision_count": 1e15}.get(k, NORM_MAX)
        _check_field(where, k, d[k], hi=hi)
    _check_field(where, "se_density", d["se_density"])
    _check_field(where, "se_quantiles_norm", d["se_quantiles_norm"], nan_ok=True)  # nan: a zone without collisions
    if "recording_drift" in d:
        _check_field(where, "recording_drift", d["recording_drift"], nan_ok=True, lo=-NORM_MAX)
    for k, v in t.refs.items():
        _check_field(where, f"ref_{k}", v, lo=0.0, hi=1e30)
        if not (np.asarray(v) > 0).all():
            raise TableError(f"{where}: reference {k} must be positive; the table's contents are refused (damaged or "
                             "edited)")
    # Every point of a table is a run with the stirrer moving, and a moving bed collides: a
    # point without a collision in any zone is not a run's result, and a zone's frequency is
    # zero exactly where it counted no collision.
    f = np.asarray(d["collision_frequency_norm"], float)
    silent = ~(f > 0.0).any(axis=-1)
    if silent.any():
        i = tuple(int(k) for k in np.argwhere(silent)[0])
        raise TableError(f"{where}: field collision_frequency_norm is 0 in every zone at point index {i}: a DEM run "
                         "with the stirrer moving records collisions; the table's contents are refused (damaged or "
                         "edited)")
    mismatch = (f > 0.0) != (np.asarray(d["collision_count"], float) > 0.0)
    if mismatch.any():
        i = tuple(int(k) for k in np.argwhere(mismatch)[0])
        raise TableError(f"{where}: at index {i} field collision_frequency_norm is {float(f[i])!r} but collision_count "
                         f"is {float(np.asarray(d['collision_count'])[i])!r}: a zone has collisions in both or in "
                         "neither; the table's contents are refused (damaged or edited)")
    # Each density of SE over log10 bins integrates to 1 (0 in a zone without collisions).
    integral = (np.asarray(d["se_density"], float) * np.diff(norm_log10_edges())).sum(-1)
    off = ~(np.isclose(integral, 1.0, rtol=0, atol=1e-6) | np.isclose(integral, 0.0, rtol=0, atol=1e-12))
    if off.any():
        i = tuple(int(k) for k in np.argwhere(off)[0])
        raise TableError(f"{where}: field se_density at index {i} integrates to {integral[i]!r}, not 1: "
                         f"the table's contents are refused (damaged or edited)")


def _table_of(arrs: dict, axes: dict, zone_names: tuple) -> Table:
    return Table(axes=axes, zone_names=zone_names,
                 data={k: arrs[k] for k in FIELDS + OPTIONAL_FIELDS if k in arrs},
                 refs={k[4:]: v for k, v in arrs.items() if k.startswith("ref_")})


# ---- shipped tables -------------------------------------------------------------------------
#: The table of the embedded default scene: ``table = "default"`` names it too.
DEFAULT_TABLE = "coupled"
DEFAULT_TABLE_NPZ = f"{DEFAULT_TABLE}_table.npz"
DEFAULT_TABLE_MANIFEST = f"{DEFAULT_TABLE}_table.json"
#: The command that rebuilds the default scene's shipped table, the coupled one (from the
#: repository root); the table's manifest records it as ``rebuild_command``.
REBUILD_DEFAULT = (
    "millfmu tables build --scene disc_slice --tip-speed 6,8,10,12,14 --filling "
    "0.5,0.6,0.7,0.8,0.9 --bead-diameter 0.0005,0.0008,0.0012 --bead-density "
    "2510,6040 --one-at-a-time bead-diameter,bead-density --across "
    "bead-diameter:tip-speed=6,10,14:filling=0.5,0.6,0.8,0.9 --across "
    "bead-density:tip-speed=6,10,14:filling=0.5,0.6,0.8,0.9 --sector-deg 10 --spin-up "
    "1.5 --record 0.4 --sample-every 0.01 --initial-rotation 0.1 --no-gravity "
    "--fluid coupled --export millfmu/data/coupled_table")


def default_table_paths() -> tuple[Path, Path]:
    """Paths of the default scene's shipped table (millfmu/data/coupled_table.npz, .json)."""
    base = Path(importlib.util.find_spec("millfmu").origin).parent / "data"
    return base / DEFAULT_TABLE_NPZ, base / DEFAULT_TABLE_MANIFEST


#: Tables shipped with millfmu, by the name a scene gives (``table = NAME``):
#: millfmu/data/NAME_table.npz and .json. ``coupled``: the disc slice with the coupled
#: fluid (tip speed x filling, bead diameter and density one at a time), the default
#: scene's; ``prescribed``: the same slice with a prescribed swirl instead of the liquid
#: (bead speeds 2-3.5 times seed 001's; kept for comparison); ``accelerator``: the
#: accelerator slice (docs/tables.md).
SHIPPED_TABLES = ("accelerator", "coupled", "prescribed")


#: Tables read by read_table_ref, by their files' identity (path, size, mtime, inode): every
#: model (every FMU instance) of a process shares one read-only copy instead of reading,
#: verifying and allocating it again (which also fragmented the heap: RSS grew per instance).
_READ_CACHE: dict = {}


def _file_id(path: Path) -> tuple:
    st = Path(path).stat()
    return str(Path(path).resolve()), st.st_size, st.st_mtime_ns, st.st_ino


def _read_cached(npz: Path, man: Path) -> Table:
    try:
        key = (_file_id(npz), _file_id(man))
    except OSError:  # missing: read_table names the file
        return read_table(npz=npz, manifest_path=man)
    t = _READ_CACHE.get(key)
    if t is None:
        t = read_table(npz=npz, manifest_path=man)
        for tab in (t, *t.one_at_a_time.values()):
            for arr in (*tab.data.values(), *tab.refs.values(), *tab.axes.values()):
                arr.flags.writeable = False
        if len(_READ_CACHE) >= 8:
            _READ_CACHE.pop(next(iter(_READ_CACHE)))
        _READ_CACHE[key] = t
    return t


def read_table_ref(ref: str) -> Table:
    """The table a scene names: "default" (the default scene's, :data:`DEFAULT_TABLE`), a
    name in SHIPPED_TABLES (millfmu/data/NAME_table.*), or PREFIX of PREFIX.npz/PREFIX.json.
    Read once per process and files (shared, arrays read-only)."""
    if ref == "default":
        npz, man = default_table_paths()
        if not npz.exists():
            return read_default_table()  # names what is missing
        return _read_cached(npz, man)
    return _read_cached(*table_ref_files(ref))


def table_ref_prefix(ref: str) -> Path:
    """PREFIX of the files (PREFIX.npz, PREFIX.json) of the table a scene names (see
    :func:`read_table_ref`)."""
    if ref == "default":
        return default_table_paths()[0].with_suffix("")
    if ref in SHIPPED_TABLES:
        return default_table_paths()[0].parent / f"{ref}_table"
    return Path(ref)


def table_ref_files(ref: str) -> tuple[Path, Path]:
    """The files (PREFIX.npz, PREFIX.json) of the table ``ref`` names ("default", a shipped
    table's name or PREFIX, see :func:`read_table_ref`). Raises TableError where
    neither exists, naming the shipped tables: a misspelt name is no file to rebuild."""
    prefix = str(table_ref_prefix(ref))
    npz, man = Path(prefix + ".npz"), Path(prefix + ".json")
    if not (npz.exists() or man.exists()):
        raise TableError(f"no {npz} or {man}, and not a shipped table's name "
                         f"({', '.join(('default',) + SHIPPED_TABLES)})")
    return npz, man


def read_default_table() -> Table:
    """The default scene's shipped table, verified (checksums, key, shapes; its kernel version
    is recorded in its manifest and not required to match the installed DEM)."""
    npz, man = default_table_paths()
    if not npz.exists():
        raise TableError(f"default table {npz.name}: not shipped in this installation")
    return read_table(npz=npz, manifest_path=man)
