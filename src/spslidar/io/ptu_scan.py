"""What a PTU file holds, before any option is chosen: one pass over its records counting the
photons on each detector channel, the markers on each marker input, the blocks those markers
cut (their length and photons), the overflows and the gaps between detections
(``spslidar inspect``; :func:`scan_ptu`).

A lab's first question of a new file is which ``--marker`` input its DMD drove, which
``--channel`` holds the detector, whether the time tags fit the code's bit rate and whether
pile-up matters: ``reconstruct`` refuses a wrong guess in one line, naming what the file holds,
but only one guess at a time. The header alone (:func:`~spslidar.io.ptu_info`) says none of
it, since it does not count records. ``ptufile`` decodes the T3 records (as the reader does);
T2 records, which ``ptufile`` reads only as whole files, are decoded here by
:mod:`spslidar.io.ptu_t2`'s layouts, so memory is one chunk whatever the file's length.
"""

from __future__ import annotations

import itertools
import os
from typing import Any

import numpy as np

from ..errors import ConfigError
from .ptu import _overflows
from .ptu_blocks import _by_channel, _check_forward, _Gaps
from .ptu_format import _FAMILY, PathLike, _check_t3, _header_summary, _open_ptu, raw_chunks
from .ptu_t2 import _MARKER, _PHOTON, _SYNC, _periodic_channel, _times

__all__ = ["MARKER_INPUTS", "scan_ptu"]

#: marker inputs a record's marker bits can name (bit ``k - 1`` is input ``k``; a HydraHarp,
#: TimeHarp or MultiHarp has four, a PicoHarp four)
MARKER_INPUTS = (1, 2, 3, 4)
#: a T2 photon's delay since its sync is histogrammed up to this many time tags (4 M: 4 us
#: of 1 ps tags; a longer sync period's later delays are left out of ``dtime_counts``)
_MAX_DELAY_TAGS = 2**22
#: photons of a T2 file kept to look for a channel of periodic events (a sync recorded on a
#: detector input): the first ones, as ``reconstruct`` looks
_PROBE_PHOTONS = 65536


class _Markers:
    """Per marker input: the time of each of its markers (seconds from the file's first
    event) and the photons read before it, chunk by chunk."""

    def __init__(self) -> None:
        self.times: dict[int, list[np.ndarray]] = {k: [] for k in MARKER_INPUTS}
        self.before: dict[int, list[np.ndarray]] = {k: [] for k in MARKER_INPUTS}

    def add(self, bits: np.ndarray, t: np.ndarray, photons_before: np.ndarray) -> None:
        for k in MARKER_INPUTS:
            on = (bits & (1 << (k - 1))) != 0
            if on.any():
                self.times[k].append(t[on])
                self.before[k].append(photons_before[on])

    def blocks(self, total: int, end_s: float
               ) -> tuple[dict[int, dict[str, Any]], dict[int, tuple[np.ndarray, np.ndarray]]]:
        """Each input's markers, the blocks between them and the photons outside them; and
        each input's blocks as arrays (dwell in seconds and photons, the last block's to the
        file's last event), as ``reconstruct`` reads them."""
        out: dict[int, dict[str, Any]] = {}
        arrays: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        for k in MARKER_INPUTS:
            if not self.times[k]:
                continue
            t = np.concatenate(self.times[k])
            before = np.concatenate(self.before[k]).astype(np.int64)
            dwell = np.diff(t)
            photons = np.diff(before)
            med = float(np.median(dwell)) if dwell.size else 0.0
            out[k] = {
                "markers": int(t.size),
                "first_s": float(t[0]),
                "photons_before_first": int(before[0]),
                "photons_after_last": int(total - before[-1]),
                "seconds_after_last": float(max(end_s - t[-1], 0.0)),
                # (None where one marker cuts no block between two)
                "dwell_s": _spread(dwell),
                "photons_per_block": _spread(photons),
                "empty_blocks": int(np.count_nonzero(photons == 0)) if dwell.size else None,
                # blocks far from the typical length: a marker missed (twice as long) or a
                # bounce (a sliver), which reconstruct reads as patterns
                "irregular_blocks": (int(np.count_nonzero((dwell > 1.5 * med)
                                                          | (dwell < med / 1.5)))
                                     if med > 0 else None),
            }
            arrays[k] = (np.append(dwell, max(end_s - t[-1], 0.0)),
                         np.append(photons, total - before[-1]))
        return out, arrays


