"""The accelerator mill of seed 002 (He et al. 2022, Minerals 12, 341): rotor, zones SEV_1-4
and the paper's stress quantities (pure numpy, no numba).

Rotor. An acceleration rotor is a disc with a channel: two shrouds (annular slabs from the
eye radius to the rim) around a channel that holds radial vanes from the shaft to the rim.
Liquid and beads enter the channel near the shaft through the eyes (where the shrouds
leave the shaft free), are thrown out at the rim by the turning vanes, return along the
chamber wall and flow inwards between the rotors (seed 002 section 3.1: "a certain degree
of vacuum is formed at the entrance of each rotor close to the shaft; under the action of
the high-pressure flow at the exit of the rotor, the grinding beads are moved in a state
of acceleration from the chamber wall to the stirrer shaft"). In the DEM the shrouds and
vanes are walls (:mod:`millfmu.dem.engine.kernels`, walls 2 and 3); in the coupled liquid the
shrouds are rotor cells and the channel is a driven zone whose swirl the vanes hold at the
rotor's speed (:class:`millfmu.dem.fluid.solver.FluidSolver`). The geometry's dimensions
and what each is derived from are in the shipped scene ``accelerator_slice.toml``.

Zones (seed 002 section 3.1, figures 4 and 5). Z' is the distance from the chamber wall
over the radial extent R = r_chamber - r_shaft; X' the axial distance from the mid-plane
between two rotors over L, half the axial period (X'/L = 1 at the rotor's mid-plane):

- SEV_1, slow acceleration: Z'/R <= z1 (0.39: the rotor rim);
- SEV_2, fast acceleration: z1 < Z'/R <= z2 (0.69);
- SEV_3, the smooth zone: Z'/R > z2 and X'/L <= x3 (0.4);
- SEV_4, deceleration: Z'/R > z2 and X'/L > x3 (the rotor's side, its channel included).

The paper's smooth zone ends at Z'/R = 0.9; the ring 0.9 < Z'/R <= 1 beside the shaft is
not assigned there, and it is given to SEV_3 and SEV_4 here (by X'/L) so that the zones
tile the chamber.

Stress quantities (seed 002 section 2.3, eqs. 1-3), per zone, from the bead-bead
contacts recorded at their first overlap:
- SE_tn = 1/2 m_g v_tn,rel^2 and SE_ts = 1/2 I_g omega_ts,rel^2 with m_g, I_g the bead's
  mass and moment of inertia (the paper's definitions; seed 001's use m* and I*, half
  of those for equal beads);
- SI, the mean stress intensity SE_tn + SE_ts per contact [J]; SN_g, contacts per volume
  and time [1/(m3 s)]; SE_cs = SI SN_g [W/m3]; SE_cs,sum = SE_cs V [W] and
  SE_ts,sum = sum of SE_ts per time [W];
- SE_net = (6 / pi) m_g,total v_r^2 n (1 + Y_p / Y_g)^-1 [W] (eq. 2, after Kwade 2003)
  with the media mass m_g,total of the full mill slice, and the efficiency
  SE_cs,sum / SE_net.

Two countings of the contacts, each named in the result (``counting``): every contact
event once at its first overlap (:func:`stress_quantities`), and the contacts present at
frames taken at a set rate (:func:`snapshot_stress_quantities`), as a post-processor of
saved frames counts them (seed 002 saved 20 frames per second); see
:mod:`millfmu.dem.analysis.snapshots`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from millfmu.dem.mills.geometry import MillGeometry
from millfmu.dem.mills.zones import ZoneError

ZONE_NAMES = ("SEV_1", "SEV_2", "SEV_3", "SEV_4")

#: Young's modulus of the product over the beads' (eq. 2's Y_p / Y_g): organic pesticide
#: crystals about 8 GPa (molecular crystals 5-10 GPa) over yttria-stabilised zirconia
#: 210 GPa; seed 002 gives neither value. It scales SE_net by 1/1.04.
PRODUCT_OVER_BEAD_MODULUS = 0.04


@dataclass(frozen=True)
class SevSpec:
    """Zone boundaries of seed 002 figure 4 [-]: Z'/R of SEV_1|2 and SEV_2|3-4, X'/L of
    SEV_3|4."""

    z1: float = 0.39
    z2: float = 0.69
    x3: float = 0.40


class SevZones:
    """SEV_1-4 of an accelerator slice: the interface of :class:`millfmu.dem.mills.zones.Zones`
    (names, classify, volumes_m3)."""

    names = ZONE_NAMES

    def __init__(self, geometry: MillGeometry, spec: SevSpec = SevSpec()):
        if not geometry.has_channel:
            raise ZoneError("SEV zones need an accelerator rotor (a disc with a channel)")
        if not 0.0 < spec.z1 < spec.z2 < 1.0 or not 0.0 < spec.x3 < 1.0:
            raise ZoneError(f"SEV boundaries z1 = {spec.z1!r}, z2 = {spec.z2!r}, x3 = "
                            f"{spec.x3!r}: need 0 < z1 < z2 < 1 and 0 < x3 < 1")
        self.g = geometry
        self.spec = spec
        self._vols = None

    def coordinates(self, p: np.ndarray):
        """(Z'/R, X'/L) of points p [m] (n, 3)."""
        g = self.g
        r = np.hypot(p[:, 0], p[:, 1])
        zr = p[:, 2] - g.disc_z_m
        zr = zr - g.height_m * np.floor(zr / g.height_m + 0.5)
        half = 0.5 * g.height_m
        return ((g.chamber_radius_m - r) / (g.chamber_radius_m - g.shaft_radius_m),
                1.0 - np.abs(zr) / half)

    def classify(self, p: np.ndarray) -> np.ndarray:
        """Zone index per point p [m] (n, 3); -1 outside the chamber."""
        zz, xx = self.coordinates(p)
        s = self.spec
        out = np.where(zz <= s.z1, 0, np.where(zz <= s.z2, 1, np.where(xx <= s.x3, 2, 3)))
        out[(zz < 0.0) | (zz > 1.0)] = -1
        return out.astype(np.int64)

    def volumes_m3(self) -> np.ndarray:
        """Open volume of each zone in the simulated sector [m3]: the ring and axial band of
        the zone, less the shrouds', vanes' and baffles' parts in it (annular slabs and
        plates of constant thickness, as MillGeometry.free_volume_m3 counts them)."""
        g = self.g
        s = self.spec
        span = g.chamber_radius_m - g.shaft_radius_m
        half = 0.5 * g.height_m
        r1 = g.chamber_radius_m - s.z1 * span
        r2 = g.chamber_radius_m - s.z2 * span
        zx = (1.0 - s.x3) * half  # |z| from the rotor's mid-plane at X'/L = x3
        bands = [((r1, g.chamber_radius_m), (0.0, half)), ((r2, r1), (0.0, half)),
                 ((g.shaft_radius_m, r2), (zx, half)), ((g.shaft_radius_m, r2), (0.0, zx))]
        hb, hc = 0.5 * g.disc_thickness_m, 0.5 * g.channel_height_m

        def overlap(a, b):
            return max(0.0, min(a[1], b[1]) - max(a[0], b[0]))

        def ring(r):  # area of the annulus r[0] < r < r[1]
            return math.pi * (r[1] ** 2 - r[0] ** 2) if r[1] > r[0] else 0.0

        out = []
        for rr, zz in bands:
            v = ring(rr) * 2.0 * (zz[1] - zz[0])
            rs = (max(rr[0], g.eye_radius_m), min(rr[1], g.disc_radius_m))
            v -= ring(rs) * 2.0 * overlap(zz, (hc, hb))
            if g.vane_count:
                v -= g.vane_count * g.vane_thickness_m * \
                    overlap(rr, (g.shaft_radius_m, g.disc_radius_m)) * 2.0 * overlap(zz, (0.0, hc))
            if g.has_baffles:  # half a period from the rotor's mid-plane, |z| near L/2
                v -= g.baffle_count * g.baffle_thickness_m * \
                    overlap(rr, (g.baffle_inner_radius_m, g.chamber_radius_m)) * 2.0 * \
                    overlap(zz, (half - 0.5 * g.baffle_height_m, half))
            out.append(v)
        return np.array(out) * g.sector_fraction


def bead_mass_kg(diameter_m: float, density_kg_per_m3: float) -> float:
    return math.pi / 6.0 * diameter_m ** 3 * density_kg_per_m3


def bead_inertia_kgm2(diameter_m: float, density_kg_per_m3: float) -> float:
    """Moment of inertia of a solid sphere, m d^2 / 10 [kg m2]."""
    return bead_mass_kg(diameter_m, density_kg_per_m3) * diameter_m ** 2 / 10.0


def net_stress_energy_w(media_mass_kg: float, tip_speed_m_per_s: float, speed_rev_s: float,
                        modulus_ratio: float = PRODUCT_OVER_BEAD_MODULUS) -> float:
    """SE_net = (6 / pi) m_g v_r^2 n (1 + Y_p / Y_g)^-1 [W] (seed 002 eq. 2)."""
    return 6.0 / math.pi * media_mass_kg * tip_speed_m_per_s ** 2 * speed_rev_s / \
        (1.0 + modulus_ratio)


def stress_quantities(events: np.ndarray, ev_cols: dict, zones, record_s: float,
                      bead_diameter_m: float, bead_density_kg_per_m3: float, n_beads: int,
                      tip_speed_m_per_s: float, omega_rad_per_s: float,
                      modulus_ratio: float = PRODUCT_OVER_BEAD_MODULUS) -> dict:
    """Seed 002's SI, SN_g, SE_cs, SE_ts,sum / SE_cs,sum per zone and in total, SE_net and
    the efficiency (plain JSON data, SI units), every bead-bead contact counted once at its
    first overlap. ``events``: recorded contacts (columns ev_cols: type, x, y, z, setn,
    serot) over ``record_s`` [s] in the simulated sector; powers are scaled to the full
    circle (per axial period)."""
    m_g = bead_mass_kg(bead_diameter_m, bead_density_kg_per_m3)
    bb = events[:, ev_cols["type"]] == 0 if events.size else np.zeros(0, bool)
    ev = events[bb] if events.size else np.zeros((0, max(ev_cols.values()) + 1))
    pos = ev[:, [ev_cols["x"], ev_cols["y"], ev_cols["z"]]]
    # recorded with m* = m_g / 2 and I* = I_g / 2 (equal beads): the paper's use m_g, I_g
    se_tn = ev[:, ev_cols["setn"]] * 2.0
    se_ts = ev[:, ev_cols["serot"]] * 2.0
    out = _quantities(pos, se_tn, se_ts, zones, record_s, n_beads * m_g, tip_speed_m_per_s,
                      omega_rad_per_s, modulus_ratio)
    out["counting"] = "every contact event, counted once at its first overlap"
    return out


def snapshot_stress_quantities(frames, interval_s: float, zones, bead_diameter_m: float,
                               bead_density_kg_per_m3: float, n_beads: int,
                               tip_speed_m_per_s: float, omega_rad_per_s: float,
                               modulus_ratio: float = PRODUCT_OVER_BEAD_MODULUS) -> dict:
    """The quantities of :func:`stress_quantities` from the contacts present at frames
    taken every ``interval_s`` [s] (:class:`millfmu.dem.analysis.snapshots.Frame`), as a
    post-processor of saved frames counts them (seed 002: 20 frames per second): SN_g is
    the contacts present summed over the frames per zone volume and recording time
    (len(frames) x interval_s), energies from each contact's relative velocity and spin at
    the frame."""
    m_g = bead_mass_kg(bead_diameter_m, bead_density_kg_per_m3)
    i_g = bead_inertia_kgm2(bead_diameter_m, bead_density_kg_per_m3)
    frames = list(frames)
    pos = np.concatenate([f.point_m for f in frames]) if frames else np.zeros((0, 3))
    vn2 = np.concatenate([f.vn2_m2_s2 for f in frames]) if frames else np.zeros(0)
    wr2 = np.concatenate([f.wrel2_rad2_s2 for f in frames]) if frames else np.zeros(0)
    out = _quantities(pos, 0.5 * m_g * vn2, 0.5 * i_g * wr2, zones,
                      len(frames) * interval_s, n_beads * m_g, tip_speed_m_per_s, omega_rad_per_s,
                      modulus_ratio)
    out["counting"] = (f"contacts present at {len(frames)} frames, one every "
                       f"{interval_s:g} s ({1.0 / interval_s:g} per second)")
    out["frames"] = len(frames)
    out["frame_interval_s"] = interval_s
    return out


def _quantities(pos, se_tn, se_ts, zones, record_s, media_mass_sector_kg, tip_speed_m_per_s,
                omega_rad_per_s, modulus_ratio) -> dict:
    """Per-zone and total quantities of bead-bead contacts at ``pos`` [m] with the paper's
    energies ``se_tn``, ``se_ts`` [J] over ``record_s`` [s]; media mass of the simulated
    sector [kg]."""
    frac = zones.g.sector_fraction
    zid = zones.classify(pos) if pos.size else np.zeros(0, np.int64)
    vols = zones.volumes_m3()
    out = {"zones": {}, "definitions": dict(
        SE_tn="1/2 m_g v_tn,rel^2 [J], m_g the bead mass",
        SE_ts="1/2 I_g omega_ts,rel^2 [J], I_g = m_g d^2 / 10",
        SI="mean of SE_tn + SE_ts per bead-bead contact [J]",
        SN_g="bead-bead contacts per volume and time [1/(m3 s)]",
        SE_cs="SI x SN_g [W/m3]",
        SE_cs_sum="SE_cs x zone volume, full circle [W]",
        SE_net="(6/pi) m_g,total v_r^2 n (1 + Y_p/Y_g)^-1 [W], full circle "
               f"(Y_p/Y_g = {modulus_ratio})")}
    tot_cs = tot_ts = tot_tn = 0.0
    for k, name in enumerate(zones.names):
        m = zid == k
        n = int(m.sum())
        tn = float(se_tn[m].sum())
        ts = float(se_ts[m].sum())
        v = float(vols[k])
        sn = n / (v * record_s) if v > 0 and record_s > 0 else 0.0
        si = (tn + ts) / n if n else None
        cs_sum = (tn + ts) / record_s / frac if record_s > 0 else 0.0
        ts_sum = ts / record_s / frac if record_s > 0 else 0.0
        out["zones"][name] = dict(
            contacts=n, volume_m3=v, SN_g_per_m3_s=sn,
            SI_j=si, SE_tn_mean_j=tn / n if n else None, SE_ts_mean_j=ts / n if n else None,
            SE_tn_median_j=float(np.median(se_tn[m])) if n else None,
            SE_ts_median_j=float(np.median(se_ts[m])) if n else None,
            SE_cs_w_per_m3=(si or 0.0) * sn, SE_cs_sum_w=cs_sum, SE_ts_sum_w=ts_sum,
            ts_share=ts_sum / cs_sum if cs_sum > 0 else None)
        tot_cs += cs_sum
        tot_ts += ts_sum
        tot_tn += tn / record_s / frac if record_s > 0 else 0.0
    media = media_mass_sector_kg / frac
    n_rev = omega_rad_per_s / (2.0 * math.pi)
    se_net = net_stress_energy_w(media, tip_speed_m_per_s, n_rev, modulus_ratio)
    out["total"] = dict(SE_cs_sum_w=tot_cs, SE_ts_sum_w=tot_ts, SE_tn_sum_w=tot_tn,
                        ts_share=tot_ts / tot_cs if tot_cs > 0 else None,
                        SN_g_per_m3_s=float(zid.size / (vols.sum() * record_s))
                        if record_s > 0 else 0.0,
                        media_mass_kg=media, SE_net_w=se_net,
                        efficiency=tot_cs / se_net if se_net > 0 else None)
    return out


def _speed_profile(sample_x, sample_v, coord, tip_speed_m_per_s: float, bins: int):
    """Mean bead speed over tip speed [-] in ``bins`` equal bins of coord(x) over [0, 1]
    (coord: positions (n, 3) -> (values, mask of the beads counted)); (centres, profile,
    samples)."""
    edges = np.linspace(0.0, 1.0, bins + 1)
    acc = np.zeros(bins)
    cnt = np.zeros(bins)
    for xs, vs in zip(sample_x, sample_v):
        c, m = coord(xs)
        k = np.clip(np.searchsorted(edges, c[m], side="right") - 1, 0, bins - 1)
        np.add.at(acc, k, np.linalg.norm(vs[m], axis=1))
        np.add.at(cnt, k, 1.0)
    with np.errstate(invalid="ignore"):
        prof = acc / cnt / tip_speed_m_per_s
    return (list(np.round(0.5 * (edges[1:] + edges[:-1]), 6)),
            [None if not np.isfinite(p) else round(float(p), 6) for p in prof],
            [int(c) for c in cnt])


def _z_over_r(xs, g: MillGeometry):
    return (g.chamber_radius_m - np.hypot(xs[:, 0], xs[:, 1])) / \
        (g.chamber_radius_m - g.shaft_radius_m)


def radial_speed_profile(sample_x, sample_v, geometry: MillGeometry, tip_speed_m_per_s: float,
                         bins: int = 20) -> dict:
    """Mean bead speed over tip speed against Z'/R (seed 002 figures 3a, 4a) [-]."""
    c, p, n = _speed_profile(sample_x, sample_v,
                             lambda xs: (_z_over_r(xs, geometry), slice(None)),
                             tip_speed_m_per_s, bins)
    return dict(z_over_r=c, speed_over_tip_speed=p, samples=n)


