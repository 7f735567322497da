"""PNG maps and distributions of a DEM run (matplotlib, headless Agg backend).

Maps are in the axial section (axial position from the disc mid-plane, radius), averaged
over the angle ("radially averaged" in seed 001's words), like seed 001 figures 12-15.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from millfmu.dem.analysis.stats import BLOCK_ROWS


#: radial bins of the collision profile per bead diameter (``collision_maps.npz``)
PROFILE_BINS_PER_DIAMETER = 4


def _profile_edges(scene):
    """Radial bin edges [m] of :func:`radial_collision_profile`: 1 /
    :data:`PROFILE_BINS_PER_DIAMETER` bead diameter from the shaft to the chamber wall; None
    for a slice with other solids than a disc (vanes, baffles)."""
    g = scene.geometry
    if g.has_channel or g.has_baffles:
        return None
    width = scene.bead_diameter_m / PROFILE_BINS_PER_DIAMETER
    n_bins = max(1, int(round((g.chamber_radius_m - g.shaft_radius_m) / width)))
    return np.linspace(g.shaft_radius_m, g.chamber_radius_m, n_bins + 1)


def _binned(scene, events: np.ndarray, cols: dict, profile_edges=None):
    """One pass over the recorded contacts: the bead-bead collisions' counts and SE_total
    sums [J] on the axial section's bins (axial position from the disc mid-plane, radius)
    and, with ``profile_edges``, on those radial bins (every axial position together).
    Returns (z_edges, r_edges, n, s, profile n, profile s), the profile's None without
    edges."""
    g = scene.geometry
    zr_edges = np.linspace(-0.5 * g.height_m, 0.5 * g.height_m, scene.map_bins_z + 1)
    r_edges = np.linspace(g.shaft_radius_m, g.chamber_radius_m, scene.map_bins_r + 1)
    n = np.zeros((scene.map_bins_z, scene.map_bins_r))
    s = np.zeros_like(n)
    pn = ps = None
    if profile_edges is not None:
        pn = np.zeros(profile_edges.size - 1)
        ps = np.zeros_like(pn)
    # in blocks of rows: copying all bead-bead rows at once took 88 bytes per contact
    for i in range(0, events.shape[0] if events.size else 0, BLOCK_ROWS):
        blk = events[i:i + BLOCK_ROWS]
        bb = blk[blk[:, cols["type"]] == 0]
        x = bb[:, cols["x"]]
        y = bb[:, cols["y"]]
        z = bb[:, cols["z"]] - g.disc_z_m
        z = z - g.height_m * np.floor(z / g.height_m + 0.5)
        r = np.hypot(x, y)
        se = bb[:, cols["setn"]] + bb[:, cols["sets"]] + bb[:, cols["serot"]]
        n += np.histogram2d(z, r, bins=[zr_edges, r_edges])[0]
        s += np.histogram2d(z, r, bins=[zr_edges, r_edges], weights=se)[0]
        if pn is not None:
            pn += np.histogram(r, bins=profile_edges)[0]
            ps += np.histogram(r, bins=profile_edges, weights=se)[0]
    return zr_edges, r_edges, n, s, pn, ps


def _section_values(scene, zr_edges, r_edges, n, s):
    """(mean SE_total per collision [J], collision frequency [1/(m3 s)], collision power
    density [W/m3]) of the section's counts n and sums s."""
    ring = math.pi * np.diff(r_edges ** 2) * scene.geometry.sector_fraction
    vol = np.outer(np.diff(zr_edges), ring)
    t = scene.record_s
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_se = np.where(n > 0, s / n, np.nan)
    return mean_se, n / (vol * t), s / (vol * t)


