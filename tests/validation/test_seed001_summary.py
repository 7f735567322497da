"""Seed 001's verdicts computed from the shipped summary of the coupled sector cases
(validation/runs/seed001_sector.json): the page's verdict column and count follow from it, so
a summary and a verdict that disagree fail here."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from validation import seed001 as S

PAGE = Path(__file__).resolve().parents[2] / "docs" / "validation-seed001.md"
#: the variants of seed 001's method and what they move
VARIANTS = PAGE.with_name("validation-seed001-variants.md")


@pytest.fixture(scope="module")
def rows():
    return S.deviation_rows()


@pytest.fixture(scope="module")
def sector_rows(tmp_path_factory):
    """The verdicts of the shipped summary's sector cases alone (its full slice left out)."""
    doc = json.loads(S.SUMMARY.read_text())
    doc.pop("full_slice", None)
    p = tmp_path_factory.mktemp("sector") / "summary.json"
    p.write_text(json.dumps(doc))
    return S.deviation_rows(summary=p)


def _page_rows() -> dict:
    """statement -> cells of the page's verdict table."""
    out = {}
    for line in PAGE.read_text(encoding="utf-8").splitlines():
        if line.startswith("| ") and not line.startswith("| seed 001 statement") and line.count("|") >= 7:
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            out[cells[0]] = cells
    return out


def test_the_summary_holds_every_case_with_what_the_table_reads():
    doc = json.loads(S.SUMMARY.read_text())
    assert sorted((r["tip_speed_m_per_s"], r["filling"]) for r in doc["runs"].values()) == sorted(S.CASES)
    for r in doc["runs"].values():
        st = r["stats"]
        assert [z["name"] for z in st["zones"]] == ["V1", "V2", "V3", "V4"]
        assert all(set(S.ZONE_KEYS) <= set(z) for z in st["zones"])
        assert set(st["flow"]) == set(S.FLOW_KEYS)
        assert set(st["maps"]) == {"frequency_peak", "frequency_peak_near_wall", "power_peak"}
    assert S.SUMMARY.stat().st_size < 200_000  # zone statistics, not contacts or maps


def test_the_pages_figures_verdicts_and_count_are_the_summarys(rows):
    page = _page_rows()
    assert len(rows) == 19
    for r in rows:
        cells = page[r["statement"]]
        assert cells[2] == r["coupled"].replace("|", "/"), r["statement"]  # the sector's figures
        assert cells[-1] == r["verdict"], r["statement"]  # with its rule, word for word
        if S.summary_stats(full_slice=True):  # the full slice's column, once its summary is kept
            assert cells[3] == r["full"].replace("|", "/"), r["statement"]
    c = S.count(rows)
    sector = S.count(S.deviation_rows(full_slice=False))
    text = " ".join(PAGE.read_text(encoding="utf-8").split())
    left = c["not evaluated"] or "none"
    assert f"**Count.** {c['matches']} of the {c['statements']} statements match, {c['missed']} are missed" in text
    assert f"and {left} is left unevaluated" in text
    assert (f"sector campaign alone matches {sector['matches']} of them" in text
            and f"misses {sector['missed']} (" in text)
    readme = " ".join((PAGE.parents[1] / "README.md").read_text(encoding="utf-8").split())
    assert (f"seed 001 (disc mill): {c['matches']} of {c['statements']} statements match (full slice "
            "where it decides)") in readme


def test_the_table_command_reads_the_summary_without_a_run_folder(capsys):
    assert S.main(["table"]) == 0
    out = capsys.readouterr().out
    assert "Coupled runs: " in out and "statements match" in out
    assert S.main(["summarize"]) == 2


def _with_full_slice(tmp_path, cases):
    """The shipped summary with ``cases`` ({(tip speed, filling): stats}) as its full
    slice's, written to tmp_path."""
    doc = json.loads(S.SUMMARY.read_text())
    doc["full_slice"] = {"runs": {S.case_label(*k): {"tip_speed_m_per_s": k[0], "filling": k[1],
                                                     "stats": st} for k, st in cases.items()}}
    p = tmp_path / "summary.json"
    p.write_text(json.dumps(doc))
    return p


def _cell(rows, start, key="full"):
    return next(r[key] for r in rows if r["statement"].startswith(start))


