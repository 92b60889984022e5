"""An image topic decoded ahead on worker threads (docs/camera.md, "Speed";
:mod:`amsfe_sym.vision.prefetch`): the same detections and the same estimate as the serial
decoder, bit for bit; at most ``depth`` frames in hand; a corrupt jpeg in the middle of a
log skipped and counted on both paths; a bad frame or Ctrl-C stops the threads and says so
in one line.

The logs: a 3 s paper-sim run written by ``amsfe simulate --bag --images jpeg`` with a 30 Hz
camera (~90 jpeg CompressedImages in ~10 MCAP chunks), and tests/test_vision.py's driver-style
logs (rosbags' writers) for the corrupt frame.
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from amsfe_sym.apps.cli import main
from amsfe_sym.codegen import library_for
from amsfe_sym.errors import ConfigError, LogError
from amsfe_sym.logs import stream
from amsfe_sym.logs.image_wire import image_message
from amsfe_sym.logs.read import read_log
from amsfe_sym.logs.spec import LogSpec
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run
from amsfe_sym.vision.detections import UNDECODABLE, Detections, ImageDecoder
from amsfe_sym.vision.prefetch import THREADS_ENV, Prefetch, image_threads
from amsfe_sym.vision.spec import MarkerSpec
from tests.test_log_reader import arm_events
from tests.test_vision import CIMG, _check_frames, image_frames, write_images_log

JOINTS = ["joint1", "joint2"]


def _threads_alive() -> list[str]:
    return [t.name for t in threading.enumerate() if t.name.startswith("amsfe-image")]


@pytest.fixture(scope="module")
def jpeg_log(tmp_path_factory) -> Path:
    """``amsfe simulate --bag --images jpeg``: 3 s, a 30 Hz camera (period = delay = 33)."""
    out = tmp_path_factory.mktemp("jpeg") / "run"
    code = main(
        ["simulate", "--controller", "amsfe", "--duration", "3", "--seed", "29", "--out",
         str(out), "--bag", "--no-plots", "--no-progress", "--set", "camera.period=33",
         "--set", "camera.delay=33", "--images", "jpeg"]
    )  # fmt: skip
    assert code == 0
    return out / "bag"


@pytest.fixture(scope="module")
def sim():
    """A 1 s paper-sim run (compiled loop, oosm): 8 camera frames."""
    sc = load_scenario("paper-sim").with_overrides(
        estimator="oosm", controller="amsfe", duration=1.0, seed=3
    )
    return run(sc, library_for(sc), runtime="compiled")


def _payloads(log: Path) -> list[Any]:
    """The image topic's payloads of ``log``, as uint8 arrays."""
    got = stream.read_topics(log, ["/camera/image_raw/compressed"], progress=False)
    return got["/camera/image_raw/compressed"].raw


def _same(a: Detections, b: Detections) -> None:
    for f in ("stamp_ns", "corners", "reason", "size"):
        assert np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True), f


def _decode(payloads: list[Any], threads: int, depth: int = 32, slice_: int = 7) -> Detections:
    """The payloads decoded in slices of ``slice_``, serially (0) or prefetched."""
    serial = ImageDecoder(CIMG, MarkerSpec(), image_message)
    dec: Any = serial if threads == 0 else Prefetch(serial, threads, depth)
    try:
        parts = [dec(payloads[i : i + slice_]) for i in range(0, len(payloads), slice_)]
        return Detections.concat([p.result() if threads else p for p in parts])
    finally:
        if threads:
            dec.close()