def _profile_values(scene, edges, n, s):
    """(collision frequency [1/(m3 s)], collision power density [W/m3]) of the radial
    profile's counts n and sums s, per volume open to the beads: inside the disc's radius
    its thickness is taken out of the axial period."""
    g = scene.geometry
    rd = g.disc_radius_m if g.has_disc else g.shaft_radius_m
    thick = g.disc_thickness_m if g.has_disc else 0.0
    inner = np.diff(np.minimum(edges, rd) ** 2)  # the part of each ring inside the disc
    outer = np.diff(np.maximum(edges, rd) ** 2)
    vol = math.pi * g.sector_fraction * (inner * (g.height_m - thick) + outer * g.height_m)
    t = scene.record_s
    return n / (vol * t), s / (vol * t)


def section_maps(scene, events: np.ndarray, cols: dict):
    """Binned maps over (axial position [m], radius [m]) of bead-bead collisions:
    mean SE_total per collision [J], collision frequency [1/(m3 s)], collision power
    density [W/m3]. Returns (z_edges, r_edges, mean_se, freq, power)."""
    ze, re_, n, s, _, _ = _binned(scene, events, cols)
    return (ze, re_) + _section_values(scene, ze, re_, n, s)


def radial_collision_profile(scene, events: np.ndarray, cols: dict):
    """Bead-bead collisions of a plain disc slice (no vanes, no baffles) over the radius,
    every axial position together, on bins of 1 / :data:`PROFILE_BINS_PER_DIAMETER` bead
    diameter from the shaft to the chamber wall (seed 001 figure 13 reads a peak two bead
    diameters from the wall, finer than the maps' bins). Per volume open to the beads:
    inside the disc's radius its thickness is taken out of the axial period. Returns
    (r_edges [m], collision frequency [1/(m3 s)], collision power density [W/m3]), or None
    for a slice with other solids."""
    edges = _profile_edges(scene)
    if edges is None:
        return None
    *_, n, s = _binned(scene, events, cols, edges)
    return (edges,) + _profile_values(scene, edges, n, s)


def _sev_outline(ax, scene):
    """Rotor (shrouds, channel) and the SEV_1-4 boundaries of an accelerator slice."""
    g = scene.geometry
    mm = 1e3
    R = g.disc_radius_m
    hb = 0.5 * g.disc_thickness_m
    hc = 0.5 * g.channel_height_m
    for z0, z1 in ((-hb, -hc), (hc, hb)):
        ax.fill_between([z0 * mm, z1 * mm], g.eye_radius_m * mm, R * mm, color="0.6")
    ax.fill_between([-hc * mm, hc * mm], g.shaft_radius_m * mm, R * mm, color="0.85",
                    alpha=0.3)  # the channel with its vanes
    span = g.chamber_radius_m - g.shaft_radius_m
    z = scene.zones
    for zz in (z.z1, z.z2):
        ax.axhline((g.chamber_radius_m - zz * span) * mm, color="w", lw=1, ls="--")
    r2 = (g.chamber_radius_m - z.z2 * span) * mm
    for sgn in (-1, 1):
        x = sgn * (1.0 - z.x3) * 0.5 * g.height_m * mm  # X'/L = x3 (from the mid-plane)
        ax.plot([x, x], [g.shaft_radius_m * mm, r2], "w:", lw=1)


def _baffle_outline(ax, g):
    """Stationary baffles (a row of radial plates between the rotors: here, at both ends of
    the axial period) drawn as hatched outlines: they stand in one angle only, so the
    maps, averaged over the angle, have values there."""
    mm = 1e3
    half = 0.5 * g.height_m
    for z0, z1 in ((-half, -half + 0.5 * g.baffle_height_m), (half - 0.5 * g.baffle_height_m,
                                                             half)):
        ax.fill_between([z0 * mm, z1 * mm], g.baffle_inner_radius_m * mm,
                        g.chamber_radius_m * mm, facecolor="none", edgecolor="w",
                        hatch="//", lw=0.8)
    ax.text(0.0, g.chamber_radius_m * mm, "hatched: baffles (one per "
            f"{360 / g.baffle_count:g} degrees)", color="w", fontsize=7, ha="center",
            va="top")


