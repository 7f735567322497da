"""Paper campaigns and equivalence runs, run from a checkout's root and not installed with
millfmu: seed 001 (:mod:`.seed001`, ``python -m validation.seed001``) and seed 002
(:mod:`.seed002`, ``python -m validation.seed002``) side by side with the papers, the DEM
work-precision study (:mod:`.work_precision`), the runs that accept a round-off change of the
DEM's sources (:mod:`.equivalence_runs`) and the causes of the detailed model's trends
(:mod:`.trends_causes`). What the installed package reads of them ships as its data
(millfmu/data/dem_work_precision.json, millfmu/data/dem_equivalence.json) and is read by
:mod:`millfmu.dem.analysis.precision` and :mod:`millfmu.dem.tables.equivalence`. They import
millfmu; nothing in millfmu imports them."""
