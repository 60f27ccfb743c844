"""Per-pixel profile helpers shared by the spatial depth estimators.

The reconstructed block ``slices`` of shape ``(Q, K)`` holds, for each pixel, a profile over
the gated delays. These helpers give the scale of its noise, filter it with the return's
footprint, turn (fractional) slice indices into depth, refine a chosen slice below one bin and
shift label images, without ever looking at a ground truth.
"""

from __future__ import annotations

import functools

import numpy as np

from ..arrays import positive_number
from ..errors import ConfigError
from ..forward import lag_to_depth
from .base import DepthContext

__all__ = ["ADJACENT_TOL", "NOISE_BESIDE_MIN", "NOISE_ONLY_MARGIN", "NOISE_ONLY_MIN_SLICES",
           "NOISE_VERDICT_PIXELS", "SUBBIN_CLEAR", "SUBBIN_FLOOR", "SUBBIN_QUANTILE",
           "effective_slices", "grid_shape", "index_to_depth", "no_return", "noise_maxima",
           "noise_only_ratio", "noise_scale", "noise_verdict", "peak_to_noise", "pulse_filter",
           "refine_subbin", "shift2d", "subbin_noise", "subbin_offset", "subbin_shift",
           "verdict_and_room"]

#: An image is said to be noise where the 90th percentile of :func:`peak_to_noise` is below
#: this many times what non-negative white noise gives at as many effective slices
#: (:func:`noise_only_ratio` of :func:`effective_slices`). Through the pipeline, noise alone (a
#: black scene, a range gate that misses the scene, with and without a calibrated IRF, 12-20 %
#: of the default signal; 16x16 to 64x64, 22-208 slices) gives 1.11-1.34 times it on FISTA's
#: 0.3 weight, 1.07-1.35 on its default 0.45 (the uncalibrated cases measured again); the
#: built-in and procedural scenes at m_n 1-10 (32x32) 3.9-22 times it (p90 5.1-36), the
#: camera at m_s = 1, m_n = 10 (RMSE 0.087 m) 1.84 times; it fires on the motorcycle at
#: m_s <= 1 (RMSE 0.64-0.80 m) and the camera at 0.6 (0.18 m), not at 1.0 (0.087 m); measured
#: again on 2026-12-02 (64x64 seed 0) at 0.4 (0.18 m), not at 0.5 (0.13 m).
NOISE_ONLY_MARGIN = 1.4
#: Fewer slices leave too few beside the peak to tell a return from noise.
NOISE_ONLY_MIN_SLICES = 16
#: Independent slices a verdict needs beside a return's own (its peak and ``exclude`` either
#: side): a calibrated 10-bin response through a 28-slice gate left 3, its white-noise
#: reference read 6.30 there and a good map (5.15, its noise maxima the response's own wings
#: at every gate) was said to be mostly noise (an audit of 2026-11-28; 11 are left at the
#: ideal pulse's 16 slices).
NOISE_BESIDE_MIN = 8


#: :func:`noise_scale` of a noiseless block (zero beside every peak), as a share of its
#: largest value
NOISELESS_SCALE = 1e-6


def noise_scale(slices: np.ndarray, exclude: int = 2) -> float:
    """RMS of the profiles away from each pixel's tallest slice: the noise floor's scale.

    Parameters
    ----------
    slices : ndarray, shape (Q, K)
    exclude : int
        Slices within this many bins of each pixel's argmax are left out (the return).

    Returns
    -------
    float
        The RMS over all remaining entries; ``NOISELESS_SCALE`` times the block's
        largest value where they are all 0 (a noiseless block); the RMS of the whole block
        when nothing remains (a block of 2 * exclude + 1 slices or fewer); never 0 for a
        non-zero block.

    Notes
    -----
    The reconstruction's per-slice TV and non-negativity make the off-peak values sparse
    (about a third are exactly 0) with rare spikes, so their RMS (not a median absolute
    deviation, which the zeros pull towards 0) is the scale of the spikes that compete with a
    weak return. On the built-in scenes the 99th percentile of the peaks is 35-100 times this
    scale, falling with the noise level ``m_n``.
    """
    x = np.asarray(slices, dtype=np.float64)
    q, k = x.shape
    if x.size == 0:
        return 1.0
    idx = np.argmax(x, axis=1)
    far = np.abs(np.arange(k)[None, :] - idx[:, None]) > exclude
    sel = x[far] if far.any() else x.ravel()
    rms = float(np.sqrt(np.mean(sel**2)))
    if not rms > 0 and far.any():
        # a noiseless block (nothing beside any peak): every return stands out, so the scale
        # is far below the data's (it was the whole block's RMS, which made a pole at a
        # tenth of the wall one noise unit, and the MRF gave it the wall, an outside audit)
        rms = NOISELESS_SCALE * float(np.max(np.abs(x)))
    if not rms > 0:
        rms = float(np.sqrt(np.mean(x**2)))
    return rms if rms > 0 else 1.0