def _zone_outline(ax, scene):
    g = scene.geometry
    if not g.has_disc:
        return
    if g.has_baffles:
        _baffle_outline(ax, g)
    if g.has_channel:
        _sev_outline(ax, scene)
        return
    mm = 1e3
    R = g.disc_radius_m
    hb = 0.5 * g.disc_thickness_m
    w1 = scene.zones.v1_width_m
    r1 = scene.zones.r_v1_over_disc_radius * R
    r3 = scene.zones.r_v3_over_disc_radius * R
    ax.fill_between([-hb * mm, hb * mm], g.shaft_radius_m * mm, R * mm, color="0.6")
    for sgn in (-1, 1):
        ax.plot([sgn * (hb + w1) * mm] * 2, [r1 * mm, g.chamber_radius_m * mm], "w:", lw=1)
        ax.plot([sgn * hb * mm, sgn * (hb + w1) * mm], [r1 * mm] * 2, "w:", lw=1)
    ax.plot([-0.5 * g.height_m * mm, -(hb + w1) * mm], [r3 * mm] * 2, "w--", lw=1)
    ax.plot([(hb + w1) * mm, 0.5 * g.height_m * mm], [r3 * mm] * 2, "w--", lw=1)
    ax.axhline(R * mm, color="w", lw=0.5, ls="-.")


