"""Reading stress-energy lookup tables: what the detailed breakage model needs of the DEM,
on a grid of operating points, per zone (energies over the bead's kinetic energy at tip
speed [-], collision rates over omega n_gb [-]).

The modules, by role:

- :mod:`.spec`: the format (axes, fields, energy bins, normalization) and
  :class:`~.spec.TableSpec`, whose key names a table, with what its manifest states;
- :mod:`.files`: canonical JSON, checksums and synced writes of a table's files;
- :mod:`.table`: :class:`~.table.Table` and its lookup (multilinear interpolation, error
  estimates), :func:`~.table.read_table`, which verifies a table's files, the shipped tables;
- :mod:`.stress_source`: :class:`~.stress_source.TableStressSource`, the kinetics'
  stress-energy source;
- :mod:`.rules`: how the mill model uses a table (the scene keys and inputs of its axes,
  refusals, warnings).

This package is what an FMU carries of the tables (numpy and the kinetics; no DEM, no
numba; every FMU carries this file and :mod:`.rules`, which the mill model imports), and a
step of a scene with a table loads nothing of the DEM's package. Building tables (grid
runs, the cache, the DEM as builder, on-demand builds) is the DEM's ``tables`` package,
which reads and writes tables through this one; only the stress source's on-demand builds
(``on_outside = 'build'``, never in an FMU) reach it, by imports inside those functions.
The package imports none of its modules itself, so that importing one loads only what
that one needs.
"""