def pulse_filter(slices: np.ndarray) -> np.ndarray:
    """Each profile filtered along the range axis by the taps ``[1/2, 1, 1/2]``.

    A return of width ``w <= 1`` bin at a fractional delay falls in one bin or is split
    between two adjacent ones; averaged over the fractional offset, its expected footprint
    on the bins is this triangle, so the filter is the matched filter of a return of unknown
    sub-bin position: it adds a split return's two halves (gaining up to ``sqrt 2`` in SNR
    for weak returns) while leaving the position of a single-bin return unchanged.
    The edges are zero-padded. The result has the dtype of ``slices`` (float32 stays).
    """
    x = np.asarray(slices)
    if not np.issubdtype(x.dtype, np.floating):
        x = x.astype(np.float64)
    y = x.copy()
    if x.shape[-1] > 1:
        y[..., 1:] += 0.5 * x[..., :-1]
        y[..., :-1] += 0.5 * x[..., 1:]
    return y


def index_to_depth(index: np.ndarray, ctx: DepthContext) -> np.ndarray:
    """Depth (m) of a (fractional) slice index: eq. (3) with the leading-edge offset of
    :func:`spslidar.depth.argmax.ml_depth` (``tau = lag + 1/2 - w/2``).

    Integer indices give exactly what the argmax estimator gives for the same slice; a
    fractional index is interpolated linearly between the lags.
    """
    lags = np.asarray(ctx.lags, dtype=np.float64)
    index = np.asarray(index, dtype=np.float64)
    pos = np.interp(index, np.arange(lags.size), lags)
    return lag_to_depth(pos, ctx.bin_width, ctx.pulse_width)


#: points of the grid of the pulse's leading edge over which :func:`subbin_offset` takes its
#: posterior mean (its spacing, 1.5 / 240 of a bin at the default half-bit pulse, bounds the
#: noiseless error at 0.003 bin, 0.05 mm at 10 GHz)
SUBBIN_GRID = 241
#: pixels whose peak reaches this share of the 99th percentile of the peaks give
#: :func:`subbin_noise` its sample (a noise peak's neighbours are as high as itself)
SUBBIN_CLEAR = 0.25
#: the percentile of the lower neighbour's share of the peak that :func:`subbin_noise` takes
SUBBIN_QUANTILE = 95.0
#: the least noise :func:`subbin_offset` takes, as a share of the peak (a noiseless block)
SUBBIN_FLOOR = 1e-6
#: two delays (in bins) are adjacent where they differ by one to within this
ADJACENT_TOL = 1e-6


def _box_shares(delta: np.ndarray, width: float) -> np.ndarray:
    """Shares of a pulse ``[delta, delta + width)`` in the bins ``-1, 0, 1`` (``(G, 3)``)."""
    j = np.arange(-1, 2, dtype=np.float64)
    d = np.asarray(delta, np.float64)[:, None]
    return np.clip(np.minimum(d + width, j + 1) - np.maximum(d, j), 0.0, None) / width


