"""Writing simulated acquisitions as PicoQuant T3 PTU files (the record layouts and the reason
for an own encoder are in :mod:`spslidar.io.ptu_format`)."""

from __future__ import annotations

import os
import struct
import uuid
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import ConfigError
from ..version import __version__
from .ptu_format import (
    _FAMILY,
    _MAGIC,
    _TAG,
    _TY_ANSISTRING,
    _TY_EMPTY8,
    _TY_FLOAT8,
    _TY_INT8,
    _TY_TDATETIME,
    T3_RECORD_TYPES,
    PathLike,
    _finite_number,
    _marker_input,
    _positive_int,
)

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["write_acquisition_ptu", "write_ptu_t3"]


# --------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------


def _tag(ident: str, typ: int, value: bytes, index: int = -1) -> bytes:
    return _TAG.pack(ident.encode("ascii"), index, typ) + value


def _encode_tag(ident: str, value: Any) -> bytes:
    """One PTU tag: 32-byte ident, int32 index, uint32 type, 8-byte value (+ string data)."""
    if value is None:
        return _tag(ident, _TY_EMPTY8, bytes(8))
    if isinstance(value, datetime):  # TDateTime: days since 1899-12-30, local time
        if value.tzinfo is not None:
            value = value.astimezone().replace(tzinfo=None)
        days = (value - datetime(1899, 12, 30)).total_seconds() / 86400.0
        return _tag(ident, _TY_TDATETIME, struct.pack("<d", days))
    if isinstance(value, bool | int | np.integer):
        if not -2**63 <= int(value) < 2**63:
            raise ConfigError(f"PTU tag {ident}={value} does not fit a 64-bit integer")
        return _tag(ident, _TY_INT8, struct.pack("<q", int(value)))
    if isinstance(value, float | np.floating):
        return _tag(ident, _TY_FLOAT8, struct.pack("<d", float(value)))
    if isinstance(value, str):
        data = value.encode("windows-1252", errors="replace") + b"\x00"
        data += bytes(-len(data) % 8)  # keep tags 8-byte aligned
        return _tag(ident, _TY_ANSISTRING, struct.pack("<q", len(data))) + data
    raise ConfigError(f"cannot encode PTU tag {ident}={value!r}: a tag holds an int, float, "
                      f"str, bool, datetime or None")


def _check_tag_name(key: Any) -> None:
    """A tag name the 32-byte ident field holds: ASCII, 1-31 characters (a longer one was cut
    silently, a non-ASCII one or a number raised from the encoder)."""
    if not isinstance(key, str) or not key or not key.isascii() or len(key) > 31:
        raise ConfigError(f"extra_tags: a tag name must be 1-31 ASCII characters, got {key!r}")


#: most overflow records :func:`write_ptu_t3` writes (1 GiB): an ``nsync`` that jumps by 2^52
#: asked for 16 GiB of them
MAX_OVERFLOW_RECORDS = 2**28


def _record_type(name: str) -> tuple[str, int, str, str]:
    for key, (code, family, hw) in T3_RECORD_TYPES.items():
        if key.lower() == str(name).lower() or (key == "GenericT3" and name == "generic"):
            return key, code, family, hw
    raise ConfigError(f"unknown T3 record type {name!r}; choose one of {sorted(T3_RECORD_TYPES)}")


def _as_int_array(values: Any, n: int, name: str) -> np.ndarray:
    arr = np.asarray(values)
    if arr.ndim == 0:
        arr = np.full(n, arr)
    if arr.shape != (n,):
        raise ConfigError(f"{name} must be a scalar or have shape ({n},), got {arr.shape}")
    if arr.size and arr.dtype.kind not in "iub":
        raise ConfigError(f"{name} must hold integers, got dtype {arr.dtype}")
    return arr.astype(np.int64)


