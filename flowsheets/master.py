"""Fixed-step co-simulation master on fmpy (FMI 2.0 or 3.0 unit FMUs): Jacobi or
Gauss-Seidel, optional rejection and retry of discarded steps with FMU state get/set, mass
balance, CSV and PNG.

Mass flows between units ([kg/s] output -> [kg/s] input) go through a buffer per connection:
a sender's flow output is its mean over its last step (see flowsheets.units), so after each
of its steps the master adds flow * step to the buffer; before a receiver's step it sets the
input to buffer / step and empties the buffer. The receiver thus takes exactly the mass the
sender discharged, whatever the step sizes, and the mass balance of the whole flowsheet,
fed = products + accumulation (holdups and buffers), closes to round-off. With fixed steps
this is plain value copying (what libcosim and ecos do): in Jacobi every flow arrives one
step late; in Gauss-Seidel only flows against the order do.

A unit that answers a step with fmi2Discard (fmi3Discard) makes the master restore every
unit's FMU state (taken before the step) and the buffers, and redo the step as two halves,
up to ``max_halvings`` times (then the run stops with an error naming the unit).

The master addresses values by name; an FMI 3.0 unit's array (``psd``) is addressed element
by element as ``psd[1]`` ... ``psd[n]``, the FMI 2.0 FMUs' names, so flowsheet files, links,
results and mass balance are the same for both versions (:class:`Instance`).

This module loads FMUs into the calling process; run each flowsheet in a fresh process if
FMUs are rebuilt (pythonfmu keeps one interpreter per process).
"""

from __future__ import annotations

import hashlib
import json
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import fmu_build.build as fb
from fmu_build.build import build_fmu, check_fmi_version, toml_text
import millfmu

from .build import build_unit_fmu, code_hash
from .spec import Flowsheet, FlowsheetError, shared_grid, unit_configs

#: Per unit type: the output holding its solids holdup [kg] (units without holdup absent).
HOLDUP = {"mill": "holdup", "tank": "holdup"}


class MasterError(RuntimeError):
    """The co-simulation could not go on (a unit refused a step it may not retry, an error)."""


# ---------------------------------------------------------------------------------------
# building
# ---------------------------------------------------------------------------------------
def _mill_code_hash() -> str:
    h = hashlib.sha256()
    for root in (Path(millfmu.__file__).resolve().parent, Path(fb.__file__).resolve().parent):
        for f in sorted(root.rglob("*.py")):
            h.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes())
    return h.hexdigest()[:12]


def _reuse(path: Path, folders) -> bool:
    for d in folders:
        src = Path(d) / path.name
        if src.is_file():
            shutil.copy2(src, path)
            return True
    return False


def build_fmus(fs: Flowsheet, fmu_dir: Path, log=print, reuse=(), fmi_version: int = 2) -> dict:
    """Build (or reuse, by content hash, from ``fmu_dir`` or one of the ``reuse`` folders,
    copying it into ``fmu_dir``) the FMU of every unit, all of one FMI version: name -> path."""
    fmi_version = check_fmi_version(fmi_version)
    tag = "" if fmi_version == 2 else f"fmi{fmi_version}_"
    fmu_dir = Path(fmu_dir)
    fmu_dir.mkdir(parents=True, exist_ok=True)
    paths = {}
    for name, (kind, cfg) in unit_configs(fs).items():
        if kind == "mill":
            text = toml_text(cfg)
            key = hashlib.sha256((_mill_code_hash() + f"\0{fmi_version}\0" + text).encode()).hexdigest()[:10]
            path = fmu_dir / f"mill_{tag}{key}.fmu"
            if not path.exists() and not _reuse(path, reuse):
                log(f"building {path.name} (mill {name})")
                scene = fmu_dir / f"mill_{tag}{key}.toml"
                scene.write_text(text)
                build_fmu(scene, path, fmi_version=fmi_version, log=log)
                scene.unlink()
        else:
            key = hashlib.sha256((code_hash(fmi_version) + "\0"
                                  + json.dumps(cfg, sort_keys=True)).encode()).hexdigest()[:10]
            path = fmu_dir / f"{kind}_{tag}{key}.fmu"
            if not path.exists() and not _reuse(path, reuse):
                log(f"building {path.name} ({kind} {name})")
                build_unit_fmu(kind, name, cfg, path, fmi_version=fmi_version, log=log)
        paths[name] = path
    return paths