def subbin_noise(values: np.ndarray, present: np.ndarray) -> float:
    """The noise on each peak's neighbours, read off the lower of the two.

    Whether a return lies in one bin or straddles two, the lower of its bin's two neighbours
    holds no share of it: what it holds is the noise beside a return, with the
    reconstruction's leaks from surfaces nearby. Taken relative to the peak (its 95th
    percentile over the pixels with a clear return, :data:`SUBBIN_CLEAR`: the leaks are
    heavy-tailed, and where the scale read a neighbour's leak as a straddle the pixel moved
    by a quarter bin) and scaled by each pixel's own peak, it covers both the
    reconstruction's residual, which grows with the return (beside a ramp's one-bin returns
    at m_n 1-3, 5-8 % of the peak against an RMS of 2-2.7 % away from the peaks), and white
    noise on exact correlations. Chosen on 32x32 ramps (m_n 0 / 1 / 3), steps and the
    camera (seed 3) and single profiles under white noise, against the ratio's RMS, its
    75th and 90th percentiles and 1 or 3 times :func:`noise_scale`.

    Parameters
    ----------
    values, present : ndarray, shape (Q, 3)
        As :func:`subbin_offset`'s.

    Returns
    -------
    float
        The noise's scale as a share of each pixel's peak (0 where no pixel has a positive
        peak and a neighbour; :func:`subbin_offset` floors it at :data:`SUBBIN_FLOOR`).
    """
    y = np.asarray(values, np.float64)
    y = np.where(np.asarray(present, bool) & np.isfinite(y), y, np.nan)
    peak = y[:, 1]
    low = np.fmin(y[:, 0], y[:, 2])  # NaN only where neither neighbour is there
    ok = np.isfinite(low) & (peak > 0)  # (a NaN peak is not > 0)
    if not ok.any():
        return 0.0
    clear = ok & (peak >= SUBBIN_CLEAR * np.percentile(peak[ok], 99))
    return float(np.percentile(np.abs(low[clear]) / peak[clear], SUBBIN_QUANTILE))


def subbin_offset(values: np.ndarray, present: np.ndarray, pulse_width: float,
                  sigma: np.ndarray | float | None = None, block: int = 16384) -> np.ndarray:
    """Sub-bin offset of each return from its bin's integer reading, from the bin and its two
    neighbours, with the pulse's known shape.

    A pulse of width ``w < 1`` bin whose leading edge lies in ``[b, b + 1 - w]`` falls wholly
    in bin ``b``: the counts cannot tell where (the integer reading, the middle of that
    interval, is then the best guess); beyond it the pulse straddles two bins and their split
    fixes its position exactly (``delta = b + 1 - w + w r``, ``r`` the later bin's share). This
    is the posterior mean of the leading edge, uniform over every position that reaches bin
    ``b``, under Gaussian noise of scale ``sigma`` on the three values, the amplitude fitted
    (non-negative): the split where the neighbour stands clear of the noise, the middle where
    it does not, and a blend between. Written here: no library fits a binned box pulse; a
    three-bin centroid assumes a one-bin pulse and errs by up to a quarter bin at the default
    half-bit pulse in either region (an outside audit, 2026-11-30: +-0.25 bin, efficiency
    0.02-0.06 of the Cramer-Rao bound at 5 120 photons).

    Parameters
    ----------
    values : ndarray, shape (Q, 3)
        Each pixel's profile at the chosen bin's predecessor, itself and successor.
    present : ndarray of bool, shape (Q, 3)
        Which of them exist (a gate's edge, or a neighbour column that is not the adjacent
        delay, is left out, and so are the positions that would put a share there; so is a
        value that is not finite). A pixel whose middle value is missing or not positive
        keeps its bin (offset 0).
    pulse_width : float
        ``w`` in bins, ``0 < w < 1``.
    sigma : float, ndarray of shape (Q,), or None
        The noise's scale on the three values (``None``: :func:`subbin_noise`'s share of
        each pixel's peak). Never below :data:`SUBBIN_FLOOR` of the peak.
    block : int
        Pixels per step (memory ``block * SUBBIN_GRID`` doubles, four arrays).

    Returns
    -------
    ndarray, shape (Q,)
        Offset in bins: the fractional slice index is the chosen one plus this (0 for a
        return wholly in its bin, up to ``+- (1 + w) / 2`` at the ends).
    """
    w = float(pulse_width)
    delta = np.linspace(-w, 1.0, SUBBIN_GRID)
    h = _box_shares(delta, w)
    v = np.asarray(values, np.float64)
    present = np.asarray(present, dtype=bool) & np.isfinite(v)  # (NaN, inf: no evidence)
    peak = v[:, 1]
    good = present[:, 1] & (peak > 0)
    scale = np.where(good, peak, 1.0)[:, None]
    # in units of each pixel's peak, so that no scale of the data overflows (1e-300 and
    # 1e300 gave NaN: a review)
    rel = subbin_noise(v, present) if sigma is None else np.asarray(sigma, np.float64)
    sig = np.broadcast_to(rel, peak.shape) / (1.0 if sigma is None else scale[:, 0])
    sig = np.maximum(np.where(np.isfinite(sig), sig, 1.0), SUBBIN_FLOOR)
    y = np.where(present, v, 0.0) / scale
    m = present.astype(np.float64)
    q = y.shape[0]
    out = np.empty(q)
    for s in range(0, q, block):
        yb, mb = y[s:s + block], m[s:s + block]
        yh = yb @ h.T
        hh = mb @ (h * h).T
        a = np.clip(np.divide(yh, hh, out=np.zeros_like(yh), where=hh > 0), 0.0, None)
        inv = 1.0 / (2.0 * sig[s:s + block, None] ** 2)
        ll = (2.0 * a * yh - a * a * hh) * inv  # less the residual's constant ||y||^2
        # a position that puts a share in a neighbour not there is left out (any amplitude
        # fits the rest: a return at the gate's edge would be read as straddling it)
        ll[((1.0 - mb) @ (h > 0).T) > 0] = -np.inf
        ll -= ll.max(axis=1, keepdims=True)
        p = np.exp(ll)
        out[s:s + block] = (p @ delta) / p.sum(axis=1)
    out = out - (1.0 - w) / 2.0
    return np.where(good & np.isfinite(out), out, 0.0)  # (no positive peak: its own bin)


