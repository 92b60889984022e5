"""The one JSON writer of the tool: strict JSON (RFC 8259), never a bare ``NaN``/``Infinity``.

``json.dumps`` writes a NaN as the bare literal ``NaN``, which no strict parser reads (the
``summary.json`` of a run whose NEES was NaN was not JSON).  :func:`to_json` writes
every non-finite number as ``null`` and records where and what it was in the top-level
object's :data:`NON_FINITE` entry (``{"nees_mean": "nan"}``), so the reason is kept;
numpy scalars and arrays become numbers and lists.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["NON_FINITE", "jsonable", "to_json", "write_json"]

#: The top-level key that lists the non-finite numbers written as ``null``: ``{path: "nan"}``.
NON_FINITE = "non_finite"


def _name(v: float) -> str:
    return "nan" if math.isnan(v) else "inf" if v > 0 else "-inf"


def jsonable(x: Any, where: str = "", found: dict[str, str] | None = None) -> Any:
    """``x`` with numpy values made plain, tuples made lists and non-finite floats made
    ``None`` (each recorded in ``found`` as ``{"a.b[2]": "nan"}``)."""
    if isinstance(x, Mapping):
        return {
            str(k): jsonable(v, f"{where}.{k}" if where else str(k), found) for k, v in x.items()
        }
    if isinstance(x, np.ndarray):
        x = x.tolist()
    if isinstance(x, list | tuple):
        return [jsonable(v, f"{where}[{i}]", found) for i, v in enumerate(x)]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        if found is not None:
            found[where] = _name(x)
        return None
    return x


def to_json(doc: Any, indent: int | None = 2, default: Any = None) -> str:
    """Strict JSON text of ``doc`` (ending in a newline): non-finite numbers as ``null``,
    listed under :data:`NON_FINITE` when ``doc`` is an object."""
    found: dict[str, str] = {}
    clean = jsonable(doc, "", found)
    if found and isinstance(clean, dict):
        clean[NON_FINITE] = {**clean.get(NON_FINITE, {}), **found}
    return json.dumps(clean, indent=indent, allow_nan=False, default=default) + "\n"


def write_json(
    path: Path, doc: Any, indent: int | None = 2, default: Any = None, own: str | None = None
) -> Path:
    """Write ``doc`` to ``path`` as strict JSON (:func:`to_json`), whole or not at all (a
    hidden sibling renamed into place).  ``own`` (e.g. ``"amsfe bench"``) marks the file as
    the tool's output (:data:`amsfe_sym.core.outputs.OWN_KEY`), which ``--force`` may
    replace."""
    if own is not None and isinstance(doc, Mapping):
        from amsfe_sym.core.outputs import OWN_KEY

        doc = {OWN_KEY: own, **doc}
    text = to_json(doc, indent, default)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        tmp.write_text(text)
        tmp.replace(path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path
