"""MillModel: the one mill model. State + step(dt, inputs) -> outputs, SI units.

The CLI, the FMU and the flowsheets adapt this class; the physics lives in
:mod:`millfmu.kinetics`.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass, replace

import numpy as np

from .kinetics import grid as kgrid
from .kinetics import materials, pbm, rates, stress
from .kinetics.stress_distribution import LogNormalStressSource, chamber_collision_rate_per_m3_s
from .scene import PSD, Scene, SceneError
from .stress_tables.rules import (NO_DEM_NOTE, TABLE_INPUTS, TABLE_INPUTS_CHECKED, TABLE_SCENE_KEYS, rebuild_hint,
                                  recording_warnings)

#: Tolerance on the sum of an input size distribution's mass fractions [-].
PSD_SUM_TOL = kgrid.PSD_SUM_TOL


class InputError(ValueError):
    """Bad input to a step: names the variable, the value and what is allowed. The state is unchanged."""

    def __init__(self, name: str, value, allowed: str):
        self.name, self.value, self.allowed = name, value, allowed
        super().__init__(f"input {name} = {value!r}: {allowed}")


class StepError(RuntimeError):
    """A step would give non-finite or negative masses. The state is unchanged."""


#: Longest step [s] (about 30,000 years): longer ones only overflow the exponentials.
MAX_STEP_S = 1e12


#: Largest mass fraction of a scene's feed or initial distribution that may lie outside the
#: size grid [-], and the below-grid fraction of the product above which a run warns.
OUTSIDE_GRID_MAX = 0.01
#: The scene key that sets a size distribution's position, per kind.
PSD_SIZE_KEY = {"lognormal": "x50_m", "rrsb": "x63_m", "monodisperse": "x_m", "table": "sizes_m"}


def psd_q3(grid: kgrid.SizeGrid, p: PSD) -> np.ndarray:
    """Q3 [-] of a scene size distribution at the grid's edges."""
    e = grid.edges_m
    if p.kind == "lognormal":
        q = kgrid.q3_lognormal(e, p.x50_m, p.sigma_ln)
    elif p.kind == "rrsb":
        q = kgrid.q3_rrsb(e, p.x63_m, p.n)
    elif p.kind == "monodisperse":
        q = (e >= p.x_m).astype(float)
    elif p.kind == "table":
        q = kgrid.q3_table(e, np.asarray(p.sizes_m, float), np.asarray(p.Q3, float))
    else:  # pragma: no cover - the scene validates kinds
        raise ValueError(p.kind)
    return q


def psd_fractions(grid: kgrid.SizeGrid, p: PSD) -> np.ndarray:
    """Class mass fractions [-] on ``grid`` for a scene size distribution (the finest class
    holds what lies below the grid, the coarsest what lies above)."""
    return kgrid.fractions_from_q3(grid, psd_q3(grid, p))


def check_psd_on_grid(grid: kgrid.SizeGrid, p: PSD, key: str, source: str) -> float:
    """SceneError if more than OUTSIDE_GRID_MAX of the distribution's mass lies outside the
    grid; returns the fraction below the lowest edge [-]."""
    below, above = kgrid.outside_fractions(psd_q3(grid, p))
    if below > OUTSIDE_GRID_MAX or above > OUTSIDE_GRID_MAX:
        sk = PSD_SIZE_KEY[p.kind]
        e = grid.edges_m
        raise SceneError(f"{key}.{sk}", getattr(p, sk),
                         f"puts {above:.1%} of the mass above the size grid's top edge {e[-1]:.4g} m and {below:.1%} "
                         f"below its lowest edge {e[0]:.4g} m; at most {OUTSIDE_GRID_MAX:.0%} may lie outside: widen "
                         "[grid] (x_min_m, x_max_m) or move the distribution", source)
    return below


def q3_at_edges(out: dict) -> np.ndarray:
    """Q3 [-] at every class edge from a step's outputs, the lowest edge's being the mass
    below the grid (the psd's finest class already holds that mass)."""
    return np.concatenate(([out["below_grid_fraction"]], np.cumsum(out["psd"])))


def build_material(s: Scene):
    m = s.material
    brk = materials.AustinBreakage(m.breakage.phi, m.breakage.gamma, m.breakage.beta)
    if m.model == "mineral":
        return materials.Mineral(m.density_kg_per_m3, m.youngs_modulus_Pa, m.f_mat_kg_per_J_m, m.x_w_min_J_m_per_kg,
                                 brk)
    if m.model == "yeast":
        return materials.Yeast(m.density_kg_per_m3, m.youngs_modulus_Pa, m.burst_energy_median_J,
                               m.burst_energy_sigma_ln, brk)
    sel = m.selection
    return materials.Austin(m.density_kg_per_m3, m.youngs_modulus_Pa, sel.a_per_s, sel.x0_m, sel.alpha, sel.mu_m,
                            sel.Lambda, brk)


_accumulate = np.add.accumulate

#: Q3 levels of the outputs x10, x50, x90
_QUANTILES = np.array([0.1, 0.5, 0.9])

