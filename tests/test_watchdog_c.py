"""The watchdogs in C (runtime/c/amsfe_watchdog.c, compiled into every full library as a
shared unit) decide what the Python reference (ros/watchdog.py) decides: fed the same calls
(the samples and idle calls of in-process free-running runs, clean and with each fault
injected), every call returns the same reason, and after every call the hold and the largest
watched quantities are equal (bit for bit), under several sets of bounds; the hold lines are
the same text."""

from __future__ import annotations

import ctypes
import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.ros.watchdog import (
    REASON_NAMES,
    Cause,
    Reason,
    Watchdog,
    WatchdogConfig,
    WatchdogTick,
)
from amsfe_sym.ros.watchdog_runs import FAULTS, Fault, WatchEvent, run_watched
from amsfe_sym.runtime.cheader import c_struct
from amsfe_sym.scenario import load_scenario
from amsfe_sym.topics.watchdog import MEASURING, WatchdogBounds

Config = c_struct("Config", "amsfe_watchdog.h", "amsfe_watchdog_config")
Tick = c_struct("Tick", "amsfe_watchdog.h", "amsfe_watchdog_tick")
State = c_struct("State", "amsfe_watchdog.h", "amsfe_watchdog_state")

OFF = MEASURING  # every bound that can be off, off
#: Bounds under which the sequences trip at other ticks and for other reasons.
BOUNDS = (
    WatchdogBounds(),
    OFF,
    WatchdogBounds(tracking_error=0.004, innovation_nis=1.2, innovation_window=7),
    WatchdogBounds(deadline=1e-4, deadline_misses=3, deadline_window=10, compute_budget=math.inf),
    WatchdogBounds(compute_budget=1.5e-4),
    WatchdogBounds(encoder_timeout=0.07),
    WatchdogBounds(innovation_nis=1.05, innovation_window=1, tracking_error=0.0045),
    WatchdogBounds(actuation_error=1e-3, actuation_ticks=1),
    WatchdogBounds(actuation_error=0.5, actuation_ticks=40, innovation_nis=math.inf),
    # late samples never enough of them: the lag's queued late samples trip tracking, which
    # is named the lateness (LATE); the clean runs' samples, late or not, are never queued
    WatchdogBounds(deadline_misses=5000, deadline_window=5000, tracking_error=0.01),
    WatchdogBounds(deadline=1e-4, deadline_misses=5000, deadline_window=5000, tracking_error=0.01),
    # the lag's queued samples (80 ms behind) in a short window: lag before deadline; the
    # stall's catch-up too
    WatchdogBounds(deadline_misses=5000, deadline_window=200, lag=0.005),
    WatchdogBounds(lag=1e-5, deadline_window=3),
)
SIZES = {"jump": 0.01, "stall": 0.3, "lag": 0.08}


