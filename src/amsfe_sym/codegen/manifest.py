"""The manifest of a generated library (``manifest.json``): what the runtime reads instead
of the symbols (DESIGN.md, "Generated-function contract")."""

from __future__ import annotations

import math
from typing import Any

__all__ = ["manifest_document"]


def _io(name: str, shape: tuple[int, int]) -> dict[str, Any]:
    """Manifest entry of one input or output: name, shape, and whether it is a matrix
    (a jacobian with one column is still a matrix) or a vector."""
    from amsfe_sym.symbolic.model import MATRIX_OUTPUTS

    return {"name": name, "shape": list(shape), "matrix": name in MATRIX_OUTPUTS or shape[1] > 1}


def manifest_document(
    model: Any,
    key: str,
    hash_inputs: dict[str, Any],
    libname: str,
    cname: str,
    timings: dict[str, float],
) -> dict[str, Any]:
    """The manifest of ``model`` (a :class:`~amsfe_sym.symbolic.model.ModelFunctions`) built
    into ``libname`` from ``cname`` with cache key ``key``."""
    robot = model.robot
    cam = robot.camera
    fns = {}
    chained = {name: model.functions[target] for name, target in model.chained.items()}
    for name, f in [*model.functions.items(), *chained.items()]:
        fns[name] = {
            "inputs": [_io(f.name_in(i), f.size_in(i)) for i in range(f.n_in())],
            "outputs": [_io(f.name_out(i), f.size_out(i)) for i in range(f.n_out())],
        }
    n, p = robot.n, robot.p
    return {
        "name": robot.name,
        "library": libname,
        "source": cname,
        "header": cname[:-2] + ".h",
        "runtime_header": "amsfe_runtime.h" if "est_predict" in model.functions else None,
        "loop_header": "amsfe_loop.h"
        if "control_amsfe" in model.functions and "est_predict" in model.functions
        else None,
        "urdf": str(robot.spec.urdf),
        "spec": None if robot.spec.spec_path is None else str(robot.spec.spec_path),
        "joints": [j.name for j in robot.joints],
        "joint_kinds": [j.kind for j in robot.joints],
        "locked": dict(robot.spec.model.locked),
        "n": n,
        "p": p,
        "N": 4 * n + p,
        "theta": [
            {
                "name": b.spec.name,
                "kind": b.spec.kind,
                "target": b.spec.target,
                "offset": list(b.spec.offset),
                "true": b.spec.true,
                "initial": b.spec.initial,
                "unit": "N m/rad" if b.spec.kind == "joint_stiffness" else "kg",
            }
            for b in robot.theta
        ],
        "tracked_frame": robot.tracked_frame,
        "tracked_offset": robot.tracked_offset.tolist(),
        "T": robot.spec.model.T,
        "integrator": robot.spec.model.integrator,
        "inverse_iterations": robot.spec.model.inverse_iterations,
        "plant_substeps": robot.spec.model.plant_substeps,
        "model_substeps": robot.spec.model.model_substeps,
        "gravity": robot.gravity.tolist(),
        "state_layout": model.layout.as_dict(),
        "noise_layout": {"w_l": [0, n], "w_m": [n, 2 * n], "w_theta": [2 * n, 2 * n + p]},
        "actuators": {
            "Ks": robot.Ks.tolist(),
            "Mm": robot.Mm.tolist(),
            "Fm": robot.Fm.tolist(),
            # JSON has no inf: a joint without a limit is null
            "u_max": [float(v) if math.isfinite(v) else None for v in robot.u_max],
        },
        "camera": {
            "K": cam.K.tolist(),
            "R_cw": cam.R_cw.tolist(),
            "position": cam.position.tolist(),
            "width": cam.width,
            "height": cam.height,
            "period": cam.period,
            "delay": cam.delay,
        },
        "camera_depends_on_theta": model.camera_depends_on_theta,
        "functions": fns,
        "content_hash": key,
        "hash_inputs": hash_inputs,
        "timings_s": {k: round(v, 4) for k, v in timings.items()},
    }
