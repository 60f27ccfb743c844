"""Per-pixel profile helpers shared by the spatial depth estimators.

The reconstructed block ``slices`` of shape ``(Q, K)`` holds, for each pixel, a profile over
the gated delays. These helpers give the scale of its noise, filter it with the return's
footprint, turn (fractional) slice indices into depth, refine a chosen slice below one bin and
shift label images, without ever looking at a ground truth.
"""

from __future__ import annotations

import numpy as np

from ..forward import delay_to_depth
from .base import DepthContext

__all__ = ["grid_shape", "index_to_depth", "no_return", "noise_scale", "pulse_filter",
           "refine_subbin", "shift2d"]


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
        The RMS over all remaining entries, or the RMS of the whole block when nothing
        remains (a block of 2 * exclude + 1 slices or fewer); never 0 for a non-zero block.

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
    return delay_to_depth(pos + 0.5 - ctx.pulse_width / 2.0, ctx.bin_width)


def refine_subbin(slices: np.ndarray, label: np.ndarray, half: int = 1) -> np.ndarray:
    """Sub-bin position of each pixel's return around its chosen slice.

    The intensity-weighted mean delay over the ``2 half + 1`` slices centred on ``label``:
    Howland et al.'s depth-weighted-intensity over intensity ratio, taken locally around the
    chosen return so that noise elsewhere in the profile does not bias it.

    Parameters
    ----------
    slices : ndarray, shape (Q, K)
    label : ndarray of int, shape (Q,)
        Chosen slice per pixel.
    half : int
        Half width of the window in slices.

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
    offs = np.arange(-half, half + 1)
    cols = label[:, None] + offs[None, :]
    inside = (cols >= 0) & (cols < k)
    w = np.where(inside, np.clip(x[np.arange(q)[:, None], np.clip(cols, 0, k - 1)], 0, None),
                 0.0)
    tot = w.sum(axis=1)
    shift = np.divide(w @ offs.astype(np.float64), tot, out=np.zeros(q), where=tot > 0)
    return label + shift


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
        raise ValueError(f"ctx.shape {ctx.shape} does not hold the {q} pixels of the slices: "
                         f"a spatial depth estimator needs the image shape")
    return n1, n2


def no_return(peak: np.ndarray, fraction: float = 0.05) -> np.ndarray:
    """Pixels without a detected return, by the rule of :func:`~.argmax.ml_depth`: a peak
    that is not positive or below ``fraction`` of the 99th percentile of all peaks."""
    peak = np.asarray(peak, dtype=np.float64)
    ref = float(np.percentile(peak, 99)) if peak.size else 0.0
    return (peak <= 0) | (peak < fraction * ref)
