"""Run a DEM scene: spin-up, recording, zone statistics and output files.

Outputs in the output folder:
- ``stats.json``: :class:`millfmu.dem.analysis.stats.DemStats` (plain JSON), with the fluid model
  named in ``fluid_model`` and, in ``flow``, the mean-flow structure (see
  :func:`flow_summary`): torque and power split into fluid shear and bead contacts and the
  power number (coupled fluid), the angular-momentum budget, vortices of the mean flow,
  swirl profiles between the discs at the disc radius and the first bead layer's angular
  velocity;
- ``se_histograms.csv``: stress-energy number densities [1/decade] per zone and component
  on the log bins of ``stats.json``;
- ``kinetic_energy.csv``: bead kinetic energy over time (spin-up and recording);
- with ``contacts=True`` only: ``contacts.npz``, every recorded bead-bead contact with its
  zone, recording chunk (one sampling interval) and SE_tn, SE_total [J], so that statistics
  of any part of the recording can be recomputed (see :func:`write_contacts`);
- ``map_stress_energy.png``, ``map_collision_frequency.png``, ``map_collision_power.png``:
  radially averaged (i.e. averaged over the angle) maps in the axial section, like seed 001
  figures 12-15, their numbers in ``collision_maps.npz`` (for a plain disc slice with the
  radial profile of the collision frequency and power on bins of a quarter bead diameter,
  :func:`millfmu.dem.analysis.plots.radial_collision_profile`); ``se_distributions.png``:
  SE_tn distributions per zone (seed 001 Fig. A1);
- accelerator slices: ``map_stress_intensity.png``, ``map_stress_number.png``,
  ``map_collision_stress_energy.png``, ``map_se_tn.png``, ``map_se_ts.png`` (seed 002
  figures 12-15), ``speed_profiles.png`` (figures 3 and 4), and in ``stats.json``
  ``flow.seed002`` (see :func:`accelerator_summary`);
- disc and accelerator slices: ``bead_fields.npz`` (time-mean bead fields of the axial section: solids
  fraction, velocities, axial solids flux, on the fluid grid's bins);
- coupled fluid only: ``fluid_fields.npz`` (time-mean fields of the axial section),
  ``map_fluid_swirl.png``, ``map_fluid_radial.png`` (with its zero contour, seed 001
  figure 7), ``map_fluid_axial.png``, ``map_turbulent_viscosity.png``,
  ``map_void_fraction.png``, and for disc slices ``swirl_profile.png`` (fluid and beads
  between the discs at the disc radius, seed 001 figures 9 and 10).

Checkpoints (``checkpoint_every_s``): while a run goes, ``checkpoint.pkl`` in the output
folder holds its whole state (beads, contact histories, the liquid, what has been recorded
so far), written anew (atomically) every so many seconds of wall time and removed once the
outputs are written. The recorded contacts are appended to ``recorded_contacts.f8`` in the
same folder as the run goes (:mod:`millfmu.dem.contact_log`: a full slice's do not fit in
memory), of which the checkpoint names the length; the file too is removed at the end.
:func:`resume_run` (``millfmu dem run --resume DIR``) goes on from a checkpoint and gives
the same outputs to the digit as the run that was not stopped.
"""

from __future__ import annotations

import importlib
import json
import math
import os
import pickle
import time
import types
from pathlib import Path

import numpy as np

from millfmu.dem.analysis import flow_structure as FS
from millfmu.dem.analysis import plots, snapshots
from millfmu.dem.analysis.circumferential import circumferential
from millfmu.dem.analysis.circumferential import summary_line as circumferential_line
from millfmu.dem.analysis.stats import DemStats, compute_stats
from millfmu.dem.contact_log import FILE as CONTACT_LOG
from millfmu.dem.contact_log import ContactLog, ContactLogError
from millfmu.dem.coupling.cfd_dem import CfdDem
from millfmu.dem.engine.sim import DemSimulation
from millfmu.dem.fluid.grid import GridError, mill_grid
from millfmu.dem.fluid.solver import FluidProperties
from millfmu.dem.mills import accelerator as A
from millfmu.dem.mills import zones_for
from millfmu.dem.mills.geometry import (bead_count_for_filling, place_beads,
                                        simple_cubic_annulus)
from millfmu.dem.scene import DemScene
from millfmu.unit_names import modern_name

#: Initial turbulence of the coupled fluid (the stirrer starts from rest): k = (0.02 v_t)^2,
#: epsilon from a 1 mm mixing length; k-epsilon forgets it within a few stirrer turns.
INITIAL_TURBULENCE_INTENSITY = 0.02
#: seed 002 saved positions, velocities and contacts 20 times per second [s]
PAPER_FRAME_INTERVAL_S = 0.05
#: a bead this many times faster than the stirrer's tip means the run has become unstable
#: (beads driven by the stirrer stay below about twice its tip speed)
UNSTABLE_SPEED_FACTOR = 20.0
#: steps between two such checks in a coupled run (about 60 us of a run's 0.1-1 s per check)
CHECK_EVERY_STEPS = 1000


class DemRunError(RuntimeError):
    """A run that cannot go on: the beads' motion became unstable. Nothing was written."""


def _instability(sim, scene) -> str | None:
    """Why the beads' state is not a physical one (None where it is)."""
    if not (np.isfinite(sim.x).all() and np.isfinite(sim.v).all()):
        return "non-finite bead positions or velocities"
    vmax = float(np.sqrt(np.einsum("ij,ij->i", sim.v, sim.v).max())) if sim.n else 0.0
    if vmax > UNSTABLE_SPEED_FACTOR * scene.tip_speed_m_per_s:
        return (f"a bead at {vmax:.3g} m/s, {vmax / scene.tip_speed_m_per_s:.0f} times the tip speed "
                f"{scene.tip_speed_m_per_s:.3g} m/s")
    return None
INITIAL_MIXING_LENGTH_M = 1e-3


def initial_positions(scene: DemScene) -> np.ndarray:
    """Bead centres [m] of a scene's initial state."""
    r = 0.5 * scene.bead_diameter_m
    if scene.placement == "lattice":
        return simple_cubic_annulus(scene.lattice_spacing_m, *scene.lattice_r_range_m,
                                    scene.geometry.height_m)
    n = bead_count_for_filling(scene.geometry, scene.filling, scene.bead_diameter_m,
                               scene.bulk_porosity)
    return place_beads(scene.geometry, n, r, seed=scene.seed)


