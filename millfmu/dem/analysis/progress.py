"""Where a checkpointed run stands (``millfmu dem progress DIR``): time simulated and to go,
its cost so far, and the bed's state at the checkpoint, for runs too long to wait for their
statistics (the full 360-degree slices).

From the run's ``checkpoint.pkl`` (:mod:`millfmu.dem.run`), read only:

- time simulated [s] of the protocol's spin-up + recording, wall time so far [s] (with any
  time the process was stopped), CPU time of all threads [s] (without it), both per
  simulated second [s/s], particle-steps per second, the checkpoint's size per bead [B];
  and the recent pace, between the last two checkpoints (wall and CPU time per simulated
  second, the wall time to go at that pace), where the run has written two since it was
  last started or resumed by these sources or later;
- the beads' mean angular velocity about the axis over the stirrer's (omega_i = v_perp / r);
- disc slices: seed 001's first bead layer (centres within 0.75 d of a disc face, inside
  the disc radius; section 3.2) at this instant, over the stirrer's angular velocity;
- with gravity across the axis: the beads per 30 degrees of azimuth, counted from the top
  (against gravity) in the direction of rotation, largest over smallest; the rising half
  (where the stirrer's motion is upwards) over the falling half; the upper half over the
  lower (:mod:`millfmu.dem.analysis.circumferential`). A sector without gravity has none
  of these (rotational symmetry).

One instant, not a time mean: a bed's state fluctuates by a few percent from one sample to
the next (the run's statistics average over its recording).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from millfmu.dem.analysis.circumferential import circumferential


def run_progress(out_dir) -> dict:
    """The figures of the module docstring for the run whose checkpoint is in ``out_dir``;
    raises DemRunError (by name) where there is none or it cannot be read."""
    from millfmu.dem.analysis.flow_structure import (FIRST_LAYER_DIAMETERS,
                                                     first_layer_angular_velocity)
    from millfmu.dem.run import CHECKPOINT, load_checkpoint

    state = load_checkpoint(out_dir)
    path = Path(out_dir) / CHECKPOINT
    scene, sim, loop = state["scene"], state["sim"], state["loop"]
    g = scene.geometry
    dt = scene.dt_s
    t_s = sim.step_count * dt
    total_s = scene.spin_up_s + scene.record_s
    wall_s = float(loop["wall_s"])
    out = dict(scene=scene.name, beads=int(sim.n), sector_deg=g.sector_deg,
               fluid=scene.fluid_description, t_s=t_s, total_s=total_s,
               phase="recording" if t_s >= scene.spin_up_s else "spin-up",
               wall_s=wall_s, wall_per_simulated_s=wall_s / t_s if t_s > 0 else math.nan,
               wall_to_go_s=wall_s / t_s * max(total_s - t_s, 0.0) if t_s > 0 else math.nan,
               particle_steps_per_s=sim.n * sim.step_count / wall_s if wall_s > 0 else math.nan,
               cpu_s=loop.get("cpu_s"),
               cpu_per_simulated_s=_cpu_per_simulated_s(loop, sim.step_count, dt),
               checkpoint_bytes_per_bead=path.stat().st_size / sim.n,
               kinetic_energy=dict(t_s=list(loop["ke_t"]), e_j=list(loop["ke"])))
    out.update(recent_pace(loop.get("checkpoints", []), dt, total_s - t_s, sim.n))
    omega = scene.tip_speed_m_per_s / (g.disc_radius_m or g.shaft_radius_m)
    x, v = sim.x, sim.v
    r = np.hypot(x[:, 0], x[:, 1])
    om_i = (x[:, 0] * v[:, 1] - x[:, 1] * v[:, 0]) / np.maximum(r, 1e-300) ** 2
    out["angular_velocity_over_stirrer"] = float(om_i.mean() / omega)
    if g.has_disc and not g.has_channel:
        d = scene.bead_diameter_m
        ratio, n = first_layer_angular_velocity([x], [v], g, omega, FIRST_LAYER_DIAMETERS * d)
        out["first_bead_layer_angular_velocity_ratio"] = ratio
        out["first_bead_layer_beads"] = n
    out.update(circumferential(x, scene.gravity_m_per_s2, g.sector_deg))
    return out


def recent_pace(checkpoints, dt_s: float, to_go_s: float, beads: int) -> dict:
    """Pace between the last two of ``checkpoints`` [(step, wall s, CPU s), ...]: wall and
    CPU time per simulated second [s/s], particle-steps per second and the wall time to go
    [s] for ``to_go_s`` [s] more at that pace; {} with fewer than two or no step between."""
    if len(checkpoints) < 2:
        return {}
    (s0, w0, c0), (s1, w1, c1) = checkpoints[-2], checkpoints[-1]
    span = (s1 - s0) * dt_s
    if span <= 0.0:
        return {}
    wall = (w1 - w0) / span
    return dict(recent_wall_per_simulated_s=wall, recent_cpu_per_simulated_s=(c1 - c0) / span,
                recent_particle_steps_per_s=beads * (s1 - s0) / max(w1 - w0, 1e-300),
                recent_wall_to_go_s=wall * max(to_go_s, 0.0))


def _cpu_per_simulated_s(loop: dict, step_count: int, dt_s: float) -> float | None:
    """CPU time of all threads per simulated second [s/s] over the steps it was counted
    for (from loop's cpu_from_step), None where it was not recorded."""
    if "cpu_s" not in loop:
        return None
    span = (step_count - loop.get("cpu_from_step", 0)) * dt_s
    return loop["cpu_s"] / span if span > 0 else None


def progress_lines(p: dict) -> list[str]:
    """Human-readable lines of :func:`run_progress`'s figures."""
    h = 3600.0
    out = [f"{p['scene']}: {p['beads']:,} beads, {p['sector_deg']:g} degrees; {p['fluid']}",
           f"simulated {p['t_s']:.4g} s of {p['total_s']:.4g} s ({p['phase']}); wall time "
           f"{p['wall_s'] / h:.2f} h, {p['wall_per_simulated_s'] / h:.2f} h per simulated "
           f"second, about {p['wall_to_go_s'] / h:.1f} h to go at that rate (wall time "
           f"since the start, including any time the process was stopped)",
           (f"CPU time (all threads) {p['cpu_per_simulated_s'] / h:.2f} h per simulated "
            f"second" if p["cpu_per_simulated_s"] is not None else
            "CPU time: not recorded (a checkpoint of earlier sources)"),
           f"{p['particle_steps_per_s'] / 1e6:.3g} M particle-steps/s; checkpoint "
           f"{p['checkpoint_bytes_per_bead'] / 1e3:.2f} kB per bead"]
    if "recent_wall_per_simulated_s" in p:
        out.append(f"between the last two checkpoints: {p['recent_wall_per_simulated_s'] / h:.2f}"
                   f" h wall ({p['recent_cpu_per_simulated_s'] / h:.2f} h CPU) per simulated "
                   f"second, {p['recent_particle_steps_per_s'] / 1e6:.3g} M particle-steps/s; "
                   f"about {p['recent_wall_to_go_s'] / h:.1f} h to go at that pace")
    out.append(f"beads' mean angular velocity / stirrer's: "
               f"{p['angular_velocity_over_stirrer']:.3f}")
    if "first_bead_layer_angular_velocity_ratio" in p:
        out.append(f"first bead layer (within 0.75 d of a disc face) / stirrer's: "
                   f"{p['first_bead_layer_angular_velocity_ratio']:.3f} "
                   f"({p['first_bead_layer_beads']:,} beads; seed 001: 0.20-0.26)")
    if "beads_per_bin" in p:
        out.append(f"beads per {p['azimuth_bin_deg']:g} degrees from the top in the direction "
                   f"of rotation: {p['beads_per_bin']}; largest / smallest "
                   f"{p['largest_over_smallest_bin']:.3f}, rising / falling half "
                   f"{p['rising_over_falling_half']:.3f}, upper / lower half "
                   f"{p['upper_over_lower_half']:.3f}")
    out.append("(one instant at the checkpoint, not a time mean)")
    return out