def write_maps(out: Path, scene, events: np.ndarray, cols: dict):
    """The maps of :func:`section_maps` as PNG files in ``out``, and their numbers in
    ``collision_maps.npz`` (bin edges [m], mean SE_total [J], collision frequency
    [1/(m3 s)], collision power density [W/m3]; for a plain disc slice also
    :func:`radial_collision_profile` as ``profile_*``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    # the maps and the profile from one pass over the contacts (a full slice's are on disk)
    edges = _profile_edges(scene)
    ze, re_, n, s, pn, ps = _binned(scene, events, cols, edges)
    mean_se, freq, power = _section_values(scene, ze, re_, n, s)
    data = dict(z_edges_m=ze, r_edges_m=re_, mean_se_total_j=mean_se,
                collision_frequency_per_m3_s=freq, collision_power_w_per_m3=power)
    if edges is not None:
        pf, pp = _profile_values(scene, edges, pn, ps)
        data.update(profile_r_edges_m=edges, profile_collision_frequency_per_m3_s=pf,
                    profile_collision_power_w_per_m3=pp)
    np.savez(out / "collision_maps.npz", **data)
    items = [("map_stress_energy.png", mean_se, "mean SE_total per collision [J]", True),
             ("map_collision_frequency.png", freq, "collision frequency [1/(m3 s)]", False),
             ("map_collision_power.png", power, "collision power density [W/m3]", True)]
    for fname, data, label, log in items:
        fig, ax = plt.subplots(figsize=(6, 4.5))
        d = np.ma.masked_invalid(data.T)
        norm = None
        if log and np.isfinite(data).any() and (data > 0).any():
            pos = data[np.isfinite(data) & (data > 0)]
            norm = LogNorm(vmin=pos.min(), vmax=pos.max())
        m = ax.pcolormesh(ze * 1e3, re_ * 1e3, d, shading="flat", norm=norm, cmap="viridis")
        fig.colorbar(m, ax=ax, label=label)
        _zone_outline(ax, scene)
        ax.set_xlabel("axial position from the disc mid-plane [mm]")
        ax.set_ylabel("radius [mm]")
        # the figure's title, above the colour bar's offset label ("1e12"), which the axes'
        # title ran into on the right
        fig.suptitle(f"{scene.name}: v_tip {scene.tip_speed_m_per_s:.3g} m/s, filling "
                     f"{scene.filling if scene.filling is not None else '-'}, fluid "
                     f"{scene.fluid_mode}", fontsize=9)
        fig.tight_layout()
        fig.savefig(out / fname, dpi=110)
        plt.close(fig)


def write_seed002_maps(out: Path, scene, events: np.ndarray, cols: dict):
    """Seed 002's maps in the axial section (its figures 12-15): stress intensity SI, stress
    number SN_g, collision stress energy SE_cs = SI SN_g and its components SE_tn, SE_ts per
    volume and time, with the paper's definitions (bead mass and moment of inertia, see
    :mod:`millfmu.dem.mills.accelerator`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    g = scene.geometry
    ze = np.linspace(-0.5 * g.height_m, 0.5 * g.height_m, scene.map_bins_z + 1)
    re_ = np.linspace(g.shaft_radius_m, g.chamber_radius_m, scene.map_bins_r + 1)
    bb = events[events[:, cols["type"]] == 0] if events.size else events
    z = bb[:, cols["z"]] - g.disc_z_m
    z = z - g.height_m * np.floor(z / g.height_m + 0.5)
    r = np.hypot(bb[:, cols["x"]], bb[:, cols["y"]])
    # recorded with m* = m/2, I* = I/2 (equal beads); the paper's use the bead's m, I
    tn = 2.0 * bb[:, cols["setn"]]
    ts = 2.0 * bb[:, cols["serot"]]
    n, _, _ = np.histogram2d(z, r, bins=[ze, re_])
    s_tn, _, _ = np.histogram2d(z, r, bins=[ze, re_], weights=tn)
    s_ts, _, _ = np.histogram2d(z, r, bins=[ze, re_], weights=ts)
    vol = np.outer(np.diff(ze), math.pi * np.diff(re_ ** 2) * g.sector_fraction)
    t = scene.record_s
    with np.errstate(invalid="ignore", divide="ignore"):
        si = np.where(n > 0, (s_tn + s_ts) / n, np.nan)
    items = [("map_stress_intensity.png", si, "stress intensity SI per contact [J]"),
             ("map_stress_number.png", n / (vol * t), "stress number SN_g [1/(m3 s)]"),
             ("map_collision_stress_energy.png", (s_tn + s_ts) / (vol * t),
              "collision stress energy SE_cs [W/m3]"),
             ("map_se_tn.png", s_tn / (vol * t), "SE_tn per volume and time [W/m3]"),
             ("map_se_ts.png", s_ts / (vol * t), "SE_ts per volume and time [W/m3]")]
    for fname, data, label in items:
        fig, ax = plt.subplots(figsize=(6, 4.5))
        norm = None
        pos = data[np.isfinite(data) & (data > 0)]
        if pos.size:
            norm = LogNorm(vmin=pos.min(), vmax=pos.max())
        m = ax.pcolormesh(ze * 1e3, re_ * 1e3, np.ma.masked_invalid(
            np.where(data > 0, data, np.nan)).T, shading="flat", norm=norm, cmap="viridis")
        fig.colorbar(m, ax=ax, label=label)
        _zone_outline(ax, scene)
        ax.set_xlabel("axial position from the rotor mid-plane [mm]")
        ax.set_ylabel("radius [mm]")
        ax.set_title(f"{scene.name}: {scene.rotor_speed_rpm:.0f} rpm, filling "
                     f"{scene.filling}, fluid {scene.fluid_mode}", fontsize=9)
        fig.tight_layout()
        fig.savefig(out / fname, dpi=110)
        plt.close(fig)


