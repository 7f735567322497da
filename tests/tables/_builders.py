"""A cheap, deterministic stand-in for the DEM builder: smooth analytic fields of the grid
point, so that cache mechanics, interpolation and executors can be tested in milliseconds.

The scene dict may name ``count_file`` (a line is appended per build, to count builds) and
``sleep_s`` (seconds to wait, to make builds overlap)."""

from __future__ import annotations

import math
import os
import time

import numpy as np
from scipy.special import ndtr

from millfmu.dem import tables as T

D_GB_M = 0.8e-3
RHO_KG_PER_M3 = 2510.0
R_DISC_M = 0.036
POROSITY = 0.4
SIGMA_DECADES = 0.6


def q50_norm(v, phi):
    """Median SE / E_ref of the analytic builder, per zone (2 zones)."""
    return np.array([2e-3, 5e-4]) * math.exp(-0.08 * v) * (0.5 + phi ** 2)


def _densities(mu) -> list:
    """Log-normal densities over log10(SE / E_ref) [1/decade] with medians 10^mu per zone
    (components tn, ts, total 0, 0.3, 0.5 decades above), binned exactly."""
    U = T.norm_log10_edges()
    dens = []
    for shift in (0.0, 0.3, 0.5):  # components tn, ts, total
        rows = []
        for m in mu + shift:
            F = ndtr((U - m) / SIGMA_DECADES)
            w = np.diff(F)
            w[0] += F[0]
            w[-1] += 1.0 - F[-1]
            rows.append(w / np.diff(U))
        dens.append(rows)
    return dens


def analytic_builder(scene: dict, point: dict) -> dict:
    if scene.get("count_file"):
        with open(scene["count_file"], "a") as fh:
            fh.write(f"{os.getpid()}\n")
    if scene.get("sleep_s"):
        time.sleep(float(scene["sleep_s"]))
    v = float(point.get("tip_speed_m_per_s", 10.0))
    phi = float(point.get("filling", 0.8))
    mu = np.log10(q50_norm(v, phi))
    dens = _densities(mu)
    z = 10.0 ** (np.array([-1.2816, 0.0, 1.2816]) * SIGMA_DECADES)
    quant = np.array([[q * z for q in 10.0 ** (mu + s)] for s in (0.0, 0.3, 0.5)])
    freq = np.array([0.05, 0.02]) * math.exp(0.5 * phi) * (1.0 + 0.02 * v)
    return {
        "zone_names": ["A", "B"],
        "volume_fraction": np.array([0.3, 0.7]),
        "filling_local": phi * np.array([0.9, 1.05]),
        "speed_over_tip_speed": np.array([0.1, 0.05]) * (1.0 + 0.01 * v),
        "collision_frequency_norm": freq,
        "collision_power_norm": freq * q50_norm(v, phi) * 3.0,
        "collision_count": np.round(1e4 * freq),
        "se_density": np.array(dens),
        "se_quantiles_norm": quant,
        "e_ref_J": T.e_ref_J(D_GB_M, RHO_KG_PER_M3, v),
        "omega_rad_per_s": v / R_DISC_M,
        "n_gb_per_m3": T.n_gb_per_m3(phi, POROSITY, D_GB_M),
    }


def spec(grid=None, kernel_version="test-kernel-1", **scene):
    """TableSpec for the analytic builder."""
    return T.TableSpec(scene={"name": "analytic", **scene},
                       grid=grid or {"tip_speed_m_per_s": [6.0, 10.0, 14.0],
                                     "filling": [0.5, 0.7, 0.9]},
                       kernel_version=kernel_version,
                       builder_id=T.builder_id_of(analytic_builder))


def count(path) -> int:
    return len(open(path).read().split()) if os.path.exists(path) else 0


