"""``amsfe sweep``: the sweep file, the Dask engine (local cluster and a real scheduler with a
worker on localhost) against runs one by one in this process, error rows, resume, report."""

from __future__ import annotations

import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from amsfe_sym.apps.cli import main
from amsfe_sym.apps.sweep import (
    SweepOptions,
    expand_jobs,
    flatten,
    load_sweep,
    make_batches,
    parse_sweep,
    run_job,
    run_sweep,
)
from amsfe_sym.apps.sweep.report import aggregate, format_report
from amsfe_sym.apps.sweep.robot_axes import derive_spec
from amsfe_sym.apps.sweep.table import PARTS, RESULTS
from amsfe_sym.errors import ConfigError
from amsfe_sym.load.spec import load_spec

#: Columns that are timings (differ between two runs of the same thing).
TIMING = ["wall_time_s", "cost_per_tick_us"]

SMALL = """
[sweep]
scenario = "paper-sim"
duration = {duration}
estimators = ["oosm", "replay"]
controllers = ["amsfe"]
seeds = {seeds}
set = ["filter.buffer_steps=300"]

[axes]
"camera.delay" = {delays}
"""


def _spec_file(
    tmp_path: Path, duration: float = 0.2, seeds: str = "[0]", delays: str = "[0, 125]"
) -> Path:
    p = tmp_path / "small.toml"
    p.write_text(SMALL.format(duration=duration, seeds=seeds, delays=delays))
    return p


def _one_by_one(spec_path: Path) -> pd.DataFrame:
    """The reference: every job of the sweep run by run_job in this process, in grid order."""
    rows = [run_job(j) for j in expand_jobs(load_sweep(spec_path))]
    return pd.DataFrame(rows)


def _same_rows(a: pd.DataFrame, b: pd.DataFrame) -> None:
    a = a.drop(columns=TIMING, errors="ignore").reset_index(drop=True)
    b = b.drop(columns=TIMING, errors="ignore").reset_index(drop=True)
    assert sorted(a.columns) == sorted(b.columns)
    pd.testing.assert_frame_equal(a[sorted(a.columns)], b[sorted(b.columns)], check_dtype=False)


# --------------------------------------------------------------------------- sweep file
def test_ranges_and_grid(tmp_path: Path) -> None:
    spec = parse_sweep(
        {
            "sweep": {
                "scenario": "paper-sim",
                "estimators": ["oosm", "cloning"],
                "seeds": {"first": 3, "count": 2},
            },
            "axes": {
                "camera.delay": {"start": 0, "stop": 500, "step": 125},
                "filter.link_torque_std": {"start": 0.1, "stop": 0.3, "num": 3},
            },
        }
    )
    assert spec.axes["camera.delay"] == (0, 125, 250, 375, 500)
    assert spec.axes["filter.link_torque_std"] == pytest.approx((0.1, 0.2, 0.3), abs=1e-15)
    assert spec.seeds == (3, 4)
    jobs = expand_jobs(spec)
    assert len(jobs) == spec.n_runs == 5 * 3 * 2 * 1 * 2
    assert len({j.run_id for j in jobs}) == len(jobs)
    j = jobs[-1]
    assert j.scenario.camera.delay == 500 and j.scenario.seed == 4
    assert j.scenario.filter.link_torque_std == pytest.approx(0.3)
    assert j.scenario.estimator == "cloning" and j.labels["estimator"] == "cloning"
    # a batch never mixes libraries (camera delay is part of the key), and keeps grid order
    batches = make_batches(jobs, 4)
    assert sum(len(b) for b in batches) == len(jobs)
    for b in batches:
        assert len({x.scenario.camera.delay for x in b}) == 1
        assert [x.index for x in b] == sorted(x.index for x in b)


@pytest.mark.parametrize(
    ("axes", "words"),
    [
        ({"camera.dealy": [0, 1]}, "camera.dealy"),
        ({"camera.delay": [0, "robot", 3]}, "one kind"),
        ({"camera.delay": {"start": 0, "stop": 10}}, "start, stop, step"),
        ({"camera.delay": {"start": 0, "stop": 10, "step": -1}}, "step"),
        ({"seed": [1, 2]}, "seeds"),
        ({"robot.theta.mass.true": [0.1]}, "robot.theta.payload.true"),
        ({"camera.delay": [1, 1]}, "distinct"),
    ],
)
def test_bad_sweep_files_are_one_line_errors(axes: dict, words: str) -> None:
    with pytest.raises(ConfigError, match=None) as exc:
        parse_sweep({"sweep": {"scenario": "paper-sim"}, "axes": axes})
    msg = str(exc.value)
    assert words in msg and "\n" not in msg


