"""What every figure shares: an Agg canvas, one panel per joint in a grid of sane size,
long lines cut to the pixels they are drawn on, axis limits set by the converged part of a
run, and the files written.

Drawing costs: matplotlib's time grows with the points it is given, not with the pixels it
fills.  A 60 s log at 1 kHz is 60 000 points a line in a panel ~800 px wide: :func:`envelope`
keeps each pixel column's smallest and largest value (the picture is the same, spikes
included).  Past the points, a panel costs its ticks and texts: each tick is three lines
and two texts, made and laid out at every draw, and a log-scale label is TeX-like math.
So a figure is a bare :class:`matplotlib.figure.Figure` on an Agg canvas (no ``pyplot``,
whose import alone costs a third of a 7-joint figure), the panels of a grid share their
time axis (its labels drawn once a column), a symlog axis has plain labels and no minor
ticks (:func:`symlog`), and the margins are fixed (no ``tight_layout``, which draws the
figure once more to measure it).  Ticks are made only where they are seen (matplotlib
makes one for every location a locator gives, in view or not), a grid's axis labels are
placed once (not from the tick labels' boxes at every draw), a figure of the same shape
is drawn again on the axes of the one before (:class:`Canvas`), and a command's figures are
drawn with the cyclic garbage collector paused (:func:`collect_once`).
"""

from __future__ import annotations

import functools
import gc
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "DPI",
    "LABEL_OFFSET",
    "LOG_SUBS_UP_TO",
    "MAX_COLUMNS",
    "PANEL",
    "PIXELS",
    "PNG_COMPRESSION",
    "Canvas",
    "collect_once",
    "converged_limit",
    "envelope",
    "few_ticks",
    "figure",
    "grid_cell",
    "import_matplotlib",
    "joint_grid",
    "logscale",
    "pyplot",
    "save",
    "symlog",
    "title",
    "window_start",
]

FloatArray = NDArray[np.float64]
F = TypeVar("F", bound=Callable[..., Any])

#: Resolution of every PNG [dots per inch].
DPI = 100
#: zlib level of the PNGs (1: a third less time to write than PIL's default 6, for files
#: 14-18 % larger; the pixels are the same).
PNG_COMPRESSION = 1
#: A log axis spanning at most this many decades is labelled at 1, 2 and 5 times each
#: (:func:`logscale`); a wider one at its decades.
LOG_SUBS_UP_TO = 2
#: Width and height [in] of a joint's panel of one axes (every such grid of a command has
#: this size, so :class:`Canvas` draws them all on one figure).
PANEL = (3.8, 2.2)
#: Joint panels per row of a grid (a 7-joint arm: 4 + 3).
MAX_COLUMNS = 4
#: Columns of pixels a line is cut to by :func:`envelope`: a joint's panel is 3.8-4 in wide
#: at :data:`DPI` (wider figures pass their own).
PIXELS = 500


def collect_once(draw: F) -> F:
    """``draw`` with Python's cyclic garbage collector paused while it runs, and one
    collection after it of what it made (figures, axes and artists hold reference cycles,
    so they go then).

    Drawing a command's figures makes ~10^5 small objects (matplotlib's import, each axes'
    ticks, texts and transforms); every 700 of them started a collection, every tenth of
    those scanned the older objects too (the command's own), and the collector took ~10 %
    of the figures' CPU time (``gc.callbacks`` around ``amsfe estimate``'s figures: 0.11 of
    1.05 s).  Paused, what the figures make is freed by reference counting as it always is.
    The objects that live on (the command's, matplotlib's modules, imported first) are
    frozen (``gc.freeze``) for the one collection at the end, which then scans only what
    the figures made: 0.01-0.02 s, counted in the figures' time.  A caller that disabled
    the collector or froze objects itself gets ``draw`` as it is.
    """

    @functools.wraps(draw)
    def run(*args: Any, **kwargs: Any) -> Any:
        if not gc.isenabled() or gc.get_freeze_count():  # the caller's choice: leave it
            return draw(*args, **kwargs)
        gc.disable()
        try:
            import_matplotlib()  # what lives on: frozen below

            gc.freeze()
            try:
                return draw(*args, **kwargs)
            finally:
                gc.collect(1)  # what the figures made: nothing frozen is scanned
                gc.unfreeze()
        finally:
            gc.enable()

    return run  # type: ignore[return-value]


