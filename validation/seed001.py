"""Seed 001 side by side: the statements of its section 3 against millfmu's disc slice,
with the coupled fluid and with the prescribed swirl.

From a checkout's root, ``python -m validation.seed001 run --out DIR`` runs the cases
(disc_slice, rotationally periodic sector without gravity; 80 % filling at 6, 8, 10, 12,
14 m/s, and 50 % and 90 % at 6 m/s) into ``DIR/<c|p>_v<tip speed>_f<filling %>``;
``python -m validation.seed001 table --out DIR`` reads
their ``stats.json`` and prints one row per statement: the paper's value, ours (coupled),
ours (prescribed), verdict. ``python -m validation.seed001 summarize --out DIR`` keeps what
the table reads of the coupled cases in ``validation/runs/seed001_sector.json`` (zone
statistics and the flow's census); ``table`` without ``--out`` computes the table from it.
``run --out DIR --full-slice`` runs seed 001's own configuration (the whole slice with
gravity) at the same cases, each from its checkpoint, into ``DIR/c360_v<tip speed>_f<filling
%>``; ``summarize --full-slice`` keeps them beside the sector's. The verdict is the full
slice's where it decides the statement (every case of it run, or a miss at a case run), else
the sector's; a quantitative statement counts as met within the tolerance named in its row;
a statement the runs' statistics cannot judge is listed as not evaluated, and the count below
the table says how many of each.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from millfmu.dem.analysis.compare import chamber_collision_density, zone

#: (tip speed [m/s], filling [-]) of seed 001's cases used here
CASES = ((10.0, 0.8), (6.0, 0.8), (14.0, 0.8), (6.0, 0.5), (6.0, 0.9), (8.0, 0.8),
         (12.0, 0.8))
FLUIDS = {"coupled": "c", "prescribed": "p"}


def case_dir(out_dir, fluid: str, tip_speed: float, filling: float, sector_deg=None) -> Path:
    tag = FLUIDS[fluid] + ("" if sector_deg in (None, 10.0) else f"{sector_deg:g}")
    return Path(out_dir) / f"{tag}_v{tip_speed:g}_f{round(filling * 100)}"


#: coupled protocol: beads and fluid start at this fraction of the stirrer's rotation ...
COUPLED_INITIAL_ROTATION = 0.1
#: ... and spin up for this long before the recording [s]. Measured at 10 m/s and 80 %:
#: after 25 stirrer revolutions (0.565 s) zone bead speeds were settled (windows within
#: 3 %) but beads still moved from V1 to V2 (V2's collision density rose 12 % over the
#: recording); after 1.0 s, windows of 0.1 s agree within 2 % in zone speeds and within
#: 6 % in zone collision densities, without a trend (see docs/validation-seed001.md).
COUPLED_SPIN_UP_S = 1.0
PRESCRIBED_SPIN_UP_S = 0.3
#: recording [s] (three windows of WINDOW_S for the stationarity check)
RECORD_S = 0.3
WINDOW_S = 0.1


@dataclass(frozen=True)
class Variant:
    """One variant of the sector campaign, in one place for its run, its summary and its
    command line: ``key`` names it in :func:`run_campaign`, :func:`summarize` and the
    summary's protocol; ``override`` is the :meth:`DemScene.with_overrides` key it sets
    (None: not a scene override, the stated bead counts, which set each case's sector);
    ``flag`` its command-line option; ``note`` what the summary's note says of a value;
    ``protocol`` what the summary's protocol keeps of it (default ``{key: value}``);
    ``cli`` the option's argparse settings."""

    key: str
    override: str | None
    flag: str
    note: Callable[[object], str]
    cli: dict
    protocol: Callable[[object], dict] | None = None

    def flag_text(self, value) -> str:
        """The option as the summary's commands give it (' --flag value')."""
        if value is True:
            return f" {self.flag}"
        return f" {self.flag} {value:g}" if isinstance(value, float) else f" {self.flag} {value}"

    def protocol_items(self, value) -> dict:
        return self.protocol(value) if self.protocol is not None else {self.key: value}


#: the sector campaign's variants, in the order their options and phrases appear
VARIANTS = (
    Variant("smoothing_diameters", "smoothing_diameters", "--smoothing-diameters",
            lambda v: f"the exchange smoothed over {v:g} bead diameters, not the scene's 1",
            dict(type=float, metavar="D", help="run and summarize: a variant of the sector "
                 "campaign with the coupled exchange smoothed over D bead diameters instead of "
                 "the scene's 1")),
    Variant("wall_friction", "wall_friction", "--wall-friction",
            lambda v: f"bead-wall friction {v:g}, not seed 001's one value (0.3) for every contact",
            dict(type=float, metavar="MU", help="run and summarize: a variant of the sector "
                 "campaign with the bead-wall friction MU instead of seed 001's one value (0.3) "
                 "for every contact")),
    Variant("stated_counts", None, "--stated-bead-counts",
            lambda v: ("the number of beads seed 001 states (155,520 at 50 %, 289,951 at 90 %, "
                       "linear between), not eq. 2's on its stated geometry; each run's "
                       "filling_eq2 is eq. 2's filling it ran at"),
            dict(action="store_true", dest="stated_counts", help="run and summarize: a variant "
                 "of the sector campaign with the number of beads seed 001 states (155,520 at "
                 "50 %%, 289,951 at 90 %%, linear between) instead of its eq. 2's on its stated "
                 "geometry (5.7-9.5 %% fewer)"),
            protocol=lambda v: {"bead_counts": "seed 001's stated"}),
    Variant("bead_stress_force", "bead_stress_force", "--bead-stress-force",
            lambda v: (f"model A's beads take the viscous stress's share too ({v}), as "
                       f"CFDEMcoupling's model A requires; seed 001 names no model type"),
            dict(metavar="NAME", help="run and summarize: a variant of the sector campaign whose "
                 "model A beads take the viscous stress's share too (anderson_jackson1967) "
                 "instead of the pressure's alone")),
    Variant("vans_model", "vans_model", "--vans-model",
            lambda v: (f"the liquid by model {v} (model B: the beads feel the drag alone, over "
                       "eps, which carries the pressure's and stresses' share; seed 001 names no "
                       "model type, the scene's is A)"),
            dict(choices=("A", "B"), help="run and summarize: a variant of the sector campaign "
                 "with the liquid by this model instead of the scene's A (B: drag alone on the "
                 "beads)")),
)
_VARIANT = {v.key: v for v in VARIANTS}


def _variants(given: dict) -> dict:
    """The variants named in ``given`` (keyword: value) that are set (not None, not False);
    an unknown keyword refused by name."""
    unknown = sorted(set(given) - set(_VARIANT))
    if unknown:
        raise TypeError(f"unknown campaign variant(s) {unknown}: allowed {sorted(_VARIANT)}")
    # in the table's order, so that a summary's phrases and options read the same however
    # they were given; identity tests, since a variant may be 0 (0.0 == False)
    return {v.key: given[v.key] for v in VARIANTS
            if given.get(v.key) is not None and given.get(v.key) is not False}


def with_variant(scene, key: str, value):
    """The scene with the variant ``key`` (one of :data:`VARIANTS`' scene overrides) at
    ``value`` (None: the scene as it is), checked by :meth:`DemScene.with_overrides`:
    smoothing_diameters [bead diameters] >= 0, wall_friction [-] >= 0, bead_stress_force
    by name and only with model A, vans_model 'A' or 'B' and only on the volume-averaged
    liquid."""
    var = _VARIANT[key]
    if var.override is None:
        raise ValueError(f"{key}: not a scene override (the stated counts set each case's "
                         f"sector: with_stated_count)")
    if value is None:
        return scene
    return scene.with_overrides(**{var.override: value})


#: seed 001's stated numbers of beads in its slice at its lowest and highest filling [-]
#: (section 2.1: "between 155,520 and 289,951" for 50 to 90 %)
STATED_BEAD_COUNTS = ((0.5, 155_520), (0.9, 289_951))


def stated_count_filling(filling: float, scene=None) -> float:
    """Eq. 2's filling [-] on the scene's slice (default disc_slice: seed 001's stated
    geometry, the whole circle) that holds the number of beads seed 001 states for its
    filling ``filling`` [-]: :data:`STATED_BEAD_COUNTS` at 50 and 90 %, linear in between
    (seed 001 states none for 60-80 %; a power law through the two points differs by 0.1 %
    at 80 %). The stated counts are 5.7 and 9.5 % above eq. 2 on the stated geometry (0.8 mm
    beads, porosity 0.4), so this gives 0.529 and 0.986 for 50 and 90 %. Refused outside
    50-90 %."""
    from millfmu.dem.scene import load_scene

    (f0, n0), (f1, n1) = STATED_BEAD_COUNTS
    if not (f0 <= filling <= f1):
        raise ValueError(f"filling = {filling!r}: seed 001 states bead counts for {f0:g} to "
                         f"{f1:g} only")
    sc = scene if scene is not None else load_scene("disc_slice")
    v_free = sc.with_overrides(sector_deg=360.0).geometry.free_volume_m3()
    per_filling = (1.0 - sc.bulk_porosity) * v_free / (math.pi / 6.0 * sc.bead_diameter_m ** 3)
    return (n0 + (filling - f0) / (f1 - f0) * (n1 - n0)) / per_filling


def stated_count_sector_deg(filling: float, sector_deg: float = 10.0, scene=None) -> float:
    """The sector [deg] a stated-count case runs in: ``sector_deg``, or the smallest multiple
    of it whose initial lattice (fcc with the placement's gap) holds the stated count
    (:func:`stated_count_filling`); at 90 % the 10-degree sector holds 7,644 beads of the
    8,054 stated for it, a 20-degree one 16,376 of 16,108."""
    from millfmu.dem.mills.geometry import bead_count_for_filling, fcc_sites, placement_gap_m
    from millfmu.dem.scene import load_scene

    sc = scene if scene is not None else load_scene("disc_slice")
    phi = stated_count_filling(filling, sc)
    r = 0.5 * sc.bead_diameter_m
    k = 1
    while k * sector_deg < 360.0:
        g = sc.with_overrides(sector_deg=k * sector_deg, gravity_m_per_s2=(0.0, 0.0, 0.0)).geometry
        if bead_count_for_filling(g, phi, sc.bead_diameter_m, sc.bulk_porosity) <= \
                fcc_sites(g, r, placement_gap_m(r)).shape[0]:
            break
        k += 1
    return min(k * sector_deg, 360.0)


def with_stated_count(scene, stated: bool):
    """The scene (its ``filling`` the campaign's nominal one) with as many beads as seed 001
    states for that filling (:func:`stated_count_filling`) where ``stated``. Set past the
    scene's range check: at 90 % the stated count lies at eq. 2's 0.986, above the 0.9 the
    scenes allow (seed 001's nominal range)."""
    from dataclasses import replace

    if not stated:
        return scene
    return replace(scene, filling=stated_count_filling(scene.filling, scene))


def run_campaign(out_dir, fluids=("coupled", "prescribed"), sector_deg: float = 10.0,
                 cases=CASES, threads=None, progress=True, **variants):
    """Run the cases that have no stats.json yet, the protocol of the table in docs/validation-seed001.md:
    no gravity, 10 degree sector, coupled runs started at COUPLED_INITIAL_ROTATION and spun
    up for COUPLED_SPIN_UP_S (27-62 stirrer revolutions at 6-14 m/s); RECORD_S of recording
    in windows of WINDOW_S; samples every 0.01 s. ``variants``: keyword = value of the
    campaign's :data:`VARIANTS` (smoothing_diameters, wall_friction, stated_counts,
    bead_stress_force, vans_model; None or False: as the scene has it)."""
    from millfmu.dem.run import run_scene
    from millfmu.dem.scene import load_scene

    chosen = _variants(variants)
    stated_counts = bool(chosen.get("stated_counts"))
    base = load_scene("disc_slice")
    for key, value in chosen.items():
        if _VARIANT[key].override is not None:
            base = with_variant(base, key, value)
    for fluid in fluids:
        for vt, fill in cases:
            deg = stated_count_sector_deg(fill, sector_deg, base) if stated_counts else sector_deg
            d = case_dir(out_dir, fluid, vt, fill, deg)
            if (d / "stats.json").exists():
                continue
            sc = base.with_overrides(
                fluid_mode=fluid, tip_speed_m_per_s=vt, filling=fill, sector_deg=deg,
                gravity_m_per_s2=(0.0, 0.0, 0.0),
                spin_up_s=COUPLED_SPIN_UP_S if fluid == "coupled" else PRESCRIBED_SPIN_UP_S,
                record_s=RECORD_S, sample_every_s=0.01,
                initial_rotation=COUPLED_INITIAL_ROTATION if fluid == "coupled" else 0.0)
            run_scene(with_stated_count(sc, stated_counts), d, progress=progress,
                      threads=threads, window_s=WINDOW_S)


#: seed 001's own configuration: the whole slice (360 degrees) with the scene's gravity
#: across the axis, the liquid in 32 theta cells, at the sector campaign's cases (CASES,
#: 10 m/s and 80 % first) and by its protocol (coupled, started at
#: COUPLED_INITIAL_ROTATION, COUPLED_SPIN_UP_S, RECORD_S in windows of WINDOW_S); 2.5-4 h a
#: case on 2 threads, so each keeps a checkpoint
FULL_CASES = CASES
FULL_SECTOR_DEG = 360.0
FULL_THETA_CELLS = 32
#: [s of wall time] between the full slice's checkpoints
FULL_CHECKPOINT_EVERY_S = 600.0
#: a full-slice case folder's lock, held by the process that runs the case
FULL_LOCK = "running.lock"
#: the full slice's pressure solver: the direct solver's pressure equation by an FFT along
#: theta (to round-off; 9 ms a solve on this grid against 60 for the default direct_ldl,
#: about 16 % of a case's time; docs/dem-full-slices.md). A case goes on from its
#: checkpoint with the solver it was started with (10 m/s, 80 %: direct_ldl); each run's
#: summary names its own (``fluid_model``)
FULL_PRESSURE_SOLVER = "theta_fft"


def case_label(vt: float, fill: float) -> str:
    """A case as the summary and the table name it: '10 m/s, 80 %'."""
    return f"{vt:g} m/s, {round(fill * 100)} %"


def run_full_slice(out_dir, cases=FULL_CASES, threads=None, progress=True, say=None) -> list[Path]:
    """Run the full slice's ``cases`` one after the other into ``out_dir/c360_v<tip
    speed>_f<filling %>``, each from its checkpoint where it has one; a case with its
    stats.json is done, a case whose folder another process holds (its lock) is left to it.
    Returns the folders of the cases done."""
    from millfmu.dem.run import CHECKPOINT, resume_run, run_scene
    from millfmu.dem.tables.point_folders import hold

    say = say or (lambda m: print(m, file=sys.stderr, flush=True))
    done = []
    for vt, fill in cases:
        d = case_dir(out_dir, "coupled", vt, fill, FULL_SECTOR_DEG)
        if (d / "stats.json").exists():
            done.append(d)
            continue
        d.mkdir(parents=True, exist_ok=True)
        with open(d / FULL_LOCK, "a+") as lock:
            if not hold(lock):
                say(f"{d}: run by another process; the next case")
                continue
            if (d / "stats.json").exists():  # finished by another process meanwhile
                pass
            elif (d / CHECKPOINT).exists():
                say(f"{d}: going on from its checkpoint")
                resume_run(d, progress=progress, threads=threads)
            else:
                run_scene(full_slice_scene(vt, fill), d, progress=progress, threads=threads,
                          window_s=WINDOW_S, checkpoint_every_s=FULL_CHECKPOINT_EVERY_S)
        done.append(d)
    return done


def full_slice_scene(vt: float = 10.0, fill: float = 0.8):
    """The full slice at tip speed ``vt`` [m/s] and filling ``fill`` [-] as a DEM scene
    (disc_slice with the campaign's protocol and :data:`FULL_PRESSURE_SOLVER`; the scene's
    gravity kept)."""
    from millfmu.dem.scene import load_scene

    return load_scene("disc_slice").with_overrides(
        fluid_mode="coupled", tip_speed_m_per_s=vt, filling=fill, sector_deg=FULL_SECTOR_DEG,
        n_theta=FULL_THETA_CELLS, spin_up_s=COUPLED_SPIN_UP_S, record_s=RECORD_S,
        sample_every_s=0.01, initial_rotation=COUPLED_INITIAL_ROTATION,
        pressure_solver=FULL_PRESSURE_SOLVER)


def _load(out_dir, fluid, vt, fill, sector_deg=None):
    return load_dir(case_dir(out_dir, fluid, vt, fill, sector_deg))


def _load_sector(out_dir, fluid, vt, fill):
    """A sector case's stats: the 10-degree sector's, else the larger sector a stated-count
    variant runs it in where seed 001's count does not fit (:func:`stated_count_sector_deg`)."""
    st = _load(out_dir, fluid, vt, fill)
    if st is None:
        deg = stated_count_sector_deg(fill)
        if deg != 10.0:
            st = _load(out_dir, fluid, vt, fill, deg)
    return st


def load_dir(d) -> dict | None:
    """A run folder's stats.json with its vortices recounted and its collision maps' peaks
    (:func:`map_peaks`) as ``maps``; None where the run has not finished."""
    d = Path(d)
    p = d / "stats.json"
    if not p.exists():
        return None
    st = json.loads(p.read_text())
    _recount_vortices(d, st)
    maps = d / "collision_maps.npz"
    if maps.exists():
        st["maps"] = map_peaks(np.load(maps))
    return st


#: "in two grinding bead diameters distance to the grinding chamber wall" (section 3.4):
#: the collision frequency's peak counts as there where its distance rounds to two bead
#: diameters
WALL_PEAK_DIAMETERS = (1.5, 2.5)
#: the radial profile's quarter-bead bins averaged over one bead diameter before its peak is
#: read: at quarter-bead bins the packed layers at the wall make a comb (contacts between
#: two layers, none within one), whose teeth would decide the peak
PROFILE_MEAN_BINS = 4
#: "at the side of the outer edge of the stirrer disc" (section 3.5): the collision power
#: density's peak counts as there within this many bead diameters of the disc's rim
RIM_PEAK_DIAMETERS = 2.0


def map_peaks(maps) -> dict:
    """Where the recorded collisions peak (a run's ``collision_maps.npz``, disc slice):
    the radial profile's highest collision frequency (every axial position together, bins
    of a quarter bead diameter averaged over one bead diameter, :data:`PROFILE_MEAN_BINS`)
    and the highest of it within three bead diameters of the wall, with their distances
    from the chamber wall; and the axial section's highest collision power density (bins of
    1 mm) with its distance from the disc's rim (the disc's outer face, r = R_disc over its
    thickness, corners included). Units: m, 1/(m3 s), W/m3; distances also in bead
    diameters."""
    from millfmu.dem.scene import load_scene

    sc = load_scene("disc_slice")
    g, dia = sc.geometry, sc.bead_diameter_m
    re_ = maps["profile_r_edges_m"]
    k = np.ones(PROFILE_MEAN_BINS) / PROFILE_MEAN_BINS
    rc = np.convolve(0.5 * (re_[1:] + re_[:-1]), k, mode="valid")
    f = np.convolve(maps["profile_collision_frequency_per_m3_s"], k, mode="valid")
    near = g.chamber_radius_m - rc <= 3.0 * dia

    def peak(mask):
        i = int(np.flatnonzero(mask)[np.argmax(f[mask])])
        w = g.chamber_radius_m - rc[i]
        return {"r_m": float(rc[i]), "from_wall_m": float(w), "from_wall_diameters": float(w / dia),
                "collision_frequency_per_m3_s": float(f[i])}

    pw = maps["collision_power_w_per_m3"]
    iz, ir = np.unravel_index(int(np.nanargmax(pw)), pw.shape)
    ze, rme = maps["z_edges_m"], maps["r_edges_m"]
    z = 0.5 * (ze[iz] + ze[iz + 1])
    r = 0.5 * (rme[ir] + rme[ir + 1])
    hb = 0.5 * g.disc_thickness_m
    rim = math.hypot(max(abs(z) - hb, 0.0), r - g.disc_radius_m)
    return {"frequency_peak": peak(np.ones_like(near)), "frequency_peak_near_wall": peak(near),
            "power_peak": {"z_m": float(z), "r_m": float(r), "power_w_per_m3": float(pw[iz, ir]),
                           "from_rim_m": float(rim), "from_rim_diameters": float(rim / dia)}}


#: What the deviation table reads of a run's stats.json: per zone and of the flow section.
ZONE_KEYS = ("name", "volume_m3", "speed_over_tip_speed", "collision_frequency_per_m3_s",
             "collision_power_w")
FLOW_KEYS = ("first_bead_layer_angular_velocity_ratio", "vortices_fluid", "vortices_beads")
#: The shipped summary of the coupled sector cases, from which the page's table is computed.
SUMMARY = Path(__file__).resolve().parent / "runs" / "seed001_sector.json"
#: The kept summary of the full slice run by seed 001's own protocol (2 s of spin-up from
#: rest, 1 s recorded with 50 samples; :mod:`validation.full_slice_paper`). Once that run has
#: finished, the full-slice column takes its case from it instead of the run by the
#: campaign's shorter protocol: the same configuration, by the paper's method.
FULL_PAPER_SUMMARY = Path(__file__).resolve().parent / "runs" / "seed001_full_paper.json"
#: how the table marks a full-slice case taken from that run
BY_PAPER_PROTOCOL = "by seed 001's protocol"
#: that run's case: seed 001's reference point, which the cold and warm full slices ran
PAPER_CASE = (10.0, 0.8)


def paper_case_dir(out_dir) -> Path:
    """The folder of the full slice by seed 001's protocol in ``out_dir``."""
    vt, fill = PAPER_CASE
    return Path(out_dir) / f"p360_v{vt:g}_f{round(fill * 100)}"


def compact(st: dict) -> dict:
    """The part of a run's stats (vortices recounted) that :func:`deviation_rows` reads: zone
    statistics (with the local filling where the run has it) and the flow's census, no raw
    contacts or maps."""
    zones = []
    for z in st["zones"]:
        c = {k: z.get(k) for k in ZONE_KEYS}
        if z.get("filling") is not None:  # local filling [-], where the run has it
            c["filling"] = z["filling"]
        c["se"] = {"tn": {"quantiles_j": {"q50": z["se"]["tn"]["quantiles_j"]["q50"]}}}
        zones.append(c)
    flow = st.get("flow", {})
    out = {"zones": zones, "flow": {k: flow[k] for k in FLOW_KEYS if k in flow}}
    if st.get("fluid_model"):  # the liquid's model and solvers, in words
        out["fluid_model"] = st["fluid_model"]
    if "maps" in st:
        out["maps"] = st["maps"]
    return out


def summarize(out_dir, path=None, full_slice: bool = False, **variants) -> Path:
    """Write the compact stats of the coupled cases in ``out_dir`` (:func:`compact`) to
    ``path`` (default :data:`SUMMARY`), with the protocol and the command that made them;
    ``full_slice``: instead the full slice's cases found there (:func:`run_full_slice`),
    kept under ``full_slice`` beside the sector's cases with those kept before. Either keeps
    the other's part of the file.
    ``variants``: the :data:`VARIANTS` the runs were made with (keyword = value, as
    :func:`run_campaign` took them; a variant campaign, summarized into a file of its own; a
    stated-count run keeps eq. 2's filling it ran at)."""
    chosen = _variants(variants)
    stated_counts = bool(chosen.get("stated_counts"))
    p = Path(path) if path is not None else SUMMARY
    old = json.loads(p.read_text()) if p.exists() else {}
    protocol = {"initial_rotation": COUPLED_INITIAL_ROTATION, "spin_up_s": COUPLED_SPIN_UP_S,
                "record_s": RECORD_S, "window_s": WINDOW_S, "sample_every_s": 0.01}
    if full_slice:
        runs = dict((old.get("full_slice") or {}).get("runs", {}))
        found = 0
        for vt, fl in FULL_CASES:
            st = _load(out_dir, "coupled", vt, fl, FULL_SECTOR_DEG)
            if st is not None:
                found += 1
                runs[case_label(vt, fl)] = {"tip_speed_m_per_s": vt, "filling": fl, "stats": compact(st)}
        if not found:
            first = case_dir(out_dir, "coupled", *FULL_CASES[0], FULL_SECTOR_DEG).name
            raise FileNotFoundError(f"{out_dir}: no full-slice case with a stats.json ({first}, ...; "
                                    f"run them: python -m validation.seed001 run --out {out_dir} "
                                    "--full-slice)")
        order = [case_label(*k) for k in FULL_CASES]
        doc = dict(old)
        doc["full_slice"] = {
            "note": ("seed 001's own configuration: the whole disc slice with gravity across the "
                     "axis, coupled, at the cases run so far; what the deviation table reads (units as "
                     "above)"),
            "protocol": dict(protocol, sector_deg=FULL_SECTOR_DEG, theta_cells=FULL_THETA_CELLS,
                             gravity_m_per_s2="the scene's"),
            "command": "python -m validation.seed001 run --out DIR --full-slice [--case 10:0.8 ...] "
                       "--threads 2, then python -m validation.seed001 summarize --out DIR --full-slice",
            "runs": {k: runs[k] for k in sorted(runs, key=lambda k: order.index(k) if k in order
                                                else len(order))}}
    else:
        runs = {}
        for vt, fl in CASES:
            deg = stated_count_sector_deg(fl) if stated_counts else None
            st = _load(out_dir, "coupled", vt, fl, deg)
            if st is not None:
                runs[case_label(vt, fl)] = {"tip_speed_m_per_s": vt, "filling": fl,
                                            **({"filling_eq2": stated_count_filling(fl),
                                                "sector_deg": deg} if stated_counts else {}),
                                            "stats": compact(st)}
        var = "".join(_VARIANT[k].flag_text(v) for k, v in chosen.items())
        dest = "" if path is None else f" --summary validation/runs/{Path(path).name}"
        doc = {"note": ("seed 001's cases on the coupled 10-degree disc sector without gravity: per zone "
                        "what the deviation table reads (units: m3, 1/(m3 s), W, J), the flow's first "
                        "bead layer and vortex census"
                        + "".join(f"; a variant: {_VARIANT[k].note(v)}" for k, v in chosen.items())),
               "protocol": dict(protocol, sector_deg=10.0, gravity_m_per_s2=[0.0, 0.0, 0.0], threads=1,
                                **{k2: v2 for k, v in chosen.items()
                                   for k2, v2 in _VARIANT[k].protocol_items(v).items()}),
               "command": f"python -m validation.seed001 run --out DIR --fluid coupled --threads 1{var}, then "
                          f"python -m validation.seed001 summarize --out DIR{var}{dest}",
               "runs": runs}
        if "full_slice" in old:
            doc["full_slice"] = old["full_slice"]
    p.write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return p


def summary_stats(path=None, full_slice: bool = False) -> dict:
    """{(tip speed, filling): compact stats} of the shipped summary (:data:`SUMMARY`): its
    sector cases, or (``full_slice``) its full slice's cases, {} where it has none."""
    doc = json.loads(Path(path if path is not None else SUMMARY).read_text())
    part = doc.get("full_slice", {}) if full_slice else doc
    return {(r["tip_speed_m_per_s"], r["filling"]): r["stats"]
            for r in part.get("runs", {}).values()}


def paper_protocol_stats(path=None) -> dict:
    """{(tip speed [m/s], filling [-]): compact stats} of the full slice run by seed 001's
    own protocol (:data:`FULL_PAPER_SUMMARY`, or ``path``) once it has finished; {} while it
    runs or where no such summary is kept."""
    p = Path(path) if path is not None else FULL_PAPER_SUMMARY
    if not p.exists():
        return {}
    doc = json.loads(p.read_text())
    if not doc.get("finished"):
        return {}
    return {(doc["tip_speed_m_per_s"], doc["filling"]): doc["stats"]}


def _recount_vortices(d: Path, st: dict):
    """Vortex census from the saved section fields (fluid_fields.npz, bead_fields.npz) with
    the current rule of :mod:`millfmu.dem.analysis.flow_structure`, so that runs made before a change
    of the rule are counted alike."""
    from millfmu.dem.analysis import flow_structure as FS
    from millfmu.dem.scene import load_scene

    g = load_scene("disc_slice").geometry
    hb = 0.5 * g.disc_thickness_m
    top = hb + 2.5e-3
    flow = st.setdefault("flow", {})
    for name, fname, thr in (("vortices_fluid", "fluid_fields.npz", 0.01),
                             ("vortices_beads", "bead_fields.npz", 0.05)):
        p = d / fname
        if not p.exists():
            continue
        f = np.load(p)
        if name == "vortices_fluid":
            order = np.argsort(f["zeta_m"])
            zs = f["zeta_m"][order]
            r = f["r_m"]
            rf = np.concatenate([[g.shaft_radius_m], 0.5 * (r[1:] + r[:-1]),
                                 [g.chamber_radius_m]])
            flux = np.nan_to_num(f["flux_z"][:, order])
            valid = np.isfinite(f["eps"][:, order])
        else:
            rf, ze = f["r_edges_m"], f["zeta_edges_m"]
            r, zs = 0.5 * (rf[1:] + rf[:-1]), 0.5 * (ze[1:] + ze[:-1])
            flux, valid = f["flux_z"], f["samples"] > 0
        psi = FS.stream_function(r, flux, np.diff(rf))
        flow[name] = FS.vortex_summary(FS.vortices(psi, r, zs, g.disc_radius_m, hb,
                                                   valid=valid, threshold=thr,
                                                   tip_zone_top_m=top))


#: Where the prescribed column comes from when no prescribed runs exist in the folder.
TABLE_NOTE = ("prescribed swirl: the shipped default table (10 degree sector, 0.05 s "
              "spin-up, 0.1 s recording per grid point)")


def prescribed_from_table(vt: float, fill: float, table=None) -> dict | None:
    """Zone statistics of the prescribed-swirl DEM at a grid point of the shipped
    prescribed-swirl table (millfmu/data/prescribed_table.*), in the form of a run's
    stats.json (zones only; energies, frequencies and powers scaled back from the table's
    normalisation). None off the grid."""
    import millfmu
    from millfmu.stress_tables.table import read_table

    if table is None:
        d = Path(millfmu.__file__).resolve().parent / "data"  # the package's data, wherever installed
        table = read_table(npz=d / "prescribed_table.npz", manifest_path=d / "prescribed_table.json")
    ax = table.axes
    try:
        i = int(np.flatnonzero(np.isclose(ax["tip_speed_m_per_s"], vt))[0])
        j = int(np.flatnonzero(np.isclose(ax["filling"], fill))[0])
    except IndexError:
        return None
    e_ref = float(table.refs["e_ref_J"][i, j])
    rate = float(table.refs["omega_rad_per_s"][i, j] * table.refs["n_gb_per_m3"][i, j])
    dat = table.data
    q50 = list(dat["se_quantiles_norm"][i, j, 0, :, 1])  # component tn, quantile q50
    zones = []
    for k, name in enumerate(table.zone_names):
        vol = float(dat["volume_fraction"][i, j, k])
        zones.append(dict(
            name=name, volume_m3=vol,
            speed_over_tip_speed=float(dat["speed_over_tip_speed"][i, j, k]),
            collision_frequency_per_m3_s=float(dat["collision_frequency_norm"][i, j, k]) * rate,
            collision_power_w=float(dat["collision_power_norm"][i, j, k]) * e_ref * rate * vol,
            se={"tn": {"quantiles_j": {"q50": float(q50[k]) * e_ref}}}))
    return dict(zones=zones, flow={}, source=TABLE_NOTE)


#: seed 001's mean bead speed over tip speed per zone at 80 % filling (section 3.2, Fig. 8a)
SPEED_BANDS = {"V1": (0.12, 0.14), "V2": (0.095, 0.095), "V3": (0.085, 0.085)}
#: seed 001's first bead layer at the disc, angular velocity over the disc's (section 3.2)
FIRST_LAYER_BAND = (0.20, 0.26)
#: how far beyond seed 001's value or range a figure still matches it [-]
BAND_TOLERANCE = 0.15
#: "no significant influence" of the tip speed on a zone's local filling (seed 001 section
#: 3.1): its spread (max - min) over its mean across 6-14 m/s at most this [-]
FILLING_SPREAD = 0.15
#: "about proportional" (seed 001 section 3.1): local over total filling of V1 and of V4
#: at 50, 80 and 90 % within a factor 1 + this of each other [-]
FILLING_PROPORTIONAL = 0.5


def within_band(v: float, lo: float, hi: float, tol: float = BAND_TOLERANCE) -> bool:
    """Whether ``v`` lies in [lo (1 - tol), hi (1 + tol)]: seed 001's value or range and
    the tolerance its figures are read with."""
    return lo * (1.0 - tol) <= v <= hi * (1.0 + tol)


def _fmt(x, nd=3):
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else \
        f"{x:.{nd}g}"


def deviation_rows(out_dir=None, summary=None, paper_summary=None, full_slice: bool = True) -> list[dict]:
    """One dict per statement of seed 001 section 3: statement, paper, coupled (the sector
    campaign), full (the full slice, seed 001's configuration, at the cases it has run: the
    values and whether the statement holds there), prescribed, verdict: of the run folders
    in ``out_dir``, or with None of the summary ``summary`` (default the shipped one,
    :data:`SUMMARY`). A full-slice case run by seed 001's own protocol takes the place of the
    same case by the campaign's protocol, and its cells say so: from its run folder in
    ``out_dir``, else from ``paper_summary`` (default: :data:`FULL_PAPER_SUMMARY` with the
    shipped summary, none with another, such as a variant campaign's). The
    verdict is the full slice's where it has run every case of the statement, or misses it
    at a case it has run (the statement then fails on seed 001's configuration whatever the
    other cases give); else the sector's. ``full_slice`` False: the sector's verdicts alone
    (no full-slice case read), as a variant campaign is judged."""
    full, by_protocol = {}, {}
    if out_dir is None:
        shipped = summary_stats(summary)
        if full_slice:
            full = summary_stats(summary, full_slice=True)
            if paper_summary is None and summary is None:
                paper_summary = FULL_PAPER_SUMMARY
            by_protocol = paper_protocol_stats(paper_summary) if paper_summary is not None else {}
        runs = {"coupled": {k: shipped.get(k) for k in CASES}, "prescribed": {k: None for k in CASES}}
    else:
        runs = {f: {(vt, fl): _load_sector(out_dir, f, vt, fl) for vt, fl in CASES} for f in FLUIDS}
        if full_slice:
            full = {k: _load(out_dir, "coupled", *k, FULL_SECTOR_DEG) for k in FULL_CASES}
            full = {k: v for k, v in full.items() if v is not None}
            st = load_dir(paper_case_dir(out_dir))
            by_protocol = {} if st is None else {PAPER_CASE: st}
    full.update(by_protocol)
    runs["full"] = {k: full.get(k) for k in CASES}
    has_full = bool(full)
    source = "prescribed-swirl runs in the folder"
    if not any(runs["prescribed"].values()):
        runs["prescribed"] = {(vt, fl): prescribed_from_table(vt, fl) for vt, fl in CASES}
        source = TABLE_NOTE
    at80 = sorted(vt for vt, fl in CASES if fl == 0.8)
    rows = []

    def per(f, fn, keys):
        out = []
        for k in keys:
            st = runs[f].get(k)
            out.append(None if st is None else fn(st))
        return out

    def mark(k):
        """How a full-slice case names its run by seed 001's protocol ('' for the others)."""
        return f" ({BY_PAPER_PROTOCOL})" if k in by_protocol else ""

    def show(vals, keys, nd=3, full=False):
        """'10 m/s 80 %: value; ...' of the cases run; the full slice's (``full``) named as
        run by seed 001's protocol where they were (:func:`mark`)."""
        def label(k):
            return f"{k[0]:g} m/s {round(k[1] * 100)} %" + (mark(k) if full else "")

        return "; ".join(f"{label(k)}: {v}" if isinstance(v, str) else f"{label(k)}: {_fmt(v, nd)}"
                         for v, k in zip(vals, keys) if v is not None) or "not run"

    def full_cell(fn, keys, accept, value=lambda v: v, text=None, keyed=False):
        """The full slice's cell and its verdict: fn(stats) at each case of ``keys`` it has
        run, shown by ``text``, judged by accept([value]) (``keyed``: accept([(case,
        value)])); (cell, True or False where the full slice decides the statement, else
        None, and its state at the cases run: 'holds', 'missed' or 'not judged'): it
        decides where it has run every case, or misses the statement at those run."""
        if not has_full:
            return "not run", None, "not judged"
        cases = [k for k in keys if runs["full"].get(k) is not None]
        if not cases:
            return "not run at these cases", None, "not judged"
        got = [(k, fn(runs["full"][k])) for k in cases]
        got = [(k, v) for k, v in got if v is not None]
        if not got:
            return "not evaluated", None, "not judged"
        shown = [text(v) if text else v if isinstance(v, str) else _fmt(v) for _, v in got]
        if len(keys) == 1:
            cell = shown[0] + mark(keys[0])
        else:
            cell = show(shown, [k for k, _ in got], full=True)
        judged = [(k, value(v)) for k, v in got if value(v) is not None]
        if not judged:
            return cell, None, "not judged"
        ok = accept(judged if keyed else [v for _, v in judged])
        if not ok:
            return f"{cell} (missed)", False, "missed"
        if len(judged) == len(keys):
            return f"{cell} (holds)", True, "holds"
        return f"{cell} (holds at the {len(judged)} of {len(keys)} cases run)", None, "holds"

    def verdict(sector_ok, full_ok, note=""):
        """The row's verdict: the full slice's where it decides, else the sector's (None:
        not run)."""
        if full_ok is not None:
            return ("matches" if full_ok else "missed") + " on the full slice" + note
        if sector_ok is None:
            return "not run"
        return ("matches" if sector_ok else "missed") + note

    def add_row(statement, paper, fn, keys, accept, note=""):
        """A row from fn(stats) per case in keys; verdict from accept(values)."""
        vals = {f: per(f, fn, keys) for f in FLUIDS}
        got = [v for v in vals["coupled"] if v is not None]
        cell, full_ok, state = full_cell(fn, keys, accept)
        rows.append(dict(statement=statement, paper=paper,
                         coupled=show(vals["coupled"], keys),
                         full=cell, full_state=state,
                         prescribed=show(vals["prescribed"], keys),
                         verdict=verdict(accept(got) if got else None, full_ok, note)))

    keys80 = [(vt, 0.8) for vt in at80]
    all_keys = list(CASES)
    # 1. mean bead speed over tip speed per zone at 80 %
    tol = BAND_TOLERANCE
    for zn, (lo, hi) in SPEED_BANDS.items():
        add_row(f"mean bead speed / tip speed in {zn} at 80 % (section 3.2, Fig. 8a)",
                f"{lo:.3g}" + (f"-{hi:.3g}" if hi != lo else ""),
                lambda st, zn=zn: zone(st, zn)["speed_over_tip_speed"], keys80,
                lambda got, lo=lo, hi=hi: all(within_band(v, lo, hi) for v in got),
                f" (within {tol:.0%})")
    # 2. first bead layer at the disc
    lo, hi = FIRST_LAYER_BAND
    add_row("angular velocity of the first bead layer at the disc / the disc's (section 3.2, "
            "Fig. 6b)", f"{lo:.2f}-{hi:.2f}",
            lambda st: st.get("flow", {}).get("first_bead_layer_angular_velocity_ratio"),
            keys80, lambda got: all(within_band(v, lo, hi) for v in got),
            f" (within {tol * 100:.0f} %)")

    # 3. median SE_tn order
    def order(st):
        med = {z["name"]: z["se"]["tn"]["quantiles_j"]["q50"] for z in st["zones"]}
        if any(v is None for v in med.values()):
            return "n/a"
        return " > ".join(sorted(med, key=lambda n: -med[n]))

    add_row("median SE_tn: V1 > V2 > V3 > V4 in all cases (section 3.3)", "V1 > V2 > V3 > V4",
            order, all_keys, lambda got: all(v == "V1 > V2 > V3 > V4" for v in got))

    # 4. collision density highest in V2, lowest in V1 (80 %)
    def dens_order(st):
        f = {z["name"]: z["collision_frequency_per_m3_s"] for z in st["zones"]}
        o = sorted(f, key=lambda n: -f[n])
        return f"max {o[0]}, min {o[-1]}"

    add_row("collision density highest in V2, lowest in V1 (80 %, all tip speeds; section 3.4, "
            "Fig. 14b)", "max V2, min V1", dens_order, keys80,
            lambda got: all(v == "max V2, min V1" for v in got))
    # 5. at 90 % V3 lowest
    add_row("at 90 % filling V3 has the lowest collision density (6 m/s)", "min V3",
            dens_order, [(6.0, 0.9)], lambda got: got[0].endswith("min V3"))

    # 6. chamber collision density roughly linear in tip speed
    def linearity(f):
        pts = [(vt, chamber_collision_density(runs[f][(vt, 0.8)])) for vt in at80
               if runs[f].get((vt, 0.8)) is not None]
        if len(pts) < 3:
            return None, "fewer than 3 tip speeds"
        x, y = np.array(pts).T
        a, b = np.polyfit(x, y, 1)
        r2 = 1.0 - ((y - (a * x + b)) ** 2).sum() / ((y - y.mean()) ** 2).sum()
        txt = (", ".join(f"{vt:g}" + (mark((vt, 0.8)) if f == "full" else "") + f": {d:.3g}"
                         for vt, d in pts) +
               f" 1/(m3 s); linear fit R^2 {r2:.3f}, intercept / value at 10 m/s "
               f"{b / (a * 10 + b):+.2f}")
        return (r2, b / (a * 10 + b)), txt

    def linear(lin):
        return lin[0] >= 0.95 and abs(lin[1]) > 0.05

    lin_c, txt_c = linearity("coupled")
    lin_p, txt_p = linearity("prescribed")
    lin_f, txt_f = linearity("full")
    n_full = sum(runs["full"].get((vt, 0.8)) is not None for vt in at80)
    full_ok = None
    state = "not judged"
    if not has_full:
        cell = "not run"
    elif lin_f is None:
        cell = f"not evaluated ({'one tip speed' if n_full == 1 else f'{n_full} tip speeds'})"
    elif n_full == len(at80):
        full_ok = linear(lin_f)
        state = "holds" if full_ok else "missed"
        cell = f"{txt_f} ({state})"
    else:
        cell = f"{txt_f} (not judged: {n_full} of {len(at80)} tip speeds run)"
    rows.append(dict(statement="collision density of the chamber about linear in tip speed, "
                               "not proportional (section 3.4)",
                     paper="linear, not proportional", coupled=txt_c, prescribed=txt_p,
                     full=cell, full_state=state,
                     verdict=verdict(None if lin_c is None else linear(lin_c), full_ok,
                                                " (R^2 >= 0.95, intercept beyond 5 %)")))

    # 7. V4 power about a decade below V1 (power density)
    def p_ratio(st):
        p = {z["name"]: z["collision_power_w"] / z["volume_m3"] for z in st["zones"]}
        return p["V1"] / p["V4"] if p["V4"] > 0 else float("inf")

    add_row("collision power density of V1 over V4 (section 4: V4 about one decade below V1)",
            "about 10", p_ratio, all_keys,
            lambda got: all(10 ** 0.5 <= v <= 10 ** 1.5 for v in got), " (3.2-32)")

    # 8./9. vortices of the mean flow (fluid when coupled; beads for both)
    def census(st, which, region):
        v = st.get("flow", {}).get(which)
        if v is None:
            return None
        if "large" not in v:  # a run from before the census rule (no section fields saved)
            return f"{v[region]} (older census)"
        if region == "between_discs":
            return f"{v['between_discs']} large ({v['large']} in all)"
        sec = [x for x in v["vortices"] if x["region"] == "disc tip to wall" and
               x["sign"] == -(v["vortices"][0]["sign"] if v["vortices"] else 0)]
        if not sec:
            return "none"
        x = sec[0]
        return (f"{len(sec)}, strength {x['strength']:.2f} at r {x['r_m'] * 1e3:.1f} mm, "
                f"{x['zeta_m'] * 1e3:.1f} mm from the disc mid-plane")

    for region, stmt, paper_v in (
            ("between_discs", "one large vortex between the discs at every tip speed "
                              "(section 3.2, Fig. 7)", "1 at 6-14 m/s"),
            ("disc_tip_to_wall", "a secondary vortex between disc tip and chamber wall at "
                                 "8-14 m/s, none at 6 m/s (section 3.2, Fig. 7)",
             "none at 6 m/s, 1 at 8-14 m/s")):
        fl = per("coupled", lambda st: census(st, "vortices_fluid", region), keys80)
        bc = per("coupled", lambda st: census(st, "vortices_beads", region), keys80)
        bp = per("prescribed", lambda st: census(st, "vortices_beads", region), keys80)
        counts = per("coupled", lambda st: st.get("flow", {}).get("vortices_fluid", {}).get(
            region), keys80)
        got = [(k, v) for k, v in zip(keys80, counts) if v is not None]
        def holds(k, v, region=region):
            return v == 1 if region == "between_discs" else (v == 0) if k[0] < 7 else (v >= 1)

        ok = bool(got) and all(holds(k, v) for k, v in got)

        def full_census(st, region=region):
            """(the fluid's count there, both censuses as text)."""
            return (st.get("flow", {}).get("vortices_fluid", {}).get(region),
                    f"fluid: {census(st, 'vortices_fluid', region) or 'not evaluated'} / beads: "
                    f"{census(st, 'vortices_beads', region) or 'not evaluated'}")

        full, full_ok, state = full_cell(full_census, keys80,
                                  lambda kv, holds=holds: all(holds(k, n) for k, n in kv),
                                  value=lambda v: v[0], text=lambda v: v[1], keyed=True)
        rows.append(dict(statement=stmt, paper=paper_v, full=full, full_state=state,
                         coupled="fluid: " + show(fl, keys80) + " / beads: " + show(bc, keys80),
                         prescribed="beads: " + show(bp, keys80) +
                         " (the prescribed swirl has no meridional flow)",
                         verdict=verdict(ok if got else None, full_ok, " (census of the stream "
                                                                      "function above 1 % of its "
                                                                      "largest value)")))

    # 10. V3 the slowest zone (section 3.2: "the mean of the grinding media velocities in
    # V3 was the lowest in all investigated cases")
    def slowest(st):
        sp = {z["name"]: z["speed_over_tip_speed"] for z in st["zones"]
              if z.get("speed_over_tip_speed")}
        return f"slowest {min(sp, key=sp.get)}" if sp else "n/a"

    add_row("mean bead speed lowest in V3 in all cases (section 3.2, Fig. 8)", "slowest V3",
            slowest, all_keys, lambda got: all(v == "slowest V3" for v in got))
    # 11./12. statements on the local maps (the runs' collision_maps.npz, :func:`map_peaks`)
    lo_d, hi_d = WALL_PEAK_DIAMETERS

    def wall_peak(st):
        m = st.get("maps")
        if m is None:
            return None
        p, q = m["frequency_peak"], m["frequency_peak_near_wall"]
        txt = f"{p['from_wall_m'] * 1e3:.1f} mm ({p['from_wall_diameters']:.1f} d)"
        if q["r_m"] != p["r_m"]:  # the highest beyond three bead diameters: and near the wall
            txt += (f"; near the wall {q['from_wall_m'] * 1e3:.1f} mm, "
                    f"{q['collision_frequency_per_m3_s'] / p['collision_frequency_per_m3_s']:.2f} of the peak")
        return p["from_wall_diameters"], txt

    def rim_peak(st):
        m = st.get("maps")
        if m is None:
            return None
        p = m["power_peak"]
        return p["from_rim_diameters"], (f"axial {p['z_m'] * 1e3:+.1f} mm, r {p['r_m'] * 1e3:.1f} mm: "
                                         f"{p['from_rim_diameters']:.2f} d from the rim")

    for stmt, paper_v, fn, ok, rule, what in (
            ("collision frequency peaks about two bead diameters from the chamber wall "
             "(section 3.4, Fig. 13)", "peak ~1.6 mm from the wall", wall_peak,
             lambda v: lo_d <= v <= hi_d, f"peak of the radial profile {lo_d:g}-{hi_d:g} d from the wall",
             "the radial profile of the collision frequency"),
            ("locally highest collision power at the side of the disc's outer edge, all "
             "cases (section 3.5, Fig. 15)", "peak at the disc's outer edge", rim_peak,
             lambda v: v <= RIM_PEAK_DIAMETERS, f"peak within {RIM_PEAK_DIAMETERS:g} d of the disc's rim",
             "the map of the collision power")):
        got = [(k, fn(runs["coupled"][k])) for k in all_keys if runs["coupled"].get(k) is not None]
        got = [(k, v) for k, v in got if v is not None]
        full, full_ok, state = full_cell(fn, all_keys, lambda vs, ok=ok: all(ok(v) for v in vs),
                                  value=lambda v: v[0], text=lambda v: v[1])
        if full == "not evaluated":
            full = "not evaluated (its runs kept no collision maps)"
        if not got and full_ok is None:
            rows.append(dict(statement=stmt, paper=paper_v, coupled="not evaluated", full=full,
                             full_state=state, prescribed="not evaluated",
                             verdict=f"not evaluated (no collision_maps.npz behind {what})"))
            continue
        rows.append(dict(statement=stmt, paper=paper_v, full=full, full_state=state,
                         coupled=show([v[1] for _, v in got], [k for k, _ in got]) if got
                         else "not evaluated",
                         prescribed="not run (the shipped table keeps no maps)",
                         verdict=verdict(all(ok(v[0]) for _, v in got) if got else None, full_ok,
                                         f" ({rule})")))
    # 13.-17. the local filling per zone (section 3.1, Fig. 4), from the zones' ``filling``
    # (eq. 2 with porosity 0.4 per zone); a summary made before its zones kept it leaves
    # these statements unevaluated
    no_filling = "not evaluated (its summary keeps no local filling)"
    no_filling_table = "not evaluated (the table keeps no local filling)"

    def fillings(st):
        f = {z["name"]: z.get("filling") for z in st["zones"]}
        return None if any(v is None for v in f.values()) else f

    def ranked(st, first):
        """'lowest V1, V4' (the two least filled zones) or 'max V2' (the most filled)."""
        f = fillings(st)
        if f is None:
            return None
        o = sorted(f, key=f.get)
        return f"lowest {o[0]}, {o[1]}" if first == "lowest" else f"max {o[-1]}"

    def filling_row(statement, paper, fn, keys, accept, note):
        n0 = len(rows)
        add_row(statement, paper, fn, keys, accept, note)
        r = rows[n0]
        if r["coupled"] == "not run" and any(runs["coupled"].get(k) for k in keys):
            r["verdict"] = no_filling
        if r["full"] == "not evaluated":
            r["full"] = no_filling
        if r["prescribed"] == "not run" and any(runs["prescribed"].get(k) for k in keys):
            r["prescribed"] = no_filling_table

    filling_row("local filling lowest in V1 and V4, all cases (section 3.1, Fig. 4)",
                "lowest V1, V4", lambda st: ranked(st, "lowest"), all_keys,
                lambda got: all(set(v[len("lowest "):].split(", ")) == {"V1", "V4"} for v in got), "")
    filling_row("local filling highest in V3 in most cases (section 3.1: \"mainly\")", "max V3",
                lambda st: ranked(st, "max"), all_keys,
                lambda got: 2 * sum(v == "max V3" for v in got) > len(got),
                " (in more than half of the cases)")
    filling_row("at 90 % filling V2 holds the highest local filling (6 m/s; section 3.1, Fig. 4b)",
                "max V2", lambda st: ranked(st, "max"), [(6.0, 0.9)],
                lambda got: got[0] == "max V2", "")

    def spread_row(statement, paper, keys, value, accept, text, rule):
        """A statement on how the zones' local filling varies over ``keys`` (all of them
        run, else not judged): value(fillings by case) -> figures, judged by accept."""
        def over(f):
            got = {k: fillings(runs[f][k]) for k in keys if runs[f].get(k) is not None}
            got = {k: v for k, v in got.items() if v is not None}
            return (value(got), text(got)) if len(got) == len(keys) else (None, (
                f"not judged: {len(got)} of {len(keys)} cases with local filling" if got
                else "not evaluated"))
        sec, sec_txt = over("coupled")
        fs, fs_txt = over("full") if has_full else (None, "not run")
        if fs_txt == "not evaluated":
            fs_txt = no_filling
        full_ok = None if fs is None else accept(fs)
        if sec is None:
            verdict_txt = no_filling if any(runs["coupled"].get(k) for k in keys) else "not run"
        else:
            verdict_txt = verdict(accept(sec), full_ok, f" ({rule})")
        rows.append(dict(statement=statement, paper=paper, coupled=sec_txt,
                         full=fs_txt if fs is None else f"{fs_txt} ({'holds' if full_ok else 'missed'})",
                         full_state="not judged" if fs is None else "holds" if full_ok else "missed",
                         prescribed=no_filling_table,
                         verdict=verdict_txt))

    def by_zone(got, fn):
        return {z: fn([f[z] for f in got.values()]) for z in ("V1", "V2", "V3", "V4")}

    spread_row("tip speed leaves the zones' local filling unchanged at 80 % (section 3.1, Fig. 4a)",
               "no significant influence", keys80,
               lambda got: by_zone(got, lambda v: (max(v) - min(v)) / (sum(v) / len(v))),
               lambda sp: all(x <= FILLING_SPREAD for x in sp.values()),
               lambda got: "; ".join(f"{z} {lo:.2f}-{hi:.2f}" for z, (lo, hi) in by_zone(
                   got, lambda v: (min(v), max(v))).items()) + " over 6-14 m/s",
               f"each zone's spread over its mean at most {FILLING_SPREAD:.0%}")
    at6 = sorted((k for k in all_keys if k[0] == 6.0), key=lambda k: k[1])
    spread_row("local filling of V1 and V4 about proportional to the total filling (6 m/s; "
               "section 3.1, Fig. 4b)", "about proportional", at6,
               lambda got: {z: [got[k][z] / k[1] for k in at6] for z in ("V1", "V4")},
               lambda q: all(max(v) <= (1 + FILLING_PROPORTIONAL) * min(v) for v in q.values()),
               lambda got: "; ".join(f"{z} " + ", ".join(f"{got[k][z]:.2f}" for k in at6)
                                     for z in ("V1", "V4")) + " at " +
               ", ".join(f"{round(k[1] * 100)}" for k in at6) + " %",
               f"local over total filling within a factor {1 + FILLING_PROPORTIONAL:g} at "
               "every filling")
    for r in rows:
        r["prescribed_source"] = source
    return rows


def count(rows) -> dict:
    """How many of the statements the coupled runs match, miss, or leave unevaluated (not
    evaluated, not run)."""
    out = {"statements": len(rows), "matches": 0, "missed": 0, "not evaluated": 0}
    for r in rows:
        v = r["verdict"]
        out["matches" if v.startswith("matches") else "missed" if v.startswith("missed")
            else "not evaluated"] += 1
    return out


def markdown(rows) -> str:
    lines = ["| seed 001 statement | paper | ours (coupled sector) | full slice, gravity, coupled (the "
             "cases run) | ours (prescribed) | verdict (the full slice where it decides, else the sector) |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append("| " + " | ".join(str(r[k]).replace("|", "/") for k in
                                       ("statement", "paper", "coupled", "full", "prescribed",
                                        "verdict")) + " |")
    if rows:
        c = count(rows)
        lines.append("")
        lines.append(f"Coupled runs: {c['matches']} of {c['statements']} statements match, "
                     f"{c['missed']} missed, {c['not evaluated']} not evaluated.")
    if rows and rows[0].get("prescribed_source"):
        lines.append("")
        lines.append(f"Prescribed column: {rows[0]['prescribed_source']}.")
    return "\n".join(lines)


