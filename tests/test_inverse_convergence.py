"""The inverse transition (eq. 22) converges or says that it did not (issue 10, deliverable 3).

The robot: Unitree Z1 from example-robot-data (7 joints, a light gripper), bare URDF with
the paper's integrator.  With the chord matrix M(q+) alone its 6 unrolled steps did not
converge: round trip off by up to 5.1e-3 (median 9.8e-4, 50 of 50 states) at joint
deflections of 0.01 rad, 0.52 at 1 rad; with the Ks-aware chord M(q+) + T^2 Ks (1 - c) it
round-trips to 2.4e-14 (2.7e-12 at 1 rad).  With stiff joints (Ks = 1e4 N m/rad) and one
iteration the inverse does not converge: the generated ``residual`` output says so, the
runtime refuses the result and ``amsfe check`` fails, printing the states.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from amsfe_sym.apps.check import run_checks
from amsfe_sym.apps.cli import main
from amsfe_sym.codegen import generate
from amsfe_sym.errors import ConvergenceError
from amsfe_sym.load import load_robot
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.runtime.models import CompiledTransition
from tests.conftest import erd_urdf


def _z1_spec(folder: Path, integrator: str, stiff: bool = False) -> Path:
    urdf = erd_urdf("z1_description/urdf/z1.urdf")
    extra = "inverse_iterations = 1\n[actuators]\nKs = [" + ", ".join(["1e4"] * 7) + "]\n"
    name = f"z1_{integrator}_{'stiff1' if stiff else 'default'}"
    spec = folder / name / "robot.toml"
    spec.parent.mkdir(parents=True)
    spec.write_text(
        f'name = "{name}"\nurdf = "{urdf}"\n[model]\nintegrator = "{integrator}"\n'
        + (extra if stiff else "")
    )
    return spec


def _states(spec: Path, count: int = 20) -> list[tuple[np.ndarray, np.ndarray]]:
    """Ordinary (x, u): |q|, |qd|, |u| <= 1, deflection |qm - q| <= 0.1, seeded."""
    n = load_robot(spec).n
    rng = np.random.default_rng(0)
    out = []
    for _ in range(count):
        q, qd = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
        qm, qmd = q + rng.uniform(-0.1, 0.1, n), qd + rng.uniform(-0.5, 0.5, n)
        out.append((np.concatenate([q, qd, qm, qmd]), rng.uniform(-1, 1, n)))
    return out


#: The inverse needs the model only (no control laws, no compiled estimators: 3x faster),
#: and its correctness does not depend on the optimizer: -O0 compiles the 7-DOF library 3-5x
#: faster than the default -O1 (33 -> 7 s paper, 59 -> 16 s rk4, this machine).
MODEL = ("model",)
QUICK = ["-O0"]


def _round_trips(spec: Path) -> tuple[list[float], list[float]]:
    """Round-trip errors and generated residuals over :func:`_states`."""
    lib = ModelLibrary(generate(spec, parts=MODEL, extra_cflags=QUICK).out_dir)  # built once
    tr, inv = lib.function("transition"), lib.function("transition_inverse")
    errs, residuals = [], []
    for x, u in _states(spec):
        xn = tr(x, u)[0]
        xb, res = inv(xn, u)
        errs.append(float(np.max(np.abs(xb - x))))
        residuals.append(float(res[0]))
        # the residual output is max|F(x, u) - x_next| at the returned x, computed in C
        assert res[0] == pytest.approx(np.max(np.abs(tr(xb, u)[0] - xn)), rel=1e-9, abs=1e-15)
    return errs, residuals


@pytest.mark.parametrize("integrator", ["paper", "rk4"])
def test_z1_inverse_round_trips(integrator: str, tmp_path: Path) -> None:
    errs, residuals = _round_trips(_z1_spec(tmp_path, integrator, None))
    assert max(errs) < 1e-12  # measured 3.1e-14 (paper), 2.0e-14 (rk4)
    assert max(residuals) < 1e-12


def test_z1_stiff_inverse_reports_non_convergence(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec = _z1_spec(tmp_path, "paper", stiff=True)
    errs, residuals = _round_trips(spec)
    bad = [i for i, e in enumerate(errs) if e > 1e-6]
    assert len(bad) >= len(errs) // 2, "expected states where the iterations do not converge"
    for i in bad:  # every failed round trip is flagged by its residual
        assert residuals[i] > 1e-8
    lib = ModelLibrary(generate(spec, parts=MODEL, extra_cflags=QUICK).out_dir)
    model = CompiledTransition(lib, np.eye(2 * lib.n))
    refused = 0
    for x, u in _states(spec):
        xn = model.step(x, u)[0]
        try:
            xb = model.inverse(xn, u)
        except ConvergenceError as exc:
            refused += 1
            assert "did not converge" in str(exc) and "inverse_iterations" in str(exc)
        else:  # what is returned is a converged answer: F(x) reproduces x_next
            limit = model.inverse_tol * max(1.0, np.max(np.abs(xn)))
            assert np.max(np.abs(model.step(xb, u)[0] - xn)) <= limit
    assert refused >= len(bad)
    # amsfe check fails the robot and prints the states where the round trip failed
    robot = load_robot(spec)
    results = {r.function: r for r in run_checks(robot, lib, samples=10, seed=0)}
    assert not results["transition_inverse"].passed
    assert results["transition_inverse"].failed_at
    assert main(["check", str(spec), "--samples", "10", "--cflags=-O0"]) == 1
    out = capsys.readouterr().out
    assert "transition_inverse failed at x = [" in out and "residual output" in out
