"""The targets for generated code that scales, met or not: runs ``amsfe bench`` and writes the
section of docs/explanation/performance.md between its ``<!-- scaling-targets -->`` markers,
and docs/data/bench-issue18.json (the data file keeps its first name).

    .venv/bin/python tools/scaling_targets_report.py   # the bench (~15-25 min, 2 cores), section
    .venv/bin/python tools/scaling_targets_report.py --from docs/data/bench-issue18.json  # section

The bench runs the sections the targets need: the closed loop (paper-sim, ur5-control,
panda-control, 10 s each) and the scaling table (chains of 1..12 joints and the Panda).  The
machine (``lscpu``) and the load average before and after the bench are written with the
figures: the machine is shared, so timings are noisy.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "docs" / "data" / "bench-issue18.json"
PAGE = ROOT / "docs" / "explanation" / "performance.md"
BEGIN, END = "<!-- scaling-targets begin -->", "<!-- scaling-targets end -->"


def run_bench(dest: Path) -> dict[str, Any]:
    """``amsfe bench`` (loop + scaling sections) into ``dest``, with the machine and load."""
    amsfe = Path(sys.executable).parent / "amsfe"
    cmd = [str(amsfe), "bench", "--skip", "generation", "calls", "estimators", "tick"]
    cmd += ["--rounds", "3", "--json", str(dest)]
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True)
    wall = time.perf_counter() - t0
    report: dict[str, Any] = json.loads(dest.read_text())
    lscpu = subprocess.run(["lscpu"], capture_output=True, text=True).stdout
    report["issue18"] = {
        "command": " ".join(["amsfe", *cmd[1:-2]]),
        "wall_s": round(wall, 1),
        "load_before": load0,
        "load_after": os.getloadavg(),
        "lscpu": {
            k.strip(): v.strip()
            for k, v in (ln.split(":", 1) for ln in lscpu.splitlines() if ":" in ln)
            if k.strip()
            in ("Model name", "CPU(s)", "Thread(s) per core", "CPU max MHz", "L3 cache")
        },
    }
    dest.write_text(json.dumps(report, indent=2) + "\n")
    return report


def _row(fig: str, target: str, measured: str, met: bool | None) -> str:
    verdict = "n/a" if met is None else ("**met**" if met else "not met")
    return f"| {fig} | {target} | {measured} | {verdict} |"


def section(report: dict[str, Any]) -> str:
    """The markdown of the section from a bench report."""
    rows = {r["robot"]: r for r in report["scaling"]["rows"]}
    ex = report["scaling"].get("exponents", {})
    panda, c12 = rows.get("panda"), rows.get("chain12")
    loops = {lp["scenario"]: lp for lp in report.get("closed_loop", [])}
    meta = report.get("issue18", {})
    cpu = meta.get("lscpu", {})
    m = report["machine"]
    out = [
        BEGIN,
        "",
        "## Targets for generated code that scales, met or not",
        "",
        "<!-- written by tools/scaling_targets_report.py from docs/data/bench-issue18.json -->",
        "",
        f"Measured with `{meta.get('command', 'amsfe bench')}` "
        f"({meta.get('wall_s', '?')} s) on {cpu.get('Model name', m['cpu'])} "
        f"({cpu.get('CPU(s)', m['cores'])} CPUs, {cpu.get('Thread(s) per core', '?')} thread(s) "
        f"per core), shared with the other sessions: load average "
        f"{_load(meta.get('load_before'))} before the bench and {_load(meta.get('load_after'))} "
        f"after; commit {m['commit']}{' (dirty)' if m.get('dirty') else ''}, casadi "
        f"{m['casadi']}, Pinocchio {m['pinocchio']}, {m['compiler']} {m['cflags']}.  Medians; "
        "no figure is asserted by a test.",
        "",
        "| figure | target | measured | |",
        "|---|---|---|---|",
    ]
    if panda:
        out.append(
            _row(
                "7-DOF (Panda): generate + compile, cold, new process",
                "<= 10 s",
                f"{panda['generate_s']:.1f} s",
                panda["generate_s"] <= 10,
            )
        )
        out.append(
            _row(
                "7-DOF: lines of generated C",
                "<= 30k",
                f"{panda['c_lines']:,}",
                panda["c_lines"] <= 30000,
            )
        )
    if c12:
        ok = c12["generate_s"] <= 20 and c12["c_lines"] <= 60000 and c12["peak_mb"] <= 300
        out.append(
            _row(
                "12-joint chain: generate + compile; lines; peak memory",
                "<= 20 s; <= 60k (lines ~ n^1); <= 300 MB",
                f"{c12['generate_s']:.1f} s; {c12['c_lines']:,} "
                f"(lines ~ n^{ex.get('c_lines', '?')}); "
                f"{c12['peak_mb']:.0f} MB",
                ok,
            )
        )
    if panda:
        out.append(
            _row(
                "7-DOF: oosm tick (rk4 model), median / p99",
                "<= 20 us / <= 60 us",
                f"{panda['tick_us']:.1f} / {panda['tick_p99_us']:.1f} us",
                panda["tick_us"] <= 20 and panda["tick_p99_us"] <= 60,
            )
        )
        out.append(
            _row(
                "7-DOF tick vs numpy + Pinocchio EKF tick, same run",
                ">= 4x",
                f"{panda['speedup_baseline']:.1f}x ({panda['baseline_us']:.0f} us vs "
                f"{panda['tick_us']:.1f} us)",
                panda["speedup_baseline"] >= 4,
            )
        )
        dj = panda.get("dynamics_jacobian")
        aba = panda["aba_derivatives_us"]
        out.append(
            _row(
                "7-DOF dynamics jacobian vs computeABADerivatives, same run",
                "<= 2x",
                f"{dj['function']} {dj['median_us']:.2f} us vs {aba:.2f} us = "
                f"{dj['median_us'] / aba:.2f}x"
                if dj
                else f"computeABADerivatives {aba:.2f} us; the library has no separate "
                "dynamics-jacobian function to time (it is inlined in transition_step)",
                (dj["median_us"] / aba <= 2) if dj else None,
            )
        )
    for name, target in (("paper-sim", 300), ("ur5-control", 80), ("panda-control", 50)):
        lp = loops.get(name, {}).get("compiled")
        if lp and "real_time_factor" in lp:
            out.append(
                _row(
                    f"closed loop, real-time factor: {name}",
                    f">= {target}x",
                    f"{lp['real_time_factor']:.1f}x ({lp['us_per_tick']:.1f} us a tick, "
                    f"{lp['sim_time_s']:g} s simulated)",
                    lp["real_time_factor"] >= target,
                )
            )
    out += ["", "Scaling rows (oosm tick in pure C; generate cold in a new process):", ""]
    out += [
        "| robot | n | N | lines of C | generate [s] | peak [MB] | tick [us] | p99 [us] "
        "| numpy + Pinocchio tick [us] | x | computeABADerivatives [us] | loop [us/tick] "
        "| x real time |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in report["scaling"]["rows"]:
        out.append(
            f"| {r['robot']} | {r['joints']} | {r['N']} | {r['c_lines']:,} | "
            f"{r['generate_s']:.1f} | {r['peak_mb']:.0f} | {r['tick_us']:.2f} | "
            f"{r['tick_p99_us']:.2f} | {r['baseline_us']:.0f} | {r['speedup_baseline']:.1f} | "
            f"{r['aba_derivatives_us']:.2f} | {r.get('loop_us_per_tick', '-')} | "
            f"{r.get('real_time_factor', '-')} |"
        )
    if ex:
        out += [
            "",
            "Growth exponents over the chains (log-log least squares, n >= 2): "
            + ", ".join(f"{k} {v:.2f}" for k, v in ex.items())
            + ".",
        ]
    out += ["", END]
    return "\n".join(out)


def _load(v: Any) -> str:
    return "?" if not v else " / ".join(f"{x:.2f}" for x in v)


def write_section(text: str) -> None:
    page = PAGE.read_text()
    if BEGIN in page:
        a, b = page.index(BEGIN), page.index(END) + len(END)
        page = page[:a] + text + page[b:]
    else:
        page = page.rstrip("\n") + "\n\n" + text + "\n"
    PAGE.write_text(page)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--from", dest="src", default=None, help="a bench JSON: skip the bench")
    args = ap.parse_args()
    report = json.loads(Path(args.src).read_text()) if args.src else run_bench(DATA)
    text = section(report)
    print(text)
    write_section(text)
    print(f"wrote the section of {PAGE}")


if __name__ == "__main__":
    main()
