"""Tables and figures of a sweep's results: one metric over one or two axes, per estimator
or controller, mean and spread over seeds.

* :func:`aggregate`: mean, standard deviation, min, max over seeds of ``metric`` per axis
  point and label (the estimator, the controller, or both when both vary), and how many runs
  diverged or failed (their metrics are left out of the statistics: a run that stopped
  early or raised has no comparable value).
* :func:`format_report`: that as a markdown table (``amsfe sweep --report``).
* :func:`plot_lines` (one axis: mean with a band of +- one standard deviation and the
  seeds' min-max as a thin line) and :func:`plot_heatmaps` (two axes: the mean, one panel
  per label).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from amsfe_sym.errors import ConfigError, describe

__all__ = [
    "aggregate",
    "format_report",
    "label_columns",
    "plot_heatmaps",
    "plot_lines",
    "write_figures",
]

_LABELS = ("estimator", "controller")
_NON_AXES = {"run_id", "seed", "status", "error", *_LABELS}


def label_columns(table: pd.DataFrame) -> list[str]:
    """The label columns that vary in ``table`` (estimator, controller; at least one)."""
    varying = [c for c in _LABELS if c in table and table[c].nunique() > 1]
    return varying or ["estimator"]


def _check(table: pd.DataFrame, metric: str, axes: Sequence[str]) -> None:
    metrics = sorted(
        c for c in table.columns if c not in _NON_AXES and pd.api.types.is_numeric_dtype(table[c])
    )
    if metric not in table.columns:
        raise ConfigError(
            describe(
                "--metric",
                "a metric column of the table",
                repr(metric),
                "use one of " + ", ".join(m for m in metrics if not m.startswith("counters")),
            )
        )
    for a in axes:
        if a not in table.columns:
            raise ConfigError(
                describe("axis", "a column of the table", repr(a), "name an axis of the sweep")
            )


def aggregate(table: pd.DataFrame, metric: str, axes: Sequence[str]) -> pd.DataFrame:
    """Seed statistics of ``metric`` per point of ``axes`` and label.

    Returns:
        One row per (axes, labels): ``mean``, ``std`` (sample, ddof = 1; 0 for one seed),
        ``min``, ``max`` over the ``ok`` runs, ``runs`` (ok), ``diverged`` and ``errors``.

    Raises:
        ConfigError: a metric or axis the table does not have.
    """
    axes = list(axes)
    _check(table, metric, axes)
    keys = [*axes, *label_columns(table)]
    ok = table[table.status == "ok"]
    g = ok.groupby(keys, sort=True)[metric]
    stats = pd.DataFrame(
        {
            "mean": g.mean(),
            "std": g.std(ddof=1).fillna(0.0),
            "min": g.min(),
            "max": g.max(),
            "runs": g.count(),
        }
    )
    status = table.groupby(keys, sort=True)["status"]
    stats = stats.reindex(status.size().index)
    stats["runs"] = stats["runs"].fillna(0).astype(int)
    stats["diverged"] = status.apply(lambda s: int((s == "diverged").sum()))
    stats["errors"] = status.apply(lambda s: int((s == "error").sum()))
    return stats.reset_index()


def _fmt(v: float) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    return f"{v:.4g}"


def format_report(table: pd.DataFrame, metric: str, axes: Sequence[str]) -> str:
    """Markdown table of :func:`aggregate`: one line per point and label, ``mean ± std``
    over the seeds, min-max, and the counts of ok, diverged and failed runs."""
    agg = aggregate(table, metric, axes)
    keys = [*axes, *label_columns(table)]
    head = [*keys, f"{metric} mean ± std", "min .. max", "ok", "diverged", "errors"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for _, r in agg.iterrows():
        cells = [str(r[k]) for k in keys]
        cells += [
            f"{_fmt(r['mean'])} ± {_fmt(r['std'])}",
            f"{_fmt(r['min'])} .. {_fmt(r['max'])}",
            str(r["runs"]),
            str(r["diverged"]),
            str(r["errors"]),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _label(row: pd.Series, labels: Sequence[str]) -> str:
    return " / ".join(str(row[c]) for c in labels)


def _safe(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in name)


def _save(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_lines(
    table: pd.DataFrame, metric: str, x: str, out: str | os.PathLike[str], title: str = ""
) -> Path:
    """``metric`` against axis ``x``, one line per label: the seeds' mean, a band of +- one
    standard deviation, and their min and max as thin dotted lines.  Returns the PNG path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    agg = aggregate(table, metric, [x])
    labels = label_columns(table)
    agg["label"] = agg.apply(lambda r: _label(r, labels), axis=1)
    fig, ax = plt.subplots(figsize=(7.0, 4.2))
    for name, g in agg.groupby("label", sort=False):
        g = g.sort_values(x)
        xs = g[x].to_numpy(dtype=float)
        (line,) = ax.plot(xs, g["mean"], marker="o", ms=3, label=str(name))
        c = line.get_color()
        ax.fill_between(xs, g["mean"] - g["std"], g["mean"] + g["std"], color=c, alpha=0.2)
        ax.plot(xs, g["min"], color=c, lw=0.6, ls=":")
        ax.plot(xs, g["max"], color=c, lw=0.6, ls=":")
    ax.set_xlabel(x)
    ax.set_ylabel(metric)
    if (agg["mean"].dropna() > 0).all() and len(agg["mean"].dropna()):
        hi, lo = agg["max"].max(), agg["min"].min()
        if lo > 0 and hi / lo > 30:
            ax.set_yscale("log")
    runs = int(table.seed.nunique())
    ax.set_title(title or f"{metric} (mean ± std over {runs} seeds; dotted: min, max)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, Path(out) / f"{_safe(metric)}-vs-{_safe(x)}.png")


def plot_heatmaps(
    table: pd.DataFrame, metric: str, x: str, y: str, out: str | os.PathLike[str]
) -> Path:
    """The seeds' mean of ``metric`` over axes ``x`` and ``y``, one panel per label (cells
    with no ok run are blank; each cell is annotated with the mean and the std)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    agg = aggregate(table, metric, [x, y])
    labels = label_columns(table)
    agg["label"] = agg.apply(lambda r: _label(r, labels), axis=1)
    names = list(dict.fromkeys(agg["label"]))
    xs, ys = sorted(agg[x].unique()), sorted(agg[y].unique())
    vmin, vmax = float(np.nanmin(agg["mean"])), float(np.nanmax(agg["mean"]))
    fig, axes = plt.subplots(
        1, len(names), figsize=(3.6 * len(names) + 1, 3.6), squeeze=False, sharey=True
    )
    im = None
    for ax, name in zip(axes[0], names, strict=True):
        g = agg[agg["label"] == name]
        grid = np.full((len(ys), len(xs)), np.nan)
        spread = np.full_like(grid, np.nan)
        for _, r in g.iterrows():
            grid[ys.index(r[y]), xs.index(r[x])] = r["mean"]
            spread[ys.index(r[y]), xs.index(r[x])] = r["std"]
        im = ax.imshow(grid, origin="lower", aspect="auto", vmin=vmin, vmax=vmax)
        for i in range(len(ys)):
            for j in range(len(xs)):
                if not np.isnan(grid[i, j]):
                    ax.text(
                        j,
                        i,
                        f"{grid[i, j]:.3g}\n±{spread[i, j]:.2g}",
                        ha="center",
                        va="center",
                        fontsize=6,
                        color="w",
                    )
        ax.set_xticks(range(len(xs)), [str(v) for v in xs], rotation=45, fontsize=7)
        ax.set_yticks(range(len(ys)), [str(v) for v in ys], fontsize=7)
        ax.set_xlabel(x)
        ax.set_title(str(name), fontsize=9)
    axes[0][0].set_ylabel(y)
    if im is not None:
        fig.colorbar(im, ax=axes[0].tolist(), label=f"{metric} (seed mean)")
    return _save(fig, Path(out) / f"{_safe(metric)}-{_safe(x)}-{_safe(y)}.png")


def write_figures(
    table: pd.DataFrame, metric: str, x: str, y: str, out: str | os.PathLike[str]
) -> list[Path]:
    """The figures of ``metric``: a heatmap per label over ``x`` and ``y`` when both are
    given, and the line plot over ``x`` (over ``y`` too when there is one)."""
    paths = []
    if x and y:
        paths.append(plot_heatmaps(table, metric, x, y, out))
    for axis in (x, y):
        if axis:
            paths.append(plot_lines(table, metric, axis, out))
    return paths