def subbin_shift(values: np.ndarray, present: np.ndarray, pulse_width: float | None = None,
                 sigma: np.ndarray | float | None = None) -> np.ndarray:
    """Each return's shift below a bin from its chosen slice and the ``h`` on each side
    (``values``, ``present``: ``(Q, 2 h + 1)``, centred on the chosen slice): with a pulse
    under one bin and ``h = 1``, :func:`subbin_offset`; otherwise the intensity-weighted
    mean offset of the slices present (a three-bin centroid at ``h = 1``; a value that is
    not finite weighs nothing). The one step of :func:`refine_subbin` and of the argmax's
    peaks (:func:`~spslidar.depth.argmax.depth_from_peaks`)."""
    v = np.asarray(values, np.float64)
    half = v.shape[1] // 2
    if pulse_width is not None and 0 < pulse_width < 1 and half == 1:
        return subbin_offset(v, present, pulse_width, sigma)
    offs = np.arange(-half, half + 1, dtype=np.float64)
    w = np.where(np.asarray(present, bool) & np.isfinite(v), np.clip(v, 0, None), 0.0)
    tot = w.sum(axis=1)
    return np.divide(w @ offs, tot, out=np.zeros(v.shape[0]), where=tot > 0)


def refine_subbin(slices: np.ndarray, label: np.ndarray, half: int = 1,
                  pulse_width: float | None = None, sigma: float | None = None,
                  lags: np.ndarray | None = None) -> np.ndarray:
    """Sub-bin position of each pixel's return around its chosen slice.

    With ``pulse_width`` below one bin (the simulator's default is half a bit), the posterior
    mean of :func:`subbin_offset` from the chosen slice and its two neighbours. Otherwise
    (and with ``pulse_width=None``) the intensity-weighted mean delay over the ``2 half + 1``
    slices centred on ``label``: Howland et al.'s depth-weighted-intensity over intensity
    ratio, taken locally around the chosen return so that noise elsewhere in the profile does
    not bias it; exact for a one-bin pulse, whose two bins' split is linear in its delay.

    Parameters
    ----------
    slices : ndarray, shape (Q, K)
    label : ndarray of int, shape (Q,)
        Chosen slice per pixel.
    half : int
        Half width of the centroid's window in slices.
    pulse_width : float or None
        The return pulse's width in bins (:class:`~spslidar.depth.base.DepthContext`).
    sigma : float, ndarray of shape (Q,), or None
        The noise's scale on each return's bins (``None``: :func:`subbin_noise`).
    lags : ndarray, shape (K,), or None
        The slices' delays in bins (``None``: consecutive); a neighbour that is not the
        adjacent delay is left out, by either method.

    Returns
    -------
    ndarray, shape (Q,)
        Fractional slice index (``label`` where the window holds no positive value).

    References
    ----------
    G. A. Howland, P. B. Dixon and J. C. Howell, "Photon-counting compressive sensing laser
    radar for 3D imaging", Appl. Opt. 50(31), 5917-5920 (2011); G. A. Howland, D. J. Lum,
    M. R. Ware and J. C. Howell, "Photon counting compressive depth mapping", Opt. Express
    21(20), 23822-23837 (2013).
    """
    x = np.asarray(slices, dtype=np.float64)
    q, k = x.shape
    label = np.asarray(label, dtype=np.int64)
    wide = 1 if pulse_width is not None and 0 < pulse_width < 1 else half
    offs = np.arange(-wide, wide + 1)
    cols = label[:, None] + offs[None, :]
    present = (cols >= 0) & (cols < k)
    cc = np.clip(cols, 0, k - 1)
    if lags is not None:  # (fractional lags, a calibrated instrument's, compared as reals)
        lg = np.asarray(lags, dtype=np.float64)
        present &= np.abs(lg[cc] - lg[label][:, None] - offs[None, :]) < ADJACENT_TOL
    return label + subbin_shift(x[np.arange(q)[:, None], cc], present, pulse_width, sigma)


