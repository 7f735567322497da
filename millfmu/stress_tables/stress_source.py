"""The kinetics' stress-energy source read from a table: :class:`TableStressSource` turns a
table lookup at an operating point into the zones (volume share, collision rate, stress
energy distribution) of :mod:`millfmu.kinetics.stress_distribution`.

The kinetics reads the normal component ``tn`` by default: SE_tn = 1/2 m* v_n^2 is the
impact energy that compresses a particle caught between two beads, the quantity of the
stress-energy concept (Kwade) and the distribution seed 001 reports; the shear and
rotational parts mostly rub rather than break. ``total`` can be chosen instead.

Part of what an FMU carries: the DEM builder loads only for ``on_outside='build'``, which an
FMU turns into ``'refuse'`` (it carries no DEM: ``build-fmu`` builds the table that covers
the scene's operating point, and the FMU carries that).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from collections.abc import Callable

import numpy as np

from ..kinetics.stress_distribution import Zone
from .spec import AXES, COMPONENTS, TableError, norm_log10_edges
from .table import EXTRAPOLABLE_AXES, FIXED_AXIS_RTOL, Lookup, OutsideGridError, Table

#: What an on-demand build does where the table's DEM kernel version is not the installed
#: DEM's (kinetics.stress_distribution.on_stale).
STALE_POLICIES = ("refuse", "rebuild", "accept")


#: Factor from the energy a table records for a bead-bead collision, 1/2 m* v_rel^2 with the
#: pair's reduced mass m* = m_i m_j / (m_i + m_j) (the DEM's zone statistics: the energy in
#: the pair's centre-of-mass frame; its shear and rotational parts with m* and I* alike), to
#: the energy counted as the collision's stress energy: ``bead_mass``, seed 001 eq. 1,
#: SE_tn = 1/2 m_GM v_rel,n^2 with the grinding bead's mass (m_GM / m* = 2, I / I* = 2 for
#: the equal beads of a table's DEM scene), or ``reduced_mass``, the recorded energy.
COLLISION_ENERGY = {"bead_mass": 2.0, "reduced_mass": 1.0}


@dataclass
class TableStressSource:
    """Stress-energy source of the detailed model read from a table
    (:class:`millfmu.kinetics.stress_distribution.StressEnergySource`).

    ``zones(op)`` interpolates the table at (tip speed, filling, and bead diameter, bead
    density, viscosity where the table has them as grid or one-at-a-time axes) and scales back with the operating
    point's own E_ref (= op.se_beads_J) and omega n_gb: energies [J] = table bins x E_ref,
    collision rate [1/(m3 s)] = collision_frequency_norm x omega n_gb. ``component``: 'tn'
    (default, see the module docstring) or 'total'.

    Axes the table does not vary (e.g. bead diameter, bead density, viscosity of the
    default table) must match the table's DEM scene (relative tolerance 1e-9), unless
    named in ``similar_axes``: then the dimensionless fields are used unchanged, i.e.
    similarity in that axis is assumed (recorded in ``last_notes``); millfmu's tests show
    the scaling only along the tip speed, so this is an explicit choice of the scene.
    ``tip_speed_m_per_s`` in ``similar_axes`` lets tip speeds outside the grid (a ramp from
    standstill, a controller's excursion) use the nearest edge's dimensionless fields.
    A point outside the grid raises :class:`OutsideGridError` unless
    ``on_outside='build'``: then ``rebuild(table, point)`` (default
    :func:`~millfmu.dem.tables.dem_builder.rebuild_including` with the DEM) builds and
    caches a table whose grid covers the point, progress shown. Such a point is checked up
    front (:meth:`check`, when the model is made): one the table's DEM scene cannot run
    (:mod:`millfmu.dem.limits`) is refused naming both ranges, and where the installed DEM's
    kernel version differs from the table's, ``on_stale`` decides: ``'refuse'`` (the
    point is refused, naming the cost of the full rebuild), ``'rebuild'`` (every point
    again with the installed DEM) or ``'accept'`` (the table's points as they are, only the
    new ones run; :mod:`millfmu.dem.tables.on_demand`). ``outside_note``: words added to
    every refusal of a point outside the grid (an FMU says that it carries no DEM).
    At tip speed 0 (stirrer at rest) there are no collisions: zones with zero rate.
    """

    table: Table
    component: str = "tn"
    similar_axes: tuple = ()
    on_outside: str = "refuse"
    rebuild: Callable | None = None  # (table, point) -> Table covering the point
    on_stale: str = "refuse"
    outside_note: str = ""
    #: Signed multiple m of the stated error the zones are put at (:meth:`relative_error`):
    #: every zone's collision rate and energies times (1 + |m| b)^sign(m), b its relative
    #: bound. 0: the table's values; +1 / -1: the upper / lower edge of the prediction band.
    error_multiple: float = 0.0
    #: How a collision's energy is counted (:data:`COLLISION_ENERGY`): the table records
    #: 1/2 m* v^2 with the pair's reduced mass; seed 001 eq. 1 counts 1/2 m_GM v^2.
    collision_energy: str = "bead_mass"
    last_lookup: Lookup | None = None
    last_notes: list = field(default_factory=list)
    #: axis -> (least, largest) value [axis unit] looked up with similarity assumed (an axis
    #: of ``similar_axes`` beyond the table's range): what :meth:`similarity_warnings` says.
    similarity_seen: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.component not in COMPONENTS:
            raise TableError(f"component = {self.component!r}: allowed {list(COMPONENTS)}")
        if self.on_outside not in ("refuse", "build"):
            raise TableError(f"on_outside = {self.on_outside!r}: allowed 'refuse', 'build'")
        if self.collision_energy not in COLLISION_ENERGY:
            raise TableError(f"collision_energy = {self.collision_energy!r}: allowed "
                             f"{', '.join(map(repr, COLLISION_ENERGY))}")
        if self.on_stale not in STALE_POLICIES:
            raise TableError(f"on_stale = {self.on_stale!r}: allowed {', '.join(map(repr, STALE_POLICIES))}")
        self.similar_axes = tuple(self.similar_axes)
        for ax in self.similar_axes:
            if ax not in EXTRAPOLABLE_AXES:
                raise TableError(f"similar_axes: {ax!r} not allowed; allowed: "
                                 f"{', '.join(EXTRAPOLABLE_AXES)}")

    def point_of(self, op) -> dict:
        """The lookup point of an operating point: the table's grid and one-at-a-time axes."""
        return {ax: float(getattr(op, AXES[ax][3]))
                for ax in (*self.table.axes, *self.table.one_at_a_time)}

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
        the same rules as the lookup (:meth:`Table.axis_value`), no interpolation. With
        ``on_outside='build'`` a point outside the grid is refused where the build could
        not run: outside what the table's DEM scene accepts (both ranges named), or, with
        ``on_stale='refuse'``, where the installed DEM kernel is not the table's (the cost
        of the full rebuild named). Neither check loads the DEM engine."""
        self._check_fixed_axes(op)
        for ax, x in self.point_of(op).items():
            if ax == "tip_speed_m_per_s" and not x > 0.0:
                continue  # the stirrer at rest: no collisions, nothing to look up
            t = self.table.side_of(ax, x) if ax in self.table.one_at_a_time else self.table
            try:
                t.axis_value(ax, x, self.similar_axes)
            except OutsideGridError as e:
                if self.on_outside != "build":
                    if self.outside_note:
                        raise OutsideGridError(e.axis, e.value, e.lo, e.hi, note=self.outside_note) from None
                    raise
                self._check_buildable(e)

    def _check_buildable(self, e: OutsideGridError):
        """For on_outside='build': refuse the point of ``e`` where no build can cover it."""
        # Here, not at the top: a step (and an FMU, which never builds) loads nothing of
        # millfmu.dem. limits holds numbers only: no DEM engine, no numba.
        from ..dem.limits import outside_dem

        why = outside_dem(self.table.manifest.get("scene") or {}, e.axis, e.value)
        if why is not None:
            raise OutsideGridError(e.axis, e.value, e.lo, e.hi,
                                   note=f"; {why}, so on_outside = 'build' cannot cover it") from None
        if self.on_stale == "refuse":
            line = self.stale_line({**self._any_point(), e.axis: e.value})
            if line is not None:
                raise OutsideGridError(e.axis, e.value, e.lo, e.hi, note=f"; on_outside = 'build': {line}") from None

    def _any_point(self) -> dict:
        """The table's anchor or first grid point (the axes a stale line's cost needs)."""
        p = {ax: float(v[0]) for ax, v in self.table.axes.items()}
        p.update({ax: float(v) for ax, v in self.table.one_at_a_time_ref.items()})
        return p

    def stale_line(self, point: dict) -> str | None:
        """One line where the installed DEM's kernel version is not the table's (what a build
        covering ``point`` would cost under each policy), else None; for DEM tables only."""
        # The builder's side (millfmu.dem.tables), here and not at the top: a step loads
        # nothing of millfmu.dem, and an FMU does not carry it.
        from ..dem.tables.on_demand import stale_line

        return stale_line(self.table, point, self.on_stale)

    def cover(self, op):
        """Make the table cover ``op`` (with ``on_outside='build'``: build it now, see
        :meth:`zones`; a no-op where the grid covers it). ``build-fmu`` calls it so that the
        FMU carries the table its scene needs."""
        if not op.tip_speed_m_per_s > 0.0:
            return
        point = self.point_of(op)
        try:
            self.table.lookup(point, self.similar_axes)
        except OutsideGridError:
            if self.on_outside != "build":
                raise
            self._extend(point)

    def _extend(self, point: dict):
        rebuild = self.rebuild
        if rebuild is None:
            # Imported here: the builder (cache, grid runs, DEM) stays out of FMUs.
            from functools import partial

            from ..dem.tables.dem_builder import rebuild_including
            rebuild = partial(rebuild_including, on_stale=self.on_stale)
        self.table = rebuild(self.table, point)

    def relative_error(self, lk: Lookup | None = None) -> dict:
        """The stated relative error per zone at a lookup (default: the last): for the
        collision frequency and the median stress energy of ``component``, the lookup's bound
        (interpolation error + 2 sigma of the DEM sampling, :meth:`Lookup.bound`) plus the
        table's work-precision expected error (recording, spin-up, sector, step, coupling;
        the manifest's ``work_precision.choice.expected_error``, SE_tn's median standing for
        the ``total`` component's), the spread between independent DEM realizations of one
        point (:meth:`Table.realization_error`) and, near a node the DEM ran again, that
        node's measured difference (:meth:`Table.node_check_error`), and off the anchor of the one-at-a-time axes
        their separability error measured by the table's checks
        (:meth:`Table.separability_error`), summed; NaN in a zone without collisions, and in every
        zone where no lookup was made (the stirrer at rest throughout: no collisions, so the
        table's error reaches no result). The local filling's error acts on the kinetics only
        through the collision frequency, which is bounded itself."""
        lk = lk if lk is not None else self.last_lookup
        names = self.table.zone_names
        if lk is None:
            nan = np.full(len(names), np.nan)
            return {"zones": list(names), "collision_frequency": nan, "se_median": nan.copy()}
        ci = COMPONENTS.index(self.component)

        def rel(v, b):
            v, b = np.abs(np.asarray(v, float)), np.asarray(b, float)
            return np.where(v > 0.0, b / np.where(v > 0.0, v, 1.0), np.nan)

        f = rel(lk.values["collision_frequency_norm"], lk.bound("collision_frequency_norm"))
        e = rel(lk.values["se_quantiles_norm"][ci, :, 1], lk.bound("se_quantiles_norm")[ci, :, 1])
        wp = ((self.table.manifest.get("work_precision") or {}).get("choice") or {}).get("expected_error") or {}
        f_wp = np.array([float((wp.get("collision_frequency") or {}).get(n, 0.0)) for n in names])
        e_wp = np.array([float((wp.get("se_tn_q50") or {}).get(n, 0.0)) for n in names])
        sep = self.table.separability_error(lk.point)
        real = self.table.realization_error()
        node = self.table.node_check_error(lk)
        return {"zones": list(names),
                "collision_frequency": f + f_wp + sep["collision_frequency"] + real["collision_frequency"]
                + node["collision_frequency"],
                "se_median": e + e_wp + sep["se_median"] + real["se_median"] + node["se_median"]}

    def unstated_zones(self, lk: Lookup | None = None, err: dict | None = None) -> list:
        """Zones of a lookup (default: the last) that have collisions but no stated error
        (:meth:`relative_error` NaN, or ``err`` where the caller has it: no check of the
        table measured them there); a band would leave them unmoved."""
        lk = lk if lk is not None else self.last_lookup
        if lk is None:
            return []
        err = err if err is not None else self.relative_error(lk)
        f = np.asarray(lk.values["collision_frequency_norm"], float)
        bad = (f > 0.0) & ~(np.isfinite(err["collision_frequency"]) & np.isfinite(err["se_median"]))
        return [z for z, b in zip(err["zones"], bad) if b]

    def zones(self, op):
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
        except OutsideGridError as e:
            if self.on_outside != "build":
                if self.outside_note:
                    raise OutsideGridError(e.axis, e.value, e.lo, e.hi, note=self.outside_note) from None
                raise
            self._extend(point)
            lk = self.table.lookup(point, self.similar_axes)
        self.last_lookup = lk
        self.last_notes = notes + lk.notes
        # the axes where similarity was assumed: the scene's values of axes the table fixes
        # (each note names its axis first: "AXIS = VALUE...") and the lookup's own; not the
        # one-at-a-time axes' scaling inside their range
        for ax in {n.split(" = ", 1)[0] for n in notes} | lk.similar:
            if ax in AXES:
                x = float(getattr(op, AXES[ax][3]))
                lo, hi = self.similarity_seen.get(ax, (x, x))
                self.similarity_seen[ax] = (min(lo, x), max(hi, x))
        eref = float(op.se_beads_J) * COLLISION_ENERGY[self.collision_energy]
        scale = float(op.omega_rad_per_s * op.n_gb_per_m3)
        edges = eref * 10.0 ** U
        ci = COMPONENTS.index(self.component)
        vf = lk.values["volume_fraction"]
        vf = vf / vf.sum()
        m = float(self.error_multiple)
        if m:
            err = self.relative_error(lk)
            # A zone without collisions has no rate to move.
            f_fac = (1.0 + abs(m) * np.nan_to_num(err["collision_frequency"])) ** np.sign(m)
            e_fac = (1.0 + abs(m) * np.nan_to_num(err["se_median"])) ** np.sign(m)
        else:
            f_fac = e_fac = np.ones(len(names))
        out = []
        for k, n in enumerate(names):
            w = np.clip(lk.values["se_density"][ci, k], 0.0, None) * np.diff(U)
            rate = max(float(lk.values["collision_frequency_norm"][k]), 0.0) * scale * float(f_fac[k])
            if w.sum() <= 0.0:
                # No recorded collisions here: no rate, and a placeholder bin at the bottom.
                w = np.zeros_like(w)
                w[0] = 1.0
                rate = 0.0
            out.append(Zone(n, float(vf[k]), rate, edges * float(e_fac[k]), w / w.sum()))
        return out

    def similarity_warnings(self) -> dict:
        """{axis: warning} for every axis whose lookups so far went beyond the table's range
        with similarity assumed (the values reached, the table's range, what it means)."""
        out = {}
        fixed = self.table.fixed_axis_values()
        for ax, (lo, hi) in self.similarity_seen.items():
            if ax in fixed:
                held = f"the table's single value {fixed[ax]:g}"
            else:
                a = self.table.one_at_a_time_values(ax) if ax in self.table.one_at_a_time else self.table.axes[ax]
                held = f"the table's range {float(a[0]):g} to {float(a[-1]):g}"
            reached = f"{lo:g}" if lo == hi else f"{lo:g} to {hi:g}"
            out[ax] = (f"{ax} = {reached} lies outside {held}: the dimensionless fields of the nearest node were used "
                       f"(similarity assumed, named in similar_axes: collision rates scaled with omega n_gb, stress "
                       f"energies with the reference energy of each operating point); the table's stated error and "
                       f"the prediction band do not cover this")
        return out

    def _volume_fractions(self):
        # The geometry fixes the zone volumes; take them at the first grid point.
        vf = self.table.data["volume_fraction"].reshape(-1, len(self.table.zone_names))[0]
        return vf / vf.sum()
