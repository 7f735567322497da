"""README.md and docs/: every relative link resolves, every command of the README's command
table exists, and the README stays short (docs/ holds the rest)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def _links(page: Path):
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)  # not in code blocks
    return LINK.findall(text)


def test_docs_exist_and_readme_is_short():
    assert len(PAGES) > 5
    assert len((ROOT / "README.md").read_text().splitlines()) <= 250


def anchors(page: Path) -> set[str]:
    """The anchors of a Markdown page's headings, as GitHub makes them: lower case, spaces to
    hyphens, punctuation other than hyphens and underscores dropped."""
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
    out = set()
    for h in re.findall(r"^#{1,6} (.+)$", text, re.M):
        out.add(re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-"))
    return out


def test_every_relative_link_resolves():
    """Every relative link of the README and docs/ names an existing file, and an anchor of a
    Markdown page names one of its headings."""
    bad = []
    n = 0
    for page in PAGES:
        for target in _links(page):
            if re.match(r"^[a-z]+:", target):
                continue  # a web address
            n += 1
            path, _, anchor = target.partition("#")
            dest = (page.parent / path) if path else page
            if not dest.exists():
                bad.append(f"{page.relative_to(ROOT)}: {target}")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                bad.append(f"{page.relative_to(ROOT)}: {target} (no such heading)")
    assert n > 10
    assert not bad, bad


# ---- size, dates, history (issue 56) ----------------------------------------------------------
def _table_cells(text: str) -> list[str]:
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    return [c for row in text.splitlines() if row.startswith("|") for c in re.split(r"(?<!\\)\|", row)[1:-1]]


def test_readme_is_at_most_12000_characters_and_its_table_cells_short():
    text = (ROOT / "README.md").read_text()
    assert len(text) <= 12_000, len(text)
    long = [c[:80] for c in _table_cells(text) if len(c) > 400]
    assert not long, f"README table cells over 400 characters: {long}"


def test_every_docs_page_is_under_40000_characters():
    big = {p.name: len(p.read_text()) for p in (ROOT / "docs").glob("*.md") if len(p.read_text()) > 40_000}
    assert not big, big


def test_no_date_in_readme_or_docs():
    """The README and docs/ say what is; dated measurements and history belong in
    CHANGELOG.md and benchmarks/results/."""
    iso = re.compile(r"\b(19|20)\d\d-[01]\d-[0-3]\d\b")
    dated = [f"{p.relative_to(ROOT)}: {m.group(0)}" for p in PAGES for m in iso.finditer(p.read_text())]
    assert not dated, dated


# ---- the README's figures and their measurements (issue 56) -----------------------------------
RESULTS = ROOT / "benchmarks" / "results"


def _numbers(x) -> list[float]:
    if isinstance(x, dict):
        return [v for y in x.values() for v in _numbers(y)]
    if isinstance(x, list):
        return [v for y in x for v in _numbers(y)]
    return [float(x)] if isinstance(x, (int, float)) and not isinstance(x, bool) else []


def figure_rows() -> list[list[str]]:
    """The rows of the README's "How good is it" table: measure, aim, figure, command, data."""
    text = (ROOT / "README.md").read_text()
    section = text.split("## How good is it", 1)[1].split("\n## ", 1)[0]
    rows = [[c.strip() for c in r.strip().strip("|").split("|")] for r in section.splitlines()
            if r.startswith("| ") and not r.startswith("| measure")]
    return rows


def test_benchmark_results_are_machine_readable():
    files = sorted(RESULTS.glob("*.json"))
    assert len(files) >= 5
    for f in files:
        d = json.loads(f.read_text())
        assert {"commit", "host", "date", "command", "figures"} <= set(d), f.name
        assert re.fullmatch(r"[0-9a-f]{7,40}", d["commit"]) and re.fullmatch(r"\d{4}-\d\d-\d\d", d["date"]), f.name
        assert d["command"].startswith(("millfmu ", "python -m benchmarks.", "python -m validation.")) \
            and _numbers(d["figures"]), f.name