def make_simulation(scene: DemScene, threads: int | None = None, device: str = "cpu"):
    """The DEM of ``scene`` and, for the coupled fluid, its :class:`CfdDem` (else None).
    ``device``: where the DEM steps ("cpu": numba threads; "gpu": numba.cuda, with the
    beads' side of the coupled exchange, :mod:`millfmu.dem.coupling.gpu_exchange`; the
    liquid and the exchange's cell side staying on the CPU's ``threads``)."""
    x0 = initial_positions(scene)
    v0 = None
    if scene.initial_rotation:
        w = scene.initial_rotation * scene.omega_rad_per_s
        v0 = np.column_stack([-w * x0[:, 1], w * x0[:, 0], np.zeros(len(x0))])
    sim = DemSimulation(scene.geometry, scene.material, x0, 0.5 * scene.bead_diameter_m,
                        scene.omega_rad_per_s, scene.dt_s, gravity_m_per_s2=scene.gravity_m_per_s2,
                        fluid=scene.fluid, threads=threads, velocities_m_per_s=v0, device=device)
    cpl = None
    if scene.fluid_mode == "coupled":
        c = scene.coupling
        grid = mill_grid(scene.geometry, c.cell_m, n_theta=c.n_theta)
        if c.scheme == "dpm":
            from millfmu.dem.coupling.dpm import DiscretePhaseCoupling as coupling
        else:
            coupling = CfdDem
        cpl = coupling(sim, grid, FluidProperties(scene.fluid.density_kg_per_m3,
                                                  scene.fluid.viscosity_Pa_s), c,
                       scene.omega_rad_per_s)
        if c.turbulence == "k_epsilon":
            cpl.solver.init_turbulence((INITIAL_TURBULENCE_INTENSITY * scene.tip_speed_m_per_s) ** 2,
                                       INITIAL_MIXING_LENGTH_M)
        if scene.initial_rotation:
            cpl.solver.init_solid_body(scene.initial_rotation)
        cpl.prime(scene.primed_s)
        cpl.liquid_changed()
    return sim, cpl


def bead_angular_momentum_kgm2_s(sim) -> float:
    """Angular momentum of the beads about the axis [kg m2/s]: orbit and spin."""
    x, v = sim.x, sim.v
    return float((sim.mass * (x[:, 0] * v[:, 1] - x[:, 1] * v[:, 0])).sum() +
                 (sim.inertia * sim.w[:, 2]).sum())


#: the checkpoint file in a run's output folder
CHECKPOINT = "checkpoint.pkl"
#: layout of a checkpoint: 2 keeps the recorded contacts in the run's contact log file,
#: 1 (earlier sources, still read) kept them in the checkpoint
CHECKPOINT_FORMAT = 2
#: the layouts this version reads (any other is refused by name)
CHECKPOINT_FORMATS_READ = (1, 2)
#: [s of wall time] checkpoint interval of a resumed run whose checkpoint does not record
#: the one it was started with (made by earlier sources)
RESUME_CHECKPOINT_EVERY_S = 600.0


class _Pickler(pickle.Pickler):
    """Pickles the kernel modules the simulation objects keep as attributes by name."""

    def reducer_override(self, obj):
        if isinstance(obj, types.ModuleType):
            return importlib.import_module, (obj.__name__,)
        return NotImplemented


