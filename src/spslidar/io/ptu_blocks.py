"""The PTU reader's helpers: the gaps between a channel's detections, the words on its
blocks, the histograms' bins and the resolution's checks (split from :mod:`spslidar.io.ptu`
to keep each module short; import them from here)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ConfigError
from .ptu_format import _FAMILY

__all__ = ["BACK_SYNCS", "BOUNCE_TIME_S", "GAP_EDGES_S", "accumulate", "block_list", "gap_bins",
           "twice_as_long"]


#: the bits of a float64 below its first 6 mantissa bits: the edges below have them 0
_GAP_SHIFT = 46
#: the histogram of the gaps between a channel's detections: edges 1/64 of an octave apart
#: (0.8-1.6 %) from 2^-34 s (58 ps) to 2^-9 s (1.95 ms), the dead times a detector may be
#: given (a linear 0.5 ns grid stopped at 4 us, and longer dead times went unchecked: a
#: review). Each edge is a float64 whose last 46 mantissa bits are 0, so a gap's bin is its
#: bits shifted (:func:`gap_bins`); 1 401 edges spaced by ``np.logspace`` took
#: ``searchsorted`` a third of a 2e7-photon file's reading
GAP_EDGES_S = (2.0 ** np.arange(-34, -9)[:, None] * (1 + np.arange(64) / 64)).ravel()
GAP_EDGES_S = np.append(GAP_EDGES_S, 2.0 ** -9)
_GAP_KEY0 = int(GAP_EDGES_S[:1].view(np.int64)[0] >> _GAP_SHIFT)
#: a marker repeated within this time of its pattern's is a bounce (a DMD trigger's ringing;
#: :mod:`spslidar.pipeline.blocks` merges such blocks, where the time is at most a tenth of
#: the typical dwell: a short code's periods are tens of nanoseconds, and a bounce three
#: 255 ns periods late was taken as a pattern and the last pattern dropped, an outside audit
#: of 2026-11-30)
BOUNCE_TIME_S = 10e-6


def accumulate(hist: np.ndarray, blocks: np.ndarray, bins: np.ndarray) -> None:
    """``hist[blocks[i], bins[i]] += 1`` for every photon of a chunk, in memory bounded by the
    chunk (``blocks`` non-decreasing)."""
    n_bins = hist.shape[1]
    b0, b1 = int(blocks[0]), int(blocks[-1])
    flat = (blocks - b0) * n_bins + bins
    span = (b1 - b0 + 1) * n_bins
    if span <= max(1 << 16, 4 * flat.size):  # dense: one bincount over the chunk's blocks
        hist[b0 : b1 + 1] += np.bincount(flat, minlength=span).reshape(-1, n_bins)
    else:  # sparse (a few photons over many blocks): add each occupied bin once
        cells, counts = np.unique(flat, return_counts=True)
        hist.reshape(-1)[b0 * n_bins + cells] += counts.astype(hist.dtype)


def _channels(channel: Any, family: str, record_type: str, path: str) -> np.ndarray | None:
    """The selected photon channels as a sorted int array (``None``: all)."""
    if channel is None:
        return None
    values = np.atleast_1d(np.asarray(channel))
    if values.size == 0 or values.ndim != 1 or values.dtype.kind not in "iu" or (
            values.min() < 0):
        raise ConfigError(f"channel must be a detector channel number >= 0 (in Python also a "
                          f"list of them), got {channel!r}")
    top = _FAMILY[family][2]
    if values.max() >= top:  # no record of this type can hold it
        raise ConfigError(
            f"{path!r} has no photons on channel {int(values.max())}: {record_type} records "
            f"number detector channels 0..{top - 1} (from 0; a PicoHarp's inputs 1-4 are 0-3)")
    return np.unique(values).astype(np.int64)


def _by_channel(ch: np.ndarray) -> list[tuple[int, Any]]:
    """Each channel of a chunk's photons and what selects its photons: the whole chunk where
    it holds one channel (the common case: no mask), else a mask per channel."""
    lo, hi = int(ch.min()), int(ch.max())
    if lo == hi:
        return [(lo, slice(None))]
    return [(c, ch == c) for c in np.unique(ch).tolist()]


class _ChannelHists:
    """Each detector channel's kept photons over the code period (the reader's
    ``channel_histograms``) and in each block: nothing is counted while every photon so far
    is of one channel (the common case costs nothing); where a second one comes, the first's
    are the histograms' sums so far, and each chunk is then counted by channel."""

    def __init__(self, n_bins: int, rows: int):
        self.n_bins, self.rows, self.only = n_bins, rows, None
        self.out: dict[int, np.ndarray] = {}
        self.blocks: dict[int, np.ndarray] = {}

    def add(self, ch: np.ndarray, bins: np.ndarray, block: np.ndarray,
            hist: np.ndarray) -> None:
        """A chunk's kept photons, their bins and blocks (``hist``: the histograms before
        they are added)."""
        chunk = _by_channel(ch)
        if not self.out:
            if len(chunk) == 1 and self.only in (None, chunk[0][0]):
                self.only = chunk[0][0]
                return
            if self.only is not None:
                self.out[self.only] = hist.sum(axis=0, dtype=np.int64)
                self.blocks[self.only] = hist.sum(axis=1, dtype=np.int64)
        for c, mine in chunk:
            h = np.bincount(bins[mine], minlength=self.n_bins).astype(np.int64)
            b = np.bincount(block[mine], minlength=self.rows).astype(np.int64)
            self.out[c] = self.out[c] + h if c in self.out else h
            self.blocks[c] = self.blocks[c] + b if c in self.blocks else b

    def follow(self, dwell: np.ndarray) -> dict[int, float]:
        """Each channel's photon rate over the blocks, its spread against a constant rate's
        (Poisson) spread: about 1 for a channel that does not follow the patterns (a laser
        monitor, a reference), more for one that sees the scene through them; empty for one
        channel."""
        d = np.asarray(dwell, np.float64)
        ok = d > 0
        out = {}
        for c, counts in self.blocks.items():
            n = counts[: d.size][ok].astype(np.float64)
            if n.size < 8 or not n.sum():
                out[c] = 0.0
                continue
            rate = n / d[ok]
            poisson = float(np.mean(n / d[ok] ** 2))
            out[c] = float(np.var(rate) / poisson) if poisson > 0 else 0.0
        return out