# --- the command: python -m validation.seed001 -------------------------------------------

def parse_cases(texts) -> list[tuple[float, float]]:
    """The cases 'V:F' (tip speed m/s, filling) of ``texts``, each one of :data:`CASES`;
    ValueError naming a case that is not."""
    out = []
    allowed = ", ".join(f"{vt:g}:{fl:g}" for vt, fl in CASES)
    for t in texts:
        try:
            vt, fl = (float(x) for x in t.split(":"))
        except ValueError:
            raise ValueError(f"--case {t!r}: expected tip speed:filling, one of {allowed}") from None
        k = next((c for c in CASES if math.isclose(c[0], vt) and math.isclose(c[1], fl)), None)
        if k is None:
            raise ValueError(f"--case {t!r}: not one of the campaign's cases ({allowed})")
        if k not in out:
            out.append(k)
    return out


def parser() -> argparse.ArgumentParser:
    """The campaign's options."""
    s = argparse.ArgumentParser(prog="python -m validation.seed001",
                                description="Seed 001 side by side: run its cases, print the "
                                            "deviation table. Run from a checkout's root.")
    s.add_argument("action", choices=("run", "table", "summarize"), help="run the cases (skipping "
                   "those done), print the table from their results (without --out: from the "
                   "shipped summary validation/runs/seed001_sector.json), or write that summary from them")
    s.add_argument("--out", help="folder of the case runs")
    s.add_argument("--fluid", default="coupled,prescribed",
                   help="fluid models to run (comma-separated; default both)")
    s.add_argument("--threads", type=int, help="numba threads (default: all cores)")
    for v in VARIANTS:
        s.add_argument(v.flag, **v.cli)
    s.add_argument("--summary", metavar="FILE", help="summarize and table: this summary instead of "
                   "validation/runs/seed001_sector.json")
    s.add_argument("--full-slice", action="store_true", help="run: instead seed 001's own "
                   "configuration (the whole slice with gravity, 32 theta cells, a checkpoint "
                   "every 600 s; run again to go on from it) at the cases of --case, into "
                   "DIR/c360_v<tip speed>_f<filling %%>; summarize: keep the full-slice cases found "
                   "there in the summary beside the sector's cases")
    s.add_argument("--case", action="append", metavar="V:F", help="run --full-slice: this case "
                   "only (tip speed m/s : filling, one of the campaign's: "
                   + ", ".join(f"{vt:g}:{fl:g}" for vt, fl in CASES) + "); repeat for several; "
                   "default all, 10:0.8 first. A case that another process runs is left to it")
    return s


