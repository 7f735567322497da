"""A DEM run folder's statistics for comparing two runs: its stats.json without the wall-clock
counts (wall time, particle-steps per second), which differ from run to run."""

from __future__ import annotations

import json


def stats_without_wall_clock(folder) -> dict:
    d = json.loads((folder / "stats.json").read_text())
    for k in ("wall_time_s", "particle_steps_per_s"):
        d["counts"].pop(k)
    return d