def test_the_full_slice_column_at_one_case_decides_only_what_it_misses(tmp_path, sector_rows):
    """A summary with a full slice at one case (here, synthetically, the sector's 10 m/s,
    80 % case in its place): its column shows the value there and whether the statement
    holds at the cases run; a statement it misses there is missed on seed 001's
    configuration (the verdict says so), one it holds there keeps the sector's verdict."""
    sector = S.summary_stats()[(10.0, 0.8)]
    got = S.deviation_rows(summary=_with_full_slice(tmp_path, {(10.0, 0.8): sector}))
    one = "(holds at the 1 of 5 cases run)"
    assert _cell(got, "mean bead speed / tip speed in V1 at 80 ") == f"10 m/s 80 %: 0.136 {one}"
    assert _cell(got, "mean bead speed / tip speed in V3 at 80 ") == f"10 m/s 80 %: 0.0976 {one}"
    assert _cell(got, "mean bead speed / tip speed in V3 at 80 ", "verdict") == "missed (within 15%)"  # the sector's
    assert _cell(got, "angular velocity of the first bead layer") == "10 m/s 80 %: 0.16 (missed)"
    assert _cell(got, "angular velocity of the first bead layer", "verdict") == \
        "missed on the full slice (within 15 %)"
    assert _cell(got, "at 90 % filling V3 has the lowest collis") == "not run at these cases"
    assert _cell(got, "collision density of the chamber about l") == "not evaluated (one tip speed)"
    assert _cell(got, "mean bead speed lowest in V3 in all case") == "10 m/s 80 %: slowest V2 (missed)"
    assert _cell(got, "collision frequency peaks about two bead ") == "10 m/s 80 %: 0.8 mm (1.0 d) (missed)"
    assert _cell(got, "locally highest collision power at the s").endswith(
        "0.88 d from the rim (holds at the 1 of 7 cases run)")
    assert _cell(got, "a secondary vortex between disc tip and c") == \
        "10 m/s 80 %: fluid: none / beads: none (missed)"
    # each row's state at the cases run is what its cell says
    for key, state in (("mean bead speed / tip speed in V1 at 80 ", "holds"),
                       ("angular velocity of the first bead layer", "missed"),
                       ("at 90 % filling V3 has the lowest collis", "not judged"),
                       ("collision density of the chamber about l", "not judged"),
                       ("a secondary vortex between disc tip and c", "missed"),
                       ("locally highest collision power at the s", "holds")):
        assert _cell(got, key, "full_state") == state, key
    for r in got:
        said = "missed" if r["full"].endswith("(missed)") else "holds" if "(holds" in r["full"] else "not judged"
        assert r["full_state"] == said, r["statement"]
    # here every miss at 10 m/s, 80 % is a miss of the sector too: the count stays
    assert S.count(got) == S.count(sector_rows)
    for r, g in zip(sector_rows, got):
        assert g["verdict"] in (r["verdict"], r["verdict"].replace("missed", "missed on the full slice", 1))
    # without the maps the map rows cannot be judged there
    bare = {k: v for k, v in sector.items() if k != "maps"}
    got = S.deviation_rows(summary=_with_full_slice(tmp_path, {(10.0, 0.8): bare}))
    assert _cell(got, "locally highest collision power at the s") == \
        "not evaluated (its runs kept no collision maps)"
    assert all(r["full"] == "not run" for r in sector_rows)


def test_the_full_slice_decides_every_statement_whose_cases_it_has_run(tmp_path, sector_rows):
    """With every case run on the full slice (synthetically the sector's, so that the
    judgements agree), every verdict is the full slice's: the sector's words with "on the
    full slice", and the same count."""
    got = S.deviation_rows(summary=_with_full_slice(tmp_path, S.summary_stats()))
    for r, g in zip(sector_rows, got):
        word = r["verdict"].split()[0]
        assert g["verdict"] == r["verdict"].replace(word, f"{word} on the full slice", 1), r["statement"]
    assert S.count(got) == S.count(sector_rows)
    assert _cell(got, "collision density of the chamber about l").endswith("(holds)")
    assert _cell(got, "collision density of the chamber about l", "full_state") == "holds"
    # four of the five speeds at 80 %: the fit is shown, not judged, and the sector decides
    four = {k: v for k, v in S.summary_stats().items() if k != (14.0, 0.8)}
    got = S.deviation_rows(summary=_with_full_slice(tmp_path, four))
    assert _cell(got, "collision density of the chamber about l").endswith("(not judged: 4 of 5 tip speeds run)")
    assert _cell(got, "collision density of the chamber about l", "verdict") == \
        _cell(sector_rows, "collision density of the chamber about l", "verdict")


def _sector_folders(out, cases):
    """A campaign's run folders in ``out``, a stats.json per case of ``cases``."""
    for (vt, fl), st in cases.items():
        d = S.case_dir(out, "coupled", vt, fl)
        d.mkdir(parents=True)
        (d / "stats.json").write_text(json.dumps(st))
    return out