# ---------------------------------------------------------------------------------------
# connections
# ---------------------------------------------------------------------------------------
@dataclass
class Link:
    src: str
    src_vr: int
    src_var: str
    dst: str
    dst_vr: int
    dst_var: str
    flow: bool  # kg/s -> kg/s: buffered


def flat_variables(md) -> dict:
    """A model description's variables by name, an FMI 3.0 array's elements as name[1] ...
    name[n] (the names FMI 2.0 FMUs give them): name -> ModelVariable (the array's for an element)."""
    out = {}
    for v in md.modelVariables:
        dims = getattr(v, "dimensions", None) or []
        if not dims:
            out[v.name] = v
            continue
        n = 1
        for d in dims:
            n *= int(d.start if d.start is not None else d.variable.start)
        out.update({f"{v.name}[{k}]": v for k in range(1, n + 1)})
    return out


def expand_connections(fs: Flowsheet, mds: dict) -> tuple:
    """Links (class-by-class lines expanded) and product outputs, checked against the FMUs'
    model descriptions: (links, products [(unit, var, vr)])."""
    by = {u: flat_variables(md) for u, md in mds.items()}
    links, seen = [], {}
    for i, (line, (su, sv, si, du, dv, di)) in enumerate(fs.connections):
        key = f"connections[{i}]"
        if si == "*":
            n_s = sum(1 for n in by[su] if n.startswith(sv + "["))
            n_d = sum(1 for n in by[du] if n.startswith(dv + "["))
            if n_s == 0 or n_s != n_d:
                raise FlowsheetError(key, line,
                                     f"{su}.{sv}[*] has {n_s} classes and {du}.{dv}[*] has {n_d}; both must be the "
                                     "same non-zero number", fs.source)
            pairs = [(f"{sv}[{k}]", f"{dv}[{k}]") for k in range(1, n_s + 1)]
        else:
            pairs = [(sv if si is None else f"{sv}[{si}]", dv if di is None else f"{dv}[{di}]")]
        for a, b in pairs:
            va, vb = by[su].get(a), by[du].get(b)
            if va is None or va.causality != "output":
                outs = sorted({n.split("[")[0] for n, v in by[su].items() if v.causality == "output"})
                raise FlowsheetError(key, line, f"{su} has no output {a}; its outputs: {', '.join(outs)}", fs.source)
            if vb is None or vb.causality not in ("input", "parameter"):
                ins = sorted({n.split("[")[0] for n, v in by[du].items() if v.causality in ("input",)})
                raise FlowsheetError(key, line, f"{du} has no input {b}; its inputs: {', '.join(ins)}", fs.source)
            if vb.causality == "parameter" and vb.variability != "tunable":
                raise FlowsheetError(key, line,
                                     f"{du}.{b} is a fixed parameter; only inputs and tunable parameters can be "
                                     "connected", fs.source)
            if (va.unit or "1") != (vb.unit or "1"):
                raise FlowsheetError(key, line, f"units differ: {su}.{a} is in {va.unit}, {du}.{b} in {vb.unit}",
                                     fs.source)
            if (du, b) in seen:
                raise FlowsheetError(key, line, f"{du}.{b} is already connected by {seen[(du, b)]!r}", fs.source)
            seen[(du, b)] = line
            links.append(Link(su, va.valueReference, a, du, vb.valueReference, b, va.unit == "kg/s"))
    connected = {(lk.src, lk.src_var) for lk in links if lk.flow}
    products = []
    for i, (u, v) in enumerate(fs.products):
        var = by[u].get(v)
        if var is None or var.causality != "output" or var.unit != "kg/s":
            raise FlowsheetError(f"products[{i}]", f"{u}.{v}", "must be a mass-flow output [kg/s] of the unit",
                                 fs.source)
        if (u, v) in connected:
            raise FlowsheetError(f"products[{i}]", f"{u}.{v}", "is connected to a unit; a product leaves the flowsheet",
                                 fs.source)
        products.append((u, v, var.valueReference))
    for u, vs in by.items():
        if fs.units[u].type == "feed":
            continue
        for n, var in vs.items():
            if (var.causality == "output" and var.unit == "kg/s" and (u, n) not in connected
                    and (u, n) not in {(p[0], p[1]) for p in products}):
                raise FlowsheetError("products", [f"{a}.{b}" for a, b in fs.products],
                                     f"mass flow {u}.{n} leaves the flowsheet unaccounted: connect it or list it in "
                                     "products", fs.source)
    return links, products


