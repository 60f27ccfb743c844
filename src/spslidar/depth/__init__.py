"""Depth estimation from the reconstructed range slices (equations 2-3): the registry of estimators.

``ESTIMATORS.load(name)()`` is an estimator; ``estimate.estimate(slices, ctx)`` returns a
:class:`DepthEstimate` (depth, confidence, peak, low-confidence mask). ``argmax`` is the
paper's ML estimator; ``censor`` (fast) and ``mrf`` (best) use the image structure: each
pixel sees one surface and surfaces are piecewise smooth in depth.
"""

from ..registry import Registry, lazy_exports

__all__ = ["ESTIMATORS", "ArgmaxDepth", "DepthContext", "DepthEstimate", "DepthEstimator",
           "ml_depth"]

# the estimators import numpy: re-exported on first access (the registry stays light)
__getattr__ = lazy_exports(__name__, {
    "ArgmaxDepth": "argmax", "ml_depth": "argmax", "DepthContext": "base",
    "DepthEstimate": "base", "DepthEstimator": "base"})

#: depth estimators by name (the ``depth`` config key / ``--depth`` option); ``slice_bytes``:
#: bytes per entry of the ``(Q, n_lags)`` slice block at the depth stage, the estimator's
#: working set (traced: argmax 8-10, censor 29-35, the MRF family 52, at 128-256 px and 61-200
#: slices) plus the slices and cube alive beside it, for the memory estimate
#: (:func:`spslidar.pipeline.budget.estimate_budget`); ``slice_seconds``: seconds per entry of
#: that block, for the time estimate (measured 2026-11-28, 64x64, a 0-50 m gate of 3 337
#: slices, 2-core machine: argmax 0.059 us, censor 0.078, mrf 0.297, guarded 0.337, evidence
#: 0.319; taken with about 1.4 times margin)
ESTIMATORS = Registry("depth estimator", "depth")
ESTIMATORS.add("argmax", "spslidar.depth.argmax:ArgmaxDepth", "ML argmax",
               "the paper's ML estimator: each pixel's tallest slice (eq. 2-3)",
               slice_bytes=20, slice_seconds=8e-8)
ESTIMATORS.add("censor", "spslidar.depth.censor:CensorDepth", "censor + recover",
               "fast: argmax, then pixels that fit no neighbour and have an ambiguous return "
               "are re-estimated near their neighbours' depths (Shin et al. 2015)",
               slice_bytes=40, slice_seconds=1.1e-7)
ESTIMATORS.add("evidence", "spslidar.depth.evidence:EvidenceDepth", "evidence-tested MRF",
               "MRF labelling that overrides a pixel's own tallest slice only where the data "
               "give it no support (a strong return, a thin line of neighbours at the same "
               "depth, or a cluster of returns in front of the MRF's surface keep it), plus a "
               "second surface per pixel; loses less than mrf where mrf loses to argmax, but "
               "gives back part of mrf's gain where noise spikes are dense",
               slice_bytes=70, slice_seconds=4.5e-7)
ESTIMATORS.add("guarded", "spslidar.depth.guarded:GuardedDepth", "guarded MRF",
               "MRF labelling that never overrides a pixel's own significant return (an "
               "evidence test against the block's noise maxima), plus a second surface per "
               "pixel where the profile holds two significant returns",
               slice_bytes=70, slice_seconds=4.5e-7)
ESTIMATORS.add("mrf", "spslidar.depth.mrf:MRFDepth", "MRF (loopy BP)",
               "the default: each pixel's range slice by a truncated-linear Markov random "
               "field over the image, solved by loopy belief propagation, keeping the argmax "
               "of pixels whose returns in front of its surface line up (poles, wires: "
               "spslidar.depth.lines) and discounting the per-slice TV's halo around bright "
               "regions (spslidar.depth.halo); best or tied on 17 of the 18 built-in cases "
               "of benchmarks/depth_quality.py",
               slice_bytes=70, slice_seconds=4.5e-7)


def __dir__() -> list[str]:
    # the lazy names too, so dir() and a REPL's completion list them (an audit of 2026-11-30)
    return sorted(set(globals()) | set(__all__))
