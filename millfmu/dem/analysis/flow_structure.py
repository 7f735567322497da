"""Structure of the mean flow in the axial section of a disc slice (pure numpy): the
meridional stream function and its vortices, the fluid's and the beads' swirl between the
discs, and the angular velocity of the first bead layer at the disc (seed 001 section 3.2,
figures 6, 7, 9 and 10).

Coordinates: radius r [m] from the axis, axial position zeta [m] from the disc mid-plane
(folded into the half period [-L/2, L/2)).
"""

from __future__ import annotations

import math

import numpy as np


def stream_function(r_c, flux_z, dr):
    """Meridional stream function psi [m3/s / rad] on cell centres (n_r, n_z) of an
    axisymmetric mean flow from its axial volume flux density flux_z = eps u_z [m/s]
    (cell centres): psi(r) = integral from the shaft of r' flux_z dr' (so that
    flux_r = -1/r dpsi/dzeta and flux_z = 1/r dpsi/dr)."""
    return np.cumsum(r_c[:, None] * flux_z * dr[:, None], axis=0) - \
        0.5 * (r_c * dr)[:, None] * flux_z


def vortices(psi, r_c, zeta_c, disc_radius_m, half_thickness_m, valid=None,
             threshold: float = 0.01, tip_zone_top_m: float | None = None):
    """Vortices of the mean flow in the half slice above the disc face
    (half_thickness <= zeta < L/2): the connected regions (8-neighbourhood) where psi keeps
    one sign and |psi| exceeds ``threshold`` times the largest |psi| there (psi is 0 on the
    walls, so each closed-streamline region is such a region; two extrema inside one region
    are one vortex). Returns a list of dicts, strongest first, with the centre (r_m, zeta_m:
    the region's extremum), sign (+1: counter-clockwise in the (r, zeta) plane seen with r up
    and zeta to the right), strength (|psi| at the centre over the largest) and region:
    'disc tip to wall' for a centre beyond the disc radius below ``tip_zone_top_m`` (seed
    001's V2, the disc's half thickness plus the V1 width; default: the half thickness plus
    2.5 mm), else 'between discs'."""
    top = half_thickness_m + 2.5e-3 if tip_zone_top_m is None else tip_zone_top_m
    nr, nz = psi.shape
    sel_z = (zeta_c >= half_thickness_m) & (zeta_c > 0)
    ok = np.ones_like(psi, bool) if valid is None else valid.copy()
    ok &= sel_z[None, :]
    amax = float(np.abs(psi[ok]).max()) if ok.any() else 0.0
    if amax == 0.0:
        return []
    strong = ok & (np.abs(psi) > threshold * amax)
    label = np.full(psi.shape, -1, np.int64)
    out = []
    for i0 in range(nr):
        for k0 in range(nz):
            if not strong[i0, k0] or label[i0, k0] >= 0:
                continue
            sgn = np.sign(psi[i0, k0])
            lab = len(out)
            stack = [(i0, k0)]
            label[i0, k0] = lab
            best = (abs(psi[i0, k0]), i0, k0)
            while stack:
                i, k = stack.pop()
                for di in (-1, 0, 1):
                    for dk in (-1, 0, 1):
                        a, b = i + di, k + dk
                        if 0 <= a < nr and 0 <= b < nz and strong[a, b] and \
                                label[a, b] < 0 and np.sign(psi[a, b]) == sgn:
                            label[a, b] = lab
                            stack.append((a, b))
                            if abs(psi[a, b]) > best[0]:
                                best = (abs(psi[a, b]), a, b)
            _, i, k = best
            r, z = float(r_c[i]), float(zeta_c[k])
            out.append(dict(r_m=r, zeta_m=z, sign=int(sgn), strength=float(best[0] / amax),
                            region="disc tip to wall" if r >= disc_radius_m and z < top
                            else "between discs"))
    out.sort(key=lambda v: -v["strength"])
    return out


def vortex_summary(found) -> dict:
    """Census of :func:`vortices`: ``large``, the vortices of at least half the strongest's
    strength (seed 001's "one large vortex between the discs"); ``between_discs``, the large
    ones there; ``disc_tip_to_wall``, the vortices turning against the strongest with their
    centre between disc tip and chamber wall (its "secondary, smaller vortex"), of any
    strength above the census threshold; and the list."""
    main = found[0]["sign"] if found else 0
    return {"large": sum(v["strength"] >= 0.5 for v in found),
            "between_discs": sum(v["strength"] >= 0.5 and v["region"] == "between discs"
                                 for v in found),
            "disc_tip_to_wall": sum(v["region"] == "disc tip to wall" and v["sign"] == -main
                                    for v in found),
            "vortices": found}


