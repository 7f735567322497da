"""The bead DEM itself: contact kernels (:mod:`.kernels`), the simulation object
(:mod:`.sim`), its numba.cuda twin (:mod:`.gpu`), the shared JIT flags (:mod:`._jit`) and
the bead materials (:mod:`.params`). Importing this package imports no numba."""