def test_bad_names_and_keys() -> None:
    with pytest.raises(ConfigError, match="estimators"):
        parse_sweep({"sweep": {"estimators": ["oosm", "kalman"]}})
    with pytest.raises(ConfigError, match="unknown"):
        parse_sweep({"sweep": {"scenaro": "paper-sim"}})
    with pytest.raises(ConfigError, match="report"):
        parse_sweep({"axes": {"camera.delay": [0]}, "report": {"x": "camera.period"}})


def test_flatten_joins_keys_and_summarises_lists() -> None:
    summary = {
        "scenario": "x",
        "ticks": 11,
        "estimation_rmse": {"q": [3.0, 4.0], "theta": [0.5]},
        "control": {"tracking_max_error": [0.2, 0.7], "saturated_fraction": 0.25},
        "theta_final": {"true": [0.15], "estimate": [0.1]},
        "diverged_at_s": None,
        "counters": {"frames_applied": 7},
    }
    row = flatten(summary)
    assert row["estimation_rmse.q.1"] == 3.0 and row["estimation_rmse.q.2"] == 4.0
    assert row["estimation_rmse.q.rms"] == pytest.approx(math.sqrt((9 + 16) / 2), rel=1e-15)
    assert row["control.tracking_max_error.max"] == 0.7
    assert row["control.saturated_fraction"] == 0.25
    assert row["theta_final.estimate.1"] == 0.1 and "theta_final.true.1" not in row
    assert math.isnan(row["diverged_at_s"])
    assert row["counters.frames_applied"] == 7 and "scenario" not in row


def test_robot_axes_derive_the_plant_model_error() -> None:
    spec = load_spec("paper_2link")
    d = derive_spec(spec, {"robot.theta.payload.true": 0.4})
    assert d.theta[0].true == 0.4 and d.theta[0].initial == spec.theta[0].initial
    assert d.name != spec.name and d.fingerprint() != spec.fingerprint()
    s = derive_spec(spec, {"robot.stiffness_error": 0.25})
    ks = [t for t in s.theta if t.kind == "joint_stiffness"]
    assert [t.target for t in ks] == list(spec.model.joints or ())
    assert [t.initial for t in ks] == list(spec.actuators.Ks or ())
    np.testing.assert_allclose([t.true for t in ks], np.array(spec.actuators.Ks) * 1.25)
    with pytest.raises(ConfigError, match="relative error"):
        derive_spec(spec, {"robot.stiffness_error": -1.0})


# --------------------------------------------------------------------------- runs
def test_a_failing_run_is_an_error_row(tmp_path: Path) -> None:
    # delay 400 steps needs a history of 400 > buffer_steps = 300: refused when the run
    # starts (camera_timing), which must give an error row while the other runs finish
    spec = load_sweep(_spec_file(tmp_path, delays="[0, 400]"))
    res = run_sweep(spec, SweepOptions(out=tmp_path / "out", workers=0, progress=False))
    t = res.table
    assert len(t) == 4 and res.errors == 2
    bad = t[t["camera.delay"] == 400]
    assert set(bad.status) == {"error"}
    assert all("buffer_steps" in e and e.startswith("ConfigError") for e in bad.error)
    assert bad["estimation_rmse.q.rms"].isna().all()
    good = t[t["camera.delay"] == 0]
    assert set(good.status) == {"ok"} and (good.error == "").all()
    assert np.isfinite(good["estimation_rmse.q.rms"]).all()
    # re-running skips them all; --retry-errors runs the two error rows only
    again = run_sweep(spec, SweepOptions(out=tmp_path / "out", workers=0, progress=False))
    assert (again.ran, again.skipped) == (0, 4)
    retry = run_sweep(
        spec, SweepOptions(out=tmp_path / "out", workers=0, progress=False, retry_errors=True)
    )
    assert (retry.ran, retry.skipped) == (2, 2) and retry.errors == 2


@pytest.mark.slow
def test_local_cluster_gives_the_in_process_table(tmp_path: Path) -> None:
    path = _spec_file(tmp_path)
    res = run_sweep(
        load_sweep(path),
        SweepOptions(out=tmp_path / "out", workers=2, batch=1, progress=False),
    )
    assert res.workers == 2 and res.ran == 4 and res.errors == 0
    assert list(res.table.status) == ["ok"] * 4
    _same_rows(res.table, _one_by_one(path))
    # the table on disk is the one returned
    _same_rows(pd.read_parquet(tmp_path / "out" / RESULTS), res.table)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)


