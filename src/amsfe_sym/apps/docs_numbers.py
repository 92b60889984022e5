"""The registry of documented numbers (docs/data/claims-registry.toml) and its two checks.

Every number in README.md and docs/*.md that a command produced is registered once: the
document, a piece of its text with ``{}`` where the numbers stand, the *source* (the command
and the stored output it wrote under docs/data/), the JSON path of each number in that
output, its display format and scale, and how far a re-measurement may move it (the stored
95 % interval at another JSON path, or an absolute tolerance in display units). A whole
generated table is registered as a *block*: the stored Markdown must stand in the document
verbatim (whitespace aside).

Two checks:

- :func:`check_text` (fast, no run; ``tests/test_docs_numbers.py``): every registered
  number, formatted from the stored output, stands in its document; every block too.
- :func:`compare` (``tools/check_docs.py``, which re-runs the sources' commands on any seed
  block): every number of a fresh output that left its interval.

Registry format (TOML)::

    [source.claims-paper-sim]
    stored = "docs/data/claims-paper-sim/claims.json"
    command = "amsfe study paper-sim --claims --first-seed {first_seed} --seeds {seeds} --out {out}"
    output = "claims.json"        # the file the command writes inside {out}
    first_seed = 1000
    seeds = 200
    costly = false                # costly sources re-run only when named (or with --all)
    fixed_seed = false            # true: one documented seed, re-run on it whatever the block
    post = ""                     # optional: a command run on {out} after it (its output is
                                  # then ``output``, e.g. "effects/effects.json")

    [[block]]
    doc = "docs/explanation/reproduction.md"
    source = "claims-paper-sim"
    stored = "docs/data/claims-paper-sim/claims.md"
    check = "claims"              # re-run: medians and p90s within their stored 95 % intervals
    restated = ["truth/oosm joint 6 median"]  # optional: stated per block only (say why)

    [[number]]
    doc = "README.md"
    source = "claims-paper-sim"
    text = "it tracks to {} / {} mrad (median"
    values = ["rows.amsfe/oosm.joints.0.median", "rows.amsfe/oosm.joints.1.median"]
    intervals = ["rows.amsfe/oosm.joints.0.median_ci95", "rows.amsfe/oosm.joints.1.median_ci95"]
    fmt = "{:.2f}"
    scale = 1000.0
    atol = 0.0
    per_block = false             # true: a value quoted for its named seed block only (one
                                  # trajectory, no interval): in the text, never re-compared

A JSON path is dot-separated: object keys, or list indices as integers.
"""

from __future__ import annotations

import gzip
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from amsfe_sym.core.toml import tomllib
from amsfe_sym.errors import ConfigError, describe

__all__ = [
    "Block",
    "Moved",
    "Number",
    "Registry",
    "Source",
    "check_text",
    "compare",
    "json_path",
    "load_registry",
]

REGISTRY = Path("docs/data/claims-registry.toml")


@dataclass(frozen=True)
class Source:
    """A command and the stored output it wrote (paths relative to the repository)."""

    name: str
    stored: str
    command: str
    output: str = ""
    first_seed: int = 0
    seeds: int = 0
    costly: bool = False
    fixed_seed: bool = False
    post: str = ""  # a command run on {out} after ``command`` (e.g. the effects of a study)
    by_hand: str = ""  # how to re-run it when its command cannot run alone (re-runs skip it)

    def command_for(self, first_seed: int, seeds: int, out: str) -> str:
        """The command on seeds ``first_seed ..`` (``seeds`` of them), writing to ``out``."""
        return self.command.format(first_seed=first_seed, seeds=seeds, out=out)


@dataclass(frozen=True)
class Number:
    """Numbers in a document's text and where they come from."""

    doc: str
    source: str
    text: str
    values: tuple[str, ...]
    fmt: tuple[str, ...]
    scale: tuple[float, ...]
    intervals: tuple[str, ...] = ()
    atol: float = 0.0
    per_block: bool = False  # quoted for its named seed block only: never re-run elsewhere


