"""millfmu.dem: soft-sphere DEM of the grinding beads of a stirred media mill.

Contact physics as in LIGGGHTS (Hertz-Mindlin with tangential history, Coulomb friction,
rolling friction), lubrication between close beads, Koch-Hill drag from a prescribed swirl
flow; geometries ``annulus`` and ``disc_slice`` (seed 001's PM-1 slice); collision
recording at first overlap and zone statistics V1-V4 (:mod:`millfmu.dem.analysis.stats`).

Importing this package is cheap: numba is imported only by the kernel modules, which
:class:`millfmu.dem.engine.sim.DemSimulation` loads when a simulation is built.
"""
