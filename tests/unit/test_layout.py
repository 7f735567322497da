"""The package's import structure, read from the source with ``ast``.

Guards the layout rules of the architecture: imports run downwards only (a study, a CLI
or a report may import the engine and the model, never the other way round), there is no
import circle of more than two modules nor one that crosses packages, and the installed
packages (millfmu, fmu_build, flowsheets) never import the checkout's measuring code
(validation, benchmarks), which the wheel leaves out.

Run as a script (``python tests/unit/test_layout.py``) it prints the figures: module
count, import circles, imports from a lower layer to a higher one, longest import chain.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: The installed packages, then the measuring code that runs from a checkout only.
INSTALLED = ("millfmu", "fmu_build", "flowsheets")
CHECKOUT_ONLY = ("validation", "benchmarks")
PACKAGES = INSTALLED + CHECKOUT_ONLY


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def modules() -> dict[str, Path]:
    """Every module of :data:`PACKAGES`, by dotted name."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            out[_module_name(path)] = path
    return out


def _resolve(name: str, known: dict[str, Path]) -> str | None:
    """The longest known module that ``name`` is or lies in (a.b.func -> a.b)."""
    while name:
        if name in known:
            return name
        name = name.rpartition(".")[0]
    return None


def imports(known: dict[str, Path] | None = None) -> dict[str, dict[str, bool]]:
    """module -> {imported module: True if at module level}; module- and function-level
    imports alike, relative ones resolved; only modules of :data:`PACKAGES`."""
    known = modules() if known is None else known
    graph: dict[str, dict[str, bool]] = {}
    for mod, path in known.items():
        is_pkg = path.name == "__init__.py"
        package = mod if is_pkg else mod.rpartition(".")[0]
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        top_level = {id(n) for n in tree.body}
        # Imports under a top-level `if`/`try` still run at import time (not those of an
        # `if __name__ == "__main__":` block); those under `if TYPE_CHECKING:` never run.
        never: set[int] = set()
        for node in tree.body:
            if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
                never |= {id(n) for n in ast.walk(node)}
            elif isinstance(node, ast.If) and "__main__" in ast.unparse(node.test):
                never |= {id(n) for n in ast.walk(node)}  # runs as a script only, never on import
            elif isinstance(node, (ast.If, ast.Try)):
                top_level |= {id(n) for n in ast.walk(node)}
        edges: dict[str, bool] = {}
        for node in ast.walk(tree):
            if id(node) in never:
                continue
            deps = []
            if isinstance(node, ast.Import):
                deps = [_resolve(a.name, known) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")
                    base = base[: len(base) - (node.level - 1)]
                    stem = ".".join(base + ([node.module] if node.module else []))
                else:
                    stem = node.module or ""
                # `from pkg import sub` imports the submodule pkg.sub; `from mod import
                # name` imports mod.
                deps = [f"{stem}.{a.name}" if f"{stem}.{a.name}" in known
                        else _resolve(stem, known) for a in node.names]
            elif isinstance(node, ast.Call) and getattr(node.func, "attr",
                                                        getattr(node.func, "id", "")) == "import_module":
                # importlib.import_module("a.b"): an import by name (the CLI's plugins)
                deps = [_resolve(a.value, known) for a in node.args[:1]
                        if isinstance(a, ast.Constant) and isinstance(a.value, str)]
            elif isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "PLUGINS" for t in node.targets):
                # PLUGINS = ("a.b", ...): modules a loop imports by name
                deps = [_resolve(e.value, known) for e in ast.walk(node.value)
                        if isinstance(e, ast.Constant) and isinstance(e.value, str) and e.value in known]
            for dep in deps:
                if dep is None or dep == mod:
                    continue
                edges[dep] = edges.get(dep, False) or id(node) in top_level
        graph[mod] = edges
    return graph


_PACKAGE_NAMES = {
    _module_name(p.parent)
    for pkg in PACKAGES
    for p in (ROOT / pkg).rglob("__init__.py")
}


def _package(mod: str) -> str:
    """The package a module belongs to (a package belongs to itself): millfmu.dem.X.a and
    millfmu.Y lie in different packages, as do millfmu.dem.a and millfmu.dem.X.b."""
    return mod if mod in _PACKAGE_NAMES else mod.rpartition(".")[0]


