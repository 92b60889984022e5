"""A section of ``amsfe bench``: ``amsfe estimate`` over a recorded log, as a user runs it
(docs/how-to/logs.md, "Speed").

Each log is a scenario simulated for its duration with the ``amsfe`` controller, seed 1
(optionally with a 30 Hz camera writing pixels or images, :data:`CAMERAS`), written by
``amsfe simulate --bag`` (a rosbag2 in MCAP, as ``tools/log_speed.py`` writes
it).  It is estimated ``rounds`` times, each by a fresh ``python -m amsfe_sym estimate LOG
--no-plots`` process; from each run come the phases of its ``summary.json`` and the
process's wall time seen from here (spawn to exit).  A bare ``python -c pass`` is timed
before each run: the interpreter's own start and exit.  Medians over the rounds.

Real-time factors: the log's duration over

- ``log``: read + estimate (the log's own cost; the first figure ``amsfe estimate`` prints);
- ``command``: the command's wall time once started (setup, library, read, estimate, write);
- ``process``: the whole process seen from outside (interpreter, imports, command, exit);
- ``process_cpu``: its CPU time (user + system), which a loaded machine inflates less;
- ``no_interpreter``: the process less a bare interpreter's start and exit.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from amsfe_sym.errors import ConfigError, describe

__all__ = ["CAMERAS", "DEFAULT_LOGS", "LogCase", "bench_log_estimate", "log_case"]

#: The phases of ``summary.json``'s ``timing`` (docs/how-to/logs.md, "Speed").
PHASES = ("startup_s", "setup_s", "library_s", "read_s", "estimate_s", "write_s", "wall_s")


#: A log case's camera besides the scenario's own: a 30 Hz camera (period and delay 33 ticks
#: of the paper's 1 ms) writing its pixel topic (``pixels``) or its images (``images``,
#: ``amsfe simulate --images``: mono8 Images + CameraInfo; ``jpeg``: jpeg CompressedImages;
#: docs/camera.md, "Speed").
CAMERAS: dict[str, list[str]] = {
    "pixels": ["--set", "camera.period=33", "--set", "camera.delay=33"],
    "images": ["--set", "camera.period=33", "--set", "camera.delay=33", "--images"],
    "jpeg": ["--set", "camera.period=33", "--set", "camera.delay=33", "--images", "jpeg"],
}


@dataclass(frozen=True)
class LogCase:
    """One log of the section: ``scenario`` simulated for ``duration`` [s], with the
    scenario's camera or one of :data:`CAMERAS` (``camera``)."""

    scenario: str
    duration: float
    camera: str = ""

    @property
    def label(self) -> str:
        extra = f", 30 Hz {self.camera}" if self.camera else ""
        return f"{self.scenario} {self.duration:g} s{extra}"


#: Issue 26 item 8's logs: a 10 s 1 kHz 2-link log (target >= 100x real time end to end)
#: and a 60 s 1 kHz Panda log with camera frames (>= 20x).
DEFAULT_LOGS = (LogCase("paper-sim", 10.0), LogCase("panda-control", 60.0))


def log_case(text: str) -> LogCase:
    """``SCENARIO:SECONDS[:CAMERA]`` (e.g. ``paper-sim:10``, ``paper-sim:60:images``) as a
    :class:`LogCase` (CAMERA: one of :data:`CAMERAS`).

    Raises:
        ConfigError: not of that form, or a duration that is not a positive number.
    """
    camera = ""
    head, _, tail = text.rpartition(":")
    if tail in CAMERAS:
        text, camera = head, tail
    name, _, seconds = text.rpartition(":")
    try:
        duration = float(seconds)
    except ValueError:
        duration = float("nan")
    if not name or not duration > 0 or duration == float("inf"):
        raise ConfigError(
            describe(
                "--logs",
                f"SCENARIO:SECONDS[:{'|'.join(CAMERAS)}], e.g. paper-sim:10",
                repr(text),
                "pass e.g. paper-sim:10 or paper-sim:60:images",
            )
        )
    return LogCase(name, duration, camera)


def _process(cmd: list[str], env: dict[str, str]) -> tuple[float, float]:
    """Wall and CPU (user + system) time [s] of ``cmd`` from spawn to exit (its output
    discarded).

    Raises:
        subprocess.CalledProcessError: it failed (its stderr kept).
    """
    import resource

    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)


def _write_log(case: LogCase, folder: Path, env: dict[str, str]) -> Path:
    """The log of ``case`` as ``amsfe simulate --bag`` writes it; its bag folder."""
    cmd = [
        sys.executable, "-m", "amsfe_sym", "simulate", case.scenario, "--controller", "amsfe",
        "--duration", f"{case.duration:g}", "--seed", "1", "--bag", "--out", str(folder),
        "--no-plots", "--no-progress", "--force", *CAMERAS.get(case.camera, []),
    ]  # fmt: skip
    _process(cmd, env)
    return folder / "bag"


