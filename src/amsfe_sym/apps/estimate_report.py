"""What ``amsfe estimate`` reports about a run: ``summary.json`` (each role's messages used
and skipped, the clock offset, NIS), the printed headline and the figure (``estimate.png``,
its NIS row too); docs/how-to/logs.md, "Consistency without truth"."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from amsfe_sym.core.provenance import provenance
from amsfe_sym.logs.read import RobotLog
from amsfe_sym.scenario import Scenario

if TYPE_CHECKING:  # the estimators (scipy) are imported when a log is estimated
    from amsfe_sym.logs.noise import EncoderNoise
    from amsfe_sym.logs.replay import LogEstimate

__all__ = [
    "CommandTiming",
    "EstimateRun",
    "figures",
    "nis_advice",
    "nis_report",
    "print_summary",
    "summary",
]


@dataclass(frozen=True)
class CommandTiming:
    """Wall time [s] of the phases of ``amsfe estimate`` other than reading and estimating
    (docs/how-to/logs.md, "Speed"); each phase includes the imports made in it.

    Attributes:
        startup_s: From the process's start to the command's: the interpreter, the
            command line's imports, argument parsing.  None when not measured (called from
            Python, or no ``/proc/self/stat``).
        setup_s: The log spec checked, the scenario and the robot's spec, the start from the
            log, the estimator built.
        library_s: The robot's library found in the cache and loaded (or generated).
        write_s: The run folder: ``estimates.parquet``, ``config.toml``, the estimates bag,
            the figures.
        wall_s: From the command's start to its summary: setup + library + read + estimate
            + write (start-up not included).
    """

    startup_s: float | None = None
    setup_s: float = 0.0
    library_s: float = 0.0
    write_s: float = 0.0
    wall_s: float = 0.0


@dataclass
class EstimateRun:
    """What ``amsfe estimate`` did: the read log, the estimates, the folder and the timing
    (``read_s``: the log read, topic search included; ``estimate_s``: the estimator over
    it; ``timing``: the other phases, set once the folder is written; ``noise``: the encoder
    noise measured from the log, when it was; ``figures_s``: the figures' part of the
    write [s])."""

    log: RobotLog
    estimate: LogEstimate
    scenario: Scenario
    out: Path
    read_s: float
    estimate_s: float
    timing: CommandTiming = field(default_factory=CommandTiming)
    noise: EncoderNoise | None = None
    figures_s: float = 0.0


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
    from amsfe_sym.estimation.ekf import chi2_ppf

    lo, hi = (float(v) for v in chi2_ppf([0.025, 0.975], dof))
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
    dof and about 95 % inside (docs/how-to/logs.md, "Consistency without truth").  Empty where the
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


def nis_advice(
    what: str,
    r: dict[str, Any],
    sc: Scenario,
    effort_kind: str,
    noise: EncoderNoise | None = None,
) -> str | None:
    """One line when the mean NIS of channel ``what`` (``encoders``, ``camera``; ``r`` from
    :func:`nis_report`) is outside its 95 % band: which way the filter is off and which R
    and Q keys to change (the log spec's or a scenario's ``[filter]``, ``[effort]``), with
    their present values; for the encoders, when the encoder noise measured from the log
    (``noise``) is more than 2x from the filter's R the way the advice goes, that noise and
    the keys that use it.  None inside the band or without samples."""
    mean, (lo, hi) = r.get("mean"), r["band_95"]
    if mean is None or lo <= mean <= hi:
        return None
    f = sc.filter
    q_keys = f"link_torque_std, motor_torque_std (now {f.link_torque_std:g}, "
    q_keys += f"{f.motor_torque_std:g} N m)"
    if effort_kind == "none":
        q_keys += "; [effort] input_rate_std"
    measured = ""
    if what == "camera":
        px = f.camera_pixel_std or sc.camera.pixel_std
        r_keys = f"[filter] camera_pixel_std (now {px:g} px)"
    else:
        q_std = f.encoder_q_std or sc.encoders.q_std
        qd_std = f.encoder_qd_std or sc.encoders.qd_std
        r_keys = f"[filter] encoder_q_std, encoder_qd_std (now {q_std:.2g} rad, {qd_std:.2g} rad/s)"
        if effort_kind == "joint_torque":
            r_keys += ", [effort] joint_torque_std"
        measured = _measured_hint(noise, (q_std, qd_std), lower=mean < lo)
    if mean < lo:
        return (
            f"NIS {what} mean {mean:.3g} below its band: the filter is pessimistic (it claims "
            f"more noise than the data show): lower R {r_keys} or Q [filter] {q_keys}" + measured
        )
    return (
        f"NIS {what} mean {mean:.3g} above its band: the filter is optimistic (the data "
        f"vary more than it allows, or the model misses something): raise Q [filter] "
        f"{q_keys} or R {r_keys}" + measured
    )


def _measured_hint(noise: EncoderNoise | None, r: tuple[float, float], lower: bool) -> str:
    """``; the log's encoder noise ...`` when a measured median is more than 2x below
    (``lower``) or above the filter's R [rad, rad/s], else empty."""
    if noise is None or noise.q_std is None or noise.qd_std is None:
        return ""
    ratios = (r[0] / noise.q_std, r[1] / noise.qd_std) if noise.q_std and noise.qd_std else ()
    if not any((x > 2.0) if lower else (x < 0.5) for x in ratios):
        return ""
    return (
        f"; the log's encoder noise is q {noise.q_std:.1e} rad, qd {noise.qd_std:.1e} rad/s: "
        'encoder_q_std = "log", encoder_qd_std = "log" use it'
    )


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
        "nis": _with_advice(nis_report(run), run),
        "encoder_noise_from_log": _noise_dict(run.noise),
        "read_s": round(run.read_s, 4),
        "estimate_s": round(run.estimate_s, 4),
        "real_time_factor": round(log.K * log.T / max(run.read_s + run.estimate_s, 1e-9), 2),
        "timing": _timing(run),
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