def test_summarize_keeps_the_sector_cases_and_the_full_slice_apart(tmp_path):
    """summarize --full-slice adds the full slice's cases beside the sector's cases, keeps
    those summarized before, and a summary of the sector's cases keeps them; each from its
    own run folders."""
    shipped = S.summary_stats()
    out = _sector_folders(tmp_path / "runs", shipped)
    p = tmp_path / "summary.json"
    S.summarize(out, path=p)
    assert S.summary_stats(p) == shipped and S.summary_stats(p, full_slice=True) == {}
    with pytest.raises(FileNotFoundError, match="c360_v10_f80"):
        S.summarize(out, path=p, full_slice=True)
    d = S.case_dir(out, "coupled", 10.0, 0.8, S.FULL_SECTOR_DEG)
    d.mkdir()
    (d / "stats.json").write_text(json.dumps(shipped[(6.0, 0.8)]))
    S.summarize(out, path=p, full_slice=True)
    assert S.summary_stats(p, full_slice=True) == {(10.0, 0.8): shipped[(6.0, 0.8)]}
    S.summarize(out, path=p)  # the sector's again: the full slice stays
    assert S.summary_stats(p) == shipped
    assert S.summary_stats(p, full_slice=True) == {(10.0, 0.8): shipped[(6.0, 0.8)]}
    assert S.deviation_rows(out)[0]["full"] == "10 m/s 80 %: 0.147 (holds at the 1 of 5 cases run)"
    # a second case, run in another folder later: both kept
    out2 = tmp_path / "runs2"
    d = S.case_dir(out2, "coupled", 6.0, 0.5, S.FULL_SECTOR_DEG)
    d.mkdir(parents=True)
    (d / "stats.json").write_text(json.dumps(shipped[(6.0, 0.5)]))
    S.summarize(out2, path=p, full_slice=True)
    assert S.summary_stats(p, full_slice=True) == {(10.0, 0.8): shipped[(6.0, 0.8)],
                                                   (6.0, 0.5): shipped[(6.0, 0.5)]}
    doc = json.loads(p.read_text())
    assert list(doc["full_slice"]["runs"]) == ["10 m/s, 80 %", "6 m/s, 50 %"]  # the campaign's order


def test_full_slice_cases_are_chosen_by_name_and_a_held_case_is_left_alone(tmp_path, capsys):
    """run --full-slice --case V:F takes the campaign's cases only, named; a case whose
    folder another process holds is left to it, one with its stats.json is done."""
    assert S.parse_cases(["6:0.5", "10:0.8", "6:0.5"]) == [(6.0, 0.5), (10.0, 0.8)]
    for bad, why in (("7:0.8", "not one of the campaign's cases"), ("fast", "expected tip speed:filling")):
        with pytest.raises(ValueError, match=why):
            S.parse_cases([bad])
    assert S.main(["run", "--out", str(tmp_path), "--full-slice", "--case", "7:0.8"]) == 2
    assert "6:0.5" in capsys.readouterr().err  # the allowed cases named
    assert S.main(["table", "--case", "6:0.5"]) == 2
    assert "--case is for run --full-slice" in capsys.readouterr().err
    done = S.case_dir(tmp_path, "coupled", 10.0, 0.8, S.FULL_SECTOR_DEG)
    done.mkdir(parents=True)
    (done / "stats.json").write_text("{}")
    held = S.case_dir(tmp_path, "coupled", 6.0, 0.5, S.FULL_SECTOR_DEG)
    held.mkdir(parents=True)
    said = []
    from millfmu.dem.tables.point_folders import hold

    with open(held / S.FULL_LOCK, "a+") as fh:
        assert hold(fh)
        got = S.run_full_slice(tmp_path, cases=[(10.0, 0.8), (6.0, 0.5)], say=said.append)
    assert got == [done]
    assert said == [f"{held}: run by another process; the next case"]


def test_the_full_slice_is_seed_001s_configuration_as_the_page_runs_it():
    """The campaign's full slice is the scene the page's command runs (disc_slice, its
    gravity, 360 degrees, 32 theta cells, the sector campaign's protocol)."""
    from millfmu.dem.scene import load_scene

    sc = S.full_slice_scene(10.0, 0.8)
    assert sc == load_scene("disc_slice").with_overrides(
        tip_speed_m_per_s=10.0, filling=0.8, n_theta=32, spin_up_s=1.0, record_s=0.3,
        sample_every_s=0.01, initial_rotation=0.1, pressure_solver="theta_fft")
    assert sc.geometry.sector_deg == 360.0 and sc.gravity_m_per_s2 == (0.0, -9.81, 0.0)
    assert sc.coupling.n_theta == 32 and sc.fluid_mode == "coupled"
    text = " ".join(PAGE.read_text(encoding="utf-8").split())
    assert "python -m validation.seed001 run --out DIR --full-slice" in text
    assert ("millfmu dem run disc_slice --out DIR --tip-speed 10 --filling 0.8 --theta-cells 32 "
            "--pressure-solver theta_fft --spin-up 1.0 --record 0.3 --sample-every 0.01 "
            "--initial-rotation 0.1 --windows 0.1 --checkpoint-every 600") in text


