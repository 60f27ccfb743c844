"""Detector channels read together, and the cable delays between them.

A lab that splits the return between two detectors (to count more photons than one
detector's dead time allows, or two polarisations) records them on two TCSPC channels, each
behind its own cable and electronics. Read together (``--channel`` left out), their photons
are merged as they are, so a delay of nanoseconds between the channels makes every return two
returns, that far apart: an uncalibrated map reads each surface twice, and a calibration
measures the two as one response (an outside lab audit of stop 65: median error 2.6-3.3 mm
through a calibration, two surfaces without one).

Both channels see the same scene through the same patterns, so their photons summed over the
patterns (the reader's ``channel_histograms``) are the same histogram over the code period,
each delayed by its own cable: the peak of their circular cross-correlation is the delay
between them (sharp, since the code's autocorrelation is: an m-sequence's is a single bin).
:func:`channel_delays` reads it, :func:`skew_note` says it, and ``--align-channels`` moves
each channel's photons onto the channel with the most (the reader's ``channel_shifts``,
whole bins; the part of a bin left is the merged response's, which a calibration measures).

Written here: NumPy's FFT gives the correlation; no time-tagging library aligns channels by
the code (``tttrlib`` and ``ptufile`` read each channel as recorded).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["MIN_PHOTONS", "MIN_Z", "SKEW_BINS", "channel_delays", "channel_shifts",
           "skew_note"]

#: photons a channel needs for its delay to be read
MIN_PHOTONS = 1000
#: how far the correlation's peak must stand above its other lags (robust deviations) for
#: a delay to be read
MIN_Z = 8.0
#: a delay of at least this many bins is said (below it the merged return is a bin wider)
SKEW_BINS = 1.5


def channel_delays(hists: dict[int, np.ndarray]) -> dict[int, float]:
    """Each channel's delay (bins, within half the period either way) against the channel
    with the most photons, read from the peak of their circular cross-correlation (a
    parabola through it and its two neighbours below a bin).

    Parameters
    ----------
    hists : dict of int to ndarray
        Each channel's photons over the code period (the reader's ``channel_histograms``).

    Returns
    -------
    dict of int to float
        The reference channel at 0.0 and every other channel whose delay can be read: one of
        :data:`MIN_PHOTONS` photons or more whose correlation peak stands :data:`MIN_Z` robust
        deviations above its other lags. Empty for fewer than two channels.
    """
    counts = {c: float(np.sum(h)) for c, h in hists.items()}
    if len(counts) < 2:
        return {}
    ref = max(counts, key=lambda c: (counts[c], -c))
    if counts[ref] < MIN_PHOTONS:
        return {}
    h0 = np.asarray(hists[ref], np.float64)
    f0 = np.fft.rfft(h0 - h0.mean())
    n = h0.size
    out = {ref: 0.0}
    for c, h in sorted(hists.items()):
        if c == ref or counts[c] < MIN_PHOTONS:
            continue
        hc = np.asarray(h, np.float64)
        r = np.fft.irfft(np.fft.rfft(hc - hc.mean()) * np.conj(f0), n)
        k = int(np.argmax(r))
        spread = 1.4826 * np.median(np.abs(r - np.median(r)))
        if not (spread > 0 and (r[k] - np.median(r)) / spread >= MIN_Z):
            continue
        a, b, d = r[(k - 1) % n], r[k], r[(k + 1) % n]
        den = a - 2 * b + d
        frac = 0.5 * (a - d) / den if den < 0 else 0.0
        lag = (k + frac + n / 2) % n - n / 2  # (within half a period either way)
        out[int(c)] = float(lag)
    return out


def channel_shifts(delays: dict[int, float]) -> dict[int, int]:
    """The whole bins each channel is moved earlier by to lie on the reference's (the
    reader's ``channel_shifts``): its delay rounded; channels already within half a bin left
    out."""
    return {c: int(round(d)) for c, d in delays.items() if round(d) != 0}


def skew_note(delays: dict[int, float], bin_width: float, after: bool = False) -> str | None:
    """A warning where channels read together lie :data:`SKEW_BINS` or more apart, naming
    the delays in bins, seconds and metres and what to do (``after``: the delays left once a
    calibration's shifts were applied, which the cables no longer fit); None otherwise."""
    if len(delays) < 2:
        return None
    ref = next(c for c, d in delays.items() if d == 0.0)
    far = {c: d for c, d in delays.items() if abs(d) >= SKEW_BINS}
    if not far:
        return None
    parts = ", ".join(f"channel {c} {d:+.1f} bins ({d * bin_width * 1e9:+.3g} ns, "
                      f"{d * bin_width * 149896229.0:+.3g} m)" for c, d in sorted(far.items()))
    if after:
        return (f"the detector channels, moved by the calibration's channel shifts, still do "
                f"not arrive together: against channel {ref}, {parts} (cables changed since "
                f"the calibration? calibrate again with --align-channels)")
    return (f"the detector channels read together do not arrive together: against channel "
            f"{ref}, {parts} (a cable delay between them?): merged as they are, every return "
            f"is read once for each channel, that far apart; --align-channels moves each onto "
            f"channel {ref}'s (or read one --channel at a time)")


def describe(delays: dict[int, float], shifts: dict[int, int]) -> dict[str, Any] | None:
    """What ``metrics.json`` records of the channels (``ptu.channel_delays_bins``), or None
    for one channel."""
    if len(delays) < 2 and not shifts:
        return None
    return {"delays_bins": {str(c): d for c, d in sorted(delays.items())},
            "shifts_bins": {str(c): k for c, k in sorted(shifts.items())}}
