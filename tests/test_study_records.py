"""study.json's compact run records (amsfe_sym.apps.study.records): written once per variant,
read back equal to every run's full record, in either format."""

from __future__ import annotations

import json
import math

from amsfe_sym.apps.study.records import compact_runs, study_json_text, study_runs


def _run(variant: str, estimator: str, seed: int, rmse: float) -> dict:
    return {
        "scenario": "paper-sim",
        "model": {"library": "paper_2link", "integrator": variant},
        "T": 0.001,
        "controller_gains": {"h": 2.0, "startup": "converged"},
        "estimator": estimator,
        "controller": "amsfe",
        "seed": seed,
        "variant": variant,
        "estimation_rmse": {"q": [rmse, 2 * rmse]},
        "diverged_at_s": None,
    }


def _runs() -> list[dict]:
    runs = [
        _run(v, e, s, 1e-3 * (1 + s + i))
        for i, v in enumerate(("paper", "rk4"))
        for e in ("oosm", "replay")
        for s in (0, 1)
    ]
    runs[1]["diverged_at_s"] = 0.4  # differs within its variant: stays per run
    runs.append({"variant": "rk4", "estimator": "naive", "seed": 0, "error": "boom"})
    runs[0]["nees_mean"] = math.nan
    return runs


def test_compact_records_read_back_equal() -> None:
    runs = _runs()
    doc = {"command": "amsfe study", "aggregate": {"paper": {}, "rk4": {}}}
    text = study_json_text(doc, runs)
    back = json.loads(text)  # strict JSON: the NaN is null, listed in the run's non_finite
    assert back["command"] == "amsfe study" and set(back["run_common"]) == {"paper", "rk4"}
    full = study_runs(back)
    assert len(full) == len(runs)
    for got, want in zip(full, runs, strict=True):
        if "nees_mean" in want:
            assert got.pop("nees_mean") is None and got.pop("non_finite") == {"nees_mean": "nan"}
            want = {k: v for k, v in want.items() if k != "nees_mean"}
        assert got == want
    # one line a run, and the shared fields written once per variant
    assert text.count('"controller_gains"') == 2
    assert sum(ln.startswith('{"') for ln in text.splitlines()) == len(runs)


def test_shared_fields_only_and_identity_kept() -> None:
    common, lines = compact_runs(_runs())
    assert "diverged_at_s" not in common["paper"] and common["rk4"]["diverged_at_s"] is None
    assert "estimation_rmse" not in common["paper"]
    assert all({"variant", "estimator", "seed"} <= set(r) for r in lines)
    assert lines[-1] == {"variant": "rk4", "estimator": "naive", "seed": 0, "error": "boom"}


def test_the_earlier_format_reads_as_it_is() -> None:
    runs = _runs()[1:]
    assert study_runs({"runs": runs}) == runs