def _variant_summarized(tmp_path, name, **variant):
    """(runs folder, summary path, summary) of a variant campaign's folder holding the
    shipped 10 m/s, 80 % case, summarized into ``name`` with ``variant`` (keyword = value
    of the campaign's VARIANTS)."""
    out = _sector_folders(tmp_path / "runs", {(10.0, 0.8): S.summary_stats()[(10.0, 0.8)]})
    p = S.summarize(out, path=tmp_path / name, **variant)
    return out, p, json.loads(p.read_text())


def _kept_variant(name, key, value):
    """(rows, count, the page's text) of a kept variant campaign ``name`` whose protocol
    sets ``key`` to ``value``, every case of the campaign run."""
    p = S.SUMMARY.parent / name
    doc = json.loads(p.read_text())
    assert doc["protocol"][key] == value and "a variant" in doc["note"]
    assert sorted((r["tip_speed_m_per_s"], r["filling"]) for r in doc["runs"].values()) == sorted(S.CASES)
    rows = S.deviation_rows(summary=p)
    text = PAGE.read_text(encoding="utf-8") + VARIANTS.read_text(encoding="utf-8")
    return rows, S.count(rows), " ".join(text.split())


#: each kept variant campaign's summary and the variant it was made with
KEPT_VARIANTS = {"seed001_sector_smoothing0.json": {"smoothing_diameters": 0.0},
                 "seed001_sector_wall_friction.json": {"wall_friction": 0.6},
                 "seed001_sector_stated_counts.json": {"stated_counts": True},
                 "seed001_sector_stress_force.json": {"bead_stress_force": "anderson_jackson1967"},
                 "seed001_sector_model_b.json": {"vans_model": "B"}}


@pytest.mark.parametrize("name", sorted(KEPT_VARIANTS))
def test_a_kept_variant_summary_is_what_summarize_writes_for_its_variant(tmp_path, name):
    """A kept variant campaign's summary names its variant in its note, its protocol and both
    its commands, and its summarize command, parsed by the campaign's own options, gives
    that variant back: summarize with it writes the same note, protocol and commands, and
    keeps the case's statistics."""
    kept = json.loads((S.SUMMARY.parent / name).read_text())
    variant = KEPT_VARIANTS[name]
    run_cmd, summarize_cmd = kept["command"].split(", then ")
    assert summarize_cmd.startswith("python -m validation.seed001 summarize ")
    args = S.parser().parse_args(summarize_cmd.split()[3:])
    parsed = {v.key: getattr(args, v.key) for v in S.VARIANTS}
    assert {k: v for k, v in parsed.items() if v is not None and v is not False} == variant
    assert args.summary == f"validation/runs/{name}"
    (key, value), = variant.items()
    flag = S.VARIANTS[[v.key for v in S.VARIANTS].index(key)].flag
    assert flag in run_cmd and "a variant" in kept["note"]
    out, p, doc = _variant_summarized(tmp_path, name, **variant)
    assert {k: doc[k] for k in ("note", "protocol", "command")} == \
        {k: kept[k] for k in ("note", "protocol", "command")}
    assert S.summary_stats(p) == {(10.0, 0.8): S.summary_stats()[(10.0, 0.8)]}
    with pytest.raises(TypeError, match=r"unknown campaign variant\(s\) \['smothing'\]"):
        S.summarize(out, path=tmp_path / "x.json", smothing=1.0)


def test_the_smoothing_variants_scene_and_refusals(tmp_path):
    """--smoothing-diameters D: the campaign's scene with the exchange smoothed over D bead
    diameters (refused below 0; its summary: the kept variants' test)."""
    from millfmu.dem.scene import load_scene

    base = load_scene("disc_slice")
    assert S.with_variant(base, "smoothing_diameters", None) is base
    assert S.with_variant(base, "smoothing_diameters", 0.0).coupling.smoothing_diameters == 0.0
    assert S.with_variant(base, "smoothing_diameters", 0.0).coupling.cell_m == base.coupling.cell_m
    with pytest.raises(ValueError, match="smoothing_diameters = -1: must be a number >= 0"):
        S.with_variant(base, "smoothing_diameters", -1)


