"""Guarded MRF depth: the MRF labelling (:mod:`.mrf`) may override a pixel's own tallest slice
only where that slice is not significant, and a second surface is reported where the profile
holds a second significant return.

The MRF (truncated-linear smoothness, loopy BP) fixes the pixels whose tallest slice is a
noise spike, but it also overrides thin structures whose evidence is real (a one-pixel pole
pays the edge cost on both sides, and the per-slice TV of the reconstruction has already
weakened it), replacing them with the surface behind. The guard is an evidence test on each
pixel's own profile before its argmax may be overridden:

* the **null distribution** of a profile's noise maximum is read off the block itself: for
  each pixel, the largest evidence outside its tallest return (+-2 slices); its ``quantile``
  over the pixels (the 99.9th percentile by default) is the threshold ``tau``;
* a pixel whose tallest evidence reaches ``tau`` keeps it (a return that rarely any profile's
  noise reaches); a weaker one takes the MRF's label.

A **second surface** is a second return of the pixel's profile: the tallest evidence outside
+-``gap`` slices of the chosen one, a local maximum, that reaches the same quantile of the
noise maxima left once both candidates are removed from every profile (so that a fence's
second surfaces on half the pixels do not raise the threshold) and at least ``ratio`` of the
chosen return's evidence. Its depth is :attr:`DepthEstimate.depth2` (NaN
elsewhere).
"""

from __future__ import annotations

import numpy as np

from .base import DepthContext, DepthEstimate
from .mrf import MRFDepth, _pseudo_marginal, auto_truncation, min_sum_bp
from .profile import grid_shape, index_to_depth, no_return, refine_subbin

__all__ = ["GuardedDepth", "noise_maxima", "second_surface", "third_maxima"]


def noise_maxima(z: np.ndarray, exclude: int = 2) -> np.ndarray:
    """Per pixel, the largest evidence outside +-``exclude`` slices of its tallest slice: a
    sample of the noise maximum of a profile (the return itself left out)."""
    q, k = z.shape
    idx = np.argmax(z, axis=1)
    far = np.abs(np.arange(k)[None, :] - idx[:, None]) > exclude
    return np.max(np.where(far, z, 0.0), axis=1) if far.any() else np.zeros(q)


def third_maxima(z: np.ndarray, label: np.ndarray, second: np.ndarray, gap: int = 3
                 ) -> np.ndarray:
    """Per pixel, the largest evidence more than ``gap`` slices from both its first return
    (``label``) and its second candidate (``second``): a sample of a profile's noise maximum
    that a real second surface does not inflate."""
    k = z.shape[1]
    cols = np.arange(k)[None, :]
    far = (np.abs(cols - label[:, None]) > gap) & (np.abs(cols - second[:, None]) > gap)
    return np.max(np.where(far, z, 0.0), axis=1)


def second_surface(z: np.ndarray, label: np.ndarray, tau: float | None = None, gap: int = 3,
                   ratio: float = 0.25, quantile: float = 0.99) -> np.ndarray:
    """Slice of each pixel's second return, -1 where the profile supports one surface.

    Parameters
    ----------
    z : ndarray, shape (Q, K)
        Evidence (the pulse-matched profile in noise units).
    label : ndarray of int, shape (Q,)
        The chosen (first) return's slice.
    tau : float or None
        Significance threshold; None: the ``quantile`` over the pixels of the noise maximum
        of a profile left once both candidates are removed (:func:`third_maxima`), so that
        second surfaces on many pixels (a fence) do not raise it.
    gap : int
        The second return lies more than this many slices from the first.
    ratio : float
        ... and holds at least this share of its evidence.

    Returns
    -------
    ndarray of int, shape (Q,)
    """
    q, k = z.shape
    rows = np.arange(q)
    far = np.abs(np.arange(k)[None, :] - label[:, None]) > gap
    masked = np.where(far, z, -np.inf)
    b = np.argmax(masked, axis=1)
    zb = masked[rows, b]
    left = z[rows, np.clip(b - 1, 0, k - 1)]
    right = z[rows, np.clip(b + 1, 0, k - 1)]
    peak = ((b == 0) | (zb >= left)) & ((b == k - 1) | (zb >= right))
    first = z[rows, label]
    if tau is None:
        tau = float(np.quantile(third_maxima(z, label, b, gap), quantile)) if q else np.inf
    ok = np.isfinite(zb) & peak & (zb >= tau) & (zb >= ratio * first)
    return np.where(ok, b, -1)


