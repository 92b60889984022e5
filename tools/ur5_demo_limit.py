"""Why ur5-demo's wrist-3 tracking moved from 31.1 to 138.5 mrad
(docs/explanation/ur5-estimation.md 5).

    .venv/bin/python tools/ur5_demo_limit.py

Runs scenarios/ur5-demo.toml on seed 0 (compiled loop) twice: as shipped, where every law
ends in the actuator limit u_max (the URDF's effort: 150 N m for joints 1-3, 28 N m for the
wrists, since the controllers' commit 82bb0ab), and with that limit lifted on the
controller (u_max = inf). Prints each run's tracking RMSE per joint [mrad], the largest
torque per joint [N m] and the fraction of saturated ticks.
"""

from __future__ import annotations

import numpy as np

from amsfe_sym.codegen import library_for
from amsfe_sym.control import base
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from amsfe_sym.sim.record import summarize


def main() -> None:
    sc = load_scenario("scenarios/ur5-demo.toml")
    lib = library_for(sc)
    for label in ("limit (URDF effort)", "no limit"):
        if label == "no limit":
            orig = base.Controller.__init__

            def init(self, *a, _o=orig, **k):  # type: ignore[no-untyped-def]
                _o(self, *a, **k)
                self.u_max = np.full_like(self.u_max, np.inf)

            base.Controller.__init__ = init  # type: ignore[method-assign]
        s = summarize(run(sc, lib, runtime="compiled"))
        c = s["control"]
        print(
            f"{label}: tracking [mrad] {np.round(1e3 * np.array(s['tracking_rmse']['q']), 1)}, "
            f"max |u| [N m] {np.round(c['u_max_abs'], 1)}, saturated {c['saturated_fraction']:.3f}"
        )


if __name__ == "__main__":
    main()
