"""Issue 37 item 4 (and its C/B cases): time as robots make it, in a recorded log.

Each case is a log written here as a driver writes one (tests/test_log_reader.py's writers:
a ROS 1 bag or a rosbag2 MCAP, header stamps and log times of their own) from a simulated
paper-sim run, read for the 2-link arm (T = 1 ms):

- a clock step of the stamps (0.3 s back or ahead mid-log, 1 h ahead for the last 3 %) is
  refused by name (tick, size), never spliced or dropped silently; a recorder's stall (log
  times 50 ms late for a burst) is not one;
- an effort stream that ends early ends the log there, named at its tick (it was held: the
  estimate ran 3.14 rad off with exit 0);
- one absurd encoder sample (1e300) is skipped and named at its tick;
- stamps 1.04 ms apart: the period printed and the ``--period`` of the fix are one number,
  and running the fix makes the same command work (end to end);
- ``positions = "link"`` with an applied effort is refused in one line.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from amsfe_sym.apps.cli import main
from amsfe_sym.codegen import library_for
from amsfe_sym.errors import LogError
from amsfe_sym.logs.grid import LogRateError
from amsfe_sym.logs.spec import LogSpec
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from tests.test_log_reader import F64, Ev, _enc_events, _read, write_log

EPOCH = 1.7e9  # header stamps on the epoch, log times from 0 (two clocks)


@pytest.fixture(scope="module")
def res():
    """A 1 s paper-sim run (compiled loop, oosm), as tests/test_log_reader.py's."""
    sc = load_scenario("paper-sim").with_overrides(
        estimator="oosm", controller="amsfe", duration=1.0, seed=3
    )
    return run(sc, library_for(sc), runtime="compiled")


def _clocked(res, stamps: list[float], log_times: list[float]) -> list[Ev]:
    return _enc_events(res, stamps, log_times)


@pytest.mark.parametrize(("size", "way"), [(-0.3, "back"), (0.3, "ahead")])
def test_a_clock_step_mid_log_is_refused_by_tick_and_size(res, tmp_path, size, way) -> None:
    T = res.lib.T
    lt = [1.0 + k * T for k in range(900)]
    st = [EPOCH + k * T + (size if k >= 500 else 0.0) for k in range(900)]
    log = write_log(tmp_path / "step", _clocked(res, st, lt), "mcap")
    with pytest.raises(LogError) as info:
        _read(res, log)
    msg = str(info.value)
    assert "\n" not in msg
    assert f"0.3 s {way} at tick 500" in msg, msg
    assert "t = 0.5000 s" in msg and "400 samples on the stepped clock" in msg


def test_a_step_for_the_last_3_percent_is_not_dropped_silently(res, tmp_path) -> None:
    """1 h ahead for the last 30 of 900 samples: the old far-stamp rule (5-95 % spread)
    skipped them and the log ended early with exit 0."""
    T = res.lib.T
    lt = [1.0 + k * T for k in range(900)]
    st = [EPOCH + k * T + (3600.0 if k >= 870 else 0.0) for k in range(900)]
    with pytest.raises(LogError, match="3600 s ahead at tick 870"):
        _read(res, write_log(tmp_path / "late", _clocked(res, st, lt), "mcap"))


def test_a_recorder_stall_is_not_a_clock_step(res, tmp_path) -> None:
    """The recorder stalls 50 ms and then takes the queued samples in a burst: log times
    late, stamps right. Every sample is used."""
    T = res.lib.T
    lt = [1.0 + k * T for k in range(900)]
    for k in range(400, 450):
        lt[k] = 1.0 + 449.5 * T + (k - 400) * 1e-6  # all at once, at 0.4495 s
    st = [EPOCH + k * T for k in range(900)]
    got = _read(res, write_log(tmp_path / "stall", _clocked(res, st, lt), "mcap"))
    assert got.K == 900 and not got.usage["encoders"].skipped
    assert np.array_equal(got.z, res.z_enc[:900])


def test_one_absurd_sample_is_skipped_and_named(res, tmp_path) -> None:
    T = res.lib.T
    st = [EPOCH + k * T for k in range(600)]
    ev = _clocked(res, st, [1.0 + k * T for k in range(600)])
    ev[200].position = [1e300, 0.1]
    got = _read(res, write_log(tmp_path / "absurd", ev, "mcap"))
    skipped = got.usage["encoders"].skipped
    assert skipped == {
        "sample with a value beyond 1e+06 (first at tick 200, t = 0.2000 s; predicted through)": 1
    }
    assert np.isnan(got.z[200]).all() and got.K == 600
    assert np.array_equal(got.z[201:], res.z_enc[201:600])


def _torque_events(res, ticks: int, effort_ticks: int) -> list[Ev]:
    """Encoders without effort for ``ticks``, and the applied torque on /torque
    (Float64MultiArray, stamped by its arrival) for the first ``effort_ticks``."""
    T = res.lib.T
    ev = _clocked(res, [EPOCH + k * T for k in range(ticks)], [1.0 + k * T for k in range(ticks)])
    for e in ev:
        e.effort = ()
    ev += [Ev(1.0 + k * T, "/torque", F64, data=res.u[k]) for k in range(effort_ticks)]
    return ev


