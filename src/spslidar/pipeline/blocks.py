"""A measured file's marker-delimited blocks against the pattern rows shown.

A real acquisition's markers are not always one per pattern at its start: an end-of-
acquisition marker adds a block after the last pattern, an arming (or start) pulse one before
the first, and some DMD controllers mark the *end* of each pattern. Read the wrong way, every
pattern is paired with its neighbour's photons and the depth map is noise while the run says
nothing (an outside audit of 2026-11-29, with files from its own PTU writer: a median error of
0.25 m against 2 mm). :func:`read_blocks` reads the file with two blocks more than the patterns
(:func:`spslidar.io.read_ptu_histograms`'s ``extra_blocks``), keeps the ``M`` that are the
patterns, and says, in one line each, what it left out and what looks like a marker read at
the wrong edge (``--marker-edge``).
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any

import numpy as np

from ..errors import ConfigError

__all__ = ["BOUNCE_PERIODS", "CHANNEL_SHARE", "DROPPED_SHARE", "SHORT_BLOCK", "channels_holding",
           "block_patterns", "channel_note", "channels_read", "check_blocks", "check_frame",
           "check_repeats", "drop_frozen", "fold_repeats", "read_blocks"]

#: photons left out (before the first marker, or past the code period) beyond this share of
#: the file's are said (they are always left out: no pattern, or no bin, is known for them)
DROPPED_SHARE = 0.05
#: a block shorter than this share of the median pattern's dwell, and as poor in photons, is
#: no pattern (an arming or end-of-acquisition marker's)
SHORT_BLOCK = 0.5
#: a marker read at the wrong edge of its pattern: the periods outside the first (last)
#: block within this share of a pattern's dwell, and a block of at most this many periods
#: at the other end
EDGE_SPAN = 0.1
EDGE_BLOCK_PERIODS = 2
#: a block between two others of at most this many code periods (or this share of the median
#: dwell, where that is more), where the patterns last at least ``BOUNCE_MIN_DWELL`` periods,
#: is a marker repeated (a DMD trigger's bounce): its photons are the next block's pattern's
BOUNCE_PERIODS = 2
BOUNCE_SHARE = 0.01
BOUNCE_MIN_DWELL = 50
#: a marker repeated within :data:`spslidar.io.ptu_blocks.BOUNCE_TIME_S` of its pattern's is a
#: bounce too, where that is at most this share of the typical dwell
BOUNCE_MAX_SHARE = 0.1
#: bounces a file may hold beyond its arming and end markers (read as extra blocks, then
#: merged): at least this many, or one pattern in ``BOUNCE_ROWS``
BOUNCE_EXTRA = 4
BOUNCE_ROWS = 16
#: a second detector channel holding at least this share of the file's photons, read
#: without --channel, is said (its photons are merged into the histograms)
CHANNEL_SHARE = 0.01


def check_blocks(data, m: int, ptu, merged: int = 0, repeats: int = 1) -> None:
    """The file's marker-delimited blocks against the ``m`` pattern blocks (``--patterns``'
    rows times ``repeats``): more blocks than that (an arming and an end-of-acquisition
    marker aside, and ``merged`` bounces) is a mismatch, refused in one line (``calibrate``
    used the first rows' blocks of such a file and said nothing)."""
    if data.n_markers - merged > m + 2:  # an end-of-acquisition or arming marker is common
        bounced = f" ({merged} of them a marker's bounce, merged)" if merged else ""
        rows = m // repeats
        shown = f" shown {repeats} times ({m} blocks)" if repeats > 1 else ""
        raise ConfigError(f"{os.fspath(ptu)!r} has {data.n_markers} marker-delimited blocks"
                          f"{bounced} but --patterns has {rows} rows{shown}: the patterns "
                          f"shown do not match the file (or --marker names the wrong input)"
                          f"{_repeats_hint(data.n_markers - merged, rows, repeats)}")


def _repeats_hint(blocks: int, m: int, given: int = 1) -> str:
    """Where ``blocks`` is a whole number of times the ``m`` pattern rows (to an arming and
    an end marker), other than the ``given`` repeats: the sequence shown that many times,
    and the flag that says so."""
    for extra in range(3):
        k, rest = divmod(blocks - extra, m)
        if k >= 2 and rest == 0 and k != given:
            return f"; or the sequence shown {k} times in a row? pass --repeats {k}"
    return ""


def check_repeats(repeats: Any) -> int:
    """``--repeats`` (times the pattern sequence was shown in a row) as a whole number >= 1,
    or one line (:class:`ConfigError`): not a bool, text or a fraction."""
    from ..arrays import real_number

    value = real_number(repeats)
    if value is None or not (math.isfinite(value) and value >= 1 and value == int(value)):
        raise ConfigError(f"--repeats must be a whole number of times the pattern sequence "
                          f"was shown, 1 or more, got {repeats!r}")
    return int(value)


def block_patterns(shown: np.ndarray, repeats: int) -> np.ndarray:
    """What the screening of a file's blocks reads of each block's pattern: the patterns
    shown, or under ``repeats`` each block's light alone, a column (block ``r M + i`` showing
    pattern ``i``; a ``(K M, Q)`` copy of the patterns would be K times their memory, and ran
    out of it at K = 10^6: a review)."""
    if repeats == 1:
        return shown
    return np.tile(shown.sum(axis=1, dtype=np.float64), repeats)[:, None]


def check_frame(frame: Any, repeats: int) -> int | None:
    """``--frame`` (one repeat of the sequence, from 0) as an int in ``[0, repeats)``, or
    None; one line (:class:`ConfigError`) otherwise, or without ``--repeats`` of 2 or more."""
    if frame is None:
        return None
    from ..arrays import real_number

    value = real_number(frame)
    if value is None or not (math.isfinite(value) and value == int(value)):
        raise ConfigError(f"--frame must be a whole number, a repeat of the sequence from 0, "
                          f"got {frame!r}")
    if repeats < 2:
        raise ConfigError("--frame reads one repeat of a sequence shown several times: give "
                          "--repeats K (2 or more), or several --ptu files, too")
    if not 0 <= value < repeats:
        raise ConfigError(f"--frame must be a repeat of the sequence read, 0 to {repeats - 1} "
                          f"(--repeats times the --ptu files: {repeats}), got {int(value)}")
    return int(value)


def fold_repeats(pattern: np.ndarray, hist: np.ndarray, periods: np.ndarray | None = None,
                 noise_totals: np.ndarray | None = None, counts: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray, Any, Any, Any]:
    """The blocks of a sequence shown several times (``--repeats``), summed per pattern.

    Parameters
    ----------
    pattern : ndarray of int, shape (B,)
        The pattern each kept block showed.
    hist : ndarray, shape (B, L)
        Each block's histogram (corrected for its own pile-up).
    periods, noise_totals, counts : ndarray, shape (B,), optional
        Each block's exposure (code periods), noise total (a pile-up correction's) and
        photons as recorded, where the caller has them.

    Returns
    -------
    patterns, hist, periods, noise_totals, counts
        One row per pattern with a kept block, increasing: its blocks' sums (a pattern's
        Poisson counts over several dwells are its counts over their sum); None for each
        optional input not given.
    """
    shown, row = np.unique(np.asarray(pattern), return_inverse=True)

    def total(values):
        if values is None:
            return None
        out = np.zeros((shown.size,) + np.shape(values)[1:], dtype=np.result_type(values))
        np.add.at(out, row, values)
        return out

    return (shown, total(np.asarray(hist, dtype=np.float64)), total(periods),
            total(noise_totals), total(counts))


def drop_frozen(data, ptu) -> tuple[Any, int, str | None]:
    """The file's last blocks where its syncs stop: two or more markers at the file's last
    sync, every event after them at that sync too (the sync signal lost, while the DMD's
    markers and the detector's photons went on). Such blocks last no code period, so no
    dwell scales them (each was read as a pattern of one period, scaled up to the mean
    dwell, or as an arming marker's block).

    Returns
    -------
    data : spslidar.io.PtuAcquisition
        Without those blocks (their photons counted as dropped after the last pattern).
    n : int
        How many were left out (0: none).
    note : str or None
        One line on them. Every block at one sync is refused (:class:`ConfigError`).
    """
    start = np.asarray(data.pattern_start_sync)
    frozen = np.flatnonzero(start == int(data.last_sync))
    if frozen.size < 2 or frozen[0] != start.size - frozen.size:
        return data, 0, None
    photons = int(data.counts_per_pattern[frozen].sum())
    if frozen.size == start.size:
        raise ConfigError(f"{os.fspath(ptu)!r}: every one of its {start.size} marker blocks "
                          f"starts at sync {int(data.last_sync)}, where the file's syncs stop "
                          f"(the sync signal missing or lost?): no block lasts a code period")
    first = int(frozen[0])
    return (_rows(data, slice(0, first), after=photons), int(frozen.size),
            f"the file's syncs stop at sync {int(data.last_sync)}: its last {frozen.size} "
            f"marker blocks (from block {first} on) start there and hold {photons} photons "
            f"in no code period (the sync signal lost?): their pattern rows are left out of "
            f"the solve")


def _typical(data) -> tuple[np.ndarray, np.ndarray, float, float]:
    """:func:`_typical_of` a read's blocks."""
    return _typical_of(data.periods_per_pattern, data.counts_per_pattern)


def _typical_of(d: Any, c: Any) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Each block's dwell and photons (float64), and the median of the blocks between the two
    ends (of all of them where there are no more than two): what a pattern's look like."""
    d = np.asarray(d, np.float64)
    c = np.asarray(c, np.float64)
    inner = slice(1, -1) if d.size > 2 else slice(None)
    return d, c, float(np.median(d[inner])), float(np.median(c[inner]))


def _drop_both_ends(data, m: int, marker: int, ptu) -> tuple[Any, str]:
    """Of ``m + 2`` blocks, the ``m`` between a short, photon-poor first and last block (an
    arming and an end-of-acquisition marker's); any other ``m + 2`` is a mismatch."""
    d, c, typ_d, typ_c = _typical(data)
    if not (_short(d[0], c[0], typ_d, typ_c) and _short(d[-1], c[-1], typ_d, typ_c)):
        raise ConfigError(f"{os.fspath(ptu)!r} has {m + 2} marker-delimited blocks but "
                          f"--patterns has {m} rows, and its first and last blocks are not both "
                          f"short of a pattern's or empty (an arming and an end marker's): the "
                          f"patterns shown do not match the file (or --marker names the wrong "
                          f"input)")
    return (_rows(data, slice(1, m + 1), before=int(c[0]), after=int(c[-1])),
            f"the file holds {m + 2} marker-delimited blocks on input {marker} for {m} pattern "
            f"rows, and its first ({int(d[0])} code periods, {int(c[0])} photons) and last "
            f"({int(d[-1])}, {int(c[-1])}) are no pattern's ({typ_d:.0f} periods, {typ_c:.0f} "
            f"photons typical): an arming and an end marker? both are left out")


def _drop_short_lead(data, marker: int) -> tuple[Any, str | None]:
    """A free-running file's first blocks that last under half a pattern's dwell (an arming
    marker before the sequence, or the first marker's bounce, which the inner blocks' merge
    does not reach) left out before the blocks are numbered, so that ``--first-pattern I``
    counts from the first whole block: kept, such a block took pattern ``I`` and every
    block after it read its neighbour's pattern (exit 0, median error 0.15 m against 0.037:
    an outside audit of stop 67). Under ``--marker-edge end`` block 0 is the pattern the
    recording's start cut, and is kept."""
    d, c, typ_d, _ = _typical(data)
    k = 0
    while k < d.size - 1 and d[k] < 0.5 * typ_d:
        k += 1
    if not k:
        return data, None
    photons = int(c[:k].sum())
    return (_rows(data, slice(k, None), before=photons),
            f"the first {k} marker block(s) on input {marker} last under half a pattern's "
            f"dwell ({', '.join(str(int(x)) for x in d[:k][:3])} of {typ_d:.0f} code periods; "
            f"{photons} photons): an arming marker or the first marker's bounce? left out, so "
            f"--first-pattern counts from the first whole block")


def _rows(data, keep: slice, before: int = 0, after: int = 0):
    """``data`` with the blocks ``keep`` only; the photons of those left out counted as
    dropped before the first pattern (``before``) or after the last (``after``), and the
    reader's word on a last block kept as a pattern of zeros dropped with that block."""
    said = [w for w in data.warnings if not (after and "kept as a pattern of zeros" in w)]
    return dataclasses.replace(
        data, histograms=data.histograms[keep], counts_per_pattern=data.counts_per_pattern[keep],
        pattern_start_sync=data.pattern_start_sync[keep],
        periods_per_pattern=data.periods_per_pattern[keep],
        settled_periods=data.settled_periods[keep] if data.settled_periods.size
        else data.settled_periods,
        n_dropped_before_first_marker=data.n_dropped_before_first_marker + before,
        n_dropped_after_last_pattern=data.n_dropped_after_last_pattern + after,
        warnings=said)


#: a block over :data:`LONG_BLOCK` patterns' dwell whose photon rate is under this share of a
#: pattern's is no pattern's (an arming marker recorded long before the sequence: its empty
#: block of two patterns' dwell was kept as pattern 0 and the last pattern dropped, an
#: outside audit of 2026-12-02); a real file's darkest line holds 7 % of the typical rate
#: (hazelnut_z1). A block of a pattern's dwell stays a pattern however dark (an all-off
#: frame, a pattern that sees no target: taken for an arming block, a review found the wrong
#: end dropped)
EMPTY_RATE = 0.02
LONG_BLOCK = 1.5


def _short(dwell: float, photons: float, typical_dwell: float, typical_photons: float) -> bool:
    """A block that is no pattern's: shorter than :data:`SHORT_BLOCK` of a pattern's dwell
    and as poor in photons, or longer than :data:`LONG_BLOCK` dwells at under
    :data:`EMPTY_RATE` of a pattern's photon rate."""
    if photons >= SHORT_BLOCK * typical_photons:
        return False
    if dwell < SHORT_BLOCK * typical_dwell:
        return True
    rate = typical_photons / max(typical_dwell, 1.0)
    return dwell > LONG_BLOCK * typical_dwell and photons / max(dwell, 1.0) < EMPTY_RATE * rate


def extra_block(d: np.ndarray, c: np.ndarray) -> tuple[str, bool, bool, float, float]:
    """Of ``m + 1`` blocks (their dwells ``d`` in code periods and photons ``c``), the one
    that is no pattern: ``"first"`` where it is short or empty (:func:`_short`) and the last
    is not, or where both are and it has the lower photon rate; else ``"last"``. Also
    whether each end is short, and a pattern's dwell and photons (the inner blocks'
    medians). ``reconstruct`` and ``inspect`` read a file's ends by this one rule."""
    d, c, typ_d, typ_c = _typical_of(d, c)
    first = _short(d[0], c[0], typ_d, typ_c)
    last = _short(d[-1], c[-1], typ_d, typ_c)
    # both ends short: an arming marker's block and a pattern cut short, or a cut pattern and
    # an end marker's; the one without a pattern's photon rate is no pattern (the last was
    # always left out, which kept an arming block as pattern 0: a review)
    drop_first = first and (not last or c[0] / max(d[0], 1.0) < c[-1] / max(d[-1], 1.0))
    return "first" if drop_first else "last", first, last, typ_d, typ_c


def _drop_extra_block(data, m: int, marker: int) -> tuple[Any, str | None]:
    """Of ``m + 1`` blocks, the ``m`` that are patterns (:func:`extra_block`)."""
    d, c = data.periods_per_pattern, data.counts_per_pattern
    which, first, last, typ_d, typ_c = extra_block(d, c)
    head = (f"the file holds {m + 1} marker-delimited blocks on input {marker} for {m} "
            f"pattern rows")
    if first and last:
        rate = typ_c / max(typ_d, 1.0)
        k = 0 if which == "first" else -1
        note = (f"{head}, and both its first ({int(d[0])} code periods, {int(c[0])} photons) "
                f"and its last block ({int(d[-1])}, {int(c[-1])}) are no pattern's "
                f"({typ_d:.0f} periods, {typ_c:.0f} photons): the {which}, at "
                f"{c[k] / max(d[k], 1.0) / max(rate, 1e-300):.2g} of a pattern's photon rate, "
                f"is left out as no pattern")
        if which == "first":
            return _rows(data, slice(1, None), before=int(c[0])), note
        return _rows(data, slice(0, m), after=int(c[-1])), note
    if first:
        return (_rows(data, slice(1, None), before=int(c[0])),
                f"{head}, and its first block ({int(d[0])} code periods, {int(c[0])} photons) "
                f"is no pattern's ({typ_d:.0f} periods, {typ_c:.0f} photons typical): an arming "
                f"or start marker? it is left out and the next {m} blocks are the patterns")
    # (a short, photon-poor last block is an end-of-acquisition marker's: left out without a
    # word; one that is not was said to last "as long as a pattern" at 53 % of its dwell, an
    # audit of 2026-11-29)
    note = None if last else (
        f"{head}, and its last block ({int(d[-1])} code periods, {int(c[-1])} photons) is no "
        f"end marker's: a pattern lasts {typ_d:.0f} periods with {typ_c:.0f} photons; it is "
        f"left out; is a row missing from --patterns?")
    return _rows(data, slice(0, m), after=int(c[-1])), note


def _merge_bounces(data, m: int, marker: int) -> tuple[Any, list[str]]:
    """Of more blocks than the ``m`` patterns, each inner block of a code period or two (a
    marker repeated within a few periods of its pattern's: a DMD trigger's bounce) merged into
    the next, at most as many as the blocks in excess, the shortest first. Left as they were,
    such a block took a pattern row and every later pattern was paired with its neighbour's
    photons, or was scaled up 2 500 times as a pattern of its own, while the warnings blamed
    the file's last block or the range gate (an outside audit of 2026-11-30: median errors of
    3-21 cm and 1 m, against 0.4 mm)."""
    n = data.n_patterns
    d = data.periods_per_pattern.astype(np.float64)
    if n <= m or n < 3:
        return data, []
    # the patterns' dwell: the median of the longer half of the inner blocks (every marker
    # may have bounced, and the median of all of them was a bounce's: a review)
    inner_d = np.sort(d[1:-1])
    typ = float(np.median(inner_d[inner_d.size // 2:]))
    if typ < BOUNCE_MIN_DWELL:  # (patterns a period or two long: no bounce can be told)
        return data, []
    from ..io.ptu_blocks import BOUNCE_TIME_S

    period_s = data.sync_period_s / max(int(getattr(data, "periods_per_sync", 1)), 1)
    in_time = BOUNCE_TIME_S / period_s if period_s > 0 else 0.0
    limit = min(max(BOUNCE_PERIODS, BOUNCE_SHARE * typ, in_time), BOUNCE_MAX_SHARE * typ)
    inner = np.arange(1, n - 1)
    short = inner[d[inner] <= max(limit, BOUNCE_PERIODS)]
    short = np.sort(short[np.argsort(d[short], kind="stable")][: n - m])
    if not short.size:
        return data, []
    keep = np.ones(n, bool)
    keep[short] = False
    photons = data.counts_per_pattern  # (each block's own, for the notes)
    hist = data.histograms.copy()
    counts = data.counts_per_pattern.copy()
    periods = data.periods_per_pattern.copy()
    settled = data.settled_periods.copy()  # (each marker's settling: the bounce's too)
    start = data.pattern_start_sync.copy()
    for k in short[::-1]:  # into the next block kept, which starts where the bounce did
        j = k + 1 + int(np.argmax(keep[k + 1:]))
        hist[j] += hist[k]
        counts[j] += counts[k]
        periods[j] += periods[k]
        if settled.size:
            settled[j] += settled[k]
        start[j] = start[k]
    data = dataclasses.replace(data, histograms=hist[keep], counts_per_pattern=counts[keep],
                               pattern_start_sync=start[keep], periods_per_pattern=periods[keep],
                               settled_periods=settled[keep] if settled.size else settled)
    from ..io.ptu_blocks import block_list

    # (short blocks after the last block a pattern long are no pattern's bounce: a burst of
    # markers after the last pattern was said to be merged into "the same pattern's" block,
    # an outside audit of 2026-11-30)
    long = np.flatnonzero(d > max(limit, BOUNCE_PERIODS))
    after = short[short > long.max()] if long.size else short[:0]
    inner_short = np.setdiff1d(short, after)
    notes = []
    if inner_short.size:
        notes.append(
            f"{inner_short.size} of the file's {data.n_markers} marker-delimited blocks on "
            f"input {marker} (block {block_list(inner_short)}) last at most "
            f"{int(d[inner_short].max())} code period(s) between two patterns' ({typ:.0f} "
            f"periods typical): a marker repeated (a DMD trigger's bounce?); each is merged, "
            f"with {int(photons[inner_short].sum())} photons in all, into the "
            f"next block, the same pattern's")
    if after.size:
        notes.append(
            f"{after.size} of the file's {data.n_markers} marker-delimited blocks on input "
            f"{marker} (block {block_list(after)}) come after the last pattern and last at "
            f"most {int(d[after].max())} code period(s) each: markers after the acquisition's "
            f"end (an end marker repeated, a bounce?); merged, with "
            f"{int(photons[after].sum())} photons, into the block after the "
            f"last pattern")
    return data, notes


def _periods(n: int) -> str:
    """``n`` code periods, in words (one period, not "1 periods")."""
    return "1 code period" if n == 1 else f"{n} code periods"


def _edge_note(data, marker: int, edge: str) -> str | None:
    """The signature of a marker read at the wrong edge of its pattern: about one pattern's
    photons and periods outside the first (``start``) or last (``end``) block, and a short
    block at the other end."""
    d, c = data.periods_per_pattern, data.counts_per_pattern
    if d.size < 3:
        return None
    typ_d, typ_c = float(np.median(d)), float(np.median(c))
    if edge == "start":
        outside, span, other = (data.n_dropped_before_first_marker,
                                int(data.pattern_start_sync[0]), d[-1])
        where, fix = "before the first marker", "end"
    else:
        outside = data.n_dropped_after_last_pattern
        span = int(data.last_sync) + 1 - int(data.pattern_start_sync[-1] + d[-1])
        where, fix, other = "after the last marker", "start", d[0]
    # a marker at the other edge leaves exactly one pattern's span outside and a block of a
    # period or two at the other end (a recording started early with start markers, and a
    # last pattern cut short, was told to pass --marker-edge end: a review). The marker's own
    # sync holds photons on both sides of it, so the span counted in whole syncs can be a
    # period short, never long: the test allows a dwell less one period to a dwell (a
    # one-period dwell read 0 against 1 and a wrong --marker-edge end went unsaid, an audit
    # of 2026-11-29; a symmetric allowance told recordings begun early to change the edge,
    # two reviews)
    if not (outside >= SHORT_BLOCK * typ_c
            and typ_d - max(EDGE_SPAN * typ_d, 1.0) <= span <= typ_d
            and other <= EDGE_BLOCK_PERIODS):
        return None
    # (a one-period dwell read "over 0 code periods ... (1 periods, ...) ... lasts 1", an
    # audit of the docs of 2026-12-01)
    over = "within a code period" if span < 1 else f"over {_periods(span)}"
    return (f"{outside} photons {over} came {where} on input {marker}, about "
            f"one pattern's ({_periods(round(typ_d))}, {typ_c:.0f} photons), and the "
            f"{'last' if edge == 'start' else 'first'} block lasts {_periods(int(other))}: "
            f"a DMD whose marker {'ends' if edge == 'start' else 'starts'} each pattern gives "
            f"this, and "
            f"read as {'starting' if edge == 'start' else 'ending'} them every pattern is paired "
            f"with its neighbour's photons; if so, pass --marker-edge {fix}")


def _double_note(data) -> str | None:
    """Inner blocks lasting about twice the others: a marker missed there, which, where the
    block count still matches the patterns (an extra marker elsewhere, an end marker), pairs
    every later pattern with its neighbour's photons (an outside audit of 2026-11-30: a
    missed marker and a bounce gave a median error of 0.9 m with only the short block
    said)."""
    from ..io.ptu_blocks import block_list, twice_as_long

    d = data.periods_per_pattern
    if d.size < 4:
        return None
    long, typ = twice_as_long(d)
    long = long[(long > 0) & (long < d.size - 1)]  # (the inner blocks)
    if not long.size:
        return None
    return (f"pattern block {block_list(long)} last{'s' if long.size == 1 else ''} about twice the "
            f"{typ:.0f} code periods of the others: a marker missed there? if so, every "
            f"pattern after it is paired with its neighbour's photons")


def channels_holding(counts: dict[int, int]) -> dict[int, int]:
    """Of photons (or detections) per channel, the channels holding at least
    :data:`CHANNEL_SHARE` of them all: each another detector."""
    total = max(sum(counts.values()), 1)
    return {c: n for c, n in counts.items() if n >= CHANNEL_SHARE * total}


def channels_read(data, channel: Any) -> list[int]:
    """The detector channels whose photons a read took: ``channel`` where one was given,
    else those holding :data:`CHANNEL_SHARE` of the file's photons (merged)."""
    if channel is not None:  # (an int, or in Python a list of them)
        return sorted({int(c) for c in np.atleast_1d(np.asarray(channel))})
    return sorted(int(c) for c in channels_holding(data.photons_per_channel))


def channel_note(cal: dict, data, channel: Any) -> str | None:
    """A word where a calibration was measured on other detector channels than an
    acquisition is read on: each channel has its own cable and electronics delay, so a
    channel's calibration moves another's depths by their difference (an outside audit of
    2026-11-30: channel 0's calibration on channel 1, cabled 0.5-3 ns later, biased every
    depth by 7.6-37.9 cm without a word). None where they agree, or where the calibration
    does not say (one written before it recorded its channels)."""
    source = cal.get("measured_from")
    measured = source.get("channels") if isinstance(source, dict) else None
    # (a file edited by hand, "measured_from": "lab A" or "channels": ["a"], was a traceback:
    # a review; such a calibration does not say its channels)
    if not (isinstance(measured, list) and all(
            isinstance(c, int) and not isinstance(c, bool) for c in measured)):
        return None
    read = channels_read(data, channel)
    if sorted(int(c) for c in measured) == read:
        return None

    def name(chs) -> str:
        return (f"channel {chs[0]}" if len(chs) == 1 else
                f"channels {', '.join(map(str, chs))} merged")

    return (f"the calibration was measured on detector {name(sorted(measured))}, and this "
            f"acquisition is read on {name(read)}: each channel has its own cable and "
            f"electronics delay (0.5 ns is 7.5 cm), so the depths may be off by their "
            f"difference; calibrate the channels read here (--channel as in reconstruct)")


def _channel_note(data) -> str | None:
    """Photons on more than one detector channel, read without ``--channel``: merged into one
    histogram, which is right for detectors that see the same returns and wrong for a laser
    monitor or a reference (an outside audit of 2026-11-30: a monitor channel at half a count
    per period was read as returns outside the range gate, without a word of it)."""
    per = channels_holding(data.photons_per_channel)
    if len(per) < 2:
        return None
    total = sum(per.values())
    listed = ", ".join(f"{c} ({100 * n / total:.3g} %)" for c, n in sorted(per.items()))
    return (f"the file holds photons on detector channels {listed}, merged into one histogram "
            f"per pattern: right for detectors that see the same returns, wrong for a laser "
            f"monitor or a reference channel; --channel C reads one (numbered from 0)")


def _lost_notes(data, marker: int, n_bins: int) -> list[str]:
    """Photons left out beyond :data:`DROPPED_SHARE` of the file's, and why."""
    notes, total = [], int(data.n_photons)
    before = int(data.n_dropped_before_first_marker)
    if total and before > DROPPED_SHARE * total:
        # (a fifth of a file's photons were dropped, said only in metrics.json: an audit)
        notes.append(f"{before} of the file's {total} photons on the channel "
                     f"({100 * before / total:.3g} %) came before the first marker on input "
                     f"{marker}, while no pattern was known, and are left out: check --marker, "
                     f"or that the acquisition started with the first pattern")
    out = int(data.n_out_of_range)
    if total and out > DROPPED_SHARE * total:
        # (a fifth, or with a sync divider of 2 half, of a file's photons were dropped
        # without a word: an audit)
        # (a divider was blamed as spanning several code periods unfolded, but PicoQuant's
        # sync period in the header is already the divided one: the real HydraHarp files
        # with dividers of 2, 4 and 8 hold every photon within it, an audit of 2026-11-29)
        divider = data.header.get("sync_divider")
        named = (f", the header's sync divider is {divider}"
                 if isinstance(divider, int | float) and divider > 1 else "")
        why = (f"the photons' TDC times run past the sync period the header gives "
               f"(MeasDesc_GlobalResolution{named}): is it the period the hardware ran at, "
               f"and --bit-rate the TDC's bin rate?")
        if data.header.get("measurement_mode") == "T2":  # (its period is the syncs' own)
            why = ("their times since the last sync record run past it: the file lacks "
                   "sync records there (the sync input's trigger level, or its dead time), "
                   "or --bit-rate is not the code's")
        notes.append(f"{out} of the file's {total} photons on the channel "
                     f"({100 * out / total:.3g} %) came at a "
                     f"{'delay' if data.header.get('measurement_mode') == 'T2' else 'TDC time'}"
                     f" past the code period ({n_bins} bins) and are left out: {why}")
    return notes


def read_blocks(ptu, m: int, n_bins: int, *, bin_width: float, marker: int = 1,
                channel: Any = None, allow_binning: bool = False,
                marker_edge: str = "start", settle: float = 0.0,
                repeats: int = 1, sync_divider: int | None = None,
                sync_channel: int | None = None,
                align_channels: bool | dict[int, int] = False,
                free_running: bool = False) -> tuple[Any, list[str]]:
    """The ``m`` pattern blocks of a measured T3 file, and what to say about them.

    Parameters
    ----------
    ptu : path
        The T3 PTU file.
    m : int
        Pattern rows shown (``--patterns``).
    n_bins : int
        Bins per code period (the code's length).
    bin_width : float
        Seconds per bin.
    marker, channel, allow_binning
        As :func:`spslidar.io.read_ptu_histograms`.
    marker_edge : {"start", "end"}
        Whether a marker starts (default) or ends its pattern.
    settle : float
        Seconds of each block's start whose photons are dropped (the reader's ``settle_s``).
    repeats : int
        Times the sequence was shown (``m`` is then its rows times this): named in a refusal.
    sync_divider : int, optional
        Code periods per sync record where the header does not say (the reader's).
    sync_channel : int, optional
        A T2 file's detector channel whose events are the syncs (the reader's).
    align_channels : bool or dict
        Detector channels read together moved onto the one with the most photons
        (:mod:`~spslidar.pipeline.skew`): ``True``, by the delays the file's own photons
        show (read twice: the delays, then the blocks); a dict, by those whole bins (a
        calibration's, :func:`~spslidar.pipeline.skew.channel_shifts`); ``False``, merged
        as recorded, a delay between them said.
    free_running : bool
        A DMD looping its sequence (``--first-pattern``): every block is read, ``m`` or more
        (fewer refused), none left out as an arming or end marker's; bounces are merged.

    Returns
    -------
    data : spslidar.io.PtuAcquisition
        ``m`` rows (fewer blocks than ``m`` is refused by the reader, more than ``m + 2``
        here); of ``m + 1`` blocks the one that is no pattern is left out, of ``m + 2`` a
        short first and last (else refused), their photons counted as dropped.
    notes : list of str
        One line each: the block left out, a marker edge that looks wrong, photons left out
        beyond :data:`DROPPED_SHARE`.
    """
    from ..arrays import real_number
    from ..io import read_ptu_histograms

    seconds = real_number(settle)  # (not a bool or text: as --dead-time is judged)
    if seconds is None or not (math.isfinite(seconds) and seconds >= 0):
        raise ConfigError(f"--settle must be a number of seconds >= 0, got {settle!r}")
    if align_channels is True:  # the delays from the file's photons, then the blocks by them
        from .skew import align_note, channel_delays, channel_shifts

        options = dict(bin_width=bin_width, marker=marker, channel=channel,
                       allow_binning=allow_binning, marker_edge=marker_edge, settle=settle,
                       repeats=repeats, sync_divider=sync_divider, sync_channel=sync_channel,
                       free_running=free_running)
        data, notes = read_blocks(ptu, m, n_bins, **options)
        delays = channel_delays(data.channel_histograms, data.channel_spread)
        shifts = channel_shifts(delays)
        note = align_note(data.channel_histograms, data.channel_spread, delays,
                          channels_read(data, channel))
        if shifts:
            data, notes = read_blocks(ptu, m, n_bins, **options, align_channels=shifts)
        # (aligned as recorded without shifts: no note of a skew was made)
        return data, notes + ([note] if note else [])
    shifts = dict(align_channels) if align_channels else None

    def read(extra: int):
        try:
            return read_ptu_histograms(ptu, n_bins, bin_width=bin_width, marker=marker,
                                       channel=channel, n_patterns=None if free_running else m,
                                       extra_blocks=0 if free_running else extra,
                                       marker_edge=marker_edge, allow_binning=allow_binning,
                                       settle_s=seconds, sync_divider=sync_divider,
                                       sync_channel=sync_channel, channel_shifts=shifts)
        except ConfigError as err:  # ("fewer than the 384 patterns" of 96 rows: say why)
            if repeats > 1 and "marker-delimited blocks" in str(err):
                raise ConfigError(f"{err} (--repeats {repeats}: {m // repeats} pattern rows "
                                  f"shown {repeats} times)") from None
            raise

    data = read(2 + max(BOUNCE_EXTRA, m // BOUNCE_ROWS))
    if free_running:  # (every block read: any number of passes, the last one cut anywhere)
        data, notes = _merge_bounces(data, m, marker)
        if marker_edge == "start":
            data, lead = _drop_short_lead(data, marker)
            notes += [lead] if lead else []
        if data.n_patterns < m:
            raise ConfigError(f"{os.fspath(ptu)!r} has {data.n_patterns} marker-delimited "
                              f"blocks on input {marker}, fewer than the {m} rows of "
                              f"--patterns: a free-running sequence (--first-pattern) must "
                              f"show each pattern at least once")
        return _said(data, ptu, notes, marker, channel, marker_edge, n_bins, bin_width,
                     bool(shifts))
    if data.n_patterns < data.n_markers <= 2 * m + 2:  # (more markers than that, up to two
        # a pattern and the arming and end markers': every marker may have bounced, so read
        # them all; the last pattern lost all but its bounce's photons, a review)
        data = read(data.n_markers - m)
    n_read = data.n_patterns
    data, notes = _merge_bounces(data, m, marker)
    check_blocks(data, m, ptu, merged=n_read - data.n_patterns, repeats=repeats)
    if data.n_patterns == m + 2:
        data, note = _drop_both_ends(data, m, marker, ptu)
        notes.append(note)
    elif data.n_patterns > m:
        data, note = _drop_extra_block(data, m, marker)
        notes += [note] if note else []
    return _said(data, ptu, notes, marker, channel, marker_edge, n_bins, bin_width,
                     bool(shifts))


def _said(data, ptu, notes: list[str], marker: int, channel: Any, marker_edge: str,
          n_bins: int, bin_width: float, shifted: bool) -> tuple[Any, list[str]]:
    """:func:`read_blocks`' last word on the blocks kept: a file without a photon in them
    refused, the notes on its marker edge, channels (``shifted``: moved by a calibration's
    shifts), missed markers and photons lost."""
    if not int(np.sum(data.counts_per_pattern)):
        # (exit 0 with an all-NaN map and "pass --marker-edge end" said of a file of markers
        # alone, while calibrate refused it: an outside audit of 2026-11-30)
        total = int(data.n_photons)
        why = ("the file holds no photons on the channel" if not total else
               f"none of the file's {total} photons on the channel lies in a pattern's block "
               f"within the code period ({int(data.n_dropped_before_first_marker)} before the "
               f"first marker, {int(data.n_dropped_after_last_pattern)} after the last "
               f"pattern, {int(data.n_out_of_range)} past the code period of {n_bins} bins)")
        raise ConfigError(f"{os.fspath(ptu)!r}: {why}: no pattern's histogram holds any (check "
                          f"--channel, --marker and --bit-rate)")
    edge = _edge_note(data, marker, marker_edge)
    mixed = _channel_note(data) if channel is None else None
    if data.channel_histograms:  # (channels read together: a cable delay between them)
        from .skew import channel_delays, monitor_note, skew_note

        monitor = monitor_note(data.channel_spread)
        skew = skew_note(channel_delays(data.channel_histograms, data.channel_spread),
                         bin_width, after=shifted, spread=data.channel_spread)
        mixed = "; and ".join(n for n in (monitor, skew) if n) or mixed
    double = _double_note(data)
    return (data, notes + ([edge] if edge else []) + ([mixed] if mixed else [])
            + ([double] if double else []) + _lost_notes(data, marker, n_bins))
