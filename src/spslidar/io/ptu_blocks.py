"""The PTU reader's helpers: the gaps between a channel's detections, the words on its
blocks, and the histograms' bins (split from :mod:`spslidar.io.ptu` to keep each module
short; the reader re-exports the public names)."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["BOUNCE_TIME_S", "GAP_EDGES_S", "block_list", "twice_as_long"]


#: the histogram of the gaps between a channel's detections: edges spaced 1.2 % apart from
#: 0.1 ns to 1 ms, the dead times a detector may be given (a linear 0.5 ns grid stopped at
#: 4 us, and longer dead times went unchecked: a review)
GAP_EDGES_S = np.logspace(-10, -3, 1401)
#: a marker repeated within this time of its pattern's is a bounce (a DMD trigger's ringing;
#: :mod:`spslidar.pipeline.blocks` merges such blocks, where the time is at most a tenth of
#: the typical dwell: a short code's periods are tens of nanoseconds, and a bounce three
#: 255 ns periods late was taken as a pattern and the last pattern dropped, an outside audit
#: of 2026-11-30)
BOUNCE_TIME_S = 10e-6


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
        for c in np.unique(ch):
            c = int(c)
            tc = t[ch == c]
            if c in self.last:
                tc = np.concatenate(([self.last[c]], tc))
            self.last[c] = float(tc[-1])
            d = np.diff(tc)
            if not d.size:
                continue
            self.n[c] = self.n.get(c, 0) + d.size
            self.shortest[c] = min(self.shortest.get(c, np.inf), float(d.min()))
            h = np.bincount(np.searchsorted(GAP_EDGES_S, d, side="right"),
                            minlength=GAP_EDGES_S.size + 1)
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