def test_the_wall_friction_variants_scene_and_refusals(tmp_path):
    """--wall-friction MU: the campaign's scene with the bead-wall friction MU, the beads'
    own kept (refused below 0, also on the command line)."""
    from millfmu.dem.scene import load_scene

    base = load_scene("disc_slice")
    assert S.with_variant(base, "wall_friction", None) is base
    var = S.with_variant(base, "wall_friction", 0.6)
    assert (var.material.bead_wall_friction, var.material.friction) == (0.6, 0.3)
    assert var.coupling == base.coupling and var.geometry == base.geometry
    for bad in (-0.1, float("nan")):
        with pytest.raises(ValueError, match="beads.wall_friction = .*: must be a finite number >= 0"):
            S.with_variant(base, "wall_friction", bad)
    assert S.main(["run", "--out", str(tmp_path), "--wall-friction", "-1", "--fluid", "coupled"]) == 2


def test_the_stress_force_variants_scene_and_refusals(tmp_path):
    """--bead-stress-force NAME: the campaign's scene whose model A beads take the viscous
    stress's share too (an unknown name and model B refused by name)."""
    from millfmu.dem.scene import load_scene

    base = load_scene("disc_slice")
    assert S.with_variant(base, "bead_stress_force", None) is base
    var = S.with_variant(base, "bead_stress_force", "anderson_jackson1967")
    assert var.coupling.bead_stress_force == "anderson_jackson1967" and base.coupling.bead_stress_force == "none"
    assert var.geometry == base.geometry and var.material == base.material
    with pytest.raises(ValueError,
                       match=r"bead_stress_force = 'viscForce': allowed \['none', 'anderson_jackson1967'\]"):
        S.with_variant(base, "bead_stress_force", "viscForce")
    with pytest.raises(ValueError, match=r"bead_stress_force = 'anderson_jackson1967': only model A .* model 'B'"):
        S.with_variant(replace(base, coupling=replace(base.coupling, model="B")), "bead_stress_force",
                       "anderson_jackson1967")
    assert S.main(["run", "--out", str(tmp_path), "--bead-stress-force", "viscForce", "--fluid", "coupled"]) == 2


def test_the_model_b_variants_scene_and_refusals(tmp_path):
    """--vans-model B: the campaign's scene with the liquid by model B (an unknown model, a
    liquid that is not volume-averaged, and model B beside model A's viscous-stress force
    refused by name)."""
    from millfmu.dem.scene import load_scene

    base = load_scene("disc_slice")
    assert S.with_variant(base, "vans_model", None) is base and base.coupling.model == "A"
    var = S.with_variant(base, "vans_model", "B")
    assert var.coupling == replace(base.coupling, model="B")
    assert var.geometry == base.geometry and var.material == base.material
    with pytest.raises(ValueError, match=r"vans_model = 'C': allowed \['A', 'B'\]"):
        S.with_variant(base, "vans_model", "C")
    with pytest.raises(ValueError, match=r"vans_model = 'B': this scene's beads take model A's viscous-stress"):
        S.with_variant(S.with_variant(base, "bead_stress_force", "anderson_jackson1967"), "vans_model", "B")
    with pytest.raises(ValueError, match=r"vans_model = 'B': the volume-averaged coupled liquid's; the fluid "
                                         r"here is 'coupled', scheme 'dpm'"):
        S.with_variant(replace(base, coupling=replace(base.coupling, scheme="dpm")), "vans_model", "B")
    with pytest.raises(SystemExit):
        S.main(["run", "--out", str(tmp_path), "--vans-model", "C", "--fluid", "coupled"])


def test_the_no_smoothing_variants_count_on_the_page_is_its_summarys():
    """The page's count of the campaign with no smoothing (a variant, not counted) follows
    from its kept summary, validation/runs/seed001_sector_smoothing0.json."""
    rows, c, text = _kept_variant("seed001_sector_smoothing0.json", "smoothing_diameters", 0.0)
    assert "with no smoothing (a variant, not counted:" in text
    judged = c["statements"] - c["not evaluated"]
    assert f"the sector matches {c['matches']} of the {judged} statements it judges: it gains the first layer" in text
    layer = next(r for r in rows if r["statement"].startswith("angular velocity of the first bead layer"))
    assert layer["verdict"].startswith("matches")