def write_ptu_t3(
    path: PathLike,
    *,
    nsync: ArrayLike,
    dtime: ArrayLike,
    channel: ArrayLike = 0,
    marker: ArrayLike | None = None,
    resolution_s: float,
    sync_rate_hz: float,
    record_type: str = "HydraHarp2T3",
    comment: str = "",
    created: datetime | None = None,
    extra_tags: dict[str, Any] | None = None,
) -> int:
    """Write time-ordered T3 events as a PicoQuant PTU file.

    Each event ``i`` is a photon (``marker[i] == 0``) or a marker record (``marker[i] > 0``
    holds the marker bits, 1..15). Events are written in the given order; sync counter
    overflow records are inserted wherever ``nsync`` crosses a multiple of the wrap (1024
    syncs, 65536 for ``PicoHarpT3``). HydraHarp v2 / TimeHarp 260 / generic overflow records
    carry up to 1023 wraps each; HydraHarp v1 and PicoHarp ones one wrap each.

    Parameters
    ----------
    path : str or os.PathLike
        Output file, replaced (written under a temporary name in its folder and moved onto
        ``path`` once complete: a failed write leaves ``path`` as it was and no partial file).
    nsync : array_like of int
        ``(n,)`` global (unwrapped) sync count of each event, non-decreasing.
    dtime : array_like of int
        ``(n,)`` delay after the sync in resolution units (``< 32768``, ``< 4096`` for
        PicoHarp); ignored for markers.
    channel : int or array_like of int
        Photon channel(s), 0-based (0..63, PicoHarp 0..3); ignored for markers.
    marker : array_like of int, optional
        ``(n,)`` marker bits per event, 0 for photons; default all photons.
    resolution_s : float
        dtime resolution in seconds (``MeasDesc_Resolution``).
    sync_rate_hz : float
        Sync rate; ``MeasDesc_GlobalResolution = 1 / sync_rate_hz``.
    record_type : str
        ``'HydraHarp2T3'`` (default), ``'HydraHarpT3'``, ``'PicoHarpT3'``,
        ``'TimeHarp260NT3'``, ``'TimeHarp260PT3'`` or ``'GenericT3'`` (alias ``'generic'``).
    comment, created : str, datetime
        ``File_Comment`` and ``File_CreatingTime`` (default now).
    extra_tags : dict, optional
        More tags (int, float, str, bool, datetime or None values); cannot override the
        format-defining tags.

    Returns
    -------
    int
        Number of 32-bit records written. Raises :class:`~spslidar.errors.ConfigError` for an
        unknown record type, values out of range for the layout or unsorted ``nsync``.
    """
    name, code, family, hardware = _record_type(record_type)
    wrap, dtime_max, channel_max = _FAMILY[family]
    t = np.asarray(nsync)
    if t.ndim != 1:
        raise ConfigError(f"nsync must be one-dimensional, got shape {t.shape}")
    n = t.size
    t = _as_int_array(t, n, "nsync")
    dt = _as_int_array(dtime, n, "dtime")
    ch = _as_int_array(channel, n, "channel")
    mk = np.zeros(n, np.int64) if marker is None else _as_int_array(marker, n, "marker")
    resolution_s = _finite_number(resolution_s, "resolution_s", True, 1.0)  # s per dtime unit
    sync_rate_hz = _finite_number(sync_rate_hz, "sync_rate_hz", True, 1e12)
    if sync_rate_hz < 1.0:  # the header's acquisition time (ms) would overflow its integer
        raise ConfigError(f"sync_rate_hz must be at least 1 Hz, got {sync_rate_hz!r}")
    if n and (t[0] < 0 or np.any(np.diff(t) < 0)):
        raise ConfigError("nsync must be non-negative and non-decreasing (time-ordered events)")
    photon = mk == 0
    if np.any((mk < 0) | (mk > 15)):
        raise ConfigError("marker bits must be in 0..15 (0 = photon)")
    if np.any(photon & ((dt < 0) | (dt >= dtime_max))):
        raise ConfigError(f"dtime out of range 0..{dtime_max - 1} for {name} records")
    if np.any(photon & ((ch < 0) | (ch >= channel_max))):
        raise ConfigError(f"channel out of range 0..{channel_max - 1} for {name} records")

    wraps = t // wrap
    local = (t - wraps * wrap).astype(np.uint32)
    gap = np.diff(wraps, prepend=0)
    per = 1023 if family == "hydraharp2" else 1
    n_ofl = -(-gap // per)  # overflow records before each event
    if int(n_ofl.sum()) > MAX_OVERFLOW_RECORDS:  # counted before they are made
        raise ConfigError(f"nsync spans {int(t[-1]):.3g} syncs: {int(n_ofl.sum()):.3g} overflow "
                          f"records, more than {MAX_OVERFLOW_RECORDS}; is nsync in syncs?")
    total = n + int(n_ofl.sum())
    records = np.empty(total, np.uint32)
    ev_pos = np.arange(n) + np.cumsum(n_ofl)
    is_ev = np.zeros(total, bool)
    is_ev[ev_pos] = True
    owner = np.repeat(np.arange(n), n_ofl)
    first = np.repeat(np.cumsum(n_ofl) - n_ofl, n_ofl)
    count = np.minimum(per, gap[owner] - per * (np.arange(owner.size) - first))
    dtu, chu, mku = dt.astype(np.uint32), ch.astype(np.uint32), mk.astype(np.uint32)
    if family == "picoharp":
        ev = np.where(photon, ((chu + 1) << 28) | (dtu << 16), (15 << 28) | (mku << 16)) | local
        ofl = np.full(owner.size, 15 << 28, np.uint32)
    else:
        ev = np.where(photon, (chu << 25) | (dtu << 10), (1 << 31) | (mku << 25)) | local
        ofl = ((0x7F << 25) | count).astype(np.uint32)
    records[is_ev] = ev.astype(np.uint32)
    records[~is_ev] = ofl

    period = 1.0 / float(sync_rate_hz)
    tags: dict[str, Any] = {
        "File_GUID": "{" + str(uuid.uuid4()) + "}", "File_Comment": comment,
        "File_CreatingTime": created if created is not None else datetime.now(),
        "CreatorSW_Name": "spslidar", "CreatorSW_Version": __version__, "HW_Type": hardware,
        "Measurement_Mode": 3, "Measurement_SubMode": 0, "MeasDesc_BinningFactor": 1,
        "MeasDesc_Resolution": float(resolution_s), "MeasDesc_GlobalResolution": period,
        "MeasDesc_AcquisitionTime": round((int(t[-1]) + 1 if n else 0) * period * 1e3),  # ms
        "TTResult_SyncRate": round(float(sync_rate_hz)), "TTResult_NumberOfRecords": total,
        "TTResultFormat_TTTRRecType": code, "TTResultFormat_BitsPerRecord": 32,
    }
    if extra_tags is not None and not isinstance(extra_tags, dict):
        raise ConfigError(f"extra_tags must be a dict of tag names and values, got "
                          f"{type(extra_tags).__name__}")
    for key, value in (extra_tags or {}).items():
        _check_tag_name(key)
        if key.startswith(("TTResultFormat_", "Measurement_", "MeasDesc_", "TTResult_Number",
                           "Header_End")):
            raise ConfigError(f"extra_tags cannot set the format tag {key!r}")
        tags[key] = value
    header = [_MAGIC, b"1.0.00\x00\x00"]
    header += [_encode_tag(key, value) for key, value in tags.items()]
    header.append(_encode_tag("Header_End", None))
    from ..outdir import atomic_file

    where = Path(os.fspath(path))
    if where.is_dir():
        raise ConfigError(f"cannot write the PTU file {os.fspath(path)!r}: it is a folder")
    if not where.parent.is_dir():
        raise ConfigError(f"cannot write the PTU file {os.fspath(path)!r}: the folder "
                          f"{where.parent} does not exist")
    with atomic_file(path) as fh:  # a failed write (a full disk) leaves no partial file
        _dump(fh, b"".join(header), records)
    return total


def _dump(fh: Any, header: bytes, records: np.ndarray) -> None:
    """The header, then the records as little-endian 32-bit words (no copy on a
    little-endian machine)."""
    fh.write(header)
    fh.write(memoryview(np.ascontiguousarray(records.astype("<u4", copy=False))).cast("B"))


def _concat(parts: list[np.ndarray]) -> np.ndarray:
    return np.concatenate(parts) if parts else np.zeros(0, np.int64)


def write_acquisition_ptu(
    path: PathLike,
    pattern_events: Sequence[ArrayLike],
    period_bins: int,
    bin_width_s: float,
    *,
    periods_per_pattern: int | Sequence[int] | None = None,
    marker: int = 1,
    channel: int = 0,
    record_type: str = "HydraHarp2T3",
    comment: str = "spslidar simulated acquisition",
    created: datetime | None = None,
) -> int:
    """Write a simulated per-pattern photon acquisition as a T3 PTU file.

    Pattern ``k`` occupies code periods ``start_k .. start_k + P_k - 1`` (``start_0 = 0``,
    ``start_{k+1} = start_k + P_k``). A marker record on input ``marker`` is written at sync
    ``start_k`` before the pattern's photons; a photon ``(p, b)`` of pattern ``k`` is written
    at ``nsync = start_k + p``, ``dtime = b``. The sync rate is ``1 / (period_bins *
    bin_width_s)`` and the resolution ``bin_width_s``, so
    ``read_ptu_histograms(path, period_bins, bin_width=bin_width_s, marker=marker)``
    returns exactly the per-pattern histograms of the events.

    Parameters
    ----------
    path : str or os.PathLike
        Output file, replaced (written under a temporary name in its folder and moved onto
        ``path`` once complete: a failed write leaves ``path`` as it was and no partial file).
    pattern_events : sequence of array_like
        Per pattern, an ``(n_k, 2)`` integer array of ``(period index, bin)`` photon events,
        ``0 <= period < P_k`` and ``0 <= bin < period_bins``, in any order.
    period_bins : int
        Bins per code period ``L`` (at most 32768, 4096 for PicoHarp records).
    bin_width_s : float
        Bin width in seconds.
    periods_per_pattern : int or sequence of int, optional
        Code periods per pattern ``P_k`` (scalar or one per pattern); default: the largest
        period index of each pattern plus one.
    marker : int
        Marker input (1..4) written at each pattern start.
    channel, record_type, comment, created
        Photon channel and, as for :func:`write_ptu_t3`, the file's record type and tags.

    Returns
    -------
    int
        Number of records written.
    """
    period_bins = _positive_int(period_bins, "period_bins")
    bit = 1 << (_marker_input(marker) - 1)
    if not bin_width_s > 0:
        raise ConfigError(f"bin_width_s must be > 0, got {bin_width_s!r}")
    events = []
    for k, ev in enumerate(pattern_events):
        arr = np.asarray(ev)
        if arr.size == 0:
            arr = np.zeros((0, 2), np.int64)
        if arr.ndim != 2 or arr.shape[1] != 2 or arr.dtype.kind not in "iu":
            raise ConfigError(f"pattern_events[{k}] must be an (n, 2) integer array of (period, "
                              f"bin), got shape {arr.shape} dtype {arr.dtype}")
        arr = arr.astype(np.int64)
        if np.any(arr < 0) or np.any(arr[:, 1] >= period_bins):
            raise ConfigError(f"pattern_events[{k}]: periods must be >= 0 and bins in "
                              f"0..{period_bins - 1}")
        events.append(arr)
    m = len(events)
    if periods_per_pattern is None:
        periods = np.array([int(e[:, 0].max()) + 1 if len(e) else 1 for e in events], np.int64)
    else:
        periods = np.asarray(periods_per_pattern, np.int64)
        periods = np.full(m, periods) if periods.ndim == 0 else periods
        if periods.shape != (m,) or np.any(periods < 1):
            raise ConfigError(f"periods_per_pattern must be a positive int or {m} positive ints")
        for k, e in enumerate(events):
            if len(e) and e[:, 0].max() >= periods[k]:
                raise ConfigError(f"pattern_events[{k}] has a period index >= "
                                  f"periods_per_pattern ({periods[k]})")
    starts = np.concatenate([[0], np.cumsum(periods)[:-1]]) if m else np.zeros(0, np.int64)
    nsync, dtime, marks = [], [], []
    for k, e in enumerate(events):
        e = e[np.lexsort((e[:, 1], e[:, 0]))]  # time order
        nsync += [np.array([starts[k]]), starts[k] + e[:, 0]]
        dtime += [np.zeros(1, np.int64), e[:, 1]]
        marks += [np.array([bit]), np.zeros(len(e), np.int64)]
    return write_ptu_t3(
        path, nsync=_concat(nsync), dtime=_concat(dtime), channel=channel, marker=_concat(marks),
        resolution_s=float(bin_width_s), sync_rate_hz=1.0 / (period_bins * float(bin_width_s)),
        record_type=record_type, comment=comment, created=created)