def main(argv=None) -> int:
    """``python -m validation.seed001 run|table --out DIR``: print the deviation table (after
    running the missing cases with ``run``, or with ``--full-slice`` the full slice's);
    ``summarize``: keep them in the summary; 2 for a fluid model or case it does not know
    or a full slice not run."""
    args = parser().parse_args(argv)
    variants = {v.key: getattr(args, v.key) for v in VARIANTS}
    if args.out is None and args.action != "table":
        print(f"python -m validation.seed001 {args.action}: give --out DIR", file=sys.stderr)
        return 2
    if args.action == "summarize":
        try:
            wrote = summarize(args.out, path=args.summary, full_slice=args.full_slice,
                              **variants)
            print(f"wrote {wrote}")
        except FileNotFoundError as e:
            print(f"python -m validation.seed001 summarize: {e}", file=sys.stderr)
            return 2
        return 0
    if args.case and not (args.action == "run" and args.full_slice):
        print("python -m validation.seed001: --case is for run --full-slice", file=sys.stderr)
        return 2
    if args.action == "run" and args.full_slice:
        try:
            cases = parse_cases(args.case) if args.case else FULL_CASES
        except ValueError as e:
            print(f"python -m validation.seed001: {e}", file=sys.stderr)
            return 2
        run_full_slice(args.out, cases=cases, threads=args.threads)
    elif args.action == "run":
        fluids = [f.strip() for f in args.fluid.split(",") if f.strip()]
        bad = [f for f in fluids if f not in FLUIDS]
        if bad:
            print(f"python -m validation.seed001: --fluid {args.fluid!r}: allowed "
                  f"{sorted(FLUIDS)}", file=sys.stderr)
            return 2
        try:
            run_campaign(args.out, fluids=fluids, threads=args.threads, **variants)
        except ValueError as e:
            print(f"python -m validation.seed001: {e}", file=sys.stderr)
            return 2
    print(markdown(deviation_rows(args.out, summary=args.summary)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
