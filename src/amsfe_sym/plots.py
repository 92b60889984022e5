"""Figures of a run (matplotlib, Agg backend; written as PNG next to the data).

- ``estimation_errors.png``: q and qd estimation errors of every joint (the paper's Fig. 4)
  with the filter's +-2 sigma band;
- ``theta.png``: theta estimate vs truth with +-2 sigma (Fig. 5);
- ``tracking.png``: link angle vs desired for every joint (Figs. 6-7).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from amsfe_sym.simulate import RunResult

__all__ = ["plot_run"]


def plot_run(res: RunResult, out: Path) -> list[Path]:
    """Write the run's figures to ``out``; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lib, t = res.lib, res.t
    n, L = lib.n, lib.layout
    e = res.x_true - res.x_hat
    sd = np.sqrt(np.maximum(res.P_diag, 0.0))
    paths = []
    title = f"{res.scenario.name}: estimator {res.scenario.estimator}, seed {res.scenario.seed}"

    fig, axes = plt.subplots(2, n, figsize=(5 * n, 6), sharex=True, squeeze=False)
    for j in range(n):
        for row, (block, unit) in enumerate((("q", "rad"), ("qd", "rad/s"))):
            c = L[block].start + j
            ax = axes[row][j]
            ax.fill_between(t, -2 * sd[:, c], 2 * sd[:, c], color="0.85", label="±2σ (filter)")
            ax.plot(t, e[:, c], lw=0.8, label="true − estimate")
            ax.set_ylabel(f"{block}{j + 1} error [{unit}]")
            ax.grid(alpha=0.3)
            lim = max(5 * float(np.percentile(np.abs(e[len(t) // 5 :, c]), 99)), 1e-6)
            ax.set_ylim(-lim, lim)
        axes[1][j].set_xlabel("t [s]")
    axes[0][0].legend(loc="upper right", fontsize=8)
    fig.suptitle(f"Estimation errors (paper Fig. 4) — {title}")
    fig.tight_layout()
    paths.append(out / "estimation_errors.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    if lib.p:
        fig, axes = plt.subplots(1, lib.p, figsize=(6 * lib.p, 3.5), squeeze=False)
        for i, th in enumerate(lib.manifest["theta"]):
            c = L["theta"].start + i
            ax = axes[0][i]
            ax.fill_between(
                t,
                res.x_hat[:, c] - 2 * sd[:, c],
                res.x_hat[:, c] + 2 * sd[:, c],
                color="0.85",
                label="±2σ",
            )
            ax.plot(t, res.x_hat[:, c], label="estimate")
            ax.plot(t, res.x_true[:, c], "k--", label="true")
            ax.set_xlabel("t [s]")
            ax.set_ylabel(f"{th['name']} ({th['kind']}) [{th.get('unit', '')}]")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
        fig.suptitle(f"theta (paper Fig. 5) — {title}")
        fig.tight_layout()
        paths.append(out / "theta.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)

    fig, axes = plt.subplots(n, 1, figsize=(8, 2.8 * n), sharex=True, squeeze=False)
    for j in range(n):
        ax = axes[j][0]
        ax.plot(t, res.q_des[:, j], "k--", label="desired")
        ax.plot(t, res.x_true[:, L["q"].start + j], label="true link angle")
        ax.plot(t, res.x_hat[:, L["q"].start + j], lw=0.8, alpha=0.8, label="estimate")
        ax.set_ylabel(f"q{j + 1} [rad]")
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8)
    axes[-1][0].set_xlabel("t [s]")
    fig.suptitle(f"Tracking (paper Figs. 6-7), controller {res.scenario.controller}")
    fig.tight_layout()
    paths.append(out / "tracking.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    return paths
