"""Libraries by robot or by scenario: generate (or reuse from the cache) and load."""

from __future__ import annotations

import os
from dataclasses import replace
from typing import Any

from amsfe_sym.codegen.build import generate
from amsfe_sym.codegen.modes import spec_at_period
from amsfe_sym.load.spec import RobotSpec, load_spec
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario, camera_timing

__all__ = ["library_at_period", "library_for", "load_library"]


def load_library(
    robot: str | os.PathLike[str] | RobotSpec = "paper_2link", **generate_kwargs: Any
) -> ModelLibrary:
    """Generate (or reuse from the cache) and load the library of ``robot``
    (``generate_kwargs`` as :func:`generate`)."""
    spec = robot if isinstance(robot, RobotSpec) else load_spec(robot)
    out_dir = generate(spec, **generate_kwargs).out_dir
    return ModelLibrary(out_dir, robot_files=(spec.urdf, spec.spec_path))


def library_for(
    sc: Scenario,
    out: str | os.PathLike[str] | None = None,
    robot: RobotSpec | None = None,
    progress: bool = False,
) -> ModelLibrary:
    """Generate (or reuse) and load the library a scenario runs on.

    The scenario's ``integrator`` (when set and different from the robot's) gives a library
    of its own, ``<robot>_<integrator>``.  The camera timing and the filter's buffer are
    checked against the robot spec first (:func:`~amsfe_sym.scenario.camera_timing`), so a
    bad scenario fails before anything is generated.  ``robot`` replaces the spec of
    ``sc.robot`` (a derived spec, e.g. a sweep's other true payload; give it its own name).
    ``progress``: when the library is built, say so and show the build's progress on stderr
    (a 7-joint arm compiles for about a minute).

    Raises:
        ConfigError: the scenario's camera timing does not fit the robot or the filter.
    """
    from amsfe_sym.codegen.preflight import check_scenario_shapes
    from amsfe_sym.estimation.registry import estimator_class

    spec = robot if robot is not None else load_spec(sc.robot)
    check_scenario_shapes(sc, spec)  # every wrong-length vector, before generating
    camera_timing(
        sc,
        spec.camera.period,
        spec.camera.delay,
        needs_history=estimator_class(sc.estimator).needs_history,
    )
    if sc.integrator and sc.integrator != spec.model.integrator:
        spec = replace(
            spec,
            name=f"{spec.name}_{sc.integrator}",
            model=replace(spec.model, integrator=sc.integrator),  # type: ignore[arg-type]
        )
    return load_library(spec, out=out, progress=progress)


def library_at_period(
    robot: str | os.PathLike[str] | RobotSpec,
    T: float,
    substeps: int | None = None,
    out: str | os.PathLike[str] | None = None,
    progress: bool = False,
) -> ModelLibrary:
    """Generate (or reuse from the cache) and load the library of ``robot`` at sampling
    interval ``T`` [s]: :func:`~amsfe_sym.codegen.modes.spec_at_period` derives its spec in
    memory (``<robot>_T<us>us_<integrator>x<m>``; the robot's own library is untouched), with
    ``substeps`` rk4 steps per T or, when None, the fewest that integrate every joint's
    elastic mode (w h <= 2.0).

    Raises:
        SpecError: T not > 0, or substeps < 1.
    """
    spec = spec_at_period(robot, T, substeps)
    out_dir = generate(spec, out=out, progress=progress).out_dir
    return ModelLibrary(out_dir, robot_files=(spec.urdf, spec.spec_path))
