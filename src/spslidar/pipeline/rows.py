"""A measured acquisition's marker blocks to the rows ``reconstruct`` solves: the blocks read
against the patterns (:func:`~spslidar.pipeline.blocks.read_blocks`), those without a dwell
or a measurement left out (a lost sync's, an end marker's, an empty short one's, a dropout's
or a stall's), each corrected for pile-up with its own dwell
(:func:`~spslidar.pipeline.screen.measured_blocks`), and, for a sequence shown several
times (``--repeats``, or in several files, each holding it that many times), one repeat
picked (``--frame``) or each pattern's blocks summed.

Moved out of :mod:`spslidar.pipeline.real`, which had grown past 700 lines with the repeats;
every step is one of those modules', in the order ``reconstruct`` takes them.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from ..errors import ConfigError

__all__ = ["SolvedRows", "channels_record", "solved_rows"]


class _FileBlocks(NamedTuple):
    """One file's blocks as :func:`_file_blocks` reads them."""

    data: Any
    hist: np.ndarray
    periods: np.ndarray
    noise_totals: np.ndarray | None
    rows: np.ndarray  # (the file's blocks kept)
    n_blocks: int
    partial: bool
    pile: dict
    drift: Any
    notes: list[str]
    n_read: int
    first: int | None  # (the first block's pattern: given, or found under "auto")


class SolvedRows(NamedTuple):
    """What :func:`solved_rows` gives."""

    #: the file read (:class:`~spslidar.io.PtuAcquisition`), without a lost sync's blocks
    data: Any
    #: one histogram a row solved (float64; pile-up corrected where a dead time was given),
    #: shape (R, L)
    hist: np.ndarray
    #: each row's exposure, code periods (a pattern's blocks summed under repeats)
    periods: np.ndarray
    #: each row's noise total where a pile-up correction gives one, else None
    noise_totals: np.ndarray | None
    #: the pattern of each row, shape (R, Q)
    patterns: np.ndarray
    #: each row's pattern number (its row of ``--patterns``)
    rows: np.ndarray
    #: each row's photons as recorded (its blocks' sum under repeats)
    counts_kept: np.ndarray
    #: the blocks left out (numbered through the repeats and the files; with ``frame``, of
    #: that repeat's blocks alone), a lost sync's among them
    blocks_left_out: np.ndarray
    #: a part of the period never recorded (:func:`~spslidar.pipeline.screen.screen_blocks`)
    partial: bool
    #: the pile-up record (``metrics.json``'s ``detector``) and the timing drift read
    pile: dict
    drift: Any
    #: the warnings, in order
    notes: list[str]
    #: how many of them the reading said (the rest come after: a caller's own go between)
    n_read: int = 0
    #: under ``first_pattern``, each pattern's kept blocks (shape (M,), in ``--patterns``
    #: order); else None
    blocks_per_pattern: np.ndarray | None = None
    #: the first block's pattern (given, or found under ``first_pattern="auto"``), or None
    first_pattern: int | None = None
    #: ``metrics.json``'s ``ptu.channels`` (:func:`channels_record`); of several files, a list
    #: of each one's (each aligned by its own delays), or None where none read several
    channels: Any = None


