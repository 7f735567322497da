"""Key results of several ``millfmu dem run`` folders side by side (``millfmu dem compare``).

Made for sensitivity checks of one operating point: sector size, grid, time step, run
length. Each row is one quantity read from the runs' ``stats.json``; each column one run,
with the relative difference to the first run (the reference) in brackets.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from millfmu.unit_names import modernize

ZONES = ("V1", "V2", "V3", "V4")


class CompareError(ValueError):
    """A folder that is not a finished DEM run."""


def load_run(path) -> dict:
    """The ``stats.json`` of a run folder (or the file itself), its names in the current
    spelling (:mod:`millfmu.unit_names`)."""
    p = Path(path)
    if p.is_dir():
        p = p / "stats.json"
    if not p.is_file():
        raise CompareError(f"run {str(path)!r}: no stats.json (not a finished "
                           "'millfmu dem run' folder)")
    try:
        st = modernize(json.loads(p.read_text()))
    except (OSError, ValueError) as e:
        raise CompareError(f"run {str(path)!r}: stats.json unreadable: {e}") from None
    if not isinstance(st, dict) or "zones" not in st:
        raise CompareError(f"run {str(path)!r}: stats.json has no 'zones' (not a DEM run)")
    return st


def zone(st, name) -> dict | None:
    """The zone ``name`` of a run's stats (None if the run has no such zone)."""
    return next((z for z in st["zones"] if z["name"] == name), None)


def _zq(name, key):
    def f(st):
        z = zone(st, name)
        return None if z is None else z.get(key)
    return f


def _median_tn(name):
    def f(st):
        z = zone(st, name)
        try:
            return z["se"]["tn"]["quantiles_j"]["q50"]
        except (TypeError, KeyError):
            return None
    return f


def chamber_collision_density(st) -> float:
    """Collision density of all zones together [1/(m3 s)] (volume-weighted mean)."""
    vol = sum(z["volume_m3"] for z in st["zones"])
    return sum(z["collision_frequency_per_m3_s"] * z["volume_m3"] for z in st["zones"]) / vol


def _flow(*keys):
    def f(st):
        d = st.get("flow", {})
        for k in keys:
            if not isinstance(d, dict) or k not in d:
                return None
            d = d[k]
        return d
    return f


def _weight_share(st):
    """The beads' weight's angular impulse over the stirrer's drive [-] (full slices with
    gravity across the axis; None where the budget has no such entry)."""
    w = _flow("angular_momentum_budget", "gravity_nms")(st)
    d = _flow("angular_momentum_budget", "stirrer_drive_nms")(st)
    return None if w is None or not d else w / d


def _centroid_mean(key):
    """Time mean [m] of the per-sample centroid list ``key`` of flow.circumferential."""
    get = _flow("circumferential", key)

    def f(st):
        v = get(st)
        return None if not v else sum(v) / len(v)
    return f


def _grid(st):
    g = st.get("flow", {}).get("fluid", {}).get("grid")
    if not g:
        return None
    dr = g["dr_m"][0] if isinstance(g.get("dr_m"), list) else g.get("dr_m")
    return f"{g['n_r']} x {g['n_theta']} x {g['n_z']}, dr {dr * 1e3:.2f} mm"


#: (label, function of stats.json, unit, compared relatively)
QUANTITIES = (
    [("beads", lambda st: st.get("beads"), "", False),
     ("sector", lambda st: st.get("sector_deg"), "deg", False),
     ("fluid grid (r x theta x z)", _grid, "", False),
     ("spin-up + recording", lambda st: f"{st['spin_up_s']:.3g} + {st['record_s']:.3g}", "s",
      False)]
    + [(f"bead speed / tip speed {z}", _zq(z, "speed_over_tip_speed"), "-", True)
       for z in ZONES]
    + [(f"local filling {z}", _zq(z, "filling"), "-", True) for z in ZONES]
    + [(f"collision density {z}", _zq(z, "collision_frequency_per_m3_s"), "1/(m3 s)", True)
       for z in ZONES]
    + [("collision density, chamber", chamber_collision_density, "1/(m3 s)", True)]
    + [(f"median SE_tn {z}", _median_tn(z), "J", True) for z in ZONES]
    + [("first bead layer / disc angular velocity",
        _flow("first_bead_layer_angular_velocity_ratio"), "-", True),
       ("power number", _flow("power_number", "value"), "-", True),
       ("stirrer torque: fluid shear share",
        lambda st: (lambda t: None if not t else t["stirrer_fluid_shear_nm"] /
                    t["stirrer_total_nm"])(st.get("flow", {}).get("torque")), "-", True),
       ("angular-momentum budget closure",
        _flow("angular_momentum_budget", "closure_rel"), "-", False),
       ("weight's angular impulse / stirrer drive", _weight_share, "-", False),
       ("rising / falling half (full slice with gravity)",
        _flow("circumferential", "rising_over_falling_half"), "-", True),
       ("upper / lower half (full slice with gravity)",
        _flow("circumferential", "upper_over_lower_half"), "-", True),
       ("beads' centroid towards the rising side, time mean",
        _centroid_mean("centroid_rising_m"), "m", False),
       ("beads' centroid upwards, time mean", _centroid_mean("centroid_up_m"), "m", False),
       ("kinetic energy trend over the recording",
        lambda st: st.get("kinetic_energy", {}).get("rel_trend_over_record"), "-", False),
       ("vortices (fluid): between discs / disc tip to wall",
        lambda st: (lambda v: None if not v else
                    f"{v.get('between_discs')} / {v.get('disc_tip_to_wall')}")(
            st.get("flow", {}).get("vortices_fluid")), "", False),
       ("particle-steps per second", lambda st: st.get("counts", {}).get(
           "particle_steps_per_s"), "1/s", False)])


def _fmt(v):
    if v is None:
        return "n/a"
    if isinstance(v, str):
        return v
    if isinstance(v, float):
        return f"{v:.4g}" if math.isfinite(v) else str(v)
    return str(v)


def compare_rows(paths) -> list[list[str]]:
    """Rows [quantity (unit), run 1, run 2 (+x % against run 1), ...]."""
    runs = [load_run(p) for p in paths]
    rows = []
    for label, fn, unit, rel in QUANTITIES:
        vals = []
        for st in runs:
            try:
                vals.append(fn(st))
            except (KeyError, TypeError, ZeroDivisionError):
                vals.append(None)
        if all(v is None for v in vals):
            continue
        cells = [_fmt(vals[0])]
        for v in vals[1:]:
            c = _fmt(v)
            if rel and isinstance(v, (int, float)) and isinstance(vals[0], (int, float)) \
                    and vals[0]:
                c += f" ({(v / vals[0] - 1.0) * 100:+.1f} %)"
            cells.append(c)
        rows.append([f"{label} [{unit}]" if unit else label] + cells)
    return rows


def markdown(paths) -> str:
    rows = compare_rows(paths)
    names = [Path(p).name or str(p) for p in paths]
    if len(set(names)) < len(names):  # same folder names in different places
        names = ["/".join(Path(p).resolve().parts[-2:]) for p in paths]
    lines = ["| quantity | " + " | ".join(names) + " |",
             "|---" * (len(names) + 1) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)