def shift2d(img: np.ndarray, dy: int, dx: int, fill: float = np.nan) -> np.ndarray:
    """``out[i, j] = img[i + dy, j + dx]`` (``fill`` outside), for 2-D or (N, N, ...) arrays."""
    out = np.full(img.shape, fill, dtype=np.result_type(img.dtype, np.asarray(fill).dtype))
    n1, n2 = img.shape[:2]
    ys, yd = (slice(dy, n1), slice(0, n1 - dy)) if dy >= 0 else (slice(0, n1 + dy),
                                                                 slice(-dy, n1))
    xs, xd = (slice(dx, n2), slice(0, n2 - dx)) if dx >= 0 else (slice(0, n2 + dx),
                                                                 slice(-dx, n2))
    out[yd, xd] = img[ys, xs]
    return out


def grid_shape(ctx: DepthContext, q: int) -> tuple[int, int]:
    """The image shape ``ctx.shape``, checked against the ``q`` pixels of the slices."""
    n1, n2 = (int(v) for v in ctx.shape)
    if n1 * n2 != q:
        raise ConfigError(f"ctx.shape {ctx.shape} does not hold the {q} pixels of the slices: "
                         f"a spatial depth estimator needs the image shape")
    return n1, n2


def noise_maxima(z: np.ndarray, exclude: int = 2, centre: np.ndarray | None = None
                 ) -> np.ndarray:
    """Per pixel, the largest evidence outside +-``exclude`` slices of its tallest slice (or
    of ``centre``, a slice per pixel: the MRF's label in :mod:`.dots`): a sample of the noise
    maximum of a profile (the return itself left out); 0 where nothing is outside. In blocks
    of at most ``NOISE_BLOCK_ENTRIES`` entries (512 x 512 pixels of 142 slices were a
    300 MB copy at once)."""
    q, k = z.shape
    if k == 0:
        return np.zeros(q)
    idx = np.argmax(z, axis=1) if centre is None else np.asarray(centre)
    out = np.empty(q)
    step = block_rows(k)
    lags = np.arange(k)[None, :]
    for i in range(0, q, step):
        j = slice(i, i + step)
        far = np.abs(lags - idx[j, None]) > exclude
        out[j] = np.max(np.where(far, z[j], 0.0), axis=1)
    return out


#: the typical noise maximum where no profile holds any noise (every maximum 0): a spike of
#: twice it pays the four truncations (``auto_truncation``'s 1.0) of an isolated pixel
NO_NOISE_MAXIMUM = 2.0


def typical_noise_maximum(null: np.ndarray) -> float:
    """The block's typical noise maximum ``nu``: the median of :func:`noise_maxima` over the
    profiles that hold any noise (a positive maximum); :data:`NO_NOISE_MAXIMUM` where none
    does.

    Sparse profiles (a photon histogram at low flux, or a solve's cube of which most
    entries are exactly 0) leave most maxima at 0: their median was 0, and every level of
    ``nu`` with it, so an outside audit's 16-slice sparse noise kept 546 of 4 096 pixels as
    dots at ``6 nu`` (2026-12-02). On the solves' dense cubes every maximum is positive and
    this is their median, as before.
    """
    null = np.asarray(null, dtype=np.float64).ravel()
    held = null[null > 0]
    return float(np.median(held)) if held.size else NO_NOISE_MAXIMUM


