"""``amsfe bench --ros``: the live loop over real DDS, the same run idle and under a stated
CPU load, for each node implementation side by side (docs/live-load.md).

One run: ``amsfe sim-node SCENARIO`` free running on the wall clock (1 kHz for paper-sim)
and ``amsfe node SCENARIO --controller amsfe [--impl IMPL]``, two processes on a fresh
ROS_DOMAIN_ID, localhost only, with ``load`` CPU hogs (:class:`~amsfe_sym.core.cpu_load.
CpuHogs`) beside them.  Reported, from the two processes' own lines:

- the node's own latency: the sample received by the middleware -> the command published,
  p50 / p99 / max [ms] (the node's ``node: latency ...`` line);
- the end-to-end latency through DDS: the arm publishes a sample -> the arm receives the
  command answering it (the sim-node's receive stamps; ``encoder -> command``);
- deadline misses: ticks of the arm that ended without a new command (the previous one was
  applied again), and ticks that started late (the arm itself behind);
- the C node's p99 per kind of tick (its ``node: latency p99 by tick`` line: the first 10
  ticks, ticks that fused or refused a camera frame, the tick after one (its diagnostics
  JSON and record were written after the command, before this sample was taken), the tick
  after a standard deviations' publish, the others): which ticks make the p99;
- how the node stopped (``done``, or the hold line with its reason);
- which arm ran (``sim-node --impl auto``: the C arm when it builds, ros/carm.py) and the
  machine's load over the run: the cores busy, from ``/proc/stat`` (every process of the
  machine, the hogs, the two nodes and anything else running).

On a noisy machine one run's p99 says little (0.2 to 0.9 ms run to run for the same idle
C node here): ``repeat`` runs each row N times and :func:`summarize` gives each row's p99
median and worst over its runs.

Nothing here is asserted by a test (a test checks the report's shape): the numbers are this
machine's, at this moment.
"""

from __future__ import annotations

import os
import re
import statistics
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from typing import Any

from amsfe_sym.core.cpu_load import CpuHogs
from amsfe_sym.core.provenance import cpu_name

__all__ = [
    "RosBenchRun",
    "RosBenchSummary",
    "bench_ros",
    "format_ros_report",
    "machine_name",
    "node_impls",
    "parse_run",
    "ros_report_json",
    "summarize",
]

_NUM = r"([0-9.]+|nan)"
_NODE_LAT = re.compile(
    rf"node: latency sample received -> command published p50 {_NUM} p99 {_NUM} max {_NUM} ms "
    r"over (\d+) commands"
)
_E2E = re.compile(rf"encoder -> command p50 {_NUM} p99 {_NUM} max {_NUM} ms")
_TICKS = re.compile(
    r"sim-node: (\d+) ticks in ([0-9.]+) s wall, (\d+) commands, (\d+) late ticks, "
    r"(\d+) without a new command"
)
_BY_KIND = re.compile(r"node: latency p99 by tick \[ms\]: (.*)")
_KIND = re.compile(rf"\s*(.+?) {_NUM} \((\d+)\)")
_STOP = re.compile(r"^node: ((?:done|hold)[^;\n]*)", re.M)
_ARM = re.compile(r"\((c|python) arm\)")


def cpu_times() -> tuple[float, float] | None:
    """(busy, total) jiffies of the machine since boot (``/proc/stat``), None off Linux."""
    try:
        with open("/proc/stat", encoding="ascii") as fh:
            v = [float(x) for x in fh.readline().split()[1:]]
    except (OSError, ValueError):
        return None
    idle = v[3] + (v[4] if len(v) > 4 else 0.0)  # idle + iowait
    return sum(v[:8]) - idle, sum(v[:8])


def busy_cores(
    before: tuple[float, float] | None, after: tuple[float, float] | None
) -> float | None:
    """Cores busy between two :func:`cpu_times` readings (None: unknown)."""
    if before is None or after is None or after[1] <= before[1]:
        return None
    return (after[0] - before[0]) / (after[1] - before[1]) * (os.cpu_count() or 1)


@dataclass(frozen=True)
class RosBenchRun:
    """One run of the live loop (module docstring); latencies [ms], None when not reported.

    Attributes:
        impl: The node's implementation (``c`` or ``python``).
        load: CPU hogs beside the two processes.
        node_p50, node_p99, node_max: The node's own latency [ms].
        commands: Commands the node timed.
        e2e_p50, e2e_p99, e2e_max: Arm publishes -> arm receives the command [ms].
        ticks: Ticks the arm ran.
        late_ticks: Ticks that started late (the arm behind the wall clock).
        missed: Deadline misses: ticks without a new command.
        stopped: How the node stopped (one line: ``done ...`` or ``hold: <reason>: ...``).
        codes: Exit codes (sim-node, node).
        arm: The arm's implementation (``c`` or ``python``; "" when it did not say).
        cpu_busy: Cores busy over the run, the whole machine (``/proc/stat``; None: unknown).
        p99_by_kind: The node's p99 per kind of tick [ms] (the C node's line; empty: none).
    """

    impl: str
    load: int
    node_p50: float | None
    node_p99: float | None
    node_max: float | None
    commands: int
    e2e_p50: float | None
    e2e_p99: float | None
    e2e_max: float | None
    ticks: int
    late_ticks: int
    missed: int
    stopped: str
    codes: tuple[int, int]
    arm: str = ""
    cpu_busy: float | None = None
    p99_by_kind: dict[str, float] = field(default_factory=dict)


