"""Closed-loop simulation: plant (truth) -> sensors -> estimator -> controller.

One tick k (t_k = k T):

1. the sensors read the true plant state x_k: encoders every step, the camera exposes
   every l steps and delivers frames d steps later (``amsfe_sym.sim.sensors``);
2. the estimator advances from k-1 to k with u_{k-1}, the encoder sample and the frames
   delivered at k (``amsfe_sym.estimation``);
3. the controller computes u_k (``amsfe_sym.control``);
4. the plant integrates over [t_k, t_k + T] with u_k held (compiled RK4, ``plant_step``),
   with the true theta and optional disturbance torques.

The plant is the continuous-time Spong model, deliberately not the estimator's discrete
map, so the estimator meets model error as on a real arm.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.codegen import generate
from amsfe_sym.control import make_controller
from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.estimation import FilterConfig, make_estimator
from amsfe_sym.preflight import check_scenario_shapes
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.runtime.models import (
    CameraMeasurement,
    CompiledTransition,
    EncoderMeasurement,
    noise_covariance,
)
from amsfe_sym.scenario import Scenario, dump_toml, load_scenario
from amsfe_sym.sim import trajectory_from_config
from amsfe_sym.sim.sensors import Camera, CameraConfig, Disturbance, EncoderConfig, Encoders
from amsfe_sym.spec import load_spec

__all__ = ["RunResult", "run", "run_from_cli", "summarize", "write_run"]

log = logging.getLogger(__name__)
FloatArray = NDArray[np.float64]


@dataclass
class RunResult:
    """Everything a run produced.

    Attributes:
        scenario: The resolved scenario.
        lib: The model library used.
        t: Times [s], shape (K,).
        x_true: True state [q, qd, qm, qmd, theta] at each tick, (K, N).
        x_hat: Posterior estimate x(k|k), (K, N).
        P_diag: Diagonal of P(k|k), (K, N).
        nees: Normalised estimation error squared e^T P^-1 e, (K,).
        q_des: Desired link angles, (K, n).
        u: Motor torques [N m], (K, n).
        z_enc: Encoder samples, (K, 2n).
        frames: Delivered camera frames: rows (exposure step, delivery step, u px, v px).
        wall_time_s: Wall time of the loop [s].
        counters: Sensor and estimator counts (frames applied, rejected, ...).
    """

    scenario: Scenario
    lib: ModelLibrary
    t: FloatArray
    x_true: FloatArray
    x_hat: FloatArray
    P_diag: FloatArray
    nees: FloatArray
    q_des: FloatArray
    u: FloatArray
    z_enc: FloatArray
    frames: FloatArray
    wall_time_s: float
    counters: dict[str, int] = field(default_factory=dict)


def _vec(values: tuple[float, ...], n: int, what: str) -> FloatArray:
    if len(values) != n:
        raise ConfigError(describe(what, f"{n} values", f"{len(values)}", "one per joint"))
    return np.array(values, dtype=float)


def library_for(sc: Scenario) -> ModelLibrary:
    """Generate (or reuse) the library of the scenario's robot, with its integrator override."""
    spec = load_spec(sc.robot)
    check_scenario_shapes(sc, spec)  # every wrong-length vector, before generating
    if sc.integrator and sc.integrator != spec.model.integrator:
        spec = replace(
            spec,
            name=f"{spec.name}_{sc.integrator}",
            model=replace(spec.model, integrator=sc.integrator),  # type: ignore[arg-type]
        )
    return ModelLibrary(generate(spec).out_dir)