def _file_blocks(ptu: Any, shown: np.ndarray, code: np.ndarray, bin_width: float, *,
                 detector: Any, marker: int, channel: Any, allow_binning: bool,
                 marker_edge: str, settle: float, repeats: int,
                 sync_divider: Any, first: int | str | None, sync_channel: Any = None,
                 align_channels: Any = False) -> _FileBlocks:
    """One file's blocks, read, screened and corrected for pile-up (:func:`solved_rows`)."""
    from .blocks import block_patterns, drop_frozen, read_blocks
    from .free_run import block_numbers, check_given, free_block_patterns, resolve_first
    from .screen import measured_blocks

    m_rows = int(shown.shape[0])
    m = m_rows * repeats
    data, notes = read_blocks(ptu, m, int(np.size(code)), bin_width=bin_width, marker=marker,
                              channel=channel, allow_binning=allow_binning,
                              marker_edge=marker_edge, settle=settle, repeats=repeats,
                              sync_divider=sync_divider, free_running=first is not None,
                              sync_channel=sync_channel, align_channels=align_channels)
    n_blocks = data.n_patterns  # (the lost syncs' blocks too, for blocks_left_out)
    if first == "auto":  # (found from the blocks' photons, said, or refused)
        first = resolve_first(data, shown, code, notes)
    elif first is not None:  # (a number given: checked against the data where cheap)
        check_given(data, shown, code, first, notes)
    # each block's pattern, as the screening reads it (free-running: every block the file
    # holds, block b showing pattern (first + b) mod M)
    if first is None:
        patterns = block_patterns(shown, repeats)
    else:
        m = n_blocks
        patterns = free_block_patterns(shown, block_numbers(first, m, m_rows))
    data, frozen, note = drop_frozen(data, ptu)
    if frozen:  # (the rows the file's lost syncs leave without a dwell)
        m, patterns = m - frozen, patterns[: m - frozen]
        notes.append(note)
    # the reader's dwell: to the next block's marker, also where that block is not a pattern
    # (the file's ends, recomputed here, gave the last of m rows in an (m + 1)-block file the
    # extra block's periods too: twice its dwell, its histogram halved)
    n_read = len(notes)
    n_k = np.maximum(data.exposure_periods, 1).astype(np.float64)  # (less any --settle)
    hist = data.histograms.astype(np.float64)
    rows = np.arange(m)  # the blocks kept, for the metrics (the rest are named in warnings)
    if m > 1 and data.ends_in_empty_block:
        # an end-of-acquisition marker read as a pattern: a row of zeros is no measurement
        notes.append(
            f"the last of the {m} marker blocks holds no photons and lasts {int(n_k[-1])} code "
            f"period(s) (an end-of-acquisition marker?): "
            + ("it is left out" if first is not None else  # (a free-running file's block)
               "its pattern row is left out of the solve (leave it out of --patterns to say "
               "so)"))
        m, n_k, hist, patterns, rows = m - 1, n_k[:-1], hist[:-1], patterns[:-1], rows[:-1]
    # any other row of zeros over less than half the median dwell is no measurement either:
    # scaled up to the mean dwell it stays 0 (an empty one-period first block under
    # --marker-edge end was kept and 'scaled up', and leaving it out moved 32 of 64 depths by
    # up to 0.94 m: an audit of 2026-11-29)
    empty = np.flatnonzero((hist.sum(axis=1) == 0) & (n_k < 0.5 * np.median(n_k)))
    if m > 1 and 0 < empty.size < m:
        notes.append(
            f"{empty.size} marker block(s) (first: {int(empty[0])}) hold no photons over less "
            f"than half the median dwell of {np.median(n_k):.0f} code periods (an arming "
            f"marker, or a marker read at the wrong edge?): their pattern rows are left out of "
            f"the solve")
        keep = np.setdiff1d(np.arange(m), empty)
        m, n_k, hist, patterns, rows = keep.size, n_k[keep], hist[keep], patterns[keep], rows[keep]
    # a dropout or a stall left out; a part of the period never recorded said (and then no
    # share of returns outside the gate is read); pile-up corrected; the drift read (the
    # warnings name each block's pattern: under repeats, block r M + i is pattern i's)
    blocks = measured_blocks(hist, hist.sum(axis=1), n_k, patterns, code, data, detector,
                             channel, bin_width, (rows + (first or 0)) % m_rows)
    if blocks.keep.size < m:
        n_k, rows = n_k[blocks.keep], rows[blocks.keep]
    return _FileBlocks(data, blocks.hist, n_k, blocks.noise_totals, rows, n_blocks,
                       blocks.partial, blocks.pile, blocks.drift, notes + blocks.notes, n_read,
                       first)


