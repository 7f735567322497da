"""The DEM cell of a table point: the scene a point runs (:func:`dem_scene_at_point`), in
the scene's own sector where the point's beads fit it, else in the narrowest wider one that
holds them. Used by the point store's keys (:mod:`.build`) and the DEM builder
(:mod:`.dem_builder`); imports neither, nor the DEM's run (no numba)."""

from __future__ import annotations

import json
from typing import NamedTuple

from ..mills.geometry import SECTORS_DEG, bead_count_for_filling, placement_capacity
from ..scene import KINDS, DemScene, scene_from_dict
from ...stress_tables.spec import scene_at_point


class Cell(NamedTuple):
    """The DEM cell of a table point: ``scene`` (the scene dict the DEM runs), ``dem`` (it
    validated; None for a scene that is no DEM scene or does not validate), the beads its
    filling needs and the most its cell holds (0, 0 where it places no beads by filling)."""

    scene: dict
    dem: DemScene | None
    need: int
    capacity: int

    @property
    def fits(self) -> bool:
        return self.need <= self.capacity


def _cell_of(d: dict) -> Cell:
    try:
        s = scene_from_dict(d) if d.get("kind") in KINDS else None
    except (ValueError, KeyError, TypeError):  # DemSceneError, GeometryError: the builder says so when it runs
        s = None
    if s is None or s.placement != "filling":
        return Cell(d, s, 0, 0)
    need = bead_count_for_filling(s.geometry, s.filling, s.bead_diameter_m, s.bulk_porosity)
    return Cell(d, s, need, placement_capacity(s.geometry, 0.5 * s.bead_diameter_m))


def dem_cells(scene: dict, point: dict) -> tuple[Cell, Cell]:
    """(the cell ``point`` runs in, the widest cell tried) for a table of DEM scene ``scene``:
    see :func:`dem_scene_at_point`. Where the scene's own sector holds the point's beads both
    are that cell; where no sector does, the first is the scene's own and the second the
    widest (what :meth:`DemBuilder.unbuildable` names)."""
    own = _cell_of(scene_at_point(scene, point))
    if own.fits or own.dem is None:
        return own, own
    widest = own
    for deg in SECTORS_DEG:
        if deg <= own.dem.geometry.sector_deg:
            continue
        d = json.loads(json.dumps(own.scene))
        d.setdefault("mill", {})["sector_deg"] = deg
        c = _cell_of(d)
        if c.dem is None:  # the scene refuses it (vane or baffle pitches, theta cells)
            continue
        widest = c
        if c.fits:
            return c, c
    return own, widest


def dem_scene_at_point(scene: dict, point: dict) -> dict:
    """The DEM scene a table point runs: ``scene`` with the point's values
    (:func:`~millfmu.stress_tables.spec.scene_at_point`) in a cell that holds the point's
    beads. This is the one place where a point's DEM cell is chosen; the point store's keys
    (:class:`~.build.PointStore`), the builder's run, cost and refusal all take it from here.

    Where the beads of the point's filling fit the scene's own sector (the lattice sites of
    :func:`~millfmu.dem.mills.geometry.placement_capacity`), the scene at the point is
    returned as it is: every point that fits keeps its content, its key in the point store
    and its result. Where they do not (large beads at high filling: 1.4 mm beads at 80 %
    need 1220 in the 10-degree disc slice, which holds 1159), ``mill.sector_deg`` is set to
    the narrowest of :data:`~millfmu.dem.mills.geometry.SECTORS_DEG` wider than the scene's
    that holds them and that the scene accepts (whole vane and baffle pitches, the liquid's
    theta cells): 1.4 mm at 80 % runs in 12 degrees, 2.0 mm at 90 % in 72 degrees. The
    zone statistics are per chamber volume, so the sector is a resolution of the point, not
    part of the operating point. Where no sector of up to 90 degrees holds them, the scene's
    own (:meth:`DemBuilder.unbuildable` says why)."""
    return dem_cells(scene, point)[0].scene
