"""Run a DEM scene: spin-up, recording, zone statistics and output files.

Outputs in the output folder:
- ``stats.json``: :class:`millfmu.dem.stats.DemStats` (plain JSON);
- ``se_histograms.csv``: stress-energy number densities [1/decade] per zone and component
  on the log bins of ``stats.json``;
- ``kinetic_energy.csv``: bead kinetic energy over time (spin-up and recording);
- ``map_stress_energy.png``, ``map_collision_frequency.png``, ``map_collision_power.png``:
  radially averaged (i.e. averaged over the angle) maps in the axial section, like seed 001
  figures 12-15; ``se_distributions.png``: SE_tn distributions per zone (seed 001 Fig. A1).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from millfmu.dem.geometry import (bead_count_for_filling, place_beads,
                                  simple_cubic_annulus)
from millfmu.dem.scene import DemScene
from millfmu.dem.stats import DemStats, compute_stats
from millfmu.dem.zones import Zones

FLUID_NOTE = ("prescribed swirl flow (no CFD coupling): azimuthal fluid velocity between "
              "the rotating stirrer and the fixed chamber wall as documented in "
              "millfmu.dem.kernels.swirl_velocity; no radial/axial circulation")


def initial_positions(scene: DemScene) -> np.ndarray:
    """Bead centres [m] of a scene's initial state."""
    r = 0.5 * scene.bead_diameter_m
    if scene.placement == "lattice":
        return simple_cubic_annulus(scene.lattice_spacing_m, *scene.lattice_r_range_m,
                                    scene.geometry.height_m)
    n = bead_count_for_filling(scene.geometry, scene.filling, scene.bead_diameter_m,
                               scene.bulk_porosity)
    return place_beads(scene.geometry, n, r, seed=scene.seed)


def run_scene(scene: DemScene, out_dir, progress: bool = True, threads: int | None = None,
              window_s: float | None = None) -> DemStats:
    """Run ``scene`` and write its outputs to ``out_dir``; returns the statistics.

    ``window_s`` [s]: also cut the recording into consecutive windows of this length (a
    whole number of sampling intervals) and write each window's zone statistics to
    ``windows.csv``, to see whether the recorded state is stationary.
    """
    from millfmu.dem import kernels as K
    from millfmu.dem.sim import DemSimulation

    EV_COLS = dict(type=K.EV_TYPE, x=K.EV_X, y=K.EV_Y, z=K.EV_Z, setn=K.EV_SETN,
                   sets=K.EV_SETS, serot=K.EV_SEROT)

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    x0 = initial_positions(scene)
    sim = DemSimulation(scene.geometry, scene.material, x0, 0.5 * scene.bead_diameter_m,
                        scene.omega_rad_s, scene.dt_s, gravity_m_s2=scene.gravity_m_s2,
                        fluid=scene.fluid, threads=threads)
    zones = Zones(scene.geometry, scene.zones)
    dt = scene.dt_s
    n_spin = int(round(scene.spin_up_s / dt))
    n_rec = max(1, int(round(scene.record_s / dt)))
    every = max(1, int(round(scene.sample_every_s / dt)))
    total = n_spin + n_rec
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=total, unit="step", desc=f"dem {scene.name} ({sim.n} beads)",
                   smoothing=0.1, bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} "
                   "[{elapsed}<{remaining}, {rate_fmt}]")
    ke_t, ke = [], []
    sx, sv = [], []
    events = []
    torques = []
    dropped = builds = 0
    t_wall = time.perf_counter()

    def sample():
        et, er = sim.kinetic_energy_j()
        ke_t.append(sim.step_count * dt)
        ke.append(et + er)

    sample()
    done = 0
    while done < total:
        recording = done >= n_spin
        k = min(every, (n_spin - done) if not recording else total - done)
        st = sim.run(k, record=recording)
        builds += st.neighbour_builds
        if recording:
            events.append(st.events)
            torques.append((k, st.torque_sum_nm_steps))
            dropped += st.dropped_events
            sx.append(sim.x.copy())
            sv.append(sim.v.copy())
        done += k
        sample()
        if bar is not None:
            bar.update(k)
    if bar is not None:
        bar.close()
    wall = time.perf_counter() - t_wall
    ev = np.concatenate(events) if events else np.zeros((0, K.EV_NF))
    notes = [
        "fluid: " + (FLUID_NOTE if scene.fluid is not None and scene.fluid.drag
                     else "no fluid drag"),
        "spin-up excluded from all statistics; samples and contacts from the recording "
        "window only",
        "zones V1-V4 as read from seed 001 Figure 2 (see millfmu.dem.zones)",
        "stirrer torque and power scaled from the simulated sector to the full circle; "
        "per axial period of the cell",
    ]

    def stats_of(chunks, t0_s, counts=None):
        # Statistics of the recording chunks ``chunks`` (indices), which start at t0_s.
        e = np.concatenate([events[i] for i in chunks]) if chunks else np.zeros((0, K.EV_NF))
        n = sum(torques[i][0] for i in chunks)
        return compute_stats(
            scene=scene.name, zones=zones, events=e, ev_cols=EV_COLS,
            sample_x=[sx[i] for i in chunks], sample_v=[sv[i] for i in chunks],
            radii_m=sim.rad, record_s=n * dt, tip_speed_m_s=scene.tip_speed_m_s,
            omega_rad_s=scene.omega_rad_s,
            torque_on_stirrer_nm=sum(torques[i][1] for i in chunks) / max(n, 1),
            ke_t_s=np.array(ke_t), ke_j=np.array(ke), spin_up_s=t0_s, dt_s=dt,
            filling=scene.filling, bulk_porosity=scene.bulk_porosity,
            fluid_model=FLUID_NOTE if scene.fluid is not None else "none", notes=notes,
            counts=counts or {})

    stats = stats_of(list(range(len(events))), n_spin * dt, counts=dict(
        contacts_recorded=int(ev.shape[0]),
        bead_bead=int((ev[:, K.EV_TYPE] == 0).sum()) if ev.size else 0,
        bead_wall=int((ev[:, K.EV_TYPE] > 0).sum()) if ev.size else 0,
        dropped_contacts=int(dropped), neighbour_builds=int(builds),
        steps=int(total), wall_time_s=wall, threads=int(sim.threads),
        particle_steps_per_s=sim.n * total / wall))
    if window_s is not None:
        per = max(1, int(round(window_s / (every * dt))))
        rows = []
        for w0 in range(0, len(events), per):
            chunks = list(range(w0, min(w0 + per, len(events))))
            t0 = (n_spin + w0 * every) * dt
            rows.append((t0, t0 + sum(torques[i][0] for i in chunks) * dt,
                         stats_of(chunks, t0)))
        _write_windows(out / "windows.csv", rows)
    (out / "stats.json").write_text(stats.to_json())
    _write_histograms(out / "se_histograms.csv", stats)
    np.savetxt(out / "kinetic_energy.csv", np.column_stack([ke_t, ke]), delimiter=",",
               header="t_s,kinetic_energy_j", comments="")
    from millfmu.dem import plots

    plots.write_maps(out, scene, ev, EV_COLS)
    plots.write_distributions(out / "se_distributions.png", stats)
    return stats


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
    lines.append(f"stirrer torque {stats.stirrer_torque_nm:.4g} N m, power "
                 f"{stats.stirrer_power_w:.4g} W; kinetic energy "
                 f"{json.dumps(stats.kinetic_energy)}")
    return "\n".join(lines)

