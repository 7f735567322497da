"""The FMI side of millfmu: co-simulation adapters of the mill and the bases that the
flowsheets' unit FMUs share with it. No physics.

- :mod:`.base2`, :mod:`.base3`: FMI 2.0 (pythonfmu) and FMI 3.0 (pythonfmu3) bases:
  values in one list, variables with units, statuses, FMU states, the model description's
  completion; numpy-free and free of millfmu imports, so any FMU can carry them;
- :mod:`.variables`: the mill FMU's variables, described once for both versions;
- :mod:`.mill2`, :mod:`.mill3`: the mill's adapters (FMI variables <-> MillModel).

An FMU carries only the modules its slave imports (``fmu_build``, ``flowsheets.build``);
importing this package imports none of them.
"""
