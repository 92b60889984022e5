"""One exception hierarchy for the whole toolkit.

Every error derives from :class:`AmsfeError` and also from the builtin it refines, so a
caller can catch either (``except ValueError`` keeps working). Messages say what was
expected, what was found, and how to fix it; :func:`describe` builds them uniformly.
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = [
    "AmsfeError",
    "CodegenError",
    "ConfigError",
    "ConvergenceError",
    "EstimatorError",
    "LogError",
    "MeasurementError",
    "ModelError",
    "RosError",
    "RunFolderError",
    "ShapeError",
    "SpecError",
    "UnsupportedJointError",
    "UrdfError",
    "check_known_keys",
    "describe",
    "unknown_name",
]


def describe(what: str, expected: str, found: str, fix: str) -> str:
    """Format a message as ``what: expected ..., found .... Fix: ...`` (no "Fix:" when
    ``fix`` is empty: an internal check whose remedy is not the user's)."""
    return f"{what}: expected {expected}, found {found}." + (f" Fix: {fix}" if fix else "")


class AmsfeError(Exception):
    """Base of every error raised by amsfe_sym."""


class UrdfError(AmsfeError, ValueError):
    """A URDF file is malformed or physically invalid (bad inertia, negative mass, ...)."""


class UnsupportedJointError(UrdfError):
    """A joint type the toolkit does not model (floating, planar, spherical, mimic)."""


class ModelError(AmsfeError, ValueError):
    """The robot model as a whole cannot be used (singular mass matrix, empty chain)."""


class SpecError(AmsfeError, ValueError):
    """A robot spec or scenario file is invalid (unknown joint or frame, bad value)."""


class ConfigError(SpecError):
    """A run configuration (scenario) is invalid: covariances, delays, estimator names."""


class ShapeError(AmsfeError, ValueError):
    """An array has the wrong shape at an API boundary."""


class CodegenError(AmsfeError, RuntimeError):
    """Generating, compiling or loading the C library failed."""


class EstimatorError(AmsfeError, RuntimeError):
    """The estimator cannot proceed (buffer too short, covariance lost definiteness)."""


class MeasurementError(AmsfeError, ValueError):
    """A measurement is unusable (NaN or inf, outside the image, wrong size)."""


class ConvergenceError(EstimatorError):
    """An iterative generated function (the inverse transition, eq. 22) did not converge:
    its ``residual`` output is above the tolerance, so its result is not used.  Estimators
    treat it like a refused frame (counted, estimate untouched)."""


class RosError(AmsfeError, RuntimeError):
    """ROS 2 cannot be used as asked: rclpy not installed, no peer on a topic in time, the
    middleware failing (docs/how-to/ros.md)."""


class LogError(AmsfeError, ValueError):
    """A recorded log cannot be used as asked: unreadable or truncated, a topic missing or of
    the wrong message type, samples off the tick grid (docs/how-to/logs.md)."""


class RunFolderError(AmsfeError, FileExistsError):
    """A run's output folder cannot be written as asked (it exists and ``--force`` is off,
    or it is a file), or a file in it that the toolkit wrote is damaged (a sweep's part)."""


def unknown_name(
    what: str, name: object, known: Iterable[str], fix: str = "pick a name from that list"
) -> ConfigError:
    """The error for a name that is not in a registry or not one of a setting's choices
    (``raise unknown_name(...)``): the message lists the known names."""
    return ConfigError(
        describe(what, "one of " + ", ".join(repr(n) for n in known), repr(name), fix)
    )


def check_known_keys(
    what: str,
    given: Iterable[str],
    known: Iterable[str],
    fix: str = "remove or rename them",
    error: type[AmsfeError] | None = None,
) -> None:
    """Raise ``error`` (default :class:`ConfigError`) listing the keys of ``given`` that
    are not ``known``."""
    unknown = sorted(set(given) - set(known))
    if unknown:
        cls = error or ConfigError
        raise cls(describe(what, f"keys among {sorted(known)}", f"unknown {unknown}", fix))
