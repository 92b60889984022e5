"""``amsfe sim-node --impl c``: the simulated arm in C on rcl (``ros/c/amsfe_arm*.c``),
configured from Python, started and waited for (docs/live-load.md, "The C arm").

The Python sim-node (:mod:`amsfe_sym.ros.sim_node`) cannot hold 1 kHz on a small loaded
machine: free running, it starts most ticks late and applies stale commands, so a node's
free-running numbers measure the arm.  A real arm's driver keeps its own real-time clock;
this one does: ``clock_nanosleep(TIMER_ABSTIME)`` every T, SCHED_FIFO and memory locked when
permitted, nothing allocated per tick.

:func:`write_arm_params` writes what the C arm reads: every noise stream of the run drawn
here by the builders of ``amsfe simulate`` (:func:`amsfe_sym.sim.compiled.simulation_inputs`,
the compiled loop's; the Python sim-node draws the same values tick by tick), the plant's
start and theta, the topic spec resolved, the QoS of the Python sim-node and the faults
(:mod:`amsfe_sym.ros.faults`).  :func:`run_c_arm` builds the arm once per content
(:func:`amsfe_sym.ros.cnode_build.build_node`, program ``amsfe_arm``), runs it, forwards
Ctrl-C / SIGTERM, and raises its refusal (no node, a missing lockstep command, two
controllers) as the Python sim-node does.  Not run in C: ``--images`` (the Python
sim-node's).
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np

from amsfe_sym.errors import ConfigError, RosError, describe
from amsfe_sym.ros.cnode_build import CNodeBuild, build_node, external_build, run_program
from amsfe_sym.ros.faults import FaultPlan
from amsfe_sym.ros.middleware import DEFAULT_RMW, LOCKSTEP_PROFILE
from amsfe_sym.ros.sim_node import SimNodeOptions
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario
from amsfe_sym.topics import TopicSpec

__all__ = ["ARM_PROGRAM", "build_arm", "c_arm_refusal", "run_c_arm", "write_arm_params"]

#: The program of ``ros/c/`` the arm is (:data:`amsfe_sym.ros.cnode_build.PROGRAMS`).
ARM_PROGRAM = "amsfe_arm"
#: SCHED_FIFO priority the arm asks for (above the node's 50: the arm is the robot's clock).
SCHED_PRIORITY = 60
#: The arm's exit code for a refusal (its line in the error file).
EXIT_REFUSED = 4


def build_arm(lib: ModelLibrary) -> CNodeBuild:
    """The C arm of ``lib``'s robot, built once per content.

    Raises:
        RosError: the ROS 2 wheels are missing, or the compiler failed.
    """
    return build_node(lib, program=ARM_PROGRAM)


def c_arm_refusal(options: SimNodeOptions) -> str | None:
    """Why the C arm cannot run these options (None: it can)."""
    if options.images:
        return "--images (the Python sim-node renders the camera's images)"
    return None


def write_arm_params(
    folder: Path, sc: Scenario, lib: ModelLibrary, spec: TopicSpec, options: SimNodeOptions
) -> Path:
    """Write the C arm's parameter file and its inputs (float64) into ``folder``.

    Raises:
        ConfigError: the same fault kind twice; joint names or topics with spaces.
    """
    from amsfe_sym.scenario import run_ticks
    from amsfe_sym.sim.builders import build_run
    from amsfe_sym.sim.compiled import simulation_inputs

    n, N, T = lib.n, lib.N, lib.T
    K = run_ticks(sc, T, n, N)
    plan = FaultPlan(options.faults, T, n)
    parts = build_run(sc, lib, compiled=True)  # the builders of `amsfe simulate`
    inputs, _ = simulation_inputs(sc, lib, K, parts)
    names = list(spec.joint_names or lib.manifest.joints)
    topics = {r: spec.topic(r) for r in ("encoders", "camera", "effort", "truth", "commands",
                                         "estimate", "clock")}  # fmt: skip
    if any(not x or any(c.isspace() for c in x) for x in [*names, *topics.values()]):
        raise ConfigError(
            describe("joint names and topics", "names without spaces", repr(names), "rename them")
        )
    cam = inputs.camera
    E = int(inputs.cam_jitter.size)
    max_jitter = int(inputs.cam_jitter.max()) if E else 0
    arrays = [inputs.x_plant0, inputs.theta_true, inputs.enc_noise, inputs.tau_d,
              inputs.cam_noise, inputs.cam_uniform, inputs.cam_jitter]  # fmt: skip
    data = folder / "arm_inputs.f64"
    np.concatenate([np.asarray(a, dtype="<f8").ravel() for a in arrays]).tofile(data)
    # free running, the writers keep 1 s of samples (as the Python sim-node's)
    out_depth = spec.depth if options.lockstep else max(spec.depth, math.ceil(1.0 / T) + 1)
    start = plan.start
    lines = [
        f"dims {n} {N} {lib.p}",
        f"T_ns {round(T * 1e9)}",
        f"T {float(T)!r}",
        f"K {K}",
        f"lockstep {int(options.lockstep)}",
        f"rate {float(options.rate)!r}",
        f"start_timeout {float(options.start_timeout)!r}",
        f"command_timeout {float(options.command_timeout)!r}",
        f"qos {spec.reliability} {spec.depth} {out_depth}",
        f"sched_priority {SCHED_PRIORITY}",
        f"joints {' '.join(names)}",
        *(f"topic_{role} {topic}" for role, topic in topics.items()),
        f"error_file {folder / 'error.txt'}",
        f"enc_resolution {float(inputs.enc_resolution)!r}",
        f"camera {int(cam['period'])} {int(cam['phase'])} {int(cam['delay'])} "
        f"{float(cam['width'])!r} {float(cam['height'])!r} {float(cam['pixel_std'])!r} "
        f"{int(bool(cam['round_to_pixel']))} {float(cam['drop_probability'])!r} {E} "
        f"{(int(cam['delay']) + max_jitter) // int(cam['period']) + 2}",
        f"faults {start.get('encoder_frozen', -1)} {start.get('encoder_jump', -1)} "
        f"{plan.jump!r} {start.get('torque_loss', -1)}",
        f"inputs {data}",
    ]
    path = folder / "arm_params.txt"
    path.write_text("\n".join(lines) + "\n")
    return path


def _resolved_spec(spec: TopicSpec, joints: tuple[str, ...], options: SimNodeOptions) -> TopicSpec:
    """The spec with its ROS parameters (``-p``) applied, read by a short-lived rclpy node
    as the Python sim-node reads them (the same checks: a mistyped name refused)."""
    from amsfe_sym.ros.middleware import check_parameters, spec_parameters, start, stop

    ctx = start(list(options.ros_args), options.domain_id)
    import rclpy

    node = rclpy.create_node("amsfe_sim_parameters", context=ctx)
    try:
        resolved = spec_parameters(node, spec, joints)
        check_parameters(node)
    finally:
        stop(ctx, node)
    return resolved


def run_c_arm(
    sc: Scenario, lib: ModelLibrary, options: SimNodeOptions, exe: Path | None = None
) -> int:
    """Build (once) and run the C arm of ``sc`` for its duration as the node ``amsfe_sim``;
    its lines (the Python sim-node's) go to this process's stdout.  Returns 0.  ``exe``: an
    arm built elsewhere (``cmake --build`` of ``ros/c/CMakeLists.txt``) for ``lib``'s robot,
    run instead of the wheel build.

    Raises:
        KeyboardInterrupt: Ctrl-C or SIGTERM (forwarded to the arm).
        RosError: the wheels missing, the build failing, no node within ``start_timeout``, a
            lockstep command missing or two controllers (the arm's one line).
        ConfigError: bad options (:func:`c_arm_refusal`, a fault kind twice), ``exe`` not
            an executable.
    """
    why = c_arm_refusal(options)
    if why is not None:
        raise ConfigError(
            describe("amsfe sim-node --impl c", "options the C arm runs", why, "--impl python")
        )
    build = external_build(exe, "--arm-exe") if exe is not None else build_arm(lib)
    if build.compiled:
        print(f"sim-node: built the C arm {build.path}", flush=True)
    spec = _resolved_spec(options.spec, tuple(lib.manifest.joints), options)
    with tempfile.TemporaryDirectory(prefix="amsfe_carm_") as tmp:
        folder = Path(tmp)
        params = write_arm_params(folder, sc, lib, spec, options)
        profile = {}
        rmw = os.environ.get("RMW_IMPLEMENTATION", DEFAULT_RMW)
        if rmw == DEFAULT_RMW and not os.environ.get("FASTDDS_DEFAULT_PROFILES_FILE"):
            # the 1 ms heartbeat of the Python sim-node (middleware.use_lockstep_profile)
            profile["FASTDDS_DEFAULT_PROFILES_FILE"] = str(LOCKSTEP_PROFILE)
        code, interrupt = run_program(
            build.path, params, options.ros_args, options.domain_id, profile
        )
        if interrupt is not None or code in (130, 143):
            raise interrupt if interrupt is not None else KeyboardInterrupt()
        error = folder / "error.txt"
        if code == EXIT_REFUSED and error.is_file():
            raise RosError(error.read_text().strip())
        if code != 0:
            raise RosError(
                describe("the C arm", "exit 0", f"exit {code}", "its line above; or --impl python")
            )
    return 0
