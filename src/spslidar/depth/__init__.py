"""Depth estimation from the reconstructed range slices (eq. 2-3): the registry of estimators.

``ESTIMATORS.load(name)()`` is an estimator; ``estimate.estimate(slices, ctx)`` returns a
:class:`DepthEstimate` (depth, confidence, peak, low-confidence mask). ``argmax`` is the
paper's ML estimator.
"""

from ..registry import Registry
from .argmax import ArgmaxDepth, ml_depth
from .base import DepthContext, DepthEstimate, DepthEstimator

__all__ = ["ESTIMATORS", "ArgmaxDepth", "DepthContext", "DepthEstimate", "DepthEstimator",
           "ml_depth"]

#: depth estimators by name (the ``depth`` config key / ``--depth`` option)
ESTIMATORS = Registry("depth estimator", "depth")
ESTIMATORS.add("argmax", "spslidar.depth.argmax:ArgmaxDepth", "ML argmax",
               "the paper's ML estimator: each pixel's tallest slice (eq. 2-3)")
