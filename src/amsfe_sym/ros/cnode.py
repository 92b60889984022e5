"""``amsfe node --impl c``: the node's per-sample path in C on rcl (``ros/c/amsfe_node*.c``),
configured from Python, started and waited for (docs/live-control.md); its build is
:mod:`amsfe_sym.ros.cnode_build`, its record :mod:`amsfe_sym.ros.cnode_record`.

- :func:`write_params` writes what the C node reads: the estimator's and the controller's
  parameter blocks as :func:`amsfe_sym.sim.compiled.run_compiled` builds them (the same
  builders), the reference per tick (a binary file), and the topic spec resolved (topics,
  joint order, QoS depths, the rates, the watchdogs' bounds) with the node's options.
- :func:`run_c_node` resolves the spec's ROS parameters (``-p``) with rclpy as the Python
  node does, starts the C node with the ``--ros-args`` (rcl applies the remaps), forwards
  Ctrl-C / SIGTERM, returns its exit code and, with ``--record``, writes the record from the
  arrays the C node wrote at its stop: the sample path stays free of Python.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.ros.cnode_build import (
    CNodeBuild,
    build_node,
    external_build,
    ros_paths,
    run_program,
)
from amsfe_sym.ros.cnode_record import read_record_arrays, write_record
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario
from amsfe_sym.topics import TopicSpec

__all__ = [
    "CNodeBuild",
    "CNodeRun",
    "build_node",
    "c_node_refusal",
    "queue_depths",
    "refuse_c_node",
    "ros_paths",
    "run_c_node",
    "write_params",
]

FloatArray = NDArray[np.float64]

#: SCHED_FIFO priority the node asks for (above every normal task; ros2_control's real-time
#: loop uses 50 too).
SCHED_PRIORITY = 50
#: The longest lag the node catches up from without losing a sample [s] (its queues hold
#: this much of each topic; longer silences hold: ``--encoder-timeout``).
CATCH_UP_S = 2.0


# ---------------------------------------------------------------------- configuration
def c_node_refusal(
    sc: Scenario, spec: TopicSpec, managed: bool, controller: bool = False, compiled: bool = True
) -> str | None:
    """Why the C node cannot run this configuration (None: it can): the C node reads an
    effort topic of kind ``applied`` only (the estimators of a joint torque or of an
    unknown input are the Python node's) and runs the controllers the C runtime has, on the
    library's C estimator (``--runtime python``, the Python estimator: the Python node)."""
    from amsfe_sym.runtime.compiled_loop import CONTROLLER_CODES

    if not compiled:
        return "--runtime python (the C node runs the library's C estimator)"
    if controller and sc.controller not in CONTROLLER_CODES:
        return f"controller {sc.controller!r} (not in the C runtime)"
    kind = spec.effort_kind or "applied"
    if kind != "applied":
        return f"effort kind {kind!r} (the C node reads the applied torque only)"
    return None


def refuse_c_node(why: str | None) -> None:
    """Raise the one-line refusal of ``--impl c`` for ``why`` (None: nothing to refuse).

    Raises:
        ConfigError: ``why`` is not None.
    """
    if why is not None:
        raise ConfigError(
            describe(
                "amsfe node --impl c",
                "a configuration the C node runs",
                why,
                "run amsfe node --impl python",
            )
        )


def queue_depths(spec: TopicSpec, T: float, camera_period: int, camera_delay: int,
                 encoder_timeout: float) -> tuple[int, int]:  # fmt: skip
    """History depths of the encoder (and effort) and camera subscriptions: the spec's
    ``qos.depth``, or more when the rates need it: the samples of the longest lag the node
    catches up from (``min(encoder_timeout, CATCH_UP_S)``; a longer silence holds) at the
    encoder rate 1 / T, and the frames of that lag plus the camera's delay at its rate
    1 / (l T)."""
    lag = min(encoder_timeout, CATCH_UP_S)
    enc = max(spec.depth, math.ceil(lag / T) + 1)
    cam = max(spec.depth, math.ceil((lag + camera_delay * T) / (max(camera_period, 1) * T)) + 2)
    return enc, cam


def _numbers(values: Any) -> str:
    return " ".join(repr(float(v)) for v in np.asarray(values, dtype=float).ravel())


def write_params(
    folder: Path,
    sc: Scenario,
    lib: ModelLibrary,
    spec: TopicSpec,
    *,
    controller: bool,
    options: dict[str, Any],
) -> Path:
    """Write the C node's parameter file (and its reference) into ``folder``.

    Args:
        folder: Where (a temporary folder of the run).
        sc: The scenario, the spec's ``[filter]`` applied.
        lib: Its library.
        spec: The topic spec, its ROS parameters resolved.
        controller: Run the controller.
        options: ``end_k`` (-1: none), ``std_every``, ``hold``, ``encoder_timeout``,
            ``subscriber_wait`` [s], ``record`` (a path or None), ``sched_priority``.

    Returns:
        The parameter file.

    Raises:
        ConfigError: a controller without a C counterpart, or an estimator the C node does
            not run (input states).
    """
    from amsfe_sym.runtime.compiled_estimator import CompiledEstimator
    from amsfe_sym.scenario import run_ticks
    from amsfe_sym.sim.builders import build_run
    from amsfe_sym.sim.compiled import controller_params, simulation_inputs

    n, N = lib.n, lib.N
    parts = build_run(sc, lib, compiled=True)  # the builders of `amsfe simulate`
    est = parts.estimator
    if not isinstance(est, CompiledEstimator):  # pragma: no cover - compiled=True builds it
        raise ConfigError(
            describe("C node estimator", "the library's C one", type(est).__name__, "")
        )
    est.require_applied_torque("the estimator of the C node", "run amsfe node --impl python")
    p = est._params
    qw, re, rc, x0, P0 = est._arrays[:5]
    timing = parts.timing
    enc_depth, cam_depth = queue_depths(
        spec, lib.T, int(timing.period), int(timing.delay), float(options["encoder_timeout"])
    )
    names = list(spec.joint_names or lib.manifest.joints)
    bad = [x for x in names if not x or any(c.isspace() for c in x)]
    if bad or any(any(c.isspace() for c in spec.topic(r)) for r in ("encoders", "camera")):
        raise ConfigError(
            describe("joint names and topics", "names without spaces", repr(bad), "rename them")
        )
    limit = np.array(lib.manifest.actuators.u_max or (np.inf,) * n, dtype=float)
    inverse_tol = float(getattr(est.effort.model, "inverse_tol", 1e-10))
    kind = spec.effort_kind or "applied"
    lines = [
        f"dims {n} {N} {lib.p} {est.dims.ne}",
        f"T_ns {round(lib.T * 1e9)}",
        f"T {float(lib.T)!r}",
        f"grid_tolerance {spec.grid_tolerance!r}",
        f"max_gap_steps {spec.max_gap_steps}",
        f"exposure_shift {spec.exposure_shift(lib.T)}",
        f"controller {int(controller)}",
        f"end_k {options['end_k']}",
        f"std_every {options['std_every']}",
        f"hold {options['hold']}",
        f"encoder_timeout {float(options['encoder_timeout'])!r}",
        f"subscriber_wait {float(options['subscriber_wait'])!r}",
        f"effort_in_encoders {int(spec.effort == spec.encoders)}",
        f"read_effort {int(kind != 'none')}",
        f"managed {int(options.get('managed', False))}",
        f"qos {spec.reliability} {spec.depth} {enc_depth} {cam_depth}",
        f"sched_priority {int(options['sched_priority'])}",
        f"joints {' '.join(names)}",
        f"est {p.estimator} {p.buffer_steps} {p.camera_iterations} {p.camera_period} "
        f"{p.camera_phase} {p.camera_max_delay} {p.max_frames_per_step} "
        f"{p.gate_camera!r} {p.gate_encoder!r} {p.k0} {p.backward_map}",
        f"qw {_numbers(qw)}",
        f"r_encoder {_numbers(re)}",
        f"r_camera {_numbers(rc)}",
        f"x0 {_numbers(x0)}",
        f"P0 {_numbers(P0)}",
        f"x0_motor_from_encoders {int(sc.estimate0.motor == 'encoders')}",
        f"inverse_tol {inverse_tol!r}",
        f"hold_limit {_numbers(limit)}",
        "watchdog " + " ".join(repr(float(v)) for v in _watchdog(spec, options)),
    ]
    for role, key in (("encoders", "encoders"), ("camera", "camera"), ("effort", "effort"),
                      ("truth", "truth"), ("estimate", "estimate"),
                      ("estimate_std", "estimate_std"), ("theta", "theta"),
                      ("diagnostics", "diagnostics"), ("commands", "commands")):  # fmt: skip
        lines.append(f"topic_{key} {spec.topic(role)}")
    if options.get("record") is not None:
        lines.append(f"record {options['record']} 1")
    if controller:
        cp = controller_params(parts.controller, lib)
        lines.append(
            f"ctrl {_ctrl_code(cp.name)} {cp.T!r} {cp.p!r} {int(cp.qmd_next_hold)} "
            f"{int(cp.state_true)} {cp.link_bandwidth!r} {cp.motor_bandwidth!r} "
            f"{int(cp.startup_converged)} {cp.ready_q_std!r} {cp.ready_qd_std!r} "
            f"{cp.blend_accel!r} {cp.blend_rate!r} {cp.ready_nis!r} {cp.ready_nis_window!r} "
            f"{int(cp.hold_motor)} {cp.blend_wf!r}"
        )
        lines.append(f"ctrl2 {cp.headroom_tau!r} {cp.blend_lead!r}")
        for key in ("h", "lam", "Lt", "eps", "phi", "wm", "tau_max", "wf", "vmax"):
            lines.append(f"{key} {_numbers(cp.gains.get(key, np.zeros(n)))}")
        for key in ("u_max", "Mm", "Fm", "Ks", "theta_initial"):
            lines.append(f"{key} {_numbers(getattr(cp, key))}")
        lines.append("ks_theta " + " ".join(str(int(v)) for v in cp.ks_theta))
        K = run_ticks(sc, lib.T, n, N)
        inputs, _ = simulation_inputs(sc, lib, K, parts)
        ref_path = folder / "reference.f64"
        np.ascontiguousarray(inputs.ref, dtype="<f8").tofile(ref_path)
        lines.append(f"ref_file {ref_path} {K}")
    path = folder / "params.txt"
    path.write_text("\n".join(lines) + "\n")
    return path


def _watchdog(spec: TopicSpec, options: dict[str, Any]) -> list[float]:
    """The ``[watchdog]`` bounds in ``amsfe_watchdog_config``'s order (inf: off), with the
    node's ``encoder_timeout`` (its ``--encoder-timeout``, as the Python node's)."""
    w = spec.watchdog
    return [w.tracking_error, w.innovation_nis, w.innovation_window, w.deadline,
            w.deadline_misses, w.deadline_window, w.compute_budget,
            float(options["encoder_timeout"]), w.actuation_error,
            w.actuation_ticks, w.lag]  # fmt: skip


def _ctrl_code(name: str) -> int:
    from amsfe_sym.runtime.compiled_loop import CONTROLLER_CODES

    return int(CONTROLLER_CODES[name])


# ---------------------------------------------------------------------- the run
@dataclass(frozen=True)
class CNodeRun:
    """How a C node run ended.

    Attributes:
        exit_code: The C node's (0 done, 2 bad input, 3 hold, 130 / 143 signals).
        record: The record written (None: none).
        build: The build it ran.
    """

    exit_code: int
    record: Path | None
    build: CNodeBuild


def _resolved_spec(spec: TopicSpec, joints: tuple[str, ...], ros_args: tuple[str, ...],
                   domain_id: int | None, std_every: int) -> tuple[TopicSpec, int]:  # fmt: skip
    """The spec with its ROS parameters (``-p``) applied, and ``publish.std_every``: read
    by a short-lived rclpy node of the same name and arguments, as the Python node reads
    them (one definition, the same checks)."""
    from amsfe_sym.ros.middleware import spec_parameters, start, stop
    from amsfe_sym.ros.outputs import std_every_parameter

    ctx = start(list(ros_args), domain_id)
    import rclpy

    node = rclpy.create_node("amsfe_node_parameters", context=ctx)
    try:
        resolved = spec_parameters(node, spec, joints)
        every = std_every_parameter(node, std_every)
    finally:
        stop(ctx, node)
    return resolved, every


def run_c_node(
    sc: Scenario,
    lib: ModelLibrary,
    options: Any,
    say: Callable[[str], None] = print,
    exe: Path | None = None,
) -> CNodeRun:
    """Build (once) and run the C node of ``sc`` with the Python node's options
    (:class:`~amsfe_sym.ros.node.NodeOptions`); its lines go to this process's stdout.
    ``exe``: a C node built elsewhere (``cmake --build`` of ``ros/c/CMakeLists.txt``) for
    ``lib``'s robot, run instead of the wheel build.

    Raises:
        KeyboardInterrupt: Ctrl-C or SIGTERM (forwarded to the C node, which published its
            hold; the record written).
        RosError: the wheels missing, the build failing, rclpy failing to start.
        ConfigError: what the C node cannot run (:func:`c_node_refusal`), bad parameters.
    """
    from amsfe_sym.ros.spec_filter import live_filter

    refuse_c_node(
        c_node_refusal(sc, options.spec, options.managed, options.controller, options.compiled)
    )
    build = external_build(exe, "--node-exe") if exe is not None else build_node(lib)
    if build.compiled:
        say(f"node: built the C node {build.path}")
    spec, every = _resolved_spec(
        options.spec,
        tuple(lib.manifest.joints),
        options.ros_args,
        options.domain_id,
        options.std_every,
    )
    refuse_c_node(c_node_refusal(sc, spec, options.managed, options.controller, options.compiled))
    sc_live = live_filter(sc, spec)
    timeout = (  # --encoder-timeout over the spec's [watchdog] encoder_timeout
        spec.watchdog.encoder_timeout
        if options.encoder_timeout is None
        else float(options.encoder_timeout)
    )
    end_k = -1 if options.duration is None else round(options.duration / lib.T)
    claimed = None
    if options.record is not None:  # one writer a path: claimed before the node starts
        from amsfe_sym.ros.record import NodeRecord

        names = list(spec.joint_names or lib.manifest.joints)
        claimed = NodeRecord(sc_live, lib, spec, names, out=options.record)
    with tempfile.TemporaryDirectory(prefix="amsfe_cnode_") as tmp:
        folder = Path(tmp)
        arrays = folder / "record.bin" if options.record is not None else None
        params = write_params(
            folder,
            sc_live,
            lib,
            spec,
            controller=options.controller,
            options={
                "end_k": end_k,
                "std_every": every,
                "hold": options.hold,
                "encoder_timeout": timeout,
                "subscriber_wait": options.subscriber_wait,
                "record": arrays,
                "sched_priority": SCHED_PRIORITY,
                "managed": options.managed,
            },
        )
        code, interrupt = run_program(build.path, params, options.ros_args, options.domain_id)
        record = None
        end = _end_line(code if interrupt is None else 130)
        if claimed is not None and arrays is not None and arrays.is_file():
            a = read_record_arrays(arrays, lib)
            record = write_record(sc_live, lib, spec, a, options.record, claimed, end)
        elif claimed is not None:  # no arrays (the node failed): the claim released, said so
            record = claimed.write(reason=end)
        if interrupt is not None or code in (130, 143):
            raise interrupt if interrupt is not None else KeyboardInterrupt()
    return CNodeRun(code, record, build)


def _end_line(code: int) -> str:
    """The record's ``amsfe.end`` for the C node's exit code (its own line says more)."""
    if code == 0:
        return "done"
    if code in (130, 143):
        return "hold: interrupted (SIGINT or SIGTERM)"
    return f"hold: the C node exited {code} (its hold line names the reason)"
