"""The record of the C node (``amsfe node --impl c --record DIR``; docs/live-control.md,
"The record"): the arrays it wrote at its stop, read and written as the rosbag2 of the
Python node's writer (:class:`~amsfe_sym.ros.record.NodeRecord`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario
from amsfe_sym.topics import TopicSpec

__all__ = ["read_record_arrays", "write_record"]


def read_record_arrays(path: Path, lib: ModelLibrary) -> dict[str, NDArray[Any]]:
    """The arrays the C node wrote at its stop (sections ``name type rows cols data``)."""
    raw = path.read_bytes()
    out: dict[str, NDArray[Any]] = {}
    pos = 0
    kinds = {"d": "<f8", "q": "<i8", "c": "u1"}
    while pos < len(raw):
        name = raw[pos : pos + 14].rstrip(b"\0").decode()
        kind = chr(raw[pos + 15])
        rows, cols = np.frombuffer(raw, "<i8", 2, pos + 16)
        pos += 32
        dtype = np.dtype(kinds[kind])
        count = int(rows) * int(cols)
        out[name] = np.frombuffer(raw, dtype, count, pos).reshape(int(rows), int(cols)).copy()
        pos += count * dtype.itemsize
    return out


def write_record(
    sc: Scenario,
    lib: ModelLibrary,
    spec: TopicSpec,
    a: dict[str, NDArray[Any]],
    out: Path,
    rec: Any = None,
    end: str = "done",
) -> Path:
    """The rosbag2 of ``--record`` from the C node's arrays, in the Python node's order
    (each tick: its diagnostics, encoders, the frames fused at it, the truth, the outputs;
    then the torques stamped up to it; the hold command last).  A tick's truth is the last
    one sent after the previous tick's encoder sample and not after its own (their DDS
    source timestamps: never the previous tick's)."""
    from amsfe_sym.ros.record import NodeRecord

    names = list(spec.joint_names or lib.manifest.joints)
    rec = NodeRecord(sc, lib, spec, names) if rec is None else rec  # (claimed at the start)
    L = lib.layout
    text = bytes(a["diag_text"].ravel())
    diags = text.split(b"\0")[:-1] if text else []
    diag_ns = a["diag_ns"].ravel()
    fr_ns, eff_ns = a["fr_ns"].ravel(), a["eff_ns"].ravel()
    sent, truth_sent = a["sent"].ravel(), a["truth_sent"].ravel()
    d = f = e = 0
    prev = np.iinfo(np.int64).min
    for t, ns in enumerate(int(v) for v in a["ns"].ravel()):
        while d < len(diag_ns) and diag_ns[d] == ns:
            rec.diagnostics(ns, diags[d].decode())
            d += 1
        rec.encoders(ns, a["z"][t])
        while f < len(fr_ns) and fr_ns[f] == ns:
            rec.frame(ns, int(a["fr_exp"][f, 0]), a["fr_z"][f])
            f += 1
        mine = np.flatnonzero((truth_sent > prev) & (truth_sent <= sent[t]))
        if mine.size:
            rec.truth(ns, a["truth_x"][mine[np.argmax(truth_sent[mine])]])
        prev = int(sent[t])
        x = a["x"][t]
        u = a["u"][t] if np.all(np.isfinite(a["u"][t])) else None
        rec.outputs(ns, x, a["std"][t], x[L["theta"]], u)
        while e < len(eff_ns) and eff_ns[e] <= ns:
            rec.applied(int(eff_ns[e]), a["eff_u"][e])
            e += 1
    while e < len(eff_ns):
        rec.applied(int(eff_ns[e]), a["eff_u"][e])
        e += 1
    if a["hold_ns"].size:
        rec.hold(int(a["hold_ns"][0, 0]), a["hold_u"][0])
    if hasattr(rec, "stopped"):  # how the node stopped, into /amsfe/config
        code = int(a["stop_code"][0, 0])
        wd = bytes(a["stop_wd"].ravel()).decode()
        line = bytes(a["stop_line"].ravel()).decode()
        rec.stopped(line, None if code in (130, 143) else code, wd or None)
        end = line or end  # the node's own line: the record's amsfe.end
    return Path(rec.write(out, reason=end))
