"""Per-seed traces of the start-up (docs/explanation/control.md, "Start-up"): one paper-sim seed
with the
paper's start, with the start-up that waits for the estimate, and with the wait and the
blended reference (paper-sim's default), compiled loop: the joints' tracking error, the link
angles' posterior std against the threshold, and the torque with the actuator limit::

    .venv/bin/python tools/startup_figure.py 1103 docs/figures/startup-seed-1103.png
"""

from __future__ import annotations

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from amsfe_sym.codegen import library_for
from amsfe_sym.scenario import apply_sets, load_scenario
from amsfe_sym.sim.loop import run


def main() -> int:
    seed, out = int(sys.argv[1]), sys.argv[2]
    fig, axes = plt.subplots(3, 3, figsize=(16, 8), sharex=True)
    variants = {
        "first": ["startup=first", "blend_accel=inf"],
        "converged": ["startup=converged", "blend_accel=inf"],
        "converged + blend": ["startup=converged", "blend_accel=20.0"],
    }
    for col, (startup, sets) in enumerate(variants.items()):
        sc = load_scenario("paper-sim").with_overrides(
            controller="amsfe", estimator="oosm", duration=3.0, seed=seed
        )
        sc = apply_sets(sc, [f"controller_gains.amsfe.{k}" for k in sets])
        res = run(sc, library_for(sc), runtime="compiled")
        n, t = res.lib.n, res.t
        e = res.x_true[:, :n] - res.q_des
        for j in range(n):
            axes[0, col].plot(t, e[:, j], label=f"joint {j + 1}")
        axes[0, col].set_title(f"seed {seed}, startup = {startup!r}")
        axes[0, col].set_ylabel("tracking error q - q_d [rad]")
        axes[0, col].legend(loc="upper right")
        sd = np.sqrt(res.P_diag[:, :n])
        axes[1, col].semilogy(t, sd)
        axes[1, col].axhline(0.03, color="k", ls="--", lw=0.8, label="ready_q_std")
        axes[1, col].set_ylabel("posterior std of q [rad]")
        axes[1, col].legend(loc="upper right")
        axes[2, col].plot(t, res.u)
        axes[2, col].set_ylabel("u [N m] (limit 100)")
        axes[2, col].set_xlabel("t [s]")
        for ax in axes[:, col]:
            ax.set_xlim(0, 3.0)
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    print(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
