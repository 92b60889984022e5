"""Estimators by name: the names scenarios and the command line use."""

from __future__ import annotations

from typing import Any

from amsfe_sym.errors import unknown_name
from amsfe_sym.estimation.base import Estimator
from amsfe_sym.estimation.cloning import CloningEstimator
from amsfe_sym.estimation.encoders import EncodersEstimator
from amsfe_sym.estimation.naive import NaiveEstimator
from amsfe_sym.estimation.oosm import OosmEstimator
from amsfe_sym.estimation.replay import ReplayEstimator

__all__ = ["ESTIMATORS", "estimator_class", "make_estimator"]

ESTIMATORS: dict[str, type[Estimator]] = {
    cls.name: cls
    for cls in (
        EncodersEstimator,
        NaiveEstimator,
        OosmEstimator,
        ReplayEstimator,
        CloningEstimator,
    )
}


def estimator_class(name: str) -> type[Estimator]:
    """The estimator class registered as ``name``.

    Raises:
        ConfigError: If ``name`` is unknown (the message lists the known names).
    """
    try:
        return ESTIMATORS[name]
    except (KeyError, TypeError):
        raise unknown_name("estimator name", name, ESTIMATORS) from None


def make_estimator(name: str, **kwargs: Any) -> Estimator:
    """Build the estimator registered as ``name``.

    Args:
        name: One of ``ESTIMATORS`` (``"encoders"``, ``"naive"``, ``"oosm"``, ``"replay"``,
            ``"cloning"``).
        **kwargs: The constructor arguments of :class:`~amsfe_sym.estimation.base.Estimator`
            (``model``, ``encoder``, ``camera``, ``x0``, ``P0``, ``config``, ``k0``).

    Raises:
        ConfigError: If ``name`` is unknown (the message lists the known names).
    """
    return estimator_class(name)(**kwargs)