def _read_each(files: list, shown: np.ndarray, code: np.ndarray, bin_width: float,
               options: dict) -> list[_FileBlocks]:
    """Each file's blocks (:func:`_file_blocks`); a refusal of one of several files names it
    (a dead time its detections contradict was said without the file: a review)."""
    import os

    parts = []
    for f in files:
        try:
            parts.append(_file_blocks(f, shown, code, bin_width, **options))
        except ConfigError as err:
            if len(files) > 1 and os.fspath(f) not in str(err):
                raise ConfigError(f"{os.fspath(f)}: {err}") from None
            raise
    if len({(p.data.resolution_s, p.data.binning, p.data.periods_per_sync,
             p.data.bin_width_s) for p in parts}) > 1:
        # (the first file's were taken for all: a review)
        raise ConfigError("the PTU files differ in their TDC resolution, binning or sync "
                          "divider: reconstruct them apart")
    return parts


def _joined(parts: list[_FileBlocks], step: int) -> Any:
    """The files' acquisitions as one (:class:`~spslidar.io.PtuAcquisition`): their blocks'
    photons in file order, each file's ``step`` blocks numbered after the files' before it (a
    lost sync's blocks, left out, count 0), their counts summed, the first file's header."""
    import dataclasses

    first = parts[0].data
    blocks = np.zeros(step * len(parts), np.int64)
    for i, part in enumerate(parts):
        c = np.asarray(part.data.counts_per_pattern)
        blocks[i * step: i * step + c.size] = c
    per_channel: dict[int, int] = {}
    for part in parts:
        for c, n in part.data.photons_per_channel.items():
            per_channel[c] = per_channel.get(c, 0) + int(n)
    counts = ("n_records", "n_photons", "n_markers", "n_overflows",
              "n_dropped_before_first_marker", "n_dropped_after_last_pattern",
              "n_out_of_range", "n_dropped_settling")
    return dataclasses.replace(
        first, counts_per_pattern=blocks, photons_per_channel=per_channel,
        **{k: sum(int(getattr(p.data, k)) for p in parts) for k in counts})


