"""millfmu: a wet stirred media mill (bead mill) as a dynamic process-chain unit.

Population balance of particle sizes advanced with breakage rates from Kwade's stress
model (stress energy, stress frequency) or, in the detailed model, from stress-energy
distributions. SI units throughout.
"""

__version__ = "0.1.0"
