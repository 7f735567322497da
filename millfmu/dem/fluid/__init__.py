"""The liquid of the bead mill: a volume-averaged Navier-Stokes (VANS) solver on a
cylindrical staggered grid (unresolved CFD-DEM, the CFD half).

- :mod:`~millfmu.dem.fluid.grid`: the (r, theta, z) grid, solids (disc, housing), walls;
- :mod:`~millfmu.dem.fluid.vans_kernels`: numba kernels of the momentum equations
  (models A and B of Anderson & Jackson as in Zhou et al. 2010);
- :mod:`~millfmu.dem.fluid.pressure`: the projection's pressure equation;
- :mod:`~millfmu.dem.fluid.k_epsilon`: standard k-epsilon with wall functions
  (Launder & Spalding 1974), or ``laminar``;
- :mod:`~millfmu.dem.fluid.solver`: :class:`FluidSolver`, the state and the time step;
- :mod:`~millfmu.dem.fluid.anderson_jackson1967`: model A's beads' share of the viscous
  stress (an option: ``[fluid.coupled] bead_stress_force``).

The beads are coupled by :mod:`millfmu.dem.coupling`. numba is imported only by the kernel
modules, which the solver loads when it is built.
"""
