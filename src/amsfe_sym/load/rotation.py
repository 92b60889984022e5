"""Rotations of the camera pose (``[camera] orientation``, docs/reference/robot-spec.md): unit
quaternions ``[qx, qy, qz, qw]`` (Hamilton, scalar last, as ROS and scipy write them) to and
from rotation matrices, and the spec key's reader."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.core.values import read_number
from amsfe_sym.errors import SpecError, describe

__all__ = ["UNIT_TOLERANCE", "matrix_to_quaternion", "quaternion_to_matrix", "read_orientation"]
__all__ += ["read_marker_orientation"]


def quaternion_to_matrix(q: tuple[float, ...] | NDArray[np.float64]) -> NDArray[np.float64]:
    """The rotation matrix of the unit quaternion ``q = [qx, qy, qz, qw]`` (Hamilton, scalar
    last, as ROS and scipy write it)."""
    x, y, z, w = (float(v) for v in q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quaternion(R: NDArray[np.float64]) -> NDArray[np.float64]:
    """The unit quaternion ``[qx, qy, qz, qw]`` (``qw >= 0``) of the rotation matrix ``R``
    (Shepperd's method: the largest of the four squared components first)."""
    R = np.asarray(R, dtype=float)
    tr = float(np.trace(R))
    d = np.array([R[0, 0], R[1, 1], R[2, 2], tr])
    i = int(np.argmax(d))
    if i == 3:
        w = 0.5 * math.sqrt(1.0 + tr)
        q = np.array(
            [
                (R[2, 1] - R[1, 2]) / (4 * w),
                (R[0, 2] - R[2, 0]) / (4 * w),
                (R[1, 0] - R[0, 1]) / (4 * w),
                w,
            ]
        )
    else:
        j, k = (i + 1) % 3, (i + 2) % 3
        a = 0.5 * math.sqrt(max(1.0 + 2.0 * R[i, i] - tr, 0.0))
        q = np.zeros(4)
        q[i] = a
        q[j] = (R[j, i] + R[i, j]) / (4 * a)
        q[k] = (R[k, i] + R[i, k]) / (4 * a)
        q[3] = (R[k, j] - R[j, k]) / (4 * a)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


#: How far from 1 the norm of an orientation's quaternion may be (it is then normalised).
UNIT_TOLERANCE = 1e-6


def read_orientation(c: Mapping[str, Any], where: str) -> tuple[float, float, float, float] | None:
    """``[camera] orientation``: a unit quaternion [qx, qy, qz, qw] (world-from-camera),
    normalised; refused with ``look_at`` or ``up``, without ``position``, or not unit."""
    x = c.get("orientation")
    if x is None:
        return None
    w = f"{where} orientation"
    q = _four_numbers(x, w)
    both = [k for k in ("look_at", "up") if k in c]
    if both:
        raise SpecError(
            describe(
                w,
                "one rotation: orientation, or look_at / up",
                f"orientation and {' and '.join(both)}",
                f"remove {' and '.join(both)} (or orientation)",
            )
        )
    if "position" not in c:
        raise SpecError(
            describe(w, "a camera position with it", "none", "add position = [x, y, z]")
        )
    return _unit(q, w)


def read_marker_orientation(
    t: Mapping[str, Any], where: str
) -> tuple[float, float, float, float] | None:
    """``[tracked] orientation``: the marker's frame in the tracked frame, a unit quaternion
    [qx, qy, qz, qw], normalised; None when absent.  The marker's frame is OpenCV's ArUco one:
    its centre at the tracked point, x to the right and y up as printed, z out of the printed
    face (toward a camera that sees it); corners at ``size/2 (-1, 1), (1, 1), (1, -1),
    (-1, -1)``."""
    x = t.get("orientation")
    w = f"{where} orientation"
    return None if x is None else _unit(_four_numbers(x, w), w)


def _four_numbers(x: Any, w: str) -> list[float]:
    """``x`` as the 4 numbers of a quaternion [qx, qy, qz, qw], refused with one line."""
    if not isinstance(x, Sequence) or isinstance(x, str) or len(x) != 4:
        raise SpecError(
            describe(w, "4 numbers [qx, qy, qz, qw]", repr(x), "write [qx, qy, qz, qw]")
        )
    return [read_number(v, w, SpecError) for v in x]


def _unit(q: Sequence[float], w: str) -> tuple[float, float, float, float]:
    """``q`` normalised, refused when its norm is not 1 within :data:`UNIT_TOLERANCE`."""
    norm = math.sqrt(sum(v * v for v in q))
    if abs(norm - 1.0) > UNIT_TOLERANCE:
        raise SpecError(
            describe(
                w,
                f"a unit quaternion (norm 1 within {UNIT_TOLERANCE:g}): a rotation",
                f"norm {norm:.9g}",
                "write the rotation's quaternion [qx, qy, qz, qw] with all its digits",
            )
        )
    a, b, d, e = (v / norm for v in q)
    return (a, b, d, e)
