"""The paper's figures from a controller comparison (matplotlib, Agg, PNG).

See :mod:`amsfe_sym.apps.reproduce` for what each file shows.  The first controller of the
comparison is "the proposed" one (its run's estimator gives the estimation figures).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from amsfe_sym.apps.plots.run import (
    RATE_PANELS_UP_TO,
    controller_label,
    error_rows,
    estimation_error_axes,
)
from amsfe_sym.apps.plots.style import (
    PANEL,
    Canvas,
    collect_once,
    converged_limit,
    envelope,
    few_ticks,
    figure,
    joint_grid,
    logscale,
    save,
    symlog,
    title,
)

if TYPE_CHECKING:
    from amsfe_sym.apps.reproduce import Comparison
    from amsfe_sym.sim.result import RunResult

__all__ = ["plot_comparison"]

_COLORS = ["tab:blue", "tab:orange", "tab:red", "tab:green", "tab:purple", "tab:brown"]


def _label(name: str, res: RunResult) -> str:
    """The legend of a controller's run: its law and what it acts on
    (:func:`~amsfe_sym.apps.plots.run.controller_label`)."""
    return controller_label(res, name)


def _save(fig: Any, path: Path, paths: list[Path]) -> None:
    save(fig, path, paths)


@collect_once
def plot_comparison(cmp: Comparison, out: Path, every: bool = False) -> list[Path]:
    """Write the comparison's figures to ``out``; returns their paths.

    Args:
        cmp: The comparison (its first controller is the proposed one).
        out: The comparison folder.
        every: Also the sliding variable and the torque of an arm of more than
            :data:`~amsfe_sym.apps.plots.run.RATE_PANELS_UP_TO` joints (the paper's arms
            always get them: they are its figures, and two panels).
    """
    n = next(iter(cmp.results.values())).lib.n
    canvas = Canvas()
    if cmp.scenario.trajectory.get("kind") == "paper_experiment":
        paths = _experiment_figures(cmp, out)
    else:
        paths = _simulation_figures(cmp, out, canvas)
    if every or n <= RATE_PANELS_UP_TO:
        paths += _control_figures(cmp, out, n, canvas)
    return paths


def _simulation_figures(cmp: Comparison, out: Path, canvas: Canvas) -> list[Path]:
    paths: list[Path] = []
    name0, res0 = next(iter(cmp.results.items()))
    n, L = res0.lib.n, res0.lib.layout
    est = res0.scenario.estimator
    rows = error_rows(n)
    fig, cells = canvas.joint_grid(n, PANEL if rows == 1 else (3.8, 1.9), rows_per_joint=rows)
    estimation_error_axes(res0, cells)
    title(
        fig,
        f"Fig. 4: estimation errors of {'q and qd' if error_rows(n) == 2 else 'q'} "
        f"({est} fusion estimate; "
        f"{_label(name0, res0)}; seed {res0.scenario.seed}); axes set by the last 80 %",
    )
    _save(fig, out / "fig04_estimation_errors.png", paths)

    if res0.lib.p:
        fig = figure((7, 3.5))
        ax = fig.subplots()
        few_ticks(ax)
        theta = L["theta"]
        err = res0.x_true[:, theta] - res0.x_hat[:, theta]
        band = 2 * np.sqrt(np.maximum(res0.P_diag[:, theta], 0.0))
        for i, th in enumerate(res0.lib.manifest.theta):
            tc, lo, hi, e = envelope(res0.t, -band[:, i], band[:, i], err[:, i])
            ax.fill_between(tc, lo, hi, color="0.85", lw=0, label="±2σ of the filter")
            ax.plot(tc, e, lw=0.9, label=f"{th.name}: true − estimate", rasterized=True)
        lim = converged_limit(err, band)  # linear within it: the band; the start logarithmic
        symlog(ax, lim)
        ax.set_xlabel("t [s]", fontsize=8)
        ax.set_ylabel(f"theta error [{th.unit}]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
        title(
            fig,
            f"Fig. 5: estimation error of theta ({est}); symlog: linear within ±{lim:.1g} "
            f"{th.unit} (the last 80 %), the convergence before it on a log scale",
        )
        _save(fig, out / "fig05_theta_error.png", paths)

    if n > 2:  # an arm: one panel per joint (the paper's Figs. 6-7 are its two joints)
        return [*paths, _tracking_grid(cmp, out, canvas)]
    for j in range(n):
        fig, axes = canvas.stack((8, 6), 2)
        axes[0].plot(res0.t, res0.q_des[:, j], "k--", lw=1.2, label="desired")
        for (name, res), color in zip(cmp.results.items(), _COLORS, strict=False):
            tc, q, dq = envelope(
                res.t,
                res.x_true[:, L["q"].start + j],
                res.x_true[:, L["q"].start + j] - res.q_des[:, j],
            )
            axes[0].plot(tc, q, color=color, lw=0.9, label=_label(name, res), rasterized=True)
            axes[1].plot(tc, dq, color=color, lw=0.9, label=_label(name, res), rasterized=True)
        axes[0].set_ylabel(f"q{j + 1} [rad]")
        axes[1].set_ylabel(f"q{j + 1} − q{j + 1},d [rad]")
        axes[1].set_xlabel("t [s]")
        symlog(axes[1], 1e-3)
        for ax in axes:
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=8)
        axes[0].legend(fontsize=8, loc="upper right")
        axes[0].set_ylim(*_span(res0.q_des[:, j]))
        title(fig, f"Fig. {6 + j}: tracking of joint {j + 1}, proposed vs DTSMC")
        _save(fig, out / f"fig{6 + j:02d}_joint{j + 1}_tracking.png", paths)
    return paths


def _tracking_grid(cmp: Comparison, out: Path, canvas: Canvas) -> Path:
    """``tracking.png``: one panel per joint, each controller's tracking error q − q_d
    (symlog: linear within 1 mrad)."""
    res0 = next(iter(cmp.results.values()))
    n, L = res0.lib.n, res0.lib.layout
    fig, cells = canvas.joint_grid(n, PANEL)
    for j, (ax,) in enumerate(cells):
        for (name, res), color in zip(cmp.results.items(), _COLORS, strict=False):
            tc, dq = envelope(res.t, res.x_true[:, L["q"].start + j] - res.q_des[:, j])
            ax.plot(tc, dq, color=color, lw=0.7, label=_label(name, res), rasterized=True)
        symlog(ax, 1e-3)
        ax.set_ylabel(f"q{j + 1} − q{j + 1},d [rad]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    cells[0][0].legend(fontsize=6, loc="upper right")
    title(fig, "Tracking error of each joint (symlog: linear within 1 mrad)")
    return save(fig, out / "tracking.png")


def _span(v: np.ndarray) -> tuple[float, float]:
    lo, hi = float(np.min(v)), float(np.max(v))
    pad = 0.5 * (hi - lo) + 0.2
    return lo - pad, hi + pad


def _vision_angle(res: RunResult) -> tuple[np.ndarray, np.ndarray]:
    """Joint angle recovered from each delivered frame (the paper's arccos of eq. 55, done as
    a back-projection of the pixel onto the motion plane z = 0), at its exposure time."""
    cam = res.lib.manifest.camera
    K, R = np.array(cam.K), np.array(cam.R_cw)
    c = np.array(cam.position)
    if res.frames.size == 0:
        return np.zeros(0), np.zeros(0)
    pix = np.column_stack([res.frames[:, 2], res.frames[:, 3], np.ones(len(res.frames))])
    rays = (R.T @ np.linalg.solve(K, pix.T)).T
    lam = -c[2] / rays[:, 2]
    pts = c + lam[:, None] * rays
    return res.frames[:, 0] * res.lib.T, np.arctan2(pts[:, 1], pts[:, 0])


def _experiment_figures(cmp: Comparison, out: Path) -> list[Path]:
    paths: list[Path] = []
    name0, res0 = next(iter(cmp.results.items()))
    L = res0.lib.layout
    t = res0.t
    q = res0.x_true[:, L["q"].start]
    t_cam, q_cam = _vision_angle(res0)
    enc = res0.z_enc[:, 0]  # the motor encoder (link side of the gear)
    fig = figure((8, 6))
    axes = fig.subplots(2, 1, sharex=True)
    te, enc_c, fused_c, q_c, enc_e, fused_e = envelope(
        t, enc, res0.x_hat[:, L["q"].start], q, enc - q, res0.x_hat[:, L["q"].start] - q
    )
    axes[0].plot(te, enc_c, lw=0.8, label="encoder (motor angle)")
    axes[0].plot(t_cam, q_cam, "o", ms=2.5, label="vision (frame exposure time)")
    axes[0].plot(te, fused_c, lw=1.0, label=f"fused ({res0.scenario.estimator})")
    axes[0].plot(te, q_c, "k--", lw=0.8, label="true link angle")
    axes[0].set_ylabel("q [rad]")
    axes[1].plot(te, enc_e, lw=0.8, label="encoder − true")
    axes[1].plot(t_cam, q_cam - np.interp(t_cam, t, q), "o", ms=2.5, label="vision − true")
    axes[1].plot(te, fused_e, lw=1.0, label="fused − true")
    axes[1].set_ylabel("angle error [rad]")
    axes[1].set_xlabel("t [s]")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    title(fig, f"Fig. 12: encoder vs vision vs fused joint angle ({name0} in the loop)")
    _save(fig, out / "fig12_encoder_vision_fused.png", paths)

    fig, cells = joint_grid(1, (8.0, 2.4), rows_per_joint=2)
    estimation_error_axes(res0, cells)
    title(fig, f"Fig. 13: estimation error of the fused estimate ({res0.scenario.estimator})")
    _save(fig, out / "fig13_estimation_error.png", paths)

    l1 = float(cmp.scenario.trajectory.get("l1", 0.6))
    fig = figure((8, 3.8))
    ax = fig.subplots()
    for (name, res), color in zip(cmp.results.items(), _COLORS, strict=False):
        dq = res.x_true[:, L["q"].start] - res.q_des[:, 0]
        tip_err = 2.0 * l1 * np.abs(np.sin(dq / 2.0))  # chord between actual and desired tip
        tc, tip = envelope(res.t, 1e3 * tip_err)
        ax.plot(tc, tip, color=color, lw=0.9, label=_label(name, res))
    logscale(ax)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("tip tracking error [mm]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(f"Fig. 14: tip tracking error on the circle of radius {l1} m, proposed vs DTSMC")
    _save(fig, out / "fig14_tip_tracking_error.png", paths)
    return paths


def _control_figures(cmp: Comparison, out: Path, n: int, canvas: Canvas) -> list[Path]:
    paths: list[Path] = []
    fig, cells = canvas.joint_grid(n, PANEL)
    for (name, res), color in zip(cmp.results.items(), _COLORS, strict=False):
        for j, (ax,) in enumerate(cells):
            tc, s = envelope(res.t, res.s[:, j])
            ax.plot(tc, s, color=color, lw=0.7, label=_label(name, res), rasterized=True)
    for j, (ax,) in enumerate(cells):
        ax.set_ylabel(f"s{j + 1} [rad/s]", fontsize=8)
        symlog(ax, 1e-2)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    cells[0][0].legend(fontsize=6, loc="upper right")
    title(fig, "Sliding variable s(k) of eq. (33) (symlog: linear within 0.01)")
    _save(fig, out / "sliding_surface.png", paths)

    # the zoom: the last 0.25 s of the longest run (a diverged run ends earlier: not shown),
    # for the paper's arms (an arm's grid: the whole run alone, half the panels to draw)
    zoomed = n <= RATE_PANELS_UP_TO
    fig, cells = canvas.joint_grid(
        n, (3.8, 1.8) if zoomed else PANEL, rows_per_joint=2 if zoomed else 1, sharex=not zoomed
    )
    t_end = max(float(res.t[-1]) for res in cmp.results.values())
    for (name, res), color in zip(cmp.results.items(), _COLORS, strict=False):
        t = res.t
        zoom = t >= t_end - 0.25
        for j, axes in enumerate(cells):
            tc, u = envelope(t, res.u[:, j])
            axes[0].plot(tc, u, color=color, lw=0.6, label=_label(name, res), rasterized=True)
            if zoomed and np.any(zoom):
                axes[1].plot(t[zoom], res.u[zoom, j], color=color, lw=0.8)
    for j, axes in enumerate(cells):
        axes[0].set_ylabel(f"u{j + 1} [N m]", fontsize=8)
        if zoomed:
            axes[1].set_ylabel(f"u{j + 1}, last 0.25 s", fontsize=8)
            axes[1].set_xlim(t_end - 0.25, t_end)
            axes[1].set_xlabel("t [s]", fontsize=8)
        for ax in axes:
            ax.grid(alpha=0.3)
    cells[0][0].legend(fontsize=6, loc="upper right")
    title(
        fig,
        "Motor torque u(k): the whole run (upper) and its last 0.25 s (lower: the chattering)"
        if zoomed
        else "Motor torque u(k)",
    )
    _save(fig, out / "torque.png", paths)
    return paths
