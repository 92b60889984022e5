"""The figure of an estimate over a recorded log (``amsfe estimate``): ``estimate.png``
(docs/how-to/logs.md, "Consistency without truth").

``estimate.png`` has one panel per joint.  A log with the truth (a simulated one) shows the
link-angle error with the filter's +-2 sigma band.  Any other log shows what can be judged
without the truth: the spring deflection the estimator infers (q_hat - qm, the encoder's
motor angle) and the encoder residual (qm - qm_hat), each with the 2-sigma band of the
estimate.  Every axis is set by the converged part (the last 80 %), so the start transient
does not hide the band.  Its bottom row shows the encoder and camera NIS over time with
their chi-square 95 % bands, a panel per channel (one figure, laid out and written once).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym.apps.plots.style import (
    MAX_COLUMNS,
    PIXELS,
    collect_once,
    converged_limit,
    envelope,
    grid_cell,
    joint_grid,
    logscale,
    save,
    title,
)
from amsfe_sym.arrays import FloatArray
from amsfe_sym.logs.read import RobotLog

__all__ = ["RUG_MAX", "NisSeries", "plot_log"]


#: Camera frames marked by a tick at the bottom of each panel up to this many (more make a
#: solid bar: the title gives their count and mean period instead).
RUG_MAX = 200


@dataclass(frozen=True)
class NisSeries:
    """What the NIS row of ``estimate.png`` draws.

    Attributes:
        report: Per channel (``encoders``, ``camera``): ``dof`` and ``band_95``
            (:func:`~amsfe_sym.apps.estimate_report.nis_report`); empty: no NIS row.
        encoder: The encoder NIS per tick, (K,), or None.
        frames: (arrival step, NIS) of each frame, or None.
    """

    report: Mapping[str, Mapping[str, Any]]
    encoder: FloatArray | None = None
    frames: tuple[FloatArray, FloatArray] | None = None


@collect_once
def plot_log(
    log: RobotLog,
    x_hat: FloatArray,
    P_diag: FloatArray,
    estimator: str,
    nis: NisSeries,
    folder: Path,
) -> list[Path]:
    """Write ``estimate.png`` of an estimate over ``log``: a panel per joint, and a row of
    NIS panels below them.

    Args:
        log: The read log (its grid, encoder samples, frames, truth).
        x_hat: x(k|k) per tick (eq. 2), (K, N).
        P_diag: diag P(k|k), (K, N).
        estimator: The estimator's name (for the titles).
        nis: The NIS to draw (an empty report: no NIS row).
        folder: Where the PNG goes.

    Returns:
        The path written, in a list.
    """
    n = log.u.shape[1]
    t = log.t
    sd = np.sqrt(np.maximum(P_diag, 0.0))
    arrivals = np.array([fr.delivery_step * log.T for fr in log.frames], dtype=float)
    rug = _rug(arrivals) if 0 < arrivals.size <= RUG_MAX else None
    cols = min(n, MAX_COLUMNS)
    channels = len(nis.report)
    nis_rows = 0 if not channels else 1 if channels <= cols else channels
    fig, cells = joint_grid(n, (3.8, 2.3), extra_rows=nis_rows)
    for j, (ax,) in enumerate(cells):
        band = 2 * sd[:, j]
        if log.truth is not None:
            err = log.truth[:, j] - x_hat[:, j]
            tc, lo, hi, e = envelope(t, -band, band, err)
            ax.fill_between(tc, lo, hi, color="0.85", lw=0, label="±2σ of the filter")
            ax.plot(tc, e, lw=0.7, label="true − estimated link angle", rasterized=True)
            lim = converged_limit(err, band)
            ax.set_ylabel(f"q{j + 1} error [rad]", fontsize=8)
        else:
            deflection = x_hat[:, j] - log.z[:, j]
            residual = log.z[:, j] - x_hat[:, 2 * n + j]
            tc, lo, hi, d, r = envelope(
                t, deflection - band, deflection + band, deflection, residual
            )
            ax.fill_between(tc, lo, hi, color="0.85", lw=0, label="±2σ of the link angle")
            ax.plot(tc, d, lw=0.8, label="spring deflection q̂ − qm (encoder)", rasterized=True)
            ax.plot(tc, r, lw=0.6, label="encoder residual qm − q̂m", rasterized=True)
            center = float(np.nanmedian(deflection[len(t) // 5 :])) if len(t) else 0.0
            lim = converged_limit(
                np.column_stack([deflection - center, residual]), band[:, None]
            ) + abs(center)
            ax.set_ylabel(f"joint {j + 1} [rad]", fontsize=8)
        ax.set_ylim(-lim, lim)
        if rug is not None:  # one line (an axvline each: 12 of 15 s; vlines: 10 %)
            ax.plot(*rug, transform=ax.get_xaxis_transform(), color="k", lw=0.3, alpha=0.5)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    cells[0][0].legend(loc="upper right", fontsize=6)
    if channels:
        _nis_row(fig, log, nis, cells[0][0], nis_rows)
    if arrivals.size > RUG_MAX:
        every = float(np.ptp(arrivals)) / (arrivals.size - 1)
        frames = f"{arrivals.size} camera frames, one every {every:.3g} s"
    else:
        frames = "ticks at the bottom: camera frames' arrivals"
    nis_line = "; below: NIS with its chi² 95 % band" if channels else ""
    title(fig, f"{estimator} on {log.path.name}; axes set by the last 80 %; {frames}{nis_line}")
    return [save(fig, folder / "estimate.png")]


def _rug(at: FloatArray, height: float = 0.04) -> tuple[FloatArray, FloatArray]:
    """A tick at each of ``at`` [s], from 0 to ``height`` of the axes, as one line (x, y)
    broken by NaN between ticks: the picture of ``vlines``, whose collection converts its
    segments one by one in Python (10 % of the figures of a 5 s log's estimate, 7 panels
    of ~150 frames), made with three numpy operations."""
    x = np.repeat(at, 3)
    x[2::3] = np.nan
    y = np.tile([0.0, height, np.nan], at.size)
    return x, y


def _nis_row(fig: Any, log: RobotLog, nis: NisSeries, time_axes: Any, rows: int) -> None:
    """The NIS of the encoder updates and of the camera frames over time, with their
    chi-square 95 % bands, in the last ``rows`` rows of ``fig``'s grid: the channels side
    by side over the columns in one row, or one a row (``rows`` = the channels, when there
    are more than columns); nothing drawn where no NIS was recorded.  ``time_axes``: the
    joint axes whose time axis they share."""
    grid = fig.axes[0].get_subplotspec().get_gridspec()
    cols, channels = grid.ncols, len(nis.report)
    side, row = rows == 1, grid.nrows - rows
    for i, (what, r) in enumerate(nis.report.items()):
        span = cols // channels if side else cols
        start = i * span if side else 0
        stop = cols if not side or i == channels - 1 else start + span
        ax = grid_cell(fig, row if side else row + i, slice(start, stop), sharex=time_axes)
        if what == "encoders" and nis.encoder is not None:
            t, v = log.t, np.asarray(nis.encoder, dtype=np.float64)
            w = max(1, len(v) // 100)  # its running mean over 1 % of the log
            ok = np.isfinite(v)
            mean = np.convolve(np.where(ok, v, 0), np.ones(w), "same") / np.maximum(
                np.convolve(ok, np.ones(w), "same"), 1
            )
            tc, vc, mc = envelope(t, v, mean, pixels=PIXELS * (stop - start))
            ax.plot(tc, vc, lw=0.3, alpha=0.5, label="encoder update", rasterized=True)
            ax.plot(tc, mc, lw=1.0, color="k", label=f"running mean ({w} ticks)")
        elif nis.frames is not None:
            arrival, v = nis.frames
            ax.plot(arrival * log.T, v, ".", ms=3, label="camera frame (at its arrival)")
        lo, hi = r["band_95"]
        ax.axhspan(lo, hi, color="g", alpha=0.12, label=f"chi²({r['dof']}) 95 % band")
        ax.axhline(r["dof"], color="g", lw=0.6)
        logscale(ax)
        ax.set_ylabel(f"NIS {what}", fontsize=8)
        ax.set_xlabel("t [s]", fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right", fontsize=6, framealpha=0.6)
