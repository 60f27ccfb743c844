"""PicoQuant T3 PTU files: per-pattern histograms in, simulated acquisitions out.

In a PSST single-pixel lidar run on PicoQuant time-tagging electronics (PicoHarp, HydraHarp,
TimeHarp 260, MultiHarp / PicoHarp 330) the T3 mode maps onto the measurement directly:

* the **sync** input is the code generator's period start, so a record's ``nsync`` counts code
  periods and its ``dtime`` is the TDC bin inside the code period;
* a **marker** input is driven by the DMD, one marker record per pattern change.

:func:`read_ptu_histograms` streams the records of such a file (with ``ptufile``) and returns
the ``(M, L)`` per-pattern histograms that the reconstruction consumes;
:func:`write_ptu_t3` / :func:`write_acquisition_ptu` write simulated events as a T3 PTU file so
the reader can be tested end to end.

The record layouts, and why spslidar writes them with its own encoder, are in
:mod:`spslidar.io.ptu_format`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ConfigError
from .ptu_blocks import (
    BOUNCE_TIME_S,
    _ChannelHists,
    _channels,
    _check_forward,
    _check_resolution,
    _fitting_codes,
    _Gaps,
    _missed_note,
    _rebin,
    _shift_table,
    _to_float32,
    accumulate,
)
from .ptu_format import (
    _FAMILY,
    PathLike,
    _check_t3,
    _finite_number,
    _header_summary,
    _marker_input,
    _open_ptu,
    _positive_int,
    raw_chunks,
)
from .ptu_t2 import T2Records, check_sync_channel, open_t2, t2_overflows

__all__ = ["PtuAcquisition", "ptu_info", "read_ptu_histograms"]


# --------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------


@dataclass
class PtuAcquisition:
    """Per-pattern histograms read from a PTU file, T3 or T2 (:func:`read_ptu_histograms`).

    Attributes
    ----------
    histograms : numpy.ndarray
        ``(M, n_bins)`` float32 counts per pattern and code-period bin (exact below 2**24).
    counts_per_pattern : numpy.ndarray
        ``(M,)`` int64 photons histogrammed per pattern (row sums of ``histograms``).
    pattern_start_sync : numpy.ndarray
        ``(M,)`` int64 global sync count (code period index) of each pattern's marker.
    last_sync : int
        Global sync count of the file's last photon or marker (-1 if none); with
        ``pattern_start_sync`` it gives each pattern's dwell in code periods.
    sync_period_s, resolution_s : float
        ``MeasDesc_GlobalResolution`` (the code period) and ``MeasDesc_Resolution`` (dtime unit).
    bin_width_s : float
        Histogram bin width, ``resolution_s * binning``.
    binning : int
        dtime units per bin (1 unless ``allow_binning``); where the bin width is no whole
        number of them, per intermediate bin, ``bin_width_s / (resolution_s * binning)`` of
        which make a bin and are split between the bins by overlap.
    n_records, n_photons, n_markers, n_overflows : int
        Records in the file; photon records on the selected channels; markers with the selected
        bit (= blocks); overflow (sync counter wrap) records.
    n_dropped_before_first_marker, n_dropped_after_last_pattern, n_out_of_range : int
        Selected photons dropped: before the first marker; after block ``n_patterns - 1``;
        with bin ``dtime // binning >= n_bins``.
    n_dropped_settling : int
        Selected photons dropped within ``settle_s`` of their block's start.
    settled_periods : numpy.ndarray
        ``(M,)`` int64 code periods at each block's start whose photons were dropped
        (``settle_s``; empty without it): the block's exposure is ``periods_per_pattern``
        less these (:attr:`exposure_periods`), while ``periods_per_pattern`` stays the
        markers' spacing that the block checks read.
    header : dict
        Header summary, as returned by :func:`ptu_info`.
    periods_per_pattern : numpy.ndarray
        ``(M,)`` int64 dwell of each pattern in code periods: from its marker to the next
        block's marker (for the file's last block, to ``last_sync + 1``: a file records
        nothing of the periods after its last event, so without an end-of-acquisition marker
        the last pattern's dwell reads short by about one gap between its photons, a
        relative error of one over its photon count, below its Poisson noise).
    warnings : list of str
        What the caller should know but that is no error (a trailing block without photons
        and of at most one code period, see :func:`read_ptu_histograms`).
    photons_per_channel : dict of int to int
        Photon records per detector channel in the whole file (0-based, every channel, the
        selected or not; channels without photons left out).
    detection_gaps : dict
        Per selected channel, the time between each detection and the one before on that
        channel: ``{"shortest_s": float, "n": int, "counts": ndarray}``, ``counts`` a
        histogram of the gaps over :data:`~spslidar.io.ptu_blocks.GAP_EDGES_S`
        (``counts[i]`` holds the gaps from edge ``i - 1`` to edge ``i``; the first, those
        under 58 ps; the last, those over 1.95 ms): a detector's dead time is the shortest gap
        it lets through.
    periods_per_sync : int
        Code periods per sync record: the header's sync divider where the file's sync period
        is that many code periods (each photon's TDC time is then folded into one code
        period, and ``periods_per_pattern`` counts code periods), else 1.
    channel_histograms : dict of int to ndarray
        Where the photons of several detector channels were read together: each channel's
        kept photons over the code period (int64, every block summed; after any
        ``channel_shifts``), from which their relative delays are read
        (:mod:`spslidar.pipeline.skew`); empty for one channel, or a TDC bin split.
    channel_shifts : dict of int to int
        The ``channel_shifts`` applied (bins, ``0 <= k < n_bins``; channels not moved left
        out).
    channel_spread : dict of int to float
        With ``channel_histograms``: each channel's photon rate over the blocks, its
        variance over a constant rate's Poisson variance (about 1 for a channel that does
        not follow the patterns: a laser monitor).
    """

    histograms: np.ndarray
    counts_per_pattern: np.ndarray
    pattern_start_sync: np.ndarray
    last_sync: int
    sync_period_s: float
    resolution_s: float
    bin_width_s: float
    binning: int
    n_records: int
    n_photons: int
    n_markers: int
    n_overflows: int
    n_dropped_before_first_marker: int
    n_dropped_after_last_pattern: int
    n_out_of_range: int
    header: dict[str, Any] = field(default_factory=dict)
    periods_per_pattern: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    warnings: list[str] = field(default_factory=list)
    photons_per_channel: dict[int, int] = field(default_factory=dict)
    periods_per_sync: int = 1
    detection_gaps: dict[int, Any] = field(default_factory=dict)
    n_dropped_settling: int = 0
    settled_periods: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    channel_histograms: dict[int, np.ndarray] = field(default_factory=dict)
    channel_shifts: dict[int, int] = field(default_factory=dict)
    channel_spread: dict[int, float] = field(default_factory=dict)

    @property
    def exposure_periods(self) -> np.ndarray:
        """Each block's dwell in code periods less its settling (:attr:`settled_periods`)."""
        if not self.settled_periods.size:
            return self.periods_per_pattern
        return self.periods_per_pattern - self.settled_periods

    @property
    def n_patterns(self) -> int:
        """Number of patterns ``M`` (rows of ``histograms``)."""
        return int(self.histograms.shape[0])

    @property
    def ends_in_empty_block(self) -> bool:
        """Whether the last row's block holds no photons and lasts at most one code period:
        what an end-of-acquisition marker read as a block looks like."""
        return bool(self.counts_per_pattern.size and self.counts_per_pattern[-1] == 0
                    and self.periods_per_pattern[-1] <= 1)


