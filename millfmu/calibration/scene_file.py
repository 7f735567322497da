"""Writing a calibration: the scene with the fitted values (``calibrated.toml``, its
comments kept, headed by what was fitted to what) and the record (``calibration.json``).
"""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

from ..api import load_scene as load_any
from ..scene import Scene, number_key, scene_to_dict, toml_text, toml_value
from .measured import CalibrationError

if TYPE_CHECKING:
    from .fitting import Calibration

_LINE = re.compile(r"^(\s*)([A-Za-z0-9_]+)(\s*=\s*)([^#\n]*?)(\s*(#.*)?)$")
_HEADER = re.compile(r"^\s*\[([A-Za-z0-9_.]+)\]\s*(#.*)?$")


def set_toml_values(text: str, values: dict, comment: str | None = None) -> str:
    """``text`` (a scene file) with dotted keys set to ``values`` (numbers, strings), comments kept; a
    key not in the file is added to its section (the section appended if missing). ``comment``:
    the new comment of a value line that had one at its end (which described the old value) for
    the keys of ``values`` that are not in the ``scene`` section."""
    lines = text.splitlines()
    todo = dict(values)
    section = ""
    for i, ln in enumerate(lines):
        h = _HEADER.match(ln)
        if h:
            section = h.group(1)
            continue
        m = _LINE.match(ln)
        if m and f"{section}.{m.group(2)}" in todo:
            v = todo.pop(f"{section}.{m.group(2)}")
            tail = m.group(5)
            if comment is not None and m.group(6) and section != "scene":
                tail = tail[:len(tail) - len(m.group(6))] + f"# {comment}"
            lines[i] = f"{m.group(1)}{m.group(2)}{m.group(3)}{toml_value(v)}{tail}"
    for key, v in todo.items():
        sec, name = key.rsplit(".", 1)
        idx = next((i for i, ln in enumerate(lines) if (h := _HEADER.match(ln)) and h.group(1) == sec), None)
        if idx is None:
            lines += ["", f"[{sec}]", f"{name} = {toml_value(v)}"]
        else:
            lines.insert(idx + 1, f"{name} = {toml_value(v)}")
    return "\n".join(lines) + "\n"


#: the first words of the head :func:`write` puts above a calibrated scene
HEAD_START = "# Calibrated by millfmu calibrate on"


def _without_earlier_head(text: str) -> str:
    """``text`` without the head an earlier :func:`write` put at its top (a calibrated scene
    calibrated again): its comment lines up to the first line that is not one."""
    lines = text.splitlines()
    if not lines or not lines[0].startswith(HEAD_START):
        return text
    n = next((i for i, ln in enumerate(lines) if not ln.startswith("#")), len(lines))
    return "\n".join(lines[n:]) + "\n"


def _scene_text(scene: Scene, scene_path) -> str:
    """The text the calibrated scene is written from: the scene file (comments kept), the
    embedded default scene's for ``scene_path = "default"``, else the resolved scene."""
    if scene_path == "default":
        from ..scene import default_scene_text

        return default_scene_text()
    if scene_path is not None:
        return Path(scene_path).read_text(encoding="utf-8")
    return toml_text(scene_to_dict(scene))


def write(cal: Calibration, out_dir, scene_path=None) -> list:
    """Write ``out_dir/calibrated.toml`` (the scene with the fitted values, headed by a comment
    naming the data file, its sha256 and the date) and ``out_dir/calibration.json``; both
    appear together or not at all."""
    from ..runner import check_out_dir, staging_dir
    from .fitting import unit_after

    out = check_out_dir(out_dir)
    head = (f"{HEAD_START} {cal.date_utc}: {', '.join(cal.constants)} fitted to\n"
            f"# {Path(cal.data_source).name} (sha256 {cal.data_sha256}); values, 95 % intervals and residuals in\n"
            f"# calibration.json. Fitted at this scene's operating point. Comments further down that\n"
            f"# describe an earlier calibration are the scene file's own: these values replace it.\n")
    for k, c in cal.constants.items():
        ci = f"[{c.ci95[0]:.4g}, {c.ci95[1]:.4g}]" if c.ci95 else "(no interval)"
        head += f"#   {k} = {c.value:.6g}{unit_after(c.unit)}, 95 % interval {ci}\n"
    # the constants with an interval, which the prediction band carries through the model
    fitted = [(k, c.ci95) for k, c in cal.constants.items() if c.ci95]
    text = head + set_toml_values(_without_earlier_head(_scene_text(cal.scene, scene_path)),
                                  {**{k: c.value for k, c in cal.constants.items()}, "scene.calibration": cal.record(),
                                   "scene.fitted": [k for k, _ in fitted],
                                   "scene.fitted_ci95_low": [float(ci[0]) for _, ci in fitted],
                                   "scene.fitted_ci95_high": [float(ci[1]) for _, ci in fitted]},
                                  comment=f"fitted: see the head of this file ({cal.date_utc})")
    check = load_any(text)
    for k, c in cal.constants.items():
        if number_key(check, k) != c.value:  # pragma: no cover - set_toml_values is tested
            raise CalibrationError(f"calibrated.toml: {k} did not take the fitted value")
    tmp = staging_dir(out, ".millfmu-")
    try:
        (tmp / "calibrated.toml").write_text(text, encoding="utf-8")
        (tmp / "calibration.json").write_text(json.dumps(cal.to_dict(), indent=1), encoding="utf-8")
        out.mkdir(parents=True, exist_ok=True)
        written = []
        for name in ("calibrated.toml", "calibration.json"):
            os.replace(tmp / name, out / name)
            written.append(out / name)
        return written
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