def _spread(v: np.ndarray) -> dict[str, float] | None:
    if not v.size:
        return None
    return {"median": float(np.median(v)), "min": float(v.min()), "max": float(v.max())}


def scan_ptu(path: PathLike, *, chunk_records: int = 2**16) -> dict[str, Any]:
    """Count what a PTU file holds, in one pass over its records.

    Parameters
    ----------
    path : str or os.PathLike
        A PicoQuant PTU file, T3 or T2 (PicoHarp, HydraHarp, TimeHarp 260, MultiHarp,
        PicoHarp 330).
    chunk_records : int
        Records read at a time (memory: about 80 bytes each; 2^16 read a file faster than
        2^20 and in a third of the memory, an outside audit); the result does not depend on
        it.

    Returns
    -------
    dict
        ``header`` (:func:`~spslidar.io.ptu_info`'s summary), ``mode`` (``"T3"`` / ``"T2"``),
        ``n_records_read`` (the header's ``n_records`` is what it announces),
        ``photons`` (per detector channel, numbered from 0 as ``--channel``), ``markers`` (per
        marker input 1-4, as ``--marker``; a record may set several), ``marker_records``,
        ``overflow_records``, ``sync_records`` (T2: the sync input's records; T3: None, its
        records count the syncs), ``sync_period_s`` (T2: measured from the sync records, None
        under two; T3: the header's), ``span_s``
        (first to last event, seconds), ``syncs_spanned`` (T3), ``dtime_max`` (T3: the
        highest TDC bin a photon took, in units of the resolution; T2: the longest delay
        since a sync record, in time tags), ``dtime_counts`` (T3: the photons in each TDC
        bin, all channels and blocks together, an int64 array; T2 with sync records: in each
        time tag since the last sync, up to 2^22 tags; else None), ``channel_dtime_counts``
        (T3: the same per channel), ``blocks`` (per marker input that holds markers:
        ``markers``, ``dwell_s`` and ``photons_per_block``
        (median / min / max over the blocks between consecutive markers), ``empty_blocks``,
        ``irregular_blocks`` (lasting over 1.5 times the median, or under its 1/1.5),
        ``photons_before_first``, ``photons_after_last``, ``seconds_after_last``; the spreads
        None where one marker cuts no block), ``block_arrays`` (per input, each block's dwell
        in seconds and photons as arrays, the last block's to the file's last event),
        ``gaps``
        (per channel: the shortest gap between consecutive detections, seconds, and their
        number; what a dead time shows), ``periodic_channel`` (T2: a channel whose events come
        at whole numbers of one period, a sync recorded on a detector input, and that
        period in seconds; else None).

    Raises
    ------
    ConfigError
        Not a PTU file, an unsupported record type, or a header that contradicts itself
        (one line, as :func:`~spslidar.io.read_ptu_histograms` says them).
    """
    if isinstance(chunk_records, bool) or not isinstance(chunk_records, int | np.integer) \
            or chunk_records < 1:
        raise ConfigError(f"chunk_records must be a whole number >= 1, got {chunk_records!r}")
    if not isinstance(path, (str, os.PathLike)):
        raise ConfigError(f"path must be the path of a PTU file, got {type(path).__name__}")
    spath = os.fspath(path)
    with _open_ptu(path) as f:
        header = _header_summary(f, path)
        family, n_records = _check_t3(f, header, spath)
        chunks = raw_chunks(f.filehandle, f.record_offset, n_records, int(chunk_records), spath)
        if family.startswith("t2"):
            out = _scan_t2(chunks, family, header, spath)
        else:
            out = _scan_t3(chunks, f.decode_records, family, header, spath)
    out["header"] = header
    out["n_records_read"] = int(n_records)
    return out