@dataclass(frozen=True)
class Block:
    """A generated Markdown table that stands verbatim in a document."""

    doc: str
    source: str
    stored: str
    check: str = ""
    skip: tuple[str, ...] = ()  # regexes of stored lines the doc leaves out (text outputs)
    # statistics of the table the doc states per block only (a re-run may move them; the
    # registry says why): findings whose place starts with one of these are not reported
    restated: tuple[str, ...] = ()


@dataclass
class Registry:
    """Every registered source, number and block."""

    root: Path
    sources: dict[str, Source] = field(default_factory=dict)
    numbers: list[Number] = field(default_factory=list)
    blocks: list[Block] = field(default_factory=list)


@dataclass(frozen=True)
class Moved:
    """One finding: a number not in its document, or a re-measured one out of its interval."""

    doc: str
    where: str
    stored: str
    found: str
    allowed: str

    def line(self) -> str:
        """One line for the console."""
        return (
            f"{self.doc}: {self.where}: stored {self.stored}, found {self.found} "
            f"(allowed {self.allowed})"
        )


def _bad(where: str, expected: str, found: str, fix: str) -> ConfigError:
    return ConfigError(describe(where, expected, found, fix))


def load_registry(root: Path, path: Path | None = None) -> Registry:
    """Read the registry (default ``root / docs/data/claims-registry.toml``)."""
    path = path or root / REGISTRY
    try:
        doc = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as e:
        raise _bad(str(path), "a readable TOML registry", str(e), "restore it from git") from e
    reg = Registry(root)
    for name, s in doc.get("source", {}).items():
        reg.sources[name] = Source(name=name, **s)
    for n in doc.get("number", []):
        values = tuple(n["values"])
        fmt = n.get("fmt", "{}")
        fmts = tuple(fmt) if isinstance(fmt, list) else (fmt,) * len(values)
        reg.numbers.append(
            Number(
                doc=n["doc"],
                source=n["source"],
                text=n["text"],
                values=values,
                fmt=fmts,
                scale=_scales(n.get("scale", 1.0), len(values)),
                intervals=tuple(n.get("intervals", ())),
                atol=float(n.get("atol", 0.0)),
                per_block=bool(n.get("per_block", False)),
            )
        )
    for b in doc.get("block", []):
        reg.blocks.append(
            Block(
                **{**b, "skip": tuple(b.get("skip", ())), "restated": tuple(b.get("restated", ()))}
            )
        )
    items: list[Number | Block] = [*reg.numbers, *reg.blocks]
    for item in items:
        if item.source not in reg.sources:
            raise _bad(
                f"{path}: entry in {item.doc}",
                f"a source among {sorted(reg.sources)}",
                repr(item.source),
                "add a [source.NAME] table or fix the name",
            )
    for n in reg.numbers:
        if (
            len(n.fmt) != len(n.values)
            or len(n.scale) != len(n.values)
            or n.text.count("{}") != len(n.values)
        ):
            raise _bad(
                f"{path}: number {n.text!r}",
                f"one '{{}}', fmt and scale per value ({len(n.values)})",
                f"{n.text.count('{}')} '{{}}', {len(n.fmt)} fmt, {len(n.scale)} scale",
                "make text, values, fmt and scale agree",
            )
        if n.intervals and len(n.intervals) != len(n.values):
            raise _bad(
                f"{path}: number {n.text!r}",
                "one interval path per value, or none",
                f"{len(n.intervals)} for {len(n.values)}",
                "list an interval for every value",
            )
    return reg


def _scales(scale: float | list[float], n: int) -> tuple[float, ...]:
    return tuple(float(x) for x in scale) if isinstance(scale, list) else (float(scale),) * n