def _shift_table(shifts: Any, rebin: Any, n_bins: int, path: str) -> np.ndarray | None:
    """``channel_shifts`` as a table by channel (bins, ``0 <= k < n_bins``), or None; one
    line where it cannot apply (a TDC bin split between bits, or not whole bins)."""
    if not shifts:
        return None
    if rebin is not None:
        raise ConfigError(f"{path!r}: channels cannot be aligned through a TDC bin split between "
                          f"the code's bits")
    table = np.zeros(128, np.int64)
    for c, k in dict(shifts).items():
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or not (
                isinstance(c, int | np.integer) and 0 <= c < 128):
            raise ConfigError(f"channel_shifts must map channel numbers to whole bins, got "
                              f"{shifts!r}")
        table[int(c)] = int(k) % n_bins
    return table


def gap_bins(gaps: np.ndarray) -> np.ndarray:
    """How many of :data:`GAP_EDGES_S` each gap (seconds, float64) reaches,
    ``np.searchsorted(GAP_EDGES_S, gaps, side="right")`` exactly, from the float's bits: a
    positive float64's bits, as an integer, grow with it, and the edges' differ by one in
    the bits above the last 46 (written here: 5-16 times faster than the search on
    5e6 gaps, 2026-11-30). A gap of 0 or below reaches none."""
    k = np.ascontiguousarray(gaps, dtype=np.float64).view(np.int64) >> _GAP_SHIFT
    k -= _GAP_KEY0 - 1
    return np.clip(k, 0, GAP_EDGES_S.size, out=k)


class _Gaps:
    """The gaps between consecutive detections on each channel, chunk by chunk (records are
    in arrival order); written here: a running difference no time-tag library keeps."""

    def __init__(self, period: float, res: float):
        self.period, self.res = float(period), float(res)
        self.last: dict[int, float] = {}
        self.shortest: dict[int, float] = {}
        self.n: dict[int, int] = {}
        self.counts: dict[int, np.ndarray] = {}

    def add(self, syncs: np.ndarray, dtime: np.ndarray, ch: np.ndarray) -> None:
        if not self.period > 0:
            return
        t = syncs.astype(np.float64) * self.period + dtime.astype(np.float64) * self.res
        if not ch.size:
            return
        for c, mine in _by_channel(ch):
            tc = t[mine]
            if c in self.last:
                tc = np.concatenate(([self.last[c]], tc))
            self.last[c] = float(tc[-1])
            d = np.diff(tc)
            if not d.size:
                continue
            self.n[c] = self.n.get(c, 0) + d.size
            self.shortest[c] = min(self.shortest.get(c, np.inf), float(d.min()))
            h = np.bincount(gap_bins(d), minlength=GAP_EDGES_S.size + 1)
            self.counts[c] = self.counts.get(c, 0) + h

    def result(self) -> dict[int, Any]:
        return {c: {"shortest_s": self.shortest[c], "n": self.n[c],
                    "counts": np.asarray(self.counts[c])} for c in self.n}