def separable_builder(scene: dict, point: dict) -> dict:
    """The analytic builder times factors of bead diameter and density that do not depend
    on tip speed or filling (a separable dependence, which one-at-a-time axes reproduce
    exactly): rates, speeds and fillings times (d/0.8 mm)^-0.4 (rho/2510)^0.2, the energy
    distribution shifted by (d/0.8 mm)^0.7 (rho/2510)^0.3. Reads d and rho from the point,
    else the scene's [beads]."""
    beads = scene.get("beads", {})
    d = float(point.get("bead_diameter_m", beads.get("diameter_m", D_GB_M)))
    rho = float(point.get("bead_density_kg_per_m3", beads.get("density_kg_per_m3", RHO_KG_PER_M3)))
    out = analytic_builder(scene, point)
    f = (d / D_GB_M) ** -0.4 * (rho / RHO_KG_PER_M3) ** 0.2
    shift = math.log10((d / D_GB_M) ** 0.7 * (rho / RHO_KG_PER_M3) ** 0.3)
    for k in ("filling_local", "speed_over_tip_speed", "collision_frequency_norm",
              "collision_power_norm"):
        out[k] = out[k] * f
    out["se_quantiles_norm"] = out["se_quantiles_norm"] * 10.0 ** shift
    v = float(point.get("tip_speed_m_per_s", 10.0))
    phi = float(point.get("filling", 0.8))
    out["se_density"] = np.array(_densities(np.log10(q50_norm(v, phi)) + shift))
    return out


def separable_spec(anchor_filling=0.7, **kw):
    """TableSpec of :func:`separable_builder`: tip speed x filling grid, bead diameter and
    density one at a time from the scene's 10 m/s, ``anchor_filling``, 0.8 mm, 2510 kg/m3."""
    scene = {"name": "separable", "mill": {"tip_speed_m_per_s": 10.0},
             "beads": {"filling": anchor_filling, "diameter_m": D_GB_M,
                       "density_kg_per_m3": RHO_KG_PER_M3}}
    return T.TableSpec(scene=scene,
                       grid={"tip_speed_m_per_s": [6.0, 10.0, 14.0], "filling": [0.5, 0.7, 0.9]},
                       kernel_version="test-kernel-1",
                       builder_id=T.builder_id_of(separable_builder),
                       one_at_a_time=kw.get("one_at_a_time", {
                           "bead_diameter_m": [0.5e-3, D_GB_M, 1.2e-3],
                           "bead_density_kg_per_m3": [RHO_KG_PER_M3, 6040.0]}))


def dem_threads_builder(scene: dict, point: dict) -> dict:
    """:func:`analytic_builder` after a few steps of a small DEM on two threads, so that a
    process pool's worker runs the DEM's parallel kernels."""
    from millfmu.dem.engine.params import BeadMaterial
    from millfmu.dem.engine.sim import DemSimulation
    from millfmu.dem.mills.geometry import MillGeometry, place_beads

    geom = MillGeometry(shaft_radius_m=0.015, chamber_radius_m=0.019, height_m=0.004)
    x = place_beads(geom, 300, 0.4e-3, seed=5)
    DemSimulation(geom, BeadMaterial(), x, 0.4e-3, 300.0, 5e-6, threads=2).run(20)
    return analytic_builder(scene, point)


class CostedBuilder:
    """The analytic builder with a cost estimate: the cost of a point is its filling (so
    that the costliest-first order differs from the grid order). Each call appends its
    point's filling to the scene's ``count_file``, so a test can read the run order."""

    builder_id = "tests.costed"

    def __call__(self, scene: dict, point: dict) -> dict:
        with open(scene["count_file"], "a") as fh:
            fh.write(f"{point['tip_speed_m_per_s']} {point['filling']} {os.getpid()}\n")
        return analytic_builder(dict(scene, count_file=None), point)

    def relative_cost(self, scene: dict, point: dict) -> float:
        return float(point["filling"])



class FakeDemBuilder:
    """The analytic builder standing in for the DEM: it has the DEM's builder id, so that a
    build applies the installed DEM kernel version (monkeypatch
    ``millfmu.dem.tables.cache.dem_kernel_version``), a relative cost (filling x tip speed)
    and a recorded wall time of 2 s per cost unit, so that estimates are exact. Each call is
    appended to ``events`` (("build", point)), beside whatever a test logs there."""

    builder_id = T.DEM_BUILDER_ID
    seconds_per_cost = 2.0

    def __init__(self, events=None):
        self.events = events if events is not None else []

    def __call__(self, scene: dict, point: dict) -> dict:
        self.events.append(("build", dict(point)))
        out = analytic_builder(scene, point)
        out["wall_time_s"] = self.seconds_per_cost * self.relative_cost(scene, point)
        return out

    def relative_cost(self, scene: dict, point: dict) -> float:
        return float(point.get("filling", 0.8)) * float(point.get("tip_speed_m_per_s", 10.0))
