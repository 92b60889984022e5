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

A case may set the image decoding threads of ``amsfe estimate`` (``...:threads=N``:
``$AMSFE_IMAGE_THREADS``, 0 = serial; docs/camera.md, "Speed").  Cases of one log (the same
scenario, duration and camera) share its written log, and the rounds interleave: round r of
every case runs before round r + 1 of any, so a before/after pair sees the same load.
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

__all__ = [
    "CAMERAS",
    "DEFAULT_LOGS",
    "LogCase",
    "bench_log_estimate",
    "bench_log_estimates",
    "log_case",
]

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
    scenario's camera or one of :data:`CAMERAS` (``camera``); ``threads``: the image
    decoding threads of ``amsfe estimate`` (None: its default; 0: serial)."""

    scenario: str
    duration: float
    camera: str = ""
    threads: int | None = None

    @property
    def label(self) -> str:
        extra = f", 30 Hz {self.camera}" if self.camera else ""
        if self.threads == 0:
            extra += ", serial decoding"
        elif self.threads is not None:
            extra += f", {self.threads} decoding thread{'s' if self.threads > 1 else ''}"
        return f"{self.scenario} {self.duration:g} s{extra}"

    @property
    def log_key(self) -> tuple[str, float, str]:
        """What the written log depends on (cases with the same key share it)."""
        return (self.scenario, self.duration, self.camera)


#: The logs of the targets: a 10 s 1 kHz 2-link log (target >= 100x real time end to end)
#: and a 60 s 1 kHz Panda log with camera frames (>= 20x).
DEFAULT_LOGS = (LogCase("paper-sim", 10.0), LogCase("panda-control", 60.0))


def log_case(text: str) -> LogCase:
    """``SCENARIO:SECONDS[:CAMERA][:threads=N]`` (e.g. ``paper-sim:10``,
    ``paper-sim:60:images``, ``paper-sim:60:jpeg:threads=0``) as a :class:`LogCase` (CAMERA:
    one of :data:`CAMERAS`; N: image decoding threads, 0 to 16, 0 serial).

    Raises:
        ConfigError: not of that form, or a duration that is not a positive number.
    """
    camera, threads = "", None
    original = text
    head, _, tail = text.rpartition(":")
    if tail.startswith("threads="):
        from amsfe_sym.vision.prefetch import image_threads

        threads = image_threads(tail.removeprefix("threads="))
        text = head
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
                f"SCENARIO:SECONDS[:{'|'.join(CAMERAS)}][:threads=N], e.g. paper-sim:10",
                repr(original),
                "pass e.g. paper-sim:10 or paper-sim:60:images",
            )
        )
    return LogCase(name, duration, camera, threads)


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
        {"log", "command", "process", "process_cpu", "no_interpreter"}}`` (and
        ``"image_threads"`` when the case sets them), or ``{"log", "error"}`` when a
        process failed.
    """
    return bench_log_estimates([case], rounds, folder, generated)[0]


def bench_log_estimates(
    cases: list[LogCase] | tuple[LogCase, ...],
    rounds: int,
    folder: Path,
    generated: str | None = None,
) -> list[dict[str, Any]]:
    """:func:`bench_log_estimate` of each case, each log written once for the cases that
    share it and the rounds interleaved across the cases (module docstring); one row per
    case, in order."""
    base = dict(os.environ)
    if generated is not None:
        base["AMSFE_GENERATED_DIR"] = generated
    bags: dict[tuple[str, float, str], Path | str] = {}
    for case in cases:
        if case.log_key not in bags:
            try:
                bags[case.log_key] = _write_log(case, folder / f"log{len(bags)}", base)
            except subprocess.CalledProcessError as exc:
                bags[case.log_key] = _last_line(exc)
    runs: list[list[tuple[float, float, dict[str, Any], float]]] = [[] for _ in cases]
    failed: dict[int, str] = {
        i: str(bags[c.log_key]) for i, c in enumerate(cases) if isinstance(bags[c.log_key], str)
    }
    for r in range(rounds):
        for i, case in enumerate(cases):
            if i in failed:
                continue
            env = dict(base)
            if case.threads is not None:
                from amsfe_sym.vision.prefetch import THREADS_ENV

                env[THREADS_ENV] = str(case.threads)
            bare = _process([sys.executable, "-c", "pass"], env)[0]
            run = folder / f"estimate-{i}-{r}"
            cmd = [sys.executable, "-m", "amsfe_sym", "estimate", str(bags[case.log_key])]
            try:
                wall, cpu = _process([*cmd, "--out", str(run), "--no-plots", "--force"], env)
            except subprocess.CalledProcessError as exc:
                failed[i] = _last_line(exc)
                continue
            runs[i].append((bare, wall, json.loads((run / "summary.json").read_text()), cpu))
    out = []
    for i, case in enumerate(cases):
        head: dict[str, Any] = {"log": case.label, "scenario": case.scenario}
        if case.threads is not None:
            head["image_threads"] = case.threads
        out.append({**head, "error": failed[i]} if i in failed else _row(head, runs[i]))
    return out


def _last_line(exc: subprocess.CalledProcessError) -> str:
    lines = (exc.stderr or b"").decode(errors="replace").strip().splitlines()
    return lines[-1] if lines else f"exit status {exc.returncode}"


def _row(
    head: dict[str, Any], runs: list[tuple[float, float, dict[str, Any], float]]
) -> dict[str, Any]:
    """One case's row from its runs ``(bare interpreter [s], wall [s], summary, CPU [s])``."""
    s = runs[-1][2]
    med = {k: statistics.median(float(r[2]["timing"][k] or 0.0) for r in runs) for k in PHASES}
    med["process_s"] = statistics.median(r[1] for r in runs)
    med["process_cpu_s"] = statistics.median(r[3] for r in runs)
    med["interpreter_s"] = statistics.median(r[0] for r in runs)
    d = float(s["duration_s"])

    def factor(seconds: float) -> float:
        return round(d / max(seconds, 1e-9), 2)

    return {
        **head,
        "duration_s": d,
        "ticks": s["ticks"],
        "frames": s["frames_fused"],
        "rounds": len(runs),
        "median": {k: round(v, 4) for k, v in med.items()},
        "real_time_factor": {
            "log": factor(med["read_s"] + med["estimate_s"]),
            "command": factor(med["wall_s"]),
            "process": factor(med["process_s"]),
            "process_cpu": factor(med["process_cpu_s"]),
            "no_interpreter": factor(med["process_s"] - med["interpreter_s"]),
        },
        "process_s": [round(r[1], 4) for r in runs],
        "process_cpu_s": [round(r[3], 4) for r in runs],
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
        "   targets: >= 100x for a 10 s 1 kHz 2-link log, >= 20x for a 60 s "
        "Panda log, end to end; >= 10x for a 60 s log with 30 Hz images "
        "(paper-sim:60:images; its pixel-topic twin paper-sim:60:pixels is the floor)"
    )
    return lines
