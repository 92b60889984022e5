"""Figures of a run and of a study (matplotlib, Agg backend; written as PNG next to the data).

A run (:func:`plot_run`):

- ``estimation_errors.png``: q and qd estimation errors of every joint (the paper's Fig. 4)
  with the filter's +-2 sigma band;
- ``theta.png``: theta estimate vs truth with +-2 sigma (Fig. 5);
- ``tracking.png``: link angle vs desired for every joint (Figs. 6-7).

A study variant (:func:`plot_study`): ``errors.png``, ``theta.png``, ``nees.png`` (see
:mod:`amsfe_sym.apps.study`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from amsfe_sym.apps.plots.style import (
    PANEL,
    Canvas,
    collect_once,
    converged_limit,
    envelope,
    figure,
    save,
    title,
)
from amsfe_sym.sim.record import nees_band, window

if TYPE_CHECKING:
    from amsfe_sym.runtime.library import ModelLibrary
    from amsfe_sym.scenario import Scenario
    from amsfe_sym.sim.result import RunResult

__all__ = [
    "RATE_PANELS_UP_TO",
    "controller_label",
    "error_rows",
    "estimation_error_axes",
    "plot_run",
    "plot_study",
]

#: What each controller's law acts on, for a legend (``{est}``: the run's estimator).
_LAWS = {
    "amsfe": "amsfe law on the {est} estimate",
    "amsfe-paper": "amsfe-paper law (37) on the {est} estimate",
    "dtsmc": "dtsmc law (54) on the motor encoders",
    "dtsmc-ekf": "dtsmc law (54) on the {est} estimate",
    "dtsmc-paper": "dtsmc-paper law (54) on the motor encoders",
    "truth": "amsfe law on the true state (oracle)",
    "truth-ct": "computed torque on the true state (oracle)",
}


def controller_label(res: RunResult, name: str | None = None) -> str:
    """What a run's controller is, for a legend: its law and what the law acts on (``truth``
    is the amsfe law on the true state, not the truth), and where the run diverged."""
    sc = res.scenario
    name = name or sc.controller
    text = _LAWS.get(name, f"{name} law").format(est=sc.estimator)
    if sc.gains_for(name).get("state") == "true":
        text = text.replace(f"the {sc.estimator} estimate", "the true state (oracle)")
    if res.diverged_at is not None:
        text += f", diverged at {res.diverged_at:.2f} s"
    return text


#: Arms with more joints than this get the link-angle errors alone in the estimation-error
#: figures (the paper's two-joint figures have q and qd): half the panels to draw.
RATE_PANELS_UP_TO = 2


def error_rows(n: int) -> int:
    """Axes a joint's panel of estimation errors has: q and qd up to
    :data:`RATE_PANELS_UP_TO` joints, q alone above."""
    return 2 if n <= RATE_PANELS_UP_TO else 1


def estimation_error_axes(res: RunResult, cells: list[list[Any]]) -> None:
    """Fill one panel per joint (``cells[j]`` = [q axes] or [q axes, qd axes],
    :func:`joint_grid` with :func:`error_rows` rows a joint) with the q (and qd) estimation
    errors and the filter's +-2 sigma band (the paper's Fig. 4 / 13).  Each axis is set by
    the converged part (the last 80 %): the start transient is clipped, the band is
    visible."""
    t, L = res.t, res.lib.layout
    e = res.x_true - res.x_hat
    sd = np.sqrt(np.maximum(res.P_diag, 0.0))
    for j, axes in enumerate(cells):
        for ax, (block, unit) in zip(axes, (("q", "rad"), ("qd", "rad/s")), strict=False):
            c = L[block].start + j
            tc, lo, hi, err = envelope(t, -2 * sd[:, c], 2 * sd[:, c], e[:, c])
            ax.fill_between(tc, lo, hi, color="0.85", lw=0, label="±2σ of the filter")
            ax.plot(tc, err, lw=0.7, label="true − estimate", rasterized=True)
            lim = converged_limit(e[:, c], 2 * sd[:, c])
            ax.set_ylim(-lim, lim)
            ax.set_ylabel(f"{block}{j + 1} error [{unit}]", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
    cells[0][0].legend(loc="upper right", fontsize=7)


@collect_once
def plot_run(res: RunResult, out: Path) -> list[Path]:
    """Write the run's figures to ``out``; returns their paths."""
    lib, t = res.lib, res.t
    n, L = lib.n, lib.layout
    sd = np.sqrt(np.maximum(res.P_diag, 0.0))
    paths: list[Path] = []
    sc = res.scenario
    what = f"{sc.name}: estimator {sc.estimator}, {controller_label(res)}, seed {sc.seed}"

    canvas = Canvas()
    rows = error_rows(n)
    fig, cells = canvas.joint_grid(n, PANEL if rows == 1 else (3.8, 1.9), rows_per_joint=rows)
    estimation_error_axes(res, cells)
    which = "q and qd" if error_rows(n) == 2 else "link angles q"
    title(fig, f"Estimation errors of {which} (paper Fig. 4), axes set by the last 80 % — {what}")
    save(fig, out / "estimation_errors.png", paths)

    if lib.p:
        cols = min(lib.p, 3)
        rows = -(-lib.p // cols)
        fig = figure((4.5 * cols, 2.8 * rows))
        axes = fig.subplots(rows, cols, squeeze=False)
        for ax in axes.flat[lib.p :]:
            ax.set_visible(False)
        for i, th in enumerate(lib.manifest.theta):
            c = L["theta"].start + i
            ax = axes.flat[i]
            tc, lo, hi, est, true = envelope(
                t,
                res.x_hat[:, c] - 2 * sd[:, c],
                res.x_hat[:, c] + 2 * sd[:, c],
                res.x_hat[:, c],
                res.x_true[:, c],
            )
            ax.fill_between(tc, lo, hi, color="0.85", lw=0, label="±2σ of the filter")
            ax.plot(tc, est, lw=0.9, label="estimate", rasterized=True)
            ax.plot(tc, true, "k--", lw=0.8, label="true value (the plant's)")
            ax.set_xlabel("t [s]", fontsize=8)
            ax.set_ylabel(f"{th.name} ({th.kind}) [{th.unit}]", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
        axes.flat[0].legend(fontsize=7)
        title(fig, f"theta (paper Fig. 5) — {what}")
        save(fig, out / "theta.png", paths)

    fig, cells = canvas.joint_grid(n, PANEL)
    for j, (ax,) in enumerate(cells):
        c = L["q"].start + j
        tc, des, true, est = envelope(t, res.q_des[:, j], res.x_true[:, c], res.x_hat[:, c])
        ax.plot(tc, des, "k--", lw=1.0, label="desired link angle")
        ax.plot(tc, true, lw=0.9, label="true link angle (plant)", rasterized=True)
        ax.plot(tc, est, lw=0.7, alpha=0.8, label=f"{sc.estimator} estimate", rasterized=True)
        ax.set_ylabel(f"q{j + 1} [rad]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    cells[0][0].legend(fontsize=7)
    title(fig, f"Tracking (paper Figs. 6-7) — {what}")
    save(fig, out / "tracking.png", paths)
    return paths


def _decimate(n: int, max_points: int = 2500) -> slice:
    return slice(None, None, max(1, n // max_points))


def plot_study(
    series: Mapping[str, Mapping[str, Any]],
    lib: ModelLibrary,
    sc: Scenario,
    fig_seed: int,
    out: Path,
    suffix: str = "",
    seeds: int = 1,
) -> list[Path]:
    """The study's three figures for one variant; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n, names = lib.n, list(series)
    dpi = 90
    paths: list[Path] = []
    first = series[names[0]]
    t = first["t"]
    dec = _decimate(t.size)
    w = window(t.size)
    title = f"{sc.name}"

    # (a) estimation errors, paper Fig. 4 analog
    labels = [f"q{j + 1} [rad]" for j in range(n)] + [f"qd{j + 1} [rad/s]" for j in range(n)]
    fig, axes = plt.subplots(
        2 * n,
        len(names),
        figsize=(2.9 * len(names) + 0.6, 1.9 * 2 * n + 0.6),
        sharex=True,
        sharey="row",
        squeeze=False,
    )
    have = [s for s in series.values() if np.isfinite(s["err"]).all()] or [
        {"err": np.ones((t.size, 2 * n))}
    ]  # the figure seed's runs that did not fail
    for r in range(2 * n):
        late = max(float(np.percentile(np.abs(s["err"][w, r]), 99)) for s in have)
        top = 1.15 * max(float(np.max(np.abs(s["err"][:, r]))) for s in have)
        lin = max(2 * late, 1e-9)
        for c, name in enumerate(names):
            s = series[name]
            ax = axes[r][c]
            ax.fill_between(t[dec], -2 * s["sd"][dec, r], 2 * s["sd"][dec, r], color="0.85", lw=0)
            ax.plot(t[dec], s["err"][dec, r], lw=0.6)
            if top > 10 * lin:  # a large start transient: symlog shows it and the late error
                ax.set_yscale("symlog", linthresh=lin)
            ax.set_ylim(-max(top, lin), max(top, lin))
            ax.grid(alpha=0.3)
            if r == 0:
                ax.set_title(name, fontsize=10)
            if c == 0:
                ax.set_ylabel(labels[r], fontsize=9)
            if r == 2 * n - 1:
                ax.set_xlabel("t [s]")
            ax.tick_params(labelsize=7)
    fig.suptitle(
        f"{title}: true − estimate (grey ±2σ of the filter), seed {fig_seed}; symlog axes "
        "are linear within 2x the 99th percentile of the last 80 %",
        fontsize=10,
    )
    fig.tight_layout()
    paths.append(out / f"errors{suffix}.png")
    fig.savefig(paths[-1], dpi=dpi)
    plt.close(fig)

    # (b) theta, paper Fig. 5 analog
    if lib.p:
        theta_true = lib.theta_true
        fig, axes = plt.subplots(lib.p, 2, figsize=(11, 3.4 * lib.p), squeeze=False, sharey="row")
        for i, th in enumerate(lib.manifest.theta):
            a0, a1 = axes[i]
            for name in names:
                s = series[name]
                (ln,) = a0.plot(t[dec], s["theta_hat"][dec, i], lw=0.9, label=name)
                allm = s["theta_all"][:, :, i]
                mu, sd = allm.mean(axis=0), allm.std(axis=0)
                a1.plot(t[dec], mu[dec], lw=0.9, color=ln.get_color(), label=name)
                a1.fill_between(
                    t[dec], (mu - sd)[dec], (mu + sd)[dec], color=ln.get_color(), alpha=0.15, lw=0
                )
            for ax in (a0, a1):
                ax.axhline(theta_true[i], color="k", ls="--", lw=0.8, label="true")
                ax.grid(alpha=0.3, which="both")
                ax.set_xscale("log")
                ax.set_xlim(t[1], t[-1])
                ax.set_xlabel("t [s] (log scale)")
            a0.set_ylabel(f"{th.name} ({th.kind}) [{th.unit}]")
            a0.set_title(f"seed {fig_seed}", fontsize=10)
            a1.set_title(f"mean ± std over {seeds} seeds", fontsize=10)
            a0.legend(fontsize=7)
        fig.suptitle(f"{title}: theta estimate (paper Fig. 5 analog)", fontsize=10)
        fig.tight_layout()
        paths.append(out / f"theta{suffix}.png")
        fig.savefig(paths[-1], dpi=dpi)
        plt.close(fig)

    # (c) average NEES with the 95 % band
    dof = lib.N
    fig, axes = plt.subplots(
        len(names), 1, figsize=(8, 1.7 * len(names) + 0.8), sharex=True, squeeze=False
    )
    for c, name in enumerate(names):
        ax = axes[c][0]
        avg = series[name]["avg_nees"]
        m = int(series[name].get("M", seeds))
        lo, hi = nees_band(dof, m)
        ax.plot(t[dec], avg[dec], lw=0.6, label=f"average NEES over {m} seeds")
        ax.axhspan(lo, hi, color="tab:green", alpha=0.2, lw=0, label="95 % band")
        ax.axhline(dof, color="k", lw=0.6, ls=":", label=f"N = {dof}")
        ax.axvline(t[w.start], color="0.5", lw=0.6, ls="--")
        inside = float(np.mean((avg[w] >= lo) & (avg[w] <= hi)))
        ax.set_title(f"{name}: {100 * inside:.0f} % of the last 80 % inside", fontsize=9)
        if np.nanmax(avg) > 10 * hi or np.nanmin(avg[w]) < 0.1 * lo:
            ax.set_yscale("log")
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
    axes[0][0].legend(fontsize=7, loc="upper right")
    axes[-1][0].set_xlabel("t [s]")
    fig.suptitle(
        f"{title}: NEES averaged over seeds with its 95 % chi-square band "
        f"[{nees_band(dof, seeds)[0]:.2f}, {nees_band(dof, seeds)[1]:.2f}] (M = {seeds})",
        fontsize=10,
    )
    fig.tight_layout()
    paths.append(out / f"nees{suffix}.png")
    fig.savefig(paths[-1], dpi=dpi)
    plt.close(fig)
    return paths