def _write_checkpoint(path: Path, state: dict):
    """Write ``state`` to ``path`` atomically: a stop while writing leaves the last one."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        _Pickler(fh, protocol=pickle.HIGHEST_PROTOCOL).dump(state)
    os.replace(tmp, path)


def _kernel_version() -> str:
    from millfmu.dem.tables.cache import kernel_source_hash

    return kernel_source_hash()


def load_checkpoint(out_dir) -> dict:
    """The state in ``out_dir``'s checkpoint (see :func:`run_scene`); refused by name
    (DemRunError) where there is none, it cannot be read, or it has another layout."""
    path = Path(out_dir) / CHECKPOINT
    if not path.exists():
        raise DemRunError(f"{out_dir}: no {CHECKPOINT} (a run writes one with "
                          f"checkpoint_every_s / --checkpoint-every)")
    try:
        with open(path, "rb") as fh:
            state = pickle.load(fh)
    except (OSError, pickle.UnpicklingError, EOFError, AttributeError, ImportError) as e:
        raise DemRunError(f"{path}: not a readable checkpoint ({type(e).__name__}: {e})") \
            from None
    fmt = state.get("format") if isinstance(state, dict) else None
    if fmt not in CHECKPOINT_FORMATS_READ:
        raise DemRunError(f"{path}: checkpoint layout {fmt!r}; this version reads layouts "
                          f"{', '.join(map(str, CHECKPOINT_FORMATS_READ))}")
    _current_attribute_names(state, set())
    return state


def _current_attribute_names(obj, seen: set):
    """Rename, in place, the attributes and dict keys of a checkpoint's objects that an
    earlier release spelled another way (:mod:`millfmu.unit_names`), so that its simulation
    goes on under these sources."""
    if id(obj) in seen:
        return
    seen.add(id(obj))
    if isinstance(obj, dict):
        for k in [k for k in obj if isinstance(k, str) and modern_name(k) != k]:
            obj[modern_name(k)] = obj.pop(k)
        for v in obj.values():
            _current_attribute_names(v, seen)
    elif isinstance(obj, (list, tuple)):
        for v in obj:
            _current_attribute_names(v, seen)
    elif type(obj).__module__.startswith("millfmu.") and hasattr(obj, "__dict__"):
        _current_attribute_names(obj.__dict__, seen)


def resume_run(out_dir, progress: bool = True, threads: int | None = None,
               checkpoint_every_s: float | None = None) -> DemStats:
    """Go on with the run whose ``checkpoint.pkl`` is in ``out_dir`` (its scene, windows
    and contacts option as it was started; ``threads`` may differ, the results do not
    while the threads are no more than the beads' chunks); returns the statistics. It goes
    on writing checkpoints every ``checkpoint_every_s`` [s of wall time], by default the
    interval the run was started with (RESUME_CHECKPOINT_EVERY_S for a checkpoint of
    earlier sources, which did not record it): a resumed run that wrote none lost all it
    did when it was stopped again. Refused by name (DemRunError) where there is no
    checkpoint, or one of another layout or made by other DEM sources."""
    state = load_checkpoint(out_dir)
    path = Path(out_dir) / CHECKPOINT
    from millfmu.dem.tables.cache import SAME_DEM_AS

    # sources that give the same results to the digit (SAME_DEM_AS) go on with the run
    made, here = state["kernel_version"], _kernel_version()
    if SAME_DEM_AS.get(made, made) != SAME_DEM_AS.get(here, here):
        raise DemRunError(f"{path}: made by other DEM sources ({made}); "
                          f"these are {here}: run the scene again")
    if threads is not None:
        state["sim"].threads = int(threads)
    if checkpoint_every_s is None:
        checkpoint_every_s = state.get("checkpoint_every_s", RESUME_CHECKPOINT_EVERY_S)
    return run_scene(state["scene"], out_dir, progress=progress, window_s=state["window_s"],
                     contacts=state["contacts"], checkpoint_every_s=checkpoint_every_s,
                     _state=state)


def run_scene(scene: DemScene, out_dir, progress: bool = True, threads: int | None = None,
              window_s: float | None = None, contacts: bool = False,
              checkpoint_every_s: float | None = None, _state: dict | None = None,
              device: str = "cpu") -> DemStats:
    """Run ``scene`` and write its outputs to ``out_dir``; returns the statistics.

    ``window_s`` [s]: also cut the recording into consecutive windows of this length (a
    whole number of sampling intervals) and write each window's zone statistics to
    ``windows.csv``, to see whether the recorded state is stationary. With the coupled
    fluid, spin-up, recording and sampling interval are rounded up to whole coupling
    intervals. ``contacts``: also write ``contacts.npz`` (:func:`write_contacts`).
    ``device``: "gpu" steps the DEM with numba.cuda (:mod:`millfmu.dem.engine.gpu`; the
    same model, results equal to the CPU's to round-off), the coupled liquid staying on
    the CPU; no checkpoints then.
    ``checkpoint_every_s`` [s of wall time]: keep ``checkpoint.pkl`` (module docstring)
    written at the first sample after each such span; :func:`resume_run` goes on from it.
    """
    from millfmu.dem.engine import kernels as K  # numba: compiled when a run is made

    out = Path(out_dir)
    _check_request(out, checkpoint_every_s, device, resuming=_state is not None)
    sim, cpl = _simulation(scene, threads, device, _state)
    if _state is None and getattr(cpl, "fused", False):
        # a short run on a cold cache: the exchange by calls, the same results to the bit
        # with two fifths less to compile (first_compile.FUSED_FROM_S)
        from millfmu.dem.first_compile import fused_exchange

        cpl.fused = fused_exchange(scene.spin_up_s + scene.record_s)
    out.mkdir(parents=True, exist_ok=True)
    unit = cpl.unit_steps if cpl is not None else 1
    n_spin = _whole_steps(scene.spin_up_s, scene.dt_s, unit)
    n_rec = _whole_steps(scene.record_s, scene.dt_s, unit, unit)
    every = _whole_steps(scene.sample_every_s, scene.dt_s, unit, unit)
    steps = (n_spin, n_spin + n_rec, every)
    loop = _state["loop"] if _state is not None else _new_loop(scene)
    events = _contact_log(out, K.EV_NF, _state, loop)
    checkpoint = None
    if checkpoint_every_s is not None:
        # the sources this run was compiled from, not those on disk at a later checkpoint
        checkpoint = dict(format=CHECKPOINT_FORMAT, kernel_version=_kernel_version(),
                          scene=scene, window_s=window_s, contacts=contacts,
                          checkpoint_every_s=checkpoint_every_s, sim=sim, cpl=cpl, loop=loop)
    wall = _record(scene, sim, cpl, out, loop, events, steps, progress, checkpoint,
                   resumed=_state is not None)
    ev_cols = dict(type=K.EV_TYPE, x=K.EV_X, y=K.EV_Y, z=K.EV_Z, setn=K.EV_SETN,
                   sets=K.EV_SETS, serot=K.EV_SEROT)
    zones = zones_for(scene)
    stats, fields, bead_fields, ev = _run_statistics(scene, zones, sim, cpl, loop, events,
                                                     steps, wall, ev_cols)
    if window_s is not None:
        _write_windows(out / "windows.csv", _window_rows(scene, zones, sim, loop, events,
                                                         steps, window_s, ev_cols))
    if contacts:
        write_contacts(out / "contacts.npz", events, [t[0] for t in loop["torques"]],
                       zones, n_spin * scene.dt_s, scene.dt_s, K.EV_TYPE,
                       [K.EV_X, K.EV_Y, K.EV_Z], K.EV_SETN, [K.EV_SETN, K.EV_SETS, K.EV_SEROT])
    _write_outputs(out, scene, sim, loop, stats, ev, ev_cols, fields, bead_fields)
    if (out / CHECKPOINT).exists():  # the outputs are written: the run needs no resuming
        (out / CHECKPOINT).unlink()
    del ev
    events.remove()
    return stats


def _check_request(out: Path, checkpoint_every_s, device: str, resuming: bool) -> None:
    """Refuse by name (DemRunError) a run that :func:`run_scene` cannot make as asked."""
    if checkpoint_every_s is not None and not checkpoint_every_s > 0.0:
        raise DemRunError(f"checkpoint_every_s = {checkpoint_every_s!r}: must be > 0 s")
    if not resuming and (out / CHECKPOINT).exists():
        # a new run would overwrite the stopped one's state at its first checkpoint
        raise DemRunError(f"{out}: holds the checkpoint of a stopped run; go on with it "
                          f"(resume_run, dem run --resume {out}) or remove "
                          f"{out / CHECKPOINT} to start afresh")
    if device not in ("cpu", "gpu"):
        raise DemRunError(f"device = {device!r}: allowed 'cpu' or 'gpu'")
    if checkpoint_every_s is not None and device != "cpu":
        raise DemRunError("checkpoints are written for runs on the CPU only (device = "
                          f"{device!r})")


def _simulation(scene: DemScene, threads, device: str, state: dict | None):
    """The DEM and its coupling (or None) of a new run, or of the checkpoint ``state``."""
    if state is None:
        try:
            return make_simulation(scene, threads, device)
        except GridError as e:  # a liquid's grid the scene's values cannot make
            raise DemRunError(f"{scene.name}: the coupled liquid's grid: {e}") from None
        except Exception as e:
            if device == "cpu":
                raise
            # no CUDA GPU or numba.cuda, a scene the GPU stepper does not model (vanes),
            # or the driver's refusal (out of device memory)
            raise DemRunError(f"{scene.name}: {e}") from None
    sim, cpl = state["sim"], state["cpl"]
    import numba

    from millfmu.dem.engine._jit import use_threads

    # a machine with fewer cores: fewer threads, the same chunks and results
    sim.threads = min(sim.threads, numba.config.NUMBA_NUM_THREADS)
    use_threads(sim.threads)
    return sim, cpl


def _whole_steps(t_s: float, dt_s: float, unit: int, at_least: int = 0) -> int:
    """DEM steps of ``t_s`` [s], rounded up to whole units of ``unit`` steps (a coupling
    interval), at least ``at_least``."""
    return max(at_least, unit * int(math.ceil(round(t_s / dt_s, 6) / unit)))


def _new_loop(scene: DemScene) -> dict:
    """What a new run has recorded (none yet), as a checkpoint keeps it."""
    return dict(
        done=0, ke_t=[], ke=[], sx=[], sv=[], torques=[],
        # accelerator slices: the contacts present at every sample, for seed 002's counting
        frames=[] if scene.kind == "accelerator_slice" else None,
        dropped=0, builds=0, fluid_acc={}, fluid_samples=0, substeps=[], budget0=None,
        wall_s=0.0)


def _contact_log(out: Path, n_cols: int, state: dict | None, loop: dict) -> ContactLog:
    """The run's recorded contacts, one chunk per sample, on disk (module docstring): a new
    log, or the one a checkpoint names (layout 1 kept the chunks in the checkpoint)."""
    if state is None:
        return ContactLog(out / CONTACT_LOG, n_cols)
    if "events" in loop:
        return ContactLog.from_chunks(out / CONTACT_LOG, n_cols, loop.pop("events"))
    try:
        return ContactLog.resume(out / CONTACT_LOG, n_cols, loop["contact_log"])
    except ContactLogError as e:
        raise DemRunError(f"cannot go on with the run: {e}") from None


def _advance(scene: DemScene, sim, cpl, k: int, record: bool) -> list:
    """``k`` steps of the DEM (and of its coupling), recording contacts with ``record``;
    the steps' statistics. A coupled run is checked every CHECK_EVERY_STEPS steps (whole
    coupling intervals, which the coupling steps one by one anyway: the same run), so that
    beads flying apart are caught before their neighbour lists take the machine's memory;
    an unstable run is refused by name (DemRunError)."""
    dt = scene.dt_s
    t0 = sim.step_count * dt
    out = []
    try:
        if cpl is None:
            out.append(sim.run(k, record=record))
        else:
            piece = cpl.unit_steps * max(1, round(CHECK_EVERY_STEPS / cpl.unit_steps))
            left = k
            while left:
                m = min(piece, left)
                out.extend(cpl.run(m, record=record))
                left -= m
                why = _instability(sim, scene) if left else None
                if why is not None:
                    break
    except MemoryError:
        # the neighbour lists of beads thrown far apart or onto each other outgrow memory
        why = _instability(sim, scene) or "the neighbour lists outgrew the memory"
        raise DemRunError(f"{scene.name}: the run became unstable between t = {t0:.4g} and "
                          f"{t0 + k * dt:.4g} s ({why}); fluid: {scene.fluid_description}; "
                          f"nothing written") from None
    why = _instability(sim, scene)
    if why is not None:
        raise DemRunError(f"{scene.name}: the run became unstable by t = "
                          f"{sim.step_count * dt:.4g} s ({why}); fluid: "
                          f"{scene.fluid_description}; nothing written")
    return out


def _record(scene: DemScene, sim, cpl, out: Path, loop: dict, events: ContactLog,
            steps: tuple, progress: bool, checkpoint: dict | None, resumed: bool) -> float:
    """Spin-up and recording from ``loop['done']`` steps on (``steps``: spin-up steps, all
    steps, steps per sample), appending the samples to ``loop`` and the contacts to
    ``events``; ``checkpoint``: what a checkpoint holds besides ``loop`` (None: no
    checkpoints). Returns the run's wall time [s]."""
    n_spin, total, every = steps
    dt = scene.dt_s
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=total, unit="step", desc=f"dem {scene.name} ({sim.n} beads)",
                   smoothing=0.1, bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} "
                   "[{elapsed}<{remaining}, {rate_fmt}]")
    ke_t, ke, sx, sv = loop["ke_t"], loop["ke"], loop["sx"], loop["sv"]
    torques, frames = loop["torques"], loop["frames"]
    dropped, builds = loop["dropped"], loop["builds"]
    fluid_acc, fluid_samples = loop["fluid_acc"], loop["fluid_samples"]
    substeps, budget0 = loop["substeps"], loop["budget0"]
    t_wall = time.perf_counter() - loop["wall_s"]
    # CPU time of all threads, for the cost of a run that was stopped or shared the machine;
    # counted from the step in cpu_from_step (a checkpoint without it: from the resume on)
    if "cpu_s" not in loop:
        loop.update(cpu_s=0.0, cpu_from_step=sim.step_count)
    t_cpu = time.process_time() - loop["cpu_s"]
    t_check = time.perf_counter()
    ckpt = out / CHECKPOINT

    def sample():
        et, er = sim.kinetic_energy_j()
        ke_t.append(sim.step_count * dt)
        ke.append(et + er)

    done = loop["done"]
    if not resumed:
        sample()
    elif bar is not None:
        bar.update(done)
    while done < total:
        recording = done >= n_spin
        if recording and budget0 is None:
            budget0 = _budget_reading(sim, cpl)
        k = min(every, (n_spin - done) if not recording else total - done)
        try:
            sts = _advance(scene, sim, cpl, k, recording)
        except DemRunError:
            if not ckpt.exists():  # nothing to resume: nothing left behind
                events.remove()
            raise
        for st in sts:
            builds += st.neighbour_builds
        if recording:
            events.append(np.concatenate([st.events for st in sts]))
            torques.append((k, sum(st.torque_sum_nm_steps for st in sts),
                            sum(st.chamber_torque_sum_nm_steps for st in sts)))
            dropped += sum(st.dropped_events for st in sts)
            sx.append(sim.x.copy())
            sv.append(sim.v.copy())
            if frames is not None:
                frames.append(snapshots.frame_of(sim))
            if cpl is not None:
                for name, a in cpl.section_fields().items():
                    fluid_acc[name] = fluid_acc.get(name, 0.0) + a
                fluid_samples += 1
                substeps.append(cpl.solver.last_substeps)
        done += k
        sample()
        if bar is not None:
            bar.update(k)
        if checkpoint is not None and done < total and \
                time.perf_counter() - t_check >= checkpoint["checkpoint_every_s"]:
            loop.update(done=done, dropped=dropped, builds=builds, fluid_acc=fluid_acc,
                        contact_log=events.state(),
                        fluid_samples=fluid_samples, budget0=budget0,
                        wall_s=time.perf_counter() - t_wall,
                        cpu_s=time.process_time() - t_cpu)
            # (step, wall s, CPU s) at every checkpoint: the recent pace for `dem progress`
            # (the mean since the start mixes in any slower or paused stretch)
            loop.setdefault("checkpoints", []).append(
                (sim.step_count, loop["wall_s"], loop["cpu_s"]))
            _write_checkpoint(ckpt, checkpoint)
            t_check = time.perf_counter()
    if bar is not None:
        bar.close()
    loop.update(done=done, dropped=dropped, builds=builds, fluid_samples=fluid_samples,
                budget0=budget0)
    return time.perf_counter() - t_wall


