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

from typing import NamedTuple

import numpy as np

__all__ = ["DRIFT_BINS", "DRIFT_SIGMAS", "GROUPS", "RETURN_SIGMAS", "SPAN_BINS", "SPAN_SIGMAS",
           "SUBSETS", "Drift", "drift_note", "timing_drift"]

#: consecutive groups of patterns whose returns' delays are compared
GROUPS = 8
#: a drift over the acquisition of at least this many bins is said (the audit's smallest
#: harmful drift was half a bin; on a 16x16 steps scene a quarter bin cost 0.20 -> 0.36 m of
#: RMSE on one seed and 0.18 -> 0.28 m on another, a tenth 0.20 -> 0.24 and nothing)
DRIFT_BINS = 0.15
#: and only where it stands this many standard errors above the photon noise (a faint file's
#: shifts jump now and then: at 4, one of six faint files without a drift was said; at 5, one
#: of 200 others, the faintest, while 6-10 of 10 quarter-bin drifts were)
DRIFT_SIGMAS = 5.0
#: interleaved subsets of each group whose shifts' scatter gives the noise (two, the even and
#: odd patterns, missed the occasional jump of a faint file's shift: 2 of 24 said a drift)
SUBSETS = 4
#: the acquisition's matched filter (its groups aligned) must peak this many robust standard
#: deviations above its median for its returns to be timed (a file of background alone peaks
#: at about 4; its groups' shifts are noise's peaks, which spanned 0.6 bins and were said as
#: a drift)
RETURN_SIGMAS = 8.0
#: a drift that is no line (a warm-up, an oscillation): the groups' shifts spanning this many
#: bins, at least ``SPAN_SIGMAS`` of one group's standard error (eight groups of Gaussian
#: noise span about 2.8 of them, and 5.4 once in a thousand; a faint file's shifts jump now
#: and then, and at 6 one of 60 faint files without a drift was said, at 7 none of 120 other
#: ones, while 8 to 10 of 10 half-bin warm-ups and bumps were)
SPAN_BINS = 0.3
#: the standard errors of one group's shift the span must reach (see ``SPAN_BINS``)
SPAN_SIGMAS = 7.0


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


class Drift(NamedTuple):
    """:func:`timing_drift`'s reading, in bins."""

    #: the fitted shift from the first pattern to the last (positive: later, farther)
    bins: float
    #: its standard error, from each group's photon noise
    se: float
    #: the largest difference between two groups' shifts (a drift that is not a line: a
    #: warm-up, an oscillation)
    span: float
    #: one group's shift's standard error (from ``SUBSETS`` interleaved subsets of each
    #: group's patterns, which see the same drift: their scatter is the noise)
    sigma: float
    #: each group's shift from the whole acquisition's returns
    shifts: np.ndarray
    #: how far the acquisition's strongest return stands above its matched filter's noise
    #: (robust standard deviations)
    peak_sigmas: float


