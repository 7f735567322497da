"""Warm starts of DEM table points: a point run by the table builder keeps its settled
state beside its stored result, and a new point with the same beads starts from the
nearest such state with a short spin-up instead of a fresh bed and the full spin-up.

*The settled state* (:func:`capture`, :func:`save_state`, :func:`read_state`): what a run
needs to go on from the end of a point's run, as a compressed npz of arrays
(``<point store>/<key>.state.npz``, :func:`state_file`), versioned (:data:`STATE_FORMAT`)
and named by the DEM kernel version that made it (a state of another version is not used):

- the beads' positions [m] (float64), velocities [m/s] and spins [rad/s] (float32);
- with the coupled liquid (:class:`~millfmu.dem.coupling.cfd_dem.CfdDem`): the liquid's
  velocities, pressure, k, epsilon, turbulent viscosity and void fractions on its grid, and
  per bead the liquid's velocity and pressure gradient at the bead (float32).

Not kept: the tangential springs of the contacts and the walls' histories (the new run
starts them at zero, as at any start; a spring lives for one contact, microseconds, against
a spin-up of tenths of a second), the neighbour lists (rebuilt) and the held fluid forces
(computed at the first exchange). For the coupled table's 6,536 beads of 0.8 mm the file
holds about 0.5 MB.

*The warm start* (:func:`pick_start`, :func:`warm_simulation`, :func:`run_point`): a
point whose scene equals a stored point's except in tip speed, bead density and liquid
viscosity (:data:`WARM_AXES`; so the same bead count, diameter and filling) starts from the
nearest such state (distance: the root sum of squares of the log ratios of those values)
within the range warm starts were measured in (:data:`WARM_RANGE`), with the beads'
velocities and spins and the liquid's velocities scaled by the ratio of the tip speeds (its
pressure and k by the square, epsilon by the cube, the turbulent viscosity by the ratio),
then runs the shorter spin-up ``warm_spin_up_s`` and the table's recording. Other points
start cold, from a fresh bed, with the scene's spin-up; one whose states with the same beads
all lie beyond the range says so on stderr. The point's result records how it started
(``start``: :func:`cold_record`, with ``why_cold`` where the range kept it cold;
:func:`warm_record`). Besides the
states in a build's point store, the package ships the coupled table's anchor state
(:func:`shipped_states`), so that a fresh install's first new point can start warm.

The DEM's own sources (:data:`~.cache.KERNEL_MODULES`) are not changed: a run goes through
:func:`millfmu.dem.run.run_scene`'s resume path with simulation objects made here, which
for a cold start are those :func:`~millfmu.dem.run.make_simulation` makes (the same run to
the bit as ``run_scene`` alone).
"""

from __future__ import annotations

import functools
import io
import json
import math
import sys
from pathlib import Path

import numpy as np

from ...stress_tables.files import canonical_json, sha256_bytes, write_replacing
from ...stress_tables.spec import AXES
from .state_files import (_UNREADABLE, STATE_FORMAT, STATE_SUFFIX, WarmStartError,
                          read_meta)

#: Table axes in which a warm-started point may differ from the state it starts from: the
#: tip speed, the beads' density and the liquid's viscosity, which leave the bead count
#: (diameter, filling, cell) as it is.
WARM_AXES = ("tip_speed_m_per_s", "bead_density_kg_per_m3", "viscosity_Pa_s")
#: their scene keys (section, key)
WARM_KEYS = tuple(AXES[a][:2] for a in WARM_AXES)
#: Spin-up [s] of a warm-started point of a DEM table (docs/tables.md: warm starts, the
#: measurement that chose it).
WARM_SPIN_UP_S = 0.2
#: How far a warm start may jump: per axis of :data:`WARM_AXES`, the (lowest, highest) ratio
#: of the point's value to that of the state it starts from, the range that ``python -m
#: validation.warm_start`` measured (docs/tables.md, "How short a warm start's spin-up may
#: be"; each within the stated error of cold starts with the 0.2 s spin-up):
#:
#: - tip speed 1 to 1.2: the 12 m/s glass node from the 10 m/s anchor's state (``--tip-speed
#:   12 --bead-density 2510``: 0.56 of the stated error, its cold run 0.52); a slower point
#:   from a faster state was not measured;
#: - bead density 1 to 7,800 / 2,510 (3.11): steel from the glass anchor's state (the default
#:   run: 0.58) and from zirconia's, 6,040 kg/m3 (``--anchor-density 6040``: 1.29, 0.81);
#:   lighter beads from a heavier state were not measured;
#: - viscosity 1 to 1: never varied in a warm start, so only the state's own viscosity.
#:
#: Each jump was measured alone: a state whose ratios all lie in range is used for a point
#: that differs on several axes at once, which the study did not run.
WARM_RANGE = {"tip_speed_m_per_s": (1.0, 1.2),
              "bead_density_kg_per_m3": (1.0, 7800.0 / 2510.0),
              "viscosity_Pa_s": (1.0, 1.0)}