def _run_notes(scene: DemScene, sim) -> list:
    """The notes of a run's statistics: what was simulated and how it was counted."""
    notes = [
        "fluid: " + scene.fluid_description,
        "spin-up excluded from all statistics; samples and contacts from the recording "
        "window only",
        ("zones SEV_1-4 from seed 002 figure 4 (see millfmu.dem.mills.accelerator)"
         if scene.kind == "accelerator_slice" else
         "zones V1-V4 as read from seed 001 Figure 2 (see millfmu.dem.mills.zones)"),
        "stirrer torque and power scaled from the simulated sector to the full circle; "
        "per axial period of the cell",
    ]
    if sim.device != "cpu":
        notes.append(f"DEM stepped on the {sim.device.upper()} (numba.cuda), the liquid and "
                     f"the exchange on {sim.threads} CPU threads")
    return notes


def _chunk_stats(scene: DemScene, zones, sim, loop: dict, events: ContactLog,
                 ev_cols: dict, chunks: range, t0_s: float, counts=None) -> DemStats:
    """Statistics of the recording chunks ``chunks`` (consecutive), which start at t0_s
    [s]: their contacts a view of the log's file."""
    torques, sx, sv = loop["torques"], loop["sx"], loop["sv"]
    dt = scene.dt_s
    e = events.chunks(chunks.start, chunks.stop)
    n = sum(torques[i][0] for i in chunks)
    return compute_stats(
        scene=scene.name, zones=zones, events=e, ev_cols=ev_cols,
        sample_x=[sx[i] for i in chunks], sample_v=[sv[i] for i in chunks],
        radii_m=sim.rad, record_s=n * dt, tip_speed_m_per_s=scene.tip_speed_m_per_s,
        omega_rad_per_s=scene.omega_rad_per_s,
        torque_on_stirrer_nm=sum(torques[i][1] for i in chunks) / max(n, 1),
        ke_t_s=np.array(loop["ke_t"]), ke_j=np.array(loop["ke"]), spin_up_s=t0_s, dt_s=dt,
        filling=scene.filling, bulk_porosity=scene.bulk_porosity,
        fluid_model=scene.fluid_description, notes=_run_notes(scene, sim),
        counts=counts or {})