class GuardedDepth(MRFDepth):
    """MRF depth that keeps every pixel's own significant return, and a second surface.

    Parameters
    ----------
    quantile : float
        The significance threshold ``tau`` is this quantile, over the pixels, of a profile's
        noise maximum (:func:`noise_maxima`).
    scale : float
        ... times this factor.
    gap, ratio : float
        Of the second-surface test (:func:`second_surface`).
    smoothness, truncation, iterations, subbin, low_confidence
        As :class:`~spslidar.depth.mrf.MRFDepth`.

    Notes
    -----
    The argmax is kept where its evidence reaches ``tau``; elsewhere the MRF's label is taken.
    Confidence is the MRF's pseudo-marginal of the chosen slice: a pixel kept by the guard
    against its neighbours' agreement is low-confidence.
    """

    name = "guarded"
    #: chosen on procedural scenes 0-1 x m_n 5, 10 x 25, 50 % (benchmarks/depth_quality.py)
    QUANTILE = 0.999
    SCALE = 1.0
    GAP = 3
    RATIO = 0.25

    def __init__(self, low_confidence: float | None = None, *, quantile: float = QUANTILE,
                 scale: float = SCALE, gap: int = GAP, ratio: float = RATIO, **mrf):
        super().__init__(low_confidence, **mrf)
        if not 0.0 <= quantile <= 1.0 or scale < 0 or gap < 1 or not 0.0 <= ratio <= 1.0:
            raise ValueError("quantile in [0, 1], scale >= 0, gap >= 1, ratio in [0, 1]")
        self.quantile, self.scale = float(quantile), float(scale)
        self.gap, self.ratio = int(gap), float(ratio)

    def estimate(self, slices: np.ndarray, ctx: DepthContext) -> DepthEstimate:
        x = np.asarray(slices, dtype=np.float32)
        q, k = x.shape
        n1, n2 = grid_shape(ctx, q)
        rows = np.arange(q)
        peak = x.max(axis=1).astype(np.float64)
        z = self.evidence(x)
        cap = self.truncation if self.truncation is not None else auto_truncation(z)
        cost = np.ascontiguousarray(-z.T).reshape(k, n1, n2)
        belief, sweeps = min_sum_bp(cost, self.smoothness, cap, self.iterations)
        belief = belief.reshape(k, q).T
        smooth = np.argmin(belief, axis=1)
        own, keep, extra = self.guard(x, z, smooth, (n1, n2))
        label = np.where(keep, own, smooth)
        conf = _pseudo_marginal(belief, label)
        guarded = keep & (own != smooth)
        subbin = ctx.subbin if self.subbin is None else self.subbin
        index = refine_subbin(x, label) if subbin and k >= 3 else label.astype(np.float64)
        depth = index_to_depth(index, ctx)
        second = second_surface(z, label, None, self.gap, self.ratio, self.quantile)
        two = second >= 0
        index2 = (refine_subbin(x, np.where(two, second, 0)) if subbin and k >= 3
                  else second.astype(np.float64))
        depth2 = np.where(two, index_to_depth(np.where(two, index2, 0.0), ctx), np.nan)
        missing = no_return(peak)
        depth[missing] = np.nan
        depth2[missing] = np.nan
        conf[missing] = 0.0
        strength = x[rows, label].astype(np.float64)
        info = {"sweeps": sweeps, **extra, "kept_by_guard": float(np.mean(guarded)),
                "changed_from_argmax": float(np.mean(label != np.argmax(x, axis=1))),
                "two_surface_fraction": float(np.mean(np.isfinite(depth2))),
                "smoothness": self.smoothness, "truncation": cap, "quantile": self.quantile}
        return DepthEstimate(depth, conf, strength, self._flag(depth, conf), info, depth2)

    def guard(self, x: np.ndarray, z: np.ndarray, smooth: np.ndarray,
              shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, dict]:
        """Each pixel's own slice, where it is kept against the MRF's label ``smooth``, and
        numbers for ``info``: here the evidence's argmax, kept where it reaches ``tau``."""
        q = z.shape[0]
        own = np.argmax(z, axis=1)
        null = noise_maxima(z)
        tau = self.scale * float(np.quantile(null, self.quantile)) if q else np.inf
        keep = z[np.arange(q), own].astype(np.float64) >= tau
        return own, keep, {"tau": tau}