#: entries (pixels x slices) of one block of :func:`_noise_stats` at most: 32 MB a float64
#: copy (65 536 pixels a block whatever the gate took 4 096 x 16 383 slices at once)
NOISE_BLOCK_ENTRIES = 2 ** 22


def block_rows(k: int, block: int | None = None) -> int:
    """Profiles of ``k`` slices a block holds: at most :data:`NOISE_BLOCK_ENTRIES` entries
    (and at most ``block`` profiles where given), one at least."""
    rows = NOISE_BLOCK_ENTRIES // max(int(k), 1)
    return max(1, rows if block is None else min(int(block), rows))


def _noise_stats(slices: np.ndarray, exclude: int = 2, corr_exclude: int = 3,
                 max_lag: int = 4, block: int = 65536) -> tuple[np.ndarray, float]:
    """One pass over the pulse-filtered profiles, ``block`` pixels at a time (and at most
    :data:`NOISE_BLOCK_ENTRIES` entries: bounds the temporary copy at 512x512 and at long
    gates): :func:`peak_to_noise` per pixel, and ``1 + 2 sum_{l=1..max_lag} rho_l``, the
    integrated autocorrelation along the delay of the profiles' noise (each slice farther
    than ``corr_exclude`` from its pixel's tallest one, less that pixel's mean there).
    """
    x = np.asarray(slices)
    q, k = x.shape
    step = block_rows(k, block)
    return _block_stats((x[i:i + step] for i in range(0, q, step)), q, k, exclude,
                        corr_exclude, max_lag)


def _block_stats(blocks, q: int, k: int, exclude: int, corr_exclude: int,
                 max_lag: int) -> tuple[np.ndarray, float]:
    """:func:`_noise_stats` over an iterable of ``(b, k)`` blocks of ``q`` profiles in all."""
    ratio = np.ones(q)
    num = np.zeros(max_lag + 1)
    start = 0
    for xb in blocks:
        z = pulse_filter(xb).astype(np.float64)
        nb = z.shape[0]
        if k > 2 * exclude + 1:  # room for a noise maximum beside the peak
            peak, null = np.max(z, axis=1), noise_maxima(z, exclude)
            r = np.ones(peak.size)
            pos = peak > 0
            r[pos] = np.divide(peak[pos], null[pos], out=np.full(int(pos.sum()), np.inf),
                               where=null[pos] > 0)
            ratio[start:start + nb] = r
        far = np.abs(np.arange(k)[None, :] - np.argmax(z, axis=1)[:, None]) > corr_exclude
        n = np.maximum(far.sum(axis=1, keepdims=True), 1)
        z = np.where(far, z - (z * far).sum(axis=1, keepdims=True) / n, 0.0)
        for lag in range(min(max_lag, k - 1) + 1):  # a lag needs two slices that far apart
            both = far[:, lag:] & far[:, :k - lag]
            num[lag] += float(np.sum(z[:, lag:] * z[:, :k - lag] * both)) / max(both.sum(), 1)
        start += nb
    tau = float(1.0 + 2.0 * np.sum(num[1:] / num[0])) if num[0] > 0 else 1.0
    return ratio, tau


def peak_to_noise(slices: np.ndarray, exclude: int = 2, block: int = 65536) -> np.ndarray:
    """Per pixel, its tallest pulse-filtered slice over the tallest one outside +-``exclude``
    slices of it (:func:`noise_maxima`): how far the return stands above its own profile's
    noise, with no truth and no noise model.

    A profile of noise alone gives about 1-2 (its two tallest noise peaks); a return that a
    depth can be read from, several. The depth estimators' no-return rule
    (:func:`no_return`) is relative to the brightest pixels, so it cannot tell an image of
    noise from a scene; this ratio can, against :func:`noise_only_ratio`.

    Parameters
    ----------
    slices : ndarray, shape (Q, K)
    exclude : int
        Slices either side of the peak left out of the noise maximum (the return's width).
    block : int
        Pixels filtered at a time (bounds the temporary copy at 512x512).

    Returns
    -------
    ndarray, shape (Q,)
        float64; 1.0 where the profile has no positive value (or ``K <= 2 exclude + 1``),
        ``inf`` where it has a peak and nothing else above zero.
    """
    return _noise_stats(slices, exclude, block=block)[0]


