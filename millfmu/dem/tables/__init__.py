"""Building stress-energy lookup tables: DEM results on a grid of operating points, cached on disk.

A DEM run takes minutes; a kinetics step takes microseconds. A table holds, for a grid of
operating points, what the detailed breakage model needs from the DEM, per zone, with
energies over the bead's kinetic energy at tip speed and collision rates over omega n_gb.
Reading a table (its format, files, lookup and the kinetics' stress source) is
:mod:`millfmu.stress_tables`, what an FMU carries; this package builds tables through it.

The modules, by role:

- :mod:`.build`: a builder run over the grid (serially, process pool, Dask) and assembled;
- :mod:`.cache`: the cache of built tables, its locks and the DEM kernel version;
- :mod:`.equivalence`: source changes of round-off only, accepted as the tables' kernel
  version on the evidence of runs scored against the version's own realizations (the
  runs, made from a checkout: ``python -m validation.equivalence_runs``);
- :mod:`.dem_builder`: the DEM as a builder (:class:`DemBuilder`), the DEM cell of a point
  (:func:`dem_scene_at_point`: a wider sector where its beads do not fit), DEM table specs and
  rebuilds that cover a new point;
- :mod:`.on_demand`: builds that extend a table to a new point, their cost and the
  policies for a table of another DEM kernel version;
- :mod:`.warm_start`: each point's settled state kept beside its result, and new points
  with the same beads started from the nearest with a short spin-up;
- :mod:`.cli`: ``millfmu tables``.

The names of the former single module stay importable from here, the reader's among them
(``from millfmu.dem.tables import Table`` is :class:`millfmu.stress_tables.table.Table`),
for the command line and the callers of that module. This package imports none of its
modules until one of its names is used: ``millfmu.dem.tables.X`` loads the module that
defines X.
"""

from __future__ import annotations

import importlib

#: Name -> the module that defines it: one of this package, or of the reader's package
#: (see _READER).
_EXPORTS = {
    **dict.fromkeys((
        "AXES", "COMPONENTS", "COUPLED_SPIN_UP_S", "DEM_BUILDER_ID", "DRIFT_FIELDS", "FIELDS",
        "FORMAT_VERSION", "NORM_BINS_PER_DECADE", "NORM_LOG10_MAX", "NORM_LOG10_MIN",
        "OPTIONAL_FIELDS", "QUANTILE_NAMES", "STEADY_SPIN_UP_S", "ZONE_FIELDS", "TableError",
        "TableSpec", "builder_id_of", "e_ref_J", "manifest_for", "n_gb_per_m3",
        "norm_log10_edges", "resolution_of", "scene_at_point"), "spec"),
    **dict.fromkeys((
        "MANIFEST_FILE", "MANIFEST_SUM_FILE", "MANIFEST_SUM_KEY", "TABLE_FILE",
        "canonical_json", "manifest_digest", "sha256_bytes", "sha256_file"), "files"),
    **dict.fromkeys((
        "DEFAULT_TABLE_MANIFEST", "DEFAULT_TABLE_NPZ", "ERROR_SAFETY", "EXTRAPOLABLE_AXES",
        "FIXED_AXIS_RTOL", "Lookup", "ONE_AT_A_TIME_PREFIX", "OutsideGridError", "REBUILD_DEFAULT",
        "Table",
        "SHIPPED_TABLES", "default_table_paths", "shift_log_density",
        "read_default_table", "read_table", "read_table_ref", "table_ref_files", "table_ref_prefix"), "table"),
    "TableStressSource": "stress_source",
    **dict.fromkeys(("CHECK_FIELDS", "PointStore", "assemble", "build_table", "check_point",
                     "order_by_cost", "point_scene", "record_check", "run_points", "stationarity_summary",
                     "wider_cells"),
                    "build"),
    **dict.fromkeys((
        "KERNEL_MODULES", "POINTS_DIR", "SAME_DEM_AS", "cache_entries", "clear_cache",
        "default_cache_dir", "dem_kernel_version", "entry_dir", "get_table",
        "kernel_source_hash", "load_cached", "resolve_cache_dir"),
        "cache"),
    **dict.fromkeys((
        "DemBuilder", "dem_cells", "dem_scene_at_point", "dem_spec", "normalize_stats", "rebin_density",
        "rebuild_including", "recording_drift"), "dem_builder"),
}
#: The modules of millfmu.stress_tables whose names are re-exported here.
_READER = ("spec", "files", "table", "stress_source")
#: Old private name, kept for callers of the single module.
_ALIASES = {"_builder_id": ("spec", "builder_id_of")}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        mod, attr = _EXPORTS[name], name
    elif name in _ALIASES:
        mod, attr = _ALIASES[name]
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    # Relative, as the package's own imports are; "..." is millfmu, whose stress_tables is
    # the reader's package.
    target = f"...stress_tables.{mod}" if mod in _READER else f".{mod}"
    return getattr(importlib.import_module(target, __name__), attr)


def __dir__():
    return sorted(set(globals()) | set(_EXPORTS))
