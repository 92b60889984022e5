"""Fuzzing the C log format (issue 20 items 5 and 7): the example readers
``examples/estimate_from_log.c`` and ``examples/control_from_log.c`` over damaged logs.

A short valid log of each kind (the estimator's, the loop's) is damaged by hypothesis: lines
deleted, repeated, swapped or invented, tokens replaced (``nan``, ``1.5x``, huge integers,
text), removed or added, the file truncated at any byte, binary bytes inserted.  Every input
either runs (exit 0, and then every estimate, covariance and torque written is finite) or
stops with exit 1 (a runtime call refused the data) or 2 (a malformed log) and one line on
stderr naming the file and the line (``LOG:LINE: ...``); never a signal, never a hang."""

from __future__ import annotations

import math
import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from amsfe_sym.codegen import compiler, library_for
from amsfe_sym.estimation import CameraFrame
from amsfe_sym.runtime.compiled_estimator import make_compiled_estimator, write_log
from amsfe_sym.runtime.compiled_loop import write_loop_log
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.builders import build_run
from amsfe_sym.sim.compiled import controller_params, simulation_inputs
from amsfe_sym.sim.loop import run
from tests.conftest import build_example
from tests.test_compiled_estimator import record

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))
#: ``LOG:LINE: message``, one line.
ERROR_LINE = re.compile(r"^(?P<path>.+?):(?P<line>\d+): \S.*\n$")


@dataclass(frozen=True)
class Reader:
    """A compiled example and a valid log it reads."""

    exe: Path
    log: bytes
    prefix: str  # the records whose numbers must be finite after a run that exits 0


@pytest.fixture(scope="module")
def readers(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Reader]:
    if shutil.which(compiler()) is None:
        pytest.skip("no C compiler")
    tmp = tmp_path_factory.mktemp("fuzz-log")
    # the estimator's log: 20 ticks of paper-sim, two frames (one fused, one late)
    rec = record(duration=0.03)
    K = 20
    frames: list[list[CameraFrame]] = [[] for _ in range(K)]
    z_px = np.array([320.0, 240.0])
    frames[12] = [CameraFrame(10, z_px)]
    frames[16] = [CameraFrame(14, z_px + 1.0), CameraFrame(15, z_px)]
    est = make_compiled_estimator("oosm", **rec.kwargs)
    est_log = write_log(tmp / "est.log", est, rec.u[:K], list(rec.z[1 : K + 1]), frames)
    lib = rec.lib
    est_exe = build_example("estimate_from_log", lib, tmp / "estimate")
    # the loop's log: 20 steps of a compiled paper-sim run, with two delivered frames
    sc = load_scenario("paper-sim").with_overrides(duration=0.019, estimator="oosm")
    lib = library_for(sc)
    c = run(sc, lib, runtime="compiled")
    parts = build_run(sc, lib, compiled=True)
    inputs, _ = simulation_inputs(sc, lib, c.t.size, parts)
    rows = np.array([[10, 12, 320.0, 240.0], [14, 16, 321.0, 241.0]])
    loop_log = write_loop_log(
        tmp / "loop.log",
        parts.estimator,  # type: ignore[arg-type]
        controller_params(parts.controller, lib),
        c.z_enc,
        inputs.ref,
        rows,
    )
    loop_exe = build_example("control_from_log", lib, tmp / "control")
    return {
        "estimate": Reader(est_exe, est_log.read_bytes(), "est "),
        "control": Reader(loop_exe, loop_log.read_bytes(), "u "),
    }


def _run(reader: Reader, data: bytes, path: Path) -> subprocess.CompletedProcess[bytes]:
    path.write_bytes(data)
    return subprocess.run([str(reader.exe), str(path)], capture_output=True, timeout=60)


def _check(reader: Reader, data: bytes, path: Path) -> int:
    """Run the reader on ``data``; assert the property; return the exit status."""
    proc = _run(reader, data, path)
    err = proc.stderr.decode(errors="replace")
    assert proc.returncode >= 0, f"killed by signal {-proc.returncode}: {err}"
    assert proc.returncode in (0, 1, 2), (proc.returncode, err)
    if proc.returncode == 0:
        for line in proc.stdout.decode().splitlines():
            if line.startswith(reader.prefix):
                values = [float(v) for v in line.split()[1:]]
                assert all(math.isfinite(v) for v in values), f"exit 0 with NaN/inf: {line}"
    else:
        m = ERROR_LINE.match(err)
        assert m, f"expected one line 'LOG:LINE: message', found {err!r}"
        assert m["path"] == str(path)
        assert 0 <= int(m["line"]) <= data.count(b"\n") + 1
        assert proc.stdout.count(b"\n") <= data.count(b"\n")
    return proc.returncode


