"""A run's folder: ``config.toml``, ``timeseries.csv``, ``frames.csv``, ``summary.json``
(and figures), and the summary metrics."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym.control.metrics import control_metrics, sliding_conditions
from amsfe_sym.core.folders import write_folder
from amsfe_sym.core.jsonfile import write_json
from amsfe_sym.core.outputs import check_output
from amsfe_sym.core.provenance import provenance
from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.scenario import Scenario, dump_toml
from amsfe_sym.sim.builders import scenario_timing
from amsfe_sym.sim.result import RunResult

#: Draws a finished run's figures into a folder: ``figures(result, folder)``.
Figures = Callable[[RunResult, Path], object]

__all__ = ["WINDOW_START", "nees_band", "run_filler", "summarize", "window", "write_run"]

#: Metrics are taken over the last 80 % of a run (the start transient left out).
WINDOW_START = 0.2


def window(K: int) -> slice:
    """The ticks the metrics use out of ``K``: the last 80 % of the run."""
    return slice(int(WINDOW_START * K), K)


def nees_band(dof: int, seeds: int, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided band of the across-seed average NEES.

    With M independent seeds and an N-dimensional Gaussian error that the filter's P
    describes, ``M * mean_m NEES_m(k)`` is chi-square with ``N M`` degrees of freedom, so
    the average lies in ``[chi2.ppf(a/2, N M) / M, chi2.ppf(1 - a/2, N M) / M]`` with
    probability ``1 - a``.
    """
    from amsfe_sym.estimation.ekf import chi2_ppf

    if dof < 1 or seeds < 1 or not (0.0 < probability < 1.0):
        raise ConfigError(
            describe("nees_band", "dof >= 1, seeds >= 1, 0 < p < 1", f"{dof}, {seeds}", "fix")
        )
    a = 1.0 - probability
    return (
        float(chi2_ppf(a / 2, dof * seeds) / seeds),
        float(chi2_ppf(1 - a / 2, dof * seeds) / seeds),
    )


def _camera_used(res: RunResult) -> dict[str, int]:
    """The camera timing [steps] the run used (the scenario's, else the robot's)."""
    t = scenario_timing(res.scenario, res.lib)
    return {"period": t.period, "delay": t.delay, "phase": t.phase, "jitter_steps": t.jitter_steps}


def summarize(res: RunResult) -> dict[str, Any]:
    """``summary.json``: RMSEs over the last 80 % of the run, NEES, timings, counters."""
    lib, sc = res.lib, res.scenario
    L = lib.layout
    K = res.t.size
    s = window(K)
    e = (res.x_true - res.x_hat)[s]

    def rmse(cols: slice) -> list[float]:
        return [float(v) for v in np.sqrt(np.mean(e[:, cols] ** 2, axis=0))]

    track = res.x_true[s, L["q"]] - res.q_des[s]
    gains = controller_gains(sc)
    control = control_metrics(res.t, res.x_true[:, L["q"]], res.q_des, res.u, res.saturated, s)
    sliding = sliding_conditions(res.s, res.bound, gains, lib.T, s)
    return {
        "scenario": sc.name,
        "robot": sc.robot,
        "model": {"library": lib.name, "integrator": lib.manifest.integrator},
        "camera": _camera_used(res),
        "estimator": sc.estimator,
        "controller": sc.controller,
        "seed": sc.seed,
        "runtime": res.runtime,
        "ticks": int(K),
        "T": lib.T,
        "sim_time_s": float(res.t[-1]),
        "wall_time_s": round(res.wall_time_s, 4),
        "cost_per_tick_us": round(1e6 * res.wall_time_s / K, 2),
        "estimation_rmse": {"q": rmse(L["q"]), "qd": rmse(L["qd"]), "theta": rmse(L["theta"])},
        "tracking_rmse": {"q": [float(v) for v in np.sqrt(np.mean(track**2, axis=0))]},
        "theta_final": {
            "true": lib.theta_true.tolist(),
            "estimate": res.x_hat[-1, L["theta"]].tolist(),
        },
        "nees_mean": float(np.mean(res.nees[s])),
        "nees_dof": int(lib.N),
        "counters": res.counters,
        "window": "last 80 % of the run",
        "diverged_at_s": res.diverged_at,
        "control": control,
        "sliding_conditions": sliding,
        "controller_gains": gains,
    }


