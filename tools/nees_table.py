"""The NEES consistency table of docs/explanation/estimation.md section 7, re-measured.

    .venv/bin/python tools/nees_table.py --first-seed 0 --seeds 20 --out docs/data/nees-consistency

Runs the section's studies (``amsfe study``, compiled loop, the oracle controller so every
estimator sees the same plant: ``truth-ct`` as in sections 2-5, ``truth`` for the camera
variants of section 6, where ``truth-ct`` diverges) on one seed block, and writes
``nees.json`` (per study, variant and estimator: the seed-averaged NEES's mean over the
window, its 95 % band, the fractions of the window inside / below / above it, theta's
e^2 / P; and the commands) and ``nees.md`` (the table; estimators whose printed row is the
same are merged). Registered in docs/data/claims-registry.toml.
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
CAMERA = (
    "--set controller=truth --set plant.link_torque_std=2 --set filter.link_torque_std=2 "
    "--variant good_encoders --variant poor_encoders encoders.q_std=0.01 encoders.qd_std=0.1 "
    "--variant poor_encoders_40Hz encoders.q_std=0.01 encoders.qd_std=0.1 camera.period=25 "
    "camera.delay=25"
)
#: (label, arguments after ``amsfe study``)
STUDIES: tuple[tuple[str, str], ...] = (
    ("paper-sim", "paper-sim --set controller=truth-ct"),
    ("paper-sim, theta_rate_std = 0", "paper-sim --set controller=truth-ct --estimators replay "
     "--set filter.theta_rate_std=0"),
    ("paper-exp", "paper-exp --set controller=truth-ct"),
    ("camera", f"paper-sim {CAMERA}"),
    ("paper-sim integrators", "paper-sim --set controller=truth-ct --variant paper "
     "integrator=paper --variant semi_implicit integrator=semi_implicit"),
    ("paper-exp, integrator=paper", "paper-exp --set controller=truth-ct --set integrator=paper"),
    ("paper-exp, 200 s", "paper-exp --set controller=truth-ct --estimators replay,encoders "
     "--duration 200"),
)  # fmt: skip


def _row(a: dict[str, Any]) -> dict[str, Any]:
    return {
        "mean_avg_nees": a["avg_nees_window_mean"],
        "band": a["nees_band95"],
        "in": a["avg_nees_in_band_fraction"],
        "below": a["avg_nees_below_band_fraction"],
        "above": a["avg_nees_above_band_fraction"],
        "theta_nes": a["nes_block_mean"]["theta"],
        "failed_seeds": len(a.get("failed_seeds", [])),
    }


def _cells(r: dict[str, Any]) -> tuple[str, ...]:
    return (
        f"{r['mean_avg_nees']:.3g}",
        f"[{r['band'][0]:.2f}, {r['band'][1]:.2f}]",
        f"{100 * r['in']:.0f} %",
        f"{100 * r['below']:.0f} %",
        f"{100 * r['above']:.0f} %",
        f"{r['theta_nes']:.2g}",
        str(r["failed_seeds"]),
    )


def format_table(doc: dict[str, Any]) -> str:
    """The Markdown table of a ``nees.json``."""
    lines = [
        "| study / variant | estimator | mean avg NEES | band | in | below | above "
        "| theta `e^2/P` | failed runs |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for study in doc["studies"]:
        for variant, rows in study["variants"].items():
            label = study["label"] if variant == "base" else f"{study['label']}: {variant}"
            groups: list[tuple[list[str], tuple[str, ...]]] = []
            for est, r in rows.items():
                c = _cells(r)
                if groups and groups[-1][1] == c:
                    groups[-1][0].append(est)
                else:
                    groups.append(([est], c))
            for ests, c in groups:
                lines.append(f"| {label} | {', '.join(ests)} | " + " | ".join(c) + " |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, required=True, help="folder for nees.json, nees.md")
    args = ap.parse_args()
    doc: dict[str, Any] = {"first_seed": args.first_seed, "seeds": args.seeds, "studies": []}
    with tempfile.TemporaryDirectory(prefix="nees-") as tmp:
        for k, (label, rest) in enumerate(STUDIES):
            out = Path(tmp) / f"s{k}"
            cmd = (
                f"amsfe study {rest} --first-seed {args.first_seed} --seeds {args.seeds} "
                f"--workers {args.workers} --no-progress --out {out}"
            )
            print(f"running: {cmd}", flush=True)
            argv = [sys.executable, "-m", "amsfe_sym", *shlex.split(cmd)[1:]]
            subprocess.run(argv, cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
            agg = json.loads((out / "study.json").read_text())["aggregate"]
            variants = {v: {e: _row(a) for e, a in g.items()} for v, g in agg.items()}
            doc["studies"].append({"label": label, "command": cmd.replace(str(out), "OUT"),
                                   "variants": variants})  # fmt: skip
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "nees.json").write_text(json.dumps(doc, indent=1) + "\n")
    table = format_table(doc)
    (args.out / "nees.md").write_text(table)
    print(table)


if __name__ == "__main__":
    main()
