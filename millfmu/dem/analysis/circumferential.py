"""Where the beads sit round the circle of a full slice with gravity across the axis
(pure numpy): beads per azimuthal bin, counted from the top (against gravity) in the
direction of rotation; the rising half (where the stirrer moves upwards) over the falling
half; the upper half over the lower. Seed 001 reports an asymmetry of this kind for its
horizontal mill, seed 002 (figure 8) the beads per sector over their mean. A sector, or a
slice without gravity across the axis, has none of these (rotational symmetry).

Used for one instant by ``millfmu dem progress`` and for the time mean over a run's
recording by :mod:`millfmu.dem.run` (``flow.circumferential``).
"""

from __future__ import annotations

import math

import numpy as np

#: azimuthal bins of the circumferential distribution [deg]
AZIMUTH_BIN_DEG = 30.0


def circumferential(x, gravity_m_per_s2, sector_deg: float) -> dict:
    """The circumferential distribution of the beads at positions ``x`` [m] (module
    docstring): one instant (x an array (n, 3)) or the time mean over samples (a sequence
    of (n_i, 3) arrays, or an array (samples, n, 3)); {} without gravity across the axis or
    in a sector. beads_per_bin: mean beads per bin; per_bin_over_mean: each bin over the
    mean of the bins (seed 002's figure 8 measure); the ratios are those of the bead counts
    summed over the samples. centroid_rising_m, centroid_up_m: the beads' mean position
    across the axis at each sample [m], towards the rising side and upwards; with equal
    beads the centre of mass, whose offset towards the rising side makes the weight's
    torque about the axis (in a turning bed it travels round with the bed)."""
    gx, gy = float(gravity_m_per_s2[0]), float(gravity_m_per_s2[1])
    gn = math.hypot(gx, gy)
    if gn == 0.0 or sector_deg < 360.0:
        return {}
    # one instant, or samples (each its own bead count: a subset, e.g. one radial ring)
    samples = [x] if isinstance(x, np.ndarray) and x.ndim == 2 else list(x)
    if not samples:
        return {}
    # azimuth from the top (the direction against gravity), positive with the rotation
    # (+z, counter-clockwise seen from +z)
    top = math.atan2(-gy, -gx)
    nb = int(round(360.0 / AZIMUTH_BIN_DEG))
    counts = np.zeros(nb, np.int64)
    rising = upper = n = 0
    # unit vectors across the axis: up (against gravity) and towards the rising side (up
    # turned by -90 degrees about +z: where the stirrer, turning about +z, moves upwards)
    ux, uy = -gx / gn, -gy / gn
    hx, hy = uy, -ux
    c_rise, c_up = [], []
    for xs in samples:
        xs = np.asarray(xs)
        c_rise.append(float(np.mean(xs[:, 0] * hx + xs[:, 1] * hy)) if xs.size else 0.0)
        c_up.append(float(np.mean(xs[:, 0] * ux + xs[:, 1] * uy)) if xs.size else 0.0)
        phi = np.mod(np.arctan2(xs[:, 1], xs[:, 0]) - top, 2.0 * math.pi)
        counts += np.bincount(np.minimum((phi / (2.0 * math.pi) * nb).astype(int), nb - 1),
                              minlength=nb)
        # the stirrer moves upwards (against gravity) where (e_z x r) . (-g) > 0: past the
        # top by 180-360 degrees in the direction of rotation
        rising += int(np.sum(phi > math.pi))
        upper += int(np.sum((phi < 0.5 * math.pi) | (phi > 1.5 * math.pi)))
        n += xs.shape[0]
    k = len(samples)
    return dict(azimuth_bin_deg=AZIMUTH_BIN_DEG, samples=k,
                beads_per_bin=counts.tolist() if k == 1 else (counts / k).tolist(),
                per_bin_over_mean=(counts / max(counts.mean(), 1e-300)).tolist(),
                largest_over_smallest_bin=float(counts.max() / max(counts.min(), 1)),
                rising_over_falling_half=float(rising / max(n - rising, 1)),
                upper_over_lower_half=float(upper / max(n - upper, 1)),
                centroid_note="the beads' centroid (mean position) across the axis [m], per "
                              "sample: towards the rising side and upwards",
                centroid_rising_m=c_rise, centroid_up_m=c_up)


def summary_line(circ: dict) -> str:
    """One line of a run's printed summary for ``circ`` (:func:`circumferential` of the
    recording): the halves, the bins' range and the centroid's mean and largest distance
    from the axis [mm]; "" where there is none."""
    if not circ:
        return ""
    rel = np.asarray(circ["per_bin_over_mean"], float)
    line = (f"circumferential (time mean of {circ['samples']} samples): rising / falling half "
            f"{circ['rising_over_falling_half']:.3f}, upper / lower "
            f"{circ['upper_over_lower_half']:.3f}, beads per {circ['azimuth_bin_deg']:.0f} "
            f"degrees {rel.min():.3f}-{rel.max():.3f} of their mean")
    cr = np.asarray(circ.get("centroid_rising_m", ()), float)
    cu = np.asarray(circ.get("centroid_up_m", ()), float)
    if cr.size:
        line += (f"; the beads' centroid on average {cr.mean() * 1e3:.2f} mm towards the "
                 f"rising side and {cu.mean() * 1e3:.2f} mm up, at most "
                 f"{np.hypot(cr, cu).max() * 1e3:.2f} mm from the axis")
    return line