def test_each_figure_of_the_readme_is_its_measurement():
    """Each row's figure and command are those of the file it links: the table and the data
    cannot drift apart."""
    rows = figure_rows()
    assert len(rows) >= 5
    for measure, aim, figure, command, data in rows:
        m = re.search(r"\]\((benchmarks/results/[\w.-]+\.json)\)", data)
        assert m, f"{measure}: no data file linked"
        d = json.loads((ROOT / m.group(1)).read_text())
        assert command == f"`{d['command']}`", (measure, command, d["command"])
        found = [float(v) for v in re.findall(r"\d+(?:\.\d+)?", figure.replace(",", ""))]
        assert found, (measure, figure)
        known = _numbers(d["figures"])
        for v in found:
            assert any(abs(v - k) <= 1e-9 * max(1.0, abs(k)) for k in known), (measure, v, d["figures"])


def table_commands(text: str) -> list[list[str]]:
    """The command words of every `millfmu ...` in the first column of the README's command
    table (``a\\|b`` gives one command per alternative; options and placeholders dropped)."""
    section = text.split("## The `millfmu` command", 1)[1].split("\n## ", 1)[0]
    out = []
    for row in section.splitlines():
        if not row.startswith("| `millfmu"):
            continue
        first = re.split(r"(?<!\\)\|", row)[1]
        for cmd in re.findall(r"`(millfmu [^`]*)`", first):
            words = []
            for tok in cmd.split()[1:]:
                if tok.startswith(("[", "-")) or not re.match(r"^[a-z0-9-]+(\\\|[a-z0-9-]+)*$", tok):
                    break
                words.append(tok.split("\\|"))
            combos = [[]]
            for alts in words:
                combos = [c + [a] for c in combos for a in alts]
            out += combos
    return out