def controller_gains(sc: Scenario) -> dict[str, Any]:
    """The run's controller gains: the class defaults updated by the scenario's."""
    from amsfe_sym.control import CONTROLLERS

    cls = CONTROLLERS.get(sc.controller)
    return {**(cls.gain_defaults if cls else {}), **sc.gains_for()}


def run_filler(
    res: RunResult,
    final: Path,
    figures: Figures | None = None,
    extra: Callable[[Path], object] | None = None,
) -> Callable[[Path], None]:
    """The ``fill(folder)`` of a run folder that will be named ``final``: config.toml,
    timeseries.csv, frames.csv, summary.json, then ``figures(res, folder)`` and
    ``extra(folder)`` (e.g. the run's bag, written inside the same temporary folder)."""

    def fill(tmp: Path) -> None:
        _write(res, tmp, final)
        if figures is not None:
            figures(res, tmp)
        if extra is not None:
            extra(tmp)

    return fill


def write_run(
    res: RunResult, out: Path, figures: Figures | None = None, force: bool = False
) -> Path:
    """Write config.toml, timeseries.csv, frames.csv, summary.json (+ figures) to ``out``.

    ``figures(res, folder)`` draws the run's figures into the folder before it is moved into
    place (the apps pass :func:`amsfe_sym.apps.plots.run.plot_run`; the recorder draws
    nothing itself).

    Complete or absent: everything is written to a hidden sibling folder, which is renamed to
    ``out`` at the end (an existing ``out`` is replaced only with ``force``, and only if
    this tool wrote it: :func:`amsfe_sym.core.outputs.check_output`); an error or Ctrl-C on
    the way removes it.  ``summary.json`` also records the
    :func:`~amsfe_sym.core.provenance.provenance` of the run.

    Raises:
        RunFolderError: ``out`` is a file, or exists and ``force`` is off, or is a folder
            this tool did not write.
    """
    check_output(out, option="out", force=force)
    return write_folder(out, run_filler(res, out, figures), replace=force) / "summary.json"


def _write(res: RunResult, out: Path, final: Path) -> None:
    """The files of :func:`write_run`, into ``out`` (named ``final`` in the config)."""
    lib = res.lib
    cfg = replace(res.scenario, compare=()).to_dict()  # re-runs this one run
    cfg["camera"].update(_camera_used(res))  # the timing used, not "the robot's"
    (out / "config.toml").write_text(
        f"# resolved scenario of run {final.name}: "
        f"`amsfe simulate {final}/config.toml` re-runs it\n" + dump_toml(cfg)
    )
    names = ["t"]
    state = [f"{b}{i + 1}" for b in ("q", "qd", "qm", "qmd") for i in range(lib.n)]
    state += [t.name for t in lib.manifest.theta]
    names += [f"true_{s}" for s in state] + [f"est_{s}" for s in state]
    names += [f"var_{s}" for s in state] + ["nees"]
    names += [f"q_des{i + 1}" for i in range(lib.n)] + [f"u{i + 1}" for i in range(lib.n)]
    names += [f"enc_qm{i + 1}" for i in range(lib.n)] + [f"enc_qmd{i + 1}" for i in range(lib.n)]
    names += [f"s{i + 1}" for i in range(lib.n)] + ["saturated"]
    names += [f"tau_l{i + 1}" for i in range(lib.n)] + [f"tau_m{i + 1}" for i in range(lib.n)]
    table = np.column_stack(
        [
            res.t,
            res.x_true,
            res.x_hat,
            res.P_diag,
            res.nees,
            res.q_des,
            res.u,
            res.z_enc,
            res.s,
            res.saturated.astype(float),
            res.tau_d,
        ]
    )
    np.savetxt(
        out / "timeseries.csv",
        table,
        delimiter=",",
        header=",".join(names),
        comments="",
        fmt="%.17g",  # round-trip precision: the run replays from this file to 1e-12
    )
    np.savetxt(
        out / "frames.csv",
        res.frames,
        delimiter=",",
        header="exposure_step,delivery_step,u_px,v_px",
        comments="",
        fmt="%.10g",
    )
    summary = summarize(res)
    summary["provenance"] = provenance()
    write_json(out / "summary.json", summary)