def timing_drift(hist: np.ndarray, code: np.ndarray) -> Drift | None:
    """The returns' drift over an acquisition, in bins.

    Parameters
    ----------
    hist : ndarray, shape (M, L)
        Histograms per pattern, in the order shown.
    code : ndarray, shape (L,)
        The code's bits (its bipolar replica is the matched filter here).

    Returns
    -------
    Drift or None
        ``None`` with fewer than ``2 * GROUPS * SUBSETS`` (64) patterns, no photon, or no
        return standing
        :data:`RETURN_SIGMAS` above the matched filter's noise. The standard errors
        come from each group's own photon noise, not from the groups' scatter about the
        line, which a warm-up's curve inflated until it hid itself (an outside audit of
        2026-11-30: a 1-bin exponential warm-up read 0.47 +- 0.19 bins and was not said).
    """
    h = np.asarray(hist)  # (summed in float64 group by group: no copy of the whole)
    m, n = h.shape
    if m < 2 * GROUPS * SUBSETS or not h.any():  # (in fewer, a subset of a group could be
        # empty, and its shift of 0 shrank the noise: 9 of 40 files of 16 patterns without a
        # drift were said to drift, a review)
        return None
    edges = np.linspace(0, m, GROUPS + 1).astype(int)
    replica = np.conj(np.fft.rfft(2.0 * (np.asarray(code, np.float64) > 0) - 1.0))
    spec = np.fft.rfft(np.add.reduceat(h, edges[:-1], axis=0, dtype=np.float64),
                       axis=1) * replica
    whole = spec.sum(axis=0)
    # each group's matched-filter output against the whole's: their cross-correlation is
    # the product of the spectra, one FFT each
    x = (edges[:-1] + edges[1:] - 1) / 2.0  # each group's middle pattern
    freq = np.arange(whole.size) / n

    def shifts_of(sp: np.ndarray) -> np.ndarray:
        prod = sp * np.conj(whole)
        cross = np.fft.irfft(prod, n=n, axis=1)
        return np.array([_shift(c, p) for c, p in zip(cross, prod, strict=True)])

    for _ in range(2):  # (again against the whole with the first line's drift taken out:
        # summed through a drift of 8 bins the whole was blurred, and one group's whole-bin
        # peak jumped, -6.6 +- 2.2 read for -8)
        shifts = shifts_of(spec)
        slope, icpt = np.polyfit(x, shifts, 1)
        line = slope * x + icpt
        whole = (spec * np.exp(2j * np.pi * freq * line[:, None])).sum(axis=0)
    total = np.fft.irfft(whole, n=n)  # (the groups aligned: a drift's own blur taken out)
    spread = 1.4826 * float(np.median(np.abs(total - np.median(total))))
    peak = float(total.max() - np.median(total)) / spread if spread > 0 else np.inf
    if not peak >= RETURN_SIGMAS:
        return None  # (no return stands out to be timed: noise's peaks read as drift)
    parts = np.array([shifts_of(np.fft.rfft(np.array(
        [h[a:b][q::SUBSETS].sum(axis=0, dtype=np.float64)
         for a, b in zip(edges[:-1], edges[1:], strict=True)]),
        axis=1) * replica) for q in range(SUBSETS)])
    # (each subset holds 1 / SUBSETS of its group's photons: SUBSETS times the variance)
    sigma = float(np.sqrt(np.mean(np.var(parts, axis=0, ddof=1)) / SUBSETS))
    se = sigma / float(np.sqrt(np.sum((x - x.mean()) ** 2)))
    return Drift(float(slope * (m - 1)), se * (m - 1), float(np.ptp(shifts)), sigma, shifts,
                 peak)


def drift_note(drift: Drift | None, bin_width: float) -> str | None:
    """A warning where :func:`timing_drift`'s line is at least :data:`DRIFT_BINS` and
    :data:`DRIFT_SIGMAS` standard errors, or its groups' span at least :data:`SPAN_BINS` and
    :data:`SPAN_SIGMAS` of one group's standard errors; ``None`` otherwise."""
    if drift is None:
        return None
    line = abs(drift.bins) >= DRIFT_BINS and abs(drift.bins) >= DRIFT_SIGMAS * drift.se
    curve = drift.span >= SPAN_BINS and drift.span >= SPAN_SIGMAS * drift.sigma
    if not (line or curve):
        return None
    mm = drift.span * bin_width * 299792458.0 / 2.0 * 1e3
    way = "later" if drift.bins > 0 else "earlier"
    return (f"the returns' delay moves by up to {drift.span:.2g} bins ({mm:.3g} mm of range) "
            f"between groups of patterns over the acquisition (from the first pattern to the "
            f"last, {abs(drift.bins):.2g} bins {way}, +-{drift.se:.2g}): a timing drift "
            f"(laser or detector warm-up, a cable's temperature, a sync clocked apart from "
            f"the code), which the solve takes as one delay per return and which blurs the "
            f"depths (half a bin cost an audit's 16x16 scene 0.4 -> 15 mm of median error); "
            f"let the instrument settle, or acquire shorter")
