"""Another vendor's time tags as T3 events (and a PTU file), so `reconstruct` reads them.

Time taggers that are not PicoQuant's (Swabian Instruments' Time Tagger, qutools' quTAG, ID
Quantique's ID900/ID1000, an FPGA TDC) give a stream of absolute timestamps, each with the
input channel it arrived on: the code generator's period start on one channel, the DMD's
pattern marker on another, the detector's photons on the rest. A T3 record holds the same
information relative to the last sync: the sync's index (``nsync``) and the delay after it
(``dtime``). :func:`t3_from_timestamps` converts one into the other and
:func:`write_ptu_from_timestamps` writes the result with :func:`~spslidar.io.write_ptu_t3`, so
``spslidar calibrate`` and ``spslidar reconstruct`` read it as they read a PicoHarp's file.

Written here: no library converts a time tagger's absolute stream to PicoQuant's T3 layout
(``ptufile`` only reads, ``tttrlib`` reads vendors' files, not an array in memory), and the
conversion is two sorted searches.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import ConfigError
from .ptu_format import PathLike, _finite_number, _marker_input

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["T3Events", "t3_from_timestamps", "write_ptu_from_timestamps"]

#: the largest relative spread of the sync intervals accepted: a code generator's period start
#: is periodic; a missed or extra sync edge moves every later photon's delay by a period
SYNC_TOL = 0.01


@dataclass
class T3Events:
    """Time-ordered T3 events (:func:`t3_from_timestamps`), as
    :func:`~spslidar.io.write_ptu_t3` takes them.

    Attributes
    ----------
    nsync, dtime, channel, marker : numpy.ndarray
        ``(n,)`` int64: the sync index of each event, its delay after that sync in units of
        ``resolution_s`` (0 for markers), the photon's channel numbered from 0 in the order of
        ``photon_channels`` (0 for markers), and the marker bits (0 for photons).
    resolution_s, sync_period_s : float
        The delay unit, and the median interval between syncs, seconds.
    photon_channels : tuple of int
        The tagger's channels whose events are photons, in the order of their new numbers.
    n_before_first_sync, n_after_last_period : int
        Events left out: before the first sync (no period start is known), and after the
        last sync by more than one period (the stream ended without the next sync).
    """

    nsync: np.ndarray
    dtime: np.ndarray
    channel: np.ndarray
    marker: np.ndarray
    resolution_s: float
    sync_period_s: float
    photon_channels: tuple[int, ...]
    n_before_first_sync: int = 0
    n_after_last_period: int = 0

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
                       photon_channels: ArrayLike | None = None,
                       marker_input: int = 1) -> T3Events:
    """T3 events (sync index, delay after the sync) from a time tagger's absolute timestamps.

    Parameters
    ----------
    times : array_like of int, shape (n,)
        Every event's timestamp in units of ``time_unit_s`` (picoseconds: ``1e-12``),
        non-decreasing, as a time tagger streams them.
    channels : array_like of int, shape (n,)
        Each event's input channel, in the tagger's numbering (negative numbers, a Swabian
        tagger's falling edges, are channels too).
    time_unit_s : float
        Seconds per unit of ``times``.
    sync_channel : int
        The channel of the code generator's period start (each code period begins at one).
    marker_channel : int
        The channel of the DMD's pattern change.
    resolution_s : float
        The delay unit of the T3 events, seconds: ``1 / bit_rate`` (a TDC bin per code bit),
        so that ``reconstruct --bit-rate`` reads one bin per delay unit.
    photon_channels : array_like of int, optional
        The detector's channels, numbered 0, 1, ... in this order in the result (as
        ``reconstruct --channel`` counts them); default every channel that is neither the
        sync's nor the marker's, in increasing order.
    marker_input : int
        The marker input (1..4) the pattern changes are written on (``reconstruct
        --marker``).

    Returns
    -------
    T3Events

    Notes
    -----
    Each event belongs to the last sync at or before it (``nsync``, counted from the
    stream's first sync), and a photon's delay is ``floor((t - t_sync) * time_unit_s /
    resolution_s)``, the TDC bin it fell in. Events before the first sync are left out (no
    period start is known), and so are events more than one period after the last sync.
    The syncs must be periodic within :data:`SYNC_TOL` of their median interval: a missed
    sync edge (a tagger's dead time on that input) would read a whole period's photons a
    period late, so it is refused with the first gap's position. Memory is about 100 bytes
    per event (the stream is held whole; convert a long acquisition in pieces of whole
    patterns, each written as its own file, or through :func:`~spslidar.io.write_ptu_t3_stream`
    with ``nsync`` carried on).

    Raises
    ------
    ConfigError
        Arrays of other lengths or not of integers, times not in order, fewer than two syncs,
        irregular syncs, no marker or no photon events, or bad scalars.
    """
    t = _int_array(times, "times")
    ch = _int_array(channels, "channels")
    if ch.size != t.size:
        raise ConfigError(f"times and channels must have the same length, got {t.size} and "
                          f"{ch.size}")
    unit = _finite_number(time_unit_s, "time_unit_s", positive=True)
    res = _finite_number(resolution_s, "resolution_s", positive=True)
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
                          f"streams in time order first)")
    present = np.unique(ch)
    if photon_channels is None:
        photons = tuple(int(c) for c in present if c not in (sync_channel, marker_channel))
    else:
        photons = tuple(int(c) for c in _int_array(np.atleast_1d(photon_channels),
                                                   "photon_channels"))
        if len(set(photons)) != len(photons) or {sync_channel, marker_channel} & set(photons):
            raise ConfigError(f"photon_channels {list(photons)} must be distinct channels, "
                              f"neither the sync's ({sync_channel}) nor the marker's "
                              f"({marker_channel})")
    is_sync = ch == sync_channel
    syncs = t[is_sync]
    if syncs.size < 2:
        raise ConfigError(f"{syncs.size} event(s) on sync_channel {sync_channel}: the code's "
                          f"period start is needed at every period (channels present: "
                          f"{', '.join(map(str, present)) or 'none'})")
    gaps = np.diff(syncs)
    period = float(np.median(gaps))
    off = np.abs(gaps - period) > SYNC_TOL * period
    if period <= 0 or off.any():
        k = int(np.flatnonzero(off)[0]) if off.any() else 0
        raise ConfigError(
            f"the syncs on channel {sync_channel} are not periodic: {int(off.sum())} of "
            f"{gaps.size} intervals differ from the median {period * unit:.6g} s by more than "
            f"{100 * SYNC_TOL:g} % (the first after sync {k}: {gaps[k] * unit:.6g} s); a missed "
            f"sync edge would read a period's photons a period late")
    is_photon = np.isin(ch, photons) if photons else np.zeros(t.size, bool)
    is_marker = ch == marker_channel
    if not is_marker.any():
        raise ConfigError(f"no event on marker_channel {marker_channel} (channels present: "
                          f"{', '.join(map(str, present))})")
    if not is_photon.any():
        raise ConfigError(f"no photon events: every event is a sync or a marker (channels "
                          f"present: {', '.join(map(str, present))})")
    events = np.flatnonzero(is_photon | is_marker)
    te = t[events]
    nsync = np.searchsorted(syncs, te, side="right") - 1
    before = nsync < 0
    offset = te - syncs[np.maximum(nsync, 0)]
    after = ~before & (nsync == syncs.size - 1) & (offset >= period)
    keep = ~before & ~after
    events, nsync, offset = events[keep], nsync[keep], offset[keep]
    ratio = res / unit  # time units per delay unit
    if abs(ratio - round(ratio)) < 1e-9 * ratio and round(ratio) >= 1:
        dtime = offset // int(round(ratio))  # exact in integers (ps timestamps, 100 ps bins)
    else:  # (the guard: 81 ns in 2.7 ns bins read 29.999999999999996)
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
                    n_before_first_sync=int(before.sum()), n_after_last_period=int(after.sum()))


def write_ptu_from_timestamps(path: PathLike, times: ArrayLike, channels: ArrayLike, *,
                              time_unit_s: float, sync_channel: int, marker_channel: int,
                              resolution_s: float, photon_channels: ArrayLike | None = None,
                              marker_input: int = 1, record_type: str = "GenericT3",
                              comment: str = "") -> T3Events:
    """Write a time tagger's absolute timestamps as a T3 PTU file that ``spslidar calibrate``
    and ``spslidar reconstruct`` read.

    The events are :func:`t3_from_timestamps`'s (the parameters of the same names are its);
    the file is :func:`~spslidar.io.write_ptu_t3`'s, its sync rate the syncs' median
    interval, ``record_type`` (default ``"GenericT3"``: delays below 32768 units, 64
    channels) and ``comment`` as there. Returns the events, with the counts left out.
    """
    from .ptu_write import write_ptu_t3

    ev = t3_from_timestamps(times, channels, time_unit_s=time_unit_s,
                            sync_channel=sync_channel, marker_channel=marker_channel,
                            resolution_s=resolution_s, photon_channels=photon_channels,
                            marker_input=marker_input)
    write_ptu_t3(path, nsync=ev.nsync, dtime=ev.dtime, channel=ev.channel, marker=ev.marker,
                 resolution_s=ev.resolution_s, sync_rate_hz=1.0 / ev.sync_period_s,
                 record_type=record_type, comment=comment)
    return ev
