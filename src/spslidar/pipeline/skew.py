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

__all__ = ["FOLLOW_MIN", "MIN_PHOTONS", "MIN_Z", "SKEW_BINS", "align_note", "channel_delays",
           "channel_shifts", "check_align", "monitor_note", "scene_channels", "skew_note"]

#: photons a channel needs for its delay to be read
MIN_PHOTONS = 1000
#: how far the correlation's peak must stand above its other lags (robust deviations) for
#: a delay to be read
MIN_Z = 8.0
#: a delay of at least this many bins is said (an outside audit of stop 67 measured a
#: 1.4-bin skew, read as 1.21 bins, taking a map from 100 % to 66 % within 5 cm at 1 ns
#: bins, unsaid under the first threshold of 1.5)
SKEW_BINS = 0.75
#: a channel whose photon rate over the blocks spreads less than this many times a constant
#: rate's Poisson spread does not follow the patterns (a laser monitor, a reference): it is
#: given no delay and is no reference (an audit of stop 67: a monitor holding 71 % of the
#: photons was read as a 29.5-bin cable delay, and --align-channels, as the warning advised,
#: moved the scene 4.3 m)
FOLLOW_MIN = 2.5


def check_align(value: Any) -> bool:
    """``align_channels`` (``--align-channels``) as a bool, or one line."""
    if not isinstance(value, (bool, np.bool_)):
        from ..errors import ConfigError

        raise ConfigError(f"align_channels must be True or False, got {value!r}")
    return bool(value)


def _followed(spread: dict[int, float] | None) -> bool:
    """Whether the rate spreads tell anything: some channel's rate follows the patterns.
    Where none does (a detector at its dead-time limit counts more evenly than Poisson
    photons: spreads 0.6-0.8 for two InGaAs detectors behind one scene; or patterns of
    nearly equal light), a monitor cannot be told from a detector, and every channel is
    taken for a detector (an outside audit of stop 68: both were named monitors, their
    0.7 ns skew neither said nor aligned)."""
    return bool(spread) and bool(scene_channels(spread))


def scene_channels(spread: dict[int, float]) -> list[int]:
    """The channels whose photon rate follows the patterns (the reader's ``channel_spread``
    at :data:`FOLLOW_MIN` or more): those a delay is read between."""
    return sorted(c for c, v in spread.items() if v >= FOLLOW_MIN)


def monitor_note(spread: dict[int, float]) -> str | None:
    """Where channels read together include some whose photon rate does not follow the
    patterns beside some that do, the words naming them (merged, they add their photons to
    every pattern alike); None otherwise."""
    scene = scene_channels(spread)
    other = sorted(c for c in spread if c not in scene)
    if not scene or not other:
        return None
    said = ", ".join(f"{c} ({spread[c]:.3g})" for c in other)
    seen = ", ".join(f"{c} ({spread[c]:.3g})" for c in scene)
    return (f"the photon rate of detector channel(s) {said} does not follow the patterns, as "
            f"that of {seen} does (the spread of each channel's rate over the blocks against "
            f"a constant rate's): a laser monitor or a reference? merged, it adds the same "
            f"photons to every pattern and is given no delay; --channel "
            f"{scene[0] if len(scene) == 1 else '/'.join(map(str, scene))} reads the scene "
            f"alone")


def channel_delays(hists: dict[int, np.ndarray],
                   spread: dict[int, float] | None = None) -> dict[int, float]:
    """Each channel's delay (bins, within half the period either way) against the channel
    with the most photons, read from the peak of their circular cross-correlation (a
    parabola through it and its two neighbours below a bin).

    Parameters
    ----------
    hists : dict of int to ndarray
        Each channel's photons over the code period (the reader's ``channel_histograms``).
    spread : dict of int to float, optional
        The reader's ``channel_spread``: only the channels that follow the patterns
        (:func:`scene_channels`) are read, a monitor's photons being no return; every
        channel where none does (a monitor cannot then be told from a detector).

    Returns
    -------
    dict of int to float
        The reference channel at 0.0 and every other channel whose delay can be read: one of
        :data:`MIN_PHOTONS` photons or more whose correlation peak stands :data:`MIN_Z` robust
        deviations above its other lags. Empty for fewer than two channels.
    """
    if _followed(spread):  # (else every channel: none can be told for a monitor)
        scene = scene_channels(spread)
        hists = {c: h for c, h in hists.items() if c in scene}
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