def block_list(blocks: np.ndarray) -> str:
    """Block numbers for a message: the first five, then "..."."""
    return (", ".join(str(int(k)) for k in blocks[:5]) + (", ..." if len(blocks) > 5 else ""))


def twice_as_long(dwell: np.ndarray) -> tuple[np.ndarray, float]:
    """The blocks lasting about twice (1.7 to 2.3 times) the median ``dwell``, a marker missed
    between two patterns, and that median (the reader's refusal of too few blocks and
    :mod:`spslidar.pipeline.blocks`' word where the count still matches)."""
    d = np.asarray(dwell, dtype=np.float64)
    typ = float(np.median(d))
    if not typ > 0:
        return np.zeros(0, np.int64), typ
    return np.flatnonzero((d > 1.7 * typ) & (d < 2.3 * typ)), typ


def _missed_note(starts: np.ndarray, last_sync: int, edge: str = "start", fold: int = 1) -> str:
    """Where blocks last about twice the others' dwell, the words naming them (a marker
    missed there); empty where none does (a missing marker was refused without saying where:
    an outside audit of 2026-11-30). ``starts``: the markers' syncs; with markers at the
    patterns' ends (``edge="end"``) the span from marker k to k + 1 is block k + 1; ``fold``
    code periods a sync. The last block, whose end the file does not record, is left out."""
    if starts.size < 3:
        return ""
    dwell = fold * np.diff(np.append(starts, last_sync + 1)).astype(np.float64)
    long, typ = twice_as_long(dwell[:-1])
    if not long.size:
        return ""
    long = long + (edge == "end")
    return (f" (block {block_list(long)} last{'s' if long.size == 1 else ''} about twice the "
            f"{typ:.0f} code periods of the others: a marker missed there?)")


