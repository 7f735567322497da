"""Studies of the model that the product runs: the population-balance integrators against
scipy's BDF and each other (:mod:`.pbm_integrators`, ``millfmu bench pbm|integrators`` and
``millfmu report``). They use the model; nothing in the model uses them. The paper campaigns
and peer benchmarks are not installed with the package: a checkout's ``validation/`` and
``benchmarks/``."""
