"""Flowsheet -> SSP 1.0 archive (System Structure and Parameterization, Modelica Association).

The archive holds ``SystemStructure.ssd`` (components, their connectors with units, the
connections class by class, the flowsheet's start values as parameter bindings, the stop
time and, as an Open Simulation Platform annotation, the fixed communication step) and the
units' FMUs under ``resources/``. libcosim (``CosimExecution.from_ssp_file``) and ecos
(``EcosSimulation(ssp_path=...)``) run it. Both masters are fixed-step Jacobi; mass flows are
copied as values there, which at a fixed step equals the fmpy master's flow buffers (see
flowsheets.master). The master-side options (Gauss-Seidel order, retry of discarded steps,
products for the mass balance) are not part of SSP.
"""

from __future__ import annotations

import shutil
import tempfile
import zipfile
from pathlib import Path
from xml.etree.ElementTree import Element, SubElement, indent, tostring

from .master import build_fmus, expand_connections
from .spec import Flowsheet
from .unit_vars import unit_exponents

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
}


def _q(prefix, tag):
    return f"{prefix}:{tag}"


def ssd_xml(fs: Flowsheet, mds: dict, sources: dict, links) -> bytes:
    """The SystemStructure.ssd text: mds, sources: unit -> model description, path in the archive."""
    root = Element(_q("ssd", "SystemStructureDescription"), {f"xmlns:{k}": v for k, v in NS.items()})
    root.set("version", "1.0")
    root.set("name", fs.name)
    system = SubElement(root, _q("ssd", "System"), {"name": fs.name, "description": fs.description})
    elements = SubElement(system, _q("ssd", "Elements"))
    used_units = set()
    for u in fs.units:
        md = mds[u]
        comp = SubElement(elements, _q("ssd", "Component"),
                          {"name": u, "source": sources[u], "type": "application/x-fmu-sharedlibrary"})
        conns = SubElement(comp, _q("ssd", "Connectors"))
        for v in md.modelVariables:
            if v.causality not in ("input", "output", "parameter") or v.type != "Real":
                continue
            kind = v.causality
            c = SubElement(conns, _q("ssd", "Connector"), {"name": v.name, "kind": kind})
            attrs = {"unit": v.unit} if v.unit else {}
            SubElement(c, _q("ssc", "Real"), attrs)
            if v.unit:
                used_units.add(v.unit)
        start = fs.units[u].start
        if start:
            pb = SubElement(SubElement(comp, _q("ssd", "ParameterBindings")), _q("ssd", "ParameterBinding"))
            pv = SubElement(pb, _q("ssd", "ParameterValues"))
            ps = SubElement(pv, _q("ssv", "ParameterSet"), {"version": "1.0", "name": f"{u}_start"})
            params = SubElement(ps, _q("ssv", "Parameters"))
            for k, x in start.items():
                p = SubElement(params, _q("ssv", "Parameter"), {"name": k})
                SubElement(p, _q("ssv", "Real"), {"value": repr(float(x))})
    connections = SubElement(system, _q("ssd", "Connections"))
    for lk in links:
        SubElement(connections, _q("ssd", "Connection"), {"startElement": lk.src, "startConnector": lk.src_var,
                                                           "endElement": lk.dst, "endConnector": lk.dst_var})
    # Units: SSP wants the unit definitions of the connectors' units at the top level.
    units = SubElement(root, _q("ssd", "Units"))
    mill_units = {"kg/m3": {"kg": 1, "m": -3}, "J": {"kg": 1, "m": 2, "s": -2}, "1/s": {"s": -1},
                  "W": {"kg": 1, "m": 2, "s": -3},
                  "J/kg": {"m": 2, "s": -2}, "Pa.s": {"kg": 1, "m": -1, "s": -1}}
    for name in sorted(used_units):
        try:
            exps = unit_exponents(name)
        except KeyError:
            exps = mill_units.get(name, {})
        un = SubElement(units, _q("ssc", "Unit"), {"name": name})
        SubElement(un, _q("ssc", "BaseUnit"), {k: str(e) for k, e in exps.items()})
    de = SubElement(root, _q("ssd", "DefaultExperiment"), {"startTime": "0.0", "stopTime": repr(fs.t_end_s)})
    ann = SubElement(SubElement(de, _q("ssd", "Annotations")), _q("ssc", "Annotation"),
                     {"type": "com.opensimulationplatform"})
    alg = SubElement(ann, _q("osp", "Algorithm"))
    SubElement(alg, _q("osp", "FixedStepAlgorithm"), {"baseStepSize": repr(fs.step_s)})
    indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="utf-8")


def export_ssp(fs: Flowsheet, out: Path, fmu_dir: Path | None = None, log=print) -> Path:
    """Build the units' FMUs (or reuse them from ``fmu_dir``) and write the .ssp archive ``out``."""
    from fmpy import read_model_description

    out = Path(out)
    with tempfile.TemporaryDirectory(prefix="flowsheet_ssp_") as tmp:
        paths = build_fmus(fs, Path(fmu_dir) if fmu_dir else Path(tmp) / "fmus", log=log)
        mds = {u: read_model_description(str(p)) for u, p in paths.items()}
        links, _ = expand_connections(fs, mds)  # checks the connections against the FMUs
        sources = {u: f"resources/{Path(p).name}" for u, p in paths.items()}
        xml = ssd_xml(fs, mds, sources, links)
        part = Path(tmp) / "out.ssp"
        with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("SystemStructure.ssd", xml)
            for p in sorted(set(paths.values())):
                z.write(p, f"resources/{Path(p).name}", compress_type=zipfile.ZIP_STORED)
        out.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(str(part), str(out))
    return out