def run(
    scenario: Scenario,
    lib: ModelLibrary | None = None,
    progress: bool = False,
) -> RunResult:
    """Simulate ``scenario`` and return the recorded signals (nothing is written)."""
    sc = scenario
    if lib is None:
        lib = library_for(sc)
    n, p, N, T = lib.n, lib.p, lib.N, lib.T
    L = lib.layout
    K = round(sc.duration / T) + 1
    rng = np.random.default_rng(sc.seed)
    rng_enc, rng_cam, rng_dist = rng.spawn(3)
    theta_true = lib.theta_true
    Ks = lib.stiffness(theta_true)

    # ---------------------------------------------------------------- plant start
    q0 = _vec(sc.plant.q0, n, "[plant] q0")
    qd0 = _vec(sc.plant.qd0, n, "[plant] qd0")
    if sc.plant.motor0 == "equilibrium":
        g = lib.function("gravity")(q0, theta_true)[0]
        qm0, qmd0 = q0 + g / Ks, qd0.copy()
    elif sc.plant.motor0 == "link":
        qm0, qmd0 = q0.copy(), qd0.copy()
    else:
        qm0 = _vec(sc.plant.qm0, n, "[plant] qm0")
        qmd0 = _vec(sc.plant.qmd0, n, "[plant] qmd0")
    xp = np.concatenate([q0, qd0, qm0, qmd0])

    # ---------------------------------------------------------------- sensors
    enc = Encoders(
        n,
        EncoderConfig(
            q_std=sc.encoders.q_std,
            qd_std=sc.encoders.qd_std,
            counts_per_rev=sc.encoders.counts_per_rev or None,
        ),
        rng_enc,
    )
    cam_spec = lib.manifest["camera"]
    cam_cfg = CameraConfig(
        period=sc.camera.period or int(cam_spec["period"]),
        delay=sc.camera.delay or int(cam_spec["delay"]),
        phase=sc.camera.phase,
        pixel_std=sc.camera.pixel_std,
        round_to_pixel=sc.camera.round_to_pixel,
        drop_probability=sc.camera.drop_probability,
        jitter_steps=sc.camera.jitter_steps,
        width=int(cam_spec["width"]),
        height=int(cam_spec["height"]),
    )
    cam_fn = lib.function("camera_measure")

    def project(q: FloatArray) -> FloatArray:
        y, _J, depth = cam_fn.call_into(q, theta_true)
        return y.copy() if depth[0] > 0 else np.full(2, np.nan)

    camera = Camera(cam_cfg, project, rng_cam)
    disturbance = Disturbance(n, sc.plant.link_torque_std, sc.plant.motor_torque_std, rng_dist)

    # ---------------------------------------------------------------- estimator
    f = sc.filter
    latency = cam_cfg.delay + cam_cfg.jitter_steps
    if sc.estimator in ("replay", "oosm", "cloning") and latency > f.buffer_steps:
        raise ConfigError(
            describe(
                "[filter] buffer_steps",
                f">= camera delay + jitter = {latency} steps",
                str(f.buffer_steps),
                "raise buffer_steps or shorten the delay",
            )
        )
    model = CompiledTransition(
        lib, noise_covariance(lib, f.link_torque_std, f.motor_torque_std, f.theta_rate_std)
    )
    enc_var = enc.variance
    encoder_model = EncoderMeasurement(
        lib,
        f.encoder_q_std**2 if f.encoder_q_std else enc_var[:n],
        f.encoder_qd_std**2 if f.encoder_qd_std else enc_var[n:],
    )
    cam_var = f.camera_pixel_std**2 if f.camera_pixel_std else cam_cfg.variance
    if cam_var <= 0:
        raise ConfigError(
            describe(
                "[filter] camera_pixel_std",
                "a positive camera noise for the filter's R",
                "0, and a noise-free camera that does not round to pixels",
                "set [filter] camera_pixel_std > 0 (an exact camera makes R singular)",
            )
        )
    camera_model = CameraMeasurement(lib, cam_var)
    z0 = enc.measure(xp[L["qm"]], xp[L["qmd"]])
    e0 = sc.estimate0
    th0 = np.array(e0.theta, dtype=float) if e0.theta else lib.theta_initial
    x0 = np.concatenate(
        [
            _vec(e0.q, n, "[estimate0] q"),
            _vec(e0.qd, n, "[estimate0] qd"),
            z0[:n] if e0.motor == "encoders" else _vec(e0.q, n, "q"),
            z0[n:] if e0.motor == "encoders" else _vec(e0.qd, n, "qd"),
            th0,
        ]
    )
    std = {"q": 0.5, "qd": 0.5, "qm": 0.01, "qmd": 0.1, "theta": 0.2, **dict(e0.std)}
    P0 = np.diag(
        np.concatenate(
            [
                np.full(n, std["q"]),
                np.full(n, std["qd"]),
                np.full(n, std["qm"]),
                np.full(n, std["qmd"]),
                np.full(p, std["theta"]),
            ]
        )
        ** 2
    )
    est = make_estimator(
        sc.estimator,
        model=model,
        encoder=encoder_model,
        camera=camera_model,
        x0=x0,
        P0=P0,
        config=FilterConfig(
            gate_probability=f.gate_probability or None,
            camera_iterations=f.camera_iterations,
            buffer_steps=f.buffer_steps,
            camera_period=cam_cfg.period,
            camera_phase=cam_cfg.phase,
            camera_max_latency=latency,
        ),
    )

    # ---------------------------------------------------------------- controller
    traj = trajectory_from_config(dict(sc.trajectory))
    if traj.n != n:
        raise ConfigError(
            describe(
                "[trajectory]",
                f"{n} joints (the robot's)",
                f"{traj.n}",
                "give one value per modelled joint in the trajectory table",
            )
        )
    ctrl = make_controller(sc.controller, lib, traj, sc.controller_gains)
    plant = lib.function("plant_step")

    # ---------------------------------------------------------------- records
    t: FloatArray = np.arange(K, dtype=float) * T
    x_true = np.zeros((K, N))
    x_hat = np.zeros((K, N))
    P_diag = np.zeros((K, N))
    nees = np.zeros(K)
    q_des = traj.evaluate(t).q.reshape(K, n)
    ctrl.prepare(t)
    u_rec = np.zeros((K, n))
    z_rec = np.zeros((K, 2 * n))
    frames_rec: list[tuple[float, float, float, float]] = []
    counters = {"frames_applied": 0, "frames_rejected": 0, "encoder_rejected": 0}

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=K, desc=f"{sc.name} [{sc.estimator}]", unit="tick", mininterval=0.5)
    u = np.zeros(n)
    x_t = np.zeros(N)
    x_t[4 * n :] = theta_true
    t0 = time.perf_counter()
    for k in range(K):
        x_t[: 4 * n] = xp
        # 1. sensors at t_k
        z = z0 if k == 0 else enc.measure(xp[L["qm"]], xp[L["qmd"]])
        delivered = camera.tick(k, xp[L["q"]])
        for fr in delivered:
            frames_rec.append((fr.exposure_step, k, float(fr.z[0]), float(fr.z[1])))
        # 2. estimator k-1 -> k
        if k > 0:
            rep = est.step(u, z, delivered)
            counters["frames_applied"] += rep.frames_applied
            counters["frames_rejected"] += rep.frames_rejected
            counters["encoder_rejected"] += int(not rep.encoder_accepted)
        xh, P = est.x, est.P
        # 3. controller
        u = ctrl.torque(k, float(t[k]), xp, theta_true, xh)
        # record
        x_true[k] = x_t
        x_hat[k] = xh
        P_diag[k] = np.diag(P)
        err = x_t - xh
        nees[k] = float(err @ np.linalg.solve(P, err))
        u_rec[k] = u
        z_rec[k] = z
        # 4. plant over [t_k, t_k + T]
        if k + 1 < K:
            dist = disturbance.sample()
            tau = np.concatenate([dist.link, dist.motor])
            xp = plant.call_into(xp, u, theta_true, tau)[0].copy()
            if not np.all(np.isfinite(xp)):
                raise ConfigError(
                    describe(
                        "plant state",
                        "finite values",
                        f"NaN/inf at t = {t[k]:.3f} s",
                        "the closed loop diverged: check gains, T and the integrator",
                    )
                )
        if bar is not None and k % 250 == 0:
            bar.update(min(250, K - bar.n))
    wall = time.perf_counter() - t0
    if bar is not None:
        bar.update(K - bar.n)
        bar.close()
    stats = camera.stats
    counters.update(
        {
            "frames_exposed": int(stats.exposed),
            "frames_delivered": int(stats.delivered),
            "frames_dropped": int(stats.dropped),
            "frames_out_of_image": int(stats.out_of_image),
        }
    )
    return RunResult(
        scenario=sc,
        lib=lib,
        t=t,
        x_true=x_true,
        x_hat=x_hat,
        P_diag=P_diag,
        nees=nees,
        q_des=q_des,
        u=u_rec,
        z_enc=z_rec,
        frames=np.array(frames_rec, dtype=float).reshape(-1, 4),
        wall_time_s=wall,
        counters=counters,
    )


