"""PicoQuant T2 files that recorded the code generator's sync, read as their T3 file would be.

A T2 record holds an absolute time tag (in units of the header's
``MeasDesc_GlobalResolution``), not a delay after the last sync. Where the sync was recorded
too, every photon's delay is the time since the last sync record before it, and its code
period the number of sync records before it: exactly what a T3 record's ``dtime`` and
``nsync`` are. :func:`open_t2` wraps an open ``ptufile.PtuFile`` of such a file so that the
T3 reader (:func:`spslidar.io.read_ptu_histograms`) reads its records chunk by chunk as T3
events, whatever the reader does with them (blocks, binning, sync divider, settling).

Record layouts (32-bit little-endian words, PicoQuant's published T2 formats, as
``libtcspc``'s decoder and PicoQuant's own descriptions of T2 mode give them):

=====================  ======================================================================
``PicoHarpT2``         channel 4 bits (31-28), time tag 28 bits (27-0). Channel 15 is special:
                       the tag's low 4 bits 0 an overflow (+210698240), else a marker bit mask
                       (the marker's tag is the rest). Channels 0..4 are inputs: the
                       PicoHarp 300's two inputs are alike in T2, and its input 0, the one
                       its T3 mode reads the sync on, is read as the sync here; 1..4 are the
                       detector's channels 0..3 (as its T3 records number them).
``HydraHarpT2``        special 1 bit (31), channel 6 bits (30-25), time tag 25 bits (24-0).
                       Special: channel 63 an overflow (+33552000), channel 0 a **sync**
                       record, channels 1..15 a marker bit mask; photons on channels 0..63.
``HydraHarp2T2``       as ``HydraHarpT2`` but an overflow adds ``33554432`` times its tag
                       (a tag of 0 counts as 1); ``TimeHarp260NT2``, ``TimeHarp260PT2`` and
                       ``GenericT2`` (MultiHarp, PicoHarp 330) use the same layout.
=====================  ======================================================================

``ptufile`` decodes a HydraHarp T2 sync record as a photon on channel 0 (found by encoding
one), so the records are decoded here, with NumPy; ``ptufile`` still opens the file and reads
its header.

**The delay unit** is the time tag's, ``MeasDesc_GlobalResolution`` (1 ps on a HydraHarp,
4 ps on a PicoHarp 300): a delay is a difference of two tags, a whole number of it. It stands
where a T3 file's TDC resolution stands, under the same rules: ``--bit-rate`` must equal it,
or, with ``--allow-binning``, be a whole number of tags (merged) or not (split by overlap).
(``MeasDesc_Resolution``, the TDC's own bin, is kept as ``tdc_resolution_s`` in the header
summary: binning 1 ps tags into 100 ps bits is exact, 8 ps ones into them would not be.)

**The sync period** is measured from the file's sync records (a T2 header gives none): the
median interval, refined over the intervals of one period in the first chunks read, and it is
checked against the code period as a T3 file's header's is. A sync divider in the header
(``HWSync_Divider``) divides the recorded syncs as it does in T3. Events before the file's
first sync are placed on the period's grid back from it (as
:func:`~spslidar.io.t3_from_timestamps` places them), so that no photon is lost. A photon is
read by its time, also where it is recorded after a sync a little later than it (inputs
merged in the hardware's order); a step back of more than ``BACK_SYNCS`` periods is refused
(files joined end to end). A marker keeps its place in the record order, as in T3 (the
photons after it are its pattern's), and is given at least the code period of the events
recorded before it (its tag is coarser, and it may come late in the stream).

A T2 file without any sync record is refused in one line: its photons have no code period to
be read against (record in T3, or record the sync), and where one of its detector channels
holds periodic events, the line names it. **The sync on a detector input** (``--sync-channel
C``, HydraHarp, TimeHarp and MultiHarp files) is read from that channel's events as from sync
records: they are the syncs, and the file's own sync records, if any, are not read.
"""

from __future__ import annotations

import math
import os
import warnings
from typing import Any

import numpy as np

from ..errors import ConfigError
from .ptu_blocks import BACK_SYNCS
from .ptu_format import _FAMILY, raw_chunks
from .timestamps import SYNC_TOL

