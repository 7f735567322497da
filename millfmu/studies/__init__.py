"""Studies of the model: the population-balance integrators against scipy's BDF and each
other (:mod:`.pbm_integrators`, ``millfmu bench pbm|integrators``). They use the model;
nothing in the model uses them. The DEM's campaigns are in :mod:`millfmu.dem.studies`."""