#: relative round-off allowed at the ends of :data:`WARM_RANGE`
_RANGE_RTOL = 1e-9

_BEADS = ("x_m", "v_m_per_s", "w_rad_per_s")
#: the coupled liquid's solver fields kept, and the power of the tip-speed ratio that scales
#: each on a warm start
_LIQUID = {"ur": 1, "ut": 1, "uz": 1, "p": 2, "k": 2, "e": 3, "nu_t": 1,
           "eps_c": 0, "eps_c_old": 0, "eps_r": 0, "eps_t": 0, "eps_z": 0}


# ---- the state -----------------------------------------------------------------------------
def capture(sim, cpl) -> dict | None:
    """The settled state of a run's simulation ``sim`` and coupling ``cpl`` (None without
    the liquid) as arrays (module docstring), or None where it cannot be kept (a coupling
    other than :class:`~millfmu.dem.coupling.cfd_dem.CfdDem`, the DEM on a GPU)."""
    if getattr(sim, "device", "cpu") != "cpu":
        return None
    out = {"x_m": np.array(sim.x, np.float64),
           "v_m_per_s": np.array(sim.v, np.float32),
           "w_rad_per_s": np.array(sim.w, np.float32)}
    if cpl is None:
        return out
    from millfmu.dem.coupling.cfd_dem import CfdDem

    if type(cpl) is not CfdDem:
        return None
    s = cpl.solver
    for k in _LIQUID:
        out["liquid_" + k] = np.array(getattr(s, k), np.float32)
    out["fluid_at_bead"] = np.array(sim.per_bead["fluid_at_bead"], np.float32)
    return out


def state_key(scene_at_point: dict, kernel_version: str) -> str:
    """The name of a point's state: sha256 over the state layout, the DEM kernel version and
    the scene at the point (as the point store names its result)."""
    content = {"format": STATE_FORMAT, "kernel_version": kernel_version, "scene": scene_at_point}
    return sha256_bytes(canonical_json(content).encode())


def state_file(folder, scene_at_point: dict, kernel_version: str) -> Path:
    return Path(folder) / (state_key(scene_at_point, kernel_version) + STATE_SUFFIX)