__all__ = ["SYNC_JITTER_BINS", "T2_WRAP", "T2Records", "check_sync_channel", "open_t2",
           "t2_overflows"]

#: time tag units per overflow, per layout family (:data:`~spslidar.io.ptu_format._T2_FAMILY`)
T2_WRAP = {"t2-picoharp": 210698240, "t2-hydraharp1": 33552000, "t2-hydraharp2": 33554432}
#: a decoded record's kind
_PHOTON, _SYNC, _MARKER, _OTHER = 0, 1, 2, 3
#: sync intervals read to measure the period (the chunks that hold them are read)
_PERIOD_SYNCS = 4096
#: a sync channel's jitter (RMS, in code bins) past which it is said
SYNC_JITTER_BINS = 0.25
#: the tolerance of a sync interval in time tags, where SYNC_TOL of the period is less: a tag
#: of rounding at each end and a sync's jitter of a tag or two
SYNC_TAGS = 4.0
#: the share of sync intervals off the period above which the file's syncs are refused as no
#: code generator's (a detector's photons on the sync input: 84 % off, an audit); below it,
#: glitches, said
SYNC_OFF_SHARE = 0.05
#: the last syncs carried from one chunk to the next (a photon recorded after a sync on
#: another input may lie before it, by up to BACK_SYNCS periods)
_CARRY = BACK_SYNCS + 2