def test_the_stress_force_variants_count_on_the_page_is_its_summarys():
    """The page's count of the campaign whose beads take the viscous stress's share (a
    variant, not counted) follows from its kept summary,
    validation/runs/seed001_sector_stress_force.json, beside the campaign's own count; the
    variant gains the first layer."""
    rows, c, text = _kept_variant("seed001_sector_stress_force.json", "bead_stress_force",
                                  "anderson_jackson1967")
    own = S.count(S.deviation_rows(full_slice=False))  # the sector's own, as a variant is judged
    assert (f"the sector matches {c['matches']} of the {c['statements']} statements (without it: "
            f"{own['matches']})") in text
    layer = next(r for r in rows if r["statement"].startswith("angular velocity of the first bead layer"))
    assert layer["verdict"].startswith("matches")


def test_the_model_b_variants_count_on_the_page_is_its_summarys():
    """The page's count of the campaign by model B (a variant, not counted) follows from its
    kept summary, validation/runs/seed001_sector_model_b.json, beside model A's count; the
    variant gains V3's speed."""
    rows, c, text = _kept_variant("seed001_sector_model_b.json", "vans_model", "B")
    own = S.count(S.deviation_rows(full_slice=False))  # the sector's own, as a variant is judged
    assert (f"the sector matches {c['matches']} of the {c['statements']} statements (model A: "
            f"{own['matches']})") in text
    assert f"model B: {c['matches']} of {c['statements']})" in text
    v3 = next(r for r in rows if r["statement"].startswith("mean bead speed / tip speed in V3"))
    assert v3["verdict"].startswith("matches")


def _paper_summary(tmp_path, stats, finished=True):
    """A kept summary of the full slice by seed 001's protocol (validation.full_slice_paper)
    at 10 m/s, 80 %, with ``stats`` as its compact statistics."""
    doc = {"case": S.case_label(10.0, 0.8), "tip_speed_m_per_s": 10.0, "filling": 0.8,
           "trace": [], "finished": finished}
    if finished:
        doc["stats"] = stats
    p = tmp_path / "paper.json"
    p.write_text(json.dumps(doc))
    return p


def test_a_finished_run_by_seed_001s_protocol_takes_its_case_in_the_full_slice(tmp_path):
    """Once the full slice by seed 001's own protocol has finished, its case replaces the
    one by the campaign's protocol, and the cells name it; while it runs, nothing changes;
    a variant campaign's summary is not combined with it unless asked."""
    shipped = S.summary_stats()
    kept = _with_full_slice(tmp_path, {(10.0, 0.8): shipped[(10.0, 0.8)]})
    before = S.deviation_rows(summary=kept)
    assert before[0]["full"] == "10 m/s 80 %: 0.136 (holds at the 1 of 5 cases run)"
    running = _paper_summary(tmp_path, None, finished=False)
    assert S.paper_protocol_stats(running) == {}
    assert S.deviation_rows(summary=kept, paper_summary=running) == before
    paper = _paper_summary(tmp_path, shipped[(6.0, 0.8)])
    assert S.paper_protocol_stats(paper) == {(10.0, 0.8): shipped[(6.0, 0.8)]}
    got = S.deviation_rows(summary=kept, paper_summary=paper)
    assert got[0]["full"] == "10 m/s 80 % (by seed 001's protocol): 0.147 (holds at the 1 of 5 cases run)"
    # every judged cell of the full slice is now that case's, by that name
    for r in got:
        if r["full_state"] != "not judged":
            assert "10 m/s 80 % (by seed 001's protocol)" in r["full"], r["statement"]
    assert _cell(got, "angular velocity of the first bead layer").startswith(
        "10 m/s 80 % (by seed 001's protocol): 0.173")
    # the sector's cells and the prescribed column stay as they were
    assert [r["coupled"] for r in got] == [r["coupled"] for r in before]
    # a summary other than the shipped one takes it only when named
    assert S.deviation_rows(summary=kept) == before


def test_the_run_folders_protocol_run_takes_its_case(tmp_path):
    """From run folders: the full slice by seed 001's protocol in its own folder
    (validation.full_slice_paper.case_dir) takes the place of the campaign's case."""
    from validation import full_slice_paper as P

    shipped = S.summary_stats()
    out = _sector_folders(tmp_path / "runs", shipped)
    d = S.case_dir(out, "coupled", 10.0, 0.8, S.FULL_SECTOR_DEG)
    d.mkdir()
    (d / "stats.json").write_text(json.dumps(shipped[(10.0, 0.8)]))
    assert S.deviation_rows(out)[0]["full"] == "10 m/s 80 %: 0.136 (holds at the 1 of 5 cases run)"
    d = P.case_dir(out)
    d.mkdir()
    (d / "stats.json").write_text(json.dumps(shipped[(6.0, 0.8)]))
    assert S.deviation_rows(out)[0]["full"] == (
        "10 m/s 80 % (by seed 001's protocol): 0.147 (holds at the 1 of 5 cases run)")