@pytest.mark.slow
def test_prefetched_detections_and_estimate_equal_the_serial_ones(
    jpeg_log: Path, tmp_path, monkeypatch, capsys
) -> None:
    """Corners, reasons, stamps and sizes of every frame, the frames on the grid, the
    counts, and ``amsfe estimate``'s estimates and summary: identical, serial (0 threads)
    against 1 and 2 decoding threads and a depth of 1 (bit for bit: the detections run in
    the log's order on the same images)."""
    payloads = _payloads(jpeg_log)
    assert len(payloads) > 80
    ref = _decode(payloads, 0)
    assert (ref.reason == 0).all()
    for threads, depth in ((1, 32), (2, 8), (2, 1)):
        _same(ref, _decode(payloads, threads, depth))
    logs = {n: read_log(jpeg_log, LogSpec(), JOINTS, 0.001, 9, image_threads=n) for n in (0, 2)}
    a, b = logs[0], logs[2]
    assert len(a.frames) == len(b.frames) == len(payloads)
    for fa, fb in zip(a.frames, b.frames, strict=True):
        assert np.array_equal(fa.z, fb.z)
        assert (fa.exposure_step, fa.delivery_step) == (fb.exposure_step, fb.delivery_step)
    assert a.skipped == b.skipped and np.array_equal(a.z, b.z)
    assert not _threads_alive()
    # the whole command, each way ($AMSFE_IMAGE_THREADS)
    import pandas as pd

    out = {}
    for n in ("0", "2"):
        monkeypatch.setenv(THREADS_ENV, n)
        est = tmp_path / f"est-{n}"
        code = main(["estimate", str(jpeg_log), "--out", str(est), "--no-plots"])
        assert code == 0, capsys.readouterr().err
        out[n] = (
            pd.read_parquet(est / "estimates.parquet"),
            json.loads((est / "summary.json").read_text()),
        )
    ea, eb = out["0"][0], out["2"][0]
    assert list(ea.columns) == list(eb.columns) and len(ea) == 3001
    assert np.array_equal(ea.to_numpy(), eb.to_numpy(), equal_nan=True)
    sa, sb = out["0"][1], out["2"][1]
    assert sa["frames_fused"] == sb["frames_fused"] == len(payloads)
    assert sa["estimation_rmse_q"] == sb["estimation_rmse_q"]
    assert sa["topics"]["camera"] == sb["topics"]["camera"]


@pytest.mark.slow
def test_at_most_depth_frames_are_in_hand(jpeg_log: Path) -> None:
    """With the detection held, the reader hands out ``depth`` frames and waits: no more are
    decoded until one is detected; the peak never exceeds ``depth``."""
    payloads = _payloads(jpeg_log)[:30]
    serial = ImageDecoder(CIMG, MarkerSpec(), image_message)
    hold = threading.Event()
    decoded: list[int] = []
    grey, detect_into = serial.grey, serial.detect_into

    def counted(*a: Any) -> Any:
        decoded.append(1)
        return grey(*a)

    def held(*a: Any) -> None:
        hold.wait(60)
        detect_into(*a)

    serial.grey, serial.detect_into = counted, held  # type: ignore[method-assign]
    pre = Prefetch(serial, threads=2, depth=3)
    result: list[Any] = []
    reader = threading.Thread(target=lambda: result.append(pre(payloads)))
    reader.start()
    for _ in range(600):  # (until the reader is blocked on the room: 3 frames handed out)
        if len(decoded) >= 3:
            break
        threading.Event().wait(0.05)
    reader.join(0.5)
    assert reader.is_alive()  # waiting for room: not every frame was read
    assert len(decoded) == 3 and pre.peak == 3
    hold.set()
    reader.join(60)
    got = result[0].result()
    pre.close()
    assert len(decoded) == 30 and pre.peak == 3 and (got.reason == 0).all()
    assert not _threads_alive()