@pytest.fixture
def dask_cluster(tmp_path: Path):  # type: ignore[no-untyped-def]
    """A real ``dask scheduler`` and ``dask worker`` (2 processes) on localhost."""
    dask = Path(sys.executable).parent / "dask"
    if not dask.is_file():
        pytest.skip("the dask command is not installed beside this Python")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    log = tmp_path / "dask.log"
    procs: list[subprocess.Popen] = []
    with log.open("w") as f:
        try:
            procs.append(
                subprocess.Popen(
                    [
                        str(dask),
                        "scheduler",
                        "--host",
                        "127.0.0.1",
                        "--port",
                        str(port),
                        "--no-dashboard",
                    ],
                    stdout=f,
                    stderr=subprocess.STDOUT,
                )
            )
            procs.append(
                subprocess.Popen(
                    [
                        str(dask),
                        "worker",
                        address,
                        "--nworkers",
                        "1",
                        "--nthreads",
                        "1",
                        "--no-dashboard",
                        "--local-directory",
                        str(tmp_path / "dask-worker"),
                    ],
                    stdout=f,
                    stderr=subprocess.STDOUT,
                )
            )
            yield address
        finally:
            for p in reversed(procs):
                _stop(p)


@pytest.mark.slow
def test_a_real_scheduler_and_worker_run_the_sweep(tmp_path: Path, dask_cluster: str) -> None:
    path = _spec_file(tmp_path)
    res = run_sweep(
        load_sweep(path),
        SweepOptions(out=tmp_path / "out", scheduler=dask_cluster, batch=2, progress=False),
    )
    assert res.workers == 1 and res.ran == 4 and res.errors == 0
    _same_rows(res.table, _one_by_one(path))
    meta = (tmp_path / "out" / "sweep.json").read_text()
    assert f"dask scheduler {dask_cluster}" in meta


@pytest.mark.slow
def test_an_interrupted_sweep_resumes_without_repeating_done_rows(tmp_path: Path) -> None:
    path = _spec_file(tmp_path, duration=0.5, seeds="[0, 1, 2]")  # 12 runs
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "amsfe_sym.apps.cli",
        "sweep",
        str(path),
        "--out",
        str(out),
        "--workers",
        "0",
        "--batch",
        "1",
        "--no-progress",
        "--no-plots",
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:  # stop it (SIGKILL: no clean-up at all) as soon as two runs are on disk
        deadline = time.monotonic() + 120
        while len(list((out / PARTS).glob("part-*.parquet"))) < 2:
            assert proc.poll() is None, "the sweep ended before it could be interrupted"
            assert time.monotonic() < deadline
            time.sleep(0.02)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        _stop(proc)
    parts = list((out / PARTS).glob("part-*.parquet"))
    first = pd.concat([pd.read_parquet(p) for p in parts], ignore_index=True)
    assert 2 <= len(first) < 12 and not (out / RESULTS).exists()
    res = run_sweep(load_sweep(path), SweepOptions(out=out, workers=0, progress=False))
    assert res.skipped == len(first) and res.ran == 12 - len(first)
    t = res.table
    assert len(t) == 12 and t.run_id.is_unique and set(t.status) == {"ok"}
    # the rows done before the kill were kept as they were (their own wall times), not re-run
    kept = t.set_index("run_id").loc[first.run_id, "wall_time_s"].to_numpy()
    np.testing.assert_array_equal(kept, first.wall_time_s.to_numpy())
    assert not (out / PARTS).exists()
    # and every row equals the same run made afresh
    _same_rows(t, _one_by_one(path))


