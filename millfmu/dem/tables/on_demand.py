"""Tables regenerated on demand: before a table is extended to cover a new operating point
(:func:`~.dem_builder.rebuild_including`), what the build will run and cost, said in one
line before anything runs, and what to do where the installed DEM is not the one that
built the table (its kernel version differs: the code changed since).

Costs come from the builder's ``relative_cost(scene, point)`` (bead count times steps for
the DEM, the steps of the start the point will have: a warm start's shorter spin-up) in
seconds per cost unit: measured with the installed DEM where it was
(:data:`~.dem_builder.MEASURED_SPEED`), else from what the table's points took (its
manifest's ``points_wall_time_s``). The line says how the points will start (warm or cold,
and why cold where a stored state was too far: :data:`~.warm_start.WARM_RANGE`). The first
compilation of the DEM's kernels is not in it: it is said in a line of its own where the
kernel cache is cold (:mod:`millfmu.dem.first_compile`).

Policies where the kernel versions differ (``kinetics.stress_distribution.on_stale``,
``millfmu run --on-stale``): ``refuse`` (nothing runs; the line names the cost of the full
rebuild and the other two choices), ``rebuild`` (every point again with the installed DEM:
the table's points belong to another kernel and are not reused) and ``accept`` (the table's
points are kept as they are and only the new points run, with the installed DEM; the new
table keeps the old kernel version, and its manifest says which points ran with which).

A build estimated to take longer than :func:`build_limit_s` (wall time; 30 minutes unless
``MILLFMU_BUILD_LIMIT_S`` says otherwise) runs only when confirmed (:func:`confirm_build`):
by a yes at a terminal, or by ``--yes`` (which lifts the limit for its process); without
either it is refused by name, before anything runs.

Imports no numba (the DEM loads in the builder's processes).
"""

from __future__ import annotations

import math
import os
import sys
from dataclasses import dataclass, replace
from . import cache as _cache
from .build import (PointStore, builder_sharing_cores, duration, points_at_once, relative_costs,
                    seconds_per_cost, stored_results)
from ...stress_tables.spec import DEM_BUILDER_ID, TableError, TableSpec, builder_id_of
from ...stress_tables.table import Table

#: The policies where the installed DEM's kernel version is not the table's.
STALE_POLICIES = ("refuse", "rebuild", "accept")


class StaleTableError(TableError):
    """An on-demand build refused because the table was built by another DEM kernel
    (on_stale = 'refuse'); the message says what a rebuild costs and the choices."""


class BuildNotConfirmedError(TableError):
    """An on-demand build over :func:`build_limit_s` that nobody confirmed; the message
    names its cost, the limit and how to confirm."""


class PointNotBuildableError(TableError):
    """A point the table's builder cannot run (beads that do not fit the DEM's cell):
    ``axis`` and ``value`` name the point's value that is out of reach, ``allowed`` why."""

    def __init__(self, axis: str, value: float, why: str):
        self.axis, self.value, self.allowed = axis, value, why
        super().__init__(f"{axis} = {value:g}: {why}")


#: Wall time [s] over which an on-demand build needs a confirmation (see module docs).
DEFAULT_BUILD_LIMIT_S = 1800.0
#: Environment variable that sets that limit [s] ("inf": no limit, as ``--yes`` sets it).
BUILD_LIMIT_ENV = "MILLFMU_BUILD_LIMIT_S"


def assume_yes() -> None:
    """``--yes``: on-demand table builds of any length run without asking (this process)."""
    os.environ[BUILD_LIMIT_ENV] = "inf"


def build_limit_s() -> float:
    """The wall time [s] over which an on-demand build needs confirmation: the value of
    ``MILLFMU_BUILD_LIMIT_S`` where set (a number of seconds, or inf), else 1800 s. A value
    that is no number is refused by name."""
    raw = os.environ.get(BUILD_LIMIT_ENV, "").strip()
    if not raw:
        return DEFAULT_BUILD_LIMIT_S
    try:
        v = float(raw)
    except ValueError:
        v = math.nan
    if not v >= 0.0:
        raise TableError(f"{BUILD_LIMIT_ENV} = {raw!r}: allowed a number of seconds >= 0, or inf")
    return v


def confirm_build(pl: Plan, what: str, ask=None) -> None:
    """Let the build of plan ``pl`` (described by ``what``) go on, or refuse it with
    :class:`BuildNotConfirmedError`: a build whose estimated wall time is within
    :func:`build_limit_s` goes on; a longer one (or a DEM build of unknown cost) goes on
    only where ``ask`` (default: a yes/no question at the terminal, where stdin and stderr
    are one) says yes."""
    if not pl.todo:
        return
    wall = pl.wall_s()
    limit = build_limit_s()
    if wall is None:
        if pl.spec.builder_id != DEM_BUILDER_ID:
            return  # a builder without a cost estimate is not the DEM: seconds, not hours
    elif wall <= limit:
        return
    if ask is None and sys.stdin is not None and sys.stdin.isatty() and sys.stderr.isatty():
        ask = _ask_at_terminal
    cost = f"about {duration(wall)} on {pl.workers} worker{'s' if pl.workers != 1 else ''}" if wall is not None \
        else "an unknown time (its table records no point's run time)"
    if ask is not None and ask(f"{what}: it takes {cost}. Run it?"):
        return
    raise BuildNotConfirmedError(
        f"{what} would take {cost}, over the {duration(limit)} a build may take without confirmation "
        f"({BUILD_LIMIT_ENV}); refused: confirm it at a terminal, pass --yes (millfmu run, millfmu build-fmu), "
        f"or set {BUILD_LIMIT_ENV} to a larger number of seconds")


