"""``study.json``'s per-run records, written compactly and read back whole.

Every run's ``summary.json`` repeats the scenario-level fields of its variant (scenario,
robot, model, camera, T, ticks, window, controller_gains, ...): 800 runs of paper-sim wrote
2.4 MB, two thirds of it repeated or indentation. ``study.json`` therefore holds, under
``run_common``, per variant the fields every successful run of that variant shares, and in
``runs`` each run's other fields (always its variant, estimator, controller and seed), one
run a line. A failed run (``"error"``) is written whole. :func:`study_runs` gives every run's
full record again, from this format or from the earlier one (no ``run_common``).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import Any

from amsfe_sym.core.jsonfile import to_json

__all__ = ["IDENTITY", "compact_runs", "study_json_text", "study_runs"]

#: Fields kept in every run's line, shared or not.
IDENTITY = ("variant", "estimator", "controller", "seed")


def _variant(run: Mapping[str, Any]) -> str:
    return str(run.get("variant", "base"))


def compact_runs(
    runs: Sequence[Mapping[str, Any]],
) -> tuple[dict[str, dict[str, Any]], list[dict[str, Any]]]:
    """``(run_common, runs)``: per variant the fields all its successful runs share (equal
    JSON), and each run without them (failed runs whole)."""
    ok: dict[str, list[Mapping[str, Any]]] = {}
    for r in runs:
        if "error" not in r:
            ok.setdefault(_variant(r), []).append(r)
    common: dict[str, dict[str, Any]] = {}
    for v, rs in ok.items():
        text = [{k: json.dumps(x, sort_keys=True, default=str) for k, x in r.items()} for r in rs]
        common[v] = {
            k: rs[0][k]
            for k in rs[0]
            if k not in IDENTITY and all(t.get(k) == text[0][k] for t in text)
        }
    out = [
        dict(r) if "error" in r else {k: x for k, x in r.items() if k not in common[_variant(r)]}
        for r in runs
    ]
    return common, out


def study_runs(doc: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Every run's full record of a ``study.json`` document (either format)."""
    common = doc.get("run_common", {})
    return [
        dict(r) if "error" in r else {**common.get(_variant(r), {}), **r}
        for r in doc.get("runs", [])
    ]


def study_json_text(doc: Mapping[str, Any], runs: Sequence[Mapping[str, Any]]) -> str:
    """The text of ``study.json``: ``doc`` indented, then ``run_common`` and ``runs`` (one
    compact line each); strict JSON (amsfe_sym.core.jsonfile.to_json)."""
    common, lines = compact_runs(runs)
    head = to_json({**doc, "run_common": common}, indent=1, default=str)
    body = ",\n".join(to_json(r, indent=None, default=str).rstrip() for r in lines)
    return head[: -len("\n}\n")] + ',\n "runs": [\n' + body + "\n ]\n}\n"