# --------------------------------------------------------------------------- CLI, report
def test_cli_sweep_report_and_bad_input(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path = _spec_file(tmp_path, seeds="[0, 1]")
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--out", str(out), "--workers", "0", "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "8 runs" in text and "0 errors" in text
    assert (out / "figures" / "tracking_rmse.q.rms-vs-camera.delay.png").is_file()
    table = pd.read_parquet(out / RESULTS)
    agg = aggregate(table, "estimation_rmse.q.rms", ["camera.delay"])
    one = table[(table["camera.delay"] == 125) & (table.estimator == "replay")]
    row = agg[(agg["camera.delay"] == 125) & (agg.estimator == "replay")].iloc[0]
    assert row["mean"] == pytest.approx(one["estimation_rmse.q.rms"].mean(), rel=1e-14)
    assert row["std"] == pytest.approx(one["estimation_rmse.q.rms"].std(ddof=1), rel=1e-12)
    assert row["runs"] == 2
    # --report reads the folder and runs nothing
    assert (
        main(
            [
                "sweep",
                str(path),
                "--out",
                str(out),
                "--report",
                "--metric",
                "nees_mean",
                "--no-plots",
            ]
        )
        == 0
    )
    report = capsys.readouterr().out
    assert report.strip().startswith("| camera.delay | estimator | nees_mean mean ± std")
    assert format_report(table, "nees_mean", ["camera.delay"]) in report
    # bad input: one line, exit 2, nothing written
    bad = tmp_path / "bad.toml"
    bad.write_text('[sweep]\nscenario = "paper-sim"\n[axes]\n"camera.dealy" = [1]\n')
    assert main(["sweep", str(bad), "--out", str(tmp_path / "bad-out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and err.count("\n") == 1
    assert not (tmp_path / "bad-out").exists()
    assert main(["sweep", str(path), "--out", str(tmp_path / "none"), "--report"]) == 2
    assert "no rows" in capsys.readouterr().err
    assert main(["sweep", str(path), "--out", str(out), "--report", "--metric", "nope"]) == 2
    assert "nope" in capsys.readouterr().err
    # a folder of another sweep (another duration) is refused, and --force starts afresh
    other = _spec_file(tmp_path, duration=0.3, seeds="[0, 1]")
    assert main(["sweep", str(other), "--out", str(out), "--workers", "0"]) == 2
    assert "another" in capsys.readouterr().err
    shutil.rmtree(out / "figures")


@pytest.mark.slow
def test_a_robot_axis_runs_on_its_own_library(tmp_path: Path) -> None:
    # builds one derived library (cached under generated/ for later runs): the plant carries
    # 0.4 kg, the model's nominal payload stays the spec's
    spec = parse_sweep(
        {
            "sweep": {
                "scenario": "paper-sim",
                "duration": 0.2,
                "estimators": ["oosm"],
                "controllers": ["dtsmc"],
            },
            "axes": {"robot.theta.payload.true": [0.4]},
        }
    )
    (job,) = expand_jobs(spec)
    row = run_job(job)
    assert row["status"] == "ok", row["error"]
    from amsfe_sym.apps.sweep.jobs import _library

    lib = _library(job.scenario, job.robot)
    base = load_spec("paper_2link")
    assert lib.theta_true.tolist() == [0.4]
    assert lib.theta_initial.tolist() == [base.theta[0].initial]
    assert lib.name.startswith("paper_2link_r") and lib.name.endswith("_rk4")


def test_a_damaged_table_or_part_is_named_and_repair_rebuilds(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """A truncated ``results.parquet`` or a part damaged by a kill: one line naming the file
    and the fix; ``--repair`` sets them aside, keeps the readable rows and re-runs the rest."""
    path = _spec_file(tmp_path)  # 4 runs
    out = tmp_path / "out"
    args = ["sweep", str(path), "--out", str(out), "--workers", "0", "--no-progress"]
    assert main([*args, "--no-plots"]) == 0
    capsys.readouterr()
    table = pd.read_parquet(out / RESULTS)
    (out / PARTS).mkdir()
    table.iloc[:2].to_parquet(out / PARTS / "part-1.parquet", index=False)  # readable
    (out / PARTS / "part-2.parquet").write_bytes(b"PAR1" + b"\0" * 50)  # killed mid-write
    data = (out / RESULTS).read_bytes()
    (out / RESULTS).write_bytes(data[: len(data) // 2])  # truncated
    for extra in ([], ["--report"]):
        assert main([*args, "--no-plots", *extra]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: sweep file") and err.count("\n") == 1, err
        assert RESULTS in err and "--repair" in err
    assert main([*args, "--no-plots", "--repair"]) == 0
    text = capsys.readouterr().out
    assert text.count("set aside") == 2 and "2 runs" in text and "2 already done" in text
    assert sorted(p.name.split(".parquet")[0] for p in (out / "damaged").iterdir()) == [
        "part-2",
        "results",
    ]
    again = pd.read_parquet(out / RESULTS)
    assert len(again) == 4 and set(again.status) == {"ok"} and not (out / PARTS).exists()
    _same_rows(again, table)
    # a sweep.json cut short: named (not "another base scenario"); --repair keeps the rows
    meta = out / "sweep.json"
    meta.write_text(meta.read_text()[:100])
    assert main([*args, "--no-plots"]) == 2
    err = capsys.readouterr().err
    assert "sweep.json" in err and "--repair" in err and err.count("\n") == 1, err
    assert main([*args, "--no-plots", "--repair"]) == 0
    assert "0 runs" in capsys.readouterr().out and meta.is_file()