# ---------------------------------------------------------------------------------------
# the master
# ---------------------------------------------------------------------------------------
class Instance:
    """One unit FMU instance (fmpy), FMI 2.0 or 3.0 behind one interface: values by name, an
    FMI 3.0 array's elements as name[k]; messages appended to ``messages`` as (instance,
    status, text); :meth:`do_step` gives None when accepted, else the status."""

    def __init__(self, md, unzip_dir: str, name: str, messages: list):
        self.name, self.md = name, md
        self.fmi3 = md.fmiVersion.startswith("3")
        self.variables = flat_variables(md)
        args = dict(guid=md.guid, unzipDirectory=unzip_dir, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=name)
        if self.fmi3:
            from fmpy.fmi3 import FMU3Slave

            def log(env, status, category, message):
                messages.append((name, int(status), (message or b"").decode()))

            self.fmu = FMU3Slave(**args)
            self.fmu.instantiate(loggingOn=True, logMessage=log)
        else:
            from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                                   fmi2CallbackFunctions,
                                   fmi2CallbackLoggerTYPE, calloc, free)

            def log(env, instance, status, category, message):
                messages.append((instance.decode(), int(status), (message or b"").decode().replace("%%", "%")))

            self._cb = cb = fmi2CallbackFunctions()  # kept alive as long as the instance
            cb.logger = fmi2CallbackLoggerTYPE(log)
            cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
            cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
            self.fmu = FMU2Slave(**args)
            self.fmu.instantiate(callbacks=cb, loggingOn=True)
        outs = [v for v in md.modelVariables if v.causality == "output"]
        self.out_vrs = [v.valueReference for v in outs]
        self.out_names = [k for k, v in self.variables.items() if v.causality == "output"]
        self._plans: dict = {}

    def enter_initialization_mode(self, stop_time: float):
        if self.fmi3:
            self.fmu.enterInitializationMode(startTime=0.0, stopTime=stop_time)
        else:
            self.fmu.setupExperiment(startTime=0.0, stopTime=stop_time)
            self.fmu.enterInitializationMode()

    def exit_initialization_mode(self):
        self.fmu.exitInitializationMode()

    def outputs(self) -> dict:
        if self.fmi3:
            return dict(zip(self.out_names, self.fmu.getFloat64(self.out_vrs, len(self.out_names))))
        return dict(zip(self.out_names, self.fmu.getReal(self.out_vrs)))

    def set(self, names: list, values: list):
        """Set variables by name; an FMI 3.0 array is set whole, from the values of the named
        elements and its current values for the others."""
        if not self.fmi3:
            self.fmu.setReal([self.variables[k].valueReference for k in names], values)
            return
        plan = self._plans.get(tuple(names))
        if plan is None:
            plan = self._plans[tuple(names)] = self._plan(names)
        arrays, where = plan
        for (buf, k), x in zip(where, values):
            buf[k] = x
        self.fmu.setFloat64([vr for vr, _ in arrays], [x for _, buf in arrays for x in buf])

    def _plan(self, names):
        """For set(names): the variables as [(vr, values)], and per name (values, index)."""
        arrays, at = [], {}
        where = []
        for k in names:
            v = self.variables[k]
            if v.valueReference not in at:
                n = sum(1 for x in self.variables.values() if x is v)
                values = self.fmu.getFloat64([v.valueReference], n) if n > 1 or v.dimensions else [0.0]
                at[v.valueReference] = values
                arrays.append((v.valueReference, values))
            where.append((at[v.valueReference], int(k[k.index("[") + 1 : -1]) - 1 if v.dimensions else 0))
        return arrays, where

    def do_step(self, t: float, h: float):
        from fmpy.fmi1 import FMICallException

        try:
            self.fmu.doStep(t, h)
            return None
        except FMICallException as e:
            return e.status

    def get_state(self):
        return self.fmu.getFMUState() if self.fmi3 else self.fmu.getFMUstate()

    def set_state(self, state):
        return self.fmu.setFMUState(state) if self.fmi3 else self.fmu.setFMUstate(state)

    def free_state(self, state):
        return self.fmu.freeFMUState(state) if self.fmi3 else self.fmu.freeFMUstate(state)

    def close(self):
        try:
            self.fmu.terminate()
        finally:
            self.fmu.freeInstance()


