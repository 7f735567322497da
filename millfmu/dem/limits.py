"""What the DEM's scenes accept, as numbers: the operating ranges of each scene kind
(tip speed, filling), checked by :func:`millfmu.dem.scene.scene_from_dict` when a DEM scene
is made and read here by whoever must know before a DEM run whether a point can be built
(a table extended on demand, :mod:`millfmu.stress_tables.stress_source`).

Imports nothing: knowing the ranges must not load the DEM engine (or numba).
"""

from __future__ import annotations

import math

#: disc_slice: tip speed [m/s] and bead filling [-], the ranges of seed 001.
DISC_SLICE_TIP_SPEED_M_PER_S = (6.0, 14.0)
DISC_SLICE_FILLING = (0.5, 0.9)
#: accelerator_slice: rotor speed [1/min] (seed 002: 800-1400 rpm, and 400 rpm in its
#: section 3.2) and bead filling [-] (seed 002: 0.6-0.9).
ACCELERATOR_RPM_RANGE = (400.0, 1600.0)
ACCELERATOR_FILLING = (0.5, 0.9)
#: coupled liquid: the widest theta cell [rad] of its grid (n_theta > 1)
MAX_THETA_CELL_RAD = 0.5


def least_theta_cells(sector_rad: float) -> int:
    """The fewest theta cells (above one) a sector of ``sector_rad`` [rad] may be cut into:
    cells no wider than MAX_THETA_CELL_RAD."""
    return math.ceil(sector_rad / MAX_THETA_CELL_RAD - 1e-12)


def point_ranges(scene: dict) -> dict:
    """Table axis -> (lo, hi, why) that the DEM scene ``scene`` (the TOML content as a dict,
    as a table's manifest keeps it) accepts; {} for a scene without limits (annulus, or no
    DEM scene: an analytic builder's)."""
    kind = scene.get("kind")
    if kind == "disc_slice":
        return {"tip_speed_m_per_s": (*DISC_SLICE_TIP_SPEED_M_PER_S, "the range of seed 001"),
                "filling": (*DISC_SLICE_FILLING, "the range of seed 001")}
    if kind == "accelerator_slice":
        out = {"filling": (*ACCELERATOR_FILLING, "seed 002: 0.6-0.9")}
        r = (scene.get("mill") or {}).get("rotor_radius_m")
        if isinstance(r, (int, float)) and r > 0:
            lo, hi = (n * 2.0 * math.pi / 60.0 * r for n in ACCELERATOR_RPM_RANGE)
            out["tip_speed_m_per_s"] = (lo, hi, f"{ACCELERATOR_RPM_RANGE[0]:g} to "
                                    f"{ACCELERATOR_RPM_RANGE[1]:g} rpm at rotor radius {r:g} m")
        return out
    return {}


def outside_dem(scene: dict, axis: str, value: float) -> str | None:
    """Why the DEM scene cannot run at ``axis = value`` (its range, in words), or None where
    it can (or the scene sets no limit on that axis)."""
    rng = point_ranges(scene).get(axis)
    if rng is None:
        return None
    lo, hi, why = rng
    if lo - 1e-9 * abs(lo) <= value <= hi + 1e-9 * abs(hi):
        return None
    return f"the DEM scene {scene.get('name', '?')} ({scene.get('kind')}) builds {lo:.6g} to {hi:.6g} only ({why})"
