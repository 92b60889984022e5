"""What every figure shares: the Agg backend, one panel per joint in a grid of sane size,
long lines cut to the pixels they are drawn on, axis limits set by the converged part of a
run, and the files written.

Drawing costs: matplotlib's time grows with the points it is given, not with the pixels it
fills.  A 60 s log at 1 kHz is 60 000 points a line in a panel ~800 px wide: :func:`envelope`
keeps each pixel column's smallest and largest value (the picture is the same, spikes
included) and the lines are rasterized in the PNG.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "DPI",
    "converged_limit",
    "envelope",
    "joint_grid",
    "pyplot",
    "save",
    "title",
    "window_start",
]

FloatArray = NDArray[np.float64]

#: Resolution of every PNG [dots per inch].
DPI = 100
#: Joint panels per row of a grid (a 7-joint arm: 4 + 3).
MAX_COLUMNS = 4
#: Columns of pixels a panel's line is cut to by :func:`envelope` (wider than any panel).
PIXELS = 1000


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend (no display; imported on first use)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def joint_grid(
    n: int,
    panel: tuple[float, float] = (4.0, 2.6),
    rows_per_joint: int = 1,
    sharex: bool = True,
) -> tuple[Any, list[list[Any]]]:
    """A figure with one panel per joint, ``min(n, 4)`` panels a row; each panel is
    ``rows_per_joint`` axes stacked (sharing x).

    Args:
        n: Joints.
        panel: Width and height of one joint's panel [in].
        rows_per_joint: Axes stacked in a panel (e.g. 2: q error above, qd error below).
        sharex: The stacked axes of a panel share their time axis.

    Returns:
        The figure and, per joint, its list of axes (top to bottom); panels past ``n`` in
        the last row are hidden.
    """
    from matplotlib.ticker import MaxNLocator

    plt = pyplot()
    cols = min(n, MAX_COLUMNS)
    rows = math.ceil(n / cols)
    fig = plt.figure(figsize=(panel[0] * cols, panel[1] * rows * rows_per_joint + 0.7))
    grid = fig.add_gridspec(rows * rows_per_joint, cols)
    cells: list[list[Any]] = []
    for j in range(n):
        r, c = divmod(j, cols)
        top = fig.add_subplot(grid[r * rows_per_joint, c])
        axes = [top] + [
            fig.add_subplot(grid[r * rows_per_joint + i, c], sharex=top if sharex else None)
            for i in range(1, rows_per_joint)
        ]
        for ax in axes:  # few ticks: each is a text to lay out and draw
            ax.xaxis.set_major_locator(MaxNLocator(5))
            ax.yaxis.set_major_locator(MaxNLocator(5))
            ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))  # 1e-4 above the axis
            ax.tick_params(labelsize=7)
            ax.yaxis.get_offset_text().set_fontsize(7)
        cells.append(axes)
    return fig, cells


def window_start(K: int) -> int:
    """First tick of the converged part: the last 80 % of a run of ``K`` ticks."""
    return K // 5


def converged_limit(values: FloatArray, band: FloatArray | None = None) -> float:
    """A symmetric axis limit that shows the converged part of a run: the 2nd-98th
    percentile of ``values`` over the last 80 %, and the 98th percentile of ``band`` there
    (a 2-sigma half-width, so the band is visible), with 30 % room; the start transient is
    clipped.  NaN is ignored; a positive floor keeps an all-zero line drawable."""
    w = window_start(values.shape[0])
    v = np.abs(values[w:][np.isfinite(values[w:])])
    lim = float(np.percentile(v, 98)) if v.size else 0.0
    if band is not None:
        b = band[w:][np.isfinite(band[w:])]
        if b.size:
            lim = max(lim, float(np.percentile(b, 98)))
    return 1.3 * lim if lim > 0 else 1e-9


def envelope(t: FloatArray, *ys: FloatArray, pixels: int = PIXELS) -> tuple[Any, ...]:
    """``t`` and each of ``ys`` cut to ``pixels`` columns, keeping each column's smallest
    and largest value of each line (2 points a column: its low, then its high): the line
    drawn is the same to the pixel, spikes included.  Short series come back as they are.

    Returns:
        ``(t_cut, y1_cut, y2_cut, ...)``.
    """
    K = t.shape[0]
    if 4 * pixels >= K:
        return (t, *ys)
    per = K // pixels
    m = per * pixels
    tt = t[:m].reshape(pixels, per)
    t_out = np.repeat(tt[:, [0, -1]].mean(axis=1), 2)
    out: list[FloatArray] = [t_out]
    for y in ys:
        yy = y[:m].reshape(pixels, per)
        with np.errstate(invalid="ignore"):
            lo = np.nanmin(np.where(np.isfinite(yy), yy, np.inf), axis=1)
            hi = np.nanmax(np.where(np.isfinite(yy), yy, -np.inf), axis=1)
        lo[~np.isfinite(lo)] = np.nan
        hi[~np.isfinite(hi)] = np.nan
        out.append(np.column_stack([lo, hi]).ravel())
    return tuple(out)


def _columns(fig: Any) -> int:
    spec = fig.axes[0].get_subplotspec() if fig.axes else None
    return int(spec.get_gridspec().ncols) if spec is not None else 1


def _rows(fig: Any) -> int:
    spec = fig.axes[0].get_subplotspec() if fig.axes else None
    return int(spec.get_gridspec().nrows) if spec is not None else 1


def title(fig: Any, text: str, size: float = 9) -> None:
    """The figure's title, wrapped to its width (a long title is cut by the PNG's edge)."""
    import textwrap

    width = max(40, int(fig.get_figwidth() * 130 / size))
    fig.suptitle(textwrap.fill(text, width), fontsize=size)


def save(fig: Any, path: Path, paths: list[Path] | None = None) -> Path:
    """Lay out ``fig`` with fixed margins [in] (``tight_layout`` draws the figure once more
    to measure it: a third of the time of a 7-joint figure), write it as a PNG at
    :data:`DPI`, close it; ``paths`` gets it."""
    plt = pyplot()
    w, h = fig.get_size_inches()
    head = 0.3 + 0.17 * (fig._suptitle.get_text().count("\n") if fig._suptitle else 0)
    fig.subplots_adjust(
        left=0.62 / w,
        right=1 - 0.15 / w,
        bottom=0.45 / h,
        top=1 - (head + 0.15) / h,
        wspace=0.75 / (w / max(1, _columns(fig))),
        hspace=0.5 / (h / max(1, _rows(fig))),
    )
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    if paths is not None:
        paths.append(path)
    return path