def _run_statistics(scene: DemScene, zones, sim, cpl, loop: dict, events: ContactLog,
                    steps: tuple, wall: float, ev_cols: dict):
    """The whole recording's statistics with their flow summary, the liquid's time-mean
    section fields (None without the coupled liquid), the beads' (None where the mill has
    none) and every recorded contact."""
    n_spin, total, every = steps
    dt = scene.dt_s
    ev = events.chunks(0, len(events))
    counts = dict(
        contacts_recorded=int(ev.shape[0]),
        bead_bead=int((ev[:, ev_cols["type"]] == 0).sum()) if ev.size else 0,
        bead_wall=int((ev[:, ev_cols["type"]] > 0).sum()) if ev.size else 0,
        dropped_contacts=int(loop["dropped"]), neighbour_builds=int(loop["builds"]),
        steps=int(total), wall_time_s=wall, threads=int(sim.threads),
        particle_steps_per_s=sim.n * total / wall)
    stats = _chunk_stats(scene, zones, sim, loop, events, ev_cols, range(len(events)),
                         n_spin * dt, counts=counts)
    fields = None
    if cpl is not None and loop["fluid_samples"]:
        fields = {k: v / loop["fluid_samples"] for k, v in loop["fluid_acc"].items()}
        fields["r_m"] = cpl.grid.r_centres_m
        fields["zeta_m"] = _zeta_of_grid(cpl.grid, scene.geometry)
    sx, sv = loop["sx"], loop["sv"]
    flow = flow_summary(scene, sim, cpl, sx, sv, loop["torques"], loop["budget0"], fields,
                        loop["substeps"])
    bead_fields = flow.pop("_bead_fields", None)
    if scene.kind == "accelerator_slice":
        flow["seed002"] = accelerator_summary(scene, sim, zones, ev, ev_cols,
                                              stats.record_s, sx, sv, fields, loop["frames"],
                                              every * dt)
    stats.flow = _finite(flow)
    return stats, fields, bead_fields, ev


def _window_rows(scene: DemScene, zones, sim, loop: dict, events: ContactLog,
                 steps: tuple, window_s: float, ev_cols: dict) -> list:
    """(start [s], end [s], statistics) of each consecutive window of ``window_s`` [s] (a
    whole number of samples) of the recording."""
    n_spin, total, every = steps
    dt = scene.dt_s
    torques = loop["torques"]
    per = max(1, int(round(window_s / (every * dt))))
    rows = []
    for w0 in range(0, len(events), per):
        chunks = range(w0, min(w0 + per, len(events)))
        t0 = (n_spin + w0 * every) * dt
        rows.append((t0, t0 + sum(torques[i][0] for i in chunks) * dt,
                     _chunk_stats(scene, zones, sim, loop, events, ev_cols, chunks, t0)))
    return rows


def _write_outputs(out: Path, scene: DemScene, sim, loop: dict, stats: DemStats, ev,
                   ev_cols: dict, fields, bead_fields) -> None:
    """stats.json, the histograms, the kinetic energy, the maps and figures, and the bead
    and liquid fields (module docstring)."""
    (out / "stats.json").write_text(stats.to_json())
    _write_histograms(out / "se_histograms.csv", stats)
    np.savetxt(out / "kinetic_energy.csv", np.column_stack([loop["ke_t"], loop["ke"]]),
               delimiter=",", header="t_s,kinetic_energy_j", comments="")
    plots.write_maps(out, scene, ev, ev_cols)
    if scene.kind == "accelerator_slice":
        plots.write_seed002_maps(out, scene, ev, ev_cols)
        plots.write_speed_profiles(out / "speed_profiles.png", stats.flow["seed002"])
    plots.write_distributions(out / "se_distributions.png", stats)
    if bead_fields is not None:
        np.savez(out / "bead_fields.npz", **bead_fields)
        # the recorded bead samples, for measures of the bead motion made later
        np.savez_compressed(out / "bead_samples.npz", x_m=np.array(loop["sx"], np.float32),
                            v_m_per_s=np.array(loop["sv"], np.float32), radii_m=sim.rad)
    if fields is not None:
        np.savez(out / "fluid_fields.npz", **fields)
        plots.write_fluid_maps(out, scene, fields)
    if "circumferential" in stats.flow:
        plots.write_circumferential(out / "circumferential.png", scene,
                                    stats.flow["circumferential"])
    if "swirl_profile_at_disc_radius" in stats.flow:
        plots.write_swirl_profile(out / "swirl_profile.png", scene,
                                  stats.flow["swirl_profile_at_disc_radius"])