def json_path(doc: Any, path: str) -> Any:
    """The value at a dot-separated ``path`` (keys, or integer list indices; a key that
    itself holds dots, such as ``theta_mean_at``'s ``"0.5"``, is matched whole)."""
    cur = doc
    parts = path.split(".")
    i = 0
    while i < len(parts):
        part = parts[i]
        if isinstance(cur, dict) and part not in cur:
            for j in range(i + 2, len(parts) + 1):
                if ".".join(parts[i:j]) in cur:
                    part, i = ".".join(parts[i:j]), j - 1
                    break
        try:
            cur = cur[int(part)] if isinstance(cur, list) else cur[part]
        except (KeyError, IndexError, ValueError, TypeError) as e:
            raise _bad(
                f"JSON path {path!r}",
                "a path into the stored output",
                f"no {part!r}",
                "fix the registry entry",
            ) from e
        i += 1
    return cur


def _flat(text: str) -> str:
    return re.sub(r"\s+", " ", text).strip()


def _tables(text: str, skip: tuple[str, ...] = ()) -> list[str]:
    """The tables of a stored Markdown output, each flattened (captions may be reworded in
    a doc); a plain-text output (no Markdown table) is one block of its lines but those
    matching a ``skip`` regex."""
    if not any(ln.lstrip().startswith("|") for ln in text.splitlines()):
        keep = [ln for ln in text.splitlines() if not any(re.match(r, ln) for r in skip)]
        return [_flat("\n".join(keep))]
    out: list[list[str]] = []
    prev = False
    for ln in text.splitlines():
        row = ln.lstrip().startswith("|")
        if row and not prev:
            out.append([])
        if row:
            out[-1].append(ln)
        prev = row
    return [_flat("\n".join(t)) for t in out]


def _show(fmt: str, v: Any, scale: float) -> str:
    if isinstance(v, bool) or v is None or isinstance(v, str):
        return str(v)
    x = float(v) * scale
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return fmt.format(round(x) if fmt.endswith("d}") else x)


def number_text(n: Number, output: Any) -> str:
    """The text of ``n`` with its values formatted from ``output``."""
    shown = [
        _show(f, json_path(output, p), k) for f, p, k in zip(n.fmt, n.values, n.scale, strict=True)
    ]
    parts = n.text.split("{}")
    return parts[0] + "".join(v + rest for v, rest in zip(shown, parts[1:], strict=True))


def _read_output(path: Path) -> Any:
    """A stored output: JSON, or the text of a command's standard output (``.txt``)."""
    if path.suffix == ".txt":
        try:
            return path.read_text()
        except OSError as e:
            raise _bad(str(path), "a stored text output", str(e), "re-run its command") from e
    return _read_json(path)


def _read_json(path: Path) -> Any:
    """A stored JSON output; ``.gz``: a large one stored whole, ``gzip -9 -n``'d."""
    try:
        with (gzip.open if path.suffix == ".gz" else open)(path, "rt", encoding="utf-8") as f:
            return json.load(f)
    except (OSError, ValueError) as e:
        raise _bad(str(path), "a stored JSON output", str(e), "re-run its command") from e


def check_text(reg: Registry, docs: set[str] | None = None) -> list[Moved]:
    """Every registered number and block, from its stored output, found in its document."""
    flat: dict[str, str] = {}
    out: list[Moved] = []
    stored = {s.name: _read_output(reg.root / s.stored) for s in reg.sources.values()}
    for n in reg.numbers:
        if docs is not None and n.doc not in docs:
            continue
        text = flat.setdefault(n.doc, _flat((reg.root / n.doc).read_text()))
        want = _flat(number_text(n, stored[n.source]))
        if want not in text:
            out.append(Moved(n.doc, n.text, want, "not in the text", "exactly"))
    for b in reg.blocks:
        if docs is not None and b.doc not in docs:
            continue
        text = flat.setdefault(b.doc, _flat((reg.root / b.doc).read_text()))
        for k, want in enumerate(_tables((reg.root / b.stored).read_text(), b.skip)):
            if want not in text:
                out.append(
                    Moved(b.doc, f"table {k + 1} of {b.stored}", "verbatim", "not in the text",
                          "exactly")
                )  # fmt: skip
    return out


