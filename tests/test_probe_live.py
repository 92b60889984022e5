"""Issue 37 item 6 (live): the live loop of ``amsfe node`` judges an encoder stamp by the log
reader's rule with what it has live, the DDS send time of each sample.  A stamp 1 h ahead
was held as "the arm's encoders stalled", all-zero stamps were taken as encoder silence, and
a clock step came out as hundreds of "missing" samples (or, back, as 0.3 s of skipped
duplicates without a word).  Here the loop is fed samples as the node's callback feeds it
(stamp, [qm, qmd], send time) on the 2-link arm."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.errors import EstimatorError
from amsfe_sym.ros.live import LiveLoop
from amsfe_sym.scenario import load_scenario

EPOCH_NS = 1_700_000_000 * 10**9
SENT0_NS = 5 * 10**9  # the send clock: another origin than the stamps'


@pytest.fixture(scope="module")
def paper() -> Any:
    sc = load_scenario("paper-sim").with_overrides(duration=2.0)
    return sc, library_for(sc)


def _feed(loop: LiveLoop, stamps: list[int], T: int) -> list[Any]:
    """Sample k sent at k T on the send clock, stamped ``stamps[k]``."""
    z = np.zeros(2 * loop.n)
    return [loop.encoders(s, z, SENT0_NS + k * T) for k, s in enumerate(stamps)]


def test_one_stamp_an_hour_ahead_is_skipped_by_name(paper: Any) -> None:
    sc, lib = paper
    loop = LiveLoop(sc, lib, controller=False)
    T = round(lib.T * 1e9)
    stamps = [EPOCH_NS + k * T for k in range(40)]
    stamps[20] += 3600 * 10**9
    out = _feed(loop, stamps, T)
    assert out[20] is None and all(o is not None for o in out[21:])
    assert out[-1].k == 39
    skipped = {k: v for k, v in loop.skipped.items() if not k.startswith("torque")}
    assert skipped == {
        "encoder stamp ahead of its send time (a clock step or a corrupt stamp)": 1,
        "encoder samples missing (predicted through)": 1,
    }


@pytest.mark.parametrize(
    ("step_s", "words"),
    [
        (0.3, "encoder stamp ahead of its send time (a clock step or a corrupt stamp)"),
        (-0.3, "encoder stamp behind the last one (a clock step back)"),
    ],
)
def test_a_clock_step_holds_with_its_name(paper: Any, step_s: float, words: str) -> None:
    sc, lib = paper
    loop = LiveLoop(sc, lib, controller=False)
    T = round(lib.T * 1e9)
    stamps = [EPOCH_NS + k * T + (round(step_s * 1e9) if k >= 30 else 0) for k in range(60)]
    with pytest.raises(EstimatorError) as info:
        _feed(loop, stamps, T)
    msg = str(info.value)
    assert "\n" not in msg and words in msg and "stalled" not in msg, msg
    assert "6 samples in a row after tick 29, the last 0.30" in msg or (
        step_s < 0 and "6 samples in a row after tick 29, the last 0.294 s" in msg
    ), msg


def test_zero_stamps_are_named_not_silence(paper: Any) -> None:
    sc, lib = paper
    loop = LiveLoop(sc, lib, controller=False)
    T = round(lib.T * 1e9)
    with pytest.raises(EstimatorError, match="zero header stamp"):
        _feed(loop, [0] * 20, T)


def test_a_gap_in_stamps_and_send_times_is_still_a_gap(paper: Any) -> None:
    """A driver that pauses 50 ms (stamps and send times both advance): the encoders
    stalled, as before, not a clock step."""
    sc, lib = paper
    loop = LiveLoop(sc, lib, controller=False)
    T = round(lib.T * 1e9)
    z = np.zeros(2 * lib.n)
    for k in range(10):
        loop.encoders(EPOCH_NS + k * T, z, SENT0_NS + k * T)
    with pytest.raises(EstimatorError, match="stalled"):
        loop.encoders(EPOCH_NS + 60 * T, z, SENT0_NS + 60 * T)


@pytest.mark.parametrize(
    ("step_s", "words"),
    [(0.3, "ahead of its send time"), (-0.3, "behind the last one"), (None, "zero header stamp")],
)
def test_the_node_path_names_bad_stamps_too(paper: Any, step_s: float | None, words: str) -> None:
    """Through :meth:`LiveLoop.watch` (what ``amsfe node`` calls) a run of bad stamps raises
    the stamps' error, which the node prints as its hold line, as the C node does; it was
    caught as an estimator failure and held as ``covariance`` or ``encoder_stall``."""
    import time

    sc, lib = paper
    loop = LiveLoop(sc, lib, controller=False)
    T = round(lib.T * 1e9)
    z = np.zeros(2 * lib.n)
    if step_s is None:
        stamps = [EPOCH_NS + k * T for k in range(30)] + [0] * 30
    else:
        stamps = [EPOCH_NS + k * T + (round(step_s * 1e9) if k >= 30 else 0) for k in range(60)]
    with pytest.raises(EstimatorError) as info:
        for k, s in enumerate(stamps):
            watched = loop.watch(
                s, z, SENT0_NS + k * T, taken=time.monotonic(), clock=time.monotonic
            )
            assert watched.reason is None or watched.reason.name == "NONE", (k, watched)
    msg = str(info.value)
    assert words in msg and "stalled" not in msg and "covariance" not in msg, msg
