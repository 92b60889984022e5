"""``amsfe estimate LOG``: an estimator of a generated robot over a recorded log (a ROS 1
``.bag``, a rosbag2 folder, an ``.mcap``), into a run folder (docs/logs.md).

A log written by ``amsfe simulate --bag`` carries its robot, scenario and estimator
(``/amsfe/config``), so ``amsfe estimate LOG`` alone reproduces the run's estimates; any
other log needs ``--robot ROBOT`` (the estimate starts from the log's first samples, the
filter from its defaults) or ``--scenario FILE`` (to tune the filter).  Topics are found by
message type and joint names (a driver's ``/joint_states``); a topic spec (``--log-spec``)
is for the unusual log.  The log's topics, types, joint names and rate are checked before
the robot's library is generated or loaded.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from amsfe_sym.core.folders import write_folder
from amsfe_sym.core.jsonfile import write_json
from amsfe_sym.core.outputs import check_output
from amsfe_sym.core.provenance import provenance
from amsfe_sym.core.toml import dump_toml, tomllib
from amsfe_sym.errors import LogError, describe
from amsfe_sym.logs.read import LogRateError, RobotLog, plan_log, read_config, read_log
from amsfe_sym.logs.source import log_topics
from amsfe_sym.logs.spec import read_log_spec
from amsfe_sym.scenario import Scenario, load_scenario, parse_scenario

if TYPE_CHECKING:  # the estimators (scipy) are imported when a log is estimated, not at start
    from amsfe_sym.logs.replay import LogEstimate

__all__ = [
    "EstimateOptions",
    "EstimateRun",
    "add_arguments",
    "default_out",
    "default_scenario",
    "estimate_command",
    "from_args",
    "nis_report",
    "print_summary",
    "summary",
]


@dataclass(frozen=True)
class EstimateOptions:
    """How ``amsfe estimate`` runs.

    Attributes:
        scenario: Scenario file for a log without amsfe's config (or to override it).
        log_spec: Topic spec TOML (topics, joint names, effort kind, timing), or None.
        estimator: Estimator name overriding the scenario's.
        runtime: ``"compiled"`` (the library's C estimator) or ``"python"`` (the reference).
        plots: Draw the figures.
        force: Replace an existing run folder.
        robot: The robot (a shipped name or a ``robot.toml``) for a log without amsfe's
            config, when no scenario is given: filter defaults, start from the log.
        verbose: Print which topic plays which role, and the clock offset.
    """

    scenario: str | None = None
    log_spec: str | None = None
    estimator: str | None = None
    runtime: str = "compiled"
    plots: bool = True
    force: bool = False
    robot: str | None = None
    verbose: bool = False


@dataclass
class EstimateRun:
    """What ``amsfe estimate`` did: the read log, the estimates, the folder and the timing."""

    log: RobotLog
    estimate: LogEstimate
    scenario: Scenario
    out: Path
    read_s: float
    estimate_s: float


def default_scenario(robot: str) -> Scenario:
    """The settings ``amsfe estimate LOG --robot ROBOT`` runs with: the scenario defaults
    (``[filter]``: process noise 0.1 N m, buffer 1000 steps; ``[encoders]`` and
    ``[camera]``: the sensor noise the filter's R is built from; docs/scenarios.md), the
    ``oosm`` estimator, and the estimate's start replaced by the log's first sample
    (:func:`_start_from_log`).  No plant or trajectory is used."""
    from amsfe_sym.codegen.preflight import modelled_joints
    from amsfe_sym.load.spec import load_spec

    spec = load_spec(robot)
    n = len(modelled_joints(spec) or ())
    zeros = [0.0] * n
    data = {
        "name": f"estimate-{spec.name}",
        "robot": str(spec.spec_path or spec.urdf) if Path(robot).exists() else robot,
        "estimator": "oosm",
        "trajectory": {"kind": "constant", "q": zeros},
        "plant": {"q0": zeros, "qd0": zeros},
        "estimate0": {"q": zeros, "qd": zeros, "motor": "encoders"},
    }
    if spec.camera.delay + 1 > 1000:
        data["filter"] = {"buffer_steps": 2 * spec.camera.delay + 1}
    return parse_scenario(data, Path(f"--robot {robot}"))


def _start_from_log(sc: Scenario, log: RobotLog) -> Scenario:
    """``[estimate0]`` from the log's first encoder sample: link angles = the measured
    positions, link rates = the measured velocities (motor states: the sample itself)."""
    n = log.u.shape[1]
    z0 = log.z[0]
    e0 = replace(sc.estimate0, q=tuple(map(float, z0[:n])), qd=tuple(map(float, z0[n:])))
    return replace(sc, estimate0=e0)


def _robot_of(scenario_robot: str) -> tuple[str, list[str], float, int]:
    """(name, joints, T, N) of a robot from its spec, without generating anything."""
    from amsfe_sym.codegen.preflight import modelled_joints
    from amsfe_sym.load.spec import load_spec

    spec = load_spec(scenario_robot)
    joints = modelled_joints(spec) or []
    return spec.name, joints, spec.model.T, 4 * len(joints) + len(spec.theta)


def _config_scenario(path: Path, config: dict[str, Any]) -> Scenario:
    try:
        data = tomllib.loads(str(config["scenario_toml"]))
    except tomllib.TOMLDecodeError as exc:
        raise LogError(
            describe(
                f"log {path}: /amsfe/config scenario_toml",
                "the run's scenario as TOML (written by amsfe simulate --bag)",
                f"text that is not TOML ({exc})",
                "pass --scenario FILE (or --robot ROBOT) to give it yourself (docs/logs.md)",
            )
        ) from exc
    return parse_scenario(data, path)


def _scenario(path: Path, config: dict[str, Any] | None, options: EstimateOptions) -> Scenario:
    from_config = None
    if config is not None and "scenario_toml" in config:
        from_config = _config_scenario(path, config)
    if options.scenario is not None:
        sc = load_scenario(options.scenario)
    elif options.robot is not None:
        sc = default_scenario(options.robot)
    elif from_config is not None:
        sc = from_config
    else:
        raise LogError(
            describe(
                f"log {path}",
                "amsfe's run config (/amsfe/config, written by amsfe simulate --bag)",
                "none",
                "pass --robot ROBOT (a shipped robot or a robot.toml: the estimate starts "
                "from the log), or --scenario FILE to tune the filter (docs/logs.md)",
            )
        )
    if from_config is not None and sc is not from_config:
        mine, theirs = _robot_of(sc.robot), _robot_of(from_config.robot)
        if (mine[0], mine[1]) != (theirs[0], theirs[1]):
            raise LogError(
                describe(
                    f"log {path}",
                    f"a log of robot {mine[0]} ({len(mine[1])} joints: {mine[1]})",
                    f"its config says robot {theirs[0]} ({len(theirs[1])} joints)",
                    f"estimate it with --robot {theirs[0]}, or a scenario of that robot",
                )
            )
    return sc.with_overrides(estimator=options.estimator)


def _generated_at_period(robot: str, period: float) -> Any:
    """The spec of ``robot`` at ``period`` [s] when ``amsfe generate ROBOT --period`` has
    already built its library (``codegen.modes``, where the build has it), else None: then
    the rate refusal stands, with that command as its fix."""
    import importlib.util

    if importlib.util.find_spec("amsfe_sym.codegen.modes") is None:
        return None
    try:
        modes = importlib.import_module("amsfe_sym.codegen.modes")
        build = importlib.import_module("amsfe_sym.codegen.build")
        spec = modes.spec_at_period(robot, period)
        return spec if build.cached_library(spec) is not None else None
    except Exception:  # an older modes API: the refusal and its fix stand
        return None


def _effort_support(kind: str, log_path: Path) -> None:
    """Refuse an effort kind this build cannot estimate with, before compiling."""
    if kind == "applied":
        return
    import importlib.util
    import inspect

    from amsfe_sym.sim.builders import build_estimator

    ok = importlib.util.find_spec("amsfe_sym.estimation.effort") is not None and (
        "effort" in inspect.signature(build_estimator).parameters
    )
    if not ok:
        raise LogError(
            describe(
                f"log {log_path}: effort of kind {kind!r}",
                "an estimator for that kind (amsfe_sym.estimation.effort)",
                "this build estimates with the applied torque only",
                'say [effort] kind = "applied" in a topic spec if the effort is the applied '
                "motor torque (docs/topics.md)",
            )
        )


def estimate_command(log_path: Path, out: Path, options: EstimateOptions) -> EstimateRun:
    """Estimate over ``log_path`` and write the run folder ``out``: ``estimates.parquet``,
    ``summary.json``, ``config.toml``, figures and ``estimates/`` (a rosbag2 in MCAP).

    Everything about the log (container, topics, types, joint names, rate, stamps) is
    checked before the robot's library is generated or loaded.

    Raises:
        LogError: the log cannot be used (one line: what, found, fix).
        ConfigError, RunFolderError: bad settings, an existing ``out`` without ``force``, an
            ``out`` that is, holds or lies inside an input (the log), even with ``force``.
    """
    inputs = [p for p in (log_path, options.scenario, options.log_spec) if p and Path(p).exists()]
    if log_path.is_file() and (log_path.parent / "metadata.yaml").is_file():
        inputs.append(log_path.parent)  # the .mcap of a bag folder: the folder is the log
    check_output(out, option="--out", force=options.force, inputs=inputs)
    spec = read_log_spec(options.log_spec)
    t0 = time.perf_counter()
    topics = log_topics(log_path)
    config = read_config(log_path, spec, topics)
    sc = _scenario(log_path, config, options)
    name, joints, T, N = _robot_of(sc.robot)
    plan = plan_log(log_path, spec, joints)
    if options.verbose:
        for line in plan.lines():
            print(f"  {line}")
    derived = None
    try:
        log = read_log(log_path, spec, joints, T, N, plan, robot=name)
    except LogRateError as exc:  # the robot generated at the log's period, if it is cached
        derived = _generated_at_period(sc.robot, exc.period)
        if derived is None:
            raise
        if options.verbose:
            print(f"  the log's period {exc.period:g} s: library {derived.name} (cached)")
        log = read_log(log_path, spec, joints, derived.model.T, N, plan, robot=name)
    log.config = config
    _effort_support(log.effort_kind, log_path)
    if options.scenario is None and (options.robot is not None or config is None):
        sc = _start_from_log(sc, log)  # --robot: the defaults, started from the log
    read_s = time.perf_counter() - t0
    if options.verbose:
        c = log.clock
        print(
            f"  clock: log time - header stamp = {c.median:+.6f} s (spread {c.spread:.2e} s); "
            "log times moved onto the stamp clock"
        )
    from amsfe_sym.codegen import library_for

    lib = library_for(sc, robot=derived)
    est, feed = _estimator(sc, lib, log, options)
    t1 = time.perf_counter()
    from amsfe_sym.logs.replay import estimate_log

    result = estimate_log(feed, est)
    estimate_s = time.perf_counter() - t1
    run = EstimateRun(log, result, sc, out, read_s, estimate_s)
    _write(run, lib.manifest.joints, options)
    return run


def _estimator(sc: Scenario, lib: Any, log: RobotLog, options: EstimateOptions) -> Any:
    """The estimator and the log it is fed (for a non-applied effort: the inputs and
    encoder measurements :mod:`amsfe_sym.estimation.effort` derives)."""
    from amsfe_sym.sim.builders import build_estimator, build_sensors, scenario_timing

    sensors = build_sensors(sc, lib, np.random.default_rng(sc.seed), scenario_timing(sc, lib))
    compiled = options.runtime == "compiled"
    if log.effort_kind == "applied":
        return build_estimator(sc, lib, sensors, log.z[0], compiled=compiled), log
    import importlib

    # issue 26.3's effort kinds (helper modules typed as Any until they are in every build)
    eff = importlib.import_module("amsfe_sym.estimation.effort")
    builders = importlib.import_module("amsfe_sym.sim.builders")
    spec = eff.EffortSpec(kind=log.effort_kind)
    est = builders.build_estimator(sc, lib, sensors, log.z[0], compiled=False, effort=spec)
    qd_std = sc.filter.encoder_qd_std or np.sqrt(sensors.encoders.variance[lib.n :])
    inputs = eff.estimator_inputs(spec, log.z, log.effort, builders.motor_params(lib), qd_std)
    return est, replace(log, u=inputs.u, z=inputs.z_encoder)


def _finite(x: float) -> float | None:
    """A number for JSON: None where it is not finite (NaN is not JSON)."""
    return float(x) if math.isfinite(x) else None


def _frame_nis(est: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """(arrival step, NIS) of each frame given to the estimator, from the replay's
    ``frame_nis`` (arrays ``arrival``, ``nis``; or records with those fields), or None."""
    fr: Any = getattr(est, "frame_nis", None)
    if fr is None:
        return None
    if hasattr(fr, "nis") and hasattr(fr, "arrival"):
        return np.asarray(fr.arrival, dtype=np.float64), np.asarray(fr.nis, dtype=np.float64)
    rows = [(_field(r, "arrival", 1), _field(r, "nis", 2)) for r in fr]
    arr = np.asarray(rows, dtype=np.float64).reshape(-1, 2)
    return arr[:, 0], arr[:, 1]


def _field(record: Any, name: str, index: int) -> Any:
    if isinstance(record, dict):
        return record.get(name)
    if hasattr(record, name):
        return getattr(record, name)
    return record[index]


def _nis_stats(values: np.ndarray, dof: int) -> dict[str, Any]:
    from scipy.stats import chi2

    lo, hi = (float(v) for v in chi2.ppf([0.025, 0.975], dof))
    v = values[np.isfinite(values)]
    inside = float(np.mean((v >= lo) & (v <= hi))) if v.size else math.nan
    return {
        "dof": dof,
        "samples": int(v.size),
        "mean": _finite(float(np.mean(v))) if v.size else None,
        "band_95": [lo, hi],
        "inside_95": _finite(inside),
    }


def nis_report(run: EstimateRun) -> dict[str, Any]:
    """Normalized innovation squared of the encoder updates (dof 2n; 3n with a joint
    torque) and of the camera frames (dof 2): mean and the fraction inside the two-sided
    chi-square 95 % band.  A filter whose model and noise fit the arm has mean NIS near the
    dof and about 95 % inside (docs/logs.md, "Consistency without truth").  Empty where the
    replay did not record NIS."""
    est, log = run.estimate, run.log
    n = log.u.shape[1]
    out: dict[str, Any] = {}
    enc: Any = getattr(est, "encoder_nis", None)
    if enc is not None and len(enc):
        dof = 3 * n if log.effort_kind == "joint_torque" else 2 * n
        out["encoders"] = _nis_stats(np.asarray(enc, dtype=np.float64), dof)
    frames = _frame_nis(est)
    if frames is not None:
        out["camera"] = _nis_stats(frames[1], 2)
    return out


def summary(run: EstimateRun) -> dict[str, Any]:
    """The ``summary.json`` of an estimate run (every number finite or null)."""
    log, est = run.log, run.estimate
    n = len(log.u[0])
    out: dict[str, Any] = {
        "log": str(log.path),
        "estimator": run.scenario.estimator,
        "ticks": log.K,
        "duration_s": log.K * log.T,
        "frames_fused": est.counters.get("frames_applied", 0),
        "counters": est.counters,
        "topics": {r: u.as_dict() for r, u in log.usage.items()},
        "effort_kind": log.effort_kind,
        "log_period_s": _finite(log.period_s),
        "clock_offset_s": _finite(log.clock.median),
        "clock_offset_spread_s": _finite(log.clock.spread),
        "nis": nis_report(run),
        "read_s": round(run.read_s, 4),
        "estimate_s": round(run.estimate_s, 4),
        "real_time_factor": round(log.K * log.T / max(run.read_s + run.estimate_s, 1e-9), 2),
    }
    if log.truth is not None and est.nees is not None:
        w = slice(int(0.2 * log.K), log.K)
        err = log.truth[w] - est.x_hat[w]
        with np.errstate(all="ignore"):
            rmse = np.sqrt(np.nanmean(err[:, :n] ** 2, axis=0))
            nees = float(np.nanmean(est.nees[w])) if np.isfinite(est.nees[w]).any() else math.nan
        out["estimation_rmse_q"] = [_finite(float(v)) for v in rmse]
        out["nees_mean"] = _finite(nees)
        out["nees_dof"] = int(est.x_hat.shape[1])
    out["provenance"] = provenance()
    return out


def add_arguments(e: argparse.ArgumentParser) -> None:
    """The options of ``amsfe estimate``."""
    e.add_argument("log", help="a ROS 1 .bag, a rosbag2 folder or an .mcap file")
    e.add_argument(
        "--robot",
        default=None,
        help="the robot (name or robot.toml) for a log not written by amsfe",
    )
    e.add_argument("--scenario", default=None, help="robot + filter settings, to tune the filter")
    e.add_argument(
        "--log-spec", default=None, metavar="FILE", help="topics, joint names, effort kind (TOML)"
    )
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
        args.scenario,
        args.log_spec,
        args.estimator,
        args.runtime,
        not args.no_plots,
        args.force,
        robot=args.robot,
        verbose=True,
    )
    print_summary(summary(estimate_command(log, out, opts)), out)
    return 0


def print_summary(s: dict[str, Any], out: Path) -> None:
    """The headline of an estimate run: ticks, frames fused, each role's messages used and
    skipped, speed, NIS and NEES."""
    c = s["counters"]
    print(f"run folder: {out} ({s['ticks']} ticks, {s['duration_s']:.2f} s of log)")
    print(
        f"  {s['estimator']}: {s['frames_fused']} camera frames fused; read {s['read_s']:.2f} s, "
        f"estimated {s['estimate_s']:.2f} s ({s['real_time_factor']:.0f}x real time)"
    )
    for role, u in s.get("topics", {}).items():
        if u["topic"] is None:
            other = u.get("topics_of_this_type_not_used")
            print(
                f"  {role}: no topic"
                + (f"; not used: {other} (name one in [topics] {role})" if other else "")
            )
            continue
        why = ", ".join(f"{k} {v}" for k, v in u["skipped"].items()) or "none"
        print(f"  {role} {u['topic']}: {u['messages']} messages, {u['used']} used; skipped: {why}")
        for note, count in u.get("notes", {}).items():
            print(f"    note: {count} {note}")
    refused = {k: v for k, v in c.items() if v and k.startswith("refused")}
    if refused:
        print("  refused by the estimator: " + ", ".join(f"{k} {v}" for k, v in refused.items()))
    for what, r in s.get("nis", {}).items():
        if r["mean"] is None:
            print(f"  NIS {what}: no samples")
            continue
        lo, hi = r["band_95"]
        print(
            f"  NIS {what}: mean {r['mean']:.2f} (dof {r['dof']}), "
            f"{100 * (r['inside_95'] or 0):.1f} % of {r['samples']} inside the 95 % band "
            f"[{lo:.2f}, {hi:.2f}]"
        )
    if s.get("nees_mean") is not None:
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

        # a bag's times are unsigned: a sim-time log whose first stamp is jittered below 0
        # starts its estimates at 0 (moved by less than T / 2)
        start = max(log.t0_ns, 0) * 1e-9
        write_estimate_bag(tmp / "estimates", start, log.t, joints, est.x_hat, est.P_diag)
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
    _nis_figure(run, folder)


def _nis_figure(run: EstimateRun, folder: Path) -> None:
    """``nis.png``: NIS of the encoder updates and of the camera frames over time, with
    their chi-square 95 % bands (nothing drawn where the replay recorded no NIS)."""
    import matplotlib.pyplot as plt

    log, est = run.log, run.estimate
    rep = nis_report(run)
    if not rep:
        return
    fig, axes = plt.subplots(len(rep), 1, figsize=(8, 2.6 * len(rep) + 0.6), squeeze=False)
    for ax, (what, r) in zip(axes[:, 0], rep.items(), strict=True):
        if what == "encoders":
            t, v = log.t, np.asarray(getattr(est, "encoder_nis", None), dtype=np.float64)
            ax.plot(t, v, lw=0.3, alpha=0.5, label="encoder update")
            w = max(1, len(v) // 100)  # its running mean over 1 % of the log
            ok = np.isfinite(v)
            mean = np.convolve(np.where(ok, v, 0), np.ones(w), "same") / np.maximum(
                np.convolve(ok, np.ones(w), "same"), 1
            )
            ax.plot(t, mean, lw=1.0, color="k", label=f"running mean ({w} ticks)")
        else:
            arrival, v = _frame_nis(est) or (np.zeros(0), np.zeros(0))
            ax.plot(arrival * log.T, v, ".", ms=3, label="camera frame (at its arrival)")
        lo, hi = r["band_95"]
        ax.axhspan(lo, hi, color="g", alpha=0.12, label=f"chi2({r['dof']}) 95 % band")
        ax.axhline(r["dof"], color="g", lw=0.6)
        ax.set_yscale("log")
        ax.set_ylabel(f"NIS {what}")
        ax.legend(loc="upper right", fontsize=7)
    axes[-1, 0].set_xlabel("t [s]")
    fig.suptitle(f"consistency without truth: NIS on {log.path.name}")
    fig.tight_layout()
    fig.savefig(folder / "nis.png", dpi=110)
    plt.close(fig)


def default_out(log_path: Path) -> Path:
    """``runs/estimate-<log name>-<UTC time>``."""
    from datetime import datetime, timezone

    stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
    return Path("runs") / f"estimate-{log_path.stem}-{stamp}"
