"""Censor-and-recover depth: find the pixels whose argmax is an ambiguous outlier among its
neighbours, then re-estimate them near the depths their reliable neighbours propose.

After Shin et al. (2015): a pixel's first estimate is its own ML (argmax) depth; a
rank-ordered absolute difference (ROAD) statistic marks it unreliable when it agrees with
none of its neighbourhood; an unreliable pixel's profile is then searched only near the
depths its reliable neighbours propose (Shin et al. censor the photon detections far from
the neighbourhood's depth and redo the ML estimate on the rest). Three changes make this fit
a reconstructed profile and scenes with slanted surfaces and thin structures:

* the ROAD statistic (:func:`road_linear`) compares the pixel with the **linear prediction**
  of each of its four opposite-neighbour pairs (vertical, horizontal, two diagonals),
  ``|k - (k_a + k_b) / 2|``, and keeps the smallest. It is zero on any plane, however steep
  (a receding floor), on both sides of a straight depth edge and along one-pixel poles (the
  pair along the pole predicts it), and large for an isolated wrong peak.
* only an **ambiguous** outlier is censored: one whose return the largest noise spike of its
  own profile nearly matches (a weak return on a textured surface that stands clear of its
  noise is kept, however much its neighbours differ).
* the candidates for a censored pixel (its current depth, its reliable neighbours' depths and
  the pairs' predictions) are scored by the evidence of its own profile near each plus a
  vote per agreeing neighbour (one round of iterated conditional modes); the pixel takes the
  tallest slice near the winner. Later passes revisit only the pixels censored at first, so
  a thin structure is never eroded from its end.

Everything is a handful of vectorised passes over the ``(Q, K)`` block (10-50 ms at
64 x 64).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import maximum_filter1d

from .base import DepthContext, DepthEstimate, DepthEstimator, option
from .profile import (
    grid_shape,
    index_to_depth,
    no_return,
    noise_scale,
    pulse_filter,
    refine_subbin,
    shift2d,
)

__all__ = ["CensorDepth", "road_linear"]

#: the four opposite-neighbour pairs (dy, dx) and (-dy, -dx)
_PAIRS = ((1, 0), (0, 1), (1, 1), (1, -1))
#: the eight neighbours
_NEIGHBOURS = tuple((dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx)


def road_linear(label: np.ndarray, reliable: np.ndarray | None = None,
                n_smallest: int = 1) -> np.ndarray:
    """Linear-prediction ROAD statistic of a label (depth-index) image.

    For each of the four opposite-neighbour pairs ``(a, b)`` of a pixel the residual is
    ``|k - (k_a + k_b) / 2|``; the statistic is the sum of the ``n_smallest`` smallest
    residuals over the pairs whose both members exist (and are ``reliable``). Where a pair is
    missing (the image's border, holes in ``reliable``), the residuals of the linear
    extrapolations ``2 k_a - k_aa`` from the neighbours ``a`` and ``aa`` one and two steps
    away in each of the eight directions join those of the pairs there are; a pixel with
    neither gets ``inf``.

    With ``n_smallest = 1`` (default) the statistic is 0 on any plane, on both sides of a
    straight depth edge and along a one-pixel line (the pair along the line predicts it):
    only a pixel that continues no direction of its neighbourhood is an outlier.

    Parameters
    ----------
    label : ndarray, shape (N1, N2)
        Depth index (slice) per pixel.
    reliable : ndarray of bool, shape (N1, N2), optional
        Only these pixels serve as neighbours (default: all).
    n_smallest : int
        Residuals summed.

    Returns
    -------
    ndarray, shape (N1, N2)
        The statistic, in slices.

    References
    ----------
    R. Garnett, T. Huegerich, C. Chui and W. He, "A universal noise removal algorithm with
    an impulse detector", IEEE Trans. Image Process. 14(11), 1747-1754 (2005) (ROAD).
    """
    lab = np.asarray(label, dtype=np.float64)
    ok = np.ones(lab.shape, bool) if reliable is None else np.asarray(reliable, bool)
    src = np.where(ok, lab, np.nan)

    def smallest(res: list[np.ndarray]) -> np.ndarray:
        r = np.sort(np.stack(res), axis=0)  # NaN (missing) sorts last
        enough = np.sum(np.isfinite(r), axis=0) >= n_smallest
        return np.where(enough, np.sum(r[:n_smallest], axis=0), np.nan)

    pairs = [np.abs(lab - 0.5 * (shift2d(src, dy, dx) + shift2d(src, -dy, -dx)))
             for dy, dx in _PAIRS]
    road = smallest(pairs)
    incomplete = np.sum([np.isfinite(r) for r in pairs], axis=0) < len(pairs)
    if incomplete.any():
        # where a pair is missing (the border, holes) the extrapolations stand beside the
        # pairs there are: along the border a straight edge's own pair is missing, and the
        # pair across it alone read 10 slices on a noiseless step (confidence 0.19, an audit)
        sides = [np.abs(lab - (2 * shift2d(src, dy, dx) - shift2d(src, 2 * dy, 2 * dx)))
                 for dy, dx in _NEIGHBOURS]
        road = np.where(incomplete, smallest(pairs + sides), road)
    return np.where(np.isnan(road), np.inf, road)


class CensorDepth(DepthEstimator):
    """Shin-style censoring of ambiguous outlier pixels and their re-estimation near the depths
    their reliable neighbours propose.

    Parameters
    ----------
    road_tol : float
        A pixel is censored when its linear ROAD statistic (:func:`road_linear`) exceeds this
        many slices ...
    gap : float
        ... and its return is ambiguous: the tallest evidence of its profile exceeds the
        tallest outside +-``window`` slices of it by less than this many noise scales.
    vote : float
        Evidence (noise scales) each agreeing reliable 8-neighbour adds to a candidate depth.
    window : int
        Half width (slices) of the window around a candidate depth.
    passes : int
        Censor / recover rounds; pixels recovered in one round serve as neighbours in the
        next.
    subbin : bool or None
        Place the return below the chosen slice (:func:`~.profile.refine_subbin`; ``None``:
        follow ``ctx.subbin``).
    low_confidence : float
        Confidence below which a pixel is flagged.

    Notes
    -----
    The evidence is the pulse-matched profile (:func:`~spslidar.depth.profile.pulse_filter`)
    in units of its noise scale (:func:`~spslidar.depth.profile.noise_scale`). The gap test
    makes the censoring depend on the number of slices: a weak return that stands clear of
    the noise of its own profile is kept even where its neighbours disagree (a textured
    surface), while one that the largest of many noise spikes nearly matches is re-estimated.

    Confidence: ``min(1, gap_k / (2 gap)) * exp(-road / (2 road_tol))`` with ``gap_k`` the gap
    of the chosen slice's evidence over the tallest outside its window and ``road`` the final
    linear ROAD statistic: a pixel is confident when its return stands clear of its profile's
    noise and its depth fits its neighbourhood.

    References
    ----------
    D. Shin, A. Kirmani, V. K. Goyal and J. H. Shapiro, "Photon-efficient computational 3-D
    and reflectivity imaging with single-photon detectors", IEEE Trans. Comput. Imaging 1(2),
    112-125 (2015), Sec. IV-B (censoring by ROAD, ML on the uncensored detections).
    J. Besag, "On the statistical analysis of dirty pictures", J. R. Stat. Soc. B 48(3),
    259-302 (1986) (iterated conditional modes).
    """

    name = "censor"
    LOW_CONFIDENCE = 0.3
    #: defaults: chosen on the motorcycle and camera scenes (see benchmarks/depth_quality.py)
    ROAD_TOL = 3.0
    GAP = 2.0
    VOTE = 2.0
    WINDOW = 2
    PASSES = 3

    def __init__(self, low_confidence: float | None = None, *, road_tol: float = ROAD_TOL,
                 gap: float = GAP, vote: float = VOTE, window: int = WINDOW,
                 passes: int = PASSES, subbin: bool | None = None):
        super().__init__(low_confidence)
        self.road_tol = option("road_tol", road_tol, open_lo=True)
        self.gap = option("gap", gap, open_lo=True)
        self.vote = option("vote", vote)
        self.window = option("window", window, integer=True)
        self.passes = option("passes", passes, integer=True)
        self.subbin = subbin

    def estimate(self, slices: np.ndarray, ctx: DepthContext) -> DepthEstimate:
        x = np.asarray(slices, dtype=np.float32)
        q, k = x.shape
        n1, n2 = grid_shape(ctx, q)
        y = pulse_filter(x)
        z = y / np.float32(noise_scale(y))
        # the evidence of each slice's window of +-window slices
        zwin = maximum_filter1d(z, 2 * self.window + 1, axis=1, mode="constant", cval=0.0)
        label = np.argmax(z, axis=1)
        lab = label.reshape(n1, n2)
        ambiguous = (self._gap(z, label) < self.gap).reshape(n1, n2)
        # censor once; later passes revisit only the censored pixels (whose neighbours may
        # have been recovered meanwhile), so a thin structure is never eroded from its end
        censored = (road_linear(lab) > self.road_tol) & ambiguous
        bad = censored
        for _ in range(self.passes):
            if not bad.any():
                break
            lab = _choose(lab, bad, _proposals(lab, ~bad), zwin.reshape(n1, n2, k),
                          z.reshape(n1, n2, k), self.window, self.vote)
            bad = censored & (road_linear(lab) > self.road_tol)
        label = lab.ravel()
        road = road_linear(lab).ravel()
        conf = (np.clip(self._gap(z, label) / (2 * self.gap), 0.0, 1.0)
                * np.exp(-road / (2 * self.road_tol)))
        subbin = ctx.subbin if self.subbin is None else self.subbin
        index = (refine_subbin(x, label, pulse_width=ctx.pulse_width, lags=ctx.lags)
                 if subbin and k >= 3 else label.astype(np.float64))
        depth = index_to_depth(index, ctx)
        missing = no_return(x.max(axis=1).astype(np.float64))
        depth[missing] = np.nan
        conf[missing] = 0.0
        info = {"censored_fraction": float(censored.mean()),
                "changed_from_argmax": float(np.mean(label != np.argmax(x, axis=1))),
                "road_tol": self.road_tol, "gap": self.gap, "vote": self.vote,
                "window": self.window}
        peak = x[np.arange(q), label].astype(np.float64)
        return DepthEstimate(depth, conf, peak, self._flag(depth, conf), info)

    def _gap(self, z: np.ndarray, label: np.ndarray) -> np.ndarray:
        """Evidence at ``label`` minus the tallest evidence outside +-window of it."""
        q, k = z.shape
        at = z[np.arange(q), label].astype(np.float64)
        far = np.abs(np.arange(k)[None, :] - label[:, None]) > self.window
        if not far.any():
            return at
        return at - np.max(np.where(far, z, 0.0), axis=1)


def _proposals(lab: np.ndarray, reliable: np.ndarray) -> np.ndarray:
    """Depth indices proposed by the reliable neighbours: their own (8) and the linear
    predictions of the reliable opposite pairs (4); NaN where a neighbour is missing."""
    src = np.where(reliable, lab.astype(np.float64), np.nan)
    props = [shift2d(src, dy, dx) for dy, dx in _NEIGHBOURS]
    props += [0.5 * (shift2d(src, dy, dx) + shift2d(src, -dy, -dx)) for dy, dx in _PAIRS]
    return np.stack(props)


def _choose(lab: np.ndarray, bad: np.ndarray, prop: np.ndarray, zwin: np.ndarray,
            z: np.ndarray, window: int, vote: float) -> np.ndarray:
    """Re-estimate the censored pixels.

    Each candidate depth (the pixel's current slice and its reliable neighbours'
    proposals) scores the evidence of the pixel's own profile in a window of +-``window``
    slices around it plus ``vote`` per reliable 8-neighbour whose depth lies in that window
    (one round of iterated conditional modes on a truncated Potts prior). The best candidate
    wins, and the pixel takes the tallest slice of its window (the candidate itself where
    the window is flat).
    """
    n1, n2, k = z.shape
    iy, ix = np.nonzero(bad)
    if iy.size == 0:
        return lab
    p = np.concatenate([lab[iy, ix][None].astype(np.float64), prop[:, iy, ix]])  # (P, B)
    have = np.isfinite(p)
    c = np.clip(np.rint(np.where(have, p, 0)), 0, k - 1).astype(np.int64)
    nb = prop[: len(_NEIGHBOURS), iy, ix]  # reliable neighbours' own depths, (8, B)
    agree = np.sum(np.abs(nb[None, :, :] - c[:, None, :]) <= window, axis=1)  # NaN -> False
    score = zwin[iy[None, :], ix[None, :], c] + vote * agree
    score = np.where(have, score, -np.inf)
    centre = c[np.argmax(score, axis=0), np.arange(iy.size)]
    offs = np.arange(-window, window + 1)
    cols = np.clip(centre[:, None] + offs[None, :], 0, k - 1)
    vals = z[iy[:, None], ix[:, None], cols]
    out = lab.copy()
    best = cols[np.arange(iy.size), np.argmax(vals, axis=1)]
    # a window without any evidence (after the non-negative solve, exact zeros) keeps the
    # chosen candidate itself (its first slice, two in front, was taken, an outside audit)
    flat = np.ptp(vals, axis=1) == 0
    out[iy, ix] = np.where(flat, centre, best)
    return out
