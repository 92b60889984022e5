"""What the blend plans on a moving start (docs/explanation/control.md, "Start-up: the blend
planned before the trusted tick"): for grid starts of tools/startup_moving.py, the largest offset
from the path that the
hand-over's blend *plans* (the peak of |delta| of control/blend.py over the plan, any joint),

* planned at the trusted tick from the estimate there (``blend_lead = 0``, the third pass),
* planned as if started at the first tick, through the same estimate (``blend_lead = 1``;
  the peak after the trusted tick),
* the oracle's, planned at t = 0 from the true start,

and the offset's largest snap [rad/s^4] at the trusted tick of the plan led from the first
tick (the plan made at the trusted tick has none there),

with the trusted tick and the estimate taken from an ``amsfe`` run with ``blend_lead = 0``
(compiled, 3 s), whether that run diverged, and whether it still diverges when the estimate
starts exactly at the plant's state (the wait and the hold unchanged)::

    .venv/bin/python tools/startup_excursion.py 18392 18634 19765 19803 19899 \\
        --out docs/data/startup-excursion.json
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from startup_moving import _start, covariance_ready

from amsfe_sym.codegen import library_for
from amsfe_sym.control import Amsfe
from amsfe_sym.control.blend import blend_offsets, blend_through, blend_time
from amsfe_sym.scenario import apply_sets, load_scenario
from amsfe_sym.signals.trajectory import from_config
from amsfe_sym.sim.loop import run


def _peak(tb: float, d0: np.ndarray, d1: np.ndarray, s0: float = 0.0) -> float:
    """max |delta| over [s0, Tb] (2001 points) [rad]."""
    if tb <= s0:
        return 0.0
    n = d0.size
    return max(
        float(np.abs(blend_offsets(s, tb, d0, d1)[:n]).max()) for s in np.linspace(s0, tb, 2001)
    )


def one(seed: int) -> dict[str, Any]:
    q0, qd0, qh, qdh = (np.array(v) for v in _start(seed))
    sc = load_scenario("paper-sim").with_overrides(controller="amsfe", duration=3.0, seed=seed)
    sc = apply_sets(sc, ["controller_gains.amsfe.blend_lead=0"])
    g = {**Amsfe.gain_defaults, **sc.gains_for("amsfe")}
    accel, rate = float(g["blend_accel"]), float(g["blend_rate"])
    lib = library_for(sc)
    n, T = lib.n, lib.T
    start = replace(sc, plant=replace(sc.plant, q0=tuple(q0), qd0=tuple(qd0)))
    res = run(replace(start, estimate0=replace(sc.estimate0, q=tuple(qh), qd=tuple(qdh))), lib)
    exact = run(replace(start, estimate0=replace(sc.estimate0, q=tuple(q0), qd=tuple(qd0))), lib)
    ok = covariance_ready(res, g)
    k = int(np.argmax(ok))
    ref = from_config(dict(sc.trajectory)).evaluate(np.array([0.0, k * T]))
    e0 = res.x_hat[k, :n] - ref.q.reshape(2, n)[1]
    e1 = res.x_hat[k, n : 2 * n] - ref.qd.reshape(2, n)[1]
    o0, o1 = q0 - ref.q.reshape(2, n)[0], qd0 - ref.qd.reshape(2, n)[0]
    tb_now = blend_time(e0, e1, accel, rate)
    s0 = k * T
    tb_led, d0, d1 = blend_through(e0, e1, s0, accel, rate)
    tb_oracle = blend_time(o0, o1, accel, rate)
    return {
        "seed": seed,
        "trusted_s": s0,
        "start_offset": o0.tolist(),
        "start_rate_offset": o1.tolist(),
        "trusted_offset": e0.tolist(),
        "trusted_rate_offset": e1.tolist(),
        "true_rate_offset_at_trust": (res.x_true[k, n : 2 * n] - ref.qd.reshape(2, n)[1]).tolist(),
        "planned_peak_at_trust": _peak(tb_now, e0, e1),
        "planned_peak_led_after_trust": _peak(tb_led, d0, d1, s0),
        "planned_peak_oracle": _peak(tb_oracle, o0, o1),
        "snap_at_trust_led": float(np.abs(blend_offsets(s0, tb_led, d0, d1)[4 * n :]).max()),
        "tb_at_trust": tb_now,
        "tb_led_after_trust": tb_led - s0,
        "diverged_at": res.diverged_at,
        "exact_estimate_diverged_at": exact.diverged_at,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("seeds", type=int, nargs="+")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    rows = [one(s) for s in args.seeds]
    for r in rows:
        print(
            f"{r['seed']}: trusted at {r['trusted_s']:.3f} s; planned peak |delta| "
            f"{r['planned_peak_at_trust']:.2f} rad at the trusted tick, "
            f"{r['planned_peak_led_after_trust']:.2f} led from the first tick, "
            f"{r['planned_peak_oracle']:.2f} the oracle's; diverged at {r['diverged_at']}, "
            f"with an exact estimate at {r['exact_estimate_diverged_at']}"
        )
    if args.out:
        doc = {
            "command": "python tools/startup_excursion.py "
            + " ".join(sys.argv[1:] if argv is None else argv),
            "scenario": "paper-sim, amsfe/oosm, blend_lead = 0 (the third pass), 3 s, compiled",
            "runs": rows,
        }
        args.out.write_text(json.dumps(doc, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