def axial_speed_profile(sample_x, sample_v, geometry: MillGeometry, tip_speed_m_per_s: float,
                        z_min: float = 0.69, bins: int = 10) -> dict:
    """Mean bead speed over tip speed against X'/L beside the shaft (Z'/R > z_min; seed
    002 figure 3b) [-]."""
    g = geometry

    def x_over_l(xs):
        zr = xs[:, 2] - g.disc_z_m
        zr = zr - g.height_m * np.floor(zr / g.height_m + 0.5)
        return 1.0 - np.abs(zr) / (0.5 * g.height_m), _z_over_r(xs, g) > z_min

    c, p, n = _speed_profile(sample_x, sample_v, x_over_l, tip_speed_m_per_s, bins)
    return dict(x_over_l=c, speed_over_tip_speed=p, samples=n)


def return_leg(sample_x, sample_v, geometry: MillGeometry, omega_rad_per_s: float,
               bead_diameter_m: float, bead_density_kg_per_m3: float, fluid_density_kg_per_m3: float,
               fields: dict | None = None) -> dict:
    """The return leg of the rotor's circulation: beads and liquid between two rotors
    (|z - z_disc| > b/2) from the eye r_1 to the chamber wall r_w, where the beads thrown
    out at the rim would have to flow back in to the eye (plain JSON data, SI units).

    - ``k_beads``: the beads' mean swirl over the rotor's at their radius, mean of
      v_theta / (omega r) over the samples [-]; ``k_liquid`` the same for the liquid
      (volume-weighted over the fluid cells of the section fields, theta-averaged);
    - ``solids_fraction``: bead volume over the open volume of that region [-];
    - ``R``: the buoyant weight of such a return leg over the rotor's head (the shared
      analysis of the slice), phi (rho_b - rho_f) k^2 (r_w^2 - r_1^2) /
      (rho_f (r_2^2 - r_1^2)) with phi the solids fraction, k = k_beads and r_2 the rim:
      a circulation of the beads needs R < 1; None without a liquid (no head);
    - ``k_beads_profile``: k_beads in five equal radial bins from r_1 to r_w."""
    g = geometry
    r1, rw, r2 = g.eye_radius_m, g.chamber_radius_m, g.disc_radius_m
    hb = 0.5 * g.disc_thickness_m
    v_bead = math.pi / 6.0 * bead_diameter_m ** 3
    edges = np.linspace(r1, rw, 6)
    ks = []
    acc = np.zeros(5)
    cnt = np.zeros(5)
    counts = []
    for xs, vs in zip(sample_x, sample_v):
        xs = np.asarray(xs, float)
        vs = np.asarray(vs, float)
        r = np.hypot(xs[:, 0], xs[:, 1])
        zr = xs[:, 2] - g.disc_z_m
        zr -= g.height_m * np.floor(zr / g.height_m + 0.5)
        m = (r >= r1) & (r < rw) & (np.abs(zr) > hb)
        counts.append(int(m.sum()))
        if not m.any():
            continue
        vt = (-xs[m, 1] * vs[m, 0] + xs[m, 0] * vs[m, 1]) / r[m]
        k = vt / (omega_rad_per_s * r[m])
        ks.append(k)
        b = np.clip(np.searchsorted(edges, r[m], side="right") - 1, 0, 4)
        np.add.at(acc, b, k)
        np.add.at(cnt, b, 1.0)
    k_beads = float(np.concatenate(ks).mean()) if ks else None
    # open volume of the region in the simulated sector: the ring between the rotors, less
    # the baffles there
    vol = math.pi * (rw ** 2 - r1 ** 2) * (g.height_m - 2.0 * hb)
    if g.has_baffles:
        vol -= g.baffle_volume_m3() * (rw - max(r1, g.baffle_inner_radius_m)) / \
            (rw - g.baffle_inner_radius_m)
    vol *= g.sector_fraction
    phi = float(np.mean(counts)) * v_bead / vol if counts else None
    k_liq = None
    if fields is not None and "u_theta" in fields:
        rr = np.asarray(fields["r_m"])
        zeta = np.asarray(fields["zeta_m"])
        ut = np.asarray(fields["u_theta"])
        sel = ((rr >= r1) & (rr < rw))[:, None] & (np.abs(zeta) > hb)[None, :] & \
            np.isfinite(ut)
        if sel.any():
            w = np.broadcast_to(rr[:, None], ut.shape)[sel]
            k_liq = float(np.sum(ut[sel] / (omega_rad_per_s * w) * w) / np.sum(w))
    rb, rf = bead_density_kg_per_m3, fluid_density_kg_per_m3
    # without a liquid (rf 0) there is no head to weigh the leg against: R is not defined
    big_r = (phi * (rb - rf) * k_beads ** 2 * (rw ** 2 - r1 ** 2) / (rf * (r2 ** 2 - r1 ** 2))
             if k_beads is not None and phi is not None and rf > 0.0 else None)
    with np.errstate(invalid="ignore"):
        prof = acc / cnt
    return dict(
        region="between two rotors (|z - z_disc| > half the rotor's thickness), eye radius "
               "to chamber wall",
        k_beads=k_beads, k_liquid=k_liq, solids_fraction=phi, R=big_r,
        k_for_R_1=(math.sqrt(rf * (r2 ** 2 - r1 ** 2) / (phi * (rb - rf) * (rw ** 2 - r1 ** 2)))
                   if phi and rf > 0.0 else None),
        k_beads_profile=dict(r_m=list(np.round(0.5 * (edges[1:] + edges[:-1]), 6)),
                             k=[None if not np.isfinite(p) else round(float(p), 6)
                                for p in prof]))


def rotor_throughflow_m3_per_s(fields: dict, geometry: MillGeometry) -> float | None:
    """Volume flow [m3/s] the rotor pumps out at its rim (full circle), from the mean
    fluid fields of a coupled run (``u_r`` and ``eps`` on the section grid, ``r_m``,
    ``zeta_m`` the axial distance from the rotor mid-plane)."""
    if fields is None or "u_r" not in fields:
        return None
    r = np.asarray(fields["r_m"])
    zeta = np.asarray(fields["zeta_m"])
    ur = np.asarray(fields["u_r"])
    eps = np.asarray(fields.get("eps", np.ones_like(ur)))
    # the rim is a cell face: the mean of the two cells beside it
    i = int(np.searchsorted(r, geometry.disc_radius_m))
    if not 0 < i < r.size:
        return None
    m = np.abs(zeta) < 0.5 * geometry.channel_height_m
    if not m.any():
        return None
    flux = 0.5 * (eps[i - 1] * ur[i - 1] + eps[i] * ur[i])
    dz = geometry.height_m / zeta.size
    q = np.nansum(flux[m]) * dz * 2.0 * math.pi * geometry.disc_radius_m
    return float(q)