def align_note(hists: dict[int, np.ndarray], spread: dict[int, float] | None,
               delays: dict[int, float], read: list[int] | None = None) -> str | None:
    """What ``--align-channels`` could not do, in one line: a single channel holding the
    scene's photons (one ``--channel`` read, or the others a monitor's) has nothing to be
    aligned with, and a channel whose delay :func:`channel_delays` could not read is merged
    as recorded (both were silent: an outside audit of stop 67). ``read``: the channels whose
    photons were read (:func:`~spslidar.pipeline.blocks.channels_read`), where the reader
    kept no histogram of each (a TDC bin split between the code's bits). None where every
    channel holding the scene's photons was read."""
    held = sorted(c for c, h in hists.items() if float(np.sum(h)) > 0)
    if len(held) < 2 and read is not None and len(read) > 1:
        # (said as "one detector channel's" of a HydraHarp file's two: found 2026-11-30)
        return (f"--align-channels: channels {', '.join(map(str, read))} are read, but their "
                f"delays are not read through a TDC bin split between the code's bits "
                f"(--allow-binning), so they are merged as recorded (or read one --channel at "
                f"a time)")
    if len(held) < 2:  # (the reader keeps no per-channel histograms of one channel)
        which = f" ({held[0]})" if held else ""
        return (f"--align-channels: the photons read are one detector channel's{which} (one "
                f"--channel is read, or the file has one), so there is nothing to align")
    follow = scene_channels(spread) if _followed(spread) else held
    scene = [c for c in held if c in follow or c not in spread]
    if len(scene) < 2:
        return (f"--align-channels: only channel {scene[0]} of {', '.join(map(str, held))} "
                f"follows the patterns (the others' photon rates do not: a monitor's), so "
                f"there is nothing to align")
    lost = [c for c in scene if c not in delays]
    if not lost:
        return None
    return (f"--align-channels: the delay of channel(s) {', '.join(map(str, lost))} could not "
            f"be read (under {MIN_PHOTONS} photons, or no correlation peak {MIN_Z:g} robust "
            f"deviations above the other lags), so they are merged as recorded")


def skew_note(delays: dict[int, float], bin_width: float, after: bool = False,
              spread: dict[int, float] | None = None) -> str | None:
    """A warning where channels read together lie :data:`SKEW_BINS` or more apart, naming
    the delays in bins, seconds and metres and what to do (``after``: the delays left once a
    calibration's shifts were applied, which the cables no longer fit; ``spread``: the
    channels' rate spreads, where none follows the patterns said to leave a monitor out);
    None otherwise."""
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
    caveat = ("" if spread is None or _followed(spread) else
              " (no channel's photon rate follows the patterns, as a detector at its dead-time "
              "limit's or under patterns of nearly equal light does not, so a laser monitor "
              "cannot be told from a detector here: leave a monitor out with --channel)")
    return (f"the detector channels read together do not arrive together: against channel "
            f"{ref}, {parts} (a cable delay between them?): merged as they are, every return "
            f"is read once for each channel, that far apart; --align-channels moves each onto "
            f"channel {ref}'s (or read one --channel at a time){caveat}")


def describe(delays: dict[int, float], shifts: dict[int, int],
             spread: dict[int, float] | None = None) -> dict[str, Any] | None:
    """What ``metrics.json`` records of the channels read together (``ptu.channels``): the
    delays read, the shifts applied and each channel's rate spread (the reader's
    ``channel_spread``); None for one channel."""
    spread = spread or {}
    if len(delays) < 2 and not shifts and len(spread) < 2:
        return None
    return {"delays_bins": {str(c): d for c, d in sorted(delays.items())},
            "shifts_bins": {str(c): k for c, k in sorted(shifts.items())},
            "rate_spread": {str(c): v for c, v in sorted(spread.items())}}
