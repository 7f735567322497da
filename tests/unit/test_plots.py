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

EXAMPLES = ["yeast_disruption", "yeast_disruption_detailed", "limestone_continuous", "limestone_simple"]


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
