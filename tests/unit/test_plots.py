"""What a person sees in a run's plots (issue 27): no two axes of a figure overlap (tight
bounding boxes, legends included), every line has a legend entry, no legend covers a curve,
time in seconds, and psd.png says what distribution it shows."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from millfmu.runner import psd_figure, simulate, sizes_figure  # noqa: E402
from millfmu.scene import load_scene, scene_from_dict  # noqa: E402

EXAMPLES = ["yeast_disruption", "yeast_disruption_detailed", "limestone_continuous", "limestone_detailed"]


def _scene(name):
    from pathlib import Path

    import millfmu

    s = load_scene(Path(millfmu.__file__).parent / "data" / "examples" / f"{name}.toml")
    from millfmu.scene import scene_to_dict

    d = scene_to_dict(s)
    d["run"].update(t_end_s=min(s.run.t_end_s, 600.0), dt_s=max(s.run.dt_s, 10.0), output_interval_s=60.0)
    d["run"].pop("tip_speed_profile", None)
    return scene_from_dict(d, name)


def check_figure(fig):
    """The checks of a figure, as messages (empty: fine)."""
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    problems = []
    axes = [ax for ax in fig.axes if ax.get_visible()]
    boxes = [ax.get_tightbbox(r) for ax in axes]
    for i in range(len(axes)):
        for j in range(i + 1, len(axes)):
            if boxes[i].overlaps(boxes[j]):
                problems.append(f"axes {i} ({axes[i].get_ylabel()!r}) and {j} ({axes[j].get_ylabel()!r}) overlap")
    legends = [ax.get_legend() for ax in axes if ax.get_legend() is not None] + list(fig.legends)
    labels = {t.get_text() for lg in legends for t in lg.get_texts()}
    for ax in axes:
        for line in ax.get_lines():
            if len(line.get_xdata()) == 0:
                continue
            if line.get_label() not in labels:
                problems.append(f"line {line.get_label()!r} in {ax.get_ylabel()!r} has no legend entry")
    for lg in legends:
        box = lg.get_window_extent(r)
        for ax in axes:
            for line in ax.get_lines():
                pts = line.get_transform().transform(line.get_xydata())
                path = line.get_transform().transform_path(line.get_path())
                drawn = line.get_linestyle() not in ("None", "none", "", " ")
                if any(box.contains(x, y) for x, y in pts) or (drawn and path.intersects_bbox(box, filled=False)):
                    problems.append(f"a legend covers line {line.get_label()!r}")
                    break
    bb = fig.get_tightbbox(r)
    if bb.x0 < -1 or bb.y0 < -1 or bb.x1 > fig.bbox.width + 1 or bb.y1 > fig.bbox.height + 1:
        problems.append(f"something is cut at the figure's edge: {bb} in {fig.bbox}")
    return problems


@pytest.mark.parametrize("name", EXAMPLES)
def test_run_plots_are_readable(name):
    scene = _scene(name)
    model, records, psds = simulate(scene, progress=False)
    for fig in (psd_figure(model, records, psds), sizes_figure(model, records)):
        try:
            assert check_figure(fig) == []
        finally:
            plt.close(fig)
    fig = sizes_figure(model, records)
    try:
        assert fig.axes[-1].get_xlabel() == "time t [s]"
        if "disrupted_fraction" in records[0]:
            assert any(line.get_label() == "disrupted cells" for ax in fig.axes for line in ax.get_lines())
    finally:
        plt.close(fig)
    fig = psd_figure(model, records, psds)
    try:
        title = fig._suptitle.get_text()
        want = "product at the mill outlet" if scene.operation.mode == "continuous" else "mill content"
        assert want in title and "v:" not in " ".join(ax.get_title() for ax in fig.axes)
    finally:
        plt.close(fig)


def test_the_checks_catch_what_was_wrong():
    """Two right-hand axes drawn over each other, a line without a legend entry, a legend
    over the curves: each is found."""
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1], label="a")
    ax.legend(loc="center")
    ax.twinx().plot([0, 1], [1, 0], "k--")
    ax.twinx().plot([0, 1], [0.5, 0.5], "k:")
    p = check_figure(fig)
    plt.close(fig)
    assert any("overlap" in m for m in p) and any("no legend entry" in m for m in p) and any("covers" in m for m in p)


# ---- issue 55: log ticks in plain numbers, the DEM work-precision figure --------------------
@pytest.fixture
def saved(monkeypatch):
    """The figures saved while the test runs (a plotting function closes its figure after
    saving it; the figure object still holds what was drawn)."""
    from matplotlib.figure import Figure

    figs = []
    orig = Figure.savefig

    def savefig(self, *a, **k):
        figs.append(self)
        return orig(self, *a, **k)

    monkeypatch.setattr(Figure, "savefig", savefig)
    yield figs
    for fig in figs:
        plt.close(fig)


def measurable(fig):
    """``fig`` with a canvas again (closing a figure leaves it without one)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    return fig


def log_tick_labels(fig):
    """(axis, label) of every labelled tick of every log axis of ``fig``, after a draw."""
    fig.canvas.draw()
    out = []
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        for axis in (ax.xaxis, ax.yaxis):
            if axis.get_scale() == "log":
                ticks = axis.get_majorticklabels() + axis.get_minorticklabels()
                out += [(axis, t.get_text()) for t in ticks if t.get_text()]
    return out


