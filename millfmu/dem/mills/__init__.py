"""Mill families: one geometry and one zone set per family. :mod:`.geometry` (annulus,
disc slice and the accelerator rotor's solid parts), :mod:`.zones` (disc mills: V1-V4,
the annulus), :mod:`.accelerator` (the accelerator slice: its rotor, SEV_1-4 and the
paper's stress quantities); :func:`zones_for` picks a scene's zone set. Pure numpy."""

from __future__ import annotations

from .accelerator import SevZones
from .zones import Zones


def zones_for(scene):
    """The zone set of a DemScene's mill family: SEV_1-4 (accelerator_slice,
    :class:`~.accelerator.SevZones`), V1-V4 (disc_slice) or the annulus
    (:class:`~.zones.Zones`)."""
    if scene.kind == "accelerator_slice":
        return SevZones(scene.geometry, scene.zones)
    return Zones(scene.geometry, scene.zones)
