"""Seed 001's full slice started warm from the settled sector (validation/full_slice_warm.py):
the repeated state against closed forms (copies turned about the axis keep every bead's
radius, axial position, speed and angular velocity; the circle holds the scene's bead count),
the added beads' clearance, and the comparison with the cold run computed from the kept
summaries, so that the page's tables and the summaries cannot disagree."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from validation import full_slice_warm as W
from validation import seed001 as S

PAGE = Path(__file__).resolve().parents[2] / "docs" / "dem-full-slices.md"


def _sector_state(n=50, sector_deg=10.0, seed=3):
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.02, 0.04, n)
    t = rng.uniform(0.0, math.radians(sector_deg), n)
    z = rng.uniform(0.0, 0.028, n)
    x = np.column_stack([r * np.cos(t), r * np.sin(t), z])
    v = rng.normal(size=(n, 3))
    w = rng.normal(size=(n, 3)) * 100.0
    return {"x_m": x, "v_m_per_s": v, "w_rad_per_s": w, "fluid_at_bead": rng.normal(size=(n, 6)),
            "liquid_ur": rng.normal(size=(5, 1, 4)), "liquid_ut": rng.normal(size=(4, 1, 4))}


def test_replicate_turns_copies_about_the_axis():
    a = _sector_state()
    rep = W.replicate(a, 10.0, 32)
    n = len(a["x_m"])
    assert rep["x_m"].shape == (36 * n, 3)
    x, v = rep["x_m"], rep["v_m_per_s"]
    r = np.hypot(x[:, 0], x[:, 1])
    omega = (x[:, 0] * v[:, 1] - x[:, 1] * v[:, 0]) / r ** 2
    x0, v0 = a["x_m"], a["v_m_per_s"]
    omega0 = (x0[:, 0] * v0[:, 1] - x0[:, 1] * v0[:, 0]) / np.hypot(x0[:, 0], x0[:, 1]) ** 2
    for k in (1, 17, 35):
        s = slice(k * n, (k + 1) * n)
        np.testing.assert_allclose(r[s], np.hypot(x0[:, 0], x0[:, 1]), rtol=1e-14)
        np.testing.assert_array_equal(x[s, 2], x0[:, 2])
        np.testing.assert_allclose(np.linalg.norm(v[s], axis=1), np.linalg.norm(v0, axis=1), rtol=1e-14)
        np.testing.assert_allclose(omega[s], omega0, rtol=1e-12, atol=1e-12)
        dt = np.angle(np.exp(1j * (np.arctan2(x[s, 1], x[s, 0]) - np.arctan2(x0[:, 1], x0[:, 0]))))
        np.testing.assert_allclose(dt, math.radians(10.0 * k) - 2 * math.pi * (k > 18), atol=1e-12)
        # spins turn with the copy; the axial spin is kept
        np.testing.assert_array_equal(rep["w_rad_per_s"][s, 2], a["w_rad_per_s"][:, 2])
    # cylindrical per-bead fields repeat as they are; the liquid over the theta cells
    np.testing.assert_array_equal(rep["fluid_at_bead"][35 * n:], a["fluid_at_bead"])
    assert rep["liquid_ur"].shape == (5, 32, 4)
    for j in (0, 31):
        np.testing.assert_array_equal(rep["liquid_ut"][:, j], a["liquid_ut"][:, 0])


def test_replicate_refuses_what_does_not_tile_the_circle():
    a = _sector_state()
    with pytest.raises(ValueError, match="sector_deg = 7.0"):
        W.replicate(a, 7.0, 32)
    a["liquid_p"] = np.zeros((4, 2, 4))
    with pytest.raises(ValueError, match="liquid_p: shape"):
        W.replicate(a, 10.0, 32)


def test_the_shipped_anchor_fills_the_full_slice():
    """The anchor repeated 36 times and the beads the filling holds beyond them: the scene's
    count; the added ones at rest, clear of every bead and wall."""
    scene = S.full_slice_scene(10.0, 0.8).with_overrides(spin_up_s=W.SPIN_UP_S)
    arrays, start = W.warm_arrays(scene)
    from millfmu.dem.mills.geometry import bead_count_for_filling

    n = bead_count_for_filling(scene.geometry, 0.8, scene.bead_diameter_m, scene.bulk_porosity)
    assert len(arrays["x_m"]) == n == 36 * 6536 + start["beads_added_at_rest"]
    assert start["beads_added_at_rest"] == 9 and start["copies"] == 36
    k = start["beads_added_at_rest"]
    new = arrays["x_m"][-k:]
    assert not np.any(arrays["v_m_per_s"][-k:]) and not np.any(arrays["w_rad_per_s"][-k:])
    g, d = scene.geometry, scene.bead_diameter_m
    old = arrays["x_m"][:-k]
    lz = g.height_m
    for p in new:
        dz = old[:, 2] - p[2]
        dz -= lz * np.round(dz / lz)
        dist = np.sqrt((old[:, 0] - p[0]) ** 2 + (old[:, 1] - p[1]) ** 2 + dz ** 2)
        assert dist.min() >= W.ADD_CLEARANCE * d
        r = math.hypot(p[0], p[1])
        assert g.shaft_radius_m + 0.5 * d < r < g.chamber_radius_m - 0.5 * d
    # every liquid field on the full slice's 32 theta cells
    assert arrays["liquid_ut"].shape[1] == 32


@pytest.fixture(scope="module")
def kept_comparison():
    kept = W.kept_runs()
    if (10.0, 0.8) not in kept:
        pytest.fail(f"{W.SUMMARY}: no warm run at 10 m/s, 80 %")
    return W.comparison(kept[(10.0, 0.8)], 10.0, 0.8)


def test_page_shows_the_comparison_the_summaries_give(kept_comparison):
    """The page's two tables are what the kept warm run and the shipped cold run give."""
    page = PAGE.read_text(encoding="utf-8")
    windows = W.windows_markdown(W.kept_windows()[(10.0, 0.8)])
    for line in (W.markdown(kept_comparison) + "\n" + windows).splitlines():
        if line.strip():
            assert line in page, line
    assert len(W.kept_windows()[(10.0, 0.8)]) == 3  # the recording's three 0.1 s windows


def test_comparison_reads_every_statement_of_the_deviation_table(kept_comparison, tmp_path):
    """The comparison's cold cells are the deviation table's full-slice cells with the
    shipped summary's full slice holding this one case (the campaign's protocol: the cold
    run)."""
    one = tmp_path / "one_case.json"
    one.write_text(json.dumps(W._summary_with(json.loads(S.SUMMARY.read_text()), S.case_label(10.0, 0.8),
                                              10.0, 0.8, S.summary_stats(full_slice=True)[(10.0, 0.8)])))
    rows = S.deviation_rows(summary=one)
    assert [s["statement"] for s in kept_comparison["statements"]] == [r["statement"] for r in rows]
    cold = {s["statement"]: s["cold"] for s in kept_comparison["statements"]}
    for r in rows:
        assert cold[r["statement"]] == r["full"]
    assert json.loads(W.SUMMARY.read_text())["runs"]["10 m/s, 80 %"]["start"]["spin_up_s"] == W.SPIN_UP_S