class CWatchdog:
    """amsfe_watchdog through ctypes, from the library's own symbols."""

    def __init__(self, path: str, config: WatchdogConfig) -> None:
        c = ctypes.CDLL(path)
        self.c = c
        vp, i, d = ctypes.c_void_p, ctypes.c_int, ctypes.c_double
        for name, res, args in (
            ("memory_size", ctypes.c_size_t, [vp]),
            ("init", i, [vp, vp, vp, ctypes.c_size_t]),
            ("sample", i, [vp, vp]),
            ("idle", i, [vp, d, i]),
            ("get_state", None, [vp, vp]),
            ("format", i, [vp, ctypes.c_char_p, ctypes.c_size_t]),
            ("reason_name", ctypes.c_char_p, [i]),
            ("cause_text", ctypes.c_char_p, [i, i]),
        ):
            f = getattr(c, f"amsfe_watchdog_{name}")
            f.restype, f.argtypes = res, args
        b = config.bounds
        self.cfg = Config(
            n=config.n,
            N=config.N,
            ne=config.ne,
            T=config.T,
            tracking_error=b.tracking_error,
            innovation_nis=b.innovation_nis,
            innovation_window=b.innovation_window,
            deadline=b.deadline,
            deadline_misses=b.deadline_misses,
            deadline_window=b.deadline_window,
            compute_budget=b.compute_budget,
            encoder_timeout=b.encoder_timeout,
            max_gap_steps=config.max_gap_steps,
            actuation_error=b.actuation_error,
            actuation_ticks=b.actuation_ticks,
            lag=b.lag,
        )
        self._u_max = np.ascontiguousarray(config.u_max, dtype=float)
        if config.u_max:
            self.cfg.u_max = self._u_max.ctypes.data
        size = c.amsfe_watchdog_memory_size(ctypes.byref(self.cfg))
        assert size > 0
        self._mem = np.zeros(size + 16, dtype=np.uint8)
        addr = self._mem.ctypes.data
        addr += (-addr) % 16
        self.h = ctypes.c_void_p()
        assert c.amsfe_watchdog_init(ctypes.byref(self.h), ctypes.byref(self.cfg), addr, size) == 0

    def sample(self, t: WatchdogTick) -> int:
        keep: list[Any] = []

        def ptr(a: Any) -> Any:
            if a is None:
                return None
            arr = np.ascontiguousarray(a, dtype=float)
            keep.append(arr)
            return arr.ctypes.data

        tick = Tick(
            k=t.k,
            gap=t.gap,
            stamp_ns=t.stamp_ns,
            taken=t.taken,
            done=t.done,
            status=t.status,
            x_hat=ptr(t.x_hat),
            P_diag=ptr(t.P_diag),
            q_des=ptr(t.q_des),
            u=ptr(t.u),
            handed_over=int(t.handed_over),
            encoder_nis=t.encoder_nis,
            frame_nis=ptr(t.frame_nis) if t.frame_nis else None,
            n_frames=len(t.frame_nis),
            applied=ptr(t.applied),
            applied_k=t.applied_k,
        )
        return int(self.c.amsfe_watchdog_sample(self.h, ctypes.byref(tick)))

    def idle(self, now: float, publishers: int) -> int:
        return int(
            self.c.amsfe_watchdog_idle(self.h, ctypes.c_double(now), ctypes.c_int(publishers))
        )

    def state(self) -> Any:
        s = State()
        self.c.amsfe_watchdog_get_state(self.h, ctypes.byref(s))
        return s

    def line(self) -> str:
        buf = ctypes.create_string_buffer(1024)
        self.c.amsfe_watchdog_format(self.h, buf, ctypes.c_size_t(1024))
        return buf.value.decode()


@pytest.fixture(scope="module")
def runs() -> dict[str, Any]:
    """Clean and faulty runs of paper-sim (every bound off: each run's calls cover it to its
    end, or to the encoder stall), and the library."""
    sc = load_scenario("paper-sim").with_overrides(duration=2.1, seed=5)
    lib = library_for(sc)
    out: dict[str, Any] = {"lib": lib}
    for kind in ("none", *FAULTS):
        f = Fault(kind, 1.5, SIZES.get(kind, 0.0))
        out[kind] = run_watched(sc, lib, f, bounds=OFF).events
    return out


def _u_max(lib: Any) -> tuple[float, ...]:
    """paper-sim's actuator limits, one joint's dropped (inf: the 1 N m scale exercised)."""
    u = list(lib.manifest.actuators.u_max)
    u[-1] = math.inf
    return tuple(u)


def _injected(events: list[WatchEvent], what: str) -> list[WatchEvent]:
    """A clean sequence with a non-finite command or an estimator failure after missing
    samples injected half-way."""
    ev = list(events)
    i = len(ev) // 2
    t = ev[i].tick
    assert t is not None
    if what == "nan":
        nan_u = np.array(t.u, dtype=float)
        nan_u[-1] = np.nan
        bad = dataclasses.replace(t, u=nan_u)
    else:
        bad = dataclasses.replace(t, status=-2, gap=3, x_hat=None, P_diag=None)
    ev[i] = dataclasses.replace(ev[i], tick=bad)
    return ev


def _lagging(lib: Any) -> list[WatchEvent]:
    """A synthetic stream 20 ms behind on every sample after the first (queued: the arm ran
    on older commands; never past deadline) whose arm drifts off its path by 0.125 mrad a
    sample: ``lag`` holds at sample 502 under the defaults (samples 2-502 queued),
    ``tracking`` at 801 without it."""
    out = []
    for k in range(1000):
        t, lag = k * 1e-3, (0.02 if k else 1e-4)
        q_des = np.zeros(lib.n)
        q_des[-1] = 1.25e-4 * k
        tick = WatchdogTick(k=k, gap=0, stamp_ns=k * 1_000_000, taken=t + lag - 1e-4,
                            done=t + lag, x_hat=np.zeros(lib.N), P_diag=np.ones(lib.N),
                            q_des=q_des, u=np.zeros(lib.n), handed_over=True,
                            encoder_nis=4.0)  # fmt: skip
        out.append(WatchEvent(tick, t + lag - 1e-4, -1, Reason.NONE))
    return out