# ---------------------------------------------------------------- damage
TOKENS = st.one_of(
    st.sampled_from(
        [
            "nan",
            "-nan",
            "inf",
            "-inf",
            "1e999",
            "1e-999",
            "abc",
            "1.5x",
            "0x10",
            "-1",
            "0",
            "1",
            "2",
            "3.5",
            "2147483648",
            "-9223372036854775809",
            "99999999999999999999",
            "tick",
            "frame",
            "step",
            "P0",
        ]
    ),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=-(2**70), max_value=2**70).map(str),
    st.text(alphabet=st.characters(min_codepoint=33, max_codepoint=126), min_size=1, max_size=6),
)


@st.composite
def damaged(draw: st.DrawFn, log: bytes) -> bytes:
    lines = log.split(b"\n")[:-1]  # every line of a valid log ends with \n
    for _ in range(draw(st.integers(1, 3))):
        if not lines:
            lines = [b""]
        i = draw(st.integers(0, len(lines) - 1))
        toks = lines[i].split(b" ")
        kind = draw(  # value changes (the structure kept) most often: they reach the runtime
            st.sampled_from(
                ["delete", "repeat", "swap", "invent", "drop", "add", "blank"] + ["replace"] * 5
            )
        )
        if kind == "replace" and len(toks) > 1 and draw(st.booleans()):
            j = draw(st.integers(1, len(toks) - 1))  # a value, by a number of any size
            toks[j] = repr(draw(st.floats(allow_nan=True, allow_infinity=True))).encode()
            lines[i] = b" ".join(toks)
        elif kind == "delete":
            del lines[i]
        elif kind == "repeat":
            lines.insert(i, lines[i])
        elif kind == "swap":
            j = draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
        elif kind == "invent":
            words = draw(st.lists(TOKENS, min_size=1, max_size=12))
            lines.insert(i, " ".join(words).encode())
        elif kind == "replace":
            j = draw(st.integers(0, len(toks) - 1))
            toks[j] = draw(TOKENS).encode()
            lines[i] = b" ".join(toks)
        elif kind == "drop" and len(toks) > 1:
            del toks[draw(st.integers(1, len(toks) - 1))]
            lines[i] = b" ".join(toks)
        elif kind == "add":
            toks.insert(draw(st.integers(1, len(toks))), draw(TOKENS).encode())
            lines[i] = b" ".join(toks)
        elif kind == "blank":
            lines.insert(i, b"")
    data = b"".join(ln + b"\n" for ln in lines)
    tail = draw(st.sampled_from(["whole"] * 4 + ["truncated", "bytes"]))
    if tail == "truncated":
        data = data[: draw(st.integers(0, len(data)))]
    elif tail == "bytes":
        at = draw(st.integers(0, len(data)))
        data = data[:at] + draw(st.binary(min_size=1, max_size=8)) + data[at:]
    return data


@pytest.mark.parametrize("name", ["estimate", "control"])
def test_the_valid_log_runs(readers: dict[str, Reader], name: str, tmp_path: Path) -> None:
    reader = readers[name]
    assert _check(reader, reader.log, tmp_path / "ok.log") == 0
    out = _run(reader, reader.log, tmp_path / "ok.log").stdout.decode()
    assert out.count(reader.prefix) == 20


@pytest.mark.parametrize(
    ("damage", "words"),
    [
        (lambda log: log + b"bogus 1 2 3\n", "found 'bogus'"),
        (lambda log: log[:-5], "truncated"),
        (lambda log: log.replace(b"\ntick ", b"\ntick 1 ", 1), "found 7"),
        (lambda log: log.replace(b"\nr_camera ", b"\nr_camera 1.5x ", 1), "'1.5x'"),
        (lambda log: log.replace(b"\nframe 10 ", b"\nframe 10.5 ", 1), "integer"),
        (lambda log: b"\n".join(ln for ln in log.split(b"\n") if not ln.startswith(b"qw ")), "qw"),
        (lambda log: log.replace(b"\n", b"\n\0", 1), "NUL"),
    ],
    ids=["unknown", "truncated", "long-vector", "bad-number", "float-step", "missing", "nul"],
)
def test_a_defect_is_named_with_its_line(
    readers: dict[str, Reader], damage: object, words: str, tmp_path: Path
) -> None:
    reader = readers["estimate"]
    data = damage(reader.log)  # type: ignore[operator]
    path = tmp_path / "bad.log"
    proc = _run(reader, data, path)
    err = proc.stderr.decode()
    assert proc.returncode == 2 and words in err and ERROR_LINE.match(err), err


