"""millfmu: a wet stirred media mill (bead mill) as a dynamic process-chain unit.

Population balance of particle sizes advanced with breakage rates from Kwade's stress
model (stress energy, stress frequency) or, in the detailed model, from stress-energy
distributions. SI units throughout: every scene key and output carries its unit in its
name (``_m``, ``_s``, ``_kg_per_s``, ``_J`` ...).

The Python API (names are imported on first use, so importing the package stays cheap):

>>> import millfmu
>>> scene = millfmu.load_scene(overrides={"mill.tip_speed_m_per_s": 8.0})  # embedded default scene
>>> result = millfmu.run(scene)        # -> millfmu.Result
>>> result.t_s, result["x50_m"]        # times [s], median sizes [m] as arrays
>>> result.q3                          # Q3 [-] at every class edge (result.edges_m) per time
>>> result.plot("out")                 # psd.png, sizes.png
>>> model = millfmu.MillModel(scene)   # step by step: model.step(dt_s, tip_speed_m_per_s=...)

- :func:`load_scene` (file, TOML text, dict or the embedded default; dotted-key overrides),
  :class:`Scene`, :func:`default_scene_text`, :func:`example_path` (a shipped example's file);
- :class:`MillModel` (``step(dt_s, **inputs) -> outputs``, ``get_state``/``set_state``);
- :func:`run` -> :class:`Result` (series as arrays, the Q3 table, warnings, provenance,
  ``plot``, ``write``);
- :func:`calibrate` -> :class:`Calibration`: fit scene constants to measured batch data
  (a CSV file), with 95 % intervals;
- errors: :class:`SceneError` (bad scene value: ``key``, ``value``, ``allowed``),
  :class:`InputError` (bad step input), :class:`StepError`,
  :class:`CalibrationError` (data that cannot pin the constants asked for).
"""

__version__ = "0.1.0"

#: Public name -> module that defines it.
_API = {
    "load_scene": "api", "run": "api", "Result": "api",
    "MillModel": "mill", "InputError": "mill", "StepError": "mill",
    "Scene": "scene", "SceneError": "scene", "default_scene_text": "scene", "example_path": "scene",
    "calibrate": "calibration", "Calibration": "calibration", "CalibrationError": "calibration",
}
__all__ = ["__version__", *_API]


def __getattr__(name):
    if name in _API:
        import importlib

        value = getattr(importlib.import_module(f".{_API[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