@dataclass
class Result:
    t: np.ndarray
    columns: list
    data: np.ndarray  # rows: output times; columns: see ``columns`` (unit.variable)
    psd: dict  # unit -> array (times, classes) of its main size distribution output
    mass: dict  # fed_kg, products_kg, holdup0_kg, holdup_kg, buffered_kg, residual_kg, relative_residual
    retries: list  # (t, step that was refused, unit, message)
    wall_s: float
    steps: int
    edges_m: np.ndarray = field(default=None)
    fmi_version: str = "2.0"  # the units' FMI version(s)
    units: list = field(default=None)  # the unit of each of ``columns`` (the FMU variables' units)

    def column(self, name):
        return self.data[:, self.columns.index(name)]


class Master:
    """fmpy master for one flowsheet: ``Master(fs, fmu_paths).run()``."""

    def __init__(self, fs: Flowsheet, fmu_paths: dict, log=print):
        from fmpy import extract, read_model_description

        self.fs, self.log = fs, log
        self.mds = {u: read_model_description(str(p)) for u, p in fmu_paths.items()}
        self.links, self.products = expand_connections(fs, self.mds)
        self.fmu_paths = fmu_paths
        self._dirs = {}
        for u, p in fmu_paths.items():
            key = str(p)
            if key not in self._dirs:
                self._dirs[key] = extract(key)
        self.messages: list = []
        self.grid = shared_grid(fs)

    # ---- set-up --------------------------------------------------------------------------
    def _init_call(self, u, f, *args):
        """An FMI call while initializing; a unit that refuses it (an FMI 3.0 FMU answers a
        parameter it refuses with fmi3Error) stops the run with its message."""
        from fmpy.fmi1 import FMICallException

        n0 = len(self.messages)
        try:
            return f(*args)
        except FMICallException as e:
            msg = "; ".join(m[2] for m in self.messages[n0:] if m[0] == u) or "(no message)"
            raise MasterError(f"unit {u} refused its initialization (status {e.status}): {msg}") from None

    def _instantiate(self):
        self.fmus, self.out_names, self.vals = {}, {}, {}
        for u in self.fs.units:
            fmu = self.fmus[u] = Instance(self.mds[u], self._dirs[str(self.fmu_paths[u])], u, self.messages)
            self._init_call(u, fmu.enter_initialization_mode, self.fs.t_end_s)
            self.out_names[u] = fmu.out_names
        for u, fmu in self.fmus.items():
            for k, x in self.fs.units[u].start.items():
                if k not in fmu.variables:
                    raise FlowsheetError(f"units.{u}.start.{k}", x, f"{u} has no variable {k}", self.fs.source)
                self._init_call(u, fmu.set, [k], [float(x)])
        # Connected non-flow inputs start from their senders' start outputs (the operating
        # point each unit initialises with); flows start empty: nothing has flowed yet.
        for u, fmu in self.fmus.items():
            self.vals[u] = fmu.outputs()
        for u, fmu in self.fmus.items():
            into = [lk for lk in self.links if lk.dst == u]
            if into:
                self._init_call(u, fmu.set, [lk.dst_var for lk in into],
                                [0.0 if lk.flow else self.vals[lk.src][lk.src_var] for lk in into])
        for u, fmu in self.fmus.items():
            self._init_call(u, fmu.exit_initialization_mode)
            self.vals[u] = fmu.outputs()
        self.buffer = [0.0] * len(self.links)
        self.into = {u: [i for i, lk in enumerate(self.links) if lk.dst == u] for u in self.fs.units}
        self.outof = {u: [i for i, lk in enumerate(self.links) if lk.src == u and lk.flow] for u in self.fs.units}
        self._into_names = {u: [self.links[i].dst_var for i in self.into[u]] for u in self.fs.units}
        self.sources = [(u, "mass_flow") for u, s in self.fs.units.items() if s.type == "feed"]
        self.fed_kg = 0.0
        self.products_kg = 0.0

    # ---- stepping ------------------------------------------------------------------------
    def _set_inputs(self, u, h):
        xs = []
        for i in self.into[u]:
            lk = self.links[i]
            if lk.flow:
                xs.append(self.buffer[i] / h)
                self.buffer[i] = 0.0
            else:
                xs.append(self.vals[lk.src][lk.src_var])
        if xs:
            self.fmus[u].set(self._into_names[u], xs)

    def _do_step(self, u, t, h):
        """doStep; None when accepted, else the unit's message (discard)."""
        n0 = len(self.messages)
        status = self.fmus[u].do_step(t, h)
        if status is None:
            return None
        msg = "; ".join(m[2] for m in self.messages[n0:] if m[0] == u) or "(no message)"
        if status == 2:
            return msg
        raise MasterError(f"unit {u} failed the step at t = {t!r} s (status {status}): {msg}")

    def _publish(self, u, h):
        self.vals[u] = self.fmus[u].outputs()
        for i in self.outof[u]:
            lk = self.links[i]
            self.buffer[i] += self.vals[u][lk.src_var] * h
        if self.fs.units[u].type == "feed":
            self.fed_kg += self.vals[u]["mass_flow"] * h
        for pu, pv, _ in self.products:
            if pu == u:
                self.products_kg += self.vals[u][pv] * h

    def _try_step(self, t, h):
        """One co-simulation step; (unit, message) of the first unit that discards, else None."""
        order = self.fs.order
        if self.fs.algorithm == "jacobi":
            for u in order:
                self._set_inputs(u, h)
            for u in order:
                msg = self._do_step(u, t, h)
                if msg is not None:
                    return u, msg
            for u in order:
                self._publish(u, h)
        else:
            for u in order:
                self._set_inputs(u, h)
                msg = self._do_step(u, t, h)
                if msg is not None:
                    return u, msg
                self._publish(u, h)
        return None

    def _snapshot(self):
        return ({u: f.get_state() for u, f in self.fmus.items()}, list(self.buffer),
                {u: dict(v) for u, v in self.vals.items()}, self.fed_kg, self.products_kg)

    def _restore(self, snap):
        states, buf, vals, fed, prod = snap
        for u, f in self.fmus.items():
            f.set_state(states[u])
        self.buffer, self.vals, self.fed_kg, self.products_kg = list(buf), {u: dict(v)
                                                                            for u, v in vals.items()}, fed, prod

    def _free(self, snap):
        for u, f in self.fmus.items():
            f.free_state(snap[0][u])

    def _macro_step(self, t, h, depth):
        if self.fs.max_halvings == 0:
            bad = self._try_step(t, h)
            if bad:
                raise MasterError(f"unit {bad[0]} refused the step [{t!r}, {t + h!r}] s: {bad[1]} "
                                  "(set flowsheet.max_halvings > 0 to retry with smaller steps)")
            self.n_steps += 1
            return
        snap = self._snapshot()
        try:
            bad = self._try_step(t, h)
            if bad is None:
                self.n_steps += 1
                return
            if depth >= self.fs.max_halvings:
                raise MasterError(f"unit {bad[0]} refused the step [{t!r}, {t + h!r}] s after {depth} halvings "
                                  f"(flowsheet.max_halvings = {self.fs.max_halvings}): {bad[1]}")
            self.retries.append((t, h, bad[0], bad[1]))
            self._restore(snap)
        finally:
            self._free(snap)
        self._macro_step(t, h / 2.0, depth + 1)
        self._macro_step(t + h / 2.0, h / 2.0, depth + 1)

    # ---- bookkeeping ---------------------------------------------------------------------
    def holdup_kg(self) -> float:
        return sum(self.vals[u][HOLDUP[s.type]] for u, s in self.fs.units.items() if s.type in HOLDUP)

    def _record(self, t, rows, psds):
        row = [t]
        for u in self.fs.units:
            row += [self.vals[u][n] for n in self._scalar[u]]
        row += [self.holdup_kg(), sum(b for b, lk in zip(self.buffer, self.links) if lk.flow), self.fed_kg,
                self.products_kg]
        rows.append(row)
        for u, prefix in self._psd_out.items():
            psds[u].append([self.vals[u][f"{prefix}[{k}]"] for k in range(1, self.grid.n + 1)])

    def run(self) -> Result:
        fs = self.fs
        t0 = time.perf_counter()
        self.fmus = {}
        self.retries, self.n_steps = [], 0
        main_psd = {"mill": "psd", "tank": "psd", "feed": "psd", "classifier": "fine_psd"}
        self._psd_out = {u: main_psd[s.type] for u, s in fs.units.items() if s.type in main_psd}
        rows, psds = [], {u: [] for u in self._psd_out}
        n = int(round(fs.t_end_s / fs.step_s))
        every = max(1, int(round(fs.output_interval_s / fs.step_s)))
        try:
            self._instantiate()
            self._scalar = {u: [n for n in self.out_names[u] if "[" not in n] for u in fs.units}
            columns = ["t"] + [f"{u}.{n}" for u in fs.units for n in self._scalar[u]] + ["total.holdup",
                                                                                         "total.buffered", "total.fed",
                                                                                         "total.products"]
            units = ["s"] + [self.fmus[u].variables[n].unit or "1" for u in fs.units for n in self._scalar[u]] \
                + ["kg"] * 4
            m0 = self.holdup_kg()
            self._record(0.0, rows, psds)
            for k in range(n):
                # Time as k h (not a running sum), so no drift over many steps.
                self._macro_step(k * fs.step_s, fs.step_s, 0)
                if (k + 1) % every == 0 or k + 1 == n:
                    self._record((k + 1) * fs.step_s, rows, psds)
        finally:
            for f in self.fmus.values():
                f.close()
        wall = time.perf_counter() - t0
        m1 = self.holdup_kg()
        buffered = sum(b for b, lk in zip(self.buffer, self.links) if lk.flow)
        res = self.fed_kg - self.products_kg - (m1 - m0 + buffered)
        scale = max(m0 + self.fed_kg, 1e-300)
        mass = {"fed_kg": self.fed_kg, "products_kg": self.products_kg, "holdup0_kg": m0, "holdup_kg": m1,
                "buffered_kg": buffered, "residual_kg": res, "relative_residual": abs(res) / scale}
        data = np.array(rows)
        return Result(data[:, 0], columns, data, {u: np.array(v) for u, v in psds.items()}, mass, self.retries, wall,
                      self.n_steps, self.grid.edges_m, ", ".join(sorted({md.fmiVersion for md in self.mds.values()})),
                      units)