def _scan_t3(chunks, decode, family: str, header: dict[str, Any], path: str
             ) -> dict[str, Any]:
    period = float(header["sync_period_s"] or 0.0)
    res = float(header["resolution_s"] or 0.0)
    wrap = _FAMILY[family][0]
    per_channel = np.zeros(128, np.int64)
    markers = _Markers()
    gaps = _Gaps(period, res)
    n_photons = n_ofl = carry = n_mark = 0
    first = last = None
    behind = -1
    dtime_max = -1
    per_dtime: dict[int, np.ndarray] = {}
    for raw in chunks:
        dec = decode(raw)
        ch, mk = dec["channel"], dec["marker"]
        sync = dec["time"].astype(np.int64) + carry
        n_ofl_chunk, wraps = _overflows(raw, family)
        n_ofl += n_ofl_chunk
        carry += wraps * wrap
        photon = ch >= 0
        event = photon | (mk != 0)
        if event.any():
            ev = sync[event]
            _check_forward(ev, behind, path)  # (two files joined: one line, as reconstruct)
            behind = int(ev[-1])
            first = int(ev[0]) if first is None else first
            last = int(ev[-1])
        if photon.any():
            per_channel += np.bincount(ch[photon].astype(np.int64), minlength=128)[:128]
            dtime_max = max(dtime_max, int(dec["dtime"][photon].max()))
            for c, mine in _by_channel(ch[photon]):
                h = np.bincount(dec["dtime"][photon][mine].astype(np.int64))
                per_dtime[c] = _add(per_dtime.get(c, np.zeros(0, np.int64)), h)
            gaps.add(sync[photon], dec["dtime"][photon], ch[photon])
        is_mark = ~photon & (mk != 0)
        n_mark += int(np.count_nonzero(is_mark))
        if is_mark.any():
            before = n_photons + np.cumsum(photon)[is_mark]
            markers.add(mk[is_mark].astype(np.int64), (sync[is_mark] - (first or 0)) * period,
                        before)
        n_photons += int(np.count_nonzero(photon))
    span_syncs = 0 if first is None else last - first
    return _result("T3", per_channel, markers, n_photons, span_syncs * period, n_mark, n_ofl,
                   gaps, sync_records=None, sync_period_s=period,
                   syncs_spanned=int(span_syncs),
                   dtime_max=None if dtime_max < 0 else dtime_max,
                   dtime_counts=_total(per_dtime), channel_dtime_counts=per_dtime,
                   periodic_channel=None)


