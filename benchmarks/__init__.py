"""Benchmarks against peer codes, run from a checkout's root and not installed with millfmu:
the DEM against LAMMPS and LIGGGHTS (:mod:`.dem_peers`, ``python -m benchmarks.dem_peers``;
``lammps/`` its input files and ``compare.sh``), and the coupled DEM-CFD against the DEM
alone (:mod:`.coupled_bench`, ``python -m benchmarks.coupled_bench``). ``results/`` holds the
measurements the README quotes (JSON, one file per measurement), each written by the
benchmark that made it: ``millfmu bench pbm|fmu --json FILE``, ``--record FILE`` here,
``python -m benchmarks.first_dem_run --out FILE``, except ``dem-bench-gpu.json``, copied
from the documentation (its note says so). They import millfmu;
nothing in millfmu imports them."""
