"""Where a marker's name goes on a map: beside it, inside the axes, clear of the names and
markers already there.

Placed once the figure's layout is drawn, in points from the axes' lower left: each name
takes the first free place among above, below, left and right of its marker, then further
above or below, then left or right stacked up or down (`_places`). A name is never placed
outside the axes (where it would run over the title, the colour bar or the legend) unless
no place inside exists.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from matplotlib.axes import Axes

Box = tuple[float, float, float, float]  # x0, y0, x1, y1, points from the axes' lower left
Place = tuple[tuple[float, float], str, str]  # offset (points), ha, va

GAP_PT = 7.0  # between a marker and its name
CHAR_WIDTH_EM = 0.65  # a generous mean glyph width (DejaVu Sans digits and capitals: 0.6 to 0.7)
MARKER_HALF_PT = 4.5  # the half width of a map marker, kept clear of names


@dataclass(frozen=True)
class Label:
    """A name to write beside the marker at (x, y) (data coordinates), with `annotate`'s style."""

    text: str
    x: float
    y: float
    fontsize: float = 8.0
    style: dict[str, Any] = field(default_factory=dict)
    pad_pt: float = 0.0  # a bbox's padding around the text, each side


def label_size_pt(text: str, fontsize: float, pad_pt: float = 0.0) -> tuple[float, float]:
    """(width, height) in points of one line of `text` at `fontsize`, padding included."""
    return CHAR_WIDTH_EM * fontsize * len(text) + 2.0 + 2 * pad_pt, 1.25 * fontsize + 2 * pad_pt


def _places(height_pt: float) -> list[Place]:
    """Offsets and alignments to try, in order (module docstring)."""
    step = height_pt + 1.0
    places: list[Place] = [
        ((0.0, GAP_PT), "center", "bottom"),
        ((0.0, -GAP_PT - 1.0), "center", "top"),
        ((-GAP_PT, 0.0), "right", "center"),
        ((GAP_PT, 0.0), "left", "center"),
    ]
    for k in (1, 2, 3):
        places += [((0.0, GAP_PT + k * step), "center", "bottom"), ((0.0, -GAP_PT - 1.0 - k * step), "center", "top")]
    for k in (1, -1, 2, -2, 3, -3, 4, -4, 5, -5):
        places += [((-GAP_PT, k * step), "right", "center"), ((GAP_PT, k * step), "left", "center")]
    return places


def _box(x_pt: float, y_pt: float, size: tuple[float, float], place: Place) -> Box:
    """The box of a name of `size` at `place` beside the marker at (x_pt, y_pt)."""
    (dx, dy), ha, va = place
    w, h = size
    cx = x_pt + dx + {"center": 0.0, "left": w / 2, "right": -w / 2}[ha]
    cy = y_pt + dy + {"center": 0.0, "bottom": h / 2, "top": -h / 2}[va]
    return cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2


def _overlaps(a: Box, b: Box) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def place_label(
    x_pt: float, y_pt: float, size: tuple[float, float], taken: Sequence[Box], area: tuple[float, float]
) -> tuple[Place, Box]:
    """The first place (`_places`) whose box lies inside `area` (the axes' width and height,
    points) and overlaps none `taken`; else the first inside, else above."""
    width, height = area
    candidates = [(p, _box(x_pt, y_pt, size, p)) for p in _places(size[1])]
    inside = [(p, b) for p, b in candidates if b[0] >= 0 and b[1] >= 0 and b[2] <= width and b[3] <= height]
    free = [(p, b) for p, b in inside if not any(_overlaps(b, t) for t in taken)]
    return (free or inside or candidates)[0]


def axes_points(ax: Axes, x: float, y: float) -> tuple[float, float]:
    """Data coordinates (x, y) as points from the axes' lower left, as last laid out."""
    px, py = ax.transData.transform((x, y))
    frame = ax.get_window_extent()
    scale = 72.0 / ax.figure.dpi
    return (px - frame.x0) * scale, (py - frame.y0) * scale


def marker_box(ax: Axes, x: float, y: float) -> Box:
    """The box a marker at data coordinates (x, y) covers."""
    mx, my = axes_points(ax, x, y)
    return mx - MARKER_HALF_PT, my - MARKER_HALF_PT, mx + MARKER_HALF_PT, my + MARKER_HALF_PT


def draw_labels(ax: Axes, labels: Sequence[Label], taken: list[Box]) -> None:
    """Write each name at its first free place (`place_label`), in order, clear of `taken`
    (extended with each name placed). Call it once the figure's layout is drawn."""
    frame = ax.get_window_extent()
    scale = 72.0 / ax.figure.dpi
    area = (frame.width * scale, frame.height * scale)
    for label in labels:
        x_pt, y_pt = axes_points(ax, label.x, label.y)
        (offset, ha, va), box = place_label(
            x_pt, y_pt, label_size_pt(label.text, label.fontsize, label.pad_pt), taken, area
        )
        taken.append(box)
        ax.annotate(label.text, (label.x, label.y), xytext=offset, textcoords="offset points", ha=ha, va=va,
                    fontsize=label.fontsize, annotation_clip=True, **label.style)  # fmt: skip