def check_sync_channel(value: Any, family: str, record_type: str, path: str) -> int | None:
    """``--sync-channel`` checked against the file: None, or a detector channel its T2
    records can hold; one line otherwise (a T3 file's records count the syncs themselves)."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise ConfigError(f"--sync-channel must be a detector channel number >= 0, got "
                          f"{value!r}")
    if not family.startswith("t2"):
        raise ConfigError(f"{path!r} holds T3 records ({record_type}), which count the syncs "
                          f"themselves: --sync-channel is for a T2 file whose sync went to a "
                          f"detector input")
    top = _FAMILY[family][2]
    if value >= top:
        raise ConfigError(f"--sync-channel {value}: {record_type} records number detector "
                          f"channels 0..{top - 1}")
    return int(value)


def _fields(raw: np.ndarray, family: str, sync_channel: int | None = None
            ) -> tuple[np.ndarray, ...]:
    """Per record: kind (:data:`_PHOTON`...), time tag (int64, before the overflows), channel
    (0-based detector channel of a photon) or marker bits, and the overflows it adds; with
    ``sync_channel`` (not for a PicoHarp), that channel's events are the syncs and the sync
    records are not."""
    raw = raw.astype(np.uint32, copy=False)
    if family == "t2-picoharp":
        ch = (raw >> 28).astype(np.int64)
        tag = (raw & 0x0FFFFFFF).astype(np.int64)
        low = tag & 15
        special = ch == 15
        kind = np.where(special, np.where(low == 0, _OTHER, _MARKER),
                        np.where(ch == 0, _SYNC, _PHOTON)).astype(np.int8)
        tag = np.where(special, tag - low, tag)  # (a marker's tag without its bits)
        value = np.where(special, low, ch - 1)
        n_ofl = (special & (low == 0)).astype(np.int64)
        return kind, tag, value, n_ofl
    special = (raw >> 31) != 0
    ch = ((raw >> 25) & 63).astype(np.int64)
    tag = (raw & 0x1FFFFFF).astype(np.int64)
    ofl = special & (ch == 63)
    kind = np.where(~special, _PHOTON, np.where(ch == 0, _SYNC, np.where(
        (ch >= 1) & (ch <= 15), _MARKER, _OTHER))).astype(np.int8)
    if sync_channel is not None:  # (the sync on a detector input: --sync-channel)
        kind[kind == _SYNC] = _OTHER
        kind[(kind == _PHOTON) & (ch == sync_channel)] = _SYNC
    if family == "t2-hydraharp1":
        n_ofl = ofl.astype(np.int64)
    else:
        n_ofl = np.where(ofl, np.maximum(tag, 1), 0)
    return kind, tag, ch, n_ofl


def t2_overflows(raw: np.ndarray, family: str) -> int:
    """Overflow (time tag wrap) records in a chunk of raw T2 records."""
    raw = raw.astype(np.uint32, copy=False)
    if family == "t2-picoharp":
        return int(np.count_nonzero(((raw >> 28) == 15) & ((raw & 15) == 0)))
    return int(np.count_nonzero((raw >> 25) == 0x7F))


def _times(raw: np.ndarray, family: str, base: int, sync_channel: int | None = None
           ) -> tuple[np.ndarray, ...]:
    """(kind, absolute time tags, channel or marker bits, the overflow base after the chunk)."""
    kind, tag, value, n_ofl = _fields(raw, family, sync_channel)
    wraps = np.cumsum(n_ofl) * T2_WRAP[family]
    t = base + wraps + tag
    return kind, t, value, base + (int(wraps[-1]) if wraps.size else 0)


class _Decoder:
    """One pass over a T2 file's records as T3 events: each chunk's photons and markers with
    their code period (``time``: the sync records before them, numbered from the file's
    first period) and delay (``dtime``, time tag units since that period's sync), carrying
    the overflows and the last sync from chunk to chunk."""

    def __init__(self, family: str, period: float, first_sync: int, first_period: int,
                 path: str, sync_channel: int | None = None):
        self.family, self.period, self.path = family, period, path
        self.first_sync, self.first_period = first_sync, first_period
        self.sync_channel = sync_channel
        self.base = 0  # time tags of the overflows so far
        self.n_syncs = 0  # sync records so far
        self.recent = np.zeros(0, np.int64)  # the last syncs' time tags (at most _CARRY)
        self.latest = -1  # the latest photon or sync time tag (their order is checked)
        self.period_so_far = 0  # the latest event's code period

    def _backwards(self) -> ConfigError:
        return ConfigError(f"{self.path!r}: its time tags run backwards (a photon or sync "
                           f"more than {BACK_SYNCS} sync periods earlier than one recorded "
                           f"before it), which no acquisition records: files joined end to "
                           f"end, or a corrupt file")

    def __call__(self, raw: np.ndarray) -> dict[str, np.ndarray]:
        kind, t, value, self.base = _times(raw, self.family, self.base, self.sync_channel)
        timed = (kind == _PHOTON) | (kind == _SYNC)  # (markers' tags are coarser: not checked)
        tt = t[timed]
        # (a photon a little earlier than a sync or photon on another input recorded before
        # it is read by its time; a step back of more than BACK_SYNCS periods is no
        # acquisition's)
        if tt.size:
            ahead = np.maximum.accumulate(np.concatenate([[self.latest], tt]))
            if np.any(tt < ahead[:-1] - BACK_SYNCS * self.period):
                raise self._backwards()
            self.latest = int(ahead[-1])
        syncs = t[kind == _SYNC]
        ev = np.flatnonzero((kind == _PHOTON) | (kind == _MARKER))
        te = t[ev]
        grid = np.concatenate([self.recent, syncs])
        first = self.n_syncs - self.recent.size  # the sync number of grid[0]
        i = np.searchsorted(grid, te, side="right") - 1
        marker = kind[ev] == _MARKER
        if self.family == "t2-picoharp" and marker.any():
            # (a PicoHarp marker's tag lacks its low 4 bits, which hold the marker: compared
            # with the syncs' full tags, a marker at its sync's tag was read a period early,
            # every dwell then one period off, an outside audit; the wrap is a multiple of 16)
            i[marker] = np.searchsorted(grid & ~15, te[marker], side="right") - 1
        before = i < 0
        if self.n_syncs:  # (a marker's coarse tag before the syncs carried: the first's)
            photon = kind[ev] == _PHOTON
            if first > 0 and np.any(before & photon):  # (periods before the syncs carried)
                raise self._backwards()
            # (before the file's first sync, recorded after it: placed back from it as the
            # first chunk's are; it was refused at some chunk boundaries only, a review)
            before &= photon
            i = np.maximum(i, 0)
        nsync = np.empty(ev.size, np.int64)
        dtime = np.empty(ev.size, np.int64)
        at = ~before
        if at.any():
            nsync[at] = self.first_period + first + i[at]
            dtime[at] = te[at] - grid[i[at]]
        if before.any():  # (before the file's first sync: on its period's grid back from it)
            since = (te[before] - self.first_sync).astype(np.float64)
            steps = np.floor(since / self.period)
            nsync[before] = self.first_period + steps.astype(np.int64)
            dtime[before] = np.floor(since - steps * self.period + 1e-9).astype(np.int64)
        # (a marker's tag, coarser and late in the stream, may lie periods before the photons
        # recorded ahead of it: it is given at least their period, so that the count never
        # runs backwards, which the reader refuses as files joined end to end)
        if nsync.size:
            nsync = np.maximum.accumulate(np.maximum(nsync, self.period_so_far))
            self.period_so_far = int(nsync[-1])
        self.n_syncs += int(syncs.size)
        self.recent = grid[-_CARRY:]
        return {"time": nsync, "dtime": np.where(marker, 0, dtime),
                "channel": np.where(marker, -1, value[ev]).astype(np.int8),
                "marker": np.where(marker, value[ev], 0).astype(np.uint8)}


class T2Records:
    """An open T2 file that recorded the sync (:func:`open_t2`), as the T3 reader reads it:
    ``filehandle`` and ``record_offset`` as ``ptufile.PtuFile``'s, and :meth:`decoder` for
    one pass over its records."""

    def __init__(self, f: Any, family: str, period: float, first_sync: int, first_period: int,
                 path: str, sync_channel: int | None = None):
        self.file, self.family, self.period = f, family, period
        self.first_sync, self.first_period, self.path = first_sync, first_period, path
        self.sync_channel = sync_channel

    @property
    def filehandle(self) -> Any:
        """The file's handle (``ptufile``'s)."""
        return self.file.filehandle

    @property
    def record_offset(self) -> int:
        """The byte offset of the first record."""
        return int(self.file.record_offset)

    def decoder(self) -> _Decoder:
        """A decoder for one pass over the records from the first: call it on each chunk of
        raw records in turn; it returns the chunk's photons and markers as T3 events
        (``time``: global sync count, ``dtime``, ``channel``: -1 for markers, ``marker``)."""
        return _Decoder(self.family, self.period, self.first_sync, self.first_period,
                        self.path, self.sync_channel)


def _periodic_channel(t: np.ndarray, ch: np.ndarray) -> tuple[int, float] | None:
    """A photon channel whose events come at whole numbers of one period (the sync recorded
    on a detector input), and that period in tags; None where none does."""
    for c in np.unique(ch):
        tc = np.sort(t[ch == c])
        if tc.size < 64:
            continue
        gaps = np.diff(tc).astype(np.float64)
        median = float(np.median(gaps))
        if not median > 0:
            continue
        whole = np.round(gaps / median)
        on = (whole >= 1) & (np.abs(gaps - whole * median)
                             <= max(SYNC_TOL * median, SYNC_TAGS))
        if on.mean() >= 1 - SYNC_OFF_SHARE:
            return int(c), median
    return None


def _no_sync(header: dict[str, Any], path: str, family: str, n: int,
             probe: tuple[np.ndarray, np.ndarray] | None = None,
             sync_channel: int | None = None) -> ConfigError:
    """The one line refusing a T2 file of ``n`` (0 or 1) sync records: what to record, and,
    where ``probe`` (the first photons' tags and channels) holds a channel of periodic events,
    that channel and the option that reads it as the sync."""
    if sync_channel is not None:
        return ConfigError(f"{path!r}: its channel {sync_channel} (--sync-channel) holds "
                           f"{'no event' if n == 0 else 'a single event'}, so no code period "
                           f"to read the photons' delays from (channels with events: "
                           f"{', '.join(map(str, np.unique(probe[1]).tolist())) or 'none'})")
    where = ("on its input 0 (channel 0 of its T2 records)" if family == "t2-picoharp" else
             "on its sync input (sync records)")
    said = "no sync record" if n == 0 else "a single sync record"
    found = _periodic_channel(*probe) if probe is not None and probe[0].size else None
    hint = ""
    if found is not None:  # (the sync on a detector input: the data hold it, an audit)
        c, every = found
        unit = header.get("time_unit_s") or 0.0
        hint = (f"; its channel {c} holds periodic events (every {every * unit:.6g} s): the "
                f"sync on a detector input? "
                + ("a PicoHarp reads its sync on input 0: connect it there"
                   if family == "t2-picoharp" else
                   f"--sync-channel {c} reads them as the sync"))
    return ConfigError(f"{path!r} holds T2 records ({header['record_type']}) with {said}: "
                       f"absolute time tags, no code period to read the photons' delays from; "
                       f"record the lidar in T3 mode, or record the code generator's sync in "
                       f"T2 {where}{hint}")


def _say_jitter(resid: np.ndarray, code_bin: float, unit: float, path: str,
                channel: int) -> None:
    """Warn where a sync channel's events jitter by more than :data:`SYNC_JITTER_BINS` of a
    code bin: each gap's departure from whole periods is two syncs' jitters, less the time
    tags' rounding (a twelfth of a tag squared each). A detector input's sync (a photodiode,
    a discriminator) can jitter where the code generator's sync output does not, and every
    photon's delay carries it: a bin of jitter took a map from 100 % to 75 % of its pixels
    within 5 cm, without a word (an outside audit of stop 67). (A sync divider the file does
    not record makes the bin look wider, so this errs towards saying nothing.)"""
    if resid.size < 2:
        return
    jitter = math.sqrt(max(float(np.var(resid)) / 2 - 1 / 12, 0.0))  # in tags
    if jitter > SYNC_JITTER_BINS * code_bin:
        warnings.warn(f"{path!r}: the events of channel {channel}, read as the sync "
                      f"(--sync-channel), jitter by {jitter * unit * 1e12:.3g} ps RMS "
                      f"({jitter / code_bin:.2g} code bins) about a steady period, and every "
                      f"photon's delay carries it, blurring each return by as much: a sync "
                      f"taken from the code generator's own output is steadier",
                      RuntimeWarning, stacklevel=4)


def open_t2(f: Any, header: dict[str, Any], family: str, n_records: int, chunk_records: int,
            path: str, sync_channel: int | None = None, n_bins: int | None = None
            ) -> tuple[T2Records, dict[str, Any]]:
    """A T2 file's records as the T3 reader reads them, and its header summary with the
    sync period measured from its sync records.

    Parameters
    ----------
    f : ptufile.PtuFile
        The open file.
    header : dict
        Its header summary (:func:`spslidar.io.ptu_info`).
    family : str
        Its layout family (``"t2-picoharp"``, ``"t2-hydraharp1"``, ``"t2-hydraharp2"``).
    n_records : int
        The records to read.
    chunk_records : int
        Records per chunk read.
    path : str
        The file's path, for messages.
    sync_channel : int, optional
        A detector channel (0-based, as ``--channel`` numbers them) whose events are the
        code's syncs, where the sync went to a detector input (the file's own sync records,
        if any, are then not read); not for a PicoHarp, whose input 0 is its sync.
    n_bins : int, optional
        Bins per code period: a ``sync_channel`` whose events jitter by more than
        :data:`SYNC_JITTER_BINS` of a bin (the sync period over ``n_bins``) is said.

    Returns
    -------
    records : T2Records
    header : dict
        A copy of ``header`` with ``sync_period_s`` (measured), ``resolution_s`` (the delay
        unit: the time tag's), ``bins_per_period`` (the period in delay units) and
        ``tdc_resolution_s`` (the header's ``MeasDesc_Resolution``).

    Raises
    ------
    ConfigError
        No time tag unit in the header; no sync record, or one; sync records that are not
        periodic (a detector on the PicoHarp's input 0).
    """
    unit = header.get("time_unit_s") or 0.0
    if not unit > 0:
        raise ConfigError(f"{path!r}: its header gives no time tag unit "
                          f"(MeasDesc_GlobalResolution) for its T2 records")
    if sync_channel is not None and family == "t2-picoharp":
        raise ConfigError(f"{path!r} is a PicoHarp T2 file, whose input 0 is read as the sync: "
                          f"--sync-channel is for HydraHarp, TimeHarp and MultiHarp files "
                          f"(connect the code generator's sync to input 0)")
    chunk_records = min(chunk_records, max(1, n_records))
    base, syncs, first_event, n_syncs, probe, first_tag = 0, [], None, 0, None, None
    n_own, n_seen = 0, 0  # (the file's own sync records, ignored under --sync-channel)
    for raw in raw_chunks(f.filehandle, f.record_offset, n_records, chunk_records, path):
        kind, t, _value, base = _times(raw, family, base, sync_channel)
        if sync_channel is not None:
            n_own += int(np.count_nonzero((raw.astype(np.uint32) >> 25) == 64))
            n_seen += raw.size
        if probe is None:  # (the first photons: a channel of periodic ones, where no sync)
            photon = kind == _PHOTON
            probe = (t[photon][:200_000], _value[photon][:200_000])
        s = t[kind == _SYNC]
        if first_tag is None and s.size:
            first_tag = int(s[0])
        # (the events before the first sync, in whichever chunk they are recorded: the
        # earliest of them)
        evk = (kind == _PHOTON) | (kind == _MARKER)
        ev = t[evk]
        if first_tag is not None:
            first_s = np.where((kind[evk] == _MARKER) & (family == "t2-picoharp"),
                               first_tag & ~15, first_tag)
            ev = ev[ev < first_s]
        if ev.size:
            early = int(ev.min())
            first_event = early if first_event is None else min(first_event, early)
        n_syncs += int(s.size)
        syncs.append(s[: _PERIOD_SYNCS + 1])
        if sum(x.size for x in syncs) > _PERIOD_SYNCS:
            break
    s = np.concatenate(syncs)[: _PERIOD_SYNCS + 1] if syncs else np.zeros(0, np.int64)
    if s.size < 2:
        raise _no_sync(header, path, family, int(s.size), probe, sync_channel)
    gaps = np.diff(s).astype(np.float64)
    median = float(np.median(gaps))
    whole = np.round(gaps / median) if median > 0 else np.zeros_like(gaps)
    # (a share of the period, or a few tags where the period is a few hundred of them: coarse
    # tags and a sync's jitter moved 80 ps tags 1-2 tags off 159, refused, an outside audit)
    tol = max(SYNC_TOL * median, SYNC_TAGS)
    off = (whole < 1) | (np.abs(gaps - whole * median) > tol)
    if off.mean() > SYNC_OFF_SHARE:
        k = int(np.flatnonzero(off)[0])
        what = ("its input 0, read as the sync, " if family == "t2-picoharp" else
                f"the events of its channel {sync_channel}, read as the sync "
                f"(--sync-channel), "
                if sync_channel is not None else "its sync records ")
        raise ConfigError(f"{path!r}: {what}are not periodic: {int(off.sum())} of the first "
                          f"{gaps.size} intervals are more than {tol * unit:.3g} s off a whole "
                          f"number of periods ({median * unit:.6g} s; the first after sync "
                          f"{k}: {gaps[k] * unit:.6g} s): not the code generator's sync (a "
                          f"detector on it?)")
    if off.any():  # (a glitch on the sync input: the period it falls in is read from it)
        warnings.warn(f"{path!r}: {int(off.sum())} of the first {gaps.size} intervals between "
                      f"its sync records are off a whole number of periods (glitches on the "
                      f"sync input?): the photons of a period that holds one have their "
                      f"delays read from it", RuntimeWarning, stacklevel=3)
    if n_own:  # (ignored without a word: an outside audit of stop 67)
        warnings.warn(f"{path!r}: --sync-channel {sync_channel}: the file holds sync records "
                      f"of its own ({n_own} in its first {n_seen} records), which are ignored "
                      f"and the events of channel {sync_channel} read as the syncs instead; if "
                      f"the code generator's sync went to the sync input, leave --sync-channel "
                      f"out", RuntimeWarning, stacklevel=3)
    period = float(gaps[~off].sum() / whole[~off].sum())
    if sync_channel is not None and n_bins:
        _say_jitter(gaps[~off] - whole[~off] * period, period / n_bins, unit, path,
                    sync_channel)
    first_sync = int(s[0])
    first_period = 0
    if first_event is not None and first_event < first_sync:
        first_period = int(math.ceil((first_sync - first_event) / period - 1e-12))
    header = dict(header, sync_period_s=period * unit, resolution_s=unit,
                  bins_per_period=period, tdc_resolution_s=header.get("resolution_s"))
    return (T2Records(f, family, period, first_sync, first_period, os.fspath(path),
                      sync_channel), header)
