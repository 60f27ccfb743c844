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
chosen return's evidence, and that at least ``support`` of the pixel's 8 neighbours hold a
return within one slice of it, first or second (:func:`neighbour_support`): a wall seen
through a fence continues the wall beside it, while a noise peak that passes the test stands
alone; and that it holds at least ``halo`` of the largest evidence a neighbour holds within a
slice of it, else it is that neighbour's TV halo (:func:`second_halo`: a one-pixel post before
a wall). Its depth is :attr:`DepthEstimate.depth2` (NaN elsewhere).
"""

from __future__ import annotations

import numpy as np

from .base import DepthContext, DepthEstimate, option
from .mrf import MRFDepth, _pseudo_marginal
from .profile import grid_shape, index_to_depth, no_return, noise_maxima, refine_subbin

__all__ = ["GuardedDepth", "neighbour_support", "second_halo", "second_surface",
           "third_maxima"]


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
    quantile : float
        The quantile of the noise maxima that sets ``tau`` when it is None (default 0.99).

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
    # strictly above the threshold: a featureless profile (every slice equal, its third
    # maximum the same value) gave a second surface on every pixel
    ok = np.isfinite(zb) & peak & (zb > tau) & (zb >= ratio * first)
    return np.where(ok, b, -1)


def neighbour_support(first: np.ndarray, second: np.ndarray, shape: tuple[int, int],
                      tol: int = 1, need: int = 2) -> np.ndarray:
    """``second`` where at least ``need`` of a pixel's 8 neighbours hold a return (their
    ``first`` or their own ``second``) within ``tol`` slices of it, else -1.

    Parameters
    ----------
    first, second : ndarray of int, shape (Q,)
        Each pixel's chosen slice and its second return's slice (-1: none).
    shape : tuple of int
        Image shape ``(N1, N2)``, ``N1 N2 = Q``.
    tol, need : int

    Notes
    -----
    The significance test of :func:`second_surface` compares a peak with the noise maxima of
    all profiles, so a few percent of one-surface pixels pass it (the per-slice TV makes
    noise peaks of several pixels). Measured on the cached reconstructions of
    ``benchmarks/depth_quality.py`` (64 x 64, ``mrf`` labels, quantile 0.999), the share of
    pixels given a second surface in scenes that have none falls from 2.0-3.7 % to
    0.3-2.7 % (camera 3.1 -> 1.2 %, motorcycle 3.0 -> 0.6 %, procedural 0-16 at m_n 5 and
    25 % 1.5-3.7 -> 0.4-2.7 %), while on the fence (a mesh at 3 m in front of a wall at
    4 m) the share of mesh pixels whose wall is found within 5 cm stays 0.72 / 0.72 / 0.65
    (m_n 1 and 5 at 50 %, 10 at 25 %) and second surfaces off the mesh fall from
    0.1-1.3 % to 0.1-0.3 %. (Measured again on 2026-11-29, FISTA's default weight 0.45, the
    whole guarded estimator: procedural 0-16 0.9-4.7 %, camera 1.4 %, motorcycle 0.8 %; a
    neighbour's first return bled into a pixel by the TV passes this test too: README,
    Known limits.)
    """
    n1, n2 = shape
    f = np.asarray(first).reshape(n1, n2)
    s2 = np.asarray(second).reshape(n1, n2)
    far = -(10 ** 9)  # outside the image: no return
    pf, ps = np.pad(f, 1, constant_values=far), np.pad(s2, 1, constant_values=far)
    count = np.zeros((n1, n2), dtype=np.int64)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy == dx == 0:
                continue
            nf = pf[1 + dy:1 + dy + n1, 1 + dx:1 + dx + n2]
            ns = ps[1 + dy:1 + dy + n1, 1 + dx:1 + dx + n2]
            count += (np.abs(nf - s2) <= tol) | ((ns >= 0) & (np.abs(ns - s2) <= tol))
    return np.where((s2 >= 0) & (count >= need), s2, -1).ravel()


def second_halo(z: np.ndarray, second: np.ndarray, shape: tuple[int, int],
                share: float) -> np.ndarray:
    """Where a pixel's second return is a neighbour's halo: its evidence at its slice below
    ``share`` of the largest that any of its 8 neighbours holds within a slice of it.

    A one-pixel post in front of a wall holds the wall's halo in the wall's slice (the
    per-slice TV's leak from the wall around it, :mod:`.halo`), which passes the significance
    and support tests of a second surface (the neighbours are the wall); a pixel that truly
    sees the wall through a mesh holds about as much of it as the wall beside it. Measured on
    the built-in ``fence`` (32 and 64 px, m_n 5 and 10, 25 and 50 %, seed 0): its
    one-surface pixels' second returns read a median 0.42-0.50 of their neighbours', its
    mesh pixels' 0.90-0.95.

    Parameters
    ----------
    z : ndarray, shape (Q, K)
        Evidence.
    second : ndarray of int, shape (Q,)
        Each pixel's second return's slice, -1 where none.
    shape : tuple of int
        Image shape ``(N1, N2)``.
    share : float

    Returns
    -------
    ndarray of bool, shape (Q,)
        True where the second return is a halo (False where there is none).
    """
    from scipy.ndimage import maximum_filter1d

    q, k = z.shape
    n1, n2 = shape
    out = np.zeros(q, bool)
    has = np.flatnonzero(np.asarray(second) >= 0)
    if not has.size or k == 0:
        return out
    near = maximum_filter1d(np.asarray(z, dtype=np.float64), 3, axis=1, mode="nearest")
    s = np.asarray(second)[has]
    i, j = np.divmod(has, n2)
    top = np.full(has.size, -np.inf)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy == dx == 0:
                continue
            a, b = i + dy, j + dx
            ok = (a >= 0) & (a < n1) & (b >= 0) & (b < n2)
            top[ok] = np.maximum(top[ok], near[a[ok] * n2 + b[ok], s[ok]])
    own = np.asarray(z, dtype=np.float64)[has, s]
    out[has] = np.isfinite(top) & (top > 0) & (own < share * top)
    return out


class GuardedDepth(MRFDepth):
    """MRF depth that keeps every pixel's own significant return, and a second surface.

    Parameters
    ----------
    quantile : float
        The significance threshold ``tau`` is this quantile, over the pixels, of a profile's
        noise maximum (:func:`~.profile.noise_maxima`).
    scale : float
        ... times this factor.
    gap, ratio : float
        Of the second-surface test (:func:`second_surface`).
    support : int
        A second surface needs a return within one slice of it in at least this many of the
        pixel's 8 neighbours (:func:`neighbour_support`; 0: no such test).
    halo : float
        ... and at least this share of the largest evidence a neighbour holds within a slice
        of it, else it is a neighbour's halo (:func:`second_halo`; 0: no such test).
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
    #: neighbours that must hold a return near a second surface (:func:`neighbour_support`)
    SUPPORT = 2
    #: a second surface below this share of its neighbours' evidence is their halo
    #: (:func:`second_halo`; chosen 2026-12-03 on the fence at seed 0 and procedural 0-11)
    HALO = 0.5

    def __init__(self, low_confidence: float | None = None, *, quantile: float = QUANTILE,
                 scale: float = SCALE, gap: int = GAP, ratio: float = RATIO,
                 support: int = SUPPORT, halo: float = HALO, **mrf):
        super().__init__(low_confidence, **mrf)
        self.quantile, self.scale = option("quantile", quantile, 0, 1), option("scale", scale)
        self.gap = option("gap", gap, 1, integer=True)
        self.ratio = option("ratio", ratio, 0, 1)
        self.support = option("support (of the 8 neighbours)", support, 0, 8, integer=True)
        self.halo = option("halo", halo, 0, 1)

    def estimate(self, slices: np.ndarray, ctx: DepthContext) -> DepthEstimate:
        x = np.asarray(slices, dtype=np.float32)
        q, k = x.shape
        n1, n2 = grid_shape(ctx, q)
        rows = np.arange(q)
        peak = x.max(axis=1).astype(np.float64)
        z = self.evidence(x)
        smooth, belief, found = self.labelling(x, z, (n1, n2))
        own, keep, extra = self.guard(x, z, smooth, (n1, n2))
        label = np.where(keep, own, smooth)
        conf = _pseudo_marginal(belief, label)
        guarded = keep & (own != smooth)
        subbin = ctx.subbin if self.subbin is None else self.subbin
        sub = dict(pulse_width=ctx.pulse_width, lags=ctx.lags)
        index = (refine_subbin(x, label, **sub) if subbin and k >= 3
                 else label.astype(np.float64))
        depth = index_to_depth(index, ctx)
        second = second_surface(z, label, None, self.gap, self.ratio, self.quantile)
        if self.support > 0:
            second = neighbour_support(label, second, (n1, n2), need=self.support)
        if self.halo > 0:
            second = np.where(second_halo(z, second, (n1, n2), self.halo), -1, second)
        two = second >= 0
        index2 = second.astype(np.float64)
        if subbin and k >= 3 and two.any():  # (the noise read off the second returns alone)
            index2[two] = refine_subbin(x[two], second[two], **sub)
        depth2 = np.where(two, index_to_depth(np.where(two, index2, 0.0), ctx), np.nan)
        missing = no_return(peak)
        depth[missing] = np.nan
        depth2[missing] = np.nan
        conf[missing] = 0.0
        strength = x[rows, label].astype(np.float64)
        info = {**found, **extra, "kept_by_guard": float(np.mean(guarded)),
                "changed_from_argmax": float(np.mean(label != np.argmax(x, axis=1))),
                "two_surface_fraction": float(np.mean(np.isfinite(depth2))),
                "smoothness": self.smoothness, "quantile": self.quantile}
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