def _value(v: Any, scale: float) -> float:
    return float("nan") if v is None else float(v) * scale


def _outside(x: float, lo: float, hi: float, atol: float) -> bool:
    if math.isinf(x) or math.isinf(lo) or math.isinf(hi):
        return not (lo - atol <= x <= hi + atol) and x not in (lo, hi)
    return not (lo - atol <= x <= hi + atol)


def _has(doc: Any, path: str) -> bool:
    try:
        json_path(doc, path)
    except ConfigError:
        return False
    return True


def _disjoint(a: Any, b: Any, atol: float) -> bool:
    """Whether two intervals (each block's 95 % interval) do not overlap, even widened by
    ``atol``: two blocks of seeds each carry their own sampling error, so a fresh value is
    judged by its own interval against the stored one, not as a point."""
    return bool(a[0] > b[1] + atol or b[0] > a[1] + atol)


def compare(reg: Registry, source: str, fresh: Any) -> list[Moved]:
    """The numbers of ``source`` in a fresh output that moved: where an interval is
    registered, the fresh block's 95 % interval and the stored one do not overlap (widened
    by ``atol``); elsewhere the value moved by more than ``atol`` [display units]."""
    old = _read_output(reg.root / reg.sources[source].stored)
    out: list[Moved] = []
    for n in reg.numbers:
        if n.source != source or n.per_block:
            continue
        for i, p in enumerate(n.values):
            if not _has(fresh, p):
                continue  # two-block effects on a one-block re-run: the table check has them
            k = n.scale[i]
            x, x0 = _value(json_path(fresh, p), k), _value(json_path(old, p), k)
            if n.intervals:
                lo, hi = sorted(_value(v, k) for v in json_path(old, n.intervals[i]))  # k < 0 flips
                flo, fhi = sorted(_value(v, k) for v in json_path(fresh, n.intervals[i]))
                moved = _disjoint((flo, fhi), (lo, hi), n.atol)
            else:
                lo = hi = x0
                moved = _outside(x, lo, hi, n.atol)
            if moved:
                out.append(
                    Moved(n.doc, f"{n.text!r} value {i + 1} ({p})", f"{x0:.4g}", f"{x:.4g}",
                          f"[{lo - n.atol:.4g}, {hi + n.atol:.4g}]")
                )  # fmt: skip
    for b in reg.blocks:
        if b.source == source and b.check:
            found = _CHECKS[b.check](b, old, fresh)
            out.extend(m for m in found if not m.where.startswith(b.restated or ("\0",)))
    return out


def _claims_block(b: Block, old: Any, new: Any) -> list[Moved]:
    """Claim tables: divergences equal; every median's and p90's 95 % interval, and every
    paired effect's, overlapping the stored one; every stated claim (an effect found on both
    stored blocks) found again, not "indistinguishable" nor reversed."""
    out: list[Moved] = []
    for key, row in old["rows"].items():
        fresh = new["rows"].get(key)
        if fresh is None:
            out.append(Moved(b.doc, f"{b.stored} row {key}", "present", "absent", "present"))
            continue
        if fresh["diverged"] != row["diverged"]:
            out.append(Moved(b.doc, f"{key} diverged", str(row["diverged"]),
                             str(fresh["diverged"]), "equal"))  # fmt: skip
        for j, (s, f) in enumerate(zip(row["joints"], fresh["joints"], strict=True)):
            for stat in ("median", "p90"):
                lo, hi = s[f"{stat}_ci95"]
                if _disjoint(f[f"{stat}_ci95"], (lo, hi), 0.0):
                    out.append(
                        Moved(b.doc, f"{key} joint {j + 1} {stat} [mrad]", f"{1e3 * s[stat]:.3f}",
                              f"{1e3 * f[stat]:.3f}", f"[{1e3 * lo:.3f}, {1e3 * hi:.3f}]")
                    )  # fmt: skip
    fresh_pairs = {p["label"]: p for p in new.get("pairs", [])}
    stated = {(e["label"], e["joint"]): e["stated"] for e in old.get("effects", [])}
    for p in old.get("pairs", []):
        q = fresh_pairs.get(p["label"])
        if q is None:
            continue
        for j, (s, f) in enumerate(zip(p["joints"], q["joints"], strict=True)):
            if "difference_ci95" not in s or "difference_ci95" not in f:
                continue
            where = f"{p['label']} joint {j + 1} a - b [mrad]"
            lo, hi = s["difference_ci95"]
            if _disjoint(f["difference_ci95"], (lo, hi), 0.0):
                out.append(Moved(b.doc, where, _ci(s["difference_ci95"]),
                                 _ci(f["difference_ci95"]), "overlapping intervals"))  # fmt: skip
            claim = stated.get((p["label"], j + 1))
            if claim in _OPPOSITE and f["verdict"] in (_OPPOSITE[claim], "indistinguishable"):
                out.append(Moved(b.doc, where.replace("a - b [mrad]", "stated claim"), claim,
                                 f["verdict"], claim))  # fmt: skip
    return out