def test_every_command_of_the_readme_table_exists():
    cmds = table_commands((ROOT / "README.md").read_text())
    assert ["run"] in cmds and ["tables", "verify"] in cmds and ["bench", "fmu"] in cmds
    # One interpreter for all: `millfmu CMD... --help` must exit 0.
    code = ("import contextlib, io, json, sys; from millfmu.cli import main\n"
            "codes = {}\n"
            "for c in json.loads(sys.argv[1]):\n"
            "    try:\n"
            "        with contextlib.redirect_stdout(io.StringIO()):\n"
            "            r = main(c + ['--help'])\n"
            "    except SystemExit as e:\n"
            "        r = e.code\n"
            "    codes[' '.join(c)] = r or 0\n"
            "print(json.dumps(codes))\n")
    r = subprocess.run([sys.executable, "-c", code, json.dumps(cmds)], capture_output=True,
                       text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    codes = json.loads(r.stdout.splitlines()[-1])
    assert not {c: v for c, v in codes.items() if v != 0}, codes


#: The measuring code's commands, run from a checkout's root (not installed with millfmu).
CHECKOUT_COMMAND = re.compile(r"python -m ((?:validation|benchmarks)\.[a-z][a-z0-9_]*)")
#: Commands that moved out of the package: no page may name them any more.
MOVED = ("millfmu dem bench", "millfmu dem seed001", "millfmu dem seed002", "millfmu dem work-precision",
         "millfmu tables equivalence")


def test_every_checkout_command_of_the_readme_and_docs_exists():
    """Each ``python -m validation.X`` and ``python -m benchmarks.X`` of the README and docs/
    names a module of the checkout, and each of the README's takes ``--help`` (one
    interpreter, from the checkout's root, as a reader runs it)."""
    readme = sorted(set(CHECKOUT_COMMAND.findall((ROOT / "README.md").read_text())))
    assert {"validation.seed001", "validation.work_precision", "benchmarks.dem_peers"} <= set(readme)
    named = {m for p in PAGES for m in CHECKOUT_COMMAND.findall(p.read_text())}
    missing = [m for m in sorted(named) if not (ROOT / (m.replace(".", "/") + ".py")).is_file()]
    assert not missing, missing
    code = ("import contextlib, importlib, io, json, sys\n"
            "codes = {}\n"
            "for m in json.loads(sys.argv[1]):\n"
            "    try:\n"
            "        with contextlib.redirect_stdout(io.StringIO()):\n"
            "            r = importlib.import_module(m).main(['--help'])\n"
            "    except SystemExit as e:\n"
            "        r = e.code\n"
            "    codes[m] = r or 0\n"
            "print(json.dumps(codes))\n")
    r = subprocess.run([sys.executable, "-c", code, json.dumps(readme)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    codes = json.loads(r.stdout.splitlines()[-1])
    assert not {m: v for m, v in codes.items() if v != 0}, codes


def test_no_page_names_a_command_that_moved_out_of_the_package():
    """The benches and campaigns that left the ``millfmu`` command are named by their
    checkout commands (CHANGELOG.md keeps the history)."""
    found = [f"{p.relative_to(ROOT)}: {c}" for p in PAGES for c in MOVED if c in p.read_text().replace("\n", " ")]
    assert not found, found


# ---- the glossary (issue 55) ------------------------------------------------------------------
GLOSSARY = ROOT / "docs" / "glossary.md"
#: Symbols and abbreviations of the papers and of the project that a reader of the README
#: meets without a definition beside them.
SYMBOLS = ("SE", "SE_P", "SF", "SN", "SN_g", "SE_tn", "SE_ts", "SE_cs", "SE_net", "SI", "SEV_1", "SEV_2", "SEV_3",
           "SEV_4", "V1", "V2", "V3", "V4", "eta_E", "eta_eff", "Re", "f_Mat", "k_c", "P_cap", "x10", "x50", "x90",
           "Q3", "tip speed", "filling", "Stokes number", "power number", "FMI", "FMU", "SSP", "DEM", "CFD", "PBM")


def glossary_names() -> set[str]:
    """The names in the first cell of every table row of the glossary: 'a, b (c)' gives a,
    b and c."""
    names = set()
    for row in GLOSSARY.read_text().splitlines():
        if not row.startswith("| ") or row.startswith(("| symbol", "| abbreviation", "|---")):
            continue
        first = row.split("|")[1]
        names |= {n.strip() for n in re.split(r", |[()]", first) if n.strip()}
    return names


def _used(symbol: str, text: str) -> bool:
    return re.search(r"(?<![A-Za-z0-9_])" + re.escape(symbol) + r"(?![A-Za-z0-9_])", text) is not None


def test_every_symbol_the_readme_uses_is_in_the_glossary():
    readme = (ROOT / "README.md").read_text()
    names = glossary_names()
    used = [s for s in SYMBOLS if _used(s, readme)]
    assert {"SEV_1", "SN_g", "SE_cs", "SE", "SF"} <= set(used)  # the list is about what the README says
    missing = [s for s in used if s not in names]
    assert not missing, f"used in README.md without a glossary entry: {missing}"
    assert all(s in names for s in SYMBOLS), [s for s in SYMBOLS if s not in names]


def test_glossary_rows_give_meaning_unit_and_source():
    rows = [r for r in GLOSSARY.read_text().splitlines()
            if r.startswith("| ") and not r.startswith(("| symbol", "| abbreviation", "|---"))]
    assert len(rows) > 40
    for r in rows:
        cells = [c.strip() for c in r.strip("|").split("|")]
        if len(cells) == 2:  # software abbreviations: a name and its meaning
            assert cells[1], r
            continue
        assert len(cells) == 4 and all(cells), r  # symbol, meaning, unit, source


def test_readme_links_the_glossary_and_names_both_fmi_versions():
    readme = (ROOT / "README.md").read_text()
    assert "(docs/glossary.md)" in readme
    for line in readme.splitlines():
        if "FMI 2.0" in line:
            assert "3.0" in line, f"names FMI 2.0 alone, while both versions are built: {line[:120]}"
    # the docs where the papers' symbols first appear link it too
    for name in ("model", "dem", "validation-seed001", "validation-seed002", "rates-and-calibration"):
        assert "(glossary.md)" in (ROOT / "docs" / f"{name}.md").read_text(), name