# Layers, lowest first. A module's layer is that of the longest prefix listed.
LAYERS = {
    # 0: the PBM kinetics; the DEM engine, its fluid, coupling and mills; neutral helpers
    "millfmu.kinetics": 0, "millfmu.dem": 0, "millfmu.dem.engine": 0, "millfmu.dem.fluid": 0,
    "millfmu.dem.coupling": 0, "millfmu.dem.mills": 0, "millfmu.fmi.base2": 0, "millfmu.fmi.base3": 0,
    "millfmu.machine": 0, "millfmu.plotstyle": 0, "millfmu.unit_names": 0, "millfmu.text_files": 0,
    # 1: DEM scenes, runs, analysis, the table builder; the table reader (below the model,
    # which reads tables; beside the builder, which reads and writes them through it)
    "millfmu.dem.scene": 1, "millfmu.dem.run": 1, "millfmu.dem.analysis": 1,
    "millfmu.dem.tables": 1, "millfmu.stress_tables": 1,
    # 2: the model: scene, MillModel, calibration, runner and the FMU adapters
    "millfmu": 2,
    # 3: FMU building and flowsheets
    "fmu_build": 3, "flowsheets": 3,
    # 4: studies, benchmarks, the report; the paper campaigns and peer benches of a checkout
    "millfmu.studies": 4, "millfmu.report": 4, "validation": 4, "benchmarks": 4,
    "fmu_build.step_cost": 4, "fmu_build.exit_study": 4, "flowsheets.wp": 4,
    # 5: command-line modules
    "millfmu.cli": 5, "millfmu.__main__": 5, "millfmu.dem.cli": 5, "millfmu.dem.tables.cli": 5,
    "millfmu.calibration.cli": 5, "fmu_build.cli": 5,
    "flowsheets.cli": 5, "millfmu.rates": 5,  # millfmu.rates: the `millfmu rates` command
}
LAYER_NAMES = ("engine/kinetics", "dem scene/run/analysis/tables, table reader", "model",
               "fmu_build/flowsheets", "studies/report", "cli")


def layer(mod: str) -> int:
    name = mod
    while name:
        if name in LAYERS:
            return LAYERS[name]
        name = name.rpartition(".")[0]
    raise KeyError(mod)


def strongly_connected(graph: dict[str, dict[str, bool]]) -> list[list[str]]:
    """Tarjan's strongly connected components of more than one module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]
    sys.setrecursionlimit(max(10000, sys.getrecursionlimit()))

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, {}):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out, key=len, reverse=True)


def upward(graph: dict[str, dict[str, bool]]) -> list[tuple[str, str, bool]]:
    """Imports from a lower layer to a higher one: (importer, imported, module level)."""
    return sorted((m, d, top) for m, deps in graph.items() for d, top in deps.items()
                  if layer(d) > layer(m))


def longest_chain(graph: dict[str, dict[str, bool]]) -> list[str]:
    """The longest simple import chain, over the graph with circles condensed (each
    circle counts once) and a package's import of its own submodules left out."""
    comps = strongly_connected(graph)
    rep = {m: m for m in graph}
    for c in comps:
        for m in c:
            rep[m] = c[0]
    dag: dict[str, set[str]] = {}
    for m, deps in graph.items():
        for d in deps:
            if rep[m] != rep[d] and not d.startswith(m + "."):
                dag.setdefault(rep[m], set()).add(rep[d])
    memo: dict[str, list[str]] = {}

    def chain(v: str) -> list[str]:
        if v not in memo:
            best: list[str] = []
            for w in sorted(dag.get(v, ())):
                c = chain(w)
                if len(c) > len(best):
                    best = c
            memo[v] = [v] + best
        return memo[v]

    return max((chain(v) for v in sorted(set(rep.values()))), key=len)


# The engine and the model: none of these may import a study, a CLI, the report, the
# FMU builder or the flowsheets.
ENGINE_AND_MODEL = ("millfmu.dem.engine", "millfmu.dem.fluid", "millfmu.dem.coupling",
                    "millfmu.dem.mills", "millfmu.dem.tables", "millfmu.stress_tables", "millfmu.dem.analysis",
                    "millfmu.kinetics", "millfmu.mill", "millfmu.scene", "millfmu.fmi")
FORBIDDEN = ("validation", "benchmarks", "millfmu.studies", "millfmu.cli", "millfmu.dem.cli",
             "millfmu.dem.tables.cli", "millfmu.calibration.cli", "millfmu.rates", "millfmu.report",
             "flowsheets", "fmu_build")


def _under(mod: str, prefixes) -> bool:
    return any(mod == p or mod.startswith(p + ".") for p in prefixes)


def test_no_import_circle_over_two_modules_nor_across_packages():
    graph = imports()
    for comp in strongly_connected(graph):
        assert len(comp) <= 2, f"import circle of {len(comp)} modules: {comp}"
        assert len({_package(m) for m in comp}) == 1, f"import circle across packages: {comp}"


def package_graph(graph: dict[str, dict[str, bool]]) -> dict[str, dict[str, bool]]:
    """package -> {package it imports from: True}, over the modules' imports; a package's
    imports of its own sub-packages and of the packages it lies in are left out (a package
    gathers its parts, and a part may use what its parent package holds)."""
    out: dict[str, dict[str, bool]] = {}
    for m, deps in graph.items():
        a = _package(m)
        for d in deps:
            b = _package(d)
            if a == b or a.startswith(b + ".") or b.startswith(a + "."):
                continue
            out.setdefault(a, {})[b] = True
        out.setdefault(a, {})
    return out


