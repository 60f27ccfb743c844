"""A timing drift over a measured acquisition: how far the returns move from the first
patterns to the last (laser or detector warm-up, a cable's temperature, a sync clocked apart
from the code generator).

The single-pixel solve takes every pattern's returns at the same delays, so a drift of half a
bin over the acquisition already blurs the range slices (an outside audit of 2026-11-30, a
16x16 scene through 128 patterns: RMSE 0.076 -> 0.299 m and median error 0.4 -> 14.6 mm at
0.5 bin, 0.398 m and 4.5 cm at 3 bins) while nothing else in the data says so. The returns'
mean delay is read per group of consecutive patterns: each group's histogram, summed over its
patterns, matched-filtered with the code over the whole period, and cross-correlated with
the whole acquisition's (its peak's bin, and below a bin the slope of the cross-spectrum's
phase); a line through the
groups' shifts gives the drift from the first pattern to the last and its standard error.
Each group sums about ``M / GROUPS`` patterns, so the scene's own profile is nearly the same
in every group and only a shift moves the cross-correlation's peak (on the project's
simulated files without drift, 0.001-0.018 bin; with a drift of 1 bin, 0.81-0.87).
"""

from __future__ import annotations

import numpy as np

__all__ = ["DRIFT_BINS", "GROUPS", "drift_note", "timing_drift"]

#: consecutive groups of patterns whose returns' delays are compared
GROUPS = 8
#: a drift over the acquisition of at least this many bins is said (the audit's smallest
#: harmful drift was half a bin; on a 16x16 steps scene a quarter bin cost 0.20 -> 0.36 m of
#: RMSE on one seed and 0.18 -> 0.28 m on another, a tenth 0.20 -> 0.24 and nothing)
DRIFT_BINS = 0.15
#: and only where it stands this many standard errors above the groups' scatter
DRIFT_SIGMAS = 4.0


def _shift(cross: np.ndarray, prod: np.ndarray) -> float:
    """One group's shift from the whole's, in bins: the whole bins from the cross-correlation's
    circular peak, the rest from the slope of the cross-spectrum's phase over the lower
    quarter of the frequencies, weighted by its magnitude (a parabola through the peak read
    a quarter-bin drift as 0.1 bin: a one-bin pulse's peak locks to the bins)."""
    n = cross.size
    whole = int(np.argmax(cross))
    whole = (whole + n // 2) % n - n // 2
    f = np.arange(prod.size) / n
    rest = prod * np.exp(2j * np.pi * f * whole)  # (the whole bins taken out)
    use = (f > 0) & (f <= 0.25)
    w, phase, f = np.abs(rest[use]), np.angle(rest[use]), f[use]
    den = 2.0 * np.pi * float(np.sum(w * f * f))
    return float(whole - (np.sum(w * f * phase) / den if den > 0 else 0.0))


def timing_drift(hist: np.ndarray, code: np.ndarray) -> tuple[float, float, np.ndarray] | None:
    """The returns' drift over an acquisition, in bins.

    Parameters
    ----------
    hist : ndarray, shape (M, L)
        Histograms per pattern, in the order shown.
    code : ndarray, shape (L,)
        The code's bits (its bipolar replica is the matched filter here).

    Returns
    -------
    (drift, standard_error, shifts) or None
        The fitted shift from the first pattern to the last (positive: later, farther), its
        standard error from the groups' scatter about the line, and each group's shift from
        the whole acquisition's returns; ``None`` with fewer than ``2 * GROUPS`` patterns or
        no photon.
    """
    h = np.asarray(hist, dtype=np.float64)
    m, n = h.shape
    if m < 2 * GROUPS or not h.any():
        return None
    edges = np.linspace(0, m, GROUPS + 1).astype(int)
    groups = np.add.reduceat(h, edges[:-1], axis=0)
    replica = 2.0 * (np.asarray(code, np.float64) > 0) - 1.0
    spec = np.fft.rfft(groups, axis=1) * np.conj(np.fft.rfft(replica))
    whole = spec.sum(axis=0)
    # each group's matched-filter output against the whole's: their cross-correlation is
    # the product of the spectra, one FFT each
    x = (edges[:-1] + edges[1:] - 1) / 2.0  # each group's middle pattern
    freq = np.arange(whole.size) / n
    for _ in range(2):  # (again against the whole with the first line's drift taken out:
        # summed through a drift of 8 bins the whole was blurred, and one group's whole-bin
        # peak jumped, -6.6 +- 2.2 read for -8)
        prod = spec * np.conj(whole)
        cross = np.fft.irfft(prod, n=n, axis=1)
        shifts = np.array([_shift(c, p) for c, p in zip(cross, prod, strict=True)])
        slope, icpt = np.polyfit(x, shifts, 1)
        line = slope * x + icpt
        whole = (spec * np.exp(2j * np.pi * freq * line[:, None])).sum(axis=0)
    resid = shifts - (slope * x + icpt)
    se = float(np.sqrt(resid @ resid / (GROUPS - 2) / np.sum((x - x.mean()) ** 2)))
    return float(slope * (m - 1)), se * (m - 1), shifts


def drift_note(drift, bin_width: float) -> str | None:
    """A warning where :func:`timing_drift`'s drift is at least :data:`DRIFT_BINS` and
    :data:`DRIFT_SIGMAS` standard errors; ``None`` otherwise."""
    if drift is None:
        return None
    bins, se, _ = drift
    if abs(bins) < DRIFT_BINS or abs(bins) < DRIFT_SIGMAS * se:
        return None
    mm = abs(bins) * bin_width * 299792458.0 / 2.0 * 1e3
    way = "later" if bins > 0 else "earlier"
    return (f"the returns arrive {abs(bins):.2g} bins ({mm:.3g} mm of range) {way} at the "
            f"last pattern than at the first (+-{se:.2g} bins): a timing drift over the "
            f"acquisition (laser or detector warm-up, a cable's temperature, a sync clocked "
            f"apart from the code), which the solve takes as one delay per return and which "
            f"blurs the depths (half a bin cost an audit's 16x16 scene 0.4 -> 15 mm of median "
            f"error); let the instrument settle, or acquire shorter")