def ptu_info(path: PathLike) -> dict[str, Any]:
    """Short summary of a PTU file's header (no records are decoded).

    Returns a dict: ``record_type`` (e.g. ``'HydraHarp2T3'``), ``measurement_mode``
    (``'T2'``/``'T3'``), ``n_records`` (header) and ``n_records_in_file`` (whole records after
    the header), ``resolution_s``, ``sync_period_s`` and ``bins_per_period`` (None for a T2
    file, whose ``time_unit_s`` is its global resolution; a float, the period over the
    resolution as the header gives them, not rounded: a real instrument's is rarely whole,
    and a file written with 127 bins may read 127.00000000000001), ``sync_rate_hz``,
    ``acquisition_time_s`` (None where the header gives none, or 0), ``hardware``,
    ``sync_divider`` (``HWSync_Divider``), ``creator``, ``comment``, ``created``, ``version``,
    ``path``. Raises
    :class:`~spslidar.errors.ConfigError` if ``path`` is not a PTU file.
    """
    with _open_ptu(path) as f:
        return _header_summary(f, path)


def _overflows(raw: np.ndarray, family: str) -> tuple[int, int]:
    """(overflow records, sync counter wraps) in a chunk of raw records."""
    if family.startswith("t2"):  # (time tag wraps: its decoder counts the syncs)
        return t2_overflows(raw, family), 0
    if family == "picoharp":
        ofl = ((raw >> 28) == 15) & (((raw >> 16) & 0xFFF) == 0)
        n = int(np.count_nonzero(ofl))
        return n, n
    ofl = (raw >> 25) == 0x7F  # special bit and channel 63
    n = int(np.count_nonzero(ofl))
    if family == "hydraharp1":
        return n, n
    count = (raw[ofl] & 0x3FF).astype(np.int64)
    return n, int(np.where(count == 0, 1, count).sum())


