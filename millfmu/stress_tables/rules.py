"""How the mill model uses a stress-energy table: which model inputs and scene keys set the
table's axes (so that a refusal names what the user gave), what an FMU adds to a refusal of
a point outside its table, how a table that cannot be read is rebuilt, and the warnings a
DEM table's recording resolution calls for.

:class:`millfmu.mill.MillModel` imports this module for every scene, so it loads nothing of
the table's reading and lookup until a scene names a table (standard library only).
"""

from __future__ import annotations

import math

#: Axes of a stress-energy table that are model inputs: axis -> input name. A table that
#: refuses an input value (outside its grid) gives an InputError naming the input.
TABLE_INPUTS = {"tip_speed_m_per_s": "tip_speed_m_per_s", "filling": "bead_filling"}
TABLE_INPUTS_CHECKED = tuple(TABLE_INPUTS.values())
#: Table axis -> the scene key that sets it (for a SceneError when the scene lies outside).
TABLE_SCENE_KEYS = {"tip_speed_m_per_s": "mill.tip_speed_m_per_s", "filling": "mill.bead_filling",
                    "bead_diameter_m": "beads.diameter_m",
                    "bead_density_kg_per_m3": "beads.density_kg_per_m3",
                    "viscosity_Pa_s": "suspension.viscosity_Pa_s"}


#: What an FMU adds to a refusal of a point outside its table where the scene asks for
#: on-demand builds (on_outside = 'build'): an FMU carries no DEM.
NO_DEM_NOTE = ("; an FMU carries no DEM, so on_outside = 'build' acts as 'refuse' here: it "
               "carries the table that millfmu build-fmu built for the scene's operating point "
               "(build the FMU again from a scene at the new point to carry a table that covers it)")


def rebuild_hint(ref: str) -> str:
    """How to get a usable table where the one a scene names (``ref``: "default", a shipped
    name or a file prefix) cannot be read."""
    if ref == "default":
        # Imported here: this module is loaded for every scene, the table module only for
        # scenes that name a table.
        from .table import REBUILD_DEFAULT

        return f"reinstall millfmu, or rebuild it (from the repository root) with `{REBUILD_DEFAULT}`"
    return (f"rebuild it with `millfmu tables build ... --export {ref}` (the command is the rebuild_command "
            f"of an intact copy of {ref}.json), or name another table")


def recording_warnings(manifest: dict) -> list:
    """Warnings for a DEM table whose recordings are too short to average the bead motion:
    shorter than one stirrer revolution at the grid's lowest tip speed (2 pi R / v_t [s], R
    the disc radius [m], v_t the tip speed [m/s]), or with fewer than 4 sampling windows
    (then the drift between the recording's halves, part of the stated error, is not
    measured). Tables from other builders have no DEM resolution."""
    dem = (manifest.get("resolution") or {}).get("dem")
    if not dem:
        return []
    rec, every = float(dem.get("record_s", 0.0)), float(dem.get("sample_every_s", 0.0))
    radius = float((manifest.get("scene") or {}).get("mill", {}).get("disc_radius_m", 0.0))
    speeds = ((manifest.get("grid") or {}).get("tip_speed_m_per_s")
              or [(manifest.get("scene") or {}).get("mill", {}).get("tip_speed_m_per_s", 0.0)])
    v_min = min(float(v) for v in speeds)
    turn = 2.0 * math.pi * radius / v_min if radius > 0.0 and v_min > 0.0 else 0.0
    out = []
    if rec < turn:
        out.append(f"stress-energy table {manifest.get('key', '?')[:12]}: built from DEM recordings of {rec:g} s, "
                   f"shorter than one stirrer revolution at its lowest tip speed ({turn:.3g} s at {v_min:g} m/s); its "
                   "zone statistics may not be representative: rebuild it with a longer --record")
    if every > 0.0 and rec < 4.0 * every:
        out.append(f"stress-energy table {manifest.get('key', '?')[:12]}: {rec:g} s recordings sampled every {every:g} "
                   "s give fewer than 4 windows: the drift within the recordings, part of the stated error, is not "
                   "measured")
    return out