def bench_log_estimate(
    case: LogCase, rounds: int, folder: Path, generated: str | None = None
) -> dict[str, Any]:
    """Time ``amsfe estimate`` over the log of ``case`` (module docstring).

    Args:
        case: The log.
        rounds: Fresh processes (the medians are reported).
        folder: Where the log and the run folders are written.
        generated: ``$AMSFE_GENERATED_DIR`` of the processes (None: this process's).

    Returns:
        ``{"log", "scenario", "duration_s", "ticks", "frames", "rounds", "median": {phase:
        seconds, "process_s", "process_cpu_s", "interpreter_s"}, "real_time_factor":
        {"log", "command", "process", "process_cpu", "no_interpreter"}}``, or ``{"log",
        "error"}`` when a process failed.
    """
    env = dict(os.environ)
    if generated is not None:
        env["AMSFE_GENERATED_DIR"] = generated
    label = case.label
    out: dict[str, Any] = {"log": label, "scenario": case.scenario}
    try:
        bag = _write_log(case, folder / "log", env)
        runs = []
        for r in range(rounds):
            bare = _process([sys.executable, "-c", "pass"], env)[0]
            run = folder / f"estimate-{r}"
            cmd = [sys.executable, "-m", "amsfe_sym", "estimate", str(bag), "--out", str(run)]
            wall, cpu = _process([*cmd, "--no-plots", "--force"], env)
            runs.append((bare, wall, json.loads((run / "summary.json").read_text()), cpu))
    except subprocess.CalledProcessError as exc:
        lines = (exc.stderr or b"").decode(errors="replace").strip().splitlines()
        return {**out, "error": lines[-1] if lines else f"exit status {exc.returncode}"}
    s = runs[-1][2]
    med = {k: statistics.median(float(r[2]["timing"][k] or 0.0) for r in runs) for k in PHASES}
    med["process_s"] = statistics.median(r[1] for r in runs)
    med["process_cpu_s"] = statistics.median(r[3] for r in runs)
    med["interpreter_s"] = statistics.median(r[0] for r in runs)
    d = float(s["duration_s"])

    def factor(seconds: float) -> float:
        return round(d / max(seconds, 1e-9), 2)

    return {
        **out,
        "duration_s": d,
        "ticks": s["ticks"],
        "frames": s["frames_fused"],
        "rounds": rounds,
        "median": {k: round(v, 4) for k, v in med.items()},
        "real_time_factor": {
            "log": factor(med["read_s"] + med["estimate_s"]),
            "command": factor(med["wall_s"]),
            "process": factor(med["process_s"]),
            "process_cpu": factor(med["process_cpu_s"]),
            "no_interpreter": factor(med["process_s"] - med["interpreter_s"]),
        },
    }


def log_lines(rows: list[dict[str, Any]]) -> list[str]:
    """Section 6 of the printed report."""
    lines = [
        "",
        "6. amsfe estimate LOG --no-plots, a fresh process per run; x real time = the log's "
        "duration / the time",
        f"   {'log':<30}{'read+est [s]':>13}{'x':>7}{'command [s]':>12}{'x':>7}"
        f"{'process [s]':>12}{'x':>7}{'  w/o python start+exit':>24}",
    ]
    for r in rows:
        if "error" in r:
            lines.append(f"   {r['log']:<30}failed: {r['error']}")
            continue
        m, f = r["median"], r["real_time_factor"]
        lines.append(
            f"   {r['log']:<30}{m['read_s'] + m['estimate_s']:>13.3f}{f['log']:>7.0f}"
            f"{m['wall_s']:>12.3f}{f['command']:>7.0f}{m['process_s']:>12.3f}{f['process']:>7.0f}"
            f"{m['process_s'] - m['interpreter_s']:>17.3f} s {f['no_interpreter']:>4.0f}x"
        )
        lines.append(
            f"   {'':<30}phases: start-up {m['startup_s']:.3f}, setup {m['setup_s']:.3f}, "
            f"library {m['library_s']:.3f}, read {m['read_s']:.3f}, estimate "
            f"{m['estimate_s']:.3f}, writing {m['write_s']:.3f}; process CPU "
            f"{m['process_cpu_s']:.3f} s = {f['process_cpu']:.0f}x; python -c pass "
            f"{m['interpreter_s']:.3f} ({r['ticks']} ticks, {r['frames']} frames, "
            f"median of {r['rounds']})"
        )
    lines.append(
        "   targets (issue 26 item 8): >= 100x for a 10 s 1 kHz 2-link log, >= 20x for a 60 s "
        "Panda log, end to end; (issue 35) >= 10x for a 60 s log with 30 Hz images "
        "(paper-sim:60:images; its pixel-topic twin paper-sim:60:pixels is the floor)"
    )
    return lines