@FUZZ
@given(data=st.data())
@pytest.mark.parametrize("name", ["estimate", "control"])
def test_fuzz_reader(
    readers: dict[str, Reader],
    name: str,
    data: st.DataObject,
    tmp_path_factory: pytest.TempPathFactory,
) -> None:
    reader = readers[name]
    log = data.draw(damaged(reader.log))
    _check(reader, log, tmp_path_factory.mktemp("f") / "run.log")


# ---------------------------------------------------------------- the rosbag / MCAP log reader
# (issue 25 item 3, issue 26): random topic sets, types, field lengths, stamps, encodings and
# truncation through `amsfe estimate LOG --robot paper_2link`: exit 0 only with a complete run
# whose encoder samples are the ones written, on the ticks they were written for; otherwise
# one line on stderr, exit 2, no run folder.
@pytest.fixture(scope="module")
def short_run():
    """0.3 s of paper-sim (compiled loop): the samples the fuzzed logs carry."""
    sc = load_scenario("paper-sim").with_overrides(
        estimator="oosm", controller="amsfe", duration=0.3, seed=4
    )
    return run(sc, library_for(sc), runtime="compiled")


STAMP_FAULTS = ["none"] * 6 + ["zero", "far", "duplicate", "backwards", "all_zero", "gap", "nan"]


@st.composite
def arm_logs(draw: st.DrawFn, res) -> tuple[list, str, dict]:
    """(events, container, expectation) of a random log of ``res``."""
    from tests.test_log_reader import F64, JS, PT, STR, Ev

    T, n = res.lib.T, res.lib.n
    joints = list(res.lib.manifest.joints)
    K = draw(st.integers(3, 120))
    topic = draw(st.sampled_from(["/joint_states", "/motor_encoders", "/arm/state"]))
    enc_type = draw(st.sampled_from([JS] * 8 + [STR, F64]))
    names = list(joints)
    extra = draw(st.sampled_from(["none"] * 4 + ["fingers"] * 3 + ["missing", "twice"]))
    if extra == "fingers":
        names = ["finger", *names[::-1]]
    elif extra == "missing":
        names = names[:1]
    elif extra == "twice":
        names = [names[0], *names]
    width = len(names)
    pos_len = draw(st.sampled_from([width] * 12 + [0, width + 1, max(width - 1, 0)]))
    vel_len = draw(st.sampled_from([width] * 12 + [0, width + 1]))
    fault = draw(st.sampled_from(STAMP_FAULTS))
    offset = draw(st.sampled_from([0.0, 203.6, 5.0]))
    jitter = draw(st.sampled_from([0.0, 0.1, 0.2]))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    ev, kept = [], {}
    for k in range(K):
        st_k = 2.0 + k * T + offset + rng.uniform(-jitter, jitter) * T  # ROS times are >= 0
        lt = 2.0 + k * T + 1e-4
        pos, vel, eff = np.full(width, 0.01), np.full(width, 0.02), np.full(width, 0.03)
        for j, name in enumerate(joints):
            if name in names:
                pos[names.index(name)] = res.z_enc[k, j]
                vel[names.index(name)] = res.z_enc[k, n + j]
                eff[names.index(name)] = res.u[k, j]
        good = True
        if fault == "zero" and k == K // 2 and offset != 0.0 and k > 0:
            st_k, good = 0.0, False
        elif fault == "far" and k == K // 2 and k > 0:
            st_k, good = st_k + 11.6 * 86400, False
        elif fault == "all_zero":
            st_k, good = 0.0, False
        elif fault == "backwards":
            st_k, good = 2.0 + (K - k) * T + offset, False
        elif fault == "gap" and K // 3 <= k < K // 3 + 8:
            continue
        elif fault == "nan" and k == K // 2 and k > 0:
            pos[0], good = draw(st.sampled_from([np.nan, np.inf, -np.inf])), False
        ev.append(
            Ev(
                lt,
                topic,
                enc_type,
                st_k,
                names,
                pos[:pos_len] if pos_len <= width else np.append(pos, 0.0),
                vel[:vel_len] if vel_len <= width else np.append(vel, 0.0),
                eff,
            )
        )
        if fault == "duplicate" and k == 1:
            ev.append(Ev(lt, topic, enc_type, st_k, names, pos, vel, eff))
        if good:
            kept[k] = res.z_enc[k]
    effort = draw(st.sampled_from(["shared"] * 3 + ["array", "array_short", "state", "late"]))
    if effort != "shared":  # a separate /motor_torque (the default effort topic) too
        short = effort == "array_short"
        for k in range(K):
            if effort == "late" and k < 3:
                continue
            if effort in ("array", "array_short"):
                data_k = res.u[k, : n - 1] if short else res.u[k]
                ev.append(Ev(2.0 + k * T + 2e-4, "/motor_torque", F64, data=data_k))
            else:
                st_e = 2.0 + k * T + offset + 0.3 * T
                ev.append(
                    Ev(2.0 + k * T + 2e-4, "/motor_torque", JS, st_e, joints, (), (), res.u[k])
                )
    if draw(st.booleans()):  # camera frames, maybe of the wrong type
        cam_type = draw(st.sampled_from([PT] * 4 + [F64]))
        for kappa in range(0, K, 25):
            arrive = kappa + draw(st.integers(-2, 30))
            xy = (draw(st.just(np.nan) | st.floats(-1e3, 1e3)), 200.0)
            ev.append(
                Ev(
                    2.0 + arrive * T + 1e-4,
                    "/camera/marker",
                    cam_type,
                    2.0 + kappa * T + offset,
                    xy=xy,
                    data=[1.0],
                )
            )
    fmt = draw(st.sampled_from(["bag", "mcap", "sqlite3", "mcapfile"]))
    # the log starts at the first effort sample (tick 3); a log of 3 ticks has none on
    # /motor_torque, so it has no such topic and the encoders' own effort serves
    if effort == "late" and K > 3:
        later = [k for k in kept if k >= 3]
        kept = {k: v for k, v in kept.items() if later and k >= min(later)}
    expect = {"kept": kept, "topic": topic, "fault": fault}
    return ev, fmt, expect