#: entries of the reference noise drawn (``pixels x k``) beyond which fewer than its 2 048
#: profiles are drawn, 256 at least (a 66 714-slice gate asked for 1.02 GiB at once, an
#: audit; it is drawn a block at a time as well): at 16 383 slices the 90th percentile of
#: 512 profiles is 1.1425 against 2 048's 1.1437 (256: 1.1469; measured 2026-11-28)
REFERENCE_ENTRIES = 2048 * 4096


def _reference_pixels(k: int, pixels: int = 2048) -> int:
    """Profiles of the reference noise at ``k`` slices (:data:`REFERENCE_ENTRIES`)."""
    return min(pixels, max(256, REFERENCE_ENTRIES // max(int(k), 1)))


def _reference_blocks(k: int, pixels: int = 2048, seed: int = 0):
    """White Gaussian noise clipped at zero, the non-negative solve's noise floor, as
    blocks of at most :data:`NOISE_BLOCK_ENTRIES` entries drawn in turn from one generator
    (the same numbers as one ``(pixels, k)`` draw)."""
    rng = np.random.default_rng(seed)
    step = block_rows(k)
    for start in range(0, pixels, step):
        yield np.maximum(rng.standard_normal((min(step, pixels - start), k)), 0.0)


def noise_only_ratio(k: int, pixels: int = 2048, seed: int = 0, exclude: int = 2) -> float:
    """The 90th percentile of :func:`peak_to_noise` over profiles of ``k`` slices of white
    Gaussian noise clipped at zero (the non-negative solve's noise floor): what an image
    without a return gives.

    It falls with ``k`` (2.5 at 16 slices, 1.85 at 28, 1.49 at 68, 1.32 at 200, 1.24 at
    1023), since the noise maximum beside a peak is then taken over more slices; a fixed
    threshold would miss noise at a narrow range gate. Drawn, with a fixed seed, rather than
    tabulated: the statistic has no closed form once the pulse filter correlates neighbours.
    NaN below :data:`NOISE_ONLY_MIN_SLICES`.
    """
    if k < NOISE_ONLY_MIN_SLICES:
        return float("nan")
    return _reference_stats(k, pixels, seed, exclude)[0]


@functools.lru_cache(maxsize=32)
def _reference_stats(k: int, pixels: int = 2048, seed: int = 0, exclude: int = 2
                     ) -> tuple[float, float]:
    """The reference noise's 90th percentile of :func:`peak_to_noise` and its integrated
    autocorrelation, from one draw and one pass (deterministic in its arguments, so kept:
    :func:`noise_verdict` needs both, often at the same ``k``, on every run)."""
    n = _reference_pixels(k, pixels)
    ratio, tau = _block_stats(_reference_blocks(k, n, seed), n, k, exclude, 3, 4)
    return float(np.percentile(ratio, 90)), tau


def _effective(k: int, tau: float) -> int:
    """``K tau_ref / tau``, at most ``K`` (see :func:`effective_slices`)."""
    if k < NOISE_ONLY_MIN_SLICES or not np.isfinite(tau):
        return k
    tau_ref = _reference_stats(k)[1]
    return int(min(k, max(round(k * tau_ref / max(tau, 1e-12)), 1)))


def effective_slices(slices: np.ndarray) -> int:
    """The number of slices of the reference noise of :func:`noise_only_ratio` that are as
    many independent draws as these profiles' ``K``: ``K tau_ref / tau``, with ``tau`` the
    integrated autocorrelation of the profiles' noise along the delay, at most ``K``.

    A calibrated instrument's matched filter (the code convolved with a spread IRF) correlates
    the noise over more lags (lag-2 correlation 0.42 against 0.15), so its noise maxima are
    drawn from fewer independent slices and stand lower beside a noise peak: read against
    ``K`` slices of white noise, an image of noise through it came within 1 % of the floor.
    """
    return _effective(int(np.shape(slices)[1]), _noise_stats(slices)[1])


#: :func:`noise_verdict` reads at most this many pixels, a fixed random subset of a larger
#: image: its 90th percentile and the noise's autocorrelation describe the image, not each
#: pixel. Measured 2026-11-27 on a reconstructed 512x512 cube of 61 slices (a 256x256
#: Hadamard run tiled): 0.763 s -> 0.082 s on a 2-core machine, the 90th percentile 77.84 ->
#: 77.90 and the floor unchanged; on 256x256 noise, 1.514 -> 1.511 against a floor of 2.13
#: (the time at 512x512 was most of a torch run's host work on an H100).
NOISE_VERDICT_PIXELS = 32768


def noise_verdict(slices: np.ndarray, cap: float = 1000.0,
                  max_pixels: int = NOISE_VERDICT_PIXELS, exclude: int = 2
                  ) -> tuple[float, float, float] | None:
    """Whether these slices hold any return above the noise, in one pass over them (over
    ``max_pixels`` of them, drawn with a fixed seed, where there are more).

    ``exclude`` is the return's half width in slices (:func:`peak_to_noise`): 2 for a
    pulse a bin wide; a calibrated instrument's returns span its response (a 10-bin IRF's
    about 12 slices either side), whose own shoulders read as the noise beside the peak
    otherwise (an audit's good map at RMSE 7 mm was said to be mostly noise: 1.15 against
    2.08). The white-noise reference then leaves out as many of its effective slices.

    Returns
    -------
    (p90, floor, null) or None
        The 90th percentile of :func:`peak_to_noise` (capped at ``cap``: a noiseless
        profile has nothing beside its peak), :data:`NOISE_ONLY_MARGIN` times ``null``, and
        ``null``, :func:`noise_only_ratio` at :func:`effective_slices`; ``p90 < floor``
        means that at most a tenth of the pixels hold a return. None where there is no
        verdict: fewer than :data:`NOISE_ONLY_MIN_SLICES` (effective) slices, fewer than
        :data:`NOISE_BESIDE_MIN` of them beside a return (:func:`verdict_and_room`), or
        slices that are not finite (a diverged solve).
    """
    return verdict_and_room(slices, cap, max_pixels, exclude)[0]


def verdict_and_room(slices: np.ndarray, cap: float = 1000.0,
                     max_pixels: int = NOISE_VERDICT_PIXELS, exclude: int = 2
                     ) -> tuple[tuple[float, float, float] | None, tuple[int, int] | None]:
    """:func:`noise_verdict`, and the room it had: ``(k_eff, beside)``, the independent
    slices (:func:`effective_slices`) and how many of them lie beside a return of half width
    ``exclude``, from the same pass (None where the slices are too few or not finite), so
    that a caller can say why there is no verdict without reading the slices again."""
    sl = np.asarray(slices)
    if sl.ndim != 2 or sl.shape[1] < NOISE_ONLY_MIN_SLICES or not np.isfinite(sl).all():
        return None, None
    if sl.shape[0] > max_pixels:
        keep = np.random.default_rng(0).choice(sl.shape[0], max_pixels, replace=False)
        sl = sl[np.sort(keep)]
    exclude = max(2, int(exclude))
    ratio, tau = _noise_stats(sl, exclude, corr_exclude=exclude + 1)
    k_eff = _effective(sl.shape[1], tau)
    # the return's width in the reference's independent slices (2 for an ideal pulse)
    ref_exclude = max(2, int(round(exclude * k_eff / sl.shape[1])))
    room = (k_eff, max(0, k_eff - (2 * ref_exclude + 1)))
    null = noise_only_ratio(k_eff, exclude=ref_exclude)
    if not np.isfinite(null) or room[1] < NOISE_BESIDE_MIN:
        return None, room
    return (float(np.percentile(np.minimum(ratio, cap), 90)), NOISE_ONLY_MARGIN * null,
            null), room


def check_peak_fraction(fraction: float) -> float:
    """``fraction`` of :func:`no_return` (``ml_depth``'s ``min_peak_fraction``) as a float
    in [0, 1], or one line (2 gave an all-NaN map, NaN and -1 were taken: an outside
    audit)."""
    f = positive_number(fraction, "the peak fraction (min_peak_fraction)", zero=True)
    if f > 1:
        raise ConfigError(f"the peak fraction (min_peak_fraction) must lie in [0, 1], got "
                          f"{fraction!r}")
    return f


def no_return(peak: np.ndarray, fraction: float = 0.05) -> np.ndarray:
    """Pixels without a detected return, by the rule of :func:`~.argmax.ml_depth`: a peak
    that is not positive or below ``fraction`` (in [0, 1]) of the 99th percentile of all
    peaks."""
    check_peak_fraction(fraction)
    peak = np.asarray(peak, dtype=np.float64)
    ref = float(np.percentile(peak, 99)) if peak.size else 0.0
    return (peak <= 0) | (peak < fraction * ref)