def _effects_block(b: Block, old: Any, new: Any) -> list[Moved]:
    """Effect tables (tools/estimator_effects.py, tools/nees_run_length.py): every stated
    claim (the same verdict on both stored blocks) found again on the fresh block's
    ``pairs``, not "indistinguishable" nor reversed; divergences as stored."""
    if "variants" in old:  # per variant: {variant: [claim rows]}, fresh {variant: [pairs]}
        stored = [(v, r) for v, rs in old["variants"].items() for r in rs]
        fresh = {(v, p["label"]): p for v, ps in new.get("pairs", {}).items() for p in ps}
    else:  # one list of claim rows; fresh pairs a list or {"all": [...]}
        stored = [("", r) for r in old.get("claims", [])]
        ps = new.get("pairs", [])
        fresh = {("", p["label"]): p for p in (ps if isinstance(ps, list) else ps.get("all", []))}
    out: list[Moved] = []
    for v, r in stored:
        q = fresh.get((v, r["label"]))
        if q is None:
            continue
        f, s = q["joints"][r["joint"] - 1], r["first"]
        where = f"{v + ': ' if v else ''}{r['label']} joint {r['joint']}"
        was = f"{s['diverged_a']} / {s['diverged_b']}"
        now = f"{f['diverged_a']} / {f['diverged_b']}"
        if was != now:
            out.append(Moved(b.doc, f"{where} diverged a / b", was, now, "equal"))
        claim = r["stated"]
        if claim in _OPPOSITE and f["verdict"] in (_OPPOSITE[claim], "indistinguishable"):
            lo, hi = f["difference_ci95"]
            found = f"{f['verdict']} [{lo:+.4g}, {hi:+.4g}]"
            out.append(Moved(b.doc, f"{where} stated claim", claim, found, claim))
    return out


def _ci(ci: Any) -> str:
    return f"[{1e3 * ci[0]:+.3f}, {1e3 * ci[1]:+.3f}]"


#: A stated claim is contradicted by a fresh block that finds the opposite or no effect.
_OPPOSITE = {"a lower": "a higher", "a higher": "a lower"}


def _check_block(b: Block, old: Any, new: Any) -> list[Moved]:
    """``amsfe check`` output: the same functions, every one still passing its tolerance."""

    def rows(text: str) -> dict[str, str]:
        return {
            ln.split()[0]: ln.split()[-1]
            for ln in text.splitlines()
            if ln.rstrip().endswith(("pass", "FAIL", "fail"))
            and not ln.startswith(("all ", "function"))
        }

    was, now = rows(old), rows(new)
    out = [
        Moved(b.doc, f"amsfe check {name}", was.get(name, "absent"), now.get(name, "absent"),
              "pass")
        for name in sorted(set(was) | set(now))
        if now.get(name) != "pass"
    ]  # fmt: skip
    return out


_CHECKS = {"claims": _claims_block, "check": _check_block, "effects": _effects_block}
