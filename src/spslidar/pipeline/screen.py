"""Marker blocks in which the instrument was not measuring, and histograms that cover part of
the code period: what a real acquisition holds that the reconstruction must not read as
returns.

**Dropouts and stalls.** The DMD's markers go on whatever the rest of the instrument does. A
detector's overload shutdown, a laser interlock or a closed shutter leaves whole blocks
without photons over a full dwell; a TCSPC that runs on while the DMD or the laser waits
(a stall) leaves a block that lasts far longer than its photons say. Either block's photon
rate per code period is far below every other block's. Read as a measurement, the first is a
pattern that saw nothing and the second, scaled to the common dwell, one that saw almost
nothing: an outside audit of 2026-11-30 found 20 such blocks of 256 made a 16x16 map 3 times
worse (RMSE 2.3 -> 7.5 cm), and a stall of one block scaled every other block up 390 times,
without a word. :func:`dropouts` finds them against the background: every pattern passes it
(a pattern that lights only the scene's dark part is dim, not empty), so a block holding a
hundredth of what its dwell gives at the background rate was not measuring. A pattern that
shows almost no light (a dark frame) may rightly hold nothing and is not screened, nor is an
acquisition without background.

**A partial period.** A gated detector (on for part of the code period) or a TDC whose range
is shorter than the period (a PicoHarp's 4096 bins at 4 ps cover 16.4 ns) records nothing in
the rest of the period. The matched filter still reads the returns (a pseudo-random code
spreads each over the whole period), but a partial period's correlation with the code is no
longer two-valued: its sidelobes read as returns at every delay, which the outside-the-gate
check took for returns outside the range gate (72-77 % "outside" a gate that held the whole
scene, in the same audit). :func:`tdc_range_note` reads the first from the file's header and
:func:`empty_window` the second from the histograms.

Written here: each is a few NumPy reductions over the blocks' totals; no library does this
screening of a marker-split time-tag file.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

__all__ = ["DARK_PATTERN", "DROPOUT_EXPECTED", "DROPOUT_SHARE", "EMPTY_MIN_BINS",
           "EMPTY_MIN_MEAN", "FLOOR_QUANTILE", "dropout_note", "dropouts", "empty_window",
           "empty_window_note", "MeasuredBlocks", "measured_blocks", "screen_blocks",
           "tdc_range_note"]

#: a block holding fewer than this share of the photons its dwell gives at the acquisition's
#: background rate alone is no measurement (the background reaches the detector whatever
#: the pattern shows: a pattern that lights only the scene's dark part is dim, not empty)
DROPOUT_SHARE = 0.01
#: the quantile of the histograms' occupied bins read as the background's floor (the
#: code's zeros under a return hold background alone)
FLOOR_QUANTILE = 0.05
#: the background photons a block's dwell must give, at least, for its few to say anything:
#: under a Poisson draw of mean 30, 0.3 or fewer is a chance of 1e-13 (an acquisition
#: without background, where a pattern lighting nothing bright may rightly hold nothing, is
#: not screened)
DROPOUT_EXPECTED = 30.0
#: a pattern showing less than this share of the median pattern's light (the sum of its
#: mirrors) is a dark frame, whose few photons are what it should hold
DARK_PATTERN = 0.05
#: the shortest run of empty bins read as a part of the period that records nothing (a run
#: of the code's own zeros, where a flat target returns no photon, is shorter: see
#: :func:`empty_window`)
EMPTY_MIN_BINS = 8
#: the photons the other bins must hold on average for an empty run to say anything
EMPTY_MIN_MEAN = 20.0


def dropouts(counts: Any, periods: Any, patterns: Any, total: Any,
             code: Any = None, window: tuple[int, int] | None = None) -> np.ndarray:
    """The blocks whose photons are too few for their dwell: a dropout or a stall.

    Parameters
    ----------
    counts : array_like, shape (M,)
        Photons per block.
    periods : array_like, shape (M,)
        Each block's dwell in code periods (> 0).
    patterns : array_like, shape (M, Q)
        The pattern shown in each block (its light: the sum of its mirrors' values).
    total : array_like, shape (L,)
        The acquisition's histogram over the code period (all blocks summed).
    code : array_like, shape (L,), optional
        The code, for :func:`empty_window` (a part of the period never recorded is left out
        of the background's floor); None: every bin is recorded.
    window : (int, int), optional
        :func:`empty_window` of ``total`` where the caller has it (``code`` is then not
        read).

    Returns
    -------
    ndarray of int
        The flagged blocks, increasing: those holding fewer than :data:`DROPOUT_SHARE` of the
        photons the background alone gives over their dwell, where that is
        :data:`DROPOUT_EXPECTED` or more and the block's pattern shows at least
        :data:`DARK_PATTERN` of the median pattern's light. The background per bin and
        period is the :data:`FLOOR_QUANTILE` quantile of ``total``'s recorded bins over the
        blocks' dwells (each at most twice the median: a stall's periods hold nothing): with
        little background most of the code's zeros hold no photon and the floor is 0 (the
        quantile of the occupied bins alone was the signal's, and a dark night's blocks that
        lit nothing were flagged: a review of 2026-11-30).
    """
    c = np.asarray(counts, dtype=np.float64)
    n = np.maximum(np.asarray(periods, dtype=np.float64), 1.0)
    h = np.asarray(total, dtype=np.float64)
    recorded = np.ones(h.size, bool)
    if window is None and code is not None:
        window = empty_window(h, code)
    if window is not None:
        recorded[(window[0] + np.arange(window[1])) % h.size] = False
    if c.size < 3 or not (h[recorded] > 0).any():
        return np.zeros(0, np.int64)
    floor = float(np.quantile(h[recorded], FLOOR_QUANTILE))
    per_bin = floor / float(np.minimum(n, 2.0 * np.median(n)).sum())
    expected = n * per_bin * int(recorded.sum())  # background photons over each dwell
    # (mirror states in [0, 1], checked by the callers; summed in float64 without a copy of
    # the whole set: a clipped float64 copy peaked at 1 GB for 4096 patterns of 128 x 128)
    light = np.asarray(patterns).sum(axis=1, dtype=np.float64)
    lit = light >= DARK_PATTERN * np.median(light)
    flagged = lit & (expected >= DROPOUT_EXPECTED) & (c < DROPOUT_SHARE * expected)
    return np.flatnonzero(flagged) if flagged.sum() < c.size else np.zeros(0, np.int64)


def dropout_note(flagged: np.ndarray, counts: Any, periods: Any,
                 names: Any = None) -> str:
    """One line naming the blocks :func:`dropouts` flagged (``flagged``, indices into
    ``counts`` and ``periods``; ``names``: each row's pattern number, default the index) and
    why they are left out."""
    from ..io.ptu_blocks import block_list

    c = np.asarray(counts, dtype=np.float64)
    n = np.asarray(periods, dtype=np.float64)
    names = np.arange(c.size) if names is None else np.asarray(names)
    keep = np.setdiff1d(np.arange(c.size), flagged)
    typical = float(np.median(c[keep] / np.maximum(n[keep], 1.0)))
    worst = int(flagged[int(np.argmax(n[flagged]))])
    return (f"the blocks of {flagged.size} pattern(s) ({block_list(names[flagged])}) hold "
            f"almost no photons for their dwell: {int(c[worst])} over {int(n[worst])} code periods "
            f"(pattern {int(names[worst])}), where the other blocks count {typical:.3g} per "
            f"period (the detector or the laser off: an overload shutdown, an interlock, a "
            f"shutter; or a TCSPC running on while the DMD or the laser waited): their pattern "
            f"rows are left out of the solve")


def tdc_range_note(header: dict, resolution_s: float, period_s: float) -> str | None:
    """A word where the TDC's range (its largest delay field times its resolution, by the
    record type of the file's header) is shorter than the sync period ``period_s`` (the
    code's, or D of them under a sync divider D): photons later in the period are never
    recorded. None where it covers the period, or the record type is unknown."""
    from ..io.ptu_format import _FAMILY, _T3_BY_CODE

    known = _T3_BY_CODE.get(header.get("record_type_code"))
    if known is None or not (resolution_s > 0 and period_s > 0):
        return None
    span = _FAMILY[known[1]][1] * resolution_s
    if span >= period_s * (1.0 - 1e-6):
        return None
    return (f"the TDC records delays up to {span * 1e9:.4g} ns ({_FAMILY[known[1]][1]} steps "
            f"of {resolution_s * 1e12:.4g} ps, {known[0]} records) of the {period_s * 1e9:.4g} "
            f"ns sync period: {1 - span / period_s:.0%} of the period is never recorded, and "
            f"its photons are lost; record with a coarser resolution (a longer TDC step, or "
            f"the instrument's binning) so that the range covers the period")


def _longest_run(empty: np.ndarray) -> tuple[int, int]:
    """(start, length) of the longest circular run of True in ``empty`` ((0, 0): none)."""
    if not empty.any():
        return 0, 0
    if empty.all():
        return 0, int(empty.size)
    shift = int(np.flatnonzero(~empty)[0])  # start the circle at a filled bin
    e = np.roll(empty, -shift)
    edges = np.diff(np.concatenate([[0], e.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    i = int(np.argmax(ends - starts))
    return int((starts[i] + shift) % empty.size), int(ends[i] - starts[i])


def empty_window(total: Any, code: Any) -> tuple[int, int] | None:
    """The part of the code period in which the whole acquisition holds no photon, where it
    says the instrument records nothing there.

    Parameters
    ----------
    total : array_like, shape (L,)
        The acquisition's histogram over the code period (all blocks summed).
    code : array_like, shape (L,)
        The code, one bin per bit.

    Returns
    -------
    (start, length) or None
        The longest circular run of empty bins, where it is at least :data:`EMPTY_MIN_BINS`
        bins and twice the code's longest run of zeros plus one (a flat target without
        background returns nothing under the code's zeros, one bin more where its return
        straddles two bins) and the other bins hold :data:`EMPTY_MIN_MEAN` photons or more on
        average; else None.
    """
    h = np.asarray(total, dtype=np.float64)
    empty = h <= 0
    start, length = _longest_run(empty)
    if not length or length == h.size:
        return None
    zeros = _longest_run(np.asarray(code) <= 0)[1]
    if length < max(EMPTY_MIN_BINS, 2 * zeros + 1):
        return None
    if h[~empty].mean() < EMPTY_MIN_MEAN:
        return None
    return start, length


def empty_window_note(window: tuple[int, int], total: Any) -> str:
    """One line on the part of the period :func:`empty_window` found."""
    h = np.asarray(total, dtype=np.float64)
    start, length = window
    end = (start + length - 1) % h.size
    return (f"the histograms hold no photon in bins {start}-{end} of the {h.size}-bin code "
            f"period ({length / h.size:.0%} of it), over the whole acquisition, where the other "
            f"bins average {h[h > 0].mean():.3g}: a gated detector, or a TDC range shorter than "
            f"the period? The returns are read from the rest of the period (the code spreads "
            f"each over all of it), with sidelobes a full period would not have; the share of "
            f"returns outside the range gate is not read (those sidelobes read as returns at "
            f"every delay)")


def screen_blocks(hist: np.ndarray, periods: np.ndarray, patterns: Any, code: Any,
                  data: Any, names: Any = None) -> tuple[np.ndarray, list[str], bool]:
    """The screening ``reconstruct`` and ``calibrate`` apply to a measured file's blocks.

    Parameters
    ----------
    hist : ndarray, shape (M, L)
        Each block's histogram.
    periods : ndarray, shape (M,)
        Each block's dwell in code periods.
    patterns : array_like, shape (M, Q)
        The pattern of each block.
    code : array_like, shape (L,)
        The code.
    data : spslidar.io.PtuAcquisition
        The file read (its header, resolution and sync period).
    names : array_like, optional
        Each row's pattern number (its row in ``--patterns``; default the row).

    Returns
    -------
    keep : ndarray of int
        The rows to solve (without :func:`dropouts`' blocks).
    notes : list of str
        One line each: the blocks left out, a part of the period never recorded.
    partial : bool
        Whether a part of the period is never recorded (the outside-the-gate share is then
        not read).
    """
    notes = []
    counts = hist.sum(axis=1)
    total = hist.sum(axis=0)
    window = empty_window(total, code)
    gone = dropouts(counts, periods, patterns, total, window=window)
    keep = np.setdiff1d(np.arange(hist.shape[0]), gone)
    if gone.size:
        notes.append(dropout_note(gone, counts, periods, names))
        total = hist[keep].sum(axis=0)  # (the kept blocks' own, as solved)
        window = empty_window(total, code)
    note = tdc_range_note(data.header, data.resolution_s, data.sync_period_s)
    if note is None and window is not None:
        note = empty_window_note(window, total)
    notes += [note] if note else []
    return keep, notes, note is not None


class MeasuredBlocks(NamedTuple):
    """What :func:`measured_blocks` gives: ``keep`` (the rows solved), ``hist`` (their
    histograms, corrected for pile-up where a dead time was given), ``noise_totals`` (the
    corrected counts' noise totals, or None), ``pile`` (``metrics.json``'s ``detector``),
    ``drift`` (:func:`~spslidar.pipeline.drift.timing_drift`), ``notes`` (the warnings, in
    order) and ``partial`` (a part of the period never recorded)."""

    keep: np.ndarray
    hist: np.ndarray
    noise_totals: np.ndarray | None
    pile: dict
    drift: Any
    notes: list[str]
    partial: bool


def measured_blocks(hist: np.ndarray, counts: Any, periods: Any, patterns: Any, code: Any,
                    data: Any, detector: Any, channel: Any, bin_width: float,
                    names: Any = None) -> MeasuredBlocks:
    """A measured file's blocks as ``reconstruct`` and ``calibrate`` both take them:
    screened (:func:`screen_blocks`), the kept ones through the detector's dead time
    (:func:`~spslidar.pipeline.deadtime.apply_dead_time`, each with its own dwell, before the
    dwells are evened out), and their timing drift read
    (:func:`~spslidar.pipeline.drift.timing_drift`). ``counts``: each row's photons;
    ``periods``: each row's exposure in code periods; ``names``: each row's pattern number
    (default the row), for the warnings; ``bin_width``: seconds a bin."""
    from .deadtime import apply_dead_time
    from .drift import drift_note, timing_drift

    keep, notes, partial = screen_blocks(hist, periods, patterns, code, data, names)
    rows = slice(None) if keep.size == hist.shape[0] else keep  # (no copy where all stay)
    names = np.arange(hist.shape[0]) if names is None else np.asarray(names)
    fixed, noise_totals, pile, pile_notes = apply_dead_time(
        hist[rows], np.asarray(counts)[rows], np.asarray(periods)[rows],
        np.size(code) * bin_width, detector, channel, data.detection_gaps, names[rows])
    drift = timing_drift(fixed, code)
    note = drift_note(drift, bin_width)
    return MeasuredBlocks(keep, fixed, noise_totals, pile, drift,
                          notes + pile_notes + ([note] if note else []), partial)
