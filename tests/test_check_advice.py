"""``amsfe check`` passes on every robot the tool advises, over 20 seeds.

What "advises" means: the shipped robots as they ship (``generate`` prints no advice for
them), and a robot at a log's period where ``generate`` says a joint is too stiff for the
model (``stiff_joints``) and prints the fix, ``model_substeps = k`` or ``amsfe generate
ROBOT --period T --substeps k`` (``stiffness_fix``).  The fix is followed as printed, and
the library it builds must pass every row of ``amsfe check`` at 20 seeds: a user who did
what the tool said never meets a FAIL (a UR10 from a bare URDF once failed the chained rk4
step's fixed 1e-13 at 1.31e-13 after following the advice ``model_substeps = 7``).

The period is 0.008 s, a 125 Hz log (the UR CB-series controller's rate), where every arm
here gets advice; the bare URDFs are example-robot-data's, with their default spec.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from amsfe_sym.apps.check import run_checks
from amsfe_sym.codegen import generate
from amsfe_sym.codegen.modes import joint_modes, robot_source, spec_at_period
from amsfe_sym.load import load_robot
from amsfe_sym.load.spec import load_spec
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.runtime.stability import stiff_joints, stiffness_fix, substeps_for

from .conftest import erd_urdf

SEEDS = range(20)
#: Random states per seed (each row of the table at 20 x 3 = 60 states).
SAMPLES = 3
#: A 125 Hz log's period [s].
LOG_T = 0.008

SHIPPED = ["paper_1link", "paper_2link", "ur5", "panda"]
#: (robot, locked joints): shipped arms and bare third-party URDFs at the log's period.
ADVISED = [
    ("ur5", None),
    ("panda", None),
    ("ur_description/urdf/ur10_robot.urdf", None),
    ("so_arm_description/urdf/so101.urdf", None),
    ("panda_description/urdf/panda.urdf", {"panda_finger_joint2": 0.02}),
]


def _failed(robot, lib: ModelLibrary) -> list[str]:
    """Every FAIL row of ``amsfe check`` over :data:`SEEDS`, named by its seed."""
    return [
        f"seed {seed}: {r.function} {r.max_error:.3g} > {r.tolerance:.3g}"
        for seed in SEEDS
        for r in run_checks(robot, lib, samples=SAMPLES, seed=seed)
        if not r.passed
    ]


@pytest.mark.slow
@pytest.mark.parametrize("name", SHIPPED)
def test_a_shipped_robot_passes_check_at_20_seeds(name: str, libraries) -> None:
    """A shipped robot as it ships: ``generate`` advises nothing, and ``check`` passes.
    (The whole library, as the other tests build it: a model-only one of the shipped Panda
    shares its folder name, ``panda-model``, with the bare example-robot-data Panda of
    tests/test_generated.py, and the cache keeps one folder per name.)"""
    robot, lib = libraries.get(name)
    m = robot.spec.model
    assert not stiff_joints(joint_modes(robot), m.T, m.integrator, m.model_substeps)
    assert not _failed(robot, lib)


@pytest.mark.slow
@pytest.mark.parametrize(("source", "lock"), ADVISED, ids=lambda v: Path(str(v)).stem)
def test_the_advice_followed_passes_check_at_20_seeds(
    source: str, lock: dict[str, float] | None, tmp_path: Path
) -> None:
    """At a 125 Hz log's period with one rk4 step a tick, ``generate`` finds stiff joints
    and prints ``--substeps k``; generated with that k, the robot has no stiff joint left
    and ``check`` passes every row at 20 seeds.  (Into a folder of its own: the library
    cache keeps one folder per robot name, and the 1 kHz libraries of the same names are
    other tests' on the other xdist worker.)"""
    path = source if "/" not in source else str(erd_urdf(source))
    spec = load_spec(path)
    loaded = load_robot(spec, lock=lock)
    modes = joint_modes(loaded)  # of the continuous arm: the same at every period
    assert stiff_joints(modes, LOG_T, "rk4", 1), "no advice here: pick a period with some"
    k = substeps_for(modes, LOG_T)
    advice = stiffness_fix(robot_source(spec), LOG_T, "rk4", k)
    assert f"model_substeps = {k}" in advice
    printed = int(re.search(r"--substeps (\d+)", advice).group(1))  # type: ignore[union-attr]
    followed = spec_at_period(spec, LOG_T, substeps=printed, loaded=loaded)
    robot = load_robot(followed, lock=lock)
    assert robot.spec.model.model_substeps == printed
    assert not stiff_joints(joint_modes(robot), LOG_T, "rk4", printed)
    lib = ModelLibrary(generate(followed, lock=lock, parts=("model",), out=tmp_path).out_dir)
    assert not _failed(robot, lib)
