"""Bad camera frames in a closed-loop run (issue 10, deliverable 5, the CI-sized part).

The camera of a paper-sim run is wrapped: one delivered frame is dropped, one holds NaN,
one is a wild outlier (+300 px), one lies far outside the image, and one old frame is
delivered again later than the filter's buffer.  A twin run delivers only the good frames.
Every bad frame must leave the estimate untouched (the two runs' estimates are identical,
bit for bit, at every tick), the run goes on to the end, and the summary's counters say
what was refused and why.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import amsfe_sym.sim.loop as loop
from amsfe_sym.codegen import library_for
from amsfe_sym.core.camera_frame import CameraFrame
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.record import summarize

BUFFER = 200  # steps; delay 125 fits
BUILD_RUN = loop.build_run  # the real one (the tests below replace it)


def _faulty(bad: bool) -> Callable[..., Any]:
    """A ``build_run`` whose camera corrupts (bad=True) or just drops (bad=False) the 2nd to
    5th delivered frames, and delivers an old frame again past the buffer (bad only)."""

    def build(sc: Any, lib: Any) -> Any:
        parts = BUILD_RUN(sc, lib)
        cam = parts.sensors.camera
        tick = cam.tick
        seen: list[int] = []

        def faulty_tick(k: int, q: Any) -> list[CameraFrame]:
            out = []
            for fr in tick(k, q):
                seen.append(fr.exposure_step)
                i = len(seen)
                if not bad and 2 <= i <= 5:
                    continue  # the clean twin: these frames never arrive
                z = {
                    2: None,  # dropped
                    3: np.array([np.nan, fr.z[1]]),
                    4: fr.z + 300.0,  # wild outlier
                    5: np.array([-5000.0, 9000.0]),  # far outside the image
                }.get(i, fr.z)
                if z is not None:
                    out.append(CameraFrame(fr.exposure_step, z))
            if bad and k == 1500:  # exposure 1250 again, 250 steps late > buffer 200
                out.append(CameraFrame(1250, np.array([320.0, 240.0])))
            return out

        cam.tick = faulty_tick
        return parts

    return build


@pytest.mark.parametrize("estimator", ["naive", "oosm", "replay", "cloning"])
def test_bad_frames_leave_the_estimate_untouched(
    estimator: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    sc = load_scenario("paper-sim").with_overrides(duration=2.0, estimator=estimator)
    sc = dataclasses.replace(sc, filter=dataclasses.replace(sc.filter, buffer_steps=BUFFER))
    lib = library_for(sc)
    monkeypatch.setattr(loop, "build_run", _faulty(bad=False))
    clean = loop.run(sc, lib)
    monkeypatch.setattr(loop, "build_run", _faulty(bad=True))
    faulty = loop.run(sc, lib)
    assert faulty.t.size == clean.t.size == 2001  # the run went on to the end
    np.testing.assert_array_equal(faulty.x_hat, clean.x_hat)
    np.testing.assert_array_equal(faulty.P_diag, clean.P_diag)
    c, c0 = summarize(faulty)["counters"], summarize(clean)["counters"]
    assert c["frames_applied"] == c0["frames_applied"]
    assert c["frames_applied"] >= (0 if estimator == "naive" else 10)
    assert c["refused_nan"] == 1
    assert c["refused_gated"] == c0["refused_gated"] + 2  # the outlier and the far pixel
    assert c["refused_too_late"] == 1
    assert c["refused_other"] == 0
    assert c["frames_rejected"] == c0["frames_rejected"] + 4
