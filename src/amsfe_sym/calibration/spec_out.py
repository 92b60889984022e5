"""The calibrated robot spec: the input ``robot.toml`` with its camera pose and tracked offset
replaced by the calibration's, which ``amsfe generate`` accepts (docs/calibrate.md)."""

from __future__ import annotations

from typing import Any

from amsfe_sym.calibration.solve import Calibration
from amsfe_sym.core.toml import dump_toml, read_toml
from amsfe_sym.errors import SpecError
from amsfe_sym.load.camera import matrix_to_quaternion
from amsfe_sym.load.types import Robot

__all__ = ["calibrated_spec"]


def calibrated_spec(robot: Robot, cal: Calibration, log: str) -> str:
    """The text of the calibrated ``robot.toml``: the input spec's keys (comments are not
    kept), ``name`` + ``_calibrated`` (its own library, beside the original's), ``urdf`` as
    an absolute path, ``[tracked]`` with the calibrated offset, ``[camera]`` with the resolved
    intrinsics, ``position`` and ``orientation`` (no ``look_at`` / ``up``)."""
    spec = robot.spec
    data: dict[str, Any] = (
        dict(read_toml(spec.spec_path, SpecError)) if spec.spec_path is not None else {}
    )
    data["name"] = f"{spec.name}_calibrated"
    data["urdf"] = str(spec.urdf.resolve())
    tracked = dict(data.get("tracked", {}))
    tracked["frame"] = robot.tracked_frame
    tracked["offset"] = [float(v) for v in cal.offset]
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
        position=[float(v) for v in cal.position],
        orientation=[float(v) for v in matrix_to_quaternion(cal.R_cw.T)],
    )
    data["camera"] = camera
    order = ["name", "urdf"] + [k for k in data if k not in ("name", "urdf")]
    head = (
        f"# {spec.spec_path or spec.urdf} with the camera pose and the tracked offset that\n"
        f"# `amsfe calibrate` found in {log} (docs/calibrate.md); time offset (stamp - exposure)\n"
        f"# {cal.time_offset * 1e3:+.3f} ms, reprojection RMS {cal.pixel_std:.3f} px per axis.\n"
    )
    body = dump_toml({k: data[k] for k in order})
    return head + body