def test_an_effort_that_ends_early_ends_the_log_there_by_name(res, tmp_path) -> None:
    log = write_log(tmp_path / "torque", _torque_events(res, 900, 400), "mcap")
    spec = LogSpec(effort="/torque", effort_kind="applied")
    got = _read(res, log, spec)
    # the last torque at tick 399, held for max_gap_steps (5) ticks: the log ends at 404
    assert got.K == 405
    reason = (
        "after the effort ended at tick 399 (t = 0.3990 s; a torque is not held past "
        "max_gap_steps ticks: the log ends there)"
    )
    assert got.usage["encoders"].skipped == {reason: 900 - 405}
    assert np.isfinite(got.u).all()


def test_an_effort_over_the_whole_log_is_not_cut(res, tmp_path) -> None:
    log = write_log(tmp_path / "whole", _torque_events(res, 600, 600), "mcap")
    got = _read(res, log, LogSpec(effort="/torque", effort_kind="applied"))
    assert got.K == 600 and not got.usage["encoders"].skipped
    assert np.array_equal(got.u, res.u[:600])


def test_link_positions_with_an_applied_effort_are_refused(res, tmp_path, capsys) -> None:
    log = write_log(tmp_path / "link", _torque_events(res, 300, 300), "mcap")
    spec = tmp_path / "spec.toml"
    spec.write_text('[topics]\neffort = "/torque"\n[joints]\npositions = "link"\n')
    out = tmp_path / "o"
    code = main(
        ["estimate", str(log), "--robot", "paper_2link", "--log-spec", str(spec), "--out", str(out)]
    )
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and err.startswith("error:"), err
    assert 'positions = "link"' in err and "'applied'" in err and "joint_torque" in err
    assert not out.exists()


def _period_log(res, tmp_path: Path) -> Path:
    """1 s of the run stamped every 1.04 ms with 0.1 T of jitter (a drive whose bus runs
    at 961.5 Hz) in a ROS 1 bag, the torque applied on /joint_states' effort."""
    rng = np.random.default_rng(7)
    P = 1.04e-3
    st = [EPOCH + k * P + rng.uniform(-0.1, 0.1) * P for k in range(900)]
    return write_log(tmp_path / "p104.bag", _clocked(res, st, [1.0 + k * P for k in range(900)]))


def test_the_period_printed_is_the_fix_that_is_run(res, tmp_path) -> None:
    with pytest.raises(LogRateError) as info:
        _read(res, _period_log(res, tmp_path))
    msg = str(info.value)
    # the fewest digits whose grid still holds the 900 stamps (the fitted period is within
    # 1e-8 s of 1.04 ms; jitter 0.1 T)
    assert info.value.period == 0.00104, msg
    assert "samples every 0.00104 s" in msg and "--period 0.00104 " in msg, msg


@pytest.mark.slow
def test_running_the_period_fix_makes_the_estimate_work(res, tmp_path, capsys, monkeypatch) -> None:
    """End to end: estimate refuses with the fix; the fix (``amsfe generate paper_2link
    --period 0.00104``, a 2-link compile into this test's own library folder, so no earlier
    run's cache answers first) is run as printed; the same estimate then runs."""
    monkeypatch.setenv("AMSFE_GENERATED_DIR", str(tmp_path / "generated"))
    log = _period_log(res, tmp_path)
    spec = tmp_path / "spec.toml"
    spec.write_text('[effort]\nkind = "applied"\n')
    args = ["estimate", str(log), "--robot", "paper_2link", "--log-spec", str(spec), "--no-plots"]
    code = main([*args, "--out", str(tmp_path / "a")])
    err = capsys.readouterr().err
    assert "samples every 0.00104 s" in err, err
    fix = err.split("amsfe generate ", 1)[1].split(" (its own library")[0]
    assert fix == "paper_2link --period 0.00104", err
    assert main(["generate", *fix.split()]) == 0
    capsys.readouterr()
    code = main([*args, "--out", str(tmp_path / "b")])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "library paper_2link_T1040us" in out, out
    s = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert s["ticks"] == 900 and s["topics"]["encoders"]["used"] == 900


def test_a_camera_that_stops_is_named_at_its_last_frame(res, tmp_path) -> None:
    """The driver-style log of the run with every camera frame after 0.5 s dropped: the
    estimate goes on (encoders and torque are there) and the camera's note names the tick
    of its last frame."""
    from tests.test_log_reader import arm_events

    ev, _ = arm_events(res, offset=0.0, jitter=0.0)
    cut = [e for e in ev if not (e.topic == "/camera/marker" and e.t > 0.5)]
    log = write_log(tmp_path / "cam", cut, "mcap")
    got = _read(res, log, LogSpec(effort_kind="applied"))
    last = max(f.delivery_step for f in got.frames)
    assert last <= 501 and len(res.t) == got.K
    notes = got.usage["camera"].notes
    key = f"frames end at tick {last} (t = {last * res.lib.T:.4f} s): none over the last "
    assert notes == {key + "ticks of the log (ticks without a frame)": got.K - 1 - last}


def test_one_absurd_torque_is_skipped_and_counted(res, tmp_path) -> None:
    """A 1e300 torque on /torque: skipped (the tick before it is held), counted as absurd;
    it was fed to the filter and reported later as "model gave NaN"."""
    ev = _torque_events(res, 600, 600)
    bad = next(e for e in ev if e.topic == "/torque" and abs(e.t - (1.0 + 0.3)) < 1e-9)
    bad.data = [1e300, 0.0]
    got = _read(res, write_log(tmp_path / "tq", ev, "mcap"), LogSpec(effort="/torque"))
    assert got.usage["effort"].skipped == {"a value beyond 1e+06 N m (absurd)": 1}
    assert np.isfinite(got.u).all() and np.abs(got.u).max() < 1e3
    assert np.array_equal(got.u[300], got.u[299])
