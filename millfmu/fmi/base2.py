"""What pythonfmu 0.7's model description lacks, added for FMI 2.0 validity.

Units in UnitDefinitions (with SI base-unit exponents) and on every Real, exact start
values, output dependencies (none: the slaves have no direct feedthrough, outputs change
only in doStep) and InitialUnknowns. Shared by the mill FMU and the flowsheet unit FMUs;
numpy-free so it can be carried into any FMU.
"""

from __future__ import annotations

import math
from xml.etree.ElementTree import Element, SubElement


def get_reals(values: list, vrs, log_error) -> list:
    """fmi2GetReal over ``values`` (indexed by value reference): a reference that names no
    Real variable reads NaN, and one error is logged with ``log_error(message)``."""
    try:
        return [values[vr] for vr in vrs]
    except (IndexError, TypeError):
        n = len(values)
        bad = [vr for vr in vrs if not (isinstance(vr, int) and 0 <= vr < n)]
        log_error(f"fmi2GetReal: no Real variable with value reference {bad[0]}; got NaN")
        return [values[vr] if isinstance(vr, int) and 0 <= vr < n else math.nan for vr in vrs]


def complete_model_description(root: Element, slave, units: dict, exponents, description: str) -> Element:
    """Complete ``root`` (from pythonfmu's ``Fmi2Slave.to_xml``) in place and return it.

    slave: the Fmi2Slave (its ``vars`` and current values ``_v`` by value reference);
    units: FMI variable name -> unit name; exponents: unit name -> {base unit: exponent};
    description: the model description text.
    """
    from pythonfmu import Fmi2Causality

    root.set("description", description)
    used = []
    by_name = {v.name: v for v in slave.vars.values()}
    for sv in root.iter("ScalarVariable"):
        name = sv.get("name")
        real = sv.find("Real")
        u = units[name]
        real.set("unit", u)
        if u not in used:
            used.append(u)
        if real.get("start") is not None:
            # pythonfmu prints start values with limited digits; write them exactly.
            real.set("start", repr(float(slave._v[by_name[name].value_reference])))
    defs = Element("UnitDefinitions")
    for u in used:
        unit = SubElement(defs, "Unit", {"name": u})
        SubElement(unit, "BaseUnit", {k: str(e) for k, e in exponents(u).items()})
    root.insert(list(root).index(root.find("CoSimulation")) + 1, defs)
    root.remove(root.find("ModelStructure"))
    ms = SubElement(root, "ModelStructure")
    outs = SubElement(ms, "Outputs")
    init = SubElement(ms, "InitialUnknowns")
    for i, v in enumerate(slave.vars.values(), 1):
        if v.causality == Fmi2Causality.output:
            SubElement(outs, "Unknown", {"index": str(i), "dependencies": ""})
            # Initial outputs follow from parameters and input start values: no dependency
            # list, i.e. "depends on all".
            SubElement(init, "Unknown", {"index": str(i)})
    return root
