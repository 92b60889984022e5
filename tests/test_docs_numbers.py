"""The documented numbers (docs/data/claims-registry.toml) against their stored outputs.

Every number registered for README.md and docs/*.md, formatted from the output its command
wrote under docs/data/, must stand in the text, and every registered table verbatim: a doc
edited by hand, or an output re-measured without pasting it, fails here. The re-run check
(``tools/check_docs.py`` on a fresh seed block) is exercised on a stored output moved
beyond its interval. No run, well under a second.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from amsfe_sym.apps.docs_numbers import check_text, compare, json_path, load_registry
from amsfe_sym.errors import ConfigError

ROOT = Path(__file__).resolve().parent.parent


def test_every_registered_number_stands_in_its_doc() -> None:
    reg = load_registry(ROOT)
    assert reg.numbers and reg.blocks
    assert {"README.md", "docs/explanation/reproduction.md"} <= {n.doc for n in reg.numbers}
    moved = check_text(reg)
    assert not moved, "\n".join(m.line() for m in moved)


def _mini(tmp_path: Path, doc_text: str) -> Path:
    (tmp_path / "docs" / "data").mkdir(parents=True)
    out = {"rows": {"a/b": {"joints": [{"median": 0.00139, "median_ci95": [0.00135, 0.00142]}]}}}
    (tmp_path / "docs" / "data" / "out.json").write_text(json.dumps(out))
    (tmp_path / "doc.md").write_text(doc_text)
    (tmp_path / "docs" / "data" / "claims-registry.toml").write_text(
        '[source.s]\nstored = "docs/data/out.json"\ncommand = "amsfe study --out {out}"\n'
        '[[number]]\ndoc = "doc.md"\nsource = "s"\ntext = "tracks to {} mrad"\n'
        'values = ["rows.a/b.joints.0.median"]\nintervals = ["rows.a/b.joints.0.median_ci95"]\n'
        'fmt = "{:.2f}"\nscale = 1000.0\n'
    )
    return tmp_path


def test_a_number_edited_by_hand_is_found(tmp_path: Path) -> None:
    good = load_registry(_mini(tmp_path / "good", "It tracks\nto 1.39 mrad."))
    assert check_text(good) == []
    bad = load_registry(_mini(tmp_path / "bad", "It tracks to 1.40 mrad."))
    (moved,) = check_text(bad)
    assert moved.stored == "tracks to 1.39 mrad"


def test_a_remeasured_interval_disjoint_from_the_stored_one_is_reported(tmp_path: Path) -> None:
    reg = load_registry(_mini(tmp_path, "tracks to 1.39 mrad"))
    stored = json.loads((tmp_path / "docs/data/out.json").read_text())
    inside = copy.deepcopy(stored)
    inside["rows"]["a/b"]["joints"][0].update(median=0.00145, median_ci95=[0.00142, 0.00148])
    assert compare(reg, "s", inside) == []
    outside = copy.deepcopy(stored)
    outside["rows"]["a/b"]["joints"][0].update(median=0.00146, median_ci95=[0.00143, 0.00149])
    (moved,) = compare(reg, "s", outside)
    assert moved.found == "1.46"


def test_the_claim_tables_rerun_check_uses_the_stored_intervals() -> None:
    reg = load_registry(ROOT)
    stored = json.loads((ROOT / reg.sources["claims-paper-sim"].stored).read_text())
    assert compare(reg, "claims-paper-sim", stored) == []
    moved = copy.deepcopy(stored)
    j = moved["rows"]["amsfe/oosm"]["joints"][1]
    width = j["median_ci95"][1] - j["median_ci95"][0]
    j["median_ci95"] = [j["median_ci95"][1] + 0.1 * width, j["median_ci95"][1] + width]
    found = compare(reg, "claims-paper-sim", moved)
    assert any("amsfe/oosm joint 2 median" in m.where for m in found)


def test_a_bad_registry_path_is_one_clear_error() -> None:
    with pytest.raises(ConfigError, match="Fix:"):
        json_path({"rows": {}}, "rows.amsfe/oosm.joints")


def test_an_effect_claim_lost_on_a_fresh_block_is_reported() -> None:
    """The estimators' effect tables: the stored first block re-checked as if fresh finds
    nothing; the same with a stated claim's interval moved across zero, or a divergence
    more, is reported (tools/check_docs.py runs the study and its one-block effects)."""
    reg = load_registry(ROOT)
    stored = json.loads((ROOT / reg.sources["estimators-paper-sim"].stored).read_text())
    fresh = {"pairs": copy.deepcopy(stored["pairs"])}
    assert compare(reg, "estimators-paper-sim", fresh) == []
    row = next(r for r in stored["variants"]["base"] if r["stated"] == "a lower")
    pair = next(p for p in fresh["pairs"]["base"] if p["label"] == row["label"])
    eff = pair["joints"][row["joint"] - 1]
    eff.update(difference_ci95=[-1e-6, 1e-6], verdict="indistinguishable", diverged_a=1)
    found = compare(reg, "estimators-paper-sim", fresh)
    wheres = [m.where for m in found]
    assert f"base: {row['label']} joint {row['joint']} stated claim" in wheres
    assert f"base: {row['label']} joint {row['joint']} diverged a / b" in wheres


def test_a_per_block_number_is_not_compared_on_another_block(tmp_path: Path) -> None:
    root = _mini(tmp_path, "tracks to 1.39 mrad")
    reg_file = root / "docs" / "data" / "claims-registry.toml"
    reg_file.write_text(reg_file.read_text() + "per_block = true\n")
    reg = load_registry(root)
    far = {"rows": {"a/b": {"joints": [{"median": 0.009, "median_ci95": [0.008, 0.01]}]}}}
    assert compare(reg, "s", far) == []
    assert check_text(reg) == []


def test_a_key_with_dots_is_matched_whole() -> None:
    doc = {"theta_mean_at": {"0.5": [0.149], "10": [0.15]}}
    assert json_path(doc, "theta_mean_at.0.5.0") == 0.149
    assert json_path(doc, "theta_mean_at.10.0") == 0.15
    with pytest.raises(ConfigError, match="no '0'"):
        json_path(doc, "theta_mean_at.0.7.0")


def test_a_restated_statistic_is_not_reported_but_its_verdict_still_is() -> None:
    """The UR5 table's joint-6 effect is stated by its sign only (its size moved between
    blocks): a fresh interval far from the stored one is not reported, a reversed verdict
    is."""
    reg = load_registry(ROOT)
    stored = json.loads((ROOT / reg.sources["claims-ur5-control"].stored).read_text())
    fresh = copy.deepcopy(stored)
    pair = next(p for p in fresh["pairs"] if p["label"] == "amsfe vs dtsmc-ekf (camera fused)")
    pair["joints"][5].update(difference_ci95=[-0.9e-3, -0.8e-3], verdict="a lower")
    assert compare(reg, "claims-ur5-control", fresh) == []
    pair["joints"][5].update(difference_ci95=[0.8e-3, 0.9e-3], verdict="a higher")
    (moved,) = compare(reg, "claims-ur5-control", fresh)
    assert moved.where == "amsfe vs dtsmc-ekf (camera fused) joint 6 stated claim"


def test_check_docs_skips_a_by_hand_source_and_survives_a_failing_command(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``tools/check_docs.py --all``: a source re-run by hand is named and skipped, a command
    that fails is one line (not a traceback) and the other sources still run; exit 1."""
    from tests.tool_modules import tool

    mod = tool("check_docs")
    (tmp_path / "docs" / "data").mkdir(parents=True)
    (tmp_path / "docs" / "data" / "out.json").write_text("{}")
    (tmp_path / "docs" / "data" / "claims-registry.toml").write_text(
        '[source.hand]\nstored = "docs/data/out.json"\ncommand = "python -c pass"\n'
        'by_hand = "run it with its twin"\n'
        '[source.broken]\nstored = "docs/data/out.json"\n'
        "command = \"python -c 'raise SystemExit(3)'\"\ncostly = true\n"
        '[source.fine]\nstored = "docs/data/out.json"\ncommand = "python -c pass"\n'
        'output = "-"\n'
    )
    monkeypatch.setattr(mod, "ROOT", tmp_path)
    assert mod.main(["--all"]) == 1
    out = capsys.readouterr().out
    assert "hand: not re-run here: run it with its twin" in out
    assert "broken: its command failed (exit 3)" in out
    assert "fine: 0 moved" in out and "1 source(s) whose command failed" in out