#: bytes of working memory per record of a chunk (raw word, ptufile's 12-byte decoded record,
#: the block index, masks and the flat histogram indices of its photons)
_BYTES_PER_CHUNK_RECORD = 64


def _check_histogram_memory(rows: int, n_bins: int, chunk_records: int, path: str) -> None:
    """Refuse (one line) per-pattern histograms that cannot fit: ``rows x n_bins`` 4-byte
    counts (converted to float32 in place) plus one chunk of records, against the memory
    available."""
    from ..machine import _gb, available_memory

    need = float(rows) * n_bins * 4 + float(chunk_records) * _BYTES_PER_CHUNK_RECORD
    avail = available_memory()
    if need > 0.8 * avail:
        raise ConfigError(f"{path!r}: {rows} pattern{'s' if rows != 1 else ''} of {n_bins} "
                          f"bins need {_gb(need)} of "
                          f"histograms, more than the {_gb(avail)} available: check n_bins "
                          f"(the code length) and the marker input, or give n_patterns")


def _chunks(f, n_records: int, chunk_records: int, path: str):
    """The file's records, ``chunk_records`` at a time: ``(raw words, ptufile decode)``, or a
    T2 file's (:class:`~spslidar.io.ptu_t2.T2Records`) as T3 events with global syncs."""
    decode = f.decoder() if isinstance(f, T2Records) else f.decode_records
    for raw in raw_chunks(f.filehandle, f.record_offset, n_records, chunk_records, path):
        yield raw, decode(raw)  # (T3: times restart at 0 in every chunk)


def _count_markers(f, n_records: int, chunk_records: int, mask: int, path: str) -> int:
    """Marker records with bit ``mask`` in the file (the number of pattern blocks)."""
    n = 0
    for _raw, dec in _chunks(f, n_records, chunk_records, path):
        n += int(np.count_nonzero((dec["channel"] < 0) & ((dec["marker"] & mask) != 0)))
    return n


def _first_marker_syncs(f, n_records: int, chunk_records: int, mask: int, family: str,
                        path: str, count: int = 2) -> list[int]:
    """The global syncs of the file's first ``count`` markers with bit ``mask`` (fewer where
    the file holds fewer), read until they are found: usually the first chunk."""
    wrap, carry, found = _FAMILY[family][0], 0, []
    for raw, dec in _chunks(f, n_records, chunk_records, path):
        is_mark = (dec["channel"] < 0) & ((dec["marker"] & mask) != 0)
        found += (dec["time"][is_mark].astype(np.int64) + carry)[: count - len(found)].tolist()
        if len(found) >= count:
            break
        carry += _overflows(raw, family)[1] * wrap
    return found


#: photons read after which the histograms are counted in int64 (no bin of an int32 can
#: wrap before: it holds at most every photon)
WIDEN_AFTER = 2**31 - 1


