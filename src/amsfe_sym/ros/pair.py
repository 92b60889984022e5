"""``amsfe live``: the simulated arm (``amsfe sim-node``) and the node (``amsfe node``) of one
scenario started together, for a first live run in one command (docs/live-control.md); what
``launch/amsfe_live.launch.py`` starts for users with a ROS 2 installation.

Both are child processes of this one, with their own output lines (``node: ...``,
``sim-node: ...``); the node starts first (the arm waits for it). Ctrl-C / SIGTERM reach
both (the node publishes its hold command first); the exit code is the node's when it is
not 0, else the arm's.

Both run for the same duration (``--duration``, else the scenario's), so the arm's last tick
is the node's end (``done``, exit 0): a node without a duration runs until stopped, and when
the arm ended after its scenario's duration the node held with ``encoder_stall`` (its
driver gone) and exit 3 -- the normal end of the data taken for a crash.

A node that ends without a hold (exit 2: it refused its options; a signal: it crashed) before
the arm stops the arm at once (SIGINT; a line says so): the arm would otherwise wait out its
start or command timeout for a node that is gone.  After a hold (exit 3) the arm runs on
under the hold command the node published, to its end, as a real arm would.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from dataclasses import dataclass

from amsfe_sym.ros.node_stop import EXIT_HOLD
from amsfe_sym.scenario import load_scenario

__all__ = ["PairOptions", "pair_commands", "run_pair"]


@dataclass(frozen=True)
class PairOptions:
    """What ``amsfe live`` starts.

    Attributes:
        scenario: Scenario name or .toml.
        controller: The node's controller (None: the scenario's; "": the scenario's too).
        lockstep: The arm advances only when its command arrived (deterministic).
        duration: [s] of sample time, for both (None: the scenario's, for both).
        seed: The arm's seed (None: the scenario's).
        rate: Free running: the arm's wall-clock speed factor.
        impl: The node's per-sample path: ``auto``, ``c`` or ``python``.
        record: The node's record folder (None: none).
        topic_spec: A topic spec file for both (None: the defaults).
        ros_args: ``--ros-args`` for both.
        encoder_timeout: The node's ``--encoder-timeout`` [s] (None: its default).
        command_timeout: The arm's ``--command-timeout`` and ``--start-timeout`` [s] (None:
            its defaults).
    """

    scenario: str = "paper-sim"
    controller: str | None = None
    lockstep: bool = False
    duration: float | None = None
    seed: int | None = None
    rate: float = 1.0
    impl: str = "auto"
    record: str | None = None
    topic_spec: str | None = None
    ros_args: tuple[str, ...] = ()
    encoder_timeout: float | None = None
    command_timeout: float | None = None


def pair_commands(opts: PairOptions) -> tuple[list[str], list[str]]:
    """The ``amsfe`` arguments of the node and of the arm: both with the run's duration
    (the node stops at the arm's last tick, module docstring).

    Raises:
        ConfigError: no duration given and the scenario does not load (what either
            process would refuse).
    """
    duration = load_scenario(opts.scenario).duration if opts.duration is None else opts.duration
    common: list[str] = ["--duration", repr(float(duration))]  # exact: the same last tick
    if opts.seed is not None:
        common += ["--seed", str(opts.seed)]
    if opts.topic_spec is not None:
        common += ["--topic-spec", opts.topic_spec]
    node = ["node", opts.scenario, "--controller", *([opts.controller] if opts.controller else [])]
    node += ["--impl", opts.impl, *common]
    if opts.record is not None:
        node += ["--record", opts.record]
    if opts.encoder_timeout is not None:
        node += ["--encoder-timeout", f"{opts.encoder_timeout:g}"]
    arm = ["sim-node", opts.scenario, *common]
    if opts.command_timeout is not None:
        t = f"{opts.command_timeout:g}"
        arm += ["--command-timeout", t, "--start-timeout", t]
    arm += ["--lockstep"] if opts.lockstep else ["--rate", f"{opts.rate:g}"]
    ros = ["--ros-args", *opts.ros_args] if opts.ros_args else []
    return [*node, *ros], [*arm, *ros]


def run_pair(opts: PairOptions) -> int:
    """Start the node, then the arm; wait for both; the exit code (module docstring).

    Raises:
        KeyboardInterrupt: Ctrl-C or SIGTERM (forwarded to both, both waited for).
    """
    node_args, arm_args = pair_commands(opts)
    exe = [sys.executable, "-m", "amsfe_sym"]
    sys.stdout.flush()
    procs = [subprocess.Popen([*exe, *node_args])]
    try:
        procs.append(subprocess.Popen([*exe, *arm_args]))
        node, arm = procs
        while node.poll() is None and arm.poll() is None:
            time.sleep(POLL_S)
        if node.returncode not in (None, 0, EXIT_HOLD) and arm.poll() is None:
            print(
                f"live: the node ended ({_how(node.returncode)}) before the arm; "
                "the arm is stopped (SIGINT)",
                flush=True,
            )
            arm.send_signal(signal.SIGINT)
        codes = [p.wait() for p in procs]
    except KeyboardInterrupt as exc:
        sig = signal.SIGINT if type(exc) is KeyboardInterrupt else signal.SIGTERM
        for p in procs:
            if p.poll() is None:
                p.send_signal(sig)
        for p in procs:
            p.wait()
        raise
    return codes[0] or codes[1]


#: How often :func:`run_pair` looks whether either process has ended [s].
POLL_S = 0.05


def _how(code: int) -> str:
    """A child's return code in words: ``exit N`` or ``killed by SIGSEGV``."""
    if code >= 0:
        return f"exit {code}"
    try:
        return f"killed by {signal.Signals(-code).name}"
    except ValueError:
        return f"killed by signal {-code}"
