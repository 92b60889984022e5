"""``amsfe estimate``'s account of its time (docs/how-to/logs.md, "Speed"): the phases in
``summary.json`` add up to the command's wall time and the real-time factors are the log's
duration over them; the process age behind "start-up"; the estimates table written without
pandas is pandas' table.  No speed is asserted here."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from amsfe_sym.apps.estimate import EstimateOptions, _arrow_table, estimate_command
from amsfe_sym.apps.estimate_report import print_summary, summary
from amsfe_sym.codegen import library_for
from amsfe_sym.logs.write import write_run_bag
from amsfe_sym.scenario import load_scenario
from amsfe_sym.sim.loop import run

PHASES = ("setup_s", "library_s", "read_s", "estimate_s", "write_s")


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 0.5 s paper-sim run (oosm, compiled loop) written as a rosbag2."""
    sc = load_scenario("paper-sim").with_overrides(controller="amsfe", duration=0.5, seed=4)
    res = run(sc, library_for(sc), runtime="compiled")
    return write_run_bag(res, tmp_path_factory.mktemp("timing") / "bag")


@pytest.mark.parametrize("startup", [None, 0.25])
def test_phases_add_up_to_the_wall_time(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], startup: float | None
) -> None:
    out = tmp_path / "est"
    got = estimate_command(bag, out, EstimateOptions(plots=False), startup_s=startup)
    s = json.loads((out / "summary.json").read_text())
    t = s["timing"]
    assert t["startup_s"] == startup
    assert all(t[k] >= 0 for k in PHASES)
    assert sum(t[k] for k in PHASES) == pytest.approx(t["wall_s"], abs=6e-4)  # 4-digit rounding
    assert (t["read_s"], t["estimate_s"]) == (s["read_s"], s["estimate_s"])
    d = s["duration_s"]
    # the times are stored to 4 decimals, the factors computed before rounding: on a fast
    # machine read + estimate is ~10 ms, so the rounding alone is ~1 % of it
    took = s["read_s"] + s["estimate_s"]
    assert s["real_time_factor"] == pytest.approx(d / took, rel=1e-2 + 2e-4 / took)
    assert t["real_time_factor_command"] == pytest.approx(
        d / t["wall_s"], rel=1e-2 + 2e-4 / t["wall_s"]
    )
    if startup is None:
        assert t["end_to_end_s"] is None and t["real_time_factor_end_to_end"] is None
    else:
        assert t["end_to_end_s"] == pytest.approx(startup + t["wall_s"], abs=1e-4)
        assert t["real_time_factor_end_to_end"] == pytest.approx(
            d / (startup + t["wall_s"]), rel=1e-2
        )
    assert summary(got)["timing"] == t  # what is printed is what was written
    table = pq.read_table(out / "estimates.parquet")
    est = got.estimate
    assert np.array_equal(table.column("t").to_numpy(), got.log.t)
    for i in range(est.x_hat.shape[1]):
        assert np.array_equal(table.column(f"est_{i}").to_numpy(), est.x_hat[:, i])
        assert np.array_equal(table.column(f"var_{i}").to_numpy(), est.P_diag[:, i])
    print_summary(s, out)
    line = next(ln for ln in capsys.readouterr().out.splitlines() if "speed:" in ln)
    assert f"read {s['read_s']:.3f} s + estimated {s['estimate_s']:.3f} s" in line
    assert f"library {t['library_s']:.2f}" in line and f"writing {t['write_s']:.2f}" in line
    assert ("start-up" in line) == (startup is not None)


def test_no_start_up_when_called_from_python(bag: Path, tmp_path: Path) -> None:
    """main() called in a process that is not the command (this test): no start-up, not
    the process's age; the command run as ``python -m amsfe_sym`` has one."""
    from amsfe_sym.apps.cli import main

    assert main(["estimate", str(bag), "--out", str(tmp_path / "a"), "--no-plots"]) == 0
    t = json.loads((tmp_path / "a" / "summary.json").read_text())["timing"]
    assert t["startup_s"] is None and t["real_time_factor_end_to_end"] is None
    cmd = [sys.executable, "-m", "amsfe_sym", "estimate", str(bag), "--out", str(tmp_path / "b")]
    t0 = time.perf_counter()
    subprocess.run([*cmd, "--no-plots"], check=True, capture_output=True)
    wall = time.perf_counter() - t0
    t = json.loads((tmp_path / "b" / "summary.json").read_text())["timing"]
    assert t["startup_s"] > 0 and t["startup_s"] + t["wall_s"] <= wall + 0.02


def test_process_age_is_the_time_since_the_process_started() -> None:
    """A child's own age, printed as it ends, lies within the parent's clock around it
    (the age has a 10 ms resolution); it grows with a sleep in the child."""
    code = (
        "import time; from amsfe_sym.apps.phases import process_age_s; "
        "a = process_age_s(); time.sleep(0.3); print(a, process_age_s())"
    )
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    wall = time.perf_counter() - t0
    first, last = map(float, out.stdout.split())
    assert 0 <= first <= last <= wall + 0.02
    assert last - first == pytest.approx(0.3, abs=0.05)


def test_the_estimates_table_is_pandas_table() -> None:
    """NaN is null, inf stays, columns and order as pandas' ``to_parquet`` wrote them."""
    import pandas as pd
    import pyarrow as pa

    rng = np.random.default_rng(0)
    x = rng.normal(size=(1001, 3))
    x[::7, 1] = np.nan
    x[3, 2] = np.inf
    cols = {"t": np.arange(1001) * 1e-3, **{f"est_{i}": x[:, i] for i in range(3)}}
    ours = _arrow_table(cols)
    theirs = pa.Table.from_pandas(pd.DataFrame(cols), preserve_index=False)
    assert ours.equals(theirs.replace_schema_metadata(None))
    assert ours.column("est_1").null_count == int(np.isnan(x[:, 1]).sum()) > 0
