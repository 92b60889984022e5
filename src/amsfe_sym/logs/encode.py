"""Bulk CDR encoding of ``sensor_msgs/msg/JointState`` messages that share their joint names
and field lengths, only the stamp and the float64 values changing (docs/how-to/logs.md, "Speed").

One template message is serialized by ``rosbags`` (``serialize_cdr``, little-endian); the
walk of :mod:`amsfe_sym.logs.layout` (the inverse of the bulk decoders: the same alignment
rules) locates its stamp (int32 sec, uint32 nanosec) and its three ``float64[]``; every
payload is the template with those bytes filled from numpy columns at once.  Anything the
bulk path does not take (a stamp whose seconds leave int32, a template the walk refuses)
goes message by message through ``rosbags``, which then serializes or raises as it always
did.  ``tests/test_encode.py`` requires the same bytes as ``serialize_cdr``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from amsfe_sym.arrays import FloatArray, IntArray
from amsfe_sym.logs.layout import UnusualError, walk_joint_state
from amsfe_sym.logs.source import typestore

__all__ = ["encode_joint_states"]


_NS = 1_000_000_000
_INT32 = (-(2**31), 2**31 - 1)

JOINT_STATE = "sensor_msgs/msg/JointState"


def _columns(values: FloatArray | None, count: int) -> FloatArray:
    """``values`` as a (count, m) float64 array (m = 0 for None; a 1-D array: m = 1)."""
    if values is None:
        return np.zeros((count, 0), dtype=np.float64)
    a = np.asarray(values, dtype=np.float64)
    if a.ndim == 2:
        return a
    return a.reshape(count, -1) if a.size else np.zeros((count, 0), dtype=np.float64)


def _message(
    stamp_ns: int, names: Sequence[str], fields: Sequence[FloatArray], frame: str
) -> bytes:
    ts = typestore()
    types = ts.types
    stamp = types["builtin_interfaces/msg/Time"](sec=stamp_ns // _NS, nanosec=stamp_ns % _NS)
    msg = types[JOINT_STATE](
        header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame),
        name=list(names),
        position=np.ascontiguousarray(fields[0], dtype=np.float64),
        velocity=np.ascontiguousarray(fields[1], dtype=np.float64),
        effort=np.ascontiguousarray(fields[2], dtype=np.float64),
    )
    return bytes(ts.serialize_cdr(msg, JOINT_STATE))


def _reference_joint_states(
    stamps_ns: Sequence[int], names: Sequence[str], cols: Sequence[FloatArray], frame: str
) -> list[bytes]:
    """The CDR payloads of the messages, ``rosbags``' ``serialize_cdr`` one by one: the
    reference of :func:`encode_joint_states` and its fallback (``cols``: its position,
    velocity and effort as (K, m) arrays)."""
    return [_message(int(s), names, [c[k] for c in cols], frame) for k, s in enumerate(stamps_ns)]


def encode_joint_states(
    stamps_ns: Sequence[int] | IntArray,
    names: Sequence[str],
    position: FloatArray | None = None,
    velocity: FloatArray | None = None,
    effort: FloatArray | None = None,
    frame: str = "",
) -> list[bytes]:
    """CDR payloads (little-endian, as ``serialize_cdr`` writes them) of the JointState
    messages k = 0..K-1 stamped ``stamps_ns[k]`` [ns] (sec = floor(ns / 1e9), nanosec = the
    rest, as the bag writer stamps them) with the joint ``names``, header ``frame`` and the
    rows ``position[k]``, ``velocity[k]``, ``effort[k]`` ((K, m) arrays [rad], [rad/s],
    [N m]; None: an empty field).  The same bytes as ``rosbags``' ``serialize_cdr`` of each
    message."""
    stamps = [int(s) for s in stamps_ns]
    count = len(stamps)
    cols = [_columns(v, count) for v in (position, velocity, effort)]
    if count == 0:
        return []
    sec = np.array([s // _NS for s in stamps], dtype=object)
    if min(sec) < _INT32[0] or max(sec) > _INT32[1]:
        return _reference_joint_states(stamps, names, cols, frame)
    template = _message(0, names, [np.zeros(c.shape[1]) for c in cols], frame)
    try:
        layout = walk_joint_state(template, "cdr")
    except UnusualError:
        return _reference_joint_states(stamps, names, cols, frame)
    counts = [c for _, c in layout.arrays]
    if layout.names != tuple(names) or counts != [c.shape[1] for c in cols]:
        return _reference_joint_states(stamps, names, cols, frame)
    length = len(template)
    data = np.tile(np.frombuffer(template, dtype=np.uint8), (count, 1))
    at = layout.stamp
    data[:, at : at + 4] = sec.astype(np.int64).astype("<i4").reshape(count, 1).view(np.uint8)
    nanosec = np.array([s % _NS for s in stamps], dtype="<u4")
    data[:, at + 4 : at + 8] = nanosec.reshape(count, 1).view(np.uint8)
    for (offset, m), c in zip(layout.arrays, cols, strict=True):
        if m:
            block = np.ascontiguousarray(c, dtype="<f8")
            data[:, offset : offset + 8 * m] = block.view(np.uint8).reshape(count, 8 * m)
    flat = data.tobytes()
    return [flat[k * length : (k + 1) * length] for k in range(count)]