def solved_rows(ptu: Any, shown: np.ndarray, code: np.ndarray, bin_width: float, *,
                detector: Any, marker: int, channel: Any, allow_binning: bool,
                marker_edge: str, settle: float, repeats: int, sync_divider: Any,
                sync_channel: Any = None, align_channels: Any = False,
                frame: int | None, first_pattern: int | None = None) -> SolvedRows:
    """The rows of a measured acquisition that ``reconstruct`` solves (:class:`SolvedRows`).

    Parameters
    ----------
    ptu : path, or list of paths
        The T3 PTU file, or several: an acquisition saved one file per pass, each holding
        the sequence ``repeats`` times, read in the order given (their blocks numbered
        through the files; each file screened, corrected for pile-up and checked for drift
        on its own, its warnings named with it).
    shown : ndarray, shape (M, Q)
        The patterns shown (checked), in marker order.
    code : ndarray, shape (L,)
        The code's bits.
    bin_width : float
        Seconds a bin.
    detector : object
        The detector's dead-time model (:func:`~spslidar.pipeline.deadtime.dead_time_model`).
    marker, channel, allow_binning, marker_edge, settle, repeats, sync_divider, sync_channel,
    align_channels, frame
        As :func:`~spslidar.pipeline.real.reconstruct_ptu` takes them (checked; ``frame``
        counts the repeats through the files).
    first_pattern : int, optional
        A free-running sequence's first block's pattern (checked, one file, no repeats):
        block ``b`` shows pattern ``(first_pattern + b) mod M``, each pattern's summed.
    """
    from .blocks import fold_repeats
    from .drift import drift_note, timing_drift

    files = list(ptu) if isinstance(ptu, (list, tuple)) else [ptu]
    m_rows = int(shown.shape[0])
    options = dict(detector=detector, marker=marker, channel=channel,
                   allow_binning=allow_binning, marker_edge=marker_edge, settle=settle,
                   repeats=repeats, sync_divider=sync_divider, first=first_pattern,
                   sync_channel=sync_channel, align_channels=align_channels)
    parts = _read_each(files, shown, code, bin_width, options)
    first_pattern = parts[0].first  # (an "auto" resolved: one file under --first-pattern)
    if len(parts) == 1:
        part = parts[0]
        data, hist, n_k, noise_totals = part.data, part.hist, part.periods, part.noise_totals
        rows, notes, drift, n_blocks = part.rows, part.notes, part.drift, part.n_blocks
        n_read, pile = part.n_read, part.pile
    else:  # (a file's blocks numbered after the files' before it: m_rows x repeats each)
        import os

        step = m_rows * repeats
        data = _joined(parts, step)
        hist = np.concatenate([p.hist for p in parts])
        n_k = np.concatenate([p.periods for p in parts])
        noise_totals = (None if any(p.noise_totals is None for p in parts) else
                        np.concatenate([p.noise_totals for p in parts]))
        rows = np.concatenate([p.rows + i * step for i, p in enumerate(parts)])
        # each file's warnings named with its path as given (two runs' scan.ptu read alike
        # by name alone: a review), but its own drift, read again over all the files in the
        # order given (a drift across the files went unsaid: a review)
        notes = [f"{os.fspath(f)}: {n}" for f, p in zip(files, parts, strict=True)
                 for n in p.notes if n != drift_note(p.drift, bin_width)]
        drift = timing_drift(hist, code)
        across = drift_note(drift, bin_width)
        notes += [f"over the {len(files)} files: {across}"] if across else []
        n_blocks, n_read = step * len(parts), 0
        # (the first file's pile-up record stood for all: the fastest count rate's now)
        pile = max((p.pile for p in parts), key=lambda d: d.get("count_rate_hz") or 0.0)
    total_repeats = repeats * len(parts)
    if frame is not None:  # one repeat's blocks alone (a frame of a video)
        mine = rows // m_rows == frame
        if not mine.any():  # (NaN gains and "Mean of empty slice": a review)
            raise ConfigError(f"every block of --frame {frame} was left out as no "
                              f"measurement (no photons over its dwell: a dropout, a stall; "
                              f"run without --frame for the warnings that name them)")
        rows, hist, n_k = rows[mine], hist[mine], n_k[mine]
        noise_totals = None if noise_totals is None else noise_totals[mine]
        # the drift over this frame's blocks alone: the repeats' own motion is not this
        # map's (it was said as a blur of the frame's map: a review)
        said = drift_note(drift, bin_width)
        drift = timing_drift(hist, code)
        notes = [n for n in notes if not (said and n.endswith(said))]
        frame_note = drift_note(drift, bin_width)
        notes += [frame_note] if frame_note else []
    elif total_repeats > 1 and drift_note(drift, bin_width):
        # (a scene moving 3 cm a repeat was said only as a timing drift of 14 bins: an
        # outside lab audit of 2026-11-30)
        notes.append(
            f"the sequence was shown {total_repeats} times, summed here: a scene that moves "
            f"between the repeats reads as the drift above; --frame I reconstructs repeat I "
            f"alone")
    elif first_pattern is not None and n_blocks > m_rows and drift_note(drift, bin_width):
        notes.append(
            f"the free-running sequence's {n_blocks} blocks ({n_blocks / m_rows:.3g} passes of "
            f"the {m_rows} patterns) are summed here: a scene that moves between the passes "
            f"reads as the drift above")
    read = np.arange(n_blocks)  # (the blocks asked for: a frame's, or every one)
    left_out = np.setdiff1d(read if frame is None else read[read // m_rows == frame], rows)
    counts_kept = data.counts_per_pattern[rows]
    per_pattern = None
    if first_pattern is not None:  # (the kept blocks of each pattern, in --patterns order)
        per_pattern = np.bincount((rows + first_pattern) % m_rows, minlength=m_rows)
    if total_repeats > 1 or first_pattern is not None:
        # each pattern's kept blocks summed: the solve has one row a pattern
        rows, hist, n_k, noise_totals, counts_kept = fold_repeats(
            (rows + (first_pattern or 0)) % m_rows, hist, n_k, noise_totals, counts_kept)
    # (the patterns themselves where every row is solved: no copy of a large set)
    every = rows.size == m_rows and np.array_equal(rows, np.arange(m_rows))
    # (of several files the first one's was recorded as all of theirs: an audit of stop 67)
    channels = [channels_record(p.data) for p in parts]
    channels = channels[0] if len(parts) == 1 else (
        None if all(c is None for c in channels) else channels)
    return SolvedRows(data, hist, n_k, noise_totals, shown if every else shown[rows], rows,
                      counts_kept, left_out, any(p.partial for p in parts), pile, drift, notes,
                      n_read, per_pattern, first_pattern, channels)


def channels_record(data: Any) -> dict[str, Any] | None:
    """``metrics.json``'s ``ptu.channels`` of one file: the delays between the channels read
    together as its histograms show them (after any shift), the shifts applied and each
    channel's rate spread; None for one channel."""
    from .skew import channel_delays, describe

    return describe(channel_delays(data.channel_histograms, data.channel_spread),
                    data.channel_shifts, data.channel_spread)


def calibration_rows(ptu: Any, shown: np.ndarray, code: np.ndarray, bin_width: float, *,
                     detector: Any, marker: int, channel: Any, allow_binning: bool,
                     marker_edge: str, settle: float, repeats: int, sync_divider: Any,
                     first: int | str | None, sync_channel: Any = None,
                     align_channels: Any = False) -> tuple[Any, np.ndarray, np.ndarray,
                                                       np.ndarray, dict, Any, list[str],
                                                       int | None]:
    """The rows ``calibrate`` reads of a flat target's file (moved out of
    :func:`~spslidar.pipeline.calibration.calibrate_ptu`): its blocks read, a lost sync's
    left out, a dropout's left out, a gated detector said, pile-up corrected and the drift
    read (which widens the response a wall's acquisition reads), as ``reconstruct`` does;
    under ``repeats`` or ``first`` (checked) each pattern's blocks summed.

    Returns
    -------
    data, keep, patterns, hists, pile, drift, notes, first
        The file read (without a lost sync's blocks), the blocks kept, each row's pattern
        ``(R, Q)`` and histogram, the pile-up record, the drift read, the warnings and the
        first block's pattern (given, or found under ``"auto"``; None without it).
    """
    from .blocks import block_patterns, drop_frozen, fold_repeats, read_blocks
    from .free_run import block_numbers, free_block_patterns, resolve_first
    from .screen import measured_blocks

    m_rows = int(shown.shape[0])
    data, notes = read_blocks(ptu, m_rows * repeats, int(np.size(code)), bin_width=bin_width,
                              marker=marker, channel=channel, allow_binning=allow_binning,
                              marker_edge=marker_edge, settle=settle, repeats=repeats,
                              sync_divider=sync_divider, free_running=first is not None,
                              sync_channel=sync_channel, align_channels=align_channels)
    if first == "auto":  # (found from the blocks' photons, said, or refused)
        first = resolve_first(data, shown, code, notes)
    patterns = (block_patterns(shown, repeats) if first is None else
                free_block_patterns(shown, block_numbers(first, data.n_patterns, m_rows)))
    data, frozen, note = drop_frozen(data, ptu)
    if frozen:  # (blocks without a dwell: the file's syncs lost)
        patterns = patterns[: patterns.shape[0] - frozen]
        notes.append(note)
    numbers = block_numbers(first, data.n_patterns, m_rows)
    blocks = measured_blocks(data.histograms, data.counts_per_pattern,
                             np.maximum(data.exposure_periods, 1), patterns, code, data,
                             detector, channel, bin_width, numbers)
    keep, hists = blocks.keep, blocks.hist
    patterns = patterns[keep]
    if repeats > 1 or first is not None:  # each pattern's blocks summed, as reconstruct does
        rows, hists, *_ = fold_repeats(numbers[keep], hists)
        patterns = shown[rows]
    return (data, keep, patterns, hists, blocks.pile, blocks.drift, notes + blocks.notes,
            first)