def read_ptu_histograms(
    path: PathLike,
    n_bins: int,
    *,
    bin_width: float | None = None,
    marker: int = 1,
    channel: int | Sequence[int] | None = None,
    n_patterns: int | None = None,
    extra_blocks: int = 0,
    marker_edge: str = "start",
    chunk_records: int = 2**20,
    rtol: float = 1e-3,
    period_tol_bins: float = 0.5,
    allow_binning: bool = False,
    check_sync_period: bool = True,
    settle_s: float = 0.0,
    sync_divider: int | None = None,
    sync_channel: int | None = None,
    channel_shifts: dict[int, int] | None = None,
) -> PtuAcquisition:
    """Read a T3 PTU file, or a T2 one with sync records, into per-pattern histograms.

    Records are read and decoded (``ptufile.PtuFile.decode_records``) ``chunk_records`` at a
    time. Memory is the histograms (``M x n_bins`` 4-byte counts, turned into float32 in
    place) plus one chunk, whatever the file's length and the number of markers; histograms
    that would not fit are refused before they are allocated (with ``n_patterns`` unset the
    markers are counted in a first, cheap pass over the file, so ``M`` is known up front).
    The result does not depend on ``chunk_records``.

    **Pattern blocks.** Records are in arrival order. Every marker record whose marker bits
    include ``marker`` starts a new block: photons between the k-th and (k+1)-th such marker
    (0-based) belong to pattern k, photons after the last marker to the last pattern. Photons
    *before the first marker are dropped* (the DMD pattern is unknown; counted in
    ``n_dropped_before_first_marker``). Without ``n_patterns`` there is one pattern per marker,
    including blocks that hold no photons (a row of zeros), wherever they are in the file; with
    it the first ``n_patterns`` blocks are kept and later photons dropped
    (``n_dropped_after_last_pattern``); ``extra_blocks`` keeps up to that many more where the
    file holds them (the caller decides which block is not a pattern: an arming marker before
    the first, an end-of-acquisition marker after the last).

    **Marker edge.** ``marker_edge="start"`` (the default) reads a marker as the start of its
    pattern, as above. ``"end"`` reads it as the end: photons up to the k-th marker (0-based)
    and after the one before it belong to pattern k, and photons after the last marker are
    dropped (``n_dropped_after_last_pattern``). Pattern 0 is taken to last as long as pattern
    1 (from sync 0 where the file holds one marker): photons before it are dropped
    (``n_dropped_before_first_marker``). DMD controllers emit either.

    **A trailing empty block.** A marker that is the file's last event (an end-of-acquisition
    marker, or a pattern cut off at once) opens a block with no photons and a dwell of at most
    one code period. It is kept as a pattern (the row count is always the number of blocks, or
    ``n_patterns``) and named in ``warnings``; pass ``n_patterns`` = blocks - 1 to leave it out.

    **Bins.** ``dtime`` is in units of the file's resolution (``MeasDesc_Resolution``). With
    ``bin_width`` given, the resolution must equal it within relative ``rtol`` (1e-3) or, with
    ``allow_binning``, ``bin_width`` must be an integer multiple ``k`` of it (within ``rtol``)
    and bin = ``dtime // k``; where it is no whole number of units (a MultiHarp's 80 ps TDC
    under a 10 GHz code's 100 ps bits, or a code clock a little off the TDC's), ``allow_binning``
    counts photons in bins of ``k = max(1, floor(ratio / 4))`` units (at most a quarter bin
    where the ratio is 4 or more; under it, the TDC's own bins) and splits each between the
    two bins it overlaps, in proportion (the histograms are then no
    longer whole counts; the sync period is checked against ``n_bins * bin_width``). Photons
    past the code period are dropped (``n_out_of_range``).

    **Code period.** With ``check_sync_period`` the sync period (``MeasDesc_GlobalResolution``)
    must equal ``n_bins * bin_width`` within ``period_tol_bins`` bins (half a bin: a larger
    mismatch would add or miss a bin at the end of every code period).

    **Settling.** A DMD shows its new pattern some microseconds after its trigger (the
    mirrors settle), and a marker may come early or late against the mirrors: the first part
    of each block then holds the previous pattern's returns. ``settle_s`` drops each block's
    photons of its first ``ceil(settle_s / sync period)`` syncs (counted in
    ``n_dropped_settling``) and shortens its dwell by as much (an outside audit of
    2026-11-30: 20 % of each dwell left to the previous pattern made a 16x16 map of 128
    patterns 2.8 times worse, without a word). A block that bounced is settled from each of
    its markers.

    **Record count.** The header's ``TTResult_NumberOfRecords`` records are read, as
    ``ptufile`` and PicoQuant's own readers read them; whole records after them are left out
    with a warning that names both counts (``ptu_info`` gives ``n_records_in_file``). A count
    of 0 (an acquisition that did not finish, or software that does not fill it in) reads
    every whole record in the file, as ``ptufile`` does, also with a warning; so does a count
    beyond the file's end (a file cut short), with a warning that names both counts.

    **Channels** are numbered from 0: the channel field of HydraHarp, TimeHarp 260 and
    MultiHarp / generic T3 records as it is, and a PicoHarp's detector inputs 1-4 (its
    records' channel field) as 0-3. This is ``ptufile``'s numbering.

    Parameters
    ----------
    path : str or os.PathLike
        T3 PTU file (PicoHarp, HydraHarp v1/v2, TimeHarp 260 N/P or generic T3 records), or
        T2 one that recorded the code's sync, read as T3 (:mod:`spslidar.io.ptu_t2`).
    n_bins : int
        Histogram bins per code period ``L``.
    bin_width : float, optional
        Expected bin width in seconds; default: the file's dtime resolution.
    marker : int
        Marker input (1..4) flagging a DMD pattern change; bit mask ``1 << (marker - 1)``.
    channel : int or sequence of int, optional
        Detector channels to keep, numbered from 0 (see above); default all. A channel on
        which the file holds no photon is refused.
    n_patterns : int, optional
        Number of patterns ``M``; the file must hold at least that many blocks.
    extra_blocks : int
        With ``n_patterns``: blocks beyond it to keep where the file holds them (default 0).
    marker_edge : {"start", "end"}
        Whether a marker starts (default) or ends its pattern's block.
    chunk_records : int
        Records per read/decode chunk (about 64 bytes of working memory each).
    rtol, period_tol_bins : float
        Tolerances of the resolution (relative) and sync period (in bins) checks.
    allow_binning : bool
        Accept a ``bin_width`` that is a multiple of the file's resolution: whole (merged) or
        not (split between bins by overlap).
    check_sync_period : bool
        Check the sync period against ``n_bins * bin_width``.
    settle_s : float
        Seconds of each block's start whose photons are dropped (default 0; see above).
    sync_divider : int, optional
        Code periods per sync record where the header does not say (its ``HWSync_Divider``):
        a sync from the code generator's frame output every D periods; given, it replaces
        the header's.
    sync_channel : int, optional
        A T2 file whose sync went to a detector input: that channel's events are the syncs
        (:func:`~spslidar.io.ptu_t2.open_t2`; HydraHarp, TimeHarp, MultiHarp).
    channel_shifts : dict of int to int, optional
        Bins each channel's photons are moved earlier by, around the code period (a cable
        delay: :mod:`spslidar.pipeline.skew`); not through a TDC bin split between bits.

    Returns
    -------
    PtuAcquisition

    Warns
    -----
    RuntimeWarning
        The header's record count is 0, or differs from the records the file holds.

    Raises
    ------
    ConfigError
        Not a PTU file (PicoQuant's legacy ``.pt3``, ``.ht3``, ``.t3r`` files named as
        such); a T2 file without sync records; unsupported record type;
        resolution or sync period disagreeing with ``bin_width`` / ``n_bins``; no markers on
        input ``marker``; fewer blocks than ``n_patterns``; no photons on ``channel``;
        histograms too large for the memory available; bad arguments.

    Examples
    --------
    Write 3 patterns' photons (10 periods of a 127-bin code each) and read them back:

    >>> import os, tempfile
    >>> import numpy as np
    >>> from spslidar.io import read_ptu_histograms, write_acquisition_ptu
    >>> rng = np.random.default_rng(0)
    >>> events = [np.column_stack([rng.integers(0, 10, 50), rng.integers(0, 127, 50)])
    ...           for _ in range(3)]  # per pattern: (period, bin) of 50 photons
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = os.path.join(tmp, "scan.ptu")
    ...     _ = write_acquisition_ptu(path, events, 127, 1e-10, periods_per_pattern=10)
    ...     acq = read_ptu_histograms(path, 127, bin_width=1e-10)
    >>> acq.histograms.shape, acq.counts_per_pattern.tolist(), acq.periods_per_pattern.tolist()
    ((3, 127), [50, 50, 50], [10, 10, 10])
    >>> np.array_equal(acq.histograms[0], np.bincount(events[0][:, 1], minlength=127))
    True
    """
    n_bins = _positive_int(n_bins, "n_bins")
    chunk_records = _positive_int(chunk_records, "chunk_records")
    limit = None if n_patterns is None else _positive_int(n_patterns, "n_patterns")
    if isinstance(extra_blocks, bool) or not isinstance(extra_blocks, int | np.integer) or \
            extra_blocks < 0:
        raise ConfigError(f"extra_blocks must be an integer >= 0, got {extra_blocks!r}")
    if marker_edge not in ("start", "end"):
        raise ConfigError(f"marker_edge must be 'start' or 'end', got {marker_edge!r}")
    mask = 1 << (_marker_input(marker) - 1)
    if not isinstance(path, (str, os.PathLike)):
        raise ConfigError(f"path must be the path of a PTU file, got {type(path).__name__}")
    spath = os.fspath(path)
    if bin_width is not None:
        bin_width = _finite_number(bin_width, "bin_width", positive=True)
    rtol = _finite_number(rtol, "rtol")
    settle_s = _finite_number(settle_s, "settle_s")
    period_tol_bins = _finite_number(period_tol_bins, "period_tol_bins")

    with _open_ptu(path) as f:
        header = _header_summary(f, path)
        family, n_records = _check_t3(f, header, spath)
        sync_channel = check_sync_channel(sync_channel, family, header["record_type"], spath)
        if family.startswith("t2"):  # (read as T3 from its sync records: f is their reader)
            f, header = open_t2(f, header, family, n_records, chunk_records, spath,
                                sync_channel, n_bins)
        channels = _channels(channel, family, header["record_type"], spath)
        if channels is not None and sync_channel in channels:
            raise ConfigError(f"--channel {sync_channel} is the --sync-channel: its events are "
                              f"the syncs, not photons")
        res, period = header["resolution_s"], header["sync_period_s"]
        binning, rebin = _check_resolution(res, bin_width, rtol, allow_binning, spath)
        width = res * binning if rebin is None else float(bin_width)
        # the bins the photons are counted in: the code's, or quarter bits split afterwards
        n_mid = n_bins if rebin is None else int(math.ceil(n_bins * rebin - 1e-9))
        if check_sync_period and not period > 0:
            raise ConfigError(f"{spath!r}: header has no sync period (MeasDesc_GlobalResolution)"
                              ", so the code's period cannot be checked against the file (in "
                              "Python, check_sync_period=False reads it unchecked)")
        # a sync divider D (the header's HWSync_Divider): each sync record spans D code periods
        # (PicoQuant's sync period is the divided one), and the TDC times are folded into one
        # (a divider of 2 was refused with "a 2046-bit code fits it", and a code given twice
        # read a third of its returns as outside the gate: an outside audit of 2026-11-30)
        divider = header.get("sync_divider")
        if sync_divider is not None:  # (given: it replaces the header's, and must fit)
            from ..arrays import real_number

            given = real_number(sync_divider)
            if given is None or not (math.isfinite(given) and 1 <= given <= 2**31
                                     and given == int(given)):
                raise ConfigError(f"--sync-divider must be a whole number of code periods "
                                  f"per sync, 1 or more, got {sync_divider!r}")
            divider = int(given)
            if check_sync_period and abs(period - divider * n_bins * width) > (
                    period_tol_bins * width):  # (it was dropped without a word: a review)
                raise ConfigError(
                    f"{spath!r}: its sync period {period:.6g} s is "
                    f"{period / (n_bins * width):.4g} code periods of {n_bins} bins, not the "
                    f"{divider} --sync-divider gives")
        fold = 1
        divided = (isinstance(divider, int | np.integer) and not isinstance(divider, bool)
                   and divider > 1)
        if not check_sync_period and divided and sync_divider is not None:
            fold = int(divider)  # (unchecked: the caller's word)
        if (check_sync_period and divided
                and abs(period - divider * n_bins * width) <= period_tol_bins * width):
            if rebin is not None:  # (the fold is of whole bins: a review found a code's two
                # periods squeezed into one through the split, correlation -0.19 with the code)
                raise ConfigError(f"{spath!r}: a sync divider ({divider}) with a TDC bin split "
                                  f"between the code's bits is not read: record with a sync "
                                  f"divider of 1, or a TDC bin that divides the code's bit")
            fold = int(divider)
        if check_sync_period and abs(period - fold * n_bins * width) > period_tol_bins * width:
            # (a sync every D code periods from the generator's frame output, with no divider
            # in the header, was told of a 2 n-bit code and a slower bit rate, which read
            # depths 1.5 m off: an outside lab audit of 2026-11-30)
            ratio = period / (n_bins * width) if n_bins * width > 0 else 0.0
            # (an absurd header's 1e308 code periods overflowed the int back to float)
            k = round(ratio) if math.isfinite(ratio) and ratio < 2**31 else 0
            whole = (not divided and k >= 2
                     and abs(period - k * n_bins * width) <= period_tol_bins * width)
            raise ConfigError(
                f"{spath!r}: sync period {period:.6g} s != code period n_bins * bin_width = "
                f"{n_bins} * {width:.6g} s = {n_bins * width:.6g} s "
                f"({(period - n_bins * width) / width:+.3g} bins, tolerance {period_tol_bins:g})"
                + (f"; it is {k} code periods: a sync every {k} of them, which the header's "
                   f"divider does not say? --sync-divider {k}" if whole else "")
                + f"; {_fitting_codes(period / width, width, period_tol_bins)}"
                + ("" if rebin is not None or divided or whole
                   or not 0 < n_bins / period < 1 / res else
                   f"; or, if the code has {n_bins} bits, its bits come at {n_bins / period:.7g} "
                   f"Hz (a code clock off the TDC's): --bit-rate {n_bins / period:.7g} "
                   f"--allow-binning splits the TDC's bins between them"))

        settle = 0
        if settle_s > 0:
            if not period > 0:
                raise ConfigError(f"{spath!r}: header has no sync period "
                                  f"(MeasDesc_GlobalResolution), so a settling time cannot "
                                  f"be read in syncs")
            settle = int(math.ceil(settle_s / period - 1e-9))
        # a chunk past the file's end is the file (10**12 was charged as 64000 GB of buffers)
        chunk_records = min(chunk_records, max(1, n_records))
        if limit is None:  # a cheap first pass: how many blocks, so memory is known up front
            _check_histogram_memory(1, n_mid, chunk_records, spath)
            rows = _count_markers(f, n_records, chunk_records, mask, spath)
        else:
            rows = limit + int(extra_blocks)
        _check_histogram_memory(rows, n_mid, chunk_records, spath)
        wrap = _FAMILY[family][0]
        first_sync = 0  # ("end": pattern 0 from its own start, not the measurement's)
        if marker_edge == "end":
            marks = _first_marker_syncs(f, n_records, chunk_records, mask, family, spath,
                                        count=8)
            # (the next marker that is no bounce of the first: a bounce 3 syncs after it made
            # pattern 0 three periods long and dropped the rest of its photons, a review)
            close = max(2, int(BOUNCE_TIME_S / period)) if period > 0 else 2
            if len(marks) > 2:  # (at most a tenth of the markers' typical spacing, as a bounce)
                close = min(close, max(2, int(0.1 * np.median(np.diff(marks)))))
            later = [s for s in marks[1:] if s - marks[0] > close]
            if later:  # as long as pattern 1 (time before it was pattern 0's, and its
                # histogram was scaled down by that dwell: a review)
                first_sync = max(0, 2 * marks[0] + 1 - later[0])
        hist = np.zeros((rows, n_mid), np.int32)  # (int64 past 2^31 - 1 photons in all)
        shifts = _shift_table(channel_shifts, rebin, n_bins, spath)
        per_hist = _ChannelHists(n_mid, rows)  # (each channel's photons, period and blocks)
        starts = np.zeros(rows + 1, np.int64)  # marker syncs, and the next block's if any
        per_channel = np.zeros(128, np.int64)  # ptufile's channel is an int8
        gaps = _Gaps(period, res)
        n_markers = n_photons = n_ofl = carry = n_before = n_after = n_out = bits_seen = 0
        n_settling = 0
        last_sync = -1
        for raw, dec in _chunks(f, n_records, chunk_records, spath):
            ch, mk, time = dec["channel"], dec["marker"], dec["time"]
            special = ch < 0
            if special.any():
                bits_seen |= int(np.bitwise_or.reduce(mk[special]))
            is_mark = special & ((mk & mask) != 0)
            k = int(np.count_nonzero(is_mark))
            if k and n_markers <= rows:
                take = time[is_mark][: rows + 1 - n_markers].astype(np.int64) + carry
                starts[n_markers : n_markers + take.size] = take
            events = np.flatnonzero(~special | (mk != 0))
            if events.size:
                _check_forward(time[events].astype(np.int64) + carry, last_sync, spath)
                last_sync = int(time[events[-1]]) + carry

            photon = ~special
            if photon.any():
                per_channel += np.bincount(ch[photon].astype(np.int64), minlength=128)[:128]
            if channels is not None:
                photon &= np.isin(ch, channels)
            n_sel = int(np.count_nonzero(photon))
            n_photons += n_sel
            if n_sel:
                gaps.add(time[photon].astype(np.int64) + carry, dec["dtime"][photon],
                         ch[photon])
                block = (np.cumsum(is_mark, dtype=np.int64)
                         + (n_markers - (marker_edge == "start")))[photon]
                bins = dec["dtime"][photon].astype(np.int64) // binning
                if fold > 1:  # (one code period; past the D periods: out of range)
                    bins = np.where(bins < fold * n_bins, bins % n_bins, n_mid)
                keep = block >= 0
                if first_sync:  # ("end": before pattern 0's start, no pattern is known)
                    keep &= (block > 0) | (time[photon].astype(np.int64) + carry >= first_sync)
                n_before += n_sel - int(np.count_nonzero(keep))
                late = block >= rows
                n_after += int(np.count_nonzero(late))
                keep &= ~late
                if settle:  # (each block's start: its marker's sync, or the one after the
                    # marker before it where markers end their patterns)
                    b = np.clip(block, 0, rows - 1)
                    if marker_edge == "start":
                        begin = starts[b]
                    else:
                        begin = np.where(b > 0, starts[np.maximum(b - 1, 0)] + 1, first_sync)
                    early = keep & (time[photon].astype(np.int64) + carry - begin < settle)
                    n_settling += int(np.count_nonzero(early))
                    keep &= ~early
                n_out += int(np.count_nonzero(keep & (bins >= n_mid)))
                keep &= bins < n_mid
                if shifts is not None:  # (a channel's cable delay taken out, bins < n_bins)
                    bins = (bins - shifts[ch[photon].astype(np.int64)]) % n_mid
                if keep.any() and rebin is None:
                    per_hist.add(ch[photon][keep], bins[keep], block[keep], hist)
                if keep.any():
                    if n_photons >= WIDEN_AFTER and hist.dtype == np.int32:
                        # (past 2^31 - 1 photons one bin could wrap to -2^31: an audit)
                        hist = hist.astype(np.int64)
                    accumulate(hist, block[keep], bins[keep])
            n_markers += k
            k_ofl, k_wraps = _overflows(raw, family)
            n_ofl += k_ofl
            carry += k_wraps * wrap

    if n_markers == 0:
        seen = [b + 1 for b in range(4) if bits_seen >> b & 1]
        raise ConfigError(
            f"{spath!r} has no marker records on marker input {marker} (needed to split photons"
            " into patterns); "
            + (f"markers present on inputs {seen}" if seen else "the file has no markers at all"))
    if n_markers < rows - (0 if limit is None else extra_blocks):
        want = rows - extra_blocks
        # (a DLP's trigger once a frame of several patterns read as missed markers: an audit)
        frame = (f" (the {want} patterns are {want // n_markers} times the {n_markers} blocks: "
                 f"a marker a frame of {want // n_markers} patterns, or an acquisition stopped "
                 f"early? reconstruct needs a marker a pattern)"
                 if n_markers > 1 and want % n_markers == 0 else "")
        raise ConfigError(f"{spath!r} has {n_markers} marker-delimited blocks on marker input "
                          f"{marker}, fewer than the {want} patterns" + frame
                          + _missed_note(starts[:n_markers], last_sync, marker_edge, fold))
    if n_markers < rows:  # the extra blocks the file does not hold
        n_after += int(hist[n_markers:].sum(dtype=np.int64))  # ("end": after the last marker)
        rows, hist = n_markers, hist[:n_markers]
    seen_channels = per_channel > 0
    if channels is not None and not seen_channels[channels].all():
        # (every listed channel: [0, 2] on a file without photons on 2 was taken)
        have = ", ".join(map(str, np.flatnonzero(seen_channels))) or "no channel"
        empty = [c for c in np.atleast_1d(channels) if not seen_channels[c]]
        raise ConfigError(
            f"{spath!r} has no photons on channel {', '.join(map(str, empty))} "
            f"(channels are numbered from 0; photons on {have})")
    counts = hist.sum(axis=1, dtype=np.int64)
    if marker_edge == "end":  # pattern k from the sync after marker k - 1 through marker k's
        ends = starts[:rows] + 1
        starts = np.append(first_sync, ends[:-1])
        dwell = ends - starts
    else:
        end = starts[rows] if n_markers > rows else last_sync + 1
        dwell = np.diff(np.append(starts[:rows], end))
    settled = np.zeros(0, np.int64)
    if settle:
        if np.median(dwell) <= settle:
            # (the time is left out in whole syncs: 1 ns read as "(1 syncs)" beside a 102 ns
            # sync, as if the user had given a sync's length, an audit of 2026-12-03)
            whole = (f"rounded up to {settle} whole sync{'s' if settle != 1 else ''} of "
                     f"{period:.4g} s")
            raise ConfigError(f"{spath!r}: the settling time {settle_s:g} s ({whole}) "
                              f"is as long as the blocks' median dwell of "
                              f"{float(np.median(dwell)):.4g} syncs: no photon would be left")
        settled = np.minimum(dwell, settle) * fold
    dwell = dwell * fold  # (in code periods)
    acq = PtuAcquisition(
        histograms=_to_float32(hist) if rebin is None else _rebin(hist, rebin, n_bins),
        counts_per_pattern=counts,
        pattern_start_sync=starts[:rows], last_sync=last_sync,
        sync_period_s=period, resolution_s=res, bin_width_s=width, binning=binning,
        n_records=n_records, n_photons=n_photons, n_markers=n_markers, n_overflows=n_ofl,
        n_dropped_before_first_marker=n_before, n_dropped_after_last_pattern=n_after,
        n_out_of_range=n_out, n_dropped_settling=n_settling, settled_periods=settled,
        header=header,
        periods_per_pattern=dwell,
        periods_per_sync=fold, detection_gaps=gaps.result(),
        photons_per_channel={int(c): int(per_channel[c]) for c in np.flatnonzero(per_channel)},
        channel_histograms=per_hist.out, channel_spread=per_hist.follow(dwell),
        channel_shifts={} if shifts is None else {
            int(c): int(shifts[c]) for c in np.flatnonzero(shifts)})
    if marker_edge == "start" and n_markers == rows and acq.ends_in_empty_block:
        acq.warnings.append(f"the last of the {rows} marker blocks holds no photons and lasts "
                            f"{int(dwell[-1])} code period(s) (an end-of-acquisition marker?): "
                            f"it is kept as a pattern of zeros; n_patterns={rows - 1} leaves "
                            f"it out")
    return acq