def write_speed_profiles(path: Path, seed002: dict):
    """Bead speed over tip speed against Z'/R and X'/L (seed 002 figures 3 and 4)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.6))
    rp = seed002["radial_speed_profile"]
    a.plot(rp["z_over_r"], [np.nan if v is None else v for v in rp["speed_over_tip_speed"]],
           "o-")
    a.set_xlabel("Z'/R (0: chamber wall, 1: shaft)")
    a.set_ylabel("bead speed / tip speed [-]")
    ap = seed002["axial_speed_profile"]
    b.plot(ap["x_over_l"], [np.nan if v is None else v for v in ap["speed_over_tip_speed"]],
           "o-")
    b.set_xlabel("X'/L (0: between rotors, 1: rotor mid-plane)\nin the inner zones (SEV_3, SEV_4)")
    fig.suptitle(f"{seed002['rotor_speed_rpm']:.0f} rpm", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_distributions(path: Path, stats):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ...plotstyle import plain_log_ticks

    e = np.asarray(stats.se_bin_edges_j)
    mid = np.sqrt(e[:-1] * e[1:])
    fig, ax = plt.subplots(figsize=(6, 4))
    for z in stats.zones:
        ax.semilogx(mid, z.se["tn"].density_per_decade, label=f"{z.name} SE_tn")
    ax.set_xlabel("stress energy SE_tn [J]")
    ax.set_ylabel("number density [1/decade]")
    ax.legend(fontsize=8)
    plain_log_ticks(fig)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_fluid_maps(out: Path, scene, fields: dict):
    """Maps of the coupled fluid's time-mean fields in the axial section: swirl, radial
    velocity with its zero contour (seed 001 figure 7), axial velocity (all over the tip
    speed), turbulent viscosity and void fraction."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    zeta = np.asarray(fields["zeta_m"])
    order = np.argsort(zeta)
    zs = zeta[order] * 1e3
    r = np.asarray(fields["r_m"]) * 1e3
    vt = scene.tip_speed_m_per_s
    items = [("map_fluid_swirl.png", fields["u_theta"] / vt, "u_theta / v_tip", "viridis", False),
             ("map_fluid_radial.png", fields["u_r"] / vt, "u_r / v_tip (black: u_r = 0)",
              "RdBu_r", True),
             ("map_fluid_axial.png", fields["u_z"] / vt, "u_z / v_tip", "RdBu_r", False),
             ("map_turbulent_viscosity.png", fields["nu_t"], "nu_t [m2/s]", "magma", False),
             ("map_void_fraction.png", fields["eps"], "void fraction [-]", "cividis", False)]
    for fname, data, label, cmap, zero in items:
        d = np.ma.masked_invalid(np.asarray(data)[:, order])
        fig, ax = plt.subplots(figsize=(6, 4.5))
        kw = {}
        if cmap == "RdBu_r":
            lim = float(np.nanmax(np.abs(d))) if d.count() else 1.0
            kw = dict(vmin=-lim, vmax=lim)
        m = ax.pcolormesh(zs, r, d, shading="nearest", cmap=cmap, **kw)
        fig.colorbar(m, ax=ax, label=label)
        if zero and d.count():
            ax.contour(zs, r, d.filled(np.nan), levels=[0.0], colors="k", linewidths=1.0)
        _zone_outline(ax, scene)
        ax.set_xlabel("axial position from the disc mid-plane [mm]")
        ax.set_ylabel("radius [mm]")
        ax.set_title(f"{scene.name}: coupled fluid, v_tip {scene.tip_speed_m_per_s:g} m/s, "
                     f"filling {scene.filling if scene.filling is not None else '-'}",
                     fontsize=9)
        fig.tight_layout()
        fig.savefig(out / fname, dpi=110)
        plt.close(fig)