def _f(text: str) -> float:
    return float(text)


def parse_run(
    impl: str, load: int, sim_out: str, node_out: str, codes: tuple[int, int]
) -> RosBenchRun:
    """A :class:`RosBenchRun` from the two processes' output."""
    node = _NODE_LAT.search(node_out)
    e2e = _E2E.search(sim_out)
    ticks = _TICKS.search(sim_out)
    stops = _STOP.findall(node_out)
    return RosBenchRun(
        impl=impl,
        load=load,
        node_p50=_f(node.group(1)) if node else None,
        node_p99=_f(node.group(2)) if node else None,
        node_max=_f(node.group(3)) if node else None,
        commands=int(node.group(4)) if node else 0,
        e2e_p50=_f(e2e.group(1)) if e2e else None,
        e2e_p99=_f(e2e.group(2)) if e2e else None,
        e2e_max=_f(e2e.group(3)) if e2e else None,
        ticks=int(ticks.group(1)) if ticks else 0,
        late_ticks=int(ticks.group(4)) if ticks else 0,
        missed=int(ticks.group(5)) if ticks else 0,
        stopped=stops[-1].strip() if stops else "no stop line (exit code only)",
        arm=arm.group(1) if (arm := _ARM.search(sim_out)) else "",
        codes=codes,
        p99_by_kind=_by_kind(node_out),
    )


def _by_kind(node_out: str) -> dict[str, float]:
    """The C node's ``node: latency p99 by tick [ms]: <kind> <p99> (<count>), ...``."""
    found = _BY_KIND.search(node_out)
    if not found:
        return {}
    return {m.group(1): _f(m.group(2)) for m in map(_KIND.match, found.group(1).split(",")) if m}


def _one_run(
    scenario: str, duration: float, impl: str, load: int, domain: int, timeout: float
) -> RosBenchRun:
    """Both processes (and ``load`` hogs) for ``duration`` [s] of the arm's time."""
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.pop("ROS_LOCALHOST_ONLY", None)
    amsfe = [sys.executable, "-m", "amsfe_sym"]
    d = f"{duration:g}"
    impl_args = ["--impl", impl] if len(node_impls()) > 1 else []
    with CpuHogs(load, limit_s=timeout + 60.0):
        before = cpu_times()
        node = subprocess.Popen(
            [*amsfe, "node", scenario, "--controller", "amsfe", "--duration", d, *impl_args],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
        try:
            sim = subprocess.run(
                [*amsfe, "sim-node", scenario, "--duration", d, "--start-timeout", "120"],
                env=env, capture_output=True, text=True, timeout=timeout,
            )  # fmt: skip
            node_out, _ = node.communicate(timeout=60)
        finally:
            if node.poll() is None:
                node.kill()
                node.communicate()
        busy = busy_cores(before, cpu_times())
    row = parse_run(
        impl, load, sim.stdout + sim.stderr, node_out, (sim.returncode, node.returncode)
    )
    return replace(row, cpu_busy=busy)


def bench_ros(
    scenario: str = "paper-sim",
    duration: float = 2.0,
    loads: tuple[int, ...] = (0, 2),
    impls: tuple[str, ...] | None = None,
    say: Any = print,
    repeat: int = 1,
) -> list[RosBenchRun]:
    """Each implementation (None: every one :func:`node_impls` offers) idle and under each
    load, ``repeat`` runs each, one after the other (module docstring)."""
    impls = node_impls() if impls is None else impls
    rows = []
    base = 60 + (os.getpid() % 30)  # a domain of its own per run: no run hears another
    plan = [(ld, im) for ld in loads for im in impls for _ in range(max(1, repeat))]
    for i, (load, impl) in enumerate(plan):
        t0 = time.perf_counter()
        domain = base + i % 30
        row = _one_run(scenario, duration, impl, load, domain, timeout=300.0 + 10 * duration)
        say(
            f"bench --ros: {impl} node, {load} hogs: {row.stopped} "
            f"({time.perf_counter() - t0:.0f} s)"
        )
        rows.append(row)
    return rows


@dataclass(frozen=True)
class RosBenchSummary:
    """The runs of one row (an implementation at a load) over ``repeat`` runs [ms].

    Attributes:
        impl, load: The row.
        runs: Its runs.
        node_p99_median, node_p99_worst: The node's own p99, median and largest over the runs.
        e2e_p99_median, e2e_p99_worst: The same of the end-to-end latency through DDS.
        missed_median, missed_worst: Ticks without a new command.
        stops: How the runs stopped: ``done`` or the hold's reason -> runs.
        p99_by_kind_median: Per kind of tick, the median over the runs of its p99.
    """

    impl: str
    load: int
    runs: int
    node_p99_median: float | None
    node_p99_worst: float | None
    e2e_p99_median: float | None
    e2e_p99_worst: float | None
    missed_median: float
    missed_worst: int
    stops: dict[str, int]
    p99_by_kind_median: dict[str, float]


def _median_worst(values: list[float | None]) -> tuple[float | None, float | None]:
    known = [v for v in values if v is not None]
    return (statistics.median(known), max(known)) if known else (None, None)


def summarize(rows: list[RosBenchRun]) -> list[RosBenchSummary]:
    """Each row's runs (same implementation and load, in the order first run): the p99's
    median and worst over them, and how they stopped."""
    groups: dict[tuple[str, int], list[RosBenchRun]] = {}
    for r in rows:
        groups.setdefault((r.impl, r.load), []).append(r)
    out = []
    for (impl, load), runs in groups.items():
        node = _median_worst([r.node_p99 for r in runs])
        e2e = _median_worst([r.e2e_p99 for r in runs])
        stops: dict[str, int] = {}
        for r in runs:
            key = "done" if r.stopped.startswith("done") else r.stopped.split(":")[:2][-1].strip()
            stops[key] = stops.get(key, 0) + 1
        kinds = {k for r in runs for k in r.p99_by_kind}
        by_kind = {
            k: statistics.median([r.p99_by_kind[k] for r in runs if k in r.p99_by_kind])
            for k in sorted(kinds)
        }
        missed = [r.missed for r in runs]
        out.append(
            RosBenchSummary(
                impl,
                load,
                len(runs),
                *node,
                *e2e,
                statistics.median(missed),
                max(missed),
                stops,
                by_kind,
            )
        )
    return out


def _short(line: str, width: int = 72) -> str:
    """A stop line cut to ``width`` characters (the JSON has it whole)."""
    return line if len(line) <= width else line[: width - 3] + "..."


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v:.3f}"