def _first_hold(reasons: list[int]) -> tuple[int, int]:
    """The first hold of a sequence's reasons and its call (0, -1: none)."""
    held = [(r, i) for i, r in enumerate(reasons) if r]
    return held[0] if held else (0, -1)


def _compare(lib: Any, events: list[WatchEvent], bounds: WatchdogBounds) -> list[int]:
    config = WatchdogConfig(lib.n, lib.N, 2 * lib.n, lib.T, bounds, 5, _u_max(lib))
    py, c = Watchdog(config), CWatchdog(str(lib.library_path), config)
    reasons = []
    for i, e in enumerate(events):
        if e.tick is None:
            rp, rc = py.idle(e.now, e.publishers), c.idle(e.now, e.publishers)
        else:
            rp, rc = py.sample(e.tick), c.sample(e.tick)
        assert int(rp) == rc, f"call {i}: Python {rp!r}, C {rc}"
        s, seen = c.state(), py.seen
        assert (s.samples, s.max_late_in_window) == (seen.samples, seen.max_late_in_window)
        for name in ("max_tracking", "max_innovation", "max_lateness", "max_compute"):
            assert getattr(s, name) == getattr(seen, name), (i, name)
        assert s.max_wall_gap == seen.max_wall_gap
        assert (s.max_actuation, s.actuation_judged) == (seen.max_actuation, seen.actuation_judged)
        assert s.max_lag == seen.max_lag, i
        if py.hold is not None:
            h = py.hold
            assert (s.reason, s.cause, s.k, s.gap) == (h.reason, h.cause, h.k, h.gap)
            assert s.caused == h.caused
            assert s.bound == h.bound
            assert s.value == h.value or (math.isnan(s.value) and math.isnan(h.value))
        reasons.append(rc)
    assert c.line() == py.line()
    return reasons


@pytest.mark.slow
def test_c_watchdog_decides_as_python(runs: dict[str, Any]) -> None:
    lib = runs["lib"]
    seen: set[int] = set()
    causes: set[int] = set()
    sequences = {k: v for k, v in runs.items() if k != "lib"}
    sequences["nan"] = _injected(runs["none"], "nan")
    sequences["failed"] = _injected(runs["none"], "failed")
    sequences["lagging"] = _lagging(lib)
    for name, events in sequences.items():
        for bounds in BOUNDS:
            reasons = _compare(lib, events, bounds)
            held = [r for r in reasons if r]
            if held:
                seen.add(held[0])
                config = WatchdogConfig(lib.n, lib.N, 2 * lib.n, lib.T, bounds, 5, _u_max(lib))
                c = CWatchdog(str(lib.library_path), config)
                for e in events:
                    if (c.idle(e.now, e.publishers) if e.tick is None else c.sample(e.tick)) != 0:
                        break
                causes.add(c.state().cause)
            assert name != "none" or bounds != WatchdogBounds() or not held, name
    # the lagging stream: lag before tracking; without it tracking, at the same calls in C
    lagging = sequences["lagging"]
    assert _first_hold(_compare(lib, lagging, WatchdogBounds())) == (Reason.LAG, 502)
    off = WatchdogBounds(lag=math.inf)
    assert _first_hold(_compare(lib, lagging, off)) == (Reason.TRACKING, 801)
    # every reason and most causes were exercised, so the comparison covered them
    assert seen == set(range(1, len(REASON_NAMES))), sorted(seen)
    expected = {Cause.LOST, Cause.UNSCHEDULED, Cause.SILENT, Cause.BEHIND, Cause.COMMAND}
    expected |= {Cause.LATE}
    assert expected <= causes, sorted(causes)


def test_c_names_and_texts_are_python_s(runs: dict[str, Any]) -> None:
    """The names and the cause texts of the C are the Python's, character for character."""
    from amsfe_sym.ros.watchdog import CAUSE_TEXT

    lib = runs["lib"]
    config = WatchdogConfig(lib.n, lib.N, 2 * lib.n, lib.T)
    c = CWatchdog(str(lib.library_path), config).c
    for r in Reason:
        assert c.amsfe_watchdog_reason_name(int(r)).decode() == REASON_NAMES[r]
    for (reason, cause), text in CAUSE_TEXT.items():
        assert c.amsfe_watchdog_cause_text(int(reason), int(cause)).decode() == text


