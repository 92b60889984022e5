"""``amsfe estimate LOG``: an estimator of a generated robot over a recorded rosbag2 / MCAP
log, into a run folder (docs/logs.md).

A log written by ``amsfe simulate --bag`` carries its robot, scenario and estimator
(``/amsfe/config``), so ``amsfe estimate LOG`` alone reproduces the run's estimates; any
other log needs ``--scenario`` (its robot, ``[filter]`` and ``[estimate0]``, and the sensor
noise R defaults from its ``[encoders]`` / ``[camera]``) and, where its topics differ from
the defaults, a log spec.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from amsfe_sym.core.folders import write_folder
from amsfe_sym.core.jsonfile import write_json
from amsfe_sym.core.outputs import check_output
from amsfe_sym.core.provenance import provenance
from amsfe_sym.core.toml import dump_toml, tomllib
from amsfe_sym.errors import LogError, describe
from amsfe_sym.logs.read import RobotLog, read_config, read_log
from amsfe_sym.logs.spec import read_log_spec
from amsfe_sym.scenario import Scenario, load_scenario, parse_scenario

if TYPE_CHECKING:  # the estimators (scipy) are imported when a log is estimated, not at start
    from amsfe_sym.logs.replay import LogEstimate

__all__ = [
    "EstimateOptions",
    "EstimateRun",
    "add_arguments",
    "default_out",
    "estimate_command",
    "from_args",
    "print_summary",
    "summary",
]


@dataclass(frozen=True)
class EstimateOptions:
    """How ``amsfe estimate`` runs.

    Attributes:
        scenario: Scenario file for a log without amsfe's config (or to override it).
        log_spec: Log spec TOML (topics, joint names, timing), or None for the defaults.
        estimator: Estimator name overriding the scenario's.
        runtime: ``"compiled"`` (the library's C estimator) or ``"python"`` (the reference).
        plots: Draw the figures.
        force: Replace an existing run folder.
    """

    scenario: str | None = None
    log_spec: str | None = None
    estimator: str | None = None
    runtime: str = "compiled"
    plots: bool = True
    force: bool = False


@dataclass
class EstimateRun:
    """What ``amsfe estimate`` did: the read log, the estimates, the folder and the timing."""

    log: RobotLog
    estimate: LogEstimate
    scenario: Scenario
    out: Path
    read_s: float
    estimate_s: float


def _scenario(path: Path, config: dict[str, Any] | None, options: EstimateOptions) -> Scenario:
    if options.scenario is not None:
        sc = load_scenario(options.scenario)
    elif config is not None and "scenario_toml" in config:
        try:
            data = tomllib.loads(str(config["scenario_toml"]))
        except tomllib.TOMLDecodeError as exc:
            raise LogError(
                describe(
                    f"log {path}: /amsfe/config scenario_toml",
                    "the run's scenario as TOML (written by amsfe simulate --bag)",
                    f"text that is not TOML ({exc})",
                    "pass --scenario FILE to give the scenario yourself (docs/logs.md)",
                )
            ) from exc
        sc = parse_scenario(data, path)
    else:
        raise LogError(
            describe(
                f"log {path}",
                "amsfe's run config (/amsfe/config, written by amsfe simulate --bag)",
                "none",
                "pass --scenario FILE: its robot, [filter], [estimate0] and sensor noise "
                "(start from a copy of scenarios/paper-sim.toml; docs/logs.md)",
            )
        )
    return sc.with_overrides(estimator=options.estimator)


def estimate_command(log_path: Path, out: Path, options: EstimateOptions) -> EstimateRun:
    """Estimate over ``log_path`` and write the run folder ``out``: ``estimates.parquet``,
    ``summary.json``, ``config.toml``, figures and ``estimates/`` (a rosbag2 in MCAP).

    Raises:
        LogError: the log cannot be used (one line: what, found, fix).
        ConfigError, RunFolderError: bad settings, an existing ``out`` without ``force``, an
            ``out`` that is, holds or lies inside an input (the log), even with ``force``.
    """
    from amsfe_sym.codegen import library_for
    from amsfe_sym.sim.builders import build_estimator, build_sensors, scenario_timing

    inputs = [p for p in (log_path, options.scenario, options.log_spec) if p and Path(p).exists()]
    if log_path.is_file() and (log_path.parent / "metadata.yaml").is_file():
        inputs.append(log_path.parent)  # the .mcap of a bag folder: the folder is the log
    check_output(out, option="--out", force=options.force, inputs=inputs)
    spec = read_log_spec(options.log_spec)
    t0 = time.perf_counter()
    config = read_config(log_path, spec)
    sc = _scenario(log_path, config, options)
    lib = library_for(sc)
    log = read_log(log_path, spec, lib.manifest.joints, lib.T, lib.N)
    read_s = time.perf_counter() - t0
    # the estimator as the loop builds it: R from the scenario's sensors unless [filter] sets it
    sensors = build_sensors(sc, lib, np.random.default_rng(sc.seed), scenario_timing(sc, lib))
    est = build_estimator(sc, lib, sensors, log.z[0], compiled=options.runtime == "compiled")
    t1 = time.perf_counter()
    from amsfe_sym.logs.replay import estimate_log

    result = estimate_log(log, est)
    estimate_s = time.perf_counter() - t1
    run = EstimateRun(log, result, sc, out, read_s, estimate_s)
    _write(run, lib.manifest.joints, options)
    return run


def summary(run: EstimateRun) -> dict[str, Any]:
    """The ``summary.json`` of an estimate run."""
    log, est = run.log, run.estimate
    n = len(log.u[0])
    out: dict[str, Any] = {
        "log": str(log.path),
        "estimator": run.scenario.estimator,
        "ticks": log.K,
        "duration_s": log.K * log.T,
        "frames_fused": est.counters.get("frames_applied", 0),
        "counters": est.counters,
        "read_s": round(run.read_s, 4),
        "estimate_s": round(run.estimate_s, 4),
        "real_time_factor": round(log.K * log.T / max(run.read_s + run.estimate_s, 1e-9), 2),
    }
    if log.truth is not None and est.nees is not None:
        w = slice(int(0.2 * log.K), log.K)
        err = log.truth[w] - est.x_hat[w]
        out["estimation_rmse_q"] = np.sqrt(np.nanmean(err[:, :n] ** 2, axis=0)).tolist()
        out["nees_mean"] = float(np.nanmean(est.nees[w]))
        out["nees_dof"] = int(est.x_hat.shape[1])
    out["provenance"] = provenance()
    return out


def add_arguments(e: argparse.ArgumentParser) -> None:
    """The options of ``amsfe estimate``."""
    e.add_argument("log", help="rosbag2 folder or .mcap file (amsfe simulate --bag writes one)")
    e.add_argument("--scenario", default=None, help="robot + filter settings (logs not ours)")
    e.add_argument("--log-spec", default=None, metavar="FILE", help="topics, joint names (TOML)")
    e.add_argument("--estimator", default=None, help="estimator name (default the scenario's)")
    e.add_argument(
        "--out",
        default=None,
        help="run folder (default runs/estimate-<log>-<stamp>); never the log, inside it or "
        "around it, even with --force",
    )
    e.add_argument("--runtime", choices=("compiled", "python"), default="compiled")
    e.add_argument("--no-plots", action="store_true", help="skip the figures")
    e.add_argument(
        "--force",
        action="store_true",
        help="replace an existing --out run folder that amsfe wrote (never an input)",
    )


def from_args(args: argparse.Namespace) -> int:
    """``amsfe estimate LOG`` from its parsed options (:func:`add_arguments`)."""
    log = Path(args.log)
    out = Path(args.out) if args.out else default_out(log)
    opts = EstimateOptions(
        args.scenario, args.log_spec, args.estimator, args.runtime, not args.no_plots, args.force
    )
    print_summary(summary(estimate_command(log, out, opts)), out)
    return 0


def print_summary(s: dict[str, Any], out: Path) -> None:
    """The headline of an estimate run: ticks, frames fused, what was skipped, speed, NEES."""
    c = s["counters"]
    print(f"run folder: {out} ({s['ticks']} ticks, {s['duration_s']:.2f} s of log)")
    print(
        f"  {s['estimator']}: {s['frames_fused']} camera frames fused; read {s['read_s']:.2f} s, "
        f"estimated {s['estimate_s']:.2f} s ({s['real_time_factor']:.0f}x real time)"
    )
    skipped = {k: v for k, v in c.items() if v and k not in ("frames_applied", "frames_in_log")}
    print("  skipped or refused: " + (", ".join(f"{k} {v}" for k, v in skipped.items()) or "none"))
    if "nees_mean" in s:
        print(f"  mean NEES {s['nees_mean']:.2f} (N = {s['nees_dof']}) against the log's truth")


def _write(run: EstimateRun, joints: tuple[str, ...] | list[str], options: EstimateOptions) -> None:
    import pandas as pd

    log, est = run.log, run.estimate

    def fill(tmp: Path) -> None:
        N = est.x_hat.shape[1]
        cols: dict[str, Any] = {"t": log.t}
        for i in range(N):
            cols[f"est_{i}"] = est.x_hat[:, i]
        for i in range(N):
            cols[f"var_{i}"] = est.P_diag[:, i]
        if est.nees is not None:
            cols["nees"] = est.nees
        pd.DataFrame(cols).to_parquet(tmp / "estimates.parquet")
        write_json(tmp / "summary.json", summary(run))
        (tmp / "config.toml").write_text(
            f"# the scenario amsfe estimate used on {log.path}\n"
            + dump_toml(run.scenario.to_dict())
        )
        from amsfe_sym.logs.write import write_estimate_bag

        write_estimate_bag(
            tmp / "estimates", log.t0_ns * 1e-9, log.t, joints, est.x_hat, est.P_diag
        )
        if options.plots:
            _figures(run, tmp)

    write_folder(run.out, fill, replace=options.force)


def _figures(run: EstimateRun, folder: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    log, est = run.log, run.estimate
    n = log.u.shape[1]
    fig, axes = plt.subplots(n, 1, figsize=(8, 2.4 * n + 0.6), sharex=True, squeeze=False)
    for j in range(n):
        ax = axes[j, 0]
        if log.truth is not None:
            ax.plot(log.t, log.truth[:, j] - est.x_hat[:, j], lw=0.8, label="error q - q_hat")
            sd = np.sqrt(np.maximum(est.P_diag[:, j], 0))
            ax.fill_between(log.t, -2 * sd, 2 * sd, alpha=0.2, label="+-2 sigma")
            ax.set_ylabel(f"q{j + 1} error [rad]")
        else:
            ax.plot(log.t, est.x_hat[:, j], lw=0.8, label="q_hat (link)")
            ax.plot(log.t, log.z[:, j], lw=0.6, label="qm (encoder)")
            ax.set_ylabel(f"joint {j + 1} [rad]")
        for fr in log.frames:
            ax.axvline(fr.delivery_step * log.T, color="k", lw=0.2, alpha=0.2)
        ax.legend(loc="upper right", fontsize=7)
    axes[-1, 0].set_xlabel("t [s] (thin lines: camera frames' arrivals)")
    fig.suptitle(f"{run.scenario.estimator} on {log.path.name}")
    fig.tight_layout()
    fig.savefig(folder / "estimate.png", dpi=110)
    plt.close(fig)


def default_out(log_path: Path) -> Path:
    """``runs/estimate-<log name>-<UTC time>``."""
    from datetime import datetime, timezone

    stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
    return Path("runs") / f"estimate-{log_path.stem}-{stamp}"