def run_flowsheet(fs: Flowsheet, fmu_dir: Path, log=print, reuse=(), fmi_version: int = 2) -> Result:
    """Build what is missing (unit FMUs of one FMI version) and run the flowsheet with the fmpy master."""
    paths = build_fmus(fs, fmu_dir, log=log, reuse=reuse, fmi_version=fmi_version)
    return Master(fs, paths, log=log).run()


# ---------------------------------------------------------------------------------------
# results
# ---------------------------------------------------------------------------------------
def write_results(res: Result, fs: Flowsheet, out: Path, plots=True) -> list:
    """results.csv (scalars per output time), psd_<unit>.csv (class fractions per output
    time), summary.json (mass balance, retries, wall time) and, with plots, flowsheet.png."""
    out = Path(out)
    files = []
    header = ",".join(res.columns)
    np.savetxt(out / "results.csv", res.data, delimiter=",", header=header, comments="", fmt="%.17g")
    files.append(out / "results.csv")
    for u, a in res.psd.items():
        p = out / f"psd_{u}.csv"
        hdr = "t," + ",".join(f"class{k + 1}_{res.edges_m[k]:.6g}_{res.edges_m[k + 1]:.6g}_m"
                              for k in range(a.shape[1]))
        np.savetxt(p, np.column_stack([res.t, a]), delimiter=",", header=hdr, comments="", fmt="%.17g")
        files.append(p)
    summary = {"flowsheet": fs.name, "fmi_version": res.fmi_version, "algorithm": fs.algorithm, "step_s": fs.step_s,
               "t_end_s": fs.t_end_s,
               "steps": res.steps, "wall_s": res.wall_s, "mass_balance": res.mass,
               "retries": [{"t_s": t, "step_s": h, "unit": u, "message": m} for t, h, u, m in res.retries],
               "final": {c: float(res.data[-1, i]) for i, c in enumerate(res.columns)},
               "units": dict(zip(res.columns, res.units or ()))}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    files.append(out / "summary.json")
    if plots:
        files.append(plot(res, fs, out / "flowsheet.png"))
    return files


