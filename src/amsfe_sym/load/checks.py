"""Checks on the loaded model that need the whole robot (a singular mass matrix)."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from amsfe_sym.errors import ModelError, describe
from amsfe_sym.load.types import Robot

__all__ = ["check_mass_matrix", "is_ancestor"]


def check_mass_matrix(robot: Robot) -> None:
    """Refuse a modelled joint whose subtree has no mass or inertia (M singular)."""
    model = robot.pin_model_at(robot.theta_true)
    data = model.createData()
    n = robot.n
    # subtree test first: a joint whose subtree has zero mass and zero rotational inertia
    for j in robot.joints:
        sub = [k for k in range(1, model.njoints) if is_ancestor(model, j.pin_id, k)]
        total = sum(model.inertias[k].mass for k in sub)
        rot = sum(float(np.abs(model.inertias[k].inertia).sum()) for k in sub)
        if total <= 0 and rot <= 0:
            raise ModelError(
                describe(
                    f"{robot.spec.urdf}: joint {j.name!r}",
                    "some mass or inertia in the subtree the joint moves",
                    "a massless subtree, so M(q) is singular",
                    "add the links' <inertial> data, or lock the joint (--lock / [model] locked)",
                )
            )
    rng = np.random.default_rng(0)
    worst = math.inf
    for _ in range(8):
        q = rng.uniform(-math.pi, math.pi, n)
        M = pin.crba(model, data, robot.to_pin_q(q))
        M = np.triu(M) + np.triu(M, 1).T
        worst = min(worst, float(np.linalg.eigvalsh(M)[0]))
    if worst <= 1e-12 * max(1.0, float(np.abs(M).max())):
        diag = np.diag(M)
        j = robot.joints[int(np.argmin(diag))]
        raise ModelError(
            describe(
                f"{robot.spec.urdf}: mass matrix",
                "positive definite M(q)",
                f"smallest eigenvalue {worst:.3g} (weakest joint {j.name!r})",
                "a modelled joint moves no inertia about its axis; lock it or fix <inertial>",
            )
        )


def is_ancestor(model: pin.Model, a: int, k: int) -> bool:
    while k > 0:
        if k == a:
            return True
        k = model.parents[k]
    return False