def test_seed_001s_stated_bead_counts_give_eq_2s_filling_on_its_geometry():
    """Seed 001 states 155,520 beads at 50 % and 289,951 at 90 %; eq. 2 on its stated
    geometry (the whole slice, 0.8 mm beads, porosity 0.4) holds them at 0.529 and 0.986,
    linear in between; the variant's scene holds that count, to the bead, in the whole
    slice and its share of it in the 10-degree sector. Outside 50-90 % it is refused."""
    from millfmu.dem.mills.geometry import bead_count_for_filling
    from millfmu.dem.scene import load_scene

    base = load_scene("disc_slice")
    assert S.with_stated_count(base, False) is base
    for fill, n in S.STATED_BEAD_COUNTS:
        full = S.with_stated_count(base.with_overrides(filling=fill), True)
        assert bead_count_for_filling(full.geometry, full.filling, full.bead_diameter_m) == n
        sector = S.with_stated_count(base.with_overrides(filling=fill, sector_deg=10.0,
                                                         gravity_m_per_s2=(0.0, 0.0, 0.0)), True)
        assert bead_count_for_filling(sector.geometry, sector.filling,
                                      sector.bead_diameter_m) == round(n / 36)
    # eq. 2 on the stated geometry: 294,131 beads per unit filling (0.6 of 131.4 mL)
    assert bead_count_for_filling(base.geometry, 1.0, base.bead_diameter_m) == 294_131
    assert [round(S.stated_count_filling(f), 3) for f in (0.5, 0.8, 0.9)] == [0.529, 0.872, 0.986]
    for bad in (0.4, 0.95):
        with pytest.raises(ValueError, match=f"filling = {bad}: seed 001 states bead counts for "
                                             "0.5 to 0.9 only"):
            S.stated_count_filling(bad)


def test_a_stated_count_case_runs_in_the_smallest_sector_that_holds_it(tmp_path):
    """At 90 % the 10-degree sector's initial lattice holds fewer beads than seed 001's
    count (7,644 of 8,054): the case runs in 20 degrees (16,108 of 16,376); 50 and 80 % stay
    in 10. The table and the summary read such a case from its folder."""
    from millfmu.dem.mills.geometry import bead_count_for_filling, fcc_sites, placement_gap_m
    from millfmu.dem.scene import load_scene

    assert [S.stated_count_sector_deg(f) for f in (0.5, 0.8, 0.9)] == [10.0, 10.0, 20.0]
    base = load_scene("disc_slice")
    r = 0.5 * base.bead_diameter_m
    for deg, n_sites in ((10.0, 7644), (20.0, 16376)):
        sc = S.with_stated_count(base.with_overrides(filling=0.9, sector_deg=deg,
                                                     gravity_m_per_s2=(0.0, 0.0, 0.0)), True)
        assert fcc_sites(sc.geometry, r, placement_gap_m(r)).shape[0] == n_sites
        assert bead_count_for_filling(sc.geometry, sc.filling, sc.bead_diameter_m) == \
            round(289_951 * deg / 360)
    shipped = S.summary_stats()
    out = _sector_folders(tmp_path / "runs", {k: v for k, v in shipped.items() if k != (6.0, 0.9)})
    d = S.case_dir(out, "coupled", 6.0, 0.9, 20.0)
    d.mkdir()
    (d / "stats.json").write_text(json.dumps(shipped[(6.0, 0.9)]))
    assert d.name == "c20_v6_f90"
    assert S.deviation_rows(out) == S.deviation_rows(_sector_folders(tmp_path / "ref", shipped))
    doc = json.loads(S.summarize(out, path=tmp_path / "s.json", stated_counts=True).read_text())
    assert doc["runs"]["6 m/s, 90 %"]["sector_deg"] == 20.0
    assert doc["runs"]["10 m/s, 80 %"]["sector_deg"] == 10.0


def test_a_stated_count_variant_keeps_each_runs_eq_2_filling(tmp_path):
    """--stated-bead-counts: each run in its summary with eq. 2's filling it ran at (the
    note, protocol and commands: the kept variants' test)."""
    out, p, doc = _variant_summarized(tmp_path, "seed001_sector_stated_counts.json",
                                      stated_counts=True)
    assert doc["runs"]["10 m/s, 80 %"]["filling_eq2"] == pytest.approx(0.8715, abs=1e-4)