#: Circles between sub-packages still to be broken, each with its reason.
PACKAGE_CIRCLES_LEFT = {
    # the command (millfmu.cli) lives in the package millfmu and gathers the commands of
    # fmu_build and flowsheets, which use the model of millfmu: the command belongs in a
    # package of its own above the three
    ("flowsheets", "fmu_build", "millfmu"),
    # the table reader reaches the builder (millfmu.dem.tables) from inside functions, for
    # on-demand builds, and the builder reads and writes tables through the reader: the
    # on-demand entry belongs above both
    ("millfmu.dem.tables", "millfmu.stress_tables"),
}


def test_no_import_circle_between_sub_packages_but_those_named():
    circles = {tuple(c) for c in strongly_connected(package_graph(imports()))}
    assert circles <= PACKAGE_CIRCLES_LEFT, sorted(circles - PACKAGE_CIRCLES_LEFT)


def test_installed_packages_import_no_checkout_only_code():
    """millfmu, fmu_build and flowsheets never import validation or benchmarks, at module
    level or inside a function: the wheel leaves those out, so an installed millfmu would
    fail where it reached them. The measuring code imports the product, not the reverse."""
    graph = imports()
    assert {"validation.work_precision", "benchmarks.dem_peers"} <= set(graph)
    assert "millfmu.dem.analysis.precision" in graph["validation.work_precision"]  # the scan sees them
    bad = [(m, d) for m, deps in graph.items() if _under(m, INSTALLED)
           for d in deps if _under(d, CHECKOUT_ONLY)]
    assert not bad, bad


def test_the_cli_plugins_are_seen_as_imports():
    graph = imports()
    assert {"millfmu.dem.cli", "fmu_build.cli", "flowsheets.cli", "millfmu.report",
            "millfmu.calibration.cli"} <= set(graph["millfmu.cli"])


def test_engine_and_model_import_no_study_cli_report_or_builder():
    graph = imports()
    bad = [(m, d) for m, deps in graph.items() if _under(m, ENGINE_AND_MODEL)
           and not _under(m, ("millfmu.dem.tables.cli",))
           for d in deps if _under(d, FORBIDDEN)]
    assert not bad, bad


def test_table_reader_imports_nothing_of_the_dem_at_module_level():
    """millfmu.stress_tables is what an FMU carries and what a step of a table scene loads:
    no module of it imports anything under millfmu.dem when loaded. Its on-demand builds
    (on_outside = 'build', never in an FMU) reach the DEM's limits and the table builder
    from inside functions only, and only these."""
    graph = imports()
    reader = {m: deps for m, deps in graph.items() if _under(m, ("millfmu.stress_tables",))}
    assert "millfmu.stress_tables.stress_source" in reader
    top = [(m, d) for m, deps in reader.items() for d, at_top in deps.items() if at_top and _under(d, ("millfmu.dem",))]
    assert not top, top
    lazy = {(m, d) for m, deps in reader.items() for d in deps if _under(d, ("millfmu.dem",))}
    assert lazy == {("millfmu.stress_tables.stress_source", "millfmu.dem.limits"),
                    ("millfmu.stress_tables.stress_source", "millfmu.dem.tables.on_demand"),
                    ("millfmu.stress_tables.stress_source", "millfmu.dem.tables.dem_builder")}, lazy


def test_at_most_two_imports_run_upwards():
    # Each allowed one is named here with its reason.
    allowed = {
        # the docs' trend table is what `millfmu rates` computes (its compute(), not its CLI)
        ("validation.trends_causes", "millfmu.rates"),
        # the report's trend section is the same table (millfmu.rates.trend_table)
        ("millfmu.report", "millfmu.rates"),
    }
    up = [(m, d) for m, d, _ in upward(imports())]
    assert set(up) <= set(allowed), sorted(set(up) - set(allowed))
    assert len(allowed) <= 2


def test_every_module_has_a_layer():
    for mod in modules():
        layer(mod)


def report() -> None:
    known = modules()
    graph = imports(known)
    print(f"modules: {len(known)}")
    comps = strongly_connected(graph)
    print(f"import circles: {len(comps)} (sizes {[len(c) for c in comps]})")
    for c in comps:
        print(f"  {len(c)}: {', '.join(c)}")
    up = upward(graph)
    print(f"lower-to-higher imports: {len(up)}")
    for m, d, top in up:
        print(f"  {m} [{LAYER_NAMES[layer(m)]}] -> {d} [{LAYER_NAMES[layer(d)]}]"
              f" ({'module level' if top else 'in a function'})")
    chain = longest_chain(graph)
    print(f"longest import chain: {len(chain)} modules (circles condensed)")
    print("  " + " -> ".join(chain))
    top = {m: {d: t for d, t in deps.items() if t} for m, deps in graph.items()}
    chain = longest_chain(top)
    print(f"longest chain of module-level imports: {len(chain)} modules (circles condensed)")
    print("  " + " -> ".join(chain))


if __name__ == "__main__":
    report()
