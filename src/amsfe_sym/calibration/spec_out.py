"""The calibrated specs (docs/calibrate.md): the input ``robot.toml`` with its camera pose and
tracked offset replaced by the calibration's, which ``amsfe generate`` accepts, and the topic
spec with the camera's ``[camera] time_offset``, which ``amsfe estimate`` and ``amsfe node``
apply."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.calibration.solve import Calibration
from amsfe_sym.core.toml import dump_toml, read_toml
from amsfe_sym.errors import ConfigError, SpecError
from amsfe_sym.load.rotation import matrix_to_quaternion
from amsfe_sym.load.types import Robot

__all__ = ["calibrated_spec", "calibrated_topic_spec", "moved_camera_spec", "spec_with_camera"]

FloatArray = NDArray[np.float64]


def spec_with_camera(
    robot: Robot,
    name: str,
    R_cw: FloatArray,
    position: FloatArray,
    offset: FloatArray,
    marker_R: FloatArray | None = None,
) -> str:
    """The text of ``robot``'s spec (its keys; comments are not kept) named ``name``, with
    ``urdf`` an absolute path, ``[tracked]`` at ``offset`` [m] in the tracked frame (and its
    ``orientation``, the quaternion of ``marker_R`` (marker -> tracked frame), when given) and
    ``[camera]`` with the resolved intrinsics, ``position`` [m] and ``orientation`` (the
    quaternion of ``R_cw`` transposed; no ``look_at`` / ``up``)."""
    spec = robot.spec
    data: dict[str, Any] = (
        dict(read_toml(spec.spec_path, SpecError)) if spec.spec_path is not None else {}
    )
    data["name"] = name
    data["urdf"] = str(spec.urdf.resolve())
    tracked = dict(data.get("tracked", {}))
    tracked["frame"] = robot.tracked_frame
    tracked["offset"] = [float(v) for v in offset]
    if marker_R is not None:
        tracked["orientation"] = [float(v) for v in matrix_to_quaternion(np.asarray(marker_R))]
    data["tracked"] = tracked
    camera = {k: v for k, v in dict(data.get("camera", {})).items() if k not in ("look_at", "up")}
    K = robot.camera.K
    camera.update(
        width=robot.camera.width,
        height=robot.camera.height,
        fx=float(K[0, 0]),
        fy=float(K[1, 1]),
        cx=float(K[0, 2]),
        cy=float(K[1, 2]),
        position=[float(v) for v in position],
        orientation=[float(v) for v in matrix_to_quaternion(np.asarray(R_cw).T)],
    )
    data["camera"] = camera
    order = ["name", "urdf"] + [k for k in data if k not in ("name", "urdf")]
    return dump_toml({k: data[k] for k in order})


def calibrated_spec(robot: Robot, cal: Calibration, log: str) -> str:
    """The calibrated ``robot.toml``: :func:`spec_with_camera` at the calibration (with the
    marker's orientation after a corner fit), named
    ``<name>_calibrated`` (its own library, beside the original's), with a header saying
    where it comes from and the time offset (a topic spec key:
    :func:`calibrated_topic_spec`)."""
    spec = robot.spec
    head = (
        f"# {spec.spec_path or spec.urdf} with the camera pose and the tracked offset that\n"
        f"# `amsfe calibrate` found in {log} (docs/calibrate.md); time offset (stamp - exposure)\n"
        f"# {cal.time_offset * 1e3:+.3f} ms (topics.toml beside it: [camera] time_offset),\n"
        f"# reprojection RMS {cal.pixel_std:.3f} px per axis.\n"
    )
    name = f"{spec.name}_calibrated"
    return head + spec_with_camera(robot, name, cal.R_cw, cal.position, cal.offset, cal.marker_R)


def calibrated_topic_spec(source: Path | None, time_offset: float, log: str) -> str:
    """The topic spec ``source`` (its keys; comments are not kept; None: an empty one) with
    ``[camera] time_offset`` = ``time_offset`` [s] (header stamp - exposure, rounded to 1 us),
    under a header saying where it comes from."""
    data: dict[str, Any] = dict(read_toml(source, ConfigError)) if source is not None else {}
    camera = dict(data.get("camera", {}))
    camera["time_offset"] = round(float(time_offset), 6)
    data["camera"] = camera
    head = (
        f"# {source or 'the default topic spec'} with the camera's time offset (header stamp -\n"
        f"# exposure) that `amsfe calibrate` found in {log} (docs/calibrate.md).\n"
    )
    return head + dump_toml(data)


def moved_camera_spec(
    robot: Robot,
    rng: np.random.Generator,
    shift: float = 0.03,
    turn_deg: float = 2.0,
    marker: float = 0.02,
    name: str | None = None,
) -> str:
    """``robot``'s spec with its camera moved ``shift`` [m] and turned ``turn_deg`` [deg],
    and its tracked point ``marker`` [m] off the spec's, in random directions from ``rng``:
    the "true" camera of a simulated recording ``amsfe calibrate`` is tested on
    (tests/test_calibrate.py, tools/calibrate_seeds.py)."""
    import cv2

    d, w, o = (v / np.linalg.norm(v) for v in rng.standard_normal((3, 3)))
    R = np.asarray(cv2.Rodrigues(w * math.radians(turn_deg))[0]) @ robot.camera.R_cw
    return spec_with_camera(
        robot,
        name or f"{robot.name}_moved",
        R,
        robot.camera.position + shift * d,
        np.asarray(robot.tracked_offset) + marker * o,
    )