def accelerator_summary(scene, sim, zones, ev, ev_cols, record_s, sx, sv, fields,
                        frames=None, frame_interval_s=None) -> dict:
    """Seed 002's quantities of an accelerator slice (plain JSON data, SI units): SI, SN_g,
    SE_cs, SE_ts,sum / SE_cs,sum per zone and in total, SE_net and the efficiency, counted
    from every contact event (at the top level) and from the contacts present at the
    samples (``snapshots``: one frame every ``frame_interval_s`` [s]; and
    ``snapshots_20_per_s``, seed 002's frame rate, where the samples are a whole fraction
    of 0.05 s apart); bead speed over tip speed against Z'/R and X'/L (figures 3 and 4);
    the rotor's pumped flow."""
    args = (scene.bead_diameter_m, scene.material.density_kg_per_m3, sim.n, scene.tip_speed_m_per_s,
            scene.omega_rad_per_s)
    out = A.stress_quantities(ev, ev_cols, zones, record_s, *args)
    if frames:
        out["snapshots"] = A.snapshot_stress_quantities(frames, frame_interval_s, zones,
                                                        *args)
        sub = snapshots.every_kth(frames, frame_interval_s, PAPER_FRAME_INTERVAL_S)
        if sub is not None:
            out["snapshots_20_per_s"] = A.snapshot_stress_quantities(sub[0], sub[1], zones,
                                                                     *args)
    out["rotor_speed_rpm"] = scene.rotor_speed_rpm
    out["radial_speed_profile"] = A.radial_speed_profile(sx, sv, scene.geometry,
                                                         scene.tip_speed_m_per_s)
    out["axial_speed_profile"] = A.axial_speed_profile(sx, sv, scene.geometry,
                                                       scene.tip_speed_m_per_s,
                                                       z_min=scene.zones.z2)
    q = A.rotor_throughflow_m3_per_s(fields, scene.geometry)
    out["rotor_throughflow_m3_per_s"] = q
    out["return_leg"] = A.return_leg(
        sx, sv, scene.geometry, scene.omega_rad_per_s, scene.bead_diameter_m,
        scene.material.density_kg_per_m3,
        scene.fluid.density_kg_per_m3 if scene.fluid is not None else 0.0, fields)
    return out


def _finite(obj):
    """Plain-JSON copy: numpy scalars as floats, non-finite numbers as None."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def _weight_note(budget: dict) -> str:
    """The weight's part of the printed budget line, where the weight has a torque."""
    w = budget.get("gravity_nms")
    if not w:
        return ""
    return f" (the beads' weight gave {w:.3g} N m s of {budget['stirrer_drive_nms']:.3g})"


def _zeta_of_grid(grid, geometry):
    return FS.fold_zeta(grid.z_centres_m, geometry.disc_z_m, geometry.height_m)


def _budget_reading(sim, cpl) -> dict:
    """Angular momenta [kg m2/s] and the fluid's wall impulses [N m s] at this instant."""
    r = dict(beads=bead_angular_momentum_kgm2_s(sim), fluid=0.0, shaft=0.0, rotor_cells=0.0,
             stator=0.0)
    if cpl is not None:
        r["fluid"] = cpl.solver.angular_momentum_kgm2_s()
        r.update(cpl.angular_impulses_nms())
        r["gravity"] = cpl.gravity_angular_impulse_nms
    return r


def flow_summary(scene, sim, cpl, sx, sv, torques, budget0, fields, substeps) -> dict:
    """Mean-flow structure of the recording (plain JSON data; SI units, full circle per
    axial period where a torque or power is given)."""
    g = scene.geometry
    frac = g.sector_fraction
    n_steps = sum(t[0] for t in torques)
    t_rec = n_steps * scene.dt_s
    om = scene.omega_rad_per_s
    out = {"fluid_mode": scene.fluid_mode}
    # torques the beads exert on stirrer and chamber (mean over the recording, sector)
    tb_rot = sum(t[1] for t in torques) / max(n_steps, 1)
    tb_sta = sum(t[2] for t in torques) / max(n_steps, 1)
    torque = {"stirrer_bead_contacts_nm": -tb_rot / frac,
              "chamber_bead_contacts_nm": tb_sta / frac}
    b1 = _budget_reading(sim, cpl)
    if cpl is not None and budget0 is not None and t_rec > 0:
        out.update(_coupled_flow(scene, cpl, torque, tb_rot, tb_sta, budget0, b1, t_rec,
                                 fields, substeps))
    out["power_w"] = {k.replace("_nm", "_w"): v * om for k, v in torque.items()}
    out["torque"] = torque
    # a full slice with gravity across the axis: where the beads sit round the circle, time
    # mean over the recording's samples (seed 001's asymmetry, seed 002's figure 8)
    circ = circumferential(sx, scene.gravity_m_per_s2, g.sector_deg)
    if circ:
        out["circumferential"] = circ
    if not g.has_disc:
        return out
    if g.has_channel:
        # the accelerator rotor: the disc's layer, vortex census and gap profile do not
        # apply; its bead fields (section maps) are written as for a disc slice
        out["_bead_fields"] = _section_bead_fields(scene, sim, cpl, sx, sv, fields)
        return out
    out.update(_disc_flow(scene, sim, cpl, sx, sv, fields))
    return out


def _coupled_flow(scene, cpl, torque: dict, tb_rot: float, tb_sta: float, budget0: dict,
                  b1: dict, t_rec: float, fields, substeps) -> dict:
    """The coupled liquid's part of :func:`flow_summary`: its shear torques (added to
    ``torque``), the angular-momentum budget of the simulated sector between the readings
    budget0 and b1 (:func:`_budget_reading`), the power number and the liquid's numbers.
    tb_rot, tb_sta [N m]: the beads' mean torques on stirrer and chamber (sector); t_rec [s]
    the recording's length."""
    g = scene.geometry
    frac = g.sector_fraction
    om = scene.omega_rad_per_s
    out = {}
    jf_rot = (b1["shaft"] - budget0["shaft"]) + (b1["rotor_cells"] - budget0["rotor_cells"])
    jf_sta = b1["stator"] - budget0["stator"]
    torque["stirrer_fluid_shear_nm"] = -jf_rot / t_rec / frac
    torque["chamber_fluid_shear_nm"] = jf_sta / t_rec / frac
    torque["stirrer_total_nm"] = torque["stirrer_fluid_shear_nm"] + \
        torque["stirrer_bead_contacts_nm"]
    drive = -(jf_rot + tb_rot * t_rec)
    walls = jf_sta + tb_sta * t_rec
    change = (b1["fluid"] - budget0["fluid"]) + (b1["beads"] - budget0["beads"])
    # the beads' weight about the axis (gravity across the axis of a full slice); a
    # checkpoint that did not integrate it gives NaN: left out
    weight = b1.get("gravity", math.nan) - budget0.get("gravity", math.nan)
    known = math.isfinite(weight)
    scale = max(abs(drive), abs(walls), abs(change), abs(weight) if known else 0.0,
                1e-300)
    out["angular_momentum_budget"] = dict(
        note="simulated sector over the recording [N m s, kg m2/s]: stirrer drive + "
             "angular impulse of the beads' buoyancy-reduced weight = change of fluid "
             "+ bead angular momentum + impulse taken by the chamber wall",
        stirrer_drive_nms=drive, gravity_nms=weight if known else None,
        chamber_nms=walls,
        change_fluid=b1["fluid"] - budget0["fluid"],
        change_beads=b1["beads"] - budget0["beads"],
        closure_rel=(drive + (weight if known else 0.0) - change - walls) / scale)
    rho = scene.fluid.density_kg_per_m3
    n_rev = om / (2.0 * math.pi)
    p_tot = torque["stirrer_total_nm"] * om
    d_disc = 2.0 * (g.disc_radius_m if g.has_disc else g.shaft_radius_m)
    out["power_number"] = dict(
        value=p_tot / (rho * n_rev ** 3 * d_disc ** 5),
        definition="Ne = P / (rho_liquid n^3 d^5): P the stirrer power of one axial "
                   "period (fluid shear + bead contacts), n [1/s] the stirrer speed, "
                   "d the disc (annulus: shaft) diameter")
    sub = np.asarray(substeps, float)
    out["fluid"] = dict(
        model=scene.fluid_description, grid=cpl.grid.describe(),
        coupling_interval_s=cpl.interval_s,
        cfd_substeps_per_interval=float(sub.mean()) if sub.size else None,
        cfd_dt_s=cpl.interval_s / float(sub.mean()) if sub.size else None,
        void_fraction_min=float(np.nanmin(fields["eps"])) if fields else None,
        void_fraction_mean=float(np.nanmean(fields["eps"])) if fields else None,
        clipped_cells_last=int(cpl.clipped_cells),
        turbulent_viscosity_max_m2_per_s=float(np.nanmax(fields["nu_t"])) if fields else None)
    return out