def _with_advice(nis: dict[str, Any], run: EstimateRun) -> dict[str, Any]:
    """Each NIS channel of :func:`nis_report` with its ``advice`` (:func:`nis_advice`)
    where its mean is outside the band."""
    for what, r in nis.items():
        advice = nis_advice(what, r, run.scenario, run.log.effort_kind, run.noise)
        if advice:
            r["advice"] = advice
    return nis


def _noise_dict(noise: EncoderNoise | None) -> dict[str, Any] | None:
    """The measured encoder noise for ``summary.json`` (None: not measured)."""
    if noise is None:
        return None
    return {
        "q_std_median": noise.q_std,
        "qd_std_median": noise.qd_std,
        "q_std": [c.std for c in noise.q],
        "qd_std": [c.std for c in noise.qd],
        "repeated_rows": noise.repeated,
    }


def _timing(run: EstimateRun) -> dict[str, float | None]:
    """The command's phases [s] and its real-time factors: the log's duration over the
    command's wall time (``real_time_factor_command``) and over start-up + wall time
    (``real_time_factor_end_to_end``, null when start-up was not measured); docs/how-to/logs.md,
    "Speed"."""
    t, d = run.timing, run.log.K * run.log.T
    whole = None if t.startup_s is None else t.startup_s + t.wall_s

    def r(x: float | None) -> float | None:
        return None if x is None else round(x, 4)

    return {
        "startup_s": r(t.startup_s),
        "setup_s": r(t.setup_s),
        "library_s": r(t.library_s),
        "read_s": r(run.read_s),
        "estimate_s": r(run.estimate_s),
        "write_s": r(t.write_s),
        "wall_s": r(t.wall_s),
        "end_to_end_s": r(whole),
        "real_time_factor_command": round(d / t.wall_s, 2) if t.wall_s > 0 else None,
        "real_time_factor_end_to_end": round(d / whole, 2) if whole else None,
    }


def _speed_line(s: dict[str, Any]) -> str:
    """What the run's speed was: reading + estimating, then the whole command by phase."""
    line = (
        f"  speed: read {s['read_s']:.3f} s + estimated {s['estimate_s']:.3f} s = "
        f"{s['real_time_factor']:.0f}x real time"
    )
    t = s.get("timing") or {}
    if not t.get("wall_s"):
        return line
    phases = {
        "start-up": t.get("startup_s"),
        "setup": t["setup_s"],
        "library": t["library_s"],
        "read + estimate": s["read_s"] + s["estimate_s"],
        "writing": t["write_s"],
    }
    parts = [f"{name} {v:.2f}" for name, v in phases.items() if v is not None]
    if t.get("end_to_end_s") is not None:
        whole = f"command {t['end_to_end_s']:.2f} s = {t['real_time_factor_end_to_end']:.0f}x"
        after = f"; {t['real_time_factor_command']:.0f}x after start-up"
    else:
        whole = f"command {t['wall_s']:.2f} s = {t['real_time_factor_command']:.0f}x"
        after = ""
    return f"{line}; {whole} ({', '.join(parts)}{after})"


def print_summary(s: dict[str, Any], out: Path) -> None:
    """The headline of an estimate run: ticks, frames fused, each role's messages used and
    skipped, speed, NIS and NEES."""
    c = s["counters"]
    print(f"run folder: {out} ({s['ticks']} ticks, {s['duration_s']:.2f} s of log)")
    print(f"  {s['estimator']}: {s['frames_fused']} camera frames fused")
    print(_speed_line(s))
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
        if r.get("advice"):
            print(f"    {r['advice']}")
    if s.get("nees_mean") is not None:
        print(f"  mean NEES {s['nees_mean']:.2f} (N = {s['nees_dof']}) against the log's truth")


def figures(run: EstimateRun, folder: Path) -> None:
    """``estimate.png`` (per joint: the error against the truth with +-2 sigma, or the
    spring deflection and the encoder residual; below, a row with the NIS over time)
    (:func:`~amsfe_sym.apps.plots.log.plot_log`)."""
    from amsfe_sym.apps.plots.log import NisSeries, plot_log

    est = run.estimate
    enc = getattr(est, "encoder_nis", None)
    nis = NisSeries(
        nis_report(run),
        None if enc is None else np.asarray(enc, dtype=np.float64),
        _frame_nis(est),
    )
    plot_log(run.log, est.x_hat, est.P_diag, run.scenario.estimator, nis, folder)
