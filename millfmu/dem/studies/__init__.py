"""Paper campaigns and benchmarks of the DEM: seed 001 (:mod:`.seed001`), seed 002
(:mod:`.seed002`), the work-precision study (:mod:`.work_precision`), the DEM benchmark
against LAMMPS and LIGGGHTS (:mod:`.bench`) and the coupled DEM-CFD throughput
(:mod:`.coupled_bench`). They use everything; nothing in the engine or the model uses them."""