def _disc_flow(scene, sim, cpl, sx, sv, fields) -> dict:
    """A disc slice's part of :func:`flow_summary`: the first bead layer's angular
    velocity, the section's bead fields (``_bead_fields``), the vortices of the beads' and
    the liquid's mean flow and the swirl profiles across the gap at the disc radius."""
    g = scene.geometry
    om = scene.omega_rad_per_s
    out = {}
    d = scene.bead_diameter_m
    # seed 001's first layer (FS.FIRST_LAYER_DIAMETERS); also the layer one bead diameter thick
    ratio, n = FS.first_layer_angular_velocity(sx, sv, g, om, FS.FIRST_LAYER_DIAMETERS * d)
    out["first_bead_layer_angular_velocity_ratio"] = ratio
    out["first_bead_layer_samples"] = n
    out["bead_layer_1d_angular_velocity_ratio"] = FS.first_layer_angular_velocity(
        sx, sv, g, om, d)[0]
    # bead fields on the fluid's section grid (or a 0.75 mm grid without fluid)
    out["_bead_fields"] = beads = _section_bead_fields(scene, sim, cpl, sx, sv, fields)
    r_edges = beads["r_edges_m"]
    zs = beads["zeta_centres_m"]
    order = np.argsort(fields["zeta_m"]) if fields is not None else None
    r_c = 0.5 * (r_edges[1:] + r_edges[:-1])
    dr = np.diff(r_edges)
    hb = 0.5 * g.disc_thickness_m
    psi_b = FS.stream_function(r_c, beads["flux_z"], dr)
    top = hb + scene.zones.v1_width_m
    out["vortices_beads"] = FS.vortex_summary(FS.vortices(
        psi_b, r_c, zs, g.disc_radius_m, hb, valid=beads["samples"] > 0, threshold=0.05,
        tip_zone_top_m=top))
    # profiles at the disc radius across the gap, x/D from one disc face to the next
    i_r = int(np.argmin(np.abs(r_c - g.disc_radius_m)))
    gap = g.height_m - g.disc_thickness_m
    x = np.where(zs >= hb, zs - hb, zs + g.height_m - hb)
    in_gap = (np.abs(zs) >= hb)
    o = np.argsort(x[in_gap])
    prof = dict(r_m=float(r_c[i_r]), x_over_gap=list((x[in_gap][o] / gap).round(6)),
                beads_speed_over_v_tip=_speed(beads, i_r, in_gap, o, scene.tip_speed_m_per_s))
    if fields is not None:
        f = {k: v[:, order] for k, v in fields.items() if np.ndim(v) == 2}
        psi_f = FS.stream_function(r_c, np.nan_to_num(f["flux_z"]), dr)
        out["vortices_fluid"] = FS.vortex_summary(FS.vortices(
            psi_f, r_c, zs, g.disc_radius_m, hb, valid=np.isfinite(f["eps"]),
            tip_zone_top_m=top))
        prof["fluid_speed_over_v_tip"] = _speed(f, i_r, in_gap, o, scene.tip_speed_m_per_s)
        prof["fluid_u_theta_over_v_tip"] = list(np.round(
            f["u_theta"][i_r, in_gap][o] / scene.tip_speed_m_per_s, 6))
    out["swirl_profile_at_disc_radius"] = prof
    return out


def _section_bead_fields(scene, sim, cpl, sx, sv, fields) -> dict:
    """Time-mean bead fields of the axial section on the fluid's bins (or 0.75 mm)."""
    g = scene.geometry
    if fields is not None:
        r_edges = cpl.grid.r_faces_m
        zeta_c = fields["zeta_m"]
    else:
        gr = mill_grid(g, 0.75e-3)
        r_edges = gr.r_faces_m
        zeta_c = _zeta_of_grid(gr, g)
    zs = np.sort(zeta_c)
    dz = float(np.diff(zs).mean())
    z_edges = np.concatenate([zs - 0.5 * dz, [zs[-1] + 0.5 * dz]])
    beads = FS.bead_section_fields(sx, sv, sim.rad, g, r_edges, z_edges)
    return dict(beads, r_edges_m=r_edges, zeta_edges_m=z_edges, zeta_centres_m=zs)


def _speed(f, i_r, sel, order, v_tip):
    sp = np.sqrt(f["u_r"] ** 2 + f["u_theta"] ** 2 + f["u_z"] ** 2)[i_r, sel][order]
    return [None if not np.isfinite(v) else round(float(v / v_tip), 6) for v in sp]


def _write_windows(path: Path, rows):
    """Per-window zone statistics: one line per window and zone."""
    lines = ["t_start_s,t_end_s,zone,filling,speed_over_tip_speed,collision_frequency_per_m3_s,"
             "se_tn_q50_j,se_tn_q90_j,collision_power_w"]
    for t0, t1, st in rows:
        for z in st.zones:
            q = z.se["tn"].quantiles_j
            lines.append(",".join([f"{t0:.9g}", f"{t1:.9g}", z.name] + [
                f"{v:.12g}" if v is not None else "nan" for v in (
                    z.filling, z.speed_over_tip_speed, z.collision_frequency_per_m3_s,
                    q["q50"], q["q90"], z.collision_power_w)]))
    path.write_text("\n".join(lines) + "\n")


