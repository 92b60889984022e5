"""Claims as effect sizes (amsfe_sym.apps.study.effects, the claim table's pairs).

Against references: the median paired difference against a sorted list's order statistic,
the bootstrap interval against a loop over resamples written out by hand, the stored claim
table (made by run_claims before effect sizes existed) against its re-tabulation from its
own per-seed RMSE; divergences counted, never dropped. No run, about a second.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from amsfe_sym.apps.study.claims import format_claims, table_from_doc
from amsfe_sym.apps.study.effects import N_BOOT, combine, paired_effect, verdict

ROOT = Path(__file__).resolve().parent.parent


def test_the_median_difference_and_its_interval_equal_a_hand_written_bootstrap() -> None:
    rng = np.random.default_rng(3)
    x, y = rng.normal(1.0, 0.1, 60), rng.normal(1.02, 0.1, 60)
    e = paired_effect(x, y, np.random.default_rng(0))
    d = x - y
    assert e["median_difference"] == sorted(d)[(d.size - 1) // 2]
    ref_rng = np.random.default_rng(0)
    idx = ref_rng.integers(0, d.size, size=(N_BOOT, d.size))
    meds = sorted(sorted(d[i])[(d.size - 1) // 2] for i in idx)
    assert e["difference_ci95"] == [
        meds[int(0.025 * (N_BOOT - 1))],
        meds[-1 - int(0.025 * (N_BOOT - 1))],
    ]
    assert e["a_better_seeds"] == int((x < y).sum())


def test_a_diverged_run_is_counted_never_dropped() -> None:
    x = np.array([1.0, 1.0, np.inf, np.inf, 1.0])
    y = np.array([2.0, 2.0, 2.0, np.inf, np.inf])
    e = paired_effect(x, y, np.random.default_rng(0))
    assert (e["diverged_a"], e["diverged_b"], e["seeds"]) == (2, 2, 5)
    # differences -1, -1, +inf, 0 (both diverged), -inf: the median is -1
    assert e["median_difference"] == -1.0
    assert e["a_better_seeds"] == 3


def test_verdicts_follow_the_interval() -> None:
    assert verdict([-0.2, -0.1]) == "a lower"
    assert verdict([0.1, 0.2]) == "a higher"
    assert verdict([-0.1, 0.1]) == "indistinguishable"


def test_a_claim_is_stated_only_where_both_blocks_agree() -> None:
    rng = np.random.default_rng(1)
    b = rng.normal(2e-3, 1e-4, (80, 1))
    first = {"scenario": "s", "seeds": [0, 79], "pairs": [{"label": "p", "a": "A", "b": "B"}]}
    one = dict(first, rmse={"A": (b - 5e-5).tolist(), "B": b.tolist()})
    two = dict(first, seeds=[100, 179], rmse={"A": (b + 5e-5).tolist(), "B": b.tolist()})
    assert combine(one, one)[0]["stated"] == "a lower"
    assert combine(one, two)[0]["stated"] == "not reproduced"


def test_the_stored_claim_table_is_its_own_per_seed_rmse_retabulated() -> None:
    doc = json.loads((ROOT / "docs/data/claims-paper-sim/claims.json").read_text())
    t = table_from_doc(doc)
    assert t.rows == doc["rows"]
    for p, q in zip(t.pairs, doc["pairs"], strict=True):
        for s, r in zip(p["joints"], q["joints"], strict=True):
            assert s["a_better_seeds"] == r["a_better_seeds"]
            lo, hi = s["difference_ci95"]
            assert lo <= s["median_difference"] <= hi
    assert "a lower" in format_claims(t)


def test_the_claims_command_with_a_second_block_writes_the_effects(tmp_path: Path) -> None:
    """``amsfe study --claims --second-block``: both blocks run, ``claims.json`` holds the
    second block and the effects, ``claims.md`` the effect table, and the stored output
    re-tabulates to itself (short runs: 2 s, 10 + 6 seeds)."""
    from amsfe_sym.apps.cli import main

    out = tmp_path / "c"
    argv = ["study", "paper-exp", "--claims", "--first-seed", "5000", "--seeds", "10"]
    argv += ["--second-block", "5100", "--second-seeds", "6", "--duration", "2"]
    assert main([*argv, "--workers", "1", "--out", str(out)]) == 0
    doc = json.loads((out / "claims.json").read_text())
    assert doc["second_block"]["seeds"] == [5100, 5105]
    assert len(doc["effects"]) == len(doc["pairs"])  # one joint on paper-exp
    for e in doc["effects"]:
        same = e["first"]["verdict"] == e["second"]["verdict"]
        assert e["stated"] == (e["first"]["verdict"] if same else "not reproduced")
    assert "Claims as effect sizes: paper-exp" in (out / "claims.md").read_text()
    again = table_from_doc(doc)
    assert again.second is not None and again.pairs == doc["pairs"]