def _interp(x: float, xp: list, fp: list) -> float:
    """np.interp(x, xp, fp) for one x over Python lists (xp increasing): fp's end values
    outside xp, linear in between. A step needs one such value; numpy's call costs more
    than the bisection."""
    if x <= xp[0]:
        return fp[0]
    if x >= xp[-1]:
        return fp[-1]
    j = bisect_right(xp, x) - 1
    return fp[j] + (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j]) * (x - xp[j])


@dataclass(frozen=True)
class _Frozen:
    """What an exact step needs for one set of frozen inputs and step size."""

    op: rates.OperatingPoint
    propagator: pbm.SeriesPropagator
    numbers: dict  # the operating point's scalars (MillModel._op_numbers), looked up once


class MillModel:
    """Wet stirred media mill: population balance of particle sizes over time.

    Batch: one perfectly mixed chamber, no flow. Continuous: N equal tanks in series
    (residence time distribution of the mill), suspension volume flow Q = feed solids mass
    flow / feed solids concentration; the suspension volume in the chamber is
    V (1 - phi (1 - eps)).

    ``step(dt_s, **inputs)`` advances by dt_s seconds with inputs held over the step:
    tip_speed_m_per_s [m/s], solids_mass_fraction [-], bead_filling [-],
    feed_mass_flow_kg_per_s [kg/s] and psd_in (feed class mass fractions [-], summing to 1).
    Inputs not given keep their last values (initially the scene's). With
    ``inputs_end`` (values at the end of the step, linear in between) or with
    capture = 'psd' (rates depend on the state), the adaptive integrator is used.
    """

    def __init__(self, scene: Scene, grid: kgrid.SizeGrid | None = None, table_error_multiple: float = 0.0,
                 no_dem: bool = False):
        """``table_error_multiple``: for a detailed model on a stress-energy table, put every
        zone's collision frequency and energies at this signed multiple of the table's stated
        error (+1: the upper edge of the prediction band, more breakage; -1: the lower; the
        table source's ``relative_error`` says what the error holds). ``no_dem``: the model
        runs where no DEM can run (an FMU): a table scene's on_outside = 'build' acts as
        'refuse', and its refusals say so."""
        self.scene = scene
        self.no_dem = bool(no_dem)
        self.table_error_multiple = float(table_error_multiple)
        g = scene.grid
        self.grid = grid or kgrid.SizeGrid.geometric(g.x_min_m, g.x_max_m, g.classes_per_octave)
        self.material = build_material(scene)
        self.operator = pbm.BreakageOperator(self.grid, self.material.breakage.cdf,
                                             inert_fragments=self.material.inert_fragments)
        self.continuous = scene.operation.mode == "continuous"
        self.n_tanks = scene.operation.n_tanks if self.continuous else 1
        self.kinetics_model = scene.kinetics.model
        self.capture_from_psd = scene.kinetics.capture == "psd"
        sd = scene.kinetics.stress_distribution
        #: Warnings about the scene's data (e.g. a table from a short DEM recording), for the
        #: CLI, the FMU's log and a run's result.
        self.warnings: list[str] = []
        self.source = self._stress_source(sd)
        self._check_source_scene()
        regime = self.regime_warning()
        if regime:
            self.warnings.append(regime)
        self._m = self.operator.state_size
        self._n = self.grid.n  # classes, read at every step
        src = scene.scene.name
        self.feed_below_grid = check_psd_on_grid(self.grid, scene.feed, "feed", src)
        if scene.initial is not None:
            check_psd_on_grid(self.grid, scene.initial, "initial", src)
        self._cache = pbm.LRUCache(32)  # exact propagators by (inputs, h)
        self._rate_cache = pbm.LRUCache(64)  # breakage operators by operating point
        self._num_cache = pbm.LRUCache(256)  # scalars by operating point
        self._log_nodes = np.log(self.operator.nodes_m.ravel()).tolist()  # a list: see _interp
        self._q3_sizes = kgrid.Q3Sizes(np.log(self.grid.edges_m), _QUANTILES)  # x10, x50, x90 step after step
        self._psd_in_checked = (None, None)  # (raw bytes, checked fractions) of the last psd_in checked
        self._fed_step = (None, None, None)  # (frozen step, psd_in, the step's feed part [kg]); see _advance
        self._last_frozen = (None, None)  # (key, frozen step) of the last exact step
        self._adaptive = self.capture_from_psd or self.scene.run.integrator == "adaptive"  # rates change within a step
        self.reset()

    def _stress_source(self, sd):
        """The detailed model's stress-energy source (None for the other models)."""
        if self.kinetics_model != "detailed":
            return None
        if sd.source == "table":
            # Imported only here: scenes without a table never load the table code (and the
            # modules that read a table are all an FMU carries of it).
            from .stress_tables.spec import TableError
            from .stress_tables.stress_source import TableStressSource
            from .stress_tables.table import read_table_ref

            try:
                table = read_table_ref(sd.table)
            except TableError as e:
                raise SceneError("kinetics.stress_distribution.table", sd.table,
                                 f"cannot be used: {e}; {rebuild_hint(sd.table)}",
                                 self.scene.scene.name) from None
            self.warnings.extend(recording_warnings(table.manifest))
            on_outside, note = sd.on_outside, ""
            if self.no_dem and on_outside == "build":
                on_outside, note = "refuse", NO_DEM_NOTE
            return TableStressSource(table, component=sd.component, similar_axes=tuple(sd.similar_axes),
                                     on_outside=on_outside,
                                     on_stale=sd.on_stale, outside_note=note, error_multiple=self.table_error_multiple,
                                     collision_energy=sd.collision_energy)
        return LogNormalStressSource(sd.median_fraction, sd.sigma_ln, sd.collision_factor)

    def _check_source_scene(self):
        """A table source refuses the scene's own operating point: a SceneError naming the
        scene key, before anything runs."""
        if not hasattr(self.source, "check"):
            return
        s = self.scene
        try:
            self.source.check(self.operating_point({
                "tip_speed_m_per_s": s.mill.tip_speed_m_per_s, "bead_filling": s.mill.bead_filling,
                "solids_mass_fraction": s.suspension.solids_mass_fraction}))
        except ValueError as e:
            if getattr(e, "axis", None) not in TABLE_SCENE_KEYS:
                raise
            allowed = e.allowed
            if getattr(self.source, "on_outside", None) == "refuse" and not self.no_dem:
                similar = "" if e.axis not in _similar_axis_choices() else (
                    f", or take the nearest edge's fields (kinetics.stress_distribution.similar_axes = "
                    f"['{e.axis}'])")
                allowed += (f"; or let the DEM extend the table (kinetics.stress_distribution.on_outside = 'build'; "
                            f"the cost is said first){similar}, or run the simple model (kinetics.model = 'simple')")
            raise SceneError(TABLE_SCENE_KEYS[e.axis], e.value, allowed, s.scene.name) from None
        if getattr(self.source, "on_outside", None) == "build":
            # Said before anything runs: an on-demand build would not reuse the table's points.
            op = self.operating_point(self.inputs_of_scene())
            line = self.source.stale_line(self.source.point_of(op))
            if line is not None:
                self.warnings.append(f"on-demand builds: {line}")

    def p_break_per_stress_of_feed(self) -> float:
        """The detailed model's breakage probability per stress [-] at the scene's operating
        point, over the feed: sum_i w_i S_i / sum_i w_i SF_i (w the feed's class mass
        fractions, S the class rates, SF the stress frequencies). NaN for other models, for
        materials without a stress model, with the stirrer at rest and at a point a table
        builds on demand that it does not yet hold."""
        if self.kinetics_model != "detailed" or not getattr(self.material, "has_stress_model", False):
            return math.nan
        op = self.operating_point(self.inputs_of_scene())
        if not op.tip_speed_m_per_s > 0.0:
            return math.nan
        src = self.source
        if getattr(src, "on_outside", None) == "build":
            # not yet on the table: built when the run starts, not to state a warning
            try:
                src.table.lookup(src.point_of(op), src.similar_axes)
            except ValueError:
                return math.nan
        nodes = self.operator.nodes_m
        w = psd_fractions(self.grid, self.scene.feed)
        coll = chamber_collision_rate_per_m3_s(self.source, op)
        s = self.operator.class_rates(rates.selection_per_s("detailed", self.material, op, nodes, None, self.source))
        sf = self.operator.class_rates(op.stress_frequency_per_s(nodes, None, coll))
        den = float(w @ sf)
        return float(w @ s) / den if den > 0.0 else math.nan

    def regime_warning(self) -> str | None:
        """The warning for a detailed model whose breakage probability per stress over the
        feed lies below :data:`~millfmu.kinetics.rates.ENERGY_LIMITED_P` (its rate then follows the collision power,
        and its trends off the calibration point leave the simple model's, which seed 000's
        measurements follow); None otherwise."""
        p = self.p_break_per_stress_of_feed()
        if not p < rates.ENERGY_LIMITED_P:
            return None
        return (f"detailed model energy-limited: breakage probability per stress over the feed {p:.2g} at the scene's "
                f"operating point (below {rates.ENERGY_LIMITED_P:g}); its rate follows the collision power, so its "
                "trends along bead diameter and density off this point leave the simple model's, which seed 000's "
                "measurements follow (docs/rates-and-calibration.md, 'Which model to trust where')")

    def cover_scene_point(self):
        """With ``on_outside = 'build'``: build the table for the scene's own operating point
        now (before a run) instead of inside its first step, so that a point the DEM cannot
        build (beads that do not fit the cell, a run that fails) is a SceneError naming the
        reason. A no-op for other sources and where the table covers the point."""
        if getattr(self.source, "on_outside", None) != "build":
            return
        try:
            self.source.cover(self.operating_point(self.inputs_of_scene()))
        except ValueError as e:  # TableError, DemSceneError: the build's reasons
            if getattr(e, "axis", None) in TABLE_SCENE_KEYS:  # a value of the point the DEM cannot run
                raise SceneError(TABLE_SCENE_KEYS[e.axis], e.value, f"{e.allowed} (on_outside = 'build')",
                                 self.scene.scene.name) from None
            raise SceneError("kinetics.stress_distribution.on_outside", "build",
                             f"the table could not be extended to the scene's operating point: {e}",
                             self.scene.scene.name) from None

    def inputs_of_scene(self) -> dict:
        """The scene's own operating inputs (tip speed, filling, solids)."""
        s = self.scene
        return {"tip_speed_m_per_s": s.mill.tip_speed_m_per_s, "bead_filling": s.mill.bead_filling,
                "solids_mass_fraction": s.suspension.solids_mass_fraction}

    def _check_source_inputs(self, inputs: dict):
        """InputError for inputs the stress-energy table refuses (see :meth:`check_inputs`)."""
        try:
            self.source.check(self.operating_point(inputs))
        except ValueError as e:
            name = TABLE_INPUTS.get(getattr(e, "axis", None))
            if name is None:
                raise
            raise InputError(name, inputs[name], e.allowed) from None

    # ---- state ---------------------------------------------------------------------------
    def reset(self):
        """Back to the scene's initial state and inputs."""
        s = self.scene
        self.inputs = {
            "tip_speed_m_per_s": s.mill.tip_speed_m_per_s,
            "solids_mass_fraction": s.suspension.solids_mass_fraction,
            "bead_filling": s.mill.bead_filling,
            "feed_mass_flow_kg_per_s": s.operation.feed_mass_flow_kg_per_s if self.continuous else 0.0,
            "psd_in": psd_fractions(self.grid, s.feed),
        }
        init = s.initial if s.initial is not None else s.feed
        q0 = psd_q3(self.grid, init)
        w0 = kgrid.fractions_from_q3(self.grid, q0)
        # The initial content's mass below the grid starts in the below-grid state (the feed
        # flow's enters the finest class, as psd_in describes it).
        below0 = min(kgrid.outside_fractions(q0)[0], w0[0])
        w0[0] -= below0
        op = self.operating_point(self.inputs)
        mass_per_tank = op.solids_concentration_kg_per_m3 * self.suspension_volume_m3(op) / self.n_tanks
        y = np.zeros(self.n_tanks * self._m + 1)
        for k in range(self.n_tanks):
            tank = y[pbm.tank_slice(k, self._m, self.n_tanks)]
            tank[: self.grid.n] = mass_per_tank * w0
            tank[-1] = mass_per_tank * below0
        self.t_s = 0.0
        self.y = y
        self.energy_J = 0.0
        self.stress_number = 0.0
        self.fed_kg = 0.0
        self.m0_kg = float(y.sum())
        self._last = self._outputs(self.y, op, self.inputs, dt_s=0.0, out_kg=0.0)

    def get_state(self) -> dict:
        """A plain copy of the whole state (numbers and arrays); see :meth:`set_state`."""
        return {
            "t_s": self.t_s,
            "y": self.y.copy(),
            "energy_J": self.energy_J,
            "stress_number": self.stress_number,
            "fed_kg": self.fed_kg,
            "m0_kg": self.m0_kg,
            "inputs": {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in self.inputs.items()},
            "last": {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in self._last.items()},
        }

    def set_state(self, state: dict):
        """Restore a state from :meth:`get_state`; the model continues bit-identically."""
        y = np.array(state["y"], dtype=float)
        if y.shape != self.y.shape:
            raise ValueError(f"state vector has {y.shape[0]} entries; this model needs {self.y.shape[0]}")
        if not (y.min() >= 0.0 and np.isfinite(y).all()):
            raise ValueError("state vector: masses must be finite and >= 0 kg")
        self.t_s = float(state["t_s"])
        self.y = y
        self.energy_J = float(state["energy_J"])
        self.stress_number = float(state["stress_number"])
        self.fed_kg = float(state["fed_kg"])
        self.m0_kg = float(state["m0_kg"])
        self.inputs = {k: (np.array(v, dtype=float) if k == "psd_in" else float(v)) for k, v in state["inputs"].items()}
        self._last = {k: (np.array(v) if isinstance(v, (list, np.ndarray)) else v) for k, v in state["last"].items()}

    # ---- operating point -----------------------------------------------------------------
    def operating_point(self, inputs) -> rates.OperatingPoint:
        s = self.scene
        return rates.OperatingPoint(
            tip_speed_m_per_s=float(inputs["tip_speed_m_per_s"]),
            filling=float(inputs["bead_filling"]),
            porosity=s.mill.bead_porosity,
            r_stirrer_m=s.mill.stirrer_radius_m,
            d_gb_m=s.beads.diameter_m,
            rho_gb_kg_per_m3=s.beads.density_kg_per_m3,
            y_gb_Pa=s.beads.youngs_modulus_Pa,
            y_p_Pa=s.material.youngs_modulus_Pa,
            rho_p_kg_per_m3=s.material.density_kg_per_m3,
            rho_l_kg_per_m3=s.suspension.liquid_density_kg_per_m3,
            eta_susp_Pa_s=s.suspension.viscosity_Pa_s,
            solids_mass_fraction=float(inputs["solids_mass_fraction"]),
            k_c=s.mill.stress_frequency_factor,
            energy_transfer=s.kinetics.energy_transfer,
        )

    def suspension_volume_m3(self, op: rates.OperatingPoint) -> float:
        """Suspension volume in the chamber, V (1 - phi (1 - eps)) [m3]."""
        return self.scene.mill.chamber_volume_m3 * (1.0 - op.bead_volume_fraction)

    def power_W(self, op: rates.OperatingPoint) -> float:
        m = self.scene.mill
        return stress.stirrer_power_W(op.rho_eff_kg_per_m3, op.eta_eff_Pa_s, op.tip_speed_m_per_s, m.stirrer_radius_m,
                                      m.n_discs, m.power_number_laminar, m.power_number_turbulent)

    def _number_concentration(self, y, op) -> float:
        """Product particles per suspension volume from the current PSD [1/m3] (intact cells for yeast)."""
        n = self.grid.n
        m = y[1:].reshape(self.n_tanks, self._m)[:, :n].sum(axis=0)
        v_p = math.pi / 6.0 * self.grid.x_m**3
        return float(np.sum(m / (op.rho_p_kg_per_m3 * v_p))) / self.suspension_volume_m3(op)

    def selection_nodes(self, op, n_p=None) -> np.ndarray:
        """Selection rates at the operator's quadrature nodes [1/s]."""
        return rates.selection_per_s(self.kinetics_model, self.material, op, self.operator.nodes_m, n_p, self.source)

    def _breakage_matrix(self, op, n_p=None):
        if n_p is not None:
            return self.operator.matrix(self.selection_nodes(op, n_p))
        return self._rate_cache.get(op, lambda: self.operator.matrix(self.selection_nodes(op)))

    def _system(self, inputs, y=None):
        """(tanks in series, feed u [kg/s per class] or None, op) for frozen inputs (and,
        capture = 'psd', the state y)."""
        op = self.operating_point(inputs)
        n_p = self._number_concentration(y, op) if (self.capture_from_psd and y is not None) else None
        a = self._breakage_matrix(op, n_p)
        if not self.continuous:
            return pbm.TanksInSeries(a, 1, 0.0, order=self.operator.upper_order), None, op
        mdot = float(inputs["feed_mass_flow_kg_per_s"])
        q = mdot / op.solids_concentration_kg_per_m3 if mdot > 0.0 else 0.0
        d = q / (self.suspension_volume_m3(op) / self.n_tanks)
        u = mdot * np.asarray(inputs["psd_in"], dtype=float)
        return pbm.TanksInSeries(a, self.n_tanks, d, n_in=self.grid.n, order=self.operator.upper_order), u, op

    def _frozen_step(self, inputs, h):
        with np.errstate(all="ignore"):  # extreme rates: a non-finite step is refused by name
            series, _, op = self._system(inputs)
            return _Frozen(op, series.propagator(h), self._op_numbers(op))

    # ---- inputs ---------------------------------------------------------------------------
    def check_inputs(self, given: dict) -> dict:
        """Merge given inputs with the current ones, validating each; raises InputError."""
        new = dict(self.inputs)
        for k, v in given.items():
            if k not in new:
                raise InputError(k, v, "unknown input; allowed: " + ", ".join(sorted(new)))
            cur = new[k]
            # A value equal to the current one passed this check when it was set (a host
            # passes every input at every step): nothing to check again.
            if k == "psd_in":
                # A host passes the same feed distribution at every step: the result of its
                # check (the normalised fractions) is remembered by content.
                raw = v.tobytes() if isinstance(v,
                                                np.ndarray) and v.dtype == np.float64 and v.shape == cur.shape else None
                if raw is not None and raw == self._psd_in_checked[0]:
                    new[k] = self._psd_in_checked[1]
                    continue
                new[k] = kgrid.checked_fractions(k, v, self.grid.n, InputError, PSD_SUM_TOL)
                if raw is not None:
                    self._psd_in_checked = (raw, new[k])
                continue
            if type(v) is float and v == cur:
                continue
            try:
                x = float(v)
            except (TypeError, ValueError):
                raise InputError(k, v, "must be a number") from None
            if not math.isfinite(x):
                raise InputError(k, x, "must be finite")
            if k == "tip_speed_m_per_s" and not 0.0 <= x <= 40.0:
                raise InputError(k, x, "must lie in [0, 40] m/s")
            if k == "bead_filling":
                c_v = x * (1.0 - self.scene.mill.bead_porosity)
                if not (0.0 < x < 1.0) or c_v >= stress.PHI_MAX_RCP:
                    raise InputError(k, x, f"must lie in (0, 1) with bead volume fraction below {stress.PHI_MAX_RCP}")
            if k == "solids_mass_fraction" and not 0.0 < x < 0.8:
                raise InputError(k, x, "must lie in (0, 0.8)")
            if k == "feed_mass_flow_kg_per_s" and not 0.0 <= x <= 1e3:
                raise InputError(k, x, "must lie in [0, 1000] kg/s")
            if k == "feed_mass_flow_kg_per_s" and x != 0.0 and not self.continuous:
                raise InputError(k, x, "must be 0 for a batch mill (operation.mode = 'batch' has no feed)")
            new[k] = x
        # The current inputs passed this check when they were set (or the scene's at
        # construction): check again only when a table input changes, not every step.
        if hasattr(self.source, "check") and any(new[k] != self.inputs[k] for k in TABLE_INPUTS_CHECKED):
            self._check_source_inputs(new)
        return new

    def set_inputs(self, **inputs):
        """Set inputs without stepping (validated as in :meth:`step`); refreshes the outputs."""
        new = self.check_inputs(inputs)
        self.inputs = new
        op = self.operating_point(new)
        keep = {k: self._last[k] for k in ("t_s", "product_mass_flow_kg_per_s", "stress_number",
                                           "specific_energy_J_per_kg") if k in self._last}
        self._last = {**self._outputs(self.y, op, new, dt_s=0.0, out_kg=0.0), **keep}
        return self._last

    # ---- stepping -------------------------------------------------------------------------
    def step(self, dt_s: float, inputs_end: dict | None = None, **inputs) -> dict:
        """Advance by dt_s [s]; returns the outputs at the end of the step (see :meth:`outputs`).

        Raises InputError for bad input and StepError for a non-finite result; either way
        the state is as it was before the call.
        """
        try:
            h = float(dt_s)
        except (TypeError, ValueError):
            raise InputError("dt_s", dt_s, "must be a number > 0 s") from None
        if not (math.isfinite(h) and 0.0 < h <= MAX_STEP_S):
            raise InputError("dt_s", dt_s, f"must be finite, > 0 s and <= {MAX_STEP_S:g} s")
        # no inputs given: the current ones, checked when they were set (never changed in place)
        new_inputs = self.check_inputs(inputs) if inputs else self.inputs
        end_inputs = self.check_inputs({**inputs, **(inputs_end or {})}) if inputs_end else None
        adaptive = self._adaptive or end_inputs is not None
        try:
            if adaptive:
                with np.errstate(all="ignore"):  # a non-finite result is refused below, by name
                    y_new, op, op_end, num, num_end = self._advance(h, new_inputs, end_inputs, adaptive)
            else:  # the propagator's build silences its own warnings; applying it is one product
                y_new, op, op_end, num, num_end = self._advance(h, new_inputs, end_inputs, adaptive)
        except (ValueError, ArithmeticError, RuntimeError, np.linalg.LinAlgError) as e:
            raise StepError(f"step of {h} s at t = {self.t_s} s failed ({type(e).__name__}: {e})") from None
        # min is NaN where an entry is; the sum is not finite where one is infinite. The
        # frozen path needs neither: its propagator is checked finite and non-negative when
        # built, the state (checked here and in set_state) and the feed are, and products
        # and sums of finite non-negative numbers are finite and non-negative in floating
        # point too.
        if adaptive and not (y_new.min() >= 0.0 and math.isfinite(y_new.sum())):
            raise StepError(f"step of {h} s at t = {self.t_s} s gave non-finite or negative masses")
        out_kg = y_new.item(0) - self.y.item(0)
        # Fed mass: the feed rate is linear over the step when ramped (as integrated above).
        mdot_end = (end_inputs or new_inputs)["feed_mass_flow_kg_per_s"]
        fed = 0.5 * (float(new_inputs["feed_mass_flow_kg_per_s"]) + float(mdot_end)) * h
        # Power and stress number with the operating point held over the step (trapezoid
        # between start and end for ramps).
        p_mean = 0.5 * (num["power_W"] + num_end["power_W"])
        outs = self._outputs(y_new, op_end, end_inputs or new_inputs, dt_s=h, out_kg=out_kg, num=num_end)
        sf_mean = 0.5 * (self._last["sf_per_s"] + outs["sf_per_s"]) if adaptive else outs["sf_per_s"]
        # Commit.
        self.y = y_new
        self.t_s += h
        self.inputs = end_inputs or new_inputs
        self.energy_J += p_mean * h
        self.fed_kg += fed
        self.stress_number += sf_mean * h
        outs["t_s"] = self.t_s
        outs["stress_number"] = self.stress_number
        outs["specific_energy_J_per_kg"] = self._specific_energy()
        self._last = outs
        return outs

    def _advance(self, h, new_inputs, end_inputs, adaptive):
        """(state after a step of h seconds, operating point at its start, at its end, and
        their scalars); commits nothing."""
        if adaptive:
            op = self.operating_point(new_inputs)

            def system(t, y):
                if end_inputs is None:
                    inp = new_inputs
                else:
                    w = min(max((t - self.t_s) / h, 0.0), 1.0)
                    inp = {k: (1 - w) * np.asarray(new_inputs[k]) + w * np.asarray(end_inputs[k]) for k in new_inputs}
                series, uu, _ = self._system(inp, y)
                return series, uu

            # Absolute tolerance scaled with the mass in the state: classes below a
            # millionth of the total are controlled absolutely, the rest relatively.
            rtol = self.scene.run.rtol
            y_new, _ = pbm.adaptive_exponential_step(self.y, self.t_s, h, system, rtol=rtol,
                                                     atol=rtol * 1e-6 * max(self.y.sum(), 1e-300))
            op_end = self.operating_point(end_inputs or new_inputs)
            return y_new, op, op_end, self._op_numbers(op), self._op_numbers(op_end)
        else:
            # Everything that depends only on the frozen inputs and h is built once.
            key = (new_inputs["tip_speed_m_per_s"], new_inputs["solids_mass_fraction"], new_inputs["bead_filling"],
                   new_inputs["feed_mass_flow_kg_per_s"], h)
            last = self._last_frozen
            if last[0] == key:  # the inputs and step of the step before (a host's usual case)
                frozen = last[1]
            else:
                frozen = self._cache.get(key, lambda: self._frozen_step(new_inputs, h))
                self._last_frozen = (key, frozen)
            if not frozen.propagator.finite:
                raise ArithmeticError("the step's propagator is not finite (rates too extreme for this step)")
            op = frozen.op
            if self.continuous:
                # The feed's part of the step, F u, is the same while the frozen inputs and
                # the feed distribution (checked, hence held, array) are: kept for them.
                psd_in = new_inputs["psd_in"]
                fed = self._fed_step
                if fed[0] is not frozen or fed[1] is not psd_in:
                    u = new_inputs["feed_mass_flow_kg_per_s"] * psd_in
                    fed = self._fed_step = (frozen, psd_in, frozen.propagator.apply(np.zeros_like(self.y), u))
                y_new = frozen.propagator.apply(self.y)
                y_new += fed[2]
            else:
                y_new = frozen.propagator.apply(self.y)
            return y_new, op, op, frozen.numbers, frozen.numbers

    def _specific_energy(self) -> float:
        """Stirrer energy per mass of solids treated [J/kg]: E / (initial holdup + solids fed)."""
        m = self.m0_kg + self.fed_kg
        return self.energy_J / m if m > 0.0 else 0.0

    # ---- outputs --------------------------------------------------------------------------
    def _outputs(self, y, op, inputs, dt_s, out_kg, num=None) -> dict:
        n, m = self._n, self._m
        # State: outflow, then tank N (the outlet) first; one tank is the whole content.
        content = y[1:] if self.n_tanks == 1 else y[1:].reshape(self.n_tanks, m).sum(axis=0)
        # Size distribution of the product (continuous: last tank = outlet) or mill content.
        dist = y[1 : 1 + m] if (self.continuous and self.n_tanks > 1) else content
        # The finest class of the psd output holds what lies below the grid (as psd_in does);
        # below_grid_fraction names that part.
        per_class = dist[:n] + dist[n : 2 * n] if self.material.inert_fragments else dist[:n].copy()
        below_kg = dist.item(-1)
        per_class[0] = per_class.item(0) + below_kg
        # One cumulative sum serves the total, the fractions and the quantiles (the ufunc's
        # accumulate: cumsum's sums, with a third of its call overhead at 100 classes).
        cum = _accumulate(per_class)
        tot = cum.item(-1)
        if tot > 0.0:
            psd = np.divide(per_class, tot, out=per_class)  # per_class is this call's own copy
            below = below_kg / tot
            x10, x50, x90 = self._q3_sizes.sizes(cum, below_kg)
        else:
            psd = np.zeros(n)
            below = 0.0
            x10 = x50 = x90 = math.nan
        # the content's total is the distribution's unless it is the outlet tank's or
        # fragments are kept apart
        holdup = tot if (dist is content and not self.material.inert_fragments) else float(content.sum())
        num = num if num is not None else self._op_numbers(op)
        if math.isfinite(x50):
            sf_nodes = num["sf_nodes"] if num["sf_nodes"] is not None else self._sf_nodes(op, y).ravel().tolist()
            sf = _interp(math.log(x50), self._log_nodes, sf_nodes)
        else:
            sf = 0.0
        out = {
            "t_s": self.t_s,
            "psd": psd,
            "x10_m": x10,
            "x50_m": x50,
            "x90_m": x90,
            "below_grid_fraction": below,
            "holdup_kg": holdup,
            "product_mass_flow_kg_per_s": out_kg / dt_s if dt_s > 0 else 0.0,
            "feed_mass_flow_kg_per_s": float(inputs["feed_mass_flow_kg_per_s"]),
            "outflow_total_kg": y.item(0),
            "se_beads_J": num["se_beads_J"],
            "se_product_J": num["se_product_J"],
            "sf_per_s": sf,
            "stress_number": self.stress_number,
            "power_W": num["power_W"],
            "specific_energy_J_per_kg": self._specific_energy(),
            "eta_eff_Pa_s": num["eta_eff_Pa_s"],
            "reynolds": num["reynolds"],
            "tip_speed_m_per_s": op.tip_speed_m_per_s,
        }
        if self.material.inert_fragments:
            debris = float(content[n:].sum())
            out["disrupted_fraction"] = debris / holdup if holdup > 0 else 0.0
        return out

    def _op_numbers(self, op) -> dict:
        """Scalars of an operating point (cached: the hot path recomputes nothing)."""
        return self._num_cache.get(op, lambda: {
            "se_beads_J": op.se_beads_J,
            "se_product_J": op.se_product_J,
            "power_W": self.power_W(op),
            "eta_eff_Pa_s": op.eta_eff_Pa_s,
            "reynolds": op.reynolds,
            # SF per node (a list: see _interp) is state-independent unless capture = 'psd'.
            "sf_nodes": None if self.capture_from_psd else self._sf_nodes(op, None).ravel().tolist(),
        })

    def _sf_nodes(self, op, y):
        if self.kinetics_model == "none":
            return np.zeros_like(self.operator.nodes_m)
        n_p = self._number_concentration(y, op) if self.capture_from_psd else None
        return op.stress_frequency_per_s(self.operator.nodes_m, n_p)

    def outputs(self) -> dict:
        """Outputs at the current time: psd (class mass fractions [-], the finest class with
        what lies below the grid), below_grid_fraction (the product's mass fraction below
        the grid's lowest edge [-]), x10_m/x50_m/x90_m [m],
        holdup_kg, product_mass_flow_kg_per_s (mean over the last step), feed_mass_flow_kg_per_s,
        se_beads_J/se_product_J [J], sf_per_s (SF at x50 [1/s]), stress_number [-],
        power_W, specific_energy_J_per_kg, eta_eff_Pa_s, reynolds [-], disrupted_fraction
        (yeast) [-]."""
        return self._last

    def similarity_warnings(self) -> dict:
        """{axis: warning} for each stress-energy table axis the operating points so far went
        beyond with similarity assumed ({} for other sources)."""
        f = getattr(self.source, "similarity_warnings", None)
        return f() if f is not None else {}

    def new_warnings(self, out: dict, said: set) -> list:
        """Warnings about ``out`` and the data used so far whose keys are not in ``said`` yet
        (the keys are added): the product below the size grid (once), each table axis gone
        beyond with similarity assumed (once per axis). For an FMU's log, which says each once."""
        new = []
        if "below_grid" not in said:
            w = self.output_warnings(out)
            if w:
                said.add("below_grid")
                new += w
        # Worded only where an axis is new: on every later step this is a set comparison.
        if not set(getattr(self.source, "similarity_seen", ())) <= said:
            for ax, w in self.similarity_warnings().items():
                if ax not in said:
                    said.add(ax)
                    new.append(w)
        return new

    def output_warnings(self, out: dict | None = None) -> list:
        """Warnings about outputs (default: the current ones): more than OUTSIDE_GRID_MAX of
        the product below the size grid, where its sizes are not resolved."""
        out = out if out is not None else self._last
        b = float(out.get("below_grid_fraction", 0.0))
        if b <= OUTSIDE_GRID_MAX:
            return []
        return [f"{b:.1%} of the product mass lies below the size grid (x < {self.grid.edges_m[0]:.3g} m) at t = "
                f"{out['t_s']:g} s; its sizes are not resolved (x10 is reported as the lowest edge when inside it): "
                "lower grid.x_min_m to resolve it"]

    def tank_masses_kg(self) -> np.ndarray:
        """Copy of the masses per tank (first tank first) and state entry [kg], shape (N, m)."""
        return self.y[1:].reshape(self.n_tanks, self._m)[::-1].copy()

    def total_mass_kg(self) -> float:
        """Solids in the mill plus all that has left it [kg] (= initial + fed, to round-off)."""
        return float(self.y.sum())

    def class_rates_per_s(self, inputs=None) -> np.ndarray:
        """Class-averaged selection rates [1/s] at the given (or current) inputs."""
        op = self.operating_point(self.check_inputs(inputs or {}))
        n_p = self._number_concentration(self.y, op) if self.capture_from_psd else None
        return self.operator.class_rates(self.selection_nodes(op, n_p))


def with_grid(scene: Scene, x_min_m: float, x_max_m: float, classes_per_octave: float) -> Scene:
    """Copy of a scene with another size grid."""
    return replace(scene,
                   grid=replace(scene.grid, x_min_m=x_min_m, x_max_m=x_max_m, classes_per_octave=classes_per_octave))


def _similar_axis_choices() -> tuple:
    """The axes a scene may name in ``kinetics.stress_distribution.similar_axes``."""
    from dataclasses import fields

    from .scene import StressDistribution

    return next(f.metadata["choices"] for f in fields(StressDistribution) if f.name == "similar_axes")