def _corrupt(frames: list[tuple], index: int, how: str) -> list[tuple]:
    """``frames`` (tests/test_vision.py's events) with image ``index``'s jpeg truncated to
    half (``half``) or its format ``bmp``."""
    images = [i for i, e in enumerate(frames) if e[2] == CIMG]
    i = images[index]
    t, topic, msgtype, build = frames[i]

    def bad(ts: Any, ros1: bool) -> Any:
        msg = build(ts, ros1)
        if how == "half":
            msg.data = msg.data[: msg.data.size // 2]
        else:
            msg.format = "bmp"
        return msg

    return [*frames[:i], (t, topic, msgtype, bad), *frames[i + 1 :]]


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["mcap", "bag"])
def test_a_corrupt_jpeg_in_the_middle_is_skipped_and_counted(fmt: str, sim, tmp_path) -> None:
    """The 4th jpeg cut to half its bytes (it does not decode): skipped and counted under
    its reason, serial and prefetched alike; every other frame fused as without it."""
    joints, _ = arm_events(sim, camera=False)
    frames, truth = image_frames(sim, "jpeg")
    name = "log.bag" if fmt == "bag" else "log"
    log = write_images_log(tmp_path / name, joints, _corrupt(frames, 3, "half"), fmt)
    lib = sim.lib
    got = {}
    for n in (0, 2):
        got[n] = read_log(log, LogSpec(), list(lib.manifest.joints), lib.T, lib.N, image_threads=n)
        use = got[n].usage["camera"]
        assert use.skipped == {UNDECODABLE: 1}, use.skipped
        assert got[n].skipped[f"frame {UNDECODABLE}"] == 1
        fourth = sorted(truth)[3]
        _check_frames(sim, got[n], {k: v for k, v in truth.items() if k != fourth})
    assert [f.z.tolist() for f in got[0].frames] == [f.z.tolist() for f in got[2].frames]
    assert not _threads_alive()