def plot(res: Result, fs: Flowsheet, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from millfmu.plotstyle import plain_log_ticks

    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5))
    t_min = res.t / 60.0
    for c in res.columns:
        if c.endswith(".x50") or c.endswith("_x50"):
            ax[0, 0].plot(t_min, res.column(c) * 1e6, label=c)
        if c.endswith("holdup"):
            ax[0, 1].plot(t_min, res.column(c), label=c)
        if c.endswith("mass_flow") or c in ("total.buffered",):
            ax[1, 0].plot(t_min, res.column(c) * (1e3 if c.endswith("mass_flow") else 1.0),
                          label=c + (" [g/s]" if c.endswith("mass_flow") else " [kg]"))
    ax[0, 0].set(xlabel="t [min]", ylabel="x50 [um]", title="median sizes")
    ax[0, 1].set(xlabel="t [min]", ylabel="solids [kg]", title="holdups")
    ax[1, 0].set(xlabel="t [min]", title="solids mass flows")
    for u, a in res.psd.items():
        ax[1, 1].semilogx(res.edges_m[1:] * 1e6, np.cumsum(a[-1]), label=f"{u} at end")
        ax[1, 1].semilogx(res.edges_m[1:] * 1e6, np.cumsum(a[0]), ":", color=ax[1, 1].lines[-1].get_color())
    ax[1, 1].set(xlabel="x [um]", ylabel="Q3 [-]", title="size distributions (dotted: start)")
    for a in ax.flat:
        if a.lines:
            a.legend(fontsize=7)
        a.grid(alpha=0.3)
    plain_log_ticks(fig)
    mb = res.mass
    fig.suptitle(f"{fs.name}: {fs.algorithm}, step {fs.step_s:g} s; mass balance residual "
                 f"{mb['relative_residual']:.1e} (relative)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
