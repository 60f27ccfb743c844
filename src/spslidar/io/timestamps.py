"""Another vendor's time tags as T3 events (and a PTU file), so `reconstruct` reads them.

Time taggers that are not PicoQuant's (Swabian Instruments' Time Tagger, qutools' quTAG, an
FPGA TDC) give a stream of absolute timestamps, each with the input channel it arrived on:
the code generator's period start on one channel, the DMD's pattern marker on another, the
detector's photons on the rest. (A quTAG's start input is not streamed, or resets its clock:
the sync goes on a stop input. ID Quantique's time controllers give each channel's times
apart, relative to a reference input: with no reference, merged in time order with a channel
array, they are such a stream.) A T3 record holds the same
information relative to the code's period: the period's index (``nsync``) and the delay
after its start (``dtime``). :func:`t3_from_timestamps` converts one into the other and
:func:`write_ptu_from_timestamps` writes the result with :func:`~spslidar.io.write_ptu_t3`, so
``spslidar calibrate`` and ``spslidar reconstruct`` read it as they read a PicoHarp's file.

Written here: the conversion is a few sorted searches on NumPy arrays, with the grid a
conditionally filtered sync needs; ``ptufile`` reads PicoQuant's files and writes none, and
``tttrlib``, which reads several vendors' files, is a compiled package this project does not
depend on for so little.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import ConfigError
from .ptu_format import _FAMILY, PathLike, _finite_number, _marker_input

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["EVENT_TYPE_NAMES", "SYNC_CLOCK_TOL", "SYNC_TOL", "T3Events", "UNEVEN_BINS_RATIO",
           "t3_from_timestamps", "write_ptu_from_timestamps"]

#: the largest distance, as a share of the period, of a sync interval from a whole number of
#: periods: a code generator's period start is periodic (syncs left out by a tagger's filter
#: or dead time leave whole periods; an extra edge or a drifting clock does not)
SYNC_TOL = 0.01
#: how far a tagger's clock may run from the code generator's, relatively, where the period
#: is given (``sync_period_s``): crystals agree to 20-50 ppm; the syncs refine it from there
SYNC_CLOCK_TOL = 1e-4
#: ``event_types`` of a Swabian Time Tagger's ``TimeTagStream.getData().getEventTypes()``:
#: 0 is a time tag; 1 an error, 2 and 3 an overflow's begin and end, 4 missed events (the
#: tagger lost tags there)
EVENT_TYPE_NAMES = {0: "time tag", 1: "error", 2: "overflow begin", 3: "overflow end",
                    4: "missed events"}
#: below this many time units per delay unit (``resolution_s / time_unit_s``), a ratio that
#: is not a whole number is said: the delay bins hold unequal numbers of the timestamps'
#: units, a comb on a flat background of up to ``1 / floor(ratio)`` of its level (5 % here;
#: 1 ps timestamps in 96.97 ps bins comb it by 1 %, under the Poisson noise of 10^4 counts)
UNEVEN_BINS_RATIO = 20.0


@dataclass
class T3Events:
    """Time-ordered T3 events (:func:`t3_from_timestamps`), as
    :func:`~spslidar.io.write_ptu_t3` takes them.

    Attributes
    ----------
    nsync, dtime, channel, marker : numpy.ndarray
        ``(n,)`` int64: the code period of each event (counted from the stream's first
        event), its delay after that period's start in units of ``resolution_s`` (0 for
        markers), the photon's channel numbered from 0 in the order of ``photon_channels`` (0
        for markers), and the marker bits (0 for photons).
    resolution_s, sync_period_s : float
        The delay unit, and the code period read from the syncs, seconds.
    photon_channels : tuple of int
        The tagger's channels whose events are photons, in the order of their new numbers.
    n_before_first_sync : int
        Events before the first sync held, placed on the period's grid back from it (a
        conditional filter never holds the sync before the stream's first event).
    n_missing_syncs : int
        Periods whose sync the stream does not hold (a tagger's conditional filter, a dead
        time on the sync input): their events are placed from the nearest sync held.
    last_sync_time, last_sync_period : int
        The last sync held (time units) and its period: where the next piece of a long
        stream is numbered on from (``after=``).
    last_event_period : int
        The period of the last event kept (a next piece's events come after it).
    """

    nsync: np.ndarray
    dtime: np.ndarray
    channel: np.ndarray
    marker: np.ndarray
    resolution_s: float
    sync_period_s: float
    photon_channels: tuple[int, ...]
    n_before_first_sync: int = 0
    n_missing_syncs: int = 0
    last_sync_time: int = 0
    last_sync_period: int = 0
    last_event_period: int = 0

    @property
    def n_photons(self) -> int:
        """Photon events kept."""
        return int(np.count_nonzero(self.marker == 0))

    @property
    def n_markers(self) -> int:
        """Marker events kept."""
        return int(np.count_nonzero(self.marker))


def _int_array(values: Any, what: str) -> np.ndarray:
    arr = np.asarray(values)
    if arr.ndim != 1:
        raise ConfigError(f"{what} must be one-dimensional, got shape {arr.shape}")
    if arr.dtype.kind not in "iu":
        raise ConfigError(f"{what} must hold integers (a time tagger's timestamps in units of "
                          f"time_unit_s, its channel numbers), got dtype {arr.dtype}")
    if arr.dtype == np.uint64 and arr.size and int(arr.max()) > np.iinfo(np.int64).max:
        raise ConfigError(f"{what} holds values beyond int64")
    return arr.astype(np.int64, copy=False)


def t3_from_timestamps(times: ArrayLike, channels: ArrayLike, *, time_unit_s: float,
                       sync_channel: int, marker_channel: int, resolution_s: float,
                       photon_channels: ArrayLike | None = None, marker_input: int = 1,
                       sync_period_s: float | None = None, event_types: ArrayLike | None = None,
                       syncs_complete: bool = False, after: T3Events | None = None
                       ) -> T3Events:
    """T3 events (code period, delay after its start) from a time tagger's absolute
    timestamps.

    Parameters
    ----------
    times : array_like of int, shape (n,)
        Every event's timestamp in units of ``time_unit_s`` (picoseconds: ``1e-12``),
        non-decreasing, as a time tagger streams them. A counter that wraps (an FPGA TDC's
        coarse counter, a file format's) is unwrapped first, e.g. ``np.unwrap(times,
        period=2**40)``.
    channels : array_like of int, shape (n,)
        Each event's input channel, in the tagger's numbering (negative numbers, a Swabian
        tagger's falling edges, are channels too).
    time_unit_s : float
        Seconds per unit of ``times``; no coarser than ``resolution_s`` (a delay bin
        narrower than a timestamp's unit would stay empty).
    sync_channel : int
        The channel of the code generator's period start (each code period begins at one).
    marker_channel : int
        The channel of the DMD's pattern change.
    resolution_s : float
        The delay unit of the T3 events, seconds: ``1 / bit_rate`` (a TDC bin per code bit),
        so that ``reconstruct --bit-rate`` reads one bin per delay unit.
    photon_channels : array_like of int, optional
        The detector's channels, numbered 0, 1, ... in this order in the result (as
        ``reconstruct --channel`` counts them). Default: the one channel that is neither the
        sync's nor the marker's; where the stream holds more (a second detector, a Swabian
        tagger's falling edges as negative channels, a quTAG's 1 ms tick on 104), they are
        to be named, since every event on them would be read as a photon.
    marker_input : int
        The marker input (1..4) the pattern changes are written on (``reconstruct
        --marker``).
    sync_period_s : float, optional
        The code period, ``L / bit_rate``; default: read from the syncs (the shortest
        intervals' median, refined over the whole stream). Give it where the stream may hold
        no two syncs of adjacent periods; the tagger's clock may then run up to
        :data:`SYNC_CLOCK_TOL` off the generator's, refined from the syncs.
    event_types : array_like of int, shape (n,), optional
        Each event's type where the tagger gives one (a Swabian ``TimeTagStream``'s
        ``getEventTypes()``, :data:`EVENT_TYPE_NAMES`): a stream with any event other than a
        time tag (0) is refused, since the tagger lost events there and the patterns'
        photon counts would be short without a word.
    syncs_complete : bool
        The stream holds every sync (no conditional filter on the sync input): a period
        without one is then refused, where it would otherwise be taken for a filtered sync
        (a tagger's overflow or a buffer overrun leaves a gap that looks the same, and the
        pattern keeps its full dwell with part of its photons).
    after : T3Events, optional
        The events of the stream's previous piece: this piece's periods are numbered on
        from its last sync (only the gap between the pieces is read from this piece's
        period), so that the pieces of a long acquisition converted one by one join into one
        file (:func:`~spslidar.io.write_ptu_t3_stream`). Default: periods from the stream's
        first event's.

    Returns
    -------
    T3Events

    Notes
    -----
    The syncs give the period ``P``, refined as the span of the syncs over the periods it
    holds, and each sync's period number (a sync interval is a whole number of periods: a
    tagger's conditional filter, which passes only the syncs that follow a photon, and a
    dead time on the sync input leave syncs out, which is allowed). Each event is placed
    from its own period's sync or, where that one is missing, from the nearest sync held,
    before or after: its period ``k_sync + floor((t - t_sync) / P)`` and its delay
    ``floor(((t - t_sync) mod P) * time_unit_s / resolution_s)``, the TDC bin it fell in.
    Events before the first sync are placed back from it, and the periods are numbered from
    the earliest event's. A sync interval more than :data:`SYNC_TOL`
    of a period off a whole number of periods (an extra edge, a sync that wanders; a steady
    difference between the tagger's clock and the generator's is the refined ``P``'s) is
    refused with its position. Memory is about 100 bytes per event (the stream is held whole;
    convert a long acquisition in pieces of two syncs or more, each given the one before as
    ``after``, and write them through :func:`~spslidar.io.write_ptu_t3_stream`).

    Raises
    ------
    ConfigError
        Arrays of other lengths or not of integers, times not in order, fewer than two syncs,
        irregular syncs, no marker or no photon events, events other than time tags, periods
        without a sync where ``syncs_complete``, several candidate photon channels with none
        named, or bad scalars.
    """
    t = _int_array(times, "times")
    ch = _int_array(channels, "channels")
    if ch.size != t.size:
        raise ConfigError(f"times and channels must have the same length, got {t.size} and "
                          f"{ch.size}")
    unit = _finite_number(time_unit_s, "time_unit_s", positive=True)
    res = _finite_number(resolution_s, "resolution_s", positive=True)
    if event_types is not None:
        _check_event_types(event_types, t.size)
    if not isinstance(syncs_complete, bool | np.bool_):
        raise ConfigError(f"syncs_complete must be True or False, got {syncs_complete!r}")
    if unit > res * (1 + 1e-9):
        raise ConfigError(f"time_unit_s {unit:g} s is coarser than resolution_s {res:g} s: delay "
                          f"bins narrower than the timestamps' unit would stay empty (a "
                          f"coarser resolution_s, or the tagger's fine timestamps)")
    ratio = res / unit  # time units per delay unit
    if ratio < UNEVEN_BINS_RATIO and abs(ratio - round(ratio)) > 1e-6 * ratio:
        warnings.warn(f"resolution_s {res:g} s holds {ratio:.4g} of the timestamps' units of "
                      f"{unit:g} s, not a whole number: the delay bins hold "
                      f"{int(np.floor(ratio))} or {int(np.ceil(ratio))} of them, so a flat "
                      f"background comes out combed by up to {100 / np.floor(ratio):.2g} %",
                      stacklevel=2)
    bits = 1 << (_marker_input(marker_input) - 1)
    for name, value in (("sync_channel", sync_channel), ("marker_channel", marker_channel)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer):
            raise ConfigError(f"{name} must be an integer channel, got {value!r}")
    if sync_channel == marker_channel:
        raise ConfigError(f"sync_channel and marker_channel are both {sync_channel}: the code's "
                          f"period start and the pattern change need their own inputs")
    if t.size > 1 and np.any(np.diff(t) < 0):
        first = int(np.flatnonzero(np.diff(t) < 0)[0]) + 1
        raise ConfigError(f"times must be non-decreasing, as a time tagger streams them: event "
                          f"{first} is earlier than the one before it (merge the channels' "
                          f"streams in time order, or unwrap a counter that wrapped, first)")
    present = np.unique(ch)
    if photon_channels is None:
        photons = tuple(int(c) for c in present if c not in (sync_channel, marker_channel))
        if len(photons) > 1:
            raise ConfigError(f"the stream holds {len(photons)} channels besides the sync's and "
                              f"the marker's ({', '.join(map(str, photons))}): give "
                              f"photon_channels, the detector's (every event on a channel "
                              f"named would be read as a photon)")
    else:
        photons = tuple(int(c) for c in _int_array(np.atleast_1d(photon_channels),
                                                   "photon_channels"))
        if len(set(photons)) != len(photons) or {sync_channel, marker_channel} & set(photons):
            raise ConfigError(f"photon_channels {list(photons)} must be distinct channels, "
                              f"neither the sync's ({sync_channel}) nor the marker's "
                              f"({marker_channel})")
    syncs = t[ch == sync_channel]
    if syncs.size < 2:
        raise ConfigError(f"{syncs.size} event(s) on sync_channel {sync_channel}: the code's "
                          f"period start is needed (channels present: "
                          f"{', '.join(map(str, present)) or 'none'})")
    syncs, index, period, missing = _sync_grid(syncs, sync_channel, unit, sync_period_s)
    if syncs_complete:
        _check_complete(t, syncs, index, period, missing, sync_channel, unit)
    is_photon = np.isin(ch, photons) if photons else np.zeros(t.size, bool)
    is_marker = ch == marker_channel
    # (a piece after another may lie within one pattern, or hold no photon: its stream's
    # markers and photons are the pieces' together)
    if not is_marker.any() and after is None:
        raise ConfigError(f"no event on marker_channel {marker_channel} (channels present: "
                          f"{', '.join(map(str, present))})")
    if not is_photon.any() and after is None:
        raise ConfigError(f"no photon events: every event is a sync or a marker (channels "
                          f"present: {', '.join(map(str, present))})")
    events = np.flatnonzero(is_photon | is_marker)
    te = t[events]
    before = te < syncs[0]  # (placed back from the first sync: a conditional filter never
    # holds the sync before the stream's first event, whose marker was lost, a review)
    # each event from its own period's sync; where that one is missing, from the nearest one
    # held, before or after (the shortest reach over periods without a sync)
    prev = np.maximum(np.searchsorted(syncs, te, side="right") - 1, 0)
    nxt = np.minimum(prev + 1, syncs.size - 1)
    ref = np.where((te - syncs[prev] < period) | (te - syncs[prev] <= syncs[nxt] - te), prev,
                   nxt)
    since = (te - syncs[ref]).astype(np.float64)
    steps = np.floor(since / period + 1e-12)
    nsync = index[ref] + steps.astype(np.int64)
    offset = since - steps * period  # in [0, period): the time units after the period's start
    first = 0  # the period of the first sync held
    if after is not None:
        first = _period_after(after, int(syncs[0]), period, unit)
        nsync = nsync + first
        if nsync.size and nsync.min() < after.last_event_period:
            raise ConfigError(f"this piece has events in period {int(nsync.min())}, before the "
                              f"previous piece's last ({after.last_event_period}): the pieces of "
                              f"one stream, in order, without overlap")
    elif nsync.size and nsync.min() < 0:  # (the periods before the first sync: from 0 on)
        first = -int(nsync.min())
        nsync = nsync + first
    if np.any(np.diff(nsync) < 0):  # (syncs' jitter at a period's edge: order by period)
        order = np.argsort(nsync, kind="stable")
        events, nsync, offset = events[order], nsync[order], offset[order]
    # (the guard: 81 ns in 2.7 ns bins read 29.999999999999996)
    dtime = np.floor(offset / ratio + 1e-9).astype(np.int64)
    photon = is_photon[events]
    channel = np.zeros(events.size, np.int64)
    if photon.any():  # each photon's channel by its place in photon_channels
        order = np.argsort(np.asarray(photons, np.int64))
        place = np.searchsorted(np.asarray(photons, np.int64)[order], ch[events][photon])
        channel[photon] = order[place]
    return T3Events(nsync=nsync.astype(np.int64), dtime=np.where(photon, dtime, 0),
                    channel=channel, marker=np.where(photon, 0, bits).astype(np.int64),
                    resolution_s=res, sync_period_s=period * unit, photon_channels=photons,
                    n_before_first_sync=int(before.sum()), n_missing_syncs=missing,
                    last_sync_time=int(syncs[-1]), last_sync_period=int(index[-1]) + first,
                    last_event_period=int(nsync.max()) if nsync.size else first)


def _check_complete(t: np.ndarray, syncs: np.ndarray, index: np.ndarray, period: float,
                    missing: int, sync_channel: int, unit: float) -> None:
    """Refuse, in one line, a stream said to hold every sync (``syncs_complete``) that lacks
    one: a period between two syncs held, or events more than a period before the first or
    after the last."""
    if missing:
        gap = int(np.flatnonzero(np.diff(index) > 1)[0])
        raise ConfigError(f"{missing} period(s) without a sync on channel {sync_channel}, the "
                          f"first after sync {gap} (at {syncs[gap] * unit:.9g} s), though "
                          f"syncs_complete: the tagger lost events there (an overflow, a "
                          f"buffer overrun), so those patterns' photons are short")
    reach = period * (1 + SYNC_TOL)  # (a period before the first sync, after the last)
    out = int(np.count_nonzero((t < syncs[0] - reach) | (t >= syncs[-1] + reach)))
    if out:
        raise ConfigError(f"{out} event(s) more than a period before the first sync or after "
                          f"the last on channel {sync_channel}, though syncs_complete: the "
                          f"tagger lost the syncs there")


def _period_after(after: Any, first_sync: int, period: float, unit: float) -> int:
    """The period of a piece's first sync, numbered on from the previous piece ``after``'s
    last sync across the gap between them, or one line."""
    if not isinstance(after, T3Events):
        raise ConfigError(f"after must be the previous piece's T3Events, got "
                          f"{type(after).__name__}")
    gap = (float(first_sync) - float(after.last_sync_time)) / period
    whole = round(gap)
    if whole < 1 or abs(gap - whole) > SYNC_TOL:
        raise ConfigError(f"this piece's first sync lies {gap:.6g} periods after the previous "
                          f"piece's last ({(first_sync - after.last_sync_time) * unit:.9g} s), "
                          f"not a whole number of periods after it: the pieces of one stream, "
                          f"in order, each given the one before as after=")
    return int(after.last_sync_period) + int(whole)


def _check_event_types(event_types: ArrayLike, n: int) -> None:
    """Refuse a stream with events other than time tags (:data:`EVENT_TYPE_NAMES`)."""
    kinds = _int_array(event_types, "event_types")
    if kinds.size != n:
        raise ConfigError(f"event_types must have one entry per event, got {kinds.size} for {n}")
    other = np.flatnonzero(kinds != 0)
    if other.size:
        k = int(other[0])
        names = sorted({EVENT_TYPE_NAMES.get(int(v), f"type {int(v)}") for v in kinds[other]})
        raise ConfigError(f"{other.size} event(s) are not time tags ({', '.join(names)}; the "
                          f"first is event {k}): the tagger lost events there, so the "
                          f"patterns' photon counts would be short; record at a lower rate "
                          f"(or convert the stream's part before the first)")


def _sync_grid(syncs: np.ndarray, sync_channel: int, unit: float,
               sync_period_s: float | None) -> tuple[np.ndarray, np.ndarray, float, int]:
    """The syncs, their period numbers, the period (time units) and the periods without a
    sync, or one line (:func:`t3_from_timestamps`).

    The period is refined from the short intervals out: each pass numbers the intervals its
    period is precise enough for (a quarter of a period of error at most) and refits the
    period over all of them, so that intervals of thousands of periods are numbered from a
    period known to a part in millions (a guess from one-period intervals in whole
    picoseconds is off by up to half a unit, 0.04 of a period over 1000 of 12.8 ns, beyond
    the 1 % tolerance: a review of 2026-11-29 found a perfect grid refused so, and a clock
    20 ppm off a given period)."""
    gaps = np.diff(syncs)
    if np.any(gaps <= 0):
        k = int(np.flatnonzero(gaps <= 0)[0])
        raise ConfigError(f"two syncs on channel {sync_channel} at the same time (syncs {k} and "
                          f"{k + 1}): one edge was recorded twice")
    if sync_period_s is None:  # the intervals of one period: the shortest ones
        short = gaps[gaps < 1.5 * gaps.min()]
        period = float(np.median(short))
        # its error: the jitter of the one-period intervals, and the timestamps' own unit
        error = (float(np.ptp(short)) + 1.0) / period
    else:
        period = _finite_number(sync_period_s, "sync_period_s", positive=True) / unit
        error = SYNC_CLOCK_TOL  # a tagger's clock against the generator's
    numbered = np.zeros(gaps.size, bool)
    while True:
        reach = gaps / period * error < 0.25  # numbered right: within a quarter period
        reach &= gaps >= (1 - SYNC_TOL) * period
        if not reach.any() or (numbered.any() and (reach == numbered).all()):
            break
        numbered = reach
        whole = np.round(gaps[numbered] / period)
        span = float(gaps[numbered].sum())
        fitted = (2.0 * np.sqrt(numbered.sum()) * max(1.0, _jitter(gaps, period))) / span
        if fitted < error:  # (a period given is kept until the syncs know it better)
            period, error = span / float(whole.sum()), fitted
        if numbered.all():
            break
    whole = np.round(gaps / period)
    off = (whole < 1) | (np.abs(gaps - whole * period) > SYNC_TOL * period)
    if off.any():
        k = int(np.flatnonzero(off)[0])
        raise ConfigError(
            f"the syncs on channel {sync_channel} are not on one period's grid: {int(off.sum())} "
            f"of {gaps.size} intervals are more than {100 * SYNC_TOL:g} % of the period "
            f"{period * unit:.9g} s off a whole number of periods (the first after sync {k}: "
            f"{gaps[k] * unit:.9g} s): an extra sync edge, or a sync that wanders"
            + ("" if sync_period_s is not None else "; sync_period_s gives the period where no "
               "two syncs of adjacent periods are recorded"))
    index = np.concatenate([[0], np.cumsum(whole)]).astype(np.int64)
    period = float(syncs[-1] - syncs[0]) / float(index[-1])  # (the tagger's clock's period)
    return syncs, index, period, int(index[-1] + 1 - syncs.size)


def _jitter(gaps: np.ndarray, period: float) -> float:
    """The syncs' timing scatter, in time units: the spread of the one-period intervals."""
    one = gaps[np.abs(gaps - period) < 0.5 * period]
    return float(np.std(one)) if one.size > 1 else 0.0


def write_ptu_from_timestamps(path: PathLike, times: ArrayLike, channels: ArrayLike, *,
                              time_unit_s: float, sync_channel: int, marker_channel: int,
                              resolution_s: float, photon_channels: ArrayLike | None = None,
                              marker_input: int = 1, sync_period_s: float | None = None,
                              event_types: ArrayLike | None = None, syncs_complete: bool = False,
                              after: T3Events | None = None, record_type: str = "GenericT3",
                              comment: str = "") -> T3Events:
    """Write a time tagger's absolute timestamps as a T3 PTU file that ``spslidar calibrate``
    and ``spslidar reconstruct`` read.

    The events are :func:`t3_from_timestamps`'s (the parameters of the same names are its);
    the file is :func:`~spslidar.io.write_ptu_t3`'s, its sync period the one read from the
    syncs, ``record_type`` (default ``"GenericT3"``: delays below 32768 units, 64 channels)
    and ``comment`` as there. Returns the events written (:class:`T3Events`).

    As :func:`~spslidar.io.write_ptu_t3` (and :func:`numpy.save`), a file at ``path`` is
    replaced: the library functions write where they are told; the commands (``run
    --save-ptu``) are the ones that refuse to replace a file they did not write.
    """
    from .ptu_write import _record_type, write_ptu_t3

    # (the record type first: a typo is refused before the conversion's work)
    kind, _, family, _ = _record_type(record_type)
    dtime_max = _FAMILY[family][1]
    ev = t3_from_timestamps(times, channels, time_unit_s=time_unit_s,
                            sync_channel=sync_channel, marker_channel=marker_channel,
                            resolution_s=resolution_s, photon_channels=photon_channels,
                            marker_input=marker_input, sync_period_s=sync_period_s,
                            event_types=event_types, syncs_complete=syncs_complete,
                            after=after)
    bins = int(np.ceil(ev.sync_period_s / ev.resolution_s - 1e-9))  # (the period's, not only
    # those the photons happened to reach: a late photon decided it, a review)
    if bins > dtime_max:
        raise ConfigError(f"the code period of {ev.sync_period_s:.6g} s holds "
                          f"{ev.sync_period_s / ev.resolution_s:.6g} delay units of "
                          f"resolution_s {ev.resolution_s:g} s, more than {kind} records "
                          f"hold ({dtime_max}): a coarser resolution_s")
    write_ptu_t3(path, nsync=ev.nsync, dtime=ev.dtime, channel=ev.channel, marker=ev.marker,
                 resolution_s=ev.resolution_s, sync_rate_hz=1.0 / ev.sync_period_s,
                 record_type=record_type, comment=comment)
    return ev