def write_swirl_profile(path: Path, scene, prof: dict):
    """Fluid and bead speed over the tip speed between the discs at the disc radius
    (seed 001 figures 9 and 10), over x/D from one disc face to the next."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = np.asarray(prof["x_over_gap"], float)
    fig, ax = plt.subplots(figsize=(6, 4))
    b = np.array([np.nan if v is None else v for v in prof["beads_speed_over_v_tip"]], float)
    ax.plot(x, b, "o-", ms=3, label="beads, mean speed")
    if "fluid_speed_over_v_tip" in prof:
        f = np.array([np.nan if v is None else v for v in prof["fluid_speed_over_v_tip"]],
                     float)
        ax.plot(x, f, "-", label="fluid, speed")
    w1 = scene.zones.v1_width_m / (scene.geometry.height_m - scene.geometry.disc_thickness_m)
    for xv in (w1, 1.0 - w1):
        ax.axvline(xv, color="r", lw=0.8)
    ax.set_xlabel("x / D between the disc faces at r = R [-]")
    ax.set_ylabel("speed / tip speed [-]")
    ax.set_title(f"{scene.name}: v_tip {scene.tip_speed_m_per_s:g} m/s, filling "
                 f"{scene.filling}; red: V1 borders", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_circumferential(path: Path, scene, circ: dict):
    """Where the beads sit round the circle of a full slice with gravity (``circ``, the
    run's ``flow.circumferential``): beads per azimuthal bin over the mean of the bins,
    the azimuth counted from the top (against gravity) in the direction of rotation; the
    rising half (the stirrer moving upwards, 180-360 degrees) shaded; beside it, where
    ``circ`` has them, the beads' centroid across the axis at each sample [mm]."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rel = np.asarray(circ["per_bin_over_mean"], float)
    w = float(circ["azimuth_bin_deg"])
    centres = w * (np.arange(rel.size) + 0.5)
    cr = np.asarray(circ.get("centroid_rising_m", ()), float) * 1e3
    cu = np.asarray(circ.get("centroid_up_m", ()), float) * 1e3
    if cr.size:
        fig, (ax, axc) = plt.subplots(1, 2, figsize=(10, 4),
                                      gridspec_kw=dict(width_ratios=[1.6, 1.0]))
    else:
        fig, ax = plt.subplots(figsize=(6, 4))
    ax.axvspan(180.0, 360.0, color="0.92", lw=0)
    ax.bar(centres, rel, width=0.85 * w, color="tab:blue")
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    lo, hi = float(rel.min()), float(rel.max())
    pad = max(0.02, 0.25 * (hi - lo))
    ax.set_ylim(min(lo - pad, 0.98), max(hi + pad, 1.02))
    ax.set_xlim(0.0, 360.0)
    ax.set_xticks(np.arange(0.0, 361.0, 60.0))
    ax.set_xlabel("azimuth from the top, in the direction of rotation [deg]")
    ax.set_ylabel("beads per bin / mean of the bins [-]")
    ax.set_title(f"{scene.name}: time mean of {circ['samples']} samples; shaded: rising "
                 f"half\nlargest / smallest bin {circ['largest_over_smallest_bin']:.3f}, "
                 f"rising / falling half {circ['rising_over_falling_half']:.3f}, upper / "
                 f"lower half {circ['upper_over_lower_half']:.3f}", fontsize=9)
    if cr.size:
        # the centroid's path: a bed whose denser part travels round draws a loop
        axc.plot(cr, cu, color="0.6", lw=0.8, zorder=1)
        sc = axc.scatter(cr, cu, c=np.arange(cr.size), cmap="viridis", s=14, zorder=2)
        axc.plot([cr.mean()], [cu.mean()], "k+", ms=12, mew=1.5, zorder=3)
        axc.axhline(0.0, color="k", lw=0.6, ls=":")
        axc.axvline(0.0, color="k", lw=0.6, ls=":")
        m = max(float(np.abs(np.r_[cr, cu]).max()) * 1.15, 0.05)
        axc.set_xlim(-m, m)
        axc.set_ylim(-m, m)
        axc.set_aspect("equal")
        axc.set_xlabel("towards the rising side [mm]")
        axc.set_ylabel("upwards [mm]")
        axc.set_title(f"the beads' centroid across the axis, per sample\n+: time mean "
                      f"({cr.mean():.2f}, {cu.mean():.2f}) mm", fontsize=9)
        fig.colorbar(sc, ax=axc, label="sample (in order)", fraction=0.046, pad=0.04)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
