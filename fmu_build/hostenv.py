"""Environment a non-Python (C, C++) host needs to load an FMU built by ``millfmu build-fmu``
(FMI 2.0 or 3.0).

pythonfmu's (and pythonfmu3's) binary does not link libpython: the host must preload it
(LD_PRELOAD), and the embedded interpreter must find its standard library (PYTHONHOME) and
numpy and scipy (PYTHONPATH). The values describe the Python running this command, which must be the one
the FMU is meant to run with (same version as its libpython).
"""

from __future__ import annotations

import importlib.util
import os
import sys
import sysconfig
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

#: What the FMU imports from the host's Python (the rest it carries).
REQUIRED = ("numpy", "scipy")


def _libpython() -> Path:
    libdir = sysconfig.get_config_var("LIBDIR") or ""
    multiarch = sysconfig.get_config_var("MULTIARCH") or ""
    names = [n for n in (sysconfig.get_config_var("INSTSONAME"), sysconfig.get_config_var("LDLIBRARY")) if n
             and not n.endswith(".a")]
    for name in names:
        for d in (Path(libdir), Path(libdir) / multiarch):
            if (d / name).exists():
                return d / name
    raise ValueError(f"this Python ({sys.executable}) has no shared libpython (looked for {names} in {libdir}); "
                     "a C host needs a Python built with --enable-shared")


def host_env(fmu: str | Path) -> dict:
    """{variable: value} for a C host loading ``fmu`` with this Python's environment."""
    fmu = Path(fmu)
    md, names = _read_fmu(fmu)
    fmi3 = md.get("fmiVersion", "").startswith("3")
    runtime = "pythonfmu3" if fmi3 else "pythonfmu"
    if not any(n.startswith(f"resources/{runtime}/") for n in names):
        raise ValueError(f"{fmu}: not a {runtime} FMU (no resources/{runtime}/)")
    cs = md.find("CoSimulation")
    ident = cs.get("modelIdentifier") if cs is not None else None
    if not ident:
        raise ValueError(f"{fmu}: modelDescription.xml declares no CoSimulation modelIdentifier: "
                         "host-env takes a co-simulation FMU built by millfmu build-fmu")
    missing = [m for m in REQUIRED if importlib.util.find_spec(m) is None]
    if missing:
        raise ValueError(f"this Python ({sys.executable}) lacks {', '.join(missing)}, which the FMU imports")
    # Where numpy and scipy live (a virtual environment's site-packages, or the system's).
    paths = []
    for m in REQUIRED:
        p = str(Path(importlib.util.find_spec(m).origin).parent.parent)
        if p not in paths:
            paths.append(p)
    return {
        "LD_PRELOAD": str(_libpython()),
        "PYTHONHOME": sys.base_prefix,
        "PYTHONPATH": os.pathsep.join(paths),
        "FMU_BINARY": f"binaries/{'x86_64-linux' if fmi3 else 'linux64'}/{ident}.so",
    }


def _read_fmu(fmu: Path):
    """(modelDescription.xml's root element, the archive's names) of an FMU file; ValueError
    naming the file and what it is instead (OSError where it cannot be read at all)."""
    what = "host-env takes an FMU (a zip archive with modelDescription.xml) built by millfmu build-fmu"
    try:
        with zipfile.ZipFile(fmu) as z:
            names = z.namelist()
            if "modelDescription.xml" not in names:
                raise ValueError(f"{fmu}: a zip archive without modelDescription.xml, not an FMU; {what}")
            text = z.read("modelDescription.xml")
    except zipfile.BadZipFile:
        raise ValueError(f"{fmu}: not a zip archive, so not an FMU; {what}") from None
    try:
        md = ET.fromstring(text)
    except ET.ParseError as e:
        raise ValueError(f"{fmu}: its modelDescription.xml is not well-formed XML ({e}); {what}") from None
    return md, names


def shell_lines(env: dict) -> list:
    """``export`` lines for a POSIX shell (FMU_BINARY as a comment: where the library is)."""
    out = [f"# binary inside the FMU: {env['FMU_BINARY']}"]
    out += [f"export {k}={_quote(v)}" for k, v in env.items() if k != "FMU_BINARY"]
    return out


def _quote(s: str) -> str:
    return "'" + s.replace("'", "'\\''") + "'"