def summarize(res: RunResult) -> dict[str, Any]:
    """``summary.json``: RMSEs over the last 80 % of the run, NEES, timings, counters."""
    lib, sc = res.lib, res.scenario
    L = lib.layout
    K = res.t.size
    s = slice(int(0.2 * K), K)
    e = (res.x_true - res.x_hat)[s]

    def rmse(cols: slice) -> list[float]:
        return [float(v) for v in np.sqrt(np.mean(e[:, cols] ** 2, axis=0))]

    track = res.x_true[s, L["q"]] - res.q_des[s]
    return {
        "scenario": sc.name,
        "robot": lib.name,
        "estimator": sc.estimator,
        "controller": sc.controller,
        "seed": sc.seed,
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
    }


def write_run(res: RunResult, out: Path, plots: bool = True) -> Path:
    """Write config.toml, timeseries.csv, frames.csv, summary.json (+ figures) to ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    lib = res.lib
    cfg = res.scenario.to_dict()
    (out / "config.toml").write_text(
        f"# resolved scenario of run {out.name}: `amsfe simulate {out}/config.toml` re-runs it\n"
        + dump_toml(cfg)
    )
    names = ["t"]
    state = [f"{b}{i + 1}" for b in ("q", "qd", "qm", "qmd") for i in range(lib.n)]
    state += [t["name"] for t in lib.manifest["theta"]]
    names += [f"true_{s}" for s in state] + [f"est_{s}" for s in state]
    names += [f"var_{s}" for s in state] + ["nees"]
    names += [f"q_des{i + 1}" for i in range(lib.n)] + [f"u{i + 1}" for i in range(lib.n)]
    names += [f"enc_qm{i + 1}" for i in range(lib.n)] + [f"enc_qmd{i + 1}" for i in range(lib.n)]
    table = np.column_stack(
        [res.t, res.x_true, res.x_hat, res.P_diag, res.nees, res.q_des, res.u, res.z_enc]
    )
    np.savetxt(
        out / "timeseries.csv",
        table,
        delimiter=",",
        header=",".join(names),
        comments="",
        fmt="%.10g",
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
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    if plots:
        from amsfe_sym.plots import plot_run

        plot_run(res, out)
    return out / "summary.json"


def run_from_cli(args: Any) -> int:
    """``amsfe simulate`` (see :mod:`amsfe_sym.cli`)."""
    sc = load_scenario(args.scenario).with_overrides(
        estimator=args.estimator,
        controller=args.controller,
        seed=args.seed,
        duration=args.duration,
    )
    res = run(sc, progress=not args.no_progress)
    stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else Path("runs") / f"{sc.name}-{sc.estimator}-{stamp}"
    write_run(res, out, plots=not args.no_plots)
    s = summarize(res)
    print(f"run folder: {out}")
    print(
        f"  {s['ticks']} ticks ({s['sim_time_s']:.2f} s simulated) in {s['wall_time_s']:.2f} s "
        f"wall, {s['cost_per_tick_us']:.1f} us/tick"
    )
    er = s["estimation_rmse"]
    print(
        f"  estimation RMSE (last 80 %): q {np.round(er['q'], 5).tolist()} rad, "
        f"qd {np.round(er['qd'], 4).tolist()} rad/s, theta {np.round(er['theta'], 4).tolist()}"
    )
    print(
        f"  theta: true {s['theta_final']['true']}, final estimate "
        f"{np.round(s['theta_final']['estimate'], 4).tolist()}"
    )
    print(
        f"  tracking RMSE: {np.round(s['tracking_rmse']['q'], 4).tolist()} rad; "
        f"mean NEES {s['nees_mean']:.2f} (N = {s['nees_dof']})"
    )
    return 0