def _rebin(hist: np.ndarray, width: float, n_bins: int) -> np.ndarray:
    """``(rows, n)`` counts in bins of ``1 / width`` of a code bit split between the code's
    ``n_bins`` bits by overlap (each bin's photons taken as spread evenly over it; the last
    bin's part beyond the code period holds none, so every photon is kept), as float32.
    Written here: a sparse matrix of at most two weights a row (SciPy), which no binning
    library offers for a bin that straddles two bits."""
    from scipy import sparse

    n = hist.shape[1]
    j = np.arange(n, dtype=np.float64)
    end = np.minimum(j + 1.0, n_bins * width)  # (the period ends inside the last bin)
    first = np.minimum(np.floor(j / width).astype(np.int64), n_bins - 1)
    edge = (first + 1) * width  # the first bit's end
    share = (np.minimum(end, edge) - j) / (end - j)
    rows = np.concatenate([np.arange(n), np.arange(n)])
    cols = np.concatenate([first, np.minimum(first + 1, n_bins - 1)])
    vals = np.concatenate([share, 1.0 - share])
    w = sparse.csr_matrix((vals, (rows, cols)), shape=(n, n_bins)).T.tocsr()
    out = np.empty((hist.shape[0], n_bins), np.float32)
    step = max(1, (1 << 22) // max(1, n))  # (rows at a time: memory bounded by a block)
    for r in range(0, hist.shape[0], step):
        out[r : r + step] = (w @ hist[r : r + step].T.astype(np.float64)).T
    return out


def _to_float32(hist: np.ndarray) -> np.ndarray:
    """The int32 counts as float32 in the same memory (block by block: no full copy); int64
    counts (a file of more than 2^31 - 1 photons) as a new float32 array."""
    if hist.dtype != np.int32:
        return hist.astype(np.float32)
    out = hist.view(np.float32)
    step = max(1, (1 << 22) // max(1, hist.shape[1]))
    for r in range(0, hist.shape[0], step):
        out[r : r + step] = hist[r : r + step].copy()  # the copy: source and target overlap
    return out


#: the most dtime units one bin can merge: a T3 record's dtime field has 15 bits at most
DTIME_MAX_BINNING = 2**15


#: a bin width within this relative distance of a whole number of dtime units is that number
#: (a header's resolution is a double: 1e-10 / 4e-12 is 25.000000000000004)
WHOLE_RTOL = 1e-6
#: with a fractional ratio, dtime units are first merged into bins of at most a quarter bin
#: (this many per code bit), which are then split between the code's bits
REBIN_SUB = 4


def _check_resolution(res: float, bin_width: float | None, rtol: float, allow_binning: bool,
                      path: str) -> tuple[int, float | None]:
    """dtime units per (intermediate) bin, and with ``allow_binning`` where ``bin_width`` is
    no whole number of dtime units, the code bit's width in those bins (else ``None``); raise
    if the file's resolution disagrees with ``bin_width``."""
    if not res > 0:
        raise ConfigError(f"{path!r}: header has no dtime resolution (MeasDesc_Resolution)")
    if bin_width is None:
        return 1, None
    if not bin_width > 0:
        raise ConfigError(f"bin_width must be > 0 seconds, got {bin_width!r}")
    ratio = bin_width / res
    if not ratio <= DTIME_MAX_BINNING:  # (a 1e-300 s resolution: 1e290 units a bin, an audit)
        raise ConfigError(f"{path!r}: dtime resolution {res:.6g} s is {ratio:.3g} times finer "
                          f"than the bin width {bin_width:.6g} s (1 / --bit-rate), more than a "
                          f"T3 record's dtime field ({DTIME_MAX_BINNING} units) spans: a "
                          f"corrupt header or the wrong bit rate")
    k = max(1, round(ratio))
    close = abs(ratio - k) <= rtol * ratio
    if allow_binning and ratio > 1.0 and abs(ratio - k) > WHOLE_RTOL * ratio:
        # (a TDC of 80 ps under 100 ps bits, MultiHarp 150's, or a code clock 600 ppm off
        # the TDC's, were refused with advice that led to a second refusal: an outside audit
        # of 2026-11-30)
        pre = max(1, int(ratio // REBIN_SUB))
        return pre, ratio / pre
    if close and (k == 1 or allow_binning):
        return k, None
    hint = (f" (it is {k} dtime units: merge them with --allow-binning, allow_binning=True in "
            f"Python)" if close else
            f" (a bin of {res:.6g} s is a bit rate of {1 / res:.6g} Hz: --bit-rate {1 / res:.6g}; "
            f"or, where the code's bits are 1 / --bit-rate, --allow-binning splits its "
            f"{res:.6g} s bins between them)" if ratio > 1 else
            f" (a TDC bin wider than the code's bit cannot be split: a bin of {res:.6g} s is a "
            f"bit rate of {1 / res:.6g} Hz: --bit-rate {1 / res:.6g})")
    raise ConfigError(f"{path!r}: dtime resolution {res:.6g} s does not match the bin width "
                      f"{bin_width:.6g} s (1 / --bit-rate; within {100 * rtol:g} %){hint}")


def _fitting_codes(bins: float, width: float, tol: float) -> str:
    """What code lengths the file's sync period of ``bins`` bins (of ``width`` seconds) fits
    within ``tol`` bins, in words: the half of the sync period mismatch's message that says
    what to do."""
    import math

    head = f"the file's sync period is {bins:.2f} bins at {1e-9 / width:.6g} GHz"
    if not bins < 2.0**53:  # (an infinite or absurd period has no bits to fit: an audit)
        return f"the file's sync period is {bins:.3g} bins: check the header and the bit rate"
    lo, hi = max(1, math.ceil(bins - tol)), math.floor(bins + tol)
    if hi - lo >= 3:  # (a tolerance of several bins)
        return f"{head}: codes of {lo} to {hi} bits fit it (or check the bit rate)"
    if hi >= lo:
        fit = [f"{n}-" for n in range(lo, hi + 1)]
        said = fit[0] if len(fit) == 1 else f"{', '.join(fit[:-1])} or {fit[-1]}"
        return f"{head}: a {said}bit code fits it (or check the bit rate)"
    near = max(1, round(bins))
    return (f"{head}: no whole number of bits fits it within {tol:g} bins (the nearest, {near}, "
            f"is {bins - near:+.3g} bins off); check the bit rate")


#: the steps back of a file's sync count that :func:`_check_forward` lets through
BACK_SYNCS = 2


def _check_forward(syncs: np.ndarray, before: int, path: str) -> None:
    """A file's events in time order, or one line: two files joined end to end, each counting
    its syncs from 0, run backwards where the second starts, and the block across the join
    was read as one code period long and scaled up 2 100 times, the map ruined under a
    warning of short dwells (an outside lab audit of 2026-11-30)."""
    # (a step back of a sync or two is let through: a marker a sync behind a photon, were any
    # hardware to record one so; a join restarts its count far behind: a review)
    back = np.flatnonzero(np.diff(np.concatenate([[before], syncs])) < -BACK_SYNCS)
    if back.size:
        i = int(back[0])
        prev = before if i == 0 else int(syncs[i - 1])
        raise ConfigError(f"{path!r}: its sync count runs backwards (sync {int(syncs[i])} "
                          f"after {prev}), which no acquisition records: files joined end to "
                          f"end, each counting its syncs from 0? Reconstruct each file with "
                          f"its own patterns")
