"""``amsfe bench --ros`` (apps/bench/ros.py): the report's shape, from a real run over DDS
with a CPU hog beside it.  No number is asserted: they are the machine's (docs/live-load.md)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parent.parent / "src"


@pytest.mark.ros
@pytest.mark.slow
def test_bench_ros_reports_both_latencies_and_the_misses(monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (pip install -e '.[ros]')")
    from amsfe_sym.apps.bench.ros import bench_ros, format_ros_report, ros_report_json

    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")]))
    lines: list[str] = []
    rows = bench_ros("paper-sim", 0.3, loads=(1,), impls=("python",), say=lines.append)
    assert len(rows) == len(lines) == 1
    row = rows[0]
    assert (row.impl, row.load, row.ticks) == ("python", 1, 301)
    assert row.codes[0] == 0 and row.codes[1] in (0, 3)  # done, or held (its line says why)
    assert row.stopped.startswith(("done", "hold: "))
    assert row.e2e_p50 is not None and row.e2e_max is not None and row.e2e_p99 is not None
    assert 0 <= row.e2e_p50 <= row.e2e_p99 <= row.e2e_max
    assert 0 <= row.missed <= row.ticks and 0 <= row.late_ticks <= row.ticks
    assert row.commands >= 1 and row.node_p50 is not None and row.node_max is not None
    assert 0 <= row.node_p50 <= row.node_max and math.isfinite(row.node_max)
    assert row.arm == "c"  # sim-node --impl auto: the C arm (it builds here)
    assert row.cpu_busy is not None and 0 < row.cpu_busy <= (os.cpu_count() or 1) + 1e-9
    table = format_ros_report(rows, "test machine").splitlines()
    assert len(table) == 4 and table[3].startswith("| python | 1 | ")
    doc = ros_report_json(rows, "test machine")
    assert doc["runs"][0]["stopped"] == row.stopped


@pytest.mark.ros
@pytest.mark.slow
def test_bench_ros_repeats_a_row_and_splits_the_c_node_p99_by_tick(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``--ros-repeat 2`` on the C node: two runs of the row, their p99's median and worst,
    how they stopped, and the C node's p99 per kind of tick (its stop line), every kind's
    count adding up to the commands it timed."""
    pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (pip install -e '.[ros]')")
    from amsfe_sym.apps.bench.ros import bench_ros, format_ros_report, ros_report_json, summarize

    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")]))
    rows = bench_ros("paper-sim", 0.3, loads=(0,), impls=("c",), say=lambda _: None, repeat=2)
    assert [(r.impl, r.load) for r in rows] == [("c", 0), ("c", 0)]
    for r in rows:
        assert r.node_p99 is not None and r.p99_by_kind, r
        assert "first 10" in r.p99_by_kind and "others" in r.p99_by_kind
        assert max(r.p99_by_kind.values()) <= (r.node_max or 0.0) + 1e-9
    (g,) = summarize(rows)
    assert g.runs == 2 and sum(g.stops.values()) == 2
    p99 = sorted(r.node_p99 for r in rows if r.node_p99 is not None)
    assert g.node_p99_worst == p99[-1] and g.node_p99_median == sum(p99) / 2
    assert set(g.p99_by_kind_median) == {k for r in rows for k in r.p99_by_kind}
    table = format_ros_report(rows, "test machine")
    assert "over the runs of each row: p99 median / worst [ms]" in table
    assert table.splitlines()[-1].startswith("| c | 0 | 2 | ")
    assert ros_report_json(rows)["summary"][0]["runs"] == 2