@pytest.mark.slow
def test_a_bad_frame_stops_the_threads_with_one_line(sim, tmp_path, capsys) -> None:
    """A CompressedImage in a format not read (``bmp``) in the middle: the reader stops
    with the serial path's one line (exit 2, no run folder) and no decoding thread left."""
    joints, _ = arm_events(sim, camera=False)
    frames, _ = image_frames(sim, "jpeg")
    log = write_images_log(tmp_path / "log", joints, _corrupt(frames, 4, "format"), "mcap")
    lib = sim.lib
    errors = []
    for n in (0, 2):
        with pytest.raises(LogError) as e:
            read_log(log, LogSpec(), list(lib.manifest.joints), lib.T, lib.N, image_threads=n)
        errors.append(str(e.value))
        assert not _threads_alive()
    assert errors[0] == errors[1] and "'bmp'" in errors[0] and "\n" not in errors[0]
    out = tmp_path / "o"
    code = main(["estimate", str(log), "--robot", "paper_2link", "--out", str(out), "--no-plots"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith("error:") and "\n" not in err and "'bmp'" in err
    assert not out.exists() and not _threads_alive()


@pytest.mark.slow
def test_ctrl_c_during_the_read_ends_the_threads(jpeg_log: Path, monkeypatch) -> None:
    """A KeyboardInterrupt on the reading thread at the 3rd chunk (Ctrl-C's exception)
    propagates as itself; the decoding and detection threads are ended before it leaves."""
    calls = []
    chunk = stream._chunk

    def interrupted(*a: Any) -> None:
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        chunk(*a)

    monkeypatch.setattr(stream, "_chunk", interrupted)
    with pytest.raises(KeyboardInterrupt):
        read_log(jpeg_log, LogSpec(), JOINTS, 0.001, 9, image_threads=2)
    assert len(calls) == 3 and not _threads_alive()


def test_the_threads_setting(monkeypatch) -> None:
    """``$AMSFE_IMAGE_THREADS``: 0 (serial) to 16; unset: 2 for compressed images on 2+
    cores, 0 for raw ones; else one line."""
    monkeypatch.setenv(THREADS_ENV, "0")
    assert image_threads() == 0
    monkeypatch.setenv(THREADS_ENV, "3")
    assert image_threads() == 3 and image_threads(compressed=False) == 3
    monkeypatch.delenv(THREADS_ENV)
    monkeypatch.setattr("os.cpu_count", lambda: 2)
    assert image_threads() == 2 and image_threads(compressed=False) == 0
    monkeypatch.setattr("os.cpu_count", lambda: 1)
    assert image_threads() == 0
    for bad in ("two", "-1", "17", "1.5"):
        with pytest.raises(ConfigError) as e:
            image_threads(bad)
        assert THREADS_ENV in str(e.value) and "\n" not in str(e.value)


@pytest.mark.slow
def test_the_bench_times_serial_and_prefetched_on_one_log(tmp_path) -> None:
    """``amsfe bench --logs paper-sim:1:jpeg:threads=0 paper-sim:1:jpeg``: the log written
    once, both cases estimated from it, each its own row with the same frames."""
    from amsfe_sym.apps.bench.logs import bench_log_estimates, log_case

    cases = [log_case("paper-sim:1:jpeg:threads=0"), log_case("paper-sim:1:jpeg")]
    rows = bench_log_estimates(cases, 1, tmp_path)
    assert [r.get("error") for r in rows] == [None, None], rows
    assert rows[0]["image_threads"] == 0 and "image_threads" not in rows[1]
    assert rows[0]["frames"] == rows[1]["frames"] > 20
    assert sorted(p.name for p in tmp_path.iterdir()) == ["estimate-0-0", "estimate-1-0", "log0"]


@pytest.mark.slow
def test_sigint_during_the_read_is_one_line(jpeg_log: Path, tmp_path) -> None:
    """A real Ctrl-C (SIGINT) to ``amsfe estimate`` 0.2 s after it printed its topic plan:
    the read of the 90 images on 2 decoding threads comes next and takes ~0.5 s, so the
    signal usually lands in it (21-49 frames detected in 4 tries by hand); wherever it
    lands: exit 130, one line, no traceback, no run folder."""
    import os
    import signal
    import subprocess
    import sys

    out = tmp_path / "est"
    env = {**os.environ, "PYTHONUNBUFFERED": "1", THREADS_ENV: "2"}
    # (run as the ``amsfe`` script runs it: ``python -m amsfe_sym`` exits by SIGINT after
    # the same one line, serial decoding too: runpy's path, not the threads')
    run = "import sys; from amsfe_sym.__main__ import run; sys.exit(run())"
    cmd = [sys.executable, "-c", run, "estimate", str(jpeg_log), "--out", str(out)]
    proc = subprocess.Popen(
        [*cmd, "--no-plots"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    assert proc.stdout is not None
    seen = []
    for line in proc.stdout:  # the plan's lines come before the read
        seen.append(line)
        if line.startswith("  truth: "):
            break
    assert proc.poll() is None, seen
    threading.Event().wait(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert len(lines) == 1 and lines[0].startswith("interrupted: amsfe estimate"), err
    assert not out.exists()


#: A prefetch whose decoding thread holds the room semaphore's lock while a Ctrl-C comes:
#: the reading thread waits to enter that lock when the interruption is due.
_CTRL_C_IN_THE_ROOMS_LOCK = """
import _thread, time
import numpy as np
from amsfe_sym.vision.images import GreyImage
from amsfe_sym.vision.prefetch import Prefetch

class Contending:
    frames = calls = 0
    def grey(self, raw, encoding="cdr", where=""):
        self.calls += 1
        if self.calls == 1:
            cond = prefetch._room._cond
            cond.acquire()
            time.sleep(0.1)
            _thread.interrupt_main()
            time.sleep(0.1)
            cond.release()
        return GreyImage(0, np.zeros((1, 1), np.uint8))
    def detect_into(self, cols, i, img):
        self.frames += 1

prefetch = Prefetch(Contending(), threads=1, depth=64)
try:
    prefetch([b"x"] * 50).result()
    print("not interrupted")
except KeyboardInterrupt:
    print("interrupted")
finally:
    prefetch.close()
print("closed")
"""


def test_ctrl_c_while_the_reader_enters_the_rooms_lock_never_hangs() -> None:
    """A Ctrl-C raised as the reading thread takes the room semaphore's lock used to leave
    that lock held (core/interrupts.py's docstring): the detection thread then waited for it
    forever and ``close`` with it (``amsfe estimate`` of a jpeg log hung on a Ctrl-C).  Now
    the Ctrl-C is raised between two waits and ``close`` ends."""
    done = subprocess.run(
        [sys.executable, "-c", _CTRL_C_IN_THE_ROOMS_LOCK],
        capture_output=True,
        text=True,
        timeout=60,  # (a hang fails here)
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["interrupted", "closed"]