def import_matplotlib() -> None:
    """Import what the figures use of matplotlib: its figure and Agg canvas (no ``pyplot``).

    (Skipping the help text matplotlib writes at import for each artist class's ``set``
    would save a third of this import, 0.95 -> 0.62 s of CPU at load 10, but only by
    replacing one of matplotlib's methods while it imports: a user's ``help()`` on those
    classes would lose their text, and a toolkit does not change a library it shares with
    its user's code.)"""
    import matplotlib.backends.backend_agg
    import matplotlib.figure  # noqa: F401


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend (no display; imported on first use)."""
    import matplotlib

    matplotlib.use("Agg")
    import_matplotlib()
    import matplotlib.pyplot as plt

    return plt


def figure(size: tuple[float, float]) -> Any:
    """A figure of ``size`` [in] on its own Agg canvas (no ``pyplot``: nothing to close,
    nothing kept once it is written)."""
    import_matplotlib()
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size)
    FigureCanvasAgg(fig)
    return fig


def symlog(ax: Any, linthresh: float) -> None:
    """A symmetric log y axis, linear within ``linthresh``, with plain labels at whole
    decades ("1e-3", not matplotlib's TeX math, which is parsed for each label) and no
    minor ticks (matplotlib's default puts eight a decade, each a tick to make)."""
    from matplotlib.ticker import FuncFormatter, NullLocator, SymmetricalLogLocator

    ax.set_yscale("symlog", linthresh=linthresh)
    seen = _in_view(SymmetricalLogLocator)
    ax.yaxis.set_major_locator(seen(linthresh=linthresh, base=10, subs=[1.0]))
    ax.yaxis.set_minor_locator(NullLocator())
    ax.yaxis.set_major_formatter(FuncFormatter(_decade))


def logscale(ax: Any) -> None:
    """A log y axis with plain labels ("0.002", not TeX math) and no minor ticks: at 1, 2
    and 5 times a decade when the data span at most :data:`LOG_SUBS_UP_TO` decades, at
    whole decades (every second one past 7) otherwise.  Call it once the data are drawn
    (their span picks the ticks)."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullLocator

    ax.set_yscale("log")
    lo, hi = sorted(ax.get_ylim())
    few = lo > 0 and math.log10(hi / lo) <= LOG_SUBS_UP_TO
    subs = (1.0, 2.0, 5.0) if few else (1.0,)
    ax.yaxis.set_major_locator(_in_view(LogLocator)(base=10, subs=subs, numticks=7))
    ax.yaxis.set_minor_locator(NullLocator())
    ax.yaxis.set_major_formatter(FuncFormatter(_decade))


def _decade(v: float, _pos: int | None = None) -> str:
    """A log or symlog tick's label, short enough for the fixed margin: 0.01 to 1000 as
    written (0.05, 20), else +-MeK (1e-3)."""
    if v == 0 or 1e-2 <= abs(v) < 1e4:
        return f"{v:g}"
    return f"{v:.0e}".replace("e-0", "e-").replace("e+0", "e")


def joint_grid(
    n: int,
    panel: tuple[float, float] = (4.0, 2.6),
    rows_per_joint: int = 1,
    sharex: bool = True,
    extra_rows: int = 0,
) -> tuple[Any, list[list[Any]]]:
    """A figure with one panel per joint, ``min(n, 4)`` panels a row; each panel is
    ``rows_per_joint`` axes stacked (sharing x).

    Args:
        n: Joints.
        panel: Width and height of one joint's panel [in].
        rows_per_joint: Axes stacked in a panel (e.g. 2: q error above, qd error below).
        sharex: Every axes shares one time axis, labelled ("t [s]") on the lowest axes of
            each column only; False: each axes its own, all labelled by the caller.
        extra_rows: Rows of the grid below the joints, ``panel[1]`` high each, left empty
            for the caller (``grid_cell``; e.g. ``estimate.png``'s NIS).

    Returns:
        The figure and, per joint, its list of axes (top to bottom); panels past ``n`` in
        the last row are hidden.
    """
    cols = min(n, MAX_COLUMNS)
    rows = math.ceil(n / cols)
    fig = figure((panel[0] * cols, panel[1] * (rows * rows_per_joint + extra_rows) + 0.7))
    grid = fig.add_gridspec(rows * rows_per_joint + extra_rows, cols)
    cells: list[list[Any]] = []
    first: Any = None
    for j in range(n):
        r, c = divmod(j, cols)
        axes: list[Any] = []
        for i in range(rows_per_joint):
            ax = fig.add_subplot(grid[r * rows_per_joint + i, c], sharex=first)
            first = first if first is not None or not sharex else ax
            few_ticks(ax)
            ax.tick_params(labelsize=7)
            _place_labels(ax)
            axes.append(ax)
        if sharex:  # the time labels once a column, on its lowest axes
            last_row = j + cols >= n
            for i, ax in enumerate(axes):
                if last_row and i == len(axes) - 1:
                    ax.set_xlabel("t [s]", fontsize=8)
                else:
                    ax.tick_params(labelbottom=False)
        cells.append(axes)
    return fig, cells


def grid_cell(fig: Any, row: int, columns: slice, sharex: Any = None) -> Any:
    """New axes in ``row`` (counted from the grid's top) over ``columns`` of the grid of
    :func:`joint_grid`'s figure ``fig`` (e.g. a row of ``extra_rows``), with the grid's few
    ticks, 7-pt labels and fixed label places; ``sharex``: axes whose time axis it shares."""
    grid = fig.axes[0].get_subplotspec().get_gridspec()
    ax = fig.add_subplot(grid[row, columns], sharex=sharex)
    few_ticks(ax)
    ax.tick_params(labelsize=7)
    _place_labels(ax)
    return ax


#: Where a grid's axis labels stand [in]: the y label's edge left of the axes (the widest
#: 7-pt tick label, "-1e-3", its tick and pads: 0.45 in), the x label's top below them.
LABEL_OFFSET = (0.48, 0.26)


def _place_labels(ax: Any) -> None:
    """The y label at :data:`LABEL_OFFSET` left of ``ax``, the x label below it, once.
    Matplotlib otherwise places each at every draw from the bounding boxes of the axis's
    tick labels, laying out its ticks a second time to get them: the fonts (7 pt) and
    margins of a grid are fixed, so the place is known (and the labels of a row line up)."""
    from matplotlib.transforms import ScaledTranslation

    inches = ax.get_figure().dpi_scale_trans
    dx, dy = LABEL_OFFSET
    ax.yaxis.set_label_coords(0.0, 0.5, ax.transAxes + ScaledTranslation(-dx, 0.0, inches))
    ax.xaxis.set_label_coords(0.5, 0.0, ax.transAxes + ScaledTranslation(0.0, -dy, inches))


def few_ticks(ax: Any) -> None:
    """At most 4 ticks on the time axis and 5 on the y axis, all in view (each is lines
    and texts to make and draw), and a y axis whose small numbers are written once above
    it (1e-4, at 7 pt)."""
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(_in_view(MaxNLocator)(3))
    ax.yaxis.set_major_locator(_in_view(MaxNLocator)(4))
    ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))
    ax.yaxis.get_offset_text().set_fontsize(7)


@functools.cache
def _in_view(locator: type) -> type:
    """``locator`` (a matplotlib tick locator class) giving only the locations inside the
    axis's view.  Matplotlib makes a tick (three lines and two texts) for every location a
    locator gives, and most locators give one or two outside the view on each side, which
    are made and never drawn: a third of a panel's ticks."""

    class InView(locator):
        def __call__(self) -> Any:
            locs = np.asarray(super().__call__(), dtype=float)
            lo, hi = sorted(self.axis.get_view_interval())
            pad = 1e-9 * (hi - lo)
            return locs[(locs >= lo - pad) & (locs <= hi + pad)]

    InView.__name__ = InView.__qualname__ = f"InView{locator.__name__}"
    return InView


class Canvas:
    """The joint grids of one command (and its figures of stacked axes,
    :meth:`stack`), drawn one after another on one figure.

    A grid's axes and their ticks cost more than what is drawn in them (a 7-joint grid: 7
    axes and ~100 ticks to make).  :meth:`joint_grid` hands back the previous grid, emptied
    (its lines, bands, legends, labels, scales and limits reset), when the shape is the
    same, and a new one otherwise: the second and later figures of a run cost a third less.
    Write each figure (:func:`save`) before asking for the next.
    """

    def __init__(self) -> None:
        self._key: tuple[Any, ...] | None = None
        self._grid: tuple[Any, list[list[Any]]] | None = None

    def joint_grid(
        self,
        n: int,
        panel: tuple[float, float] = (4.0, 2.6),
        rows_per_joint: int = 1,
        sharex: bool = True,
    ) -> tuple[Any, list[list[Any]]]:
        """:func:`joint_grid`'s figure and axes, the previous ones emptied if the same."""
        key = (n, panel, rows_per_joint, sharex)
        if self._grid is None or key != self._key:
            self._key, self._grid = key, joint_grid(n, panel, rows_per_joint, sharex)
            return self._grid
        fig, cells = self._grid
        for ax in (ax for axes in cells for ax in axes):
            _empty(ax)
        return fig, cells

    def stack(self, size: tuple[float, float], rows: int) -> tuple[Any, list[Any]]:
        """A figure of ``size`` [in] with ``rows`` axes stacked, sharing their time axis
        (few ticks, :func:`few_ticks`), or the previous such figure emptied if the same
        (the paper's Figs. 6 and 7: one figure drawn twice)."""
        key = ("stack", size, rows)
        if self._grid is None or key != self._key:
            fig = figure(size)
            axes = list(fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0])
            for ax in axes:
                few_ticks(ax)
            self._key, self._grid = key, (fig, [axes])
            return fig, axes
        fig, (axes,) = self._grid
        for ax in axes:
            _empty(ax)
        return fig, axes


def _empty(ax: Any) -> None:
    """``ax`` as :func:`joint_grid` made it, keeping its ticks: no artists, no legend, no
    y label or title, the colours from the first, a linear y axis with few ticks, limits
    from the data again."""
    for artist in [*ax.lines, *ax.collections, *ax.patches, *ax.texts, *ax.images]:
        artist.remove()
    if ax.get_legend() is not None:
        ax.get_legend().remove()
    ax.set_prop_cycle(None)  # the first line is blue again
    ax.set_ylabel("")
    ax.set_title("")
    if ax.get_yscale() != "linear":
        ax.set_yscale("linear")
    few_ticks(ax)
    ax.relim()
    ax.set_autoscale_on(True)
    ax.autoscale_view()


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
    starts = (np.arange(pixels) * K) // pixels  # every sample in one column, the last too
    ends = np.append(starts[1:], K) - 1
    t_out = np.repeat(0.5 * (t[starts] + t[ends]), 2)
    out: list[FloatArray] = [t_out]
    for y in ys:
        finite = np.isfinite(y)
        lo = np.minimum.reduceat(np.where(finite, y, np.inf), starts)
        hi = np.maximum.reduceat(np.where(finite, y, -np.inf), starts)
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
    :data:`DPI` and zlib level :data:`PNG_COMPRESSION`; ``paths`` gets it."""
    w, h = fig.get_size_inches()
    head = 0.3 + 0.17 * (fig._suptitle.get_text().count("\n") if fig._suptitle else 0)
    left, right, gap = 0.62, 0.15, LABEL_OFFSET[0] + 0.3  # gap: a y label and room
    cols = max(1, _columns(fig))
    width = (w - left - right - gap * (cols - 1)) / cols  # of one axes
    fig.subplots_adjust(
        left=left / w,
        right=1 - right / w,
        bottom=0.45 / h,
        top=1 - (head + 0.15) / h,
        wspace=gap / width,
        hspace=0.5 / (h / max(1, _rows(fig))),
    )
    fig.savefig(path, dpi=DPI, pil_kwargs={"compress_level": PNG_COMPRESSION})
    if getattr(fig.canvas, "manager", None) is not None:  # a pyplot figure: let it go
        pyplot().close(fig)
    if paths is not None:
        paths.append(path)
    return path
