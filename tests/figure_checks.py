"""Layout checks of a matplotlib figure, from the artists' extents in
display coordinates after a draw (what the PNG shows):

* every title, axis label and legend lies inside the figure (nothing clipped);
* no legend covers data: no plotted point (lines, markers, scatter, error
  bars) inside a legend's box, and no legend over an image or colour mesh;
* no legend covers a title or an axis label (a figure legend beside the
  axes at the top can reach into a long figure title);
* every axes that shows data has both axis labels, each with its unit in
  parentheses, or one of the dimensionless quantities named in
  DIMENSIONLESS; a colour bar's label has its unit.

``problems(fig)`` returns one line per violation (empty: the figure is fine).
"""

import re

import numpy as np
from matplotlib.collections import LineCollection, PathCollection, QuadMesh
from matplotlib.image import AxesImage

UNIT = re.compile(r"\((mm|m|N|N\*m|deg|rad|ms|s|Hz|um/N|kg|W|kW|%)\)")
# axis labels of quantities without a unit, and why
DIMENSIONLESS = (
    "measurement order",  # a count
    "file line",  # a line number
    "joint",  # the joint's number
    "stiffness / nominal",  # a ratio
    "sign of f",  # -1, 0, +1
    "filter cutoff and mode",  # categories (their cutoffs carry Hz in the tick labels)
)
TOLERANCE_PX = 1.0


def _inside(bb, outer):
    return (bb.x0 >= outer.x0 - TOLERANCE_PX and bb.y0 >= outer.y0 - TOLERANCE_PX
            and bb.x1 <= outer.x1 + TOLERANCE_PX and bb.y1 <= outer.y1 + TOLERANCE_PX)


def _texts(fig):
    out = []
    for getter in ("_suptitle", "_supxlabel", "_supylabel"):
        t = getattr(fig, getter, None)
        if t is not None and t.get_text():
            out.append(("figure title", t))
    for ax in fig.axes:
        for t in (ax.title, ax._left_title, ax._right_title, ax.xaxis.label, ax.yaxis.label):
            if t.get_text() and t.get_visible():
                out.append((f"axes text {t.get_text()[:40]!r}", t))
    return out


def _legends(fig):
    legends = list(fig.legends)
    legends += [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    return legends


def _data_points(ax):
    """Display coordinates (N, 2) of every plotted point of ``ax`` inside its box."""
    pts = []
    for line in ax.lines:
        if not line.get_visible():
            continue
        xy = np.column_stack([np.asarray(line.get_xdata(), dtype=float), np.asarray(line.get_ydata(), dtype=float)])
        xy = xy[np.all(np.isfinite(xy), axis=1)]
        if len(xy):
            pts.append(line.get_transform().transform(xy))
    for coll in ax.collections:
        if isinstance(coll, PathCollection) and len(coll.get_offsets()):
            pts.append(coll.get_offset_transform().transform(np.asarray(coll.get_offsets(), dtype=float)))
        elif isinstance(coll, LineCollection):
            for seg in coll.get_segments():
                if len(seg):
                    pts.append(coll.get_transform().transform(np.asarray(seg, dtype=float)))
    if not pts:
        return np.zeros((0, 2))
    xy = np.vstack(pts)
    box = ax.bbox
    keep = (xy[:, 0] >= box.x0) & (xy[:, 0] <= box.x1) & (xy[:, 1] >= box.y0) & (xy[:, 1] <= box.y1)
    return xy[keep]


def _overlap(a, b):
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def problems(fig):
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    found = []
    for what, t in _texts(fig):
        if not _inside(t.get_window_extent(renderer), fig.bbox):
            found.append(f"{what} is cut off at the figure's edge")
    for leg in _legends(fig):
        lb = leg.get_window_extent(renderer)
        name = "legend " + ", ".join(t.get_text() for t in leg.get_texts()[:2])
        if not _inside(lb, fig.bbox):
            found.append(f"{name} is cut off at the figure's edge")
        for what, t in _texts(fig):
            if _overlap(lb, t.get_window_extent(renderer)):
                found.append(f"{name} covers the {what}")
        for ax in fig.axes:
            xy = _data_points(ax)
            inside = (xy[:, 0] > lb.x0) & (xy[:, 0] < lb.x1) & (xy[:, 1] > lb.y0) & (xy[:, 1] < lb.y1)
            if inside.any():
                found.append(f"{name} covers {int(inside.sum())} data point(s) of axes {ax.get_title()[:40]!r}")
            for art in (*ax.images, *ax.collections):
                if isinstance(art, (AxesImage, QuadMesh)) and _overlap(lb, art.get_window_extent(renderer)) \
                        and _overlap(lb, ax.bbox):
                    found.append(f"{name} covers the colour map of axes {ax.get_title()[:40]!r}")
    for ax in fig.axes:
        if hasattr(ax, "_colorbar"):
            label = ax.get_ylabel() or ax.get_xlabel()
            if not UNIT.search(label):
                found.append(f"colour bar label {label!r} has no unit")
            continue
        if not (ax.lines or ax.collections or ax.images):
            continue
        for axis, label in (("x", ax.get_xlabel()), ("y", ax.get_ylabel())):
            if not label:
                found.append(f"axes {ax.get_title()[:40]!r}: no {axis} label")
            elif not UNIT.search(label) and not any(label.startswith(d) for d in DIMENSIONLESS):
                found.append(f"axes {ax.get_title()[:40]!r}: {axis} label {label!r} has no unit")
    return found
