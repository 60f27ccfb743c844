"""The timing jitter (instrument response) of a photon-counting detector, bin-integrated.

A photon uniform within its bin, delayed by a jitter ``J`` (Gaussian, optionally plus, with
some probability, an exponential diffusion tail: ex-Gaussian), is recorded ``k`` bins later with
probability ``P(floor(U + J) = k) = G(k+1) - 2 G(k) + G(k-1)``, ``G(y) = E[(y - J)^+]`` (model
equation D1 in ``docs/model.md``). The closed forms of ``G`` make the kernel exact however
narrow the jitter is against a bin; SciPy gives the Gaussian and ex-Gaussian CDFs and the FFT.
Used by the GMAPD (:mod:`spslidar.detectors.gmapd`, before its dead time) and by the simulated
instrument response (:mod:`spslidar.instrument`).
"""

from __future__ import annotations

import numpy as np
from scipy import fft as sfft
from scipy import special, stats

__all__ = ["NARROWEST_BINS", "convolve_periodic", "jitter_antiderivative", "jitter_kernel"]

#: largest IRF kernel support (bins)
_MAX_KERNEL = 10_000_000


def _g_gauss(y: np.ndarray, sigma: float) -> np.ndarray:
    """``G(y) = E[(y - J)^+]`` for ``J ~ N(0, sigma^2)`` (the antiderivative of its CDF)."""
    if sigma == 0:
        return np.maximum(y, 0.0)
    z = y / sigma
    return y * special.ndtr(z) + sigma * np.exp(-0.5 * z * z) / np.sqrt(2 * np.pi)


def _g_exgauss(y: np.ndarray, sigma: float, tau: float) -> np.ndarray:
    """``E[(y - J)^+]`` for ``J = N(0, sigma^2) + Exp(tau)``: ``G_gauss(y) - tau F_J(y)``."""
    if tau == 0:
        return _g_gauss(y, sigma)
    if sigma == 0:
        cdf = np.where(y > 0, -np.expm1(-np.maximum(y, 0.0) / tau), 0.0)
    else:
        cdf = stats.exponnorm.cdf(y, tau / sigma, scale=sigma)
    return _g_gauss(y, sigma) - tau * cdf


#: a jitter width (bins) below this is none: the closed forms divide by it, and 1e-300 s
#: overflowed (NumPy's warnings on stderr) while its kernel is a delta to far below 1e-6
NARROWEST_BINS = 1e-6


def _resolved(width: float) -> float:
    """``width`` (bins), or 0 below :data:`NARROWEST_BINS`."""
    return 0.0 if width < NARROWEST_BINS else float(width)


def jitter_antiderivative(y: np.ndarray, sigma: float, tail: float = 0.0,
                          tail_weight: float = 0.0) -> np.ndarray:
    """``G(y) = E[(y - J)^+]`` of the jitter of :func:`jitter_kernel` (Gaussian, with
    probability ``tail_weight`` plus an exponential tail of mean ``tail``; bins): the
    antiderivative of its CDF, from which the share of any time interval follows exactly."""
    sigma, tail = _resolved(sigma), _resolved(tail)
    tw = float(tail_weight) if tail > 0 else 0.0
    out = (1.0 - tw) * _g_gauss(y, sigma)
    return out + tw * _g_exgauss(y, sigma, tail) if tw else out


def jitter_kernel(period: int, sigma: float, tail: float = 0.0,
                  tail_weight: float = 0.0) -> np.ndarray:
    """The bin-to-bin timing-jitter kernel, wrapped onto one period.

    Parameters
    ----------
    period : int
        ``L``, bins per code period.
    sigma : float
        Gaussian jitter standard deviation (bins).
    tail, tail_weight : float
        Mean (bins) and weight of the exponential tail: with probability ``tail_weight`` the
        jitter is ``N(0, sigma^2) + Exp(tail)`` (an ex-Gaussian diffusion tail).

    Returns
    -------
    ndarray, shape (L,)
        ``K[k mod L] = P(floor(U + J) = k)``: a photon uniform (``U``) within bin ``s`` is
        recorded in bin ``s + k``. Sums to 1.

    Notes
    -----
    ``P(floor(U + J) = k) = G(k+1) - 2 G(k) + G(k-1)`` with ``G(y) = E[(y - J)^+]``, in closed
    form for both components (``G_exG = G_gauss - tail * F_exG``), so the kernel is exact
    however narrow the jitter is compared with a bin.
    """
    sigma, tail = _resolved(sigma), _resolved(tail)
    tw = float(tail_weight) if tail > 0 else 0.0
    kern = np.zeros(period)
    if sigma == 0 and tw == 0:
        kern[0] = 1.0
        return kern
    lo = -int(np.ceil(10 * sigma)) - 2
    hi = int(np.ceil(10 * sigma + (40 * tail if tw else 0.0))) + 2
    if hi - lo > _MAX_KERNEL:
        raise ValueError("timing jitter spans more than 1e7 bins; use a coarser bin width")
    k = np.arange(lo, hi + 1, dtype=np.float64)
    out = np.zeros(k.size)
    for weight, g in ((1.0 - tw, lambda y: _g_gauss(y, sigma)),
                      (tw, lambda y: _g_exgauss(y, sigma, tail))):
        if weight:
            out += weight * (g(k + 1) - 2 * g(k) + g(k - 1))
    out = np.maximum(out, 0.0)
    np.add.at(kern, k.astype(np.int64) % period, out / out.sum())
    return kern


def convolve_periodic(x: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Circular convolution of each row of ``x`` (B, L) with ``kernel`` (L,), by FFT, clipped at
    0 (round-off); ``x`` itself (as float64) when the kernel is the identity."""
    x = np.asarray(x, dtype=np.float64)
    if kernel[0] == 1.0:
        return x
    n = x.shape[-1]
    out = sfft.irfft(sfft.rfft(x, axis=-1) * sfft.rfft(kernel), n=n, axis=-1)
    return np.maximum(out, 0.0, out=out)
