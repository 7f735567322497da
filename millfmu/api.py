"""The Python API: load a scene, run it to a :class:`Result` (see :mod:`millfmu`)."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .mill import MillModel
from .runner import RESULT_KEYS, _plots, provenance, run_warnings, simulate, write_results
from .scene import (Scene, SceneError, load_scene as _load_scene_file, scene_from_dict,
                    scene_to_dict)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def _nested(overrides: dict) -> dict:
    """{"mill.tip_speed_m_per_s": 8.0} or {"mill": {"tip_speed_m_per_s": 8.0}} -> nested dict."""
    out: dict = {}
    for key, value in overrides.items():
        if isinstance(value, dict):
            value = _nested(value)
        parts = str(key).split(".")
        d = out
        for p in parts[:-1]:
            d = d.setdefault(p, {})
            if not isinstance(d, dict):
                raise SceneError(key, value, "overrides a key that is not a section", "overrides")
        if isinstance(value, dict) and isinstance(d.get(parts[-1]), dict):
            d[parts[-1]].update(value)
        else:
            d[parts[-1]] = value
    return out


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def load_scene(source: str | Path | dict | Scene | None = None, overrides: dict | None = None) -> Scene:
    """A validated scene (SI units) from ``source``:

    - None: the embedded default scene (``millfmu scene-keys --default``);
    - a path (``str`` or ``Path``) of a TOML scene file;
    - TOML text (a ``str`` with a newline or ``=``);
    - a dict as read from TOML, or a :class:`Scene`.

    ``overrides``: scene keys to change, dotted (``{"mill.tip_speed_m_per_s": 8.0}``) or
    nested (``{"mill": {"tip_speed_m_per_s": 8.0}}``). Keys left out anywhere take the
    embedded default scene's values. Raises :class:`SceneError` naming the key, the value
    and what is allowed.
    """
    if isinstance(source, Scene):
        d, where = scene_to_dict(source), "scene"
    elif isinstance(source, dict):
        d, where = source, "scene"
    elif source is None:
        d, where = {}, "default scene"
    elif isinstance(source, str) and ("\n" in source or "=" in source):
        try:
            d = tomllib.loads(source)
        except tomllib.TOMLDecodeError as e:
            raise SceneError("(syntax)", str(e), "the text must be valid TOML", "scene text") from None
        where = "scene text"
    else:
        if not overrides:
            return _load_scene_file(source)
        p = Path(source)
        try:
            d = tomllib.loads(p.read_text())
        except OSError as e:
            raise SceneError("(file)", str(p), f"cannot be read: {e.strerror or e}", str(p)) from None
        except tomllib.TOMLDecodeError as e:
            raise SceneError("(syntax)", str(e), "the file must be valid TOML", str(p)) from None
        where = str(p)
    if overrides:
        d = _merge(d, _nested(overrides))
    return scene_from_dict(d, where)


@dataclass
class Result:
    """A run of a scene: one entry per output time.

    ``t_s`` [s]; ``series``: every scalar output as an array over the output times, keyed
    as in result.json with the unit in the name (``x50_m`` [m], ``power_W`` [W],
    ``below_grid_fraction`` [-], ...; ``result["x50_m"]`` is the same); ``edges_m``: the
    size classes' edges [m]; ``q3``: Q3 [-] at every edge per output time, shape
    (times, classes + 1), its first column the mass below the grid; ``warnings``;
    ``provenance`` (what reproduces the run, as in result.json); ``model``: the
    :class:`MillModel` at the end.
    """

    scene: Scene
    model: MillModel
    t_s: np.ndarray
    series: dict
    edges_m: np.ndarray
    q3: np.ndarray
    warnings: list = field(default_factory=list)
    wall_s: float = 0.0
    _records: list = field(default_factory=list, repr=False)

    def __getitem__(self, key: str) -> np.ndarray:
        return self.series[key]

    @property
    def units(self) -> dict:
        """Unit of each series."""
        return {k: RESULT_KEYS[k] for k in self.series}

    @property
    def provenance(self) -> dict:
        return provenance(self.scene, self.model, self.wall_s)

    def plot(self, folder: str | Path) -> list:
        """Write the plots (psd.png: Q3 and q3 over size at up to 8 times; sizes.png:
        x10/x50/x90 over time) into ``folder``; returns their paths."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        _plots(folder, self.model, self._records, list(self.q3))
        return [folder / "psd.png", folder / "sizes.png"]

    def write(self, folder: str | Path, plots: bool = True) -> list:
        """Write result.json, psd.csv (and the plots) as ``millfmu run`` does; returns the paths."""
        return write_results(folder, self.scene, self.model, self._records, list(self.q3), plots=plots,
                             wall_s=self.wall_s)


def run(scene: Scene | str | Path | dict | None = None, overrides: dict | None = None,
        progress: bool = False) -> Result:
    """Run a scene (anything :func:`load_scene` takes, with ``overrides``) from t = 0 to its
    run.t_end_s at run.dt_s steps, recording every run.output_interval_s; returns a :class:`Result`."""
    if not isinstance(scene, Scene) or overrides:
        scene = load_scene(scene, overrides)
    t0 = time.perf_counter()
    model, records, psds = simulate(scene, progress=progress)
    wall = time.perf_counter() - t0
    series = {k: np.array([r[k] for r in records]) for k in RESULT_KEYS if k in records[0]}
    return Result(scene=scene, model=model, t_s=series["t_s"], series=series, edges_m=model.grid.edges_m.copy(),
                  q3=np.array(psds), warnings=run_warnings(model, records), wall_s=wall, _records=records)