def write_contacts(path: Path, events, chunk_steps, zones, t0_s: float, dt_s: float,
                   c_type: int, c_xyz, c_setn: int, c_setotal) -> None:
    """Bead-bead contacts of the recording, per recording chunk (one sampling interval):
    ``zone`` (index into ``zone_names``, -1 outside every zone), ``chunk`` (index of the
    chunk), ``se_tn_j`` and ``se_total_j`` [J] (as in :mod:`millfmu.dem.analysis.stats`);
    ``chunk_start_s`` and ``chunk_s`` [s] per chunk; ``zone_names``, ``zone_volumes_m3``.
    ``events``: the recorded contact rows per chunk; ``chunk_steps``: DEM steps per chunk."""
    zone, chunk, setn, setot = [], [], [], []
    for i, e in enumerate(events):
        bb = e[e[:, c_type] == 0] if e.size else e
        zone.append(zones.classify(bb[:, c_xyz]).astype(np.int8) if bb.size else
                    np.zeros(0, np.int8))
        chunk.append(np.full(bb.shape[0], i, np.int32))
        setn.append(bb[:, c_setn] if bb.size else np.zeros(0))
        setot.append(bb[:, c_setotal].sum(axis=1) if bb.size else np.zeros(0))
    steps = np.asarray(chunk_steps, np.int64)
    starts = t0_s + np.concatenate([[0], np.cumsum(steps)[:-1]]) * dt_s if steps.size else \
        np.zeros(0)
    cat = (lambda a, dt: np.concatenate(a) if a else np.zeros(0, dt))
    np.savez_compressed(path, zone=cat(zone, np.int8), chunk=cat(chunk, np.int32),
                        se_tn_j=cat(setn, float), se_total_j=cat(setot, float),
                        chunk_start_s=starts, chunk_s=steps * dt_s,
                        zone_names=np.array(zones.names), zone_volumes_m3=zones.volumes_m3())


def _write_histograms(path: Path, stats: DemStats):
    e = np.asarray(stats.se_bin_edges_j)
    cols = [e[:-1], e[1:]]
    names = ["se_lo_j", "se_hi_j"]
    for z in stats.zones:
        for c, dist in z.se.items():
            cols.append(np.asarray(dist.density_per_decade))
            names.append(f"{z.name}_{c}_per_decade")
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=",".join(names),
               comments="")


def summary_table(stats: DemStats) -> str:
    """Plain-text zone table: filling, speed/tip speed, collision frequency, median SE_tn."""
    lines = [f"{'zone':8s} {'volume m3':>10s} {'filling':>8s} {'v/v_tip':>8s} "
             f"{'f_c 1/(m3 s)':>13s} {'med SE_tn J':>12s} {'P_c W':>10s}"]
    for z in stats.zones:
        q = z.se["tn"].quantiles_j["q50"]
        lines.append(f"{z.name:8s} {z.volume_m3:10.3e} {z.filling:8.3f} "
                     f"{z.speed_over_tip_speed:8.4f} {z.collision_frequency_per_m3_s:13.3e} "
                     f"{(q if q is not None else float('nan')):12.3e} "
                     f"{z.collision_power_w:10.3e}")
    lines.append(f"stirrer torque from bead contacts {stats.stirrer_torque_nm:.4g} N m, power "
                 f"{stats.stirrer_power_w:.4g} W; kinetic energy "
                 f"{json.dumps(stats.kinetic_energy)}")
    fl = stats.flow or {}
    t = fl.get("torque", {})
    if "stirrer_fluid_shear_nm" in t:
        lines.append(f"coupled fluid: stirrer torque {t['stirrer_total_nm']:.4g} N m (fluid "
                     f"shear {t['stirrer_fluid_shear_nm']:.4g}, bead contacts "
                     f"{t['stirrer_bead_contacts_nm']:.4g}), power number "
                     f"{fl['power_number']['value']:.4g}; angular momentum budget closes to "
                     f"{fl['angular_momentum_budget']['closure_rel']:.1e}"
                     f"{_weight_note(fl['angular_momentum_budget'])}; CFD step "
                     f"{fl['fluid']['cfd_dt_s']:.3g} s, grid {fl['fluid']['grid']['n_r']} x "
                     f"{fl['fluid']['grid']['n_theta']} x {fl['fluid']['grid']['n_z']}")
    if fl.get("circumferential"):
        lines.append(circumferential_line(fl["circumferential"]))
    a = fl.get("seed002")
    if a:
        lines.append(f"seed 002 ({a['rotor_speed_rpm']:.0f} rpm): " + "; ".join(
            f"{k} SN_g {z['SN_g_per_m3_s']:.3g} 1/(m3 s), SI "
            f"{(z['SI_j'] if z['SI_j'] is not None else float('nan')):.3g} J, SE_ts share "
            f"{(z['ts_share'] if z['ts_share'] is not None else float('nan')):.3f}"
            for k, z in a["zones"].items()))
        t = a["total"]
        lines.append(f"SE_cs,sum {t['SE_cs_sum_w']:.4g} W, SE_ts,sum / SE_cs,sum "
                     f"{(t['ts_share'] or float('nan')):.3f}, SE_net {t['SE_net_w']:.4g} W, "
                     f"efficiency {(t['efficiency'] or float('nan')):.3%}; rotor pumps "
                     f"{(a['rotor_throughflow_m3_per_s'] or float('nan')) * 6e4:.4g} L/min")
        rl = a.get("return_leg") or {}
        if rl.get("k_beads") is not None:
            kl = rl["k_liquid"] if rl["k_liquid"] is not None else float("nan")
            lines.append(
                f"return leg (between the rotors): beads swirl at k = {rl['k_beads']:.3f} of "
                f"the rotor, liquid at {kl:.3f}; "
                f"solids fraction {rl['solids_fraction']:.3f}; "
                + (f"weight over rotor head R = {rl['R']:.3g} (a bead circulation needs R < 1, "
                   f"i.e. k < {(rl['k_for_R_1'] or float('nan')):.3f})" if rl["R"] is not None
                   else "weight over rotor head R: none without a liquid"))
    if fl.get("first_bead_layer_angular_velocity_ratio") is not None:
        vf = fl.get("vortices_fluid")
        lines.append("first bead layer at the disc: angular velocity "
                     f"{fl['first_bead_layer_angular_velocity_ratio']:.3f} of the disc's; "
                     "vortices of the mean flow (between discs / disc tip to wall): beads "
                     f"{fl['vortices_beads']['between_discs']} / "
                     f"{fl['vortices_beads']['disc_tip_to_wall']}" +
                     (f", fluid {vf['between_discs']} / {vf['disc_tip_to_wall']}" if vf else ""))
    return "\n".join(lines)

