"""Stress-energy lookup tables: DEM results on a grid of operating points, cached on disk.

A DEM run takes minutes; a kinetics step takes microseconds. A table holds, for a grid of
operating points, what the detailed breakage model needs from the DEM, per zone, with
energies over the bead's kinetic energy at tip speed and collision rates over omega n_gb.

The modules, by role:

- :mod:`.spec`: the format (axes, fields, energy bins, normalization) and
  :class:`TableSpec`, whose key names a table, with what its manifest states;
- :mod:`.files`: canonical JSON, checksums and synced writes of a table's files;
- :mod:`.table`: :class:`Table` and its lookup (multilinear interpolation, error
  estimates), :func:`read_table`, which verifies a table's files, the shipped default table;
- :mod:`.stress_source`: :class:`TableStressSource`, the kinetics' stress-energy source;
- :mod:`.build`: a builder run over the grid (serially, process pool, Dask) and assembled;
- :mod:`.cache`: the cache of built tables, its locks and the DEM kernel version;
- :mod:`.equivalence`: source changes of round-off only, accepted as the tables' kernel
  version on the evidence of runs scored against the version's own realizations (the
  runs: :mod:`.equivalence_runs`);
- :mod:`.dem_builder`: the DEM as a builder (:class:`DemBuilder`), DEM table specs and
  rebuilds that cover a new point.

An FMU carries only the first four (what reading and looking up needs: numpy, no DEM, no
numba). This package therefore imports none of its modules until one of its names is used:
``millfmu.dem.tables.X`` (and ``from millfmu.dem.tables import X``) loads the module that
defines X, so the names stay importable from here as from the one module they came from.
"""

from __future__ import annotations

import importlib

#: Name -> the module of this package that defines it.
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
        "read_default_table", "read_table", "read_table_ref", "table_ref_prefix"), "table"),
    "TableStressSource": "stress_source",
    **dict.fromkeys(("CHECK_FIELDS", "PointStore", "assemble", "build_table", "check_point",
                     "order_by_cost", "record_check", "run_points", "stationarity_summary"),
                    "build"),
    **dict.fromkeys((
        "KERNEL_MODULES", "POINTS_DIR", "SAME_DEM_AS", "cache_entries", "clear_cache",
        "default_cache_dir", "dem_kernel_version", "entry_dir", "get_table",
        "kernel_source_hash", "load_cached", "resolve_cache_dir"),
        "cache"),
    **dict.fromkeys((
        "DemBuilder", "dem_spec", "normalize_stats", "rebin_density", "rebuild_including",
        "recording_drift"), "dem_builder"),
}
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
    # Relative: an FMU carries this package under another top-level name.
    return getattr(importlib.import_module(f".{mod}", __name__), attr)


def __dir__():
    return sorted(set(globals()) | set(_EXPORTS))
