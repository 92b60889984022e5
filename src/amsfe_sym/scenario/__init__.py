"""Scenarios: everything a simulation run needs beyond the robot, in one TOML file.

Shipped scenarios live in ``scenarios/`` (``paper-sim``, ``paper-exp``); copy one and edit
it.  Every key is documented in ``docs/reference/scenarios.md``.  A run saves its resolved scenario
as ``config.toml``, which ``amsfe simulate <run>/config.toml`` re-runs exactly.

The package: ``model`` (the :class:`Scenario` value objects), ``read``
(:func:`load_scenario`, the value checks), ``timing`` (:func:`camera_timing`), ``overrides``
(:func:`apply_sets`, ``--set``).  May import: errors, core, load.spec (types and the shipped
data folder); nothing of the build, runtime or simulation.
"""

from amsfe_sym.core.toml import dump_toml
from amsfe_sym.scenario.model import (
    CameraSettings,
    EncoderSettings,
    EstimateInit,
    FilterSettings,
    PlantConfig,
    Scenario,
)
from amsfe_sym.scenario.overrides import apply_sets, with_filter
from amsfe_sym.scenario.read import (
    find_scenario,
    load_scenario,
    parse_scenario,
    scenarios_dir,
    validate,
)
from amsfe_sym.scenario.timing import (
    MAX_RECORD_BYTES,
    CameraTiming,
    camera_timing,
    record_bytes_per_tick,
    run_ticks,
)

__all__ = [
    "MAX_RECORD_BYTES",
    "CameraSettings",
    "CameraTiming",
    "EncoderSettings",
    "EstimateInit",
    "FilterSettings",
    "PlantConfig",
    "Scenario",
    "apply_sets",
    "camera_timing",
    "dump_toml",
    "find_scenario",
    "load_scenario",
    "parse_scenario",
    "record_bytes_per_tick",
    "run_ticks",
    "scenarios_dir",
    "validate",
    "with_filter",
]
