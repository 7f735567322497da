"""Zone statistics of a DEM run: the plain-data result the kinetics will read.

Everything here is numpy and dataclasses; ``DemStats.to_json`` / ``from_json`` round-trip
through plain JSON (no pickles). This is what ``stats.json`` holds.

Definitions (seed 001, sections 2.2-2.3 and 3):
- local filling phi = V_beads / (V_zone (1 - eps)), eps = 0.4 the bulk porosity at rest
  (seed 001 eq. 2), time-averaged over the samples, beads assigned by their centre;
- mean bead speed over the stirrer tip speed, averaged over beads and samples;
- collision frequency: bead-bead contacts, each counted once at its first overlap,
  located at the contact point, per zone volume and recording time [1/(m3 s)]; the
  wall collision frequency likewise for bead-wall contacts, located at the bead's centre;
- stress energies at the first overlap: SE_tn = 1/2 m* v_n^2 (seed 001 eq. 1 with the
  reduced mass), SE_ts = 1/2 m* |v_t|^2 (translational shear), SE_rot = 1/2 I* |w_i -
  w_j|^2 (rolling and torsion lumped), SE_total = SE_tn + SE_ts + SE_rot [J];
- distributions: number density over log10(SE) [1/decade] on fixed log bins, and the
  10/50/90 % quantiles;
- collision power: sum of SE_total of the zone's bead-bead collisions per recording time
  [W] (seed 001 section 3.5, "cumulating the local collision energies").
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field

import numpy as np

from millfmu.unit_names import modernize

SE_LOG10_MIN = -20.0  # seed 001 saved energies between 1e-20 and 1 J
SE_LOG10_MAX = 0.0
SE_BINS_PER_DECADE = 5
QUANTILES = (0.1, 0.5, 0.9)
COMPONENTS = ("tn", "ts", "total")


def se_bin_edges_j() -> np.ndarray:
    """Log-spaced stress-energy bin edges [J]."""
    n = int(round((SE_LOG10_MAX - SE_LOG10_MIN) * SE_BINS_PER_DECADE))
    return np.logspace(SE_LOG10_MIN, SE_LOG10_MAX, n + 1)


@dataclass
class EnergyDistribution:
    """Distribution of one stress-energy component in one zone."""

    density_per_decade: list  # number density over log10(SE), integrates to 1 [1/decade]
    quantiles_j: dict  # {"q10": .., "q50": .., "q90": ..} [J]; None without collisions
    mean_j: float | None


@dataclass
class ZoneStats:
    name: str
    volume_m3: float
    filling: float  # time-averaged local grinding-media filling [-]
    speed_over_tip_speed: float  # mean bead speed / stirrer tip speed [-]
    collision_count: int  # bead-bead collisions recorded
    collision_frequency_per_m3_s: float  # [1/(m3 s)]
    wall_collision_frequency_per_m3_s: float  # bead-wall/rotor collisions [1/(m3 s)]
    collision_power_w: float  # [W]
    se: dict  # component ("tn", "ts", "total") -> EnergyDistribution


@dataclass
class DemStats:
    scene: str
    fluid_model: str
    tip_speed_m_per_s: float
    filling: float | None
    beads: int
    sector_deg: float
    dt_s: float
    spin_up_s: float
    record_s: float
    se_bin_edges_j: list
    zones: list  # of ZoneStats
    stirrer_torque_nm: float  # drive torque on the simulated cell, full circle [N m]
    stirrer_power_w: float  # drive power of the simulated cell, full circle [W]
    kinetic_energy: dict  # steadiness of the bead kinetic energy
    counts: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    # mean-flow structure (beads, and the liquid when coupled): torques split into fluid
    # shear and bead contacts, power number, angular-momentum budget, vortices, swirl
    # profiles between the discs; see millfmu.dem.run
    flow: dict = field(default_factory=dict)
    # bead-wall impacts per wall that had any (shaft, chamber, disc or shrouds, vanes,
    # baffles):
    # contacts, rate_per_s_cell (in the simulated cell [1/s]) and quantiles q50, q90, q99
    # and the largest value of SE_tn = 1/2 m v_n^2 and SE_ts = 1/2 m |v_t|^2 [J] at the
    # first overlap, v relative to the wall's surface and m the bead's mass (between two
    # equal beads m* is half of it)
    walls: dict = field(default_factory=dict)

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=1, allow_nan=False)

    @staticmethod
    def from_json(text: str) -> "DemStats":
        """The stats of a ``stats.json`` (names in an earlier release's spelling read as the
        current ones: :mod:`millfmu.unit_names`)."""
        d = modernize(json.loads(text))
        zones = []
        for z in d.pop("zones"):
            z["se"] = {k: EnergyDistribution(**v) for k, v in z["se"].items()}
            zones.append(ZoneStats(**z))
        return DemStats(zones=zones, **d)

    def zone(self, name: str) -> ZoneStats:
        for z in self.zones:
            if z.name == name:
                return z
        raise KeyError(name)


#: wall names by the contact record's type - 1 (kernel wall ids: 0 shaft, 1 chamber,
#: 2 disc or the accelerator's shrouds, 3 vanes, 4 stationary baffles)
WALL_NAMES = ("shaft", "chamber", "disc", "vanes", "baffles")


def _tail(se_j: np.ndarray) -> dict:
    """Median, upper quantiles and largest value [J] of energies se_j (not empty)."""
    q = np.quantile(se_j, [0.5, 0.9, 0.99])
    return dict(q50=float(q[0]), q90=float(q[1]), q99=float(q[2]), max=float(se_j.max()))


def energy_distribution(se_j: np.ndarray, edges: np.ndarray) -> EnergyDistribution:
    """Log-binned number density [1/decade] and quantiles [J] of energies se_j."""
    se_j = np.asarray(se_j, float)
    nb = edges.size - 1
    if se_j.size == 0:
        return EnergyDistribution([0.0] * nb, {"q10": None, "q50": None, "q90": None}, None)
    # energies outside the bins are clipped into the end bins so that nothing is lost
    lo = np.clip(se_j, edges[0], edges[-1] * (1 - 1e-12))
    counts, _ = np.histogram(lo, bins=edges)
    dlog = np.diff(np.log10(edges))
    dens = counts / (se_j.size * dlog)
    q = np.quantile(se_j, QUANTILES)
    return EnergyDistribution([float(x) for x in dens],
                              {f"q{int(round(p * 100))}": float(v) for p, v in zip(QUANTILES, q)},
                              float(se_j.mean()))


def kinetic_energy_steadiness(t_s: np.ndarray, ke_j: np.ndarray, t_record_start_s: float
                              ) -> dict:
    """How steady the bead kinetic energy was during recording: mean [J], relative
    standard deviation [-], and relative linear trend over the recording window [-]
    (slope x duration / mean), plus the same mean over the last fifth of the spin-up."""
    t_s = np.asarray(t_s, float)
    ke_j = np.asarray(ke_j, float)
    rec = t_s >= t_record_start_s - 1e-12
    out = {"samples": int(rec.sum())}
    if rec.sum() >= 2:
        tt = t_s[rec]
        kk = ke_j[rec]
        mean = float(kk.mean())
        slope = float(np.polyfit(tt - tt[0], kk, 1)[0])
        dur = float(tt[-1] - tt[0])
        out.update(mean_j=mean, rel_std=float(kk.std() / mean) if mean > 0 else 0.0,
                   rel_trend_over_record=slope * dur / mean if mean > 0 else 0.0)
    spin = (t_s < t_record_start_s) & (t_s >= 0.8 * t_record_start_s)
    if spin.any():
        out["late_spin_up_mean_j"] = float(ke_j[spin].mean())
    return out


#: rows of recorded contacts taken at a time where a whole-recording pass would copy them
#: all (a full slice's recording is 7.4 GB, read from its file: millfmu.dem.contact_log)
BLOCK_ROWS = 1 << 22


def zone_of_rows(zones, ev: np.ndarray, ev_cols: dict) -> np.ndarray:
    """Zone index (int8, -1 outside every zone) of each recorded contact's position,
    BLOCK_ROWS rows at a time (the per-point classification of all rows at once took
    about 60 bytes per row)."""
    out = np.empty(ev.shape[0], np.int8)
    cols = [ev_cols["x"], ev_cols["y"], ev_cols["z"]]
    for i in range(0, ev.shape[0], BLOCK_ROWS):
        out[i:i + BLOCK_ROWS] = zones.classify(ev[i:i + BLOCK_ROWS][:, cols])
    return out


def compute_stats(*, scene: str, zones, events: np.ndarray, ev_cols: dict,
                  sample_x: list, sample_v: list, radii_m: np.ndarray,
                  record_s: float, tip_speed_m_per_s: float, omega_rad_per_s: float,
                  torque_on_stirrer_nm: float, ke_t_s, ke_j, spin_up_s: float,
                  dt_s: float, filling: float | None, bulk_porosity: float = 0.4,
                  fluid_model: str = "", notes=(), counts=None) -> DemStats:
    """Assemble DemStats from recorded contacts and position/velocity samples.

    events: rows of recorded contacts (columns named by ev_cols: type, x, y, z, setn, sets,
    serot); sample_x / sample_v: lists of (n, 3) arrays [m, m/s]; torque_on_stirrer_nm:
    mean torque the beads exert on the stirrer [N m] in the simulated cell.
    """
    g = zones.g
    vols = zones.volumes_m3()
    edges = se_bin_edges_j()
    vbead = 4.0 / 3.0 * math.pi * np.asarray(radii_m) ** 3
    nz = len(zones.names)
    fill_acc = np.zeros(nz)
    speed_acc = np.zeros(nz)
    speed_n = np.zeros(nz)
    for xs, vs in zip(sample_x, sample_v):
        zid = zones.classify(xs)
        sp = np.linalg.norm(vs, axis=1)
        for k in range(nz):
            m = zid == k
            fill_acc[k] += vbead[m].sum() / (vols[k] * (1.0 - bulk_porosity))
            speed_acc[k] += sp[m].sum()
            speed_n[k] += m.sum()
    ns = max(len(sample_x), 1)
    ev = events
    typ = ev[:, ev_cols["type"]] if ev.size else np.zeros(0)
    # bead-wall contacts are recorded at the bead's centre: they count in the bead's zone
    zid_ev = zone_of_rows(zones, ev, ev_cols) if ev.size else np.zeros(0, int)
    se_tn = ev[:, ev_cols["setn"]] if ev.size else np.zeros(0)
    se_ts = ev[:, ev_cols["sets"]] if ev.size else np.zeros(0)
    se_tot = se_tn + se_ts + (ev[:, ev_cols["serot"]] if ev.size else np.zeros(0))
    out = []
    for k, name in enumerate(zones.names):
        bb = (typ == 0) & (zid_ev == k)
        bw = (typ > 0) & (zid_ev == k)
        comp = {"tn": se_tn[bb], "ts": se_ts[bb], "total": se_tot[bb]}
        out.append(ZoneStats(
            name=name, volume_m3=float(vols[k]), filling=float(fill_acc[k] / ns),
            speed_over_tip_speed=float(speed_acc[k] / max(speed_n[k], 1) / tip_speed_m_per_s),
            collision_count=int(bb.sum()),
            collision_frequency_per_m3_s=float(bb.sum() / (vols[k] * record_s)),
            wall_collision_frequency_per_m3_s=float(bw.sum() / (vols[k] * record_s)),
            collision_power_w=float(se_tot[bb].sum() / record_s),
            se={c: energy_distribution(v, edges) for c, v in comp.items()}))
    walls = {}
    for q, wname in enumerate(WALL_NAMES):
        m = typ == 1.0 + q
        if m.any():
            walls[wname] = dict(contacts=int(m.sum()), rate_per_s_cell=float(m.sum() / record_s),
                                se_tn_j=_tail(se_tn[m]), se_ts_j=_tail(se_ts[m]))
    frac = g.sector_fraction
    drive_torque = -torque_on_stirrer_nm / frac + 0.0  # + 0.0: no "-0" without contacts
    return DemStats(
        scene=scene, fluid_model=fluid_model, tip_speed_m_per_s=tip_speed_m_per_s, filling=filling,
        beads=int(np.asarray(radii_m).size), sector_deg=g.sector_deg, dt_s=dt_s,
        spin_up_s=spin_up_s, record_s=record_s, se_bin_edges_j=[float(e) for e in edges],
        zones=out, stirrer_torque_nm=float(drive_torque),
        stirrer_power_w=float(drive_torque * omega_rad_per_s),
        kinetic_energy=kinetic_energy_steadiness(ke_t_s, ke_j, spin_up_s),
        counts=dict(counts or {}), notes=list(notes), walls=walls)