def powers_of_ten_in_modest_range(fig):
    """Log-tick labels written as powers of ten ("2x10^0") on an axis whose view lies
    within the plain range: each should read as a plain number."""
    from millfmu.plotstyle import PLAIN_RANGE

    bad = []
    for axis, text in log_tick_labels(fig):
        lo, hi = sorted(abs(v) for v in axis.get_view_interval())
        if PLAIN_RANGE[0] <= lo and hi <= PLAIN_RANGE[1] and ("^" in text or "times" in text or "e" in text):
            bad.append(text)
    return bad


@pytest.mark.parametrize("limits, want", [((0.06, 0.3), {"0.1", "0.06", "0.2", "0.3"}),
                                          ((0.5, 30.0), {"1", "10"}),
                                          ((300.0, 1500.0), {"1000", "300", "600"})])
def test_plain_log_ticks_give_plain_numbers(limits, want):
    from millfmu.plotstyle import plain_log_ticks

    fig, ax = plt.subplots()
    ax.loglog(limits, limits)
    plain_log_ticks(fig)
    try:
        labels = {t for _, t in log_tick_labels(fig)}
        assert want <= labels and powers_of_ten_in_modest_range(fig) == []
    finally:
        plt.close(fig)


def test_plain_log_ticks_keep_powers_of_ten_over_many_decades():
    from millfmu.plotstyle import plain_log_ticks

    fig, ax = plt.subplots()
    ax.semilogy([0, 1], [1e-10, 1e9])
    plain_log_ticks(ax)
    try:
        labels = [t for _, t in log_tick_labels(fig)]
        assert labels and all("10^" in t for t in labels)  # 1e-10 as a plain number: unreadable
    finally:
        plt.close(fig)


def test_flowsheet_work_precision_ticks_are_plain(saved, tmp_path):
    from types import SimpleNamespace

    import numpy as np

    from flowsheets.wp import _plot

    rows = [{"step_s": h, "wall_s": w, "relative_error": e}
            for h, w, e in ((40.0, 2.1, 0.3), (20.0, 3.5, 0.16), (10.0, 6.2, 0.08), (5.0, 11.0, 0.041))]
    times = np.linspace(0.0, 600.0, 5)
    runs = {r["step_s"]: (None, 1e-5 * (1 - times / 1200.0)) for r in rows}
    fs = SimpleNamespace(name="demo", algorithm="jacobi")
    _plot(rows, runs, 5.0, times, "mill.x50", fs, 0.97, tmp_path / "wp.png")
    fig = measurable(saved[0])
    assert len(saved) == 1 and log_tick_labels(fig)
    assert powers_of_ten_in_modest_range(fig) == []


def _shipped_dem_study():
    import json

    from millfmu.dem.analysis import precision as W

    if not W.SUMMARY_PATH.is_file():
        pytest.skip("no DEM study shipped")
    return W, json.loads(W.SUMMARY_PATH.read_text())["study"]


def test_dem_work_precision_figure_reads(saved, tmp_path):
    """The report's DEM figure: every line in a legend (marker meanings included), titles
    in words rather than marker codes, point labels that do not overlap one another, plain
    log ticks."""
    import re

    W, res = _shipped_dem_study()
    W.plot(res, tmp_path / "wp.png")
    fig = measurable(saved[0])
    assert check_figure(fig) == []
    titles = [ax.get_title() for ax in fig.axes]
    assert not [t for t in titles if re.search(r"\((o|s|D|--)[ ,)]|\bD variants", t)], titles
    assert powers_of_ten_in_modest_range(fig) == []
    r = fig.canvas.get_renderer()
    for ax in fig.axes:
        boxes = [t.get_window_extent(r) for t in ax.texts]
        clash = [(ax.texts[i].get_text(), ax.texts[j].get_text()) for i in range(len(boxes))
                 for j in range(i + 1, len(boxes)) if boxes[i].overlaps(boxes[j])]
        assert clash == [], clash
    wp_axes = [ax for ax in fig.axes if ax.get_title().startswith("work-precision")]
    assert wp_axes and len(wp_axes[0].texts) >= len(res["variants"])  # the variants are named
    legend = {t.get_text() for t in wp_axes[0].get_legend().get_texts()}
    assert any("spin-up" in t for t in legend) and any("recording" in t for t in legend)


def test_label_points_leaves_out_what_would_overlap():
    from millfmu.plotstyle import label_points

    fig, ax = plt.subplots(figsize=(3, 2))
    pts = [(1.0, 1.0), (1.001, 1.001), (1.002, 1.0), (1.0, 1.002), (2.0, 2.0)]
    ax.plot([p[0] for p in pts], [p[1] for p in pts], "o")
    placed = label_points(ax, pts, [f"a long label {i}" for i in range(len(pts))])
    r = fig.canvas.get_renderer()
    try:
        boxes = [a.get_window_extent(r) for a in placed]
        assert 1 <= len(placed) < len(pts)
        assert not any(boxes[i].overlaps(boxes[j]) for i in range(len(boxes)) for j in range(i + 1, len(boxes)))
    finally:
        plt.close(fig)