def test_the_wall_friction_variants_count_on_the_page_is_its_summarys():
    """The page's count of the campaign with the walls' friction at 0.6 (a variant, not
    counted) and the verdicts it names follow from its kept summary,
    validation/runs/seed001_sector_wall_friction.json."""
    rows, c, text = _kept_variant("seed001_sector_wall_friction.json", "wall_friction", 0.6)
    assert "--wall-friction 0.6 --summary validation/runs/seed001_sector_wall_friction.json`; 52 minutes" in text
    judged = c["statements"] - c["not evaluated"]
    assert (f"the sector matches {c['matches']} of the {judged} statements it judges (its summary "
            "keeps no local filling). The layer turns at") in text

    def verdict(start):
        return next(r["verdict"].split()[0] for r in rows if r["statement"].startswith(start))

    assert verdict("angular velocity of the first bead layer") == "missed"
    assert verdict("mean bead speed / tip speed in V3") == "matches"
    assert verdict("collision frequency peaks about two bead") == "matches"
    assert verdict("mean bead speed / tip speed in V2") == "missed"
    assert verdict("median SE_tn: V1 > V2 > V3 > V4") == "missed"
    assert verdict("at 90 % filling V3 has the lowest") == "missed"
    layer = next(r for r in rows if r["statement"].startswith("angular velocity of the first bead layer"))
    assert layer["coupled"] == ("6 m/s 80 %: 0.179; 8 m/s 80 %: 0.175; 10 m/s 80 %: 0.174; "
                                "12 m/s 80 %: 0.168; 14 m/s 80 %: 0.167")


def test_the_stated_count_variants_figures_on_the_page_are_its_summarys():
    """The page's figures for the campaign with seed 001's stated bead counts (a variant, not
    counted) follow from its kept summary, validation/runs/seed001_sector_stated_counts.json:
    the count, the slowing at 80 %, the layer, V2 and V3 at 80 %, and the jammed bed at 90 %."""
    rows, c, text = _kept_variant("seed001_sector_stated_counts.json", "bead_counts",
                                  "seed 001's stated")
    assert "--stated-bead-counts --summary validation/runs/seed001_sector_stated_counts.json`" in text
    assert c["not evaluated"] == 0
    eq2 = S.count(S.deviation_rows(full_slice=False))["matches"]
    assert (f"the sector matches {c['matches']} of the {c['statements']} statements (eq. 2's "
            f"count: {eq2})") in text
    var = S.summary_stats(S.SUMMARY.parent / "seed001_sector_stated_counts.json")
    base = S.summary_stats()
    at80 = [k for k in S.CASES if k[1] == 0.8]

    def speed(st, zn):
        return S.zone(st, zn)["speed_over_tip_speed"]

    slow = [100 * (1 - speed(var[k], zn) / speed(base[k], zn)) for k in at80
            for zn in ("V1", "V2", "V3", "V4")]
    assert f"every zone slows by {min(slow):.0f}-{max(slow):.0f} %" in text
    layer = [var[k]["flow"]["first_bead_layer_angular_velocity_ratio"] for k in at80]
    assert f"first layer turns at {min(layer):.3f}-{max(layer):.3f}" in text
    v3 = [speed(var[k], "V3") for k in at80]
    v2 = [speed(var[k], "V2") for k in at80]
    assert f"V3 comes to {min(v3):.3g}-{max(v3):.3g}" in text
    assert f"V2 leaves its band ({min(v2):.3g}-{max(v2):.3g})" in text
    lo, hi = S.SPEED_BANDS["V3"]
    assert [S.within_band(v, lo, hi) for v in v3] == [k[0] != 14.0 for k in at80]
    jam, ref = var[(6.0, 0.9)], base[(6.0, 0.9)]
    assert (f"V2 and V3 move at {100 * speed(jam, 'V2'):.1f} and {100 * speed(jam, 'V3'):.1f} % "
            f"of the tip speed (eq. 2's count: {100 * speed(ref, 'V2'):.1f} %)") in text
    fills = [z["filling"] for z in jam["zones"]]
    assert f"local filling {min(fills):.2f}-{max(fills):.2f} in every zone" in text
    assert round(S.zone(ref, "V2")["collision_frequency_per_m3_s"] /
                 S.zone(jam, "V2")["collision_frequency_per_m3_s"]) == 8  # "an eighth"

    def ratio(rows_):
        r = next(r for r in rows_ if r["statement"].startswith("collision power density of V1"))
        return float(dict(x.split(": ") for x in r["coupled"].split("; "))["6 m/s 50 %"])

    assert f"moves from {ratio(S.deviation_rows()):.3g} to {ratio(rows):.2g}" in text
