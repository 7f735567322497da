"""Tick labels of the project's log axes.

Matplotlib labels a log axis's minor ticks as "2x10^0" or "6x10^-1". Where the axis spans
a modest range, plain numbers (0.6, 2, 20) read at a glance; only an axis reaching beyond
:data:`PLAIN_RANGE` keeps the powers of ten, where a plain number would need a run of
zeros. Every plot of the project with a log axis passes its figure (or axes) to
:func:`plain_log_ticks` once its scales and limits are set.
"""

from __future__ import annotations

import numpy as np
from matplotlib.ticker import LogFormatterSciNotation

#: Plain numbers while the axis's view lies within these magnitudes: 0.001 and 10000 are
#: the longest plain labels (five characters) that still read faster than 10^n.
PLAIN_RANGE = (1e-3, 1e4)


class PlainLogFormatter(LogFormatterSciNotation):
    """Labels the ticks matplotlib's log formatter would label (it picks which minor ticks
    get one), as plain numbers with at most four significant digits while the view lies
    within :data:`PLAIN_RANGE`, else as matplotlib does. The choice is made at draw time,
    so limits set later count."""

    def __call__(self, x, pos=None):
        label = super().__call__(x, pos)
        if not label or not self._plain():
            return label
        return np.format_float_positional(float(x), precision=4, unique=True, fractional=False, trim="-")

    def _plain(self) -> bool:
        if self.axis is None:
            return False
        lo, hi = sorted(abs(float(v)) for v in self.axis.get_view_interval())
        return PLAIN_RANGE[0] <= lo and hi <= PLAIN_RANGE[1]


def plain_log_ticks(target) -> None:
    """Give every log axis of ``target`` (a figure, an axes or a list of axes) the
    :class:`PlainLogFormatter`; linear axes are left alone. Call it after the scales are
    set: setting a scale puts matplotlib's own formatters back."""
    axes = getattr(target, "axes", target)
    if not isinstance(axes, (list, tuple, np.ndarray)):
        axes = [axes]
    for ax in np.ravel(np.asarray(axes, dtype=object)):
        for axis in (ax.xaxis, ax.yaxis):
            if axis.get_scale() == "log":
                axis.set_major_formatter(PlainLogFormatter())
                axis.set_minor_formatter(PlainLogFormatter(labelOnlyBase=False))


#: Where a point's label may go, tried in turn: (dx, dy) [points] from the point and the
#: label's alignment there.
LABEL_OFFSETS = ((5, 3, "left", "bottom"), (5, -3, "left", "top"), (-5, 3, "right", "bottom"),
                 (-5, -3, "right", "top"), (0, 7, "center", "bottom"), (0, -7, "center", "top"))


def label_points(ax, points, texts, fontsize=7, marker_px=5.0) -> list:
    """Annotate ``points`` (data coordinates) of ``ax`` with ``texts`` in turn, each at the
    first of :data:`LABEL_OFFSETS` where it stays inside the axes and covers neither a label
    placed before nor a marker of the axes' lines (``marker_px``: a marker's half width in
    pixels), preferring a place that no drawn line crosses either; a label with no such
    place is left out, since one on top of another can be read as neither. Call it once
    the figure's layout is final (after ``tight_layout``): the places are measured in
    pixels. Returns the annotations placed."""
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    ax.autoscale_view()
    frame = ax.get_window_extent(renderer)
    lines = [ln for ln in ax.get_lines() if len(ln.get_xdata())]
    markers = [ln.get_transform().transform(ln.get_xydata()) for ln in lines
               if ln.get_marker() not in (None, "None", "none", "", " ")]
    markers = np.concatenate(markers) if markers else np.empty((0, 2))
    markers = markers[np.all(np.isfinite(markers), axis=1)]
    paths = [ln.get_transform().transform_path(ln.get_path()) for ln in lines
             if ln.get_linestyle() not in ("None", "none", "", " ")]
    boxes, placed = [], []
    for (x, y), text in zip(points, texts):
        own = ax.transData.transform((x, y))
        near = markers[np.linalg.norm(markers - own, axis=1) > 0.5]  # not the labelled point itself
        free, fallback = None, None
        for dx, dy, ha, va in LABEL_OFFSETS:
            ann = ax.annotate(text, (x, y), xytext=(dx, dy), textcoords="offset points", ha=ha, va=va,
                              fontsize=fontsize)
            bb = ann.get_window_extent(renderer)
            ann.remove()
            hits_marker = bool(near.size) and bool(np.any(
                (near[:, 0] > bb.x0 - marker_px) & (near[:, 0] < bb.x1 + marker_px)
                & (near[:, 1] > bb.y0 - marker_px) & (near[:, 1] < bb.y1 + marker_px)))
            if not (frame.x0 <= bb.x0 and bb.x1 <= frame.x1 and frame.y0 <= bb.y0 and bb.y1 <= frame.y1) \
                    or hits_marker or any(bb.overlaps(b) for b in boxes):
                continue
            if not any(pa.intersects_bbox(bb, filled=False) for pa in paths):
                free = (dx, dy, ha, va, bb)
                break
            fallback = fallback or (dx, dy, ha, va, bb)
        chosen = free or fallback
        if chosen is None:
            continue
        dx, dy, ha, va, bb = chosen
        placed.append(ax.annotate(text, (x, y), xytext=(dx, dy), textcoords="offset points", ha=ha, va=va,
                                  fontsize=fontsize))
        boxes.append(bb)
    return placed
