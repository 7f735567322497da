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


def test_every_relative_link_resolves():
    bad = []
    n = 0
    for page in PAGES:
        for target in _links(page):
            if re.match(r"^[a-z]+:", target) or target.startswith("#"):
                continue  # a web address or an anchor on the same page
            n += 1
            if not (page.parent / target.split("#")[0]).exists():
                bad.append(f"{page.relative_to(ROOT)}: {target}")
    assert n > 10
    assert not bad, bad


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