@pytest.mark.slow
@settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck), database=None)
@given(data=st.data())
def test_fuzz_log_reader(
    short_run, data: st.DataObject, tmp_path_factory: pytest.TempPathFactory
) -> None:
    import json

    from amsfe_sym.apps.cli import main
    from amsfe_sym.logs.read import read_log
    from amsfe_sym.logs.spec import read_log_spec
    from tests.test_log_reader import write_log

    res = short_run
    events, fmt, expect = data.draw(arm_logs(res))
    # a quarter of the logs truncated anywhere (the file, or a rosbag2 folder's storage file)
    cut = data.draw(st.one_of(st.none(), st.none(), st.none(), st.floats(0.0, 0.999)))
    tmp = tmp_path_factory.mktemp("arm")
    log = write_log(tmp / ("log.bag" if fmt == "bag" else "log"), events, fmt)
    if cut is not None:  # the file, or the storage file of a rosbag2 folder
        files = [log] if log.is_file() else [p for p in log.iterdir() if p.suffix != ".yaml"]
        raw = files[0].read_bytes()
        files[0].write_bytes(raw[: int(cut * len(raw))])
    spec = tmp / "spec.toml"
    spec.write_text('[effort]\nkind = "applied"\n')
    out = tmp / "out"
    args = ["estimate", str(log), "--robot", "paper_2link", "--log-spec", str(spec)]
    code = main([*args, "--out", str(out), "--no-plots"])
    event(f"exit {code}")  # --hypothesis-show-statistics: how many ran, how many refused
    if code != 0:
        assert code == 2
        assert not out.exists()
        return
    # exit 0: a complete run, and the encoder samples on the ticks they were written for
    summary = json.loads((out / "summary.json").read_text())
    enc = summary["topics"]["encoders"]
    assert enc["used"] + sum(enc["skipped"].values()) == enc["messages"]
    lib = res.lib
    got = read_log(log, read_log_spec(str(spec)), lib.manifest.joints, lib.T, lib.N)
    kept = expect["kept"]
    first = min(kept)
    assert got.K == max(kept) - first + 1 == summary["ticks"]
    for k, z in kept.items():
        assert np.array_equal(got.z[k - first], z), (k, expect["fault"])
    import pandas as pd

    est = pd.read_parquet(out / "estimates.parquet")
    assert len(est) == got.K and np.isfinite(est.to_numpy()).all()
