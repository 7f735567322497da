"""Contacts present at an instant: the counting of a post-processor that reads saved frames.

The DEM records every bead-bead contact once, at its first overlap (the ``events`` of
:mod:`millfmu.dem.engine.kernels`). A simulation whose contacts are exported at a few
frames per second (seed 002: positions, velocities and contacts saved 20 times per second)
sees instead the contacts that happen to be present at each frame. Summed over the frames
and divided by the recording time, that count is a rate that grows with the frame rate and
with how long a contact lasts, not with how often beads meet: at 20 frames per second
the two counts differ by orders of magnitude (a contact lasts about 1e-4 s; a bead meets
another several hundred times per second in a packed bed).

:func:`contacts_present` takes one frame's state and returns its contacts with the same
energies the event record holds (relative normal velocity and relative spin, here at the
frame's instant instead of at the first overlap). Pure numpy, no numba.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Frame:
    """Bead-bead contacts present at one instant: ``point_m`` (n, 3) the middle of each
    overlap [m] (as the event record), ``vn2_m2_s2`` the squared relative normal velocity
    [m2/s2] and ``wrel2_rad2_s2`` the squared relative spin [rad2/s2] of each."""

    point_m: np.ndarray
    vn2_m2_s2: np.ndarray
    wrel2_rad2_s2: np.ndarray

    @property
    def count(self) -> int:
        return int(self.vn2_m2_s2.size)


def _rotate_z(a: np.ndarray, ang: np.ndarray) -> np.ndarray:
    """Vectors a (n, 3) turned about the z axis by ang (n,) [rad]."""
    c, s = np.cos(ang), np.sin(ang)
    out = a.copy()
    out[:, 0] = c * a[:, 0] - s * a[:, 1]
    out[:, 1] = s * a[:, 0] + c * a[:, 1]
    return out


def contacts_present(x_m, v_m_per_s, w_rad_per_s, radii_m, pairs, sector_rad: float,
                     period_m: float) -> Frame:
    """The bead-bead contacts (overlap > 0) among the candidate ``pairs`` (i, j, s): j's
    image turned by s x ``sector_rad`` about the axis (0 without a sector), the axial
    separation reduced to the nearest image over ``period_m`` [m] (the kernels'
    conventions, :meth:`millfmu.dem.engine.sim.Simulation._pairs`)."""
    x = np.asarray(x_m, float)
    v = np.asarray(v_m_per_s, float)
    w = np.asarray(w_rad_per_s, float)
    rad = np.broadcast_to(np.asarray(radii_m, float), (x.shape[0],))
    i, j, s = (np.asarray(a, np.int64) for a in pairs)
    if i.size == 0:
        return Frame(np.zeros((0, 3)), np.zeros(0), np.zeros(0))
    ang = s * sector_rad if sector_rad > 0 else np.zeros(i.size)
    xj, vj, wj = (_rotate_z(a[j], ang) for a in (x, v, w))
    d = x[i] - xj
    d[:, 2] -= period_m * np.round(d[:, 2] / period_m)
    r = np.sqrt(np.einsum("ij,ij->i", d, d))
    delta = rad[i] + rad[j] - r
    on = delta > 0.0
    n = d[on] / r[on, None]
    vn = np.einsum("ij,ij->i", v[i[on]] - vj[on], n)
    wr = w[i[on]] - wj[on]
    lev = rad[i[on]] - 0.5 * delta[on]
    return Frame(point_m=x[i[on]] - lev[:, None] * n, vn2_m2_s2=vn * vn,
                 wrel2_rad2_s2=np.einsum("ij,ij->i", wr, wr))


def frame_of(sim) -> Frame:
    """The contacts present in simulation ``sim`` now."""
    g = sim.geometry
    return contacts_present(sim.x, sim.v, sim.w, sim.rad, sim._pairs(), g.sector_rad,
                            g.height_m)


def every_kth(frames: list, interval_s: float, target_s: float) -> tuple[list, float] | None:
    """The frames at ``target_s`` [s] intervals taken from frames at ``interval_s``, and
    that interval, where target_s is a whole multiple of interval_s (>= 2) and at least one
    frame falls on it; else None."""
    k = target_s / interval_s
    if k < 1.5 or abs(k - round(k)) > 1e-6:
        return None
    k = int(round(k))
    sub = frames[k - 1::k]
    return (sub, k * interval_s) if sub else None
