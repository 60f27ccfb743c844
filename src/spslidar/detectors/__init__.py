"""Detector models (the stage after the forward model) and their registry.

``DETECTORS.load(name)(**options)`` is a :class:`~spslidar.detectors.base.DetectorModel`;
``linear`` is the paper's counter (the default).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..registry import Registry, lazy_exports

if TYPE_CHECKING:
    from .base import DetectorModel

__all__ = ["DETECTORS", "DetectorModel", "build_detector"]

# the models import numpy: re-exported on first access (the registry stays light)
__getattr__ = lazy_exports(__name__, {"DetectorModel": "base"})

#: detector models by name (the ``detector`` config key / ``--detector`` option)
DETECTORS = Registry("detector model", "detector")
DETECTORS.add("linear", "spslidar.detectors.linear:LinearDetector", "linear counter",
              "the paper's linear Poisson counter, no dead time (default)")


def build_detector(name: str, **options) -> DetectorModel:
    """The detector model registered under ``name``, built with ``options``."""
    return DETECTORS.load(name)(**options)