def _ask_at_terminal(question: str) -> bool:
    print(f"millfmu: {question} [y/N] ", end="", file=sys.stderr, flush=True)
    try:
        answer = sys.stdin.readline()
    except (OSError, KeyboardInterrupt):
        return False
    return answer.strip().lower() in ("y", "yes")


def unbuildable(table: Table, point: dict, builder) -> None:
    """Refuse (:class:`PointNotBuildableError`) where ``builder`` cannot run a point of the
    build that extends ``table`` to ``point``: asked of each point to run, before anything
    is said or run, from builders that know (``builder.unbuildable(scene, point)``, the
    reason or None)."""
    check = getattr(builder, "unbuildable", None)
    if check is None:
        return
    old = table.spec()
    grid, oat = extended_axes(old, point)
    spec = replace(old, grid=grid, one_at_a_time=oat)
    ran = old.points()
    for p in spec.points():
        if p in ran:
            continue
        why = check(spec.scene, p)
        if why is not None:
            # Name the value the point was extended to (else the first that is new).
            new = [ax for ax in p if ax in point and float(p[ax]) == float(point[ax])
                   and not _on_axis(old, ax, float(p[ax]))]
            ax = new[0] if new else next(iter(p))
            raise PointNotBuildableError(ax, float(p[ax]), why)


def _on_axis(spec: TableSpec, ax: str, x: float) -> bool:
    vals = spec.grid.get(ax, spec.one_at_a_time.get(ax, ()))
    return bool(vals) and vals[0] <= x <= vals[-1]


def extended_axes(spec: TableSpec, point: dict) -> tuple[dict, dict]:
    """(grid, one-at-a-time axes) of ``spec`` with each value of ``point`` that lies outside
    its axis added as a new end node."""

    def extended(axes):
        out = {}
        for ax, vals in axes.items():
            if ax not in point:
                out[ax] = list(vals)
                continue
            x = float(point[ax])
            out[ax] = sorted(set(vals) | ({x} if not vals[0] <= x <= vals[-1] else set()))
        return out

    return extended(spec.grid), extended(spec.one_at_a_time)


def installed_kernel_version(table: Table) -> str:
    """The kernel version a build of ``table``'s kind would run with: the installed DEM's
    (:func:`~.cache.dem_kernel_version`) for a DEM table, else the table's own (another
    builder has no DEM kernel)."""
    if table.manifest.get("builder", table.spec().builder_id) == DEM_BUILDER_ID:
        return _cache.dem_kernel_version()
    return table.spec().kernel_version


def default_builder(table: Table):
    """The DEM as builder, with the table's work-precision entry, starting a new point warm
    from the settled state of a point with the same beads where the point store holds one
    (:mod:`.warm_start`; loads no numba)."""
    from .dem_builder import DemBuilder
    from .warm_start import WARM_SPIN_UP_S

    return DemBuilder(work_precision=table.manifest.get("work_precision"), warm_spin_up_s=WARM_SPIN_UP_S)


@dataclass
class Plan:
    """What an on-demand build will do: the spec it builds, its points, those that run
    (``todo``, each with its relative cost where the builder estimates one, and how it will
    start where the builder says: ``starts``, ("warm" or "cold", why cold or None) each),
    and the seconds per cost unit (None where unknown)."""

    spec: TableSpec
    points: list
    todo: list
    costs: list | None
    seconds_per_cost: float | None
    workers: int = 1
    starts: list | None = None

    def runs_s(self, costs=None) -> float | None:
        """The points' run times [s] summed, each at the thread count it runs with."""
        costs = self.costs if costs is None else costs
        if costs is None or self.seconds_per_cost is None:
            return None
        return sum(costs) * self.seconds_per_cost

    def wall_s(self) -> float | None:
        """Wall time on ``workers`` processes: at least the costliest point, at most the sum."""
        runs = self.runs_s()
        if runs is None or not self.costs:
            return runs
        return max(runs / points_at_once(self.workers, len(self.costs)),
                   max(self.costs) * self.seconds_per_cost)

    def starts_text(self) -> str:
        """How the points to run will start, in words ('' where the builder does not say)."""
        if not self.starts or not self.todo:
            return ""
        warm = sum(k == "warm" for k, _ in self.starts)
        if len(self.starts) == 1:
            w = self.starts[0][1]
            return (", started warm from a stored settled state" if warm else
                    ", started cold" + (f" ({w})" if w else ""))
        whys: dict = {}
        for k, w in self.starts:
            if k == "cold" and w:
                whys[w] = whys.get(w, 0) + 1
        why = "; ".join(f"{n} of them: {w}" for w, n in whys.items())
        cold = len(self.starts) - warm
        cold_text = ("all started cold" if not warm else f"{cold} cold") + (f" ({why})" if why else "")
        if not warm:
            return ", " + cold_text
        return f", {warm} started warm from stored settled states" + (f", {cold_text}" if cold else "")

    def line(self) -> str:
        n, m = len(self.points), len(self.todo)
        # the points' run times summed (each at the thread count it runs with: CPU time
        # only where that is one), and the wall time on the workers
        cost = (f" (about {duration(self.runs_s())} of point runs, {duration(self.wall_s())} on "
                f"{self.workers} worker{'s' if self.workers != 1 else ''})"
                if self.runs_s() is not None else "")
        return f"{n} points, {n - m} already built, {m} to run{self.starts_text()}{cost}"


