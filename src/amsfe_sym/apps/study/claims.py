"""The claim table (docs/explanation/reproduction.md): the controller x estimator rows the paper's
claims
rest on, over any seed range, on the compiled loop, with their spread and paired tests.

``amsfe study paper-sim --claims --first-seed 1000 --seeds 200`` prints it and writes
``claims.json`` / ``claims.md``.  Per row: divergences, and per joint the median, 90th and
99th percentiles and worst seed of the tracking RMSE over the last 80 % of each run, with
bootstrap 95 % intervals of the median and the 90th percentile.  A diverged run counts as
the worst value (+inf), never dropped.  Pairs (same seeds): camera vs encoders alone under
``amsfe``, ``amsfe`` vs ``dtsmc-ekf`` with the camera, the estimate vs the true state: the
effect size (median over seeds of the paired difference a - b with its bootstrap 95 %
interval, a diverged run +inf; :mod:`amsfe_sym.apps.study.effects`), its verdict on these
seeds, how many seeds a is better on, and (JSON only) the Wilcoxon signed-rank p-value.

``--second-block FIRST`` runs the same table on a second, disjoint block of seeds and adds
the claims as effect sizes on both blocks, stated only where the two agree
(``second_block`` and ``effects`` in ``claims.json``; the last table of ``claims.md``).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from amsfe_sym.core.folders import write_folder
from amsfe_sym.core.jsonfile import write_json

__all__ = [
    "CLAIM_PAIRS",
    "CLAIM_ROWS",
    "ClaimTable",
    "format_claims",
    "is_claims_folder",
    "run_claims",
    "table_from_doc",
    "tabulate",
    "write_claims",
]

#: The rows: (controller, estimator).
CLAIM_ROWS: tuple[tuple[str, str], ...] = (
    ("amsfe", "oosm"),
    ("amsfe", "encoders"),
    ("dtsmc-ekf", "oosm"),
    ("dtsmc-ekf", "encoders"),
    ("truth", "oosm"),
)
#: The paired comparisons: (label, row a, row b); "a better" = a has the lower RMSE.
CLAIM_PAIRS: tuple[tuple[str, tuple[str, str], tuple[str, str]], ...] = (
    ("camera fused vs encoders alone (amsfe)", ("amsfe", "oosm"), ("amsfe", "encoders")),
    ("amsfe vs dtsmc-ekf (camera fused)", ("amsfe", "oosm"), ("dtsmc-ekf", "oosm")),
    ("amsfe vs dtsmc-ekf (encoders alone)", ("amsfe", "encoders"), ("dtsmc-ekf", "encoders")),
    ("the true state vs the estimate (amsfe law)", ("truth", "oosm"), ("amsfe", "oosm")),
)


@dataclass
class ClaimTable:
    """The claim table of one scenario and seed range."""

    scenario: str
    seeds: list[int]
    duration: float | None
    rows: dict[str, dict[str, Any]] = field(default_factory=dict)
    pairs: list[dict[str, Any]] = field(default_factory=list)
    rmse: dict[str, list[list[float]]] = field(default_factory=dict)
    second: ClaimTable | None = None


def _key(row: tuple[str, str]) -> str:
    return f"{row[0]}/{row[1]}"


def _one(job: tuple[str, int, str, str, float | None, tuple[str, ...]]) -> list[float]:
    from amsfe_sym.codegen import library_for
    from amsfe_sym.scenario import apply_sets, load_scenario
    from amsfe_sym.sim.loop import run
    from amsfe_sym.sim.record import summarize

    scenario, seed, controller, estimator, duration, sets = job
    sc = load_scenario(scenario).with_overrides(
        controller=controller, estimator=estimator, seed=seed, duration=duration
    )
    if sets:
        sc = apply_sets(sc, list(sets))
    res = run(sc, library_for(sc), runtime="compiled")
    if res.diverged_at is not None:
        return [float("inf")] * res.lib.n
    return [float(v) for v in summarize(res)["tracking_rmse"]["q"]]


def _spread(v: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
    boot = rng.choice(v, size=(2000, v.size), replace=True)
    pct = lambda a, q, **kw: np.percentile(a, q, method="lower", **kw)  # noqa: E731
    med, p90 = pct(boot, 50, axis=1), pct(boot, 90, axis=1)
    return {
        "median": float(pct(v, 50)),
        "median_ci95": [float(np.percentile(med, 2.5)), float(np.percentile(med, 97.5))],
        "p90": float(pct(v, 90)),
        "p90_ci95": [float(np.percentile(p90, 2.5)), float(np.percentile(p90, 97.5))],
        "p99": float(pct(v, 99)),
        "worst": float(v.max()),
    }


def run_claims(
    scenario: str,
    first_seed: int,
    seeds: int,
    duration: float | None = None,
    workers: int = 2,
    sets: Sequence[str] = (),
    rows: Sequence[tuple[str, str]] = CLAIM_ROWS,
) -> ClaimTable:
    """Run ``rows`` (default every row of :data:`CLAIM_ROWS`) on seeds ``first_seed ..``
    (compiled loop); the pairs of :data:`CLAIM_PAIRS` whose rows both ran are compared."""
    seed_list = list(range(first_seed, first_seed + seeds))
    jobs = [(scenario, s, c, e, duration, tuple(sets)) for (c, e) in rows for s in seed_list]
    if workers > 1:
        with ProcessPoolExecutor(workers) as ex:
            out = list(ex.map(_one, jobs, chunksize=4))
    else:
        out = [_one(j) for j in jobs]
    rmse = {_key(row): out[i * seeds : (i + 1) * seeds] for i, row in enumerate(rows)}
    return tabulate(scenario, seed_list, duration, rmse)


def tabulate(
    scenario: str, seeds: list[int], duration: float | None, rmse: dict[str, list[list[float]]]
) -> ClaimTable:
    """The claim table of per-seed tracking RMSE [rad] (``rmse[row][seed][joint]``, inf =
    diverged): each row's spread, each pair's paired effect
    (:func:`amsfe_sym.apps.study.effects.paired_effect`) and Wilcoxon p-value."""
    from scipy.stats import wilcoxon

    from amsfe_sym.apps.study.effects import paired_effect

    table = ClaimTable(scenario, list(seeds), duration)
    rng = np.random.default_rng(0)
    for key, values in rmse.items():
        r = np.array(values, dtype=float)
        table.rmse[key] = r.tolist()
        table.rows[key] = {
            "diverged": int(np.isinf(r[:, 0]).sum()),
            "joints": [_spread(r[:, j], rng) for j in range(r.shape[1])],
        }
    prng = np.random.default_rng(0)
    for label, a, b in CLAIM_PAIRS:
        if _key(a) not in table.rmse or _key(b) not in table.rmse:
            continue
        ra, rb = np.array(table.rmse[_key(a)]), np.array(table.rmse[_key(b)])
        joints = []
        for j in range(ra.shape[1]):
            x, y = ra[:, j], rb[:, j]
            fin = np.isfinite(x) & np.isfinite(y)
            p = float(wilcoxon(x[fin], y[fin]).pvalue) if fin.sum() >= 10 else None
            effect = paired_effect(x, y, prng)
            effect.update(
                p90_a=float(np.percentile(x, 90, method="lower")),
                p90_b=float(np.percentile(y, 90, method="lower")),
                wilcoxon_p=p,
            )
            joints.append(effect)
        table.pairs.append({"label": label, "a": _key(a), "b": _key(b), "joints": joints})
    return table


def table_from_doc(doc: dict[str, Any]) -> ClaimTable:
    """A claim table again from a stored ``claims.json`` (its per-seed RMSE), with today's
    statistics."""
    first, last = doc["seeds"]
    t = tabulate(doc["scenario"], list(range(first, last + 1)), doc["duration"], doc["rmse"])
    if "second_block" in doc:
        t.second = table_from_doc(doc["second_block"])
    return t


def _mrad(v: float) -> str:
    return "inf" if not np.isfinite(v) else f"{1e3 * v:.2f}"


def _diff(v: float) -> str:
    return ("+inf" if v > 0 else "-inf") if not np.isfinite(v) else f"{1e3 * v:+.3f}"


def format_claims(t: ClaimTable) -> str:
    """The table as Markdown (RMSE in mrad)."""
    n = len(next(iter(t.rows.values()))["joints"])
    head = (
        f"Claim table: {t.scenario}, seeds {t.seeds[0]}-{t.seeds[-1]} ({len(t.seeds)}), "
        "compiled loop; tracking RMSE [mrad] over the last 80 % of each run, a diverged run "
        "counted as inf.\n\n"
        "| controller / estimator | diverged | "
        + " | ".join(f"j{j + 1} median [95% CI] | j{j + 1} p90 / p99 / worst" for j in range(n))
        + " |\n|---|---|"
        + "---|---|" * n
        + "\n"
    )
    lines = []
    for key, row in t.rows.items():
        cells = []
        for s in row["joints"]:
            lo, hi = s["median_ci95"]
            cells.append(f"{_mrad(s['median'])} [{_mrad(lo)}, {_mrad(hi)}]")
            cells.append(f"{_mrad(s['p90'])} / {_mrad(s['p99'])} / {_mrad(s['worst'])}")
        lines.append(f"| {key} | {row['diverged']} / {len(t.seeds)} | " + " | ".join(cells) + " |")
    pairs = [
        "",
        "| paired comparison (a vs b) | joint | a better on | diverged a / b "
        "| median a - b [mrad] [95% CI] | on these seeds | p90 a / b |",
        "|---|---|---|---|---|---|---|",
    ]
    for p in t.pairs:
        for j, s in enumerate(p["joints"]):
            lo, hi = s["difference_ci95"]
            pairs.append(
                f"| {p['label']} | {j + 1} | {s['a_better_seeds']} / {len(t.seeds)} | "
                f"{s['diverged_a']} / {s['diverged_b']} | {_diff(s['median_difference'])} "
                f"[{_diff(lo)}, {_diff(hi)}] | {s['verdict']} | {_mrad(s['p90_a'])} / "
                f"{_mrad(s['p90_b'])} |"
            )
    text = head + "\n".join(lines) + "\n" + "\n".join(pairs) + "\n"
    if t.second is not None:
        from amsfe_sym.apps.study.effects import format_effects

        text += "\n" + format_effects(_doc(t), _doc(t.second))
    return text


def is_claims_folder(path: Path) -> bool:
    """Whether ``path`` is a claims folder amsfe wrote: it holds the marker, or (written
    before the marker existed) a ``claims.json`` with the claim table's keys."""
    from amsfe_sym.core.folders import is_run_folder

    if is_run_folder(path):
        return True
    try:
        doc = json.loads((path / "claims.json").read_text())
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and {"rows", "pairs"} <= set(doc)


def _doc(t: ClaimTable) -> dict[str, Any]:
    return {
        "scenario": t.scenario,
        "seeds": [t.seeds[0], t.seeds[-1]],
        "duration": t.duration,
        "rows": t.rows,
        "pairs": t.pairs,
        "rmse": t.rmse,
    }


def write_claims(t: ClaimTable, out: Path, force: bool = False) -> None:
    """``claims.json`` and ``claims.md`` as the folder ``out``, complete or absent (an
    existing ``out`` is replaced only with ``force``; the caller checks it with
    :func:`amsfe_sym.core.outputs.check_output` before the runs)."""
    doc = _doc(t)
    if t.second is not None:
        from amsfe_sym.apps.study.effects import combine

        doc["second_block"] = _doc(t.second)
        doc["effects"] = combine(doc, doc["second_block"])

    def fill(tmp: Path) -> None:
        write_json(tmp / "claims.json", doc, indent=1)
        (tmp / "claims.md").write_text(format_claims(t))

    write_folder(out, fill, replace=force, own=is_claims_folder)
