"""Two-way coupling of the bead DEM and the fluid (unresolved CFD-DEM).

- :mod:`~millfmu.dem.coupling.projection`: beads <-> grid (deposit, smoothing, node splits)
  with exact transposes, so that exchanged momentum is conserved to round-off;
- drag laws: Koch & Hill (2001), :mod:`millfmu.dem.engine.koch_hill2001` (the prescribed
  swirl's too); Schiller & Naumann (1933), :mod:`~millfmu.dem.coupling.schiller_naumann`;
- :mod:`~millfmu.dem.coupling.cfd_dem`: :class:`CfdDem`, the loop that alternates them.
"""