def plan(table: Table, point: dict, builder, kernel_version: str, cache_dir=None,
         workers: int | None = None) -> Plan:
    """The plan of a build of ``table`` extended to ``point`` with ``kernel_version``:
    the point store seeded as the build will seed it (the table itself and the shipped
    tables of the same scene and kernel), so that ``todo`` is what will run."""
    old = table.spec()
    grid, oat = extended_axes(old, point)
    spec = replace(old, grid=grid, kernel_version=kernel_version, builder_id=builder_id_of(builder),
                   one_at_a_time=oat)
    store = PointStore(_cache.resolve_cache_dir(cache_dir) / _cache.POINTS_DIR)
    have = [r is not None for r in stored_results(spec, store)]
    if not all(have):
        seeds = [t for t in (table, *_cache.seed_tables(spec)) if t.spec().kernel_version == kernel_version]
        if seeds:
            # What the build will find: the seeded points (no file is written for this).
            known = {_key(store, t.spec(), p) for t in seeds for p in t.spec().points()}
            have = [h or _key(store, spec, p) in known for h, p in zip(have, spec.points())]
    points = spec.points()
    todo = [p for p, h in zip(points, have) if not h]
    # the points to run at the cost of their start (a warm start's shorter spin-up, where
    # the builder keeps states: warm_start); the table's points calibrate at the cost of
    # their own starts (seconds_per_cost)
    runs = builder.with_states(store.folder) if hasattr(builder, "with_states") else builder
    costs = relative_costs(runs, spec.scene, todo)
    starts = None
    if hasattr(runs, "start_of"):
        try:
            starts = [tuple(runs.start_of(spec.scene, p)) for p in todo]
        except (ValueError, KeyError, TypeError):  # as relative_costs: a scene it cannot read
            starts = None
    n = workers or os.cpu_count() or 1
    # points run at once share the cores out (build.builder_sharing_cores): their speed
    at_once = builder_sharing_cores(builder, points_at_once(workers, len(todo)))
    return Plan(spec, points, todo, costs, seconds_per_cost(table, at_once), n, starts)


def _key(store: PointStore, spec: TableSpec, p: dict) -> str:
    return store.key(spec, p)


def stale_line(table: Table, point: dict, policy: str, builder=None, cache_dir=None,
               workers: int | None = None) -> str | None:
    """One line where the installed DEM kernel is not the one that built ``table``: the two
    versions, what rebuilding the table extended to ``point`` costs, and what ``policy``
    does; None where the versions agree (or the table is not a DEM table)."""
    if policy not in STALE_POLICIES:
        raise TableError(f"on_stale = {policy!r}: allowed {', '.join(map(repr, STALE_POLICIES))}")
    old_v = table.spec().kernel_version
    new_v = installed_kernel_version(table)
    if new_v == old_v:
        return None
    builder = builder if builder is not None else default_builder(table)
    full = plan(table, point, builder, new_v, cache_dir, workers)
    name = (table.manifest.get("scene") or {}).get("name", "?")
    head = (f"table {name} {table.manifest.get('key', '')[:10]} was built by DEM kernel "
            f"{old_v[:19]}..., the installed DEM is {new_v[:19]}...: a build that extends it runs "
            f"{full.line()}")
    if policy == "refuse":
        return (head + "; such a build is refused (on_stale = 'refuse'): set kinetics.stress_distribution."
                "on_stale = 'rebuild' (or millfmu run --on-stale rebuild) to run them, or "
                "'accept' to keep the table's points and run only the new ones")
    if policy == "rebuild":
        return head + "; on_stale = 'rebuild': rebuilding"
    kept = plan(table, point, builder, old_v, cache_dir, workers)
    return (head + f"; on_stale = 'accept': the table's points are kept as they are, "
            f"{kept.line()} with the installed DEM")
