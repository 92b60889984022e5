"""The printed laws (37) and (54) in closed loop, under every reading and relaxation we
could think of: when does each diverge?  (docs/explanation/control.md, section 2.)

    .venv/bin/python tools/paper_laws.py            # paper-sim, seed 0

Rows: the law (``amsfe-paper`` = (37), ``dtsmc-paper`` = (54)), the reading of Fhat's
qmd(k+1) (``predict`` from (1c) with u(k-1), ``hold`` = qmd(k)), the state the law reads
(the fusion estimate, or the true state for (37)), and the arm: as specified (u_max = 100 N m
from the URDF's effort), without a torque limit, without the switching term (eps = 0),
with a boundary layer (phi = 5 instead of sgn), and with stiff joints (Ks = 1000 N m/rad).
Each row prints the time the loop diverged (a tracking error beyond pi rad, or a
non-finite state), or its tracking RMSE if it did not.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

from amsfe_sym.codegen import load_library
from amsfe_sym.load.spec import load_spec
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from amsfe_sym.sim.record import summarize


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario", nargs="?", default="paper-sim")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--duration", type=float, default=5.0)
    args = ap.parse_args()
    base = load_scenario(args.scenario).with_overrides(seed=args.seed, duration=args.duration)
    spec = load_spec(base.robot)
    spec = replace(
        spec,
        name=f"{spec.name}_{base.integrator}",
        model=replace(spec.model, integrator=base.integrator),
    )
    n = len(spec.actuators.Ks or ())
    arms = {
        "as specified": spec,
        "no torque limit": replace(
            spec, name=spec.name + "_nolimit", actuators=replace(spec.actuators, u_max=(1e9,) * n)
        ),
        "stiff joints (Ks = 1000)": replace(
            spec, name=spec.name + "_stiff", actuators=replace(spec.actuators, Ks=(1000.0,) * n)
        ),
    }
    libs = {k: load_library(v) for k, v in arms.items()}
    print(f"{args.scenario}, seed {args.seed}, {args.duration} s; estimator {base.estimator}")
    print("| law | qmd(k+1) | reads | arm | gains | result |")
    print("|---|---|---|---|---|---|")
    for law in ("amsfe-paper", "dtsmc-paper"):
        for reading in ("predict", "hold"):
            for state in ("estimate", "true") if law == "amsfe-paper" else ("encoders",):
                for arm, lib in libs.items():
                    for label, extra in (
                        ("paper", {}),
                        ("eps = 0", {"eps": 0.0}),
                        ("phi = 5", {"phi": 5.0}),
                    ):
                        if arm != "as specified" and label != "paper":
                            continue
                        gains = {**base.gains_for(law), "qmd_next": reading, **extra}
                        if law == "amsfe-paper":
                            gains["state"] = state
                        sc = replace(base, controller=law, controller_gains={law: gains})
                        s = summarize(run(sc, lib))
                        res = (
                            f"diverged at {s['diverged_at_s']:.3f} s"
                            if s["diverged_at_s"] is not None
                            else "bounded, RMSE "
                            + " / ".join(f"{v:.4f}" for v in s["control"]["tracking_rmse"])
                            + " rad"
                        )
                        print(
                            f"| {law} | {reading} | {state} | {arm} | {label} | {res} |", flush=True
                        )


if __name__ == "__main__":
    main()
