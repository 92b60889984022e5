"""Real-time factor of the compiled closed loop per estimator and controller
(docs/explanation/performance.md
section 6): median of 3 runs of ``run(..., runtime="compiled")``.

    .venv/bin/python tools/loop_rtf.py paper-sim 10
"""

from __future__ import annotations

import logging
import statistics
import sys


def main() -> None:
    from amsfe_sym.codegen import library_for
    from amsfe_sym.scenario import load_scenario
    from amsfe_sym.sim.loop import run

    logging.getLogger("amsfe_sym").setLevel(logging.ERROR)
    scn = sys.argv[1] if len(sys.argv) > 1 else "paper-sim"
    dur = float(sys.argv[2]) if len(sys.argv) > 2 else 10.0
    base = load_scenario(scn).with_overrides(duration=dur, seed=1)
    lib = library_for(base)
    ticks = round(dur / lib.T) + 1
    for est in ("encoders", "naive", "oosm", "replay", "cloning"):
        for ctrl in ("amsfe", "truth-ct"):
            sc = base.with_overrides(estimator=est, controller=ctrl)
            try:
                w = statistics.median(
                    run(sc, lib, runtime="compiled").wall_time_s for _ in range(3)
                )
            except Exception as exc:  # a configuration the C runtime refuses: say so
                print(f"{scn} {est:9s} {ctrl:9s} {type(exc).__name__}: {exc}")
                continue
            print(
                f"{scn} {est:9s} {ctrl:9s} wall {w:.4f} s  {1e6 * w / ticks:.1f} us/tick  "
                f"{dur / w:.0f}x real time",
                flush=True,
            )


if __name__ == "__main__":
    main()