def fold_zeta(z, disc_z_m, period_m):
    """Axial position [m] from the disc mid-plane, folded into [-L/2, L/2)."""
    zr = np.asarray(z) - disc_z_m
    return zr - period_m * np.floor(zr / period_m + 0.5)


#: seed 001's first bead layer: bead centres within this many bead diameters of a disc face
#: (its 0.6 mm for its 0.8 mm beads, section 3.2); what the run statistics'
#: ``first_bead_layer_*`` and ``dem progress`` measure
FIRST_LAYER_DIAMETERS = 0.75


def first_layer_angular_velocity(sample_x, sample_v, geometry, omega_rad_per_s,
                                 max_distance_m):
    """Mean angular velocity about the axis, over the stirrer's, of the beads whose centre
    lies within ``max_distance_m`` [m] of a disc face (between the shaft and the disc rim):
    seed 001's "first layer" at the disc (section 3.2: within 0.6 mm of the disc the
    angular velocity is 20-26 % of the stirrer's). omega_i = v_perp / r with v_perp the bead
    velocity across the radius in the plane normal to the axis. Returns (ratio, bead samples
    used)."""
    g = geometry
    acc = 0.0
    n = 0
    for x, v in zip(sample_x, sample_v):
        r = np.hypot(x[:, 0], x[:, 1])
        zeta = fold_zeta(x[:, 2], g.disc_z_m, g.height_m)
        gap = np.abs(zeta) - 0.5 * g.disc_thickness_m
        m = (gap >= 0) & (gap < max_distance_m) & (r < g.disc_radius_m)
        vperp = (x[m, 0] * v[m, 1] - x[m, 1] * v[m, 0]) / r[m]
        acc += float((vperp / r[m]).sum())
        n += int(m.sum())
    return (acc / n / omega_rad_per_s if n else float("nan")), n


def bead_section_fields(sample_x, sample_v, radii_m, geometry, r_edges, zeta_edges,
                        bulk_porosity: float = 0.4):
    """Time-mean bead fields on (r, zeta) bins: solids volume fraction [-], mean bead
    velocity components (u_r, u_theta, u_z) [m/s] and solids volume flux density
    (phi u_z) [m/s]; bins without beads hold NaN velocities."""
    g = geometry
    nr, nz = r_edges.size - 1, zeta_edges.size - 1
    vol = np.zeros((nr, nz))
    mom = np.zeros((3, nr, nz))
    cnt = np.zeros((nr, nz))
    vb = 4.0 / 3.0 * math.pi * np.asarray(radii_m) ** 3
    vb = np.broadcast_to(vb, (sample_x[0].shape[0],)) if np.ndim(vb) else \
        np.full(sample_x[0].shape[0], float(vb))
    for x, v in zip(sample_x, sample_v):
        r = np.hypot(x[:, 0], x[:, 1])
        zeta = fold_zeta(x[:, 2], g.disc_z_m, g.height_m)
        ur = (x[:, 0] * v[:, 0] + x[:, 1] * v[:, 1]) / r
        ut = (x[:, 0] * v[:, 1] - x[:, 1] * v[:, 0]) / r
        i = np.clip(np.searchsorted(r_edges, r) - 1, 0, nr - 1)
        k = np.clip(np.searchsorted(zeta_edges, zeta) - 1, 0, nz - 1)
        np.add.at(vol, (i, k), vb)
        np.add.at(cnt, (i, k), 1.0)
        for c, u in enumerate((ur, ut, v[:, 2])):
            np.add.at(mom[c], (i, k), vb * u)
    ns = max(len(sample_x), 1)
    ring = math.pi * np.diff(r_edges ** 2) * g.sector_fraction
    cell = np.outer(ring, np.diff(zeta_edges))
    phi = vol / ns / cell
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(vol > 0, mom / vol, np.nan)
    return dict(solids_fraction=phi, u_r=u[0], u_theta=u[1], u_z=u[2],
                flux_z=np.nan_to_num(phi * u[2]), samples=cnt)