def _add(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a + b`` of two count arrays of any lengths (the shorter read as 0 past its end)."""
    if b.size > a.size:
        a, b = b, a
    a = a.copy()
    a[: b.size] += b
    return a


def _total(per: dict[int, np.ndarray]) -> np.ndarray:
    out = np.zeros(0, np.int64)
    for h in per.values():
        out = _add(out, h)
    return out


def _result(mode: str, per_channel: np.ndarray, markers: _Markers, n_photons: int,
            span_s: float, n_mark: int, n_ofl: int, gaps: _Gaps, **more: Any
            ) -> dict[str, Any]:
    """A scan's result, T3 or T2 alike (:func:`scan_ptu` names the keys)."""
    blocks, arrays = markers.blocks(n_photons, span_s)
    return {"mode": mode, "photons": _nonzero(per_channel),
            "markers": {k: v["markers"] for k, v in blocks.items()},
            "marker_records": int(n_mark), "overflow_records": int(n_ofl),
            "span_s": float(span_s), "blocks": blocks, "block_arrays": arrays,
            "gaps": _gaps(gaps), **more}


def _scan_t2(chunks, family: str, header: dict[str, Any], path: str) -> dict[str, Any]:
    unit = float(header["time_unit_s"] or 0.0)
    per_channel = np.zeros(128, np.int64)
    markers = _Markers()
    gaps = _Gaps(unit, 0.0)  # (a T2 time tag is its "sync"; no dtime)
    n_photons = n_ofl = n_sync = base = n_mark = 0
    latest = -(2**62)
    back = int(1e-6 / unit) if unit > 0 else 0  # (a microsecond of tags: no reordering)
    first = last = None
    sync_first = sync_last = None
    delays = np.zeros(0, np.int64)
    # a sync recorded on a detector input: found in the first chunk's photons (as reconstruct
    # looks), so that the blocks' photon counts leave its events out (they counted them, a
    # review)
    # chunks, whatever their size (the result may not depend on it)
    chunks = iter(chunks)
    head: list[np.ndarray] = []
    probe_t, probe_c, seen_sync, tags = [], [], False, 0
    while sum(x.size for x in probe_t) < _PROBE_PHOTONS:
        raw = next(chunks, None)
        if raw is None:
            break
        head.append(raw)
        kind, t, value, tags = _times(raw, family, tags)
        seen_sync |= bool(np.any(kind == _SYNC))
        probe_t.append(t[kind == _PHOTON])
        probe_c.append(value[kind == _PHOTON])
    sync_ch = None
    if not seen_sync and probe_t:
        found = _periodic_channel(np.concatenate(probe_t)[:_PROBE_PHOTONS],
                                  np.concatenate(probe_c)[:_PROBE_PHOTONS])
        sync_ch = None if found is None else (int(found[0]), float(found[1] * unit))
    for raw in itertools.chain(head, chunks):
        kind, t, value, base_after = _times(raw, family, base)
        n_ofl += int(np.count_nonzero(_overflow_t2(raw, family)))
        base = base_after
        photon = kind == _PHOTON
        event = photon | (kind == _SYNC) | (kind == _MARKER)
        if event.any():
            ev = t[event]
            timed = t[photon | (kind == _SYNC)]  # (markers' tags are coarser: not checked)
            if timed.size:
                ahead = np.maximum.accumulate(np.concatenate([[latest], timed]))
                if np.any(timed < ahead[:-1] - back):
                    raise ConfigError(f"{path!r}: its time tags run backwards (an event "
                                      f"more than 1 us before one recorded ahead of it), "
                                      f"which no acquisition records: files joined end to "
                                      f"end, or a corrupt file")
                latest = int(ahead[-1])
            first = int(ev[0]) if first is None else first
            last = int(ev[-1])
        is_sync = kind == _SYNC
        st = t[is_sync]
        if st.size:
            sync_first = int(st[0]) if sync_first is None else sync_first
            n_sync += int(st.size)
        if photon.any():
            c = value[photon]
            per_channel += np.bincount(c, minlength=128)[:128]
            gaps.add(t[photon], np.zeros(c.size, np.int64), c)
            # each photon's delay since the last sync record, in tags (as a T3 file's dtime)
            pt = t[photon]
            before = -1 if sync_last is None else sync_last
            if st.size:
                i = np.searchsorted(st, pt, side="right") - 1
                prev = np.where(i >= 0, st[np.maximum(i, 0)], before)
            else:
                prev = np.full(pt.size, before)
            d = (pt - prev)[prev >= 0]
            d = d[d < _MAX_DELAY_TAGS]
            if d.size:
                delays = _add(delays, np.bincount(d))
        if st.size:
            sync_last = int(st[-1])
        counted = photon if sync_ch is None else photon & (value != sync_ch[0])
        is_mark = kind == _MARKER
        n_mark += int(np.count_nonzero(is_mark))
        if is_mark.any():
            before = n_photons + np.cumsum(counted)[is_mark]
            markers.add(value[is_mark], (t[is_mark] - (first or 0)) * unit, before)
        n_photons += int(np.count_nonzero(counted))
    span = 0 if first is None else last - first
    periodic = (None if sync_ch is None or n_sync >= 2 else
                {"channel": sync_ch[0], "period_s": sync_ch[1]})
    sync_period = (float((sync_last - sync_first) / (n_sync - 1) * unit)
                   if n_sync >= 2 else None)
    return _result("T2", per_channel, markers, n_photons, span * unit, n_mark, n_ofl, gaps,
                   sync_records=int(n_sync), sync_period_s=sync_period, syncs_spanned=None,
                   dtime_max=int(delays.size - 1) if delays.size else None,
                   dtime_counts=delays if n_sync >= 2 else None, channel_dtime_counts=None,
                   periodic_channel=periodic)


def _overflow_t2(raw: np.ndarray, family: str) -> np.ndarray:
    raw = raw.astype(np.uint32, copy=False)
    if family == "t2-picoharp":
        return ((raw >> 28) == 15) & ((raw & 15) == 0)
    return (raw >> 25) == 0x7F


def _nonzero(per_channel: np.ndarray) -> dict[int, int]:
    return {int(c): int(per_channel[c]) for c in np.flatnonzero(per_channel)}


def _gaps(gaps: _Gaps) -> dict[int, dict[str, Any]]:
    return {int(c): {"shortest_s": float(g["shortest_s"]), "n": int(g["n"])}
            for c, g in sorted(gaps.result().items())}
