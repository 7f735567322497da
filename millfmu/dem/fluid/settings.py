"""Options of the liquid that its solver and the coupling both name (plain data; no numba,
no scipy): the pressure equation's solvers."""

#: How the liquid's pressure equation is solved (the same solution to round-off):
#: - ``direct_lu``: one sparse LU of the whole operator (millfmu.dem.fluid.pressure);
#: - ``theta_fft``: an FFT in theta and one LU per mode (millfmu.dem.fluid.theta_fft_pressure),
#:   for grids with theta cells whose solids do not vary with theta (disc mills, the
#:   accelerator: its vanes are driven nodes; not stationary baffles): a full slice's
#:   solve costs a few milliseconds instead of tens;
#: - ``direct_ldl``: a symmetric factorisation L D L^T on a minimum-degree ordering, solved
#:   by a numba kernel (millfmu.dem.fluid.ldl_pressure): the operator is symmetric, and
#:   the factor holds about a third of direct_lu's entries on a 10-degree disc sector (a
#:   solve in a third of the time) and a quarter on a disc full slice (no slower).
PRESSURE_SOLVERS = ("direct_lu", "theta_fft", "direct_ldl")
#: the solver a scene gets when it names none: ``direct_ldl``, the fastest of the two
#: solvers that take every grid. Its results differ from ``direct_lu``'s in round-off
#: only, accepted for the shipped tables' kernel version on the statistics' evidence
#: (millfmu.dem.tables.equivalence; docs/tables.md).
DEFAULT_PRESSURE_SOLVER = "direct_ldl"