def format_ros_report(rows: list[RosBenchRun], machine: str = "") -> str:
    """The runs as a table (latencies [ms])."""
    head = (
        "| node | hogs | node p50 | node p99 | node max | DDS e2e p50 | e2e p99 | e2e max "
        "| ticks | missed | late | stopped | arm | busy cores |"
    )
    lines = [f"live loop over DDS{f' ({machine})' if machine else ''}", head, "|" + "---|" * 14]
    for r in rows:
        lines.append(
            f"| {r.impl} | {r.load} | {_ms(r.node_p50)} | {_ms(r.node_p99)} | "
            f"{_ms(r.node_max)} | {_ms(r.e2e_p50)} | {_ms(r.e2e_p99)} | {_ms(r.e2e_max)} | "
            f"{r.ticks} | {r.missed} | {r.late_ticks} | {_short(r.stopped)} | {r.arm or '-'} | "
            f"{'-' if r.cpu_busy is None else f'{r.cpu_busy:.2f}'} |"
        )
    summary = summarize(rows)
    if any(g.runs > 1 for g in summary):
        lines += ["", "over the runs of each row: p99 median / worst [ms]", _SUMMARY_HEAD]
        lines.append("|" + "---|" * 8)
        for g in summary:
            kinds = ", ".join(f"{k} {v:.3f}" for k, v in g.p99_by_kind_median.items()) or "-"
            stops = ", ".join(f"{k} {v}" for k, v in g.stops.items())
            lines.append(
                f"| {g.impl} | {g.load} | {g.runs} | {_ms(g.node_p99_median)} / "
                f"{_ms(g.node_p99_worst)} | {_ms(g.e2e_p99_median)} / {_ms(g.e2e_p99_worst)} | "
                f"{g.missed_median:g} / {g.missed_worst} | {stops} | {kinds} |"
            )
    return "\n".join(lines)


_SUMMARY_HEAD = (
    "| node | hogs | runs | node p99 | e2e p99 | missed | stopped | node p99 by tick (median) |"
)


def ros_report_json(rows: list[RosBenchRun], machine: str = "") -> dict[str, Any]:
    """The runs as JSON (``--json``)."""
    return {
        "machine": machine,
        "runs": [asdict(r) for r in rows],
        "summary": [asdict(g) for g in summarize(rows)],
    }


def machine_name() -> str:
    """The CPU's model name (:func:`~amsfe_sym.core.provenance.cpu_name`) and its core count."""
    return f"{cpu_name()}, {os.cpu_count()} cores"


def node_impls() -> tuple[str, ...]:
    """The implementations ``amsfe node`` offers (``--impl``'s choices; only the Python
    node when it has no such option)."""
    import argparse

    from amsfe_sym.apps.ros_nodes import add_node_arguments

    p = argparse.ArgumentParser()
    add_node_arguments(p)
    action = p._option_string_actions.get("--impl")
    if action is None or not action.choices:
        return ("python",)
    return tuple(c for c in ("c", "python") if c in action.choices)