def test_c_refuses_a_bad_config(runs: dict[str, Any]) -> None:
    """A bad config: memory_size 0, init AMSFE_ERR_CONFIG; a small block AMSFE_ERR_MEMORY;
    the Python refuses the same configs."""
    from amsfe_sym.errors import ConfigError

    lib = runs["lib"]
    good = WatchdogConfig(lib.n, lib.N, 2 * lib.n, lib.T)
    c = CWatchdog(str(lib.library_path), good)
    for bad in (
        dataclasses.replace(good, T=0.0),
        dataclasses.replace(good, ne=0),
        dataclasses.replace(good, bounds=WatchdogBounds(innovation_nis=math.nan)),
        dataclasses.replace(good, max_gap_steps=-1),
    ):
        cfg = Config(**{k: getattr(c.cfg, k) for k, _ in Config._fields_})
        cfg.T, cfg.ne = bad.T, bad.ne
        cfg.innovation_nis, cfg.max_gap_steps = bad.bounds.innovation_nis, bad.max_gap_steps
        assert c.c.amsfe_watchdog_memory_size(ctypes.byref(cfg)) == 0
        h = ctypes.c_void_p()
        assert (
            c.c.amsfe_watchdog_init(ctypes.byref(h), ctypes.byref(cfg), c._mem.ctypes.data, 64)
            == -6
        )
        with pytest.raises(ConfigError):
            Watchdog(bad)
    h = ctypes.c_void_p()
    assert (
        c.c.amsfe_watchdog_init(ctypes.byref(h), ctypes.byref(c.cfg), c._mem.ctypes.data, 8) == -7
    )


@pytest.mark.slow
def test_c_controller_hands_over_at_the_python_tick() -> None:
    """amsfe_ctrl_handed_over (what the C node gives its tracking watchdog) is the Python
    controller's handed_over at every tick of a closed-loop run whose start-up waits and
    blends (the two controllers on the same inputs, their torques equal to 1e-12)."""
    from amsfe_sym.ros.arm import SimArm
    from amsfe_sym.ros.live import LiveLoop
    from tests.test_startup import controller_pair

    sc = load_scenario("paper-sim").with_overrides(duration=1.6, seed=3)
    lib = library_for(sc)
    arm, loop = SimArm(sc, lib), LiveLoop(sc, lib, controller=True)
    _, cc, ref = controller_pair(sc, lib, arm.K)
    handed = ctypes.CDLL(str(lib.library_path)).amsfe_ctrl_handed_over
    handed.restype, handed.argtypes = ctypes.c_int, [ctypes.c_void_p, ctypes.c_long]
    T_ns, N = round(lib.T * 1e9), lib.N
    flips = []
    for k in range(arm.K):
        s = arm.sense()
        for f in s.frames:
            loop.frame(f.exposure_step * T_ns, f.z)
        out = loop.encoders(k * T_ns, s.z)
        assert out is not None and out.u is not None and loop.ctrl is not None and loop.est
        nis = None if out.report is None else out.report.encoder_nis
        u_c = cc.torque(k, ref[k], out.x_hat, s.z, None, loop.est.P[:N, :N], nis)
        np.testing.assert_allclose(u_c, out.u, rtol=1e-12, atol=1e-12, err_msg=f"k={k}")
        py = loop.ctrl.handed_over(k)
        assert bool(handed(cc.handle, k)) == py, k
        if not flips or flips[-1][1] != py:
            flips.append((k, py))
        arm.advance(out.u)
    # it waited, then blended, then handed over once, within the run
    assert [f[1] for f in flips] == [False, True] and 0 < flips[1][0] < arm.K - 1, flips


def test_c_watchdog_builds_alone_and_never_allocates(tmp_path: Path) -> None:
    """amsfe_watchdog.c compiles on its own (C99, every warning an error) and calls nothing
    but memset, memcpy and snprintf: no allocation, no clock, no I/O of its own."""
    import shutil
    import subprocess

    from amsfe_sym.codegen import compiler
    from amsfe_sym.runtime.cheader import C_DIR

    cc = compiler()
    if shutil.which(cc) is None or shutil.which("nm") is None:
        pytest.skip("no C compiler or nm")
    obj = tmp_path / "amsfe_watchdog.o"
    flags = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O1", "-c"]
    subprocess.run([cc, *flags, str(C_DIR / "amsfe_watchdog.c"), "-o", str(obj)], check=True)
    nm = subprocess.run(["nm", "-u", str(obj)], check=True, capture_output=True, text=True)
    called = {line.split()[-1] for line in nm.stdout.splitlines() if line.strip()}
    assert called <= {"memset", "memcpy", "snprintf"}, called