def save_state(path, arrays: dict, meta: dict) -> Path:
    """Write ``arrays`` and ``meta`` (JSON: the scene at the point, the kernel version, how
    the point started) compressed to ``path``, atomically (as the point store writes a
    result: :func:`~millfmu.stress_tables.files.write_replacing`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    np.savez_compressed(buf, meta=np.array(canonical_json(dict(meta, format=STATE_FORMAT))), **arrays)
    write_replacing(path, buf.getvalue(), prefix=".tmp-state-")
    return path


def read_state(path, kernel_version: str | None = None) -> tuple[dict, dict]:
    """(arrays, meta) of a state file; WarmStartError where it cannot be read, has another
    layout or (``kernel_version`` given) was made by another DEM kernel version."""
    meta = read_meta(path)
    if kernel_version is not None and meta.get("kernel_version") != kernel_version:
        raise WarmStartError(f"{path}: made by DEM kernel version {meta.get('kernel_version')}, "
                             f"the installed DEM is {kernel_version}")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files if k != "meta"}
    except _UNREADABLE as e:
        raise WarmStartError(f"{path}: not a readable state ({type(e).__name__}: {e})") from None
    missing = [k for k in _BEADS if k not in arrays]
    if missing:
        raise WarmStartError(f"{path}: no {', '.join(missing)}")
    return arrays, meta


def scaled(arrays: dict, ratio: float) -> dict:
    """The state with its velocities scaled by ``ratio`` (the new tip speed over the
    state's): bead velocities and spins, the liquid's velocities and turbulent viscosity by
    the ratio, its pressure and k by its square, epsilon by its cube, the liquid's velocity
    at each bead by the ratio and the pressure gradient there by its square; positions and
    void fractions as they are. Float64 copies."""
    r = float(ratio)
    out = {}
    for k, a in arrays.items():
        a = np.array(a, np.float64)
        if k in ("v_m_per_s", "w_rad_per_s"):
            a *= r
        elif k.startswith("liquid_"):
            a *= r ** _LIQUID[k[len("liquid_"):]]
        elif k == "fluid_at_bead":
            a[:, 0:3] *= r
            a[:, 3:6] *= r * r
        out[k] = a
    return out


# ---- which state a point starts from -------------------------------------------------------
def _value(scene: dict, sec: str, key: str):
    return (scene.get(sec) or {}).get(key)


def _without_warm_keys(scene: dict) -> dict:
    d = json.loads(canonical_json(scene))
    for sec, key in WARM_KEYS:
        (d.get(sec) or {}).pop(key, None)
    return d


def compatible(scene: dict, other: dict) -> bool:
    """Whether a point of ``scene`` (a scene dict at the point) may start from a state of a
    point of ``other``: the same scene except in :data:`WARM_KEYS` (so the same beads, cell
    and settings), and those values positive in both."""
    for sec, key in WARM_KEYS:
        for s in (scene, other):
            v = _value(s, sec, key)
            if v is not None and not (isinstance(v, (int, float)) and v > 0):
                return False
    return _without_warm_keys(scene) == _without_warm_keys(other)


def distance(scene: dict, other: dict) -> float:
    """Root sum of squares of ln(value / other's value) over :data:`WARM_KEYS` (a key
    neither scene names adds nothing)."""
    s = 0.0
    for sec, key in WARM_KEYS:
        a, b = _value(scene, sec, key), _value(other, sec, key)
        if a is None and b is None:
            continue
        if a is None or b is None:
            return math.inf
        s += math.log(float(a) / float(b)) ** 2
    return math.sqrt(s)


def beyond_range(scene: dict, other: dict, within: dict | None = None) -> str | None:
    """Why a point of ``scene`` may not start warm from a state of a point of ``other`` (a
    :func:`compatible` scene): the axes whose ratio (the point's value over the state's)
    lies outside ``within`` (default :data:`WARM_RANGE`), each named with its ratio and the
    range allowed; None where every ratio lies inside."""
    within = WARM_RANGE if within is None else within
    out = []
    for ax, (sec, key) in zip(WARM_AXES, WARM_KEYS):
        if ax not in within:
            continue
        a, b = _value(scene, sec, key), _value(other, sec, key)
        if a is None or b is None:
            continue
        lo, hi = within[ax]
        r = float(a) / float(b)
        if not lo * (1.0 - _RANGE_RTOL) <= r <= hi * (1.0 + _RANGE_RTOL):
            allowed = f"{lo:.3g}" if lo == hi else f"{lo:.3g} to {hi:.3g}"
            out.append(f"{ax} {float(a):g} against the state's {float(b):g} (ratio {r:.3g}; "
                       f"warm starts measured for {allowed})")
    return "; ".join(out) or None


def pick_start(scene: dict, candidates, kernel_version: str, within: dict | None = WARM_RANGE) -> tuple:
    """How a point of ``scene`` (a scene dict at the point) starts: (pick, why). ``pick``:
    the state it starts from, (path, meta), among ``candidates`` ((path, meta) pairs, as
    :func:`candidates_in` gives them) those of ``kernel_version`` whose scene is
    :func:`compatible` and whose ratios lie within ``within`` (default :data:`WARM_RANGE`;
    None: any), the nearest (:func:`distance`; on a tie the first by file name); None where
    there is none (a cold start). ``why``: where it starts cold although a compatible state
    is at hand, the nearest such state's values and why it lies beyond the range
    (:func:`beyond_range`), else None. A state of the point itself is not used (its run
    would repeat what is stored)."""
    best, capped = None, None
    for path, meta in sorted(candidates, key=lambda c: Path(c[0]).name):
        other = meta.get("scene")
        if meta.get("kernel_version") != kernel_version or not isinstance(other, dict):
            continue
        if not compatible(scene, other) or canonical_json(other) == canonical_json(scene):
            continue
        d = distance(scene, other)
        if not math.isfinite(d):
            continue
        why = beyond_range(scene, other, within) if within is not None else None
        # (equal up to round-off counts as a tie: ln(10/8) and ln(12.5/10))
        if why is not None:
            if capped is None or d < capped[0] - 1e-9:
                capped = (d, why)
        elif best is None or d < best[0] - 1e-9:
            best = (d, path, meta)
    if best is not None:
        return (best[1], best[2]), None
    if capped is not None:
        return None, f"the nearest stored state with the same beads is too far: {capped[1]}"
    return None, None


def choose_anchor(scene: dict, candidates, kernel_version: str, within: dict | None = WARM_RANGE) -> tuple | None:
    """The state a point of ``scene`` starts from, (path, meta), or None (a cold start):
    :func:`pick_start`'s pick."""
    return pick_start(scene, candidates, kernel_version, within)[0]


def candidates_in(folder, names=None) -> list:
    """(path, meta) of the readable states in ``folder`` (``names``: only these file
    names, e.g. the states there when a build started)."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    paths = sorted(folder.glob("*" + STATE_SUFFIX)) if names is None else \
        [folder / n for n in sorted(names)]
    out = []
    for p in paths:
        try:
            out.append((p, read_meta(p)))
        except WarmStartError:
            continue
    return out


def shipped_states() -> list[Path]:
    """The settled states shipped with the package (``millfmu/data/*.state.npz``: the
    coupled table's anchor), so that the first new point of a fresh install can start warm."""
    from importlib import resources

    root = Path(str(resources.files("millfmu") / "data"))
    return sorted(root.glob("*" + STATE_SUFFIX))


@functools.lru_cache(maxsize=32)
def _candidates(folder: str | None, names: tuple) -> tuple:
    found = candidates_in(folder, names) if folder is not None and names else []
    for p in shipped_states():
        found += candidates_in(p.parent, [p.name])
    return tuple(found)


def warm_candidates(folder, names) -> list:
    """What a build may start its points from: the states ``names`` in ``folder`` (those
    there when it began) and the shipped ones (:func:`shipped_states`), as (path, meta);
    none where ``names`` is None (every point cold). Read once per folder and names."""
    if names is None:
        return []
    return list(_candidates(None if folder is None else str(folder), tuple(names)))


def start_of(scene_at_point: dict, folder, names, kernel_version: str | None = None) -> tuple[str, str | None]:
    """How a point of ``scene_at_point`` would start from :func:`warm_candidates` (for its
    cost estimate and the line that says it): ("warm", None), or ("cold", why) with
    :func:`pick_start`'s why (None where no stored state has the same beads)."""
    cands = warm_candidates(folder, names)
    if not cands:
        return "cold", None
    if kernel_version is None:
        from .cache import dem_kernel_version

        kernel_version = dem_kernel_version()
    pick, why = pick_start(scene_at_point, cands, kernel_version)
    return ("warm", None) if pick is not None else ("cold", why)


def starts_warm(scene_at_point: dict, folder, names, kernel_version: str | None = None) -> bool:
    """Whether a point of ``scene_at_point`` would start warm (:func:`start_of`)."""
    return start_of(scene_at_point, folder, names, kernel_version)[0] == "warm"


# ---- running a point -----------------------------------------------------------------------
def cold_record(scene, why: str | None = None) -> dict:
    """How a point started cold: a fresh bed and the scene's spin-up [s]; ``why``: why not
    warm, where a state with the same beads was at hand (:func:`pick_start`)."""
    out = {"start": "cold", "spin_up_s": float(scene.spin_up_s)}
    if why is not None:
        out["why_cold"] = why
    return out


def _warm_values(scene: dict) -> dict:
    """The :data:`WARM_AXES` values a scene dict names."""
    return {ax: v for ax, (sec, key) in zip(WARM_AXES, WARM_KEYS) if (v := _value(scene, sec, key)) is not None}


def warm_record(meta: dict, path, spin_up_s: float, ratio: float) -> dict:
    """How a point started warm: from the state of the point whose :data:`WARM_AXES`
    values ``from`` names (file ``state``), spin-up ``spin_up_s`` [s], velocities scaled by
    ``speed_scale``."""
    frm = _warm_values(meta.get("scene") or {})
    return {"start": "warm", "from": frm, "state": Path(path).name, "spin_up_s": float(spin_up_s),
            "speed_scale": float(ratio)}


def warm_simulation(scene, arrays: dict, threads: int | None = None):
    """The DEM of ``scene`` (and its :class:`~millfmu.dem.coupling.cfd_dem.CfdDem` where the
    liquid is coupled, else None) started from the state ``arrays`` (already scaled: see
    :func:`scaled`): beads placed at the state's positions with its velocities and spins
    (neighbour lists, forces and sorting made as for any new simulation), the liquid made as
    :func:`~millfmu.dem.run.make_simulation` makes it and then given the state's fields.
    WarmStartError where the state does not fit the scene (bead count, liquid grid)."""
    from millfmu.dem.engine.sim import DemSimulation
    from millfmu.dem.mills.geometry import bead_count_for_filling

    x = np.asarray(arrays["x_m"], np.float64)
    n = bead_count_for_filling(scene.geometry, scene.filling, scene.bead_diameter_m,
                               scene.bulk_porosity) if scene.placement == "filling" else len(x)
    if n != len(x):
        raise WarmStartError(f"the state holds {len(x)} beads, the scene places {n}")
    sim = DemSimulation(scene.geometry, scene.material, x, 0.5 * scene.bead_diameter_m,
                        scene.omega_rad_per_s, scene.dt_s, gravity_m_per_s2=scene.gravity_m_per_s2,
                        fluid=scene.fluid, threads=threads, velocities_m_per_s=arrays["v_m_per_s"],
                        spins_rad_per_s=arrays["w_rad_per_s"])
    if scene.fluid_mode != "coupled":
        return sim, None
    c = scene.coupling
    if c.scheme == "dpm" or "liquid_ur" not in arrays:
        raise WarmStartError("the state holds no coupled liquid of this scene's kind "
                             f"(scheme {c.scheme!r})")
    from millfmu.dem.coupling.cfd_dem import CfdDem
    from millfmu.dem.fluid.grid import mill_grid
    from millfmu.dem.fluid.solver import FluidProperties

    grid = mill_grid(scene.geometry, c.cell_m, n_theta=c.n_theta)
    cpl = CfdDem(sim, grid, FluidProperties(scene.fluid.density_kg_per_m3, scene.fluid.viscosity_Pa_s),
                 c, scene.omega_rad_per_s)
    s = cpl.solver
    for k in _LIQUID:
        a = arrays["liquid_" + k]
        dst = getattr(s, k)
        if a.shape != dst.shape:
            raise WarmStartError(f"the state's liquid field {k} is {a.shape}, the scene's grid {dst.shape}")
        dst[:] = a  # in place: the solver's kernels hold these arrays
    # the bead rows as the new simulation sorted them (ids: row -> the state's row)
    sim.per_bead["fluid_at_bead"][:] = np.asarray(arrays["fluid_at_bead"], np.float64)[sim.ids]
    cpl.liquid_changed()
    return sim, cpl


def _loop(scene, sim) -> dict:
    """What :func:`millfmu.dem.run.run_scene` holds of a run that has not started (its first
    kinetic-energy sample taken as a new run takes it), for its resume path."""
    from millfmu.dem import run as R

    loop = R._new_loop(scene)
    loop["events"] = []  # a new contact log
    et, er = sim.kinetic_energy_j()
    loop["ke_t"].append(sim.step_count * scene.dt_s)
    loop["ke"].append(et + er)
    return loop


def run_point(scene, scene_at_point: dict, out_dir, *, threads=None, window_s=None,
              state_dir=None, candidates=None, warm_spin_up_s=None, kernel_version=None,
              checkpoint_every_s=None, on_start=None):
    """Run the table point ``scene`` (:class:`~millfmu.dem.scene.DemScene`; its scene dict
    ``scene_at_point``) into ``out_dir``; returns (statistics, start record).

    With ``warm_spin_up_s`` and a compatible state among ``candidates`` ((path, meta), as
    :func:`candidates_in` gives them) the point starts warm from the nearest within
    :data:`WARM_RANGE` (:func:`pick_start`) with that spin-up, else cold (the scene's spin-up,
    the same run as :func:`~millfmu.dem.run.run_scene`); where compatible states are at hand
    but all lie beyond the range, it says so on stderr and its start record says why
    (``why_cold``). With ``state_dir`` the state at the end of the
    run is saved there (:func:`state_file`) with the start record. ``kernel_version``: the
    installed DEM's (default :func:`~.cache.dem_kernel_version`). ``checkpoint_every_s`` [s
    of wall time]: keep the run's checkpoint in ``out_dir`` (:func:`~millfmu.dem.run.run_scene`;
    :func:`resume_point` goes on from it); ``on_start``: called with the start record before
    the run begins (so that a resumed point knows how it was started)."""
    from millfmu.dem.run import make_simulation, run_scene

    if kernel_version is None:
        from .cache import dem_kernel_version

        kernel_version = dem_kernel_version()
    start, sim, cpl, run, why = None, None, None, scene, None
    if warm_spin_up_s is not None and candidates:
        pick, why = pick_start(scene_at_point, candidates, kernel_version)
        if why is not None:
            print(f"millfmu: table point {_warm_values(scene_at_point)} starts cold: {why}",
                  file=sys.stderr, flush=True)
        if pick is not None:
            path, meta = pick
            v0 = _value(meta["scene"], "mill", "tip_speed_m_per_s")
            ratio = scene.tip_speed_m_per_s / float(v0) if v0 else 1.0
            try:
                arrays, meta = read_state(path, kernel_version)
                run = scene.with_overrides(spin_up_s=float(warm_spin_up_s))
                sim, cpl = warm_simulation(run, scaled(arrays, ratio), threads)
                start = warm_record(meta, path, run.spin_up_s, ratio)
            except WarmStartError:
                sim, cpl, run = None, None, scene
    if sim is None:
        from millfmu.dem.fluid.grid import GridError
        from millfmu.dem.run import DemRunError

        try:
            sim, cpl = make_simulation(scene, threads)
        except GridError as e:  # as run_scene says it
            raise DemRunError(f"{scene.name}: the coupled liquid's grid: {e}") from None
        start = cold_record(scene, why)
    if on_start is not None:
        on_start(start)
    stats = run_scene(run, out_dir, progress=False, threads=threads, window_s=window_s,
                      checkpoint_every_s=checkpoint_every_s,
                      _state=dict(sim=sim, cpl=cpl, loop=_loop(run, sim)))
    keep_state(state_dir, scene_at_point, kernel_version, sim, cpl, start)
    return stats, start


def keep_state(state_dir, scene_at_point: dict, kernel_version: str, sim, cpl, start: dict) -> None:
    """Save the settled state of a point's finished run (``sim``, ``cpl``) in ``state_dir``
    (None: nowhere) with its start record, for later points' warm starts."""
    if state_dir is None:
        return
    arrays = capture(sim, cpl)
    if arrays is not None:
        try:
            save_state(state_file(state_dir, scene_at_point, kernel_version), arrays,
                       {"scene": scene_at_point, "kernel_version": kernel_version, "start": start})
        except OSError:
            pass  # the point's result is what counts; a later point starts cold


def point_checkpoint(out_dir) -> dict:
    """The checkpoint a table point's run (:func:`run_point` with ``checkpoint_every_s``)
    left in ``out_dir``, for :func:`resume_point`. DemRunError (from
    :func:`~millfmu.dem.run.load_checkpoint`) where it cannot be read, or where it was made
    by DEM sources that do not give the same results (:data:`~.cache.SAME_DEM_AS`)."""
    from millfmu.dem import run as R
    from millfmu.dem.tables.cache import SAME_DEM_AS

    state = R.load_checkpoint(out_dir)
    made, here = state["kernel_version"], R._kernel_version()
    if SAME_DEM_AS.get(made, made) != SAME_DEM_AS.get(here, here):
        raise R.DemRunError(f"made by other DEM sources ({made})")
    return state


def resume_point(out_dir, scene_at_point: dict, start: dict, state: dict, *, threads=None,
                 state_dir=None, kernel_version=None, checkpoint_every_s=None):
    """Go on with the table point whose run left the checkpoint ``state`` in ``out_dir``
    (:func:`point_checkpoint`); ``start``: the start record the run began with. Returns the
    statistics, those of the run that was not stopped to the digit (the DEM's resume), and
    keeps the settled state as :func:`run_point` does."""
    from millfmu.dem import run as R

    if kernel_version is None:
        from .cache import dem_kernel_version

        kernel_version = dem_kernel_version()
    if threads is not None:
        state["sim"].threads = int(threads)
    every = checkpoint_every_s if checkpoint_every_s is not None else state["checkpoint_every_s"]
    stats = R.run_scene(state["scene"], out_dir, progress=False, window_s=state["window_s"],
                        contacts=state["contacts"], checkpoint_every_s=every, _state=state)
    keep_state(state_dir, scene_at_point, kernel_version, state["sim"], state["cpl"], start)
    return stats
