"""T2 PTU files that recorded the code generator's sync are read as their T3 file is.

The T2 files are written here by an encoder of their own, from PicoQuant's published T2
layouts (32-bit little-endian words):

* HydraHarp T2 v2 (``0x01010204``; TimeHarp 260 N/P and generic T2 alike): bits 0-24 time
  tag, 25-30 channel, 31 special; special channel 63 an overflow of ``2**25`` tags times the
  tag field (0 counts as 1), channel 0 a sync, channels 1-15 a marker bit mask.
* HydraHarp T2 v1 (``0x00010204``): as v2, but each overflow record adds 33552000 tags.
* PicoHarp T2 (``0x00010203``): bits 0-27 time tag, 28-31 channel; channel 15 special: tag
  bits 0-3 zero an overflow of 210698240 tags, else a marker bit mask (the marker's tag is
  the rest); channel 0 is the PicoHarp's input 0, its T3 sync input, read as the sync;
  channels 1-4 its detector's, 0-3 in the reader's numbering.

Each T2 file re-encodes the photons and markers of a T3 file (``ptufile`` decodes it) with a
sync record at every code period's start, the time tags in a unit of the T3 file's TDC bin
over ``k``. ``ptufile`` decodes each T2 file to the same times (its T2 decode gives a HydraHarp
sync as a photon on channel 0, so syncs and photons are compared together).
"""

from __future__ import annotations

import struct
import warnings

import numpy as np
import ptufile
import pytest

from spslidar.cli import main
from spslidar.errors import ConfigError
from spslidar.io import read_ptu_histograms, write_acquisition_ptu

REAL = __import__("pathlib").Path(__file__).resolve().parents[1].parent / "shared" / "realdata"
HH_T2_V1, HH_T2_V2, PH_T2, GENERIC_T2 = 0x00010204, 0x01010204, 0x00010203, 0x00010207
L, BW = 127, 1e-10  # the code's bits and the T3 file's TDC bin
_SYNC, _MARK, _PHOT = 0, 1, 2  # (at one time tag: the sync, then the marker, then photons)


def _header(rectype: int, n_records: int, unit: float, res: float, mode: int = 2,
            divider: int | None = None) -> bytes:
    """A PTU tag header (magic, version, Int8/Float8 tags, Header_End)."""
    tags = [("Measurement_Mode", 0x10000008, mode), ("Measurement_SubMode", 0x10000008, 0),
            ("MeasDesc_Resolution", 0x20000008, res),
            ("MeasDesc_GlobalResolution", 0x20000008, unit),
            ("TTResult_NumberOfRecords", 0x10000008, n_records),
            ("TTResultFormat_TTTRRecType", 0x10000008, rectype),
            ("TTResultFormat_BitsPerRecord", 0x10000008, 32)]
    if divider is not None:
        tags.append(("HWSync_Divider", 0x10000008, divider))
    out = [b"PQTTTR\0\0", b"1.0.00\0\0"]
    for name, typ, value in tags + [("Header_End", 0xFFFF0008, 0)]:
        fmt = "<32siId" if typ == 0x20000008 else "<32siIq"
        out.append(struct.pack(fmt, name.encode(), -1, typ, value))
    return b"".join(out)


def _encode(rectype: int, t: np.ndarray, kind: np.ndarray, value: np.ndarray) -> np.ndarray:
    """T2 records of events at absolute tags ``t`` (sorted), with overflow records before the
    first event past each wrap (v2: one record for several wraps)."""
    pico = rectype == PH_T2
    wrap = 210698240 if pico else 33552000 if rectype == HH_T2_V1 else 2**25
    w = t // wrap
    field = t - w * wrap
    if pico:
        word = np.where(kind == _SYNC, field, np.where(
            kind == _MARK, (15 << 28) | (field & ~15) | value, ((value + 1) << 28) | field))
    else:
        word = np.where(kind == _PHOT, (value << 25) | field,
                        (1 << 31) | (np.where(kind == _SYNC, 0, value) << 25) | field)
    out, start, prev = [], 0, 0
    for i in np.flatnonzero(np.diff(np.concatenate([[0], w])) > 0):
        out.append(word[start:i])
        n = int(w[i] - prev)
        if pico:
            ofl = [15 << 28] * n
        elif rectype == HH_T2_V1:
            ofl = [(1 << 31) | (63 << 25) | 1] * n
        else:  # (a single wrap written as a count of 0, as PicoQuant's readers take it)
            ofl = [(1 << 31) | (63 << 25) | (0 if n == 1 else n)]
        out.append(np.array(ofl, np.int64))
        start, prev = i, int(w[i])
    out.append(word[start:])
    return np.concatenate(out).astype("<u4")


def _t3_events(path) -> tuple[np.ndarray, ...]:
    """A T3 file's photons and markers (``ptufile``): nsync, dtime, channel, marker bits."""
    with ptufile.PtuFile(path) as f:
        d = f.decode_records()
    keep = (d["channel"] >= 0) | (d["marker"] > 0)
    return tuple(d[k][keep].astype(np.int64) for k in ("time", "dtime", "channel", "marker"))


def _as_t2(t3, path, rectype: int = HH_T2_V2, k: int = 1, start: int = 5, seed: int = 0,
           skip_first_sync: bool = False, syncs: bool = True, extra: float = 0.0,
           drop: np.ndarray | None = None, sync_as_channel: int | None = None):
    """Write the T3 file ``t3``'s events as a T2 file at ``path`` with tags of ``BW / k``: a
    sync at every period's start ``start + n * L * k``, each marker at its period's sync and
    each photon at ``dtime * k`` after it plus a random part of the bin. Returns the
    absolute tags of the syncs, photons and markers written, and their kinds. ``extra``
    lengthens the sync period by that many tags (a code clock off the tagger's: the syncs
    fall on ``round(start + n * (L * k + extra))``); the syncs of the periods ``drop`` are
    not written; ``sync_as_channel``: the syncs written as photons on that channel (the sync
    on a detector input)."""
    nsync, dtime, channel, marker = _t3_events(t3)
    rng = np.random.default_rng(seed)
    period = L * k
    phot = marker == 0
    n = np.arange(int(nsync.max()) + 2)[1 if skip_first_sync else 0:]
    n = n if drop is None else np.setdiff1d(n, drop)

    def at(i):  # the sync of period i
        return np.round(start + i * (period + extra)).astype(np.int64)

    times = [at(n) if syncs else np.zeros(0, np.int64),
             at(nsync) + np.where(phot, dtime * k + rng.integers(0, k, nsync.size), 0)]
    kinds = [np.full(times[0].size, _SYNC), np.where(phot, _PHOT, _MARK)]
    values = [np.zeros(times[0].size, np.int64), np.where(phot, channel, marker)]
    t, kind, value = (np.concatenate(x) for x in (times, kinds, values))
    order = np.lexsort((np.arange(t.size), kind, t))  # (stable within a kind, as written)
    t, kind, value = t[order], kind[order], value[order]
    if sync_as_channel is not None:
        value = np.where(kind == _SYNC, sync_as_channel, value)
        kind = np.where(kind == _SYNC, _PHOT, kind)
    rec = _encode(rectype, t, kind, value)
    path.write_bytes(_header(rectype, rec.size, BW / k, BW / k) + rec.tobytes())
    return t, kind, value


@pytest.fixture(scope="module")
def t3_file(tmp_path_factory):
    """A T3 file of 24 patterns of 40 to 400 code periods each, 3 to 300 photons a pattern
    on channels 0 and 1 (a few at the period's first and last bins)."""
    d = tmp_path_factory.mktemp("t3")
    rng = np.random.default_rng(1)
    dwell = rng.integers(40, 400, 24)
    events = []
    for p in range(24):
        m = int(rng.integers(3, 300))
        ev = np.column_stack([rng.integers(0, dwell[p], m), rng.integers(0, L, m)])
        ev[:2, 1] = [0, L - 1]
        events.append(ev[np.argsort(ev[:, 0], kind="stable")])
    write_acquisition_ptu(d / "a.ptu", events, L, BW, periods_per_pattern=dwell)
    return d / "a.ptu"


def _same(a, b) -> None:
    """Two reads agree in everything the reconstruction takes from them."""
    np.testing.assert_array_equal(a.histograms, b.histograms)
    for name in ("counts_per_pattern", "pattern_start_sync", "periods_per_pattern"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    for name in ("last_sync", "n_photons", "n_markers", "bin_width_s", "photons_per_channel",
                 "n_dropped_before_first_marker", "n_out_of_range", "periods_per_sync"):
        assert getattr(a, name) == getattr(b, name), name
    assert np.isclose(a.sync_period_s, b.sync_period_s, rtol=1e-9)


@pytest.mark.parametrize("rectype,k,start", [
    (HH_T2_V2, 1, 5),
    (GENERIC_T2, 8, 2**25 * 3 - 50_000),  # (two wraps before the first event, one record)
    (HH_T2_V1, 100, 33552000 - 2_000_000),  # 1 ps tags: wraps every 33.552 us
    (HH_T2_V2, 100, 7),
    # (the syncs on multiples of 16: a PicoHarp marker's tag is coarser)
    (PH_T2, 16, 210698240 - 5_000_000),
])
def test_t2_reads_as_its_t3_file(t3_file, tmp_path, rectype, k, start):
    t2 = tmp_path / "b.ptu"
    t, kind, value = _as_t2(t3_file, t2, rectype, k=k, start=start)
    # ptufile, a peer, decodes the file written here to the same times and marker bits
    with ptufile.PtuFile(t2) as f:
        d = f.decode_records()
    timed = d["channel"] >= 0
    np.testing.assert_array_equal(d["time"][timed], t[kind != _MARK])
    np.testing.assert_array_equal(d["marker"][d["marker"] > 0], value[kind == _MARK])

    ref = read_ptu_histograms(t3_file, L, bin_width=BW)
    binning = {"allow_binning": True} if k > 1 else {}
    got = read_ptu_histograms(t2, L, bin_width=BW, **binning)
    _same(got, ref)
    assert got.resolution_s == pytest.approx(BW / k) and got.binning == k
    assert got.n_overflows > 0 or start < 10**6
    # chunks of 1000 records (a wrap, a pattern's marker and a sync between chunks)
    _same(read_ptu_histograms(t2, L, bin_width=BW, chunk_records=1000, **binning), ref)
    if k > 1:  # as a T3 file of a finer TDC: its tags merged only with --allow-binning
        with pytest.raises(ConfigError, match="merge them with --allow-binning"):
            read_ptu_histograms(t2, L, bin_width=BW)
    for edge in ("end",):  # the other options read it alike
        _same(read_ptu_histograms(t2, L, bin_width=BW, marker_edge=edge, n_patterns=20,
                                  settle_s=2e-8, **binning),
              read_ptu_histograms(t3_file, L, bin_width=BW, marker_edge=edge, n_patterns=20,
                                  settle_s=2e-8))


def test_a_sync_period_of_no_whole_number_of_tags(t3_file, tmp_path):
    """Syncs 12700.37 tags apart (1 ps tags, a code clock 29 ppm slow against the tagger's):
    each photon is read from its own sync, so the file reads as its T3 file, its period
    measured to within a hundredth of a tag."""
    t2 = tmp_path / "b.ptu"
    _as_t2(t3_file, t2, HH_T2_V2, k=100, start=3, extra=0.37)
    got = read_ptu_histograms(t2, L, bin_width=BW, allow_binning=True, chunk_records=4000)
    ref = read_ptu_histograms(t3_file, L, bin_width=BW)
    np.testing.assert_array_equal(got.histograms, ref.histograms)
    np.testing.assert_array_equal(got.periods_per_pattern, ref.periods_per_pattern)
    assert got.sync_period_s == pytest.approx(12700.37e-12, abs=0.01e-12)


def test_events_before_the_first_sync_are_placed_back_from_it(t3_file, tmp_path):
    """Without the first period's sync, its photons are read from the next one's, a period
    back (as a time tagger's stream is converted): nothing is lost or moved."""
    t2 = tmp_path / "b.ptu"
    _as_t2(t3_file, t2, GENERIC_T2, k=4, start=1000, skip_first_sync=True)
    _same(read_ptu_histograms(t2, L, bin_width=BW, allow_binning=True, chunk_records=300),
          read_ptu_histograms(t3_file, L, bin_width=BW))


def test_a_photon_recorded_after_a_later_sync_is_read_by_its_time(tmp_path):
    """A photon 2 tags before a sync but recorded after it (inputs merged in the hardware's
    order) is read in the period before, at its last bin, in any chunking; one 3 periods
    back is refused in one line as time running backwards."""
    rng = np.random.default_rng(2)
    n = 400
    phot = np.sort(rng.integers(0, n * L, 3000))
    t = np.concatenate([np.arange(n) * L, [0], phot])
    kind = np.concatenate([np.full(n, _SYNC), [_MARK], np.full(phot.size, _PHOT)])
    order = np.lexsort((kind, t))
    t, kind = t[order], kind[order]
    value = np.where(kind == _MARK, 1, 0)
    late = np.flatnonzero((kind == _SYNC) & (t == 200 * L))[0]
    t = np.insert(t, late + 1, 200 * L - 2)  # (after sync 200's record, before its time)
    kind, value = np.insert(kind, late + 1, _PHOT), np.insert(value, late + 1, 0)
    want = np.bincount(t[kind == _PHOT] % L, minlength=L)
    assert want[L - 2] >= 1
    for chunk in (2**20, late + 1, 97):
        rec = _encode(HH_T2_V2, t, kind, value)
        path = tmp_path / "order.ptu"
        path.write_bytes(_header(HH_T2_V2, rec.size, BW, BW) + rec.tobytes())
        got = read_ptu_histograms(path, L, bin_width=BW, chunk_records=chunk)
        np.testing.assert_array_equal(got.histograms[0], want)
    t[late + 1] = 197 * L
    rec = _encode(HH_T2_V2, t, kind, value)
    path.write_bytes(_header(HH_T2_V2, rec.size, BW, BW) + rec.tobytes())
    with pytest.raises(ConfigError, match="its time tags run backwards") as info:
        read_ptu_histograms(path, L, bin_width=BW)
    assert "\n" not in str(info.value)


def test_a_sync_divider_folds_t2_delays_as_t3(t3_file, tmp_path):
    """A sync every 2 code periods (the header's HWSync_Divider 2): each photon's delay from
    its sync is folded into one code period, as a T3 file's TDC times are."""
    nsync, dtime, channel, marker = _t3_events(t3_file)
    period, phot = 2 * L, marker == 0
    t = np.concatenate([np.arange(int(nsync.max()) // 2 + 2) * period,
                        nsync * L + np.where(phot, dtime, 0)])
    kind = np.concatenate([np.full(t.size - nsync.size, _SYNC), np.where(phot, _PHOT, _MARK)])
    value = np.concatenate([np.zeros(t.size - nsync.size, np.int64),
                            np.where(phot, channel, marker)])
    order = np.lexsort((np.arange(t.size), kind, t))
    rec = _encode(HH_T2_V2, t[order], kind[order], value[order])
    t2 = tmp_path / "d.ptu"
    t2.write_bytes(_header(HH_T2_V2, rec.size, BW, BW, divider=2) + rec.tobytes())
    got, ref = read_ptu_histograms(t2, L, bin_width=BW), read_ptu_histograms(t3_file, L,
                                                                              bin_width=BW)
    assert got.periods_per_sync == 2
    np.testing.assert_array_equal(got.histograms, ref.histograms)
    np.testing.assert_array_equal(got.counts_per_pattern, ref.counts_per_pattern)


def test_a_marker_tagged_periods_early_keeps_its_place(t3_file, tmp_path):
    """A marker whose tag lies 5 code periods before the photons recorded ahead of it (a
    marker's tag is coarser, and it may come late in the stream) is given their period: the
    file is read, not refused as a sync count that runs backwards, and its blocks are the
    T3 file's."""
    t2 = tmp_path / "late.ptu"
    t, kind, value = _as_t2(t3_file, t2, HH_T2_V2)
    late = t.copy()
    late[kind == _MARK] -= 5 * L  # (tags only: the records stay where they are)
    rec = _encode(HH_T2_V2, np.maximum(late, 0), kind, value)
    assert np.any(np.diff(np.maximum(late, 0)) < 0)
    t2.write_bytes(_header(HH_T2_V2, rec.size, BW, BW) + rec.tobytes())
    got, ref = read_ptu_histograms(t2, L, bin_width=BW), read_ptu_histograms(t3_file, L,
                                                                              bin_width=BW)
    np.testing.assert_array_equal(got.histograms, ref.histograms)
    assert np.all(got.pattern_start_sync <= ref.pattern_start_sync)
    assert np.all(got.pattern_start_sync >= ref.pattern_start_sync - 5)


@pytest.fixture(scope="module")
def wall(tmp_path_factory):
    """``run --save-ptu``'s T3 file of a wall at 1.2 m (8x8, 127-bit code at 10 GHz), its
    patterns and code, and the same events as a T2 file of 1 ps tags (``t2.ptu``)."""
    d = tmp_path_factory.mktemp("wall")
    np.save(d / "wall.npy", np.full((8, 8), 1.2))
    assert main(["run", "--scene", str(d / "wall.npy"), "--size", "8", "--code-length", "127",
                 "--signal", "1", "--noise", "0.02", "--compression", "0.5", "--range-gate",
                 "0.5", "1.8", "--no-figure", "--save-ptu", str(d / "scan.ptu"),
                 "--out", str(d / "run")]) == 0
    _as_t2(d / "scan.ptu", d / "t2.ptu", HH_T2_V2, k=100, start=2**25 - 3000)
    return d


def _reconstruct(d, ptu: str, out: str, *extra: str) -> int:
    return main(["reconstruct", "--ptu", str(d / ptu), "--patterns",
                 str(d / "scan_patterns.npy"), "--code", str(d / "scan_code.npy"),
                 "--bit-rate", "10e9", "--range-gate", "0.5", "1.8", "--out", str(d / out),
                 "--no-figure", *extra])


def test_reconstruct_and_calibrate_read_t2_as_t3(wall, capsys):
    """The T2 file of 1 ps tags gives the T3 file's depth map, with --allow-binning (its tags
    are 100 to a bit, as a 1 ps TDC's bins would be), and the same calibration."""
    d = wall
    assert _reconstruct(d, "scan.ptu", "r3") == 0
    assert _reconstruct(d, "t2.ptu", "r2", "--allow-binning") == 0
    np.testing.assert_array_equal(np.load(d / "r2" / "depth.npy"), np.load(d / "r3" / "depth.npy"))
    capsys.readouterr()
    assert _reconstruct(d, "t2.ptu", "r2b") == 2  # (as a T3 file of a 1 ps TDC would be)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--allow-binning" in err[0], err
    import json

    cal = {}
    for name, extra in (("scan.ptu", []), ("t2.ptu", ["--allow-binning"])):
        out = d / f"cal_{name}.json"
        assert main(["calibrate", "--ptu", str(d / name), "--patterns",
                     str(d / "scan_patterns.npy"), "--code", str(d / "scan_code.npy"),
                     "--bit-rate", "10e9", "--distance", "1.2", "--out", str(out), *extra]) == 0
        cal[name] = json.loads(out.read_text())
    for key in ("delay_s", "lag_shift", "irf_offsets", "irf_values", "irf_fwhm_bins"):
        assert cal["t2.ptu"][key] == cal["scan.ptu"][key], key


def test_reconstruct_with_the_sync_on_a_detector_input(wall, capsys):
    """The same events with the sync recorded on detector channel 2: reconstruct and
    calibrate with --sync-channel 2 give the T3 file's depth map and calibration, and
    metrics.json names the channel; without it, one line and nothing written."""
    import json

    d = wall
    _as_t2(d / "scan.ptu", d / "c2.ptu", HH_T2_V2, k=100, start=2**25 - 3000,
           sync_as_channel=2)
    assert _reconstruct(d, "scan.ptu", "s3") == 0
    assert _reconstruct(d, "c2.ptu", "s2", "--allow-binning", "--sync-channel", "2") == 0
    np.testing.assert_array_equal(np.load(d / "s2" / "depth.npy"), np.load(d / "s3" / "depth.npy"))
    metrics = json.loads((d / "s2" / "metrics.json").read_text())
    assert metrics["ptu"]["sync_channel"] == 2
    assert json.loads((d / "s3" / "metrics.json").read_text())["ptu"]["sync_channel"] is None
    capsys.readouterr()
    assert _reconstruct(d, "c2.ptu", "s2b", "--allow-binning") == 2
    err = capsys.readouterr().err.strip().splitlines()
    # (33 syncs, one a pattern under run's sync divider: too few to name the channel, which
    # the refusal does from 64 periodic events, test_the_sync_on_a_detector_input_read_...)
    assert len(err) == 1 and "with no sync record" in err[0], err
    assert not (d / "s2b").exists()
    cal = []
    for name, extra in (("scan.ptu", []), ("c2.ptu", ["--allow-binning", "--sync-channel", "2"])):
        out = d / f"calc_{name}.json"
        assert main(["calibrate", "--ptu", str(d / name), "--patterns",
                     str(d / "scan_patterns.npy"), "--code", str(d / "scan_code.npy"),
                     "--bit-rate", "10e9", "--distance", "1.2", "--out", str(out), *extra]) == 0
        cal.append(json.loads(out.read_text()))
    for key in ("delay_s", "lag_shift", "irf_offsets", "irf_values", "irf_fwhm_bins"):
        assert cal[1][key] == cal[0][key], key


def test_photons_after_a_missing_sync_are_said(wall):
    """A T2 file whose sync records miss a quarter of the periods (a sync input's trigger
    level): those periods' photons come past the code period, are left out, and the warning
    says that syncs are missing, not that the header's sync period is wrong."""
    d = wall
    _as_t2(d / "scan.ptu", d / "gaps.ptu", HH_T2_V2, k=1, drop=np.arange(3, 33, 4))
    assert _reconstruct(d, "gaps.ptu", "rg") == 0
    import json

    said = [w for w in json.loads((d / "rg" / "metrics.json").read_text())["warnings"]
            if "past the code period" in w]
    assert len(said) == 1 and "the file lacks sync records there" in said[0], said
    assert "header" not in said[0]


def _one_line_refusal(capsys, d, ptu, *extra) -> str:
    capsys.readouterr()
    assert _reconstruct(d, ptu, "refused", *extra) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert not (d / "refused").exists()
    return err[0]


def test_t2_without_a_sync_is_refused_in_one_line(wall, capsys):
    d = wall
    _as_t2(d / "scan.ptu", d / "nosync.ptu", HH_T2_V2, k=100, syncs=False)
    err = _one_line_refusal(capsys, d, "nosync.ptu", "--allow-binning")
    assert "holds T2 records (HydraHarp2T2) with no sync record" in err
    assert "record the lidar in T3 mode, or record the code generator's sync in T2" in err
    assert main(["calibrate", "--ptu", str(d / "nosync.ptu"), "--patterns",
                 str(d / "scan_patterns.npy"), "--code", str(d / "scan_code.npy"),
                 "--bit-rate", "10e9", "--distance", "1.2", "--allow-binning", "--out",
                 str(d / "nocal.json")]) == 2
    said = capsys.readouterr().err.strip().splitlines()
    assert len(said) == 1 and "with no sync record" in said[0], said
    assert not (d / "nocal.json").exists()
    (d / "empty.ptu").write_bytes(_header(HH_T2_V2, 0, BW, BW))  # (no record at all)
    with pytest.raises(ConfigError, match="with no sync record"):
        read_ptu_histograms(d / "empty.ptu", L, bin_width=BW)
    with pytest.raises(ConfigError, match="a single sync record"):
        one = _encode(HH_T2_V2, np.array([0, 5]), np.array([_SYNC, _PHOT]), np.array([0, 0]))
        (d / "one.ptu").write_bytes(_header(HH_T2_V2, 2, BW, BW) + one.tobytes())
        read_ptu_histograms(d / "one.ptu", L, bin_width=BW)


def test_a_detector_on_the_picoharps_input_0_is_no_sync(tmp_path):
    """A PicoHarp T2 file of two detectors (its usual use): input 0's photons are not
    periodic, and are refused as a sync in one line."""
    rng = np.random.default_rng(0)
    t = np.sort(rng.integers(0, 10**7, 3000))
    kind = np.where(rng.random(t.size) < 0.5, _SYNC, _PHOT)
    kind[5] = _MARK
    rec = _encode(PH_T2, t, kind, np.where(kind == _MARK, 1, 0))
    path = tmp_path / "fcs.ptu"
    path.write_bytes(_header(PH_T2, rec.size, 4e-12, 4e-12) + rec.tobytes())
    with pytest.raises(ConfigError, match=r"its input 0, read as the sync, are not periodic"
                       ) as info:
        read_ptu_histograms(path, L, bin_width=BW, allow_binning=True)
    assert "\n" not in str(info.value)


@pytest.mark.skipif(not REAL.is_dir(), reason="../shared/realdata is absent")
def test_the_real_t2_file_without_sync_is_refused_in_one_line(wall, capsys):
    """libpicoquant's HydraHarp T2 file (a detector, no sync records) is refused."""
    err = _one_line_refusal(capsys, wall, REAL / "libpicoquant_hh_v30_t2.ptu",
                            "--allow-binning")
    assert "holds T2 records (HydraHarp2T2) with no sync record" in err


def test_a_picoharp_marker_at_its_syncs_tag_starts_that_period(t3_file, tmp_path):
    """A PicoHarp T2 marker's tag lacks its low 4 bits: at its sync's tag, with the syncs off
    multiples of 16 (4 ps tags under 100 ps bits), it was read a period early and every dwell
    was one period off (an outside audit: 201 / 199 for 200); it reads as its T3 file."""
    t2 = tmp_path / "b.ptu"
    _as_t2(t3_file, t2, PH_T2, k=25, start=7)
    ref = read_ptu_histograms(t3_file, L, bin_width=BW)
    _same(read_ptu_histograms(t2, L, bin_width=BW, allow_binning=True), ref)
    _same(read_ptu_histograms(t2, L, bin_width=BW, allow_binning=True, chunk_records=333), ref)


def _syncs_file(path, sync_t, rectype=HH_T2_V2, sync_as_channel=None, seed=3):
    """A T2 file of syncs at ``sync_t``, a marker at the first and 2000 photons between (on
    channel 0), or with the syncs written as photons on ``sync_as_channel``."""
    rng = np.random.default_rng(seed)
    phot = np.sort(rng.integers(int(sync_t[0]), int(sync_t[-1]), 2000))
    t = np.concatenate([sync_t, [sync_t[0]], phot])
    kind = np.concatenate([np.full(sync_t.size, _SYNC if sync_as_channel is None else _PHOT),
                           [_MARK], np.full(phot.size, _PHOT)])
    value = np.concatenate([np.full(sync_t.size, sync_as_channel or 0), [1],
                            np.zeros(phot.size, np.int64)])
    order = np.lexsort((np.arange(t.size), kind, t))
    rec = _encode(rectype, t[order], kind[order], value[order])
    path.write_bytes(_header(rectype, rec.size, BW, BW) + rec.tobytes())


def test_a_jittered_sync_on_coarse_tags_and_a_few_glitches_are_read(tmp_path):
    """Syncs 127 tags apart, each moved by up to 2 tags (jitter and the tags' rounding: 1.6 %
    of the period, over the 1 % share; refused as "a detector on it?", an outside audit), are
    read, the period measured from them; a few glitches (an extra sync 40 tags after 3 of
    them) are read with a warning, not refused."""
    rng = np.random.default_rng(4)
    n = np.arange(3000)
    jittered = n * L + 50 + rng.integers(-2, 3, n.size)
    _syncs_file(tmp_path / "j.ptu", jittered)
    got = read_ptu_histograms(tmp_path / "j.ptu", L, bin_width=BW)
    assert got.sync_period_s == pytest.approx(L * BW, rel=1e-4)
    assert got.n_photons == 2000
    glitched = np.sort(np.concatenate([n * L + 50, [100 * L + 90, 900 * L + 90,
                                                    1500 * L + 90]]))
    _syncs_file(tmp_path / "g.ptu", glitched)
    with pytest.warns(RuntimeWarning, match="6 of the first 3002 intervals between its sync "
                                            "records are off"):
        got = read_ptu_histograms(tmp_path / "g.ptu", L, bin_width=BW)
    assert got.sync_period_s == pytest.approx(L * BW, rel=1e-9)


def test_a_sync_recorded_on_a_detector_input_is_named(tmp_path, capsys):
    """No sync record, but channel 3 holds periodic events: the refusal names the channel
    and the converter that takes it as the sync (the data hold it: an outside audit)."""
    _syncs_file(tmp_path / "s.ptu", np.arange(3000) * L + 50, sync_as_channel=3)
    with pytest.raises(ConfigError, match=r"with no sync record.*its channel 3 holds periodic "
                                          r"events \(every 1\.27e-08 s\).*--sync-channel 3 "
                                          r"reads them as the sync") as info:
        read_ptu_histograms(tmp_path / "s.ptu", L, bin_width=BW)
    assert "\n" not in str(info.value)


def test_a_jittered_sync_channel_is_said(tmp_path):
    """A sync on a detector input that jitters by a code bin (RMS) blurs every photon's delay
    by as much; it was read without a word (an outside audit of stop 67). Steady syncs on the
    same channel, their tags only rounded, are read without one."""
    n = np.arange(3000)
    rng = np.random.default_rng(5)
    _syncs_file(tmp_path / "j.ptu", n * L + 50 + np.rint(rng.normal(0, 1.0, n.size)).astype(int),
                sync_as_channel=3)
    with pytest.warns(RuntimeWarning, match=r"the events of channel 3, read as the sync "
                                            r"\(--sync-channel\), jitter by [\d.]+ ps RMS "
                                            r"\((0\.9\d|1|1\.0\d) code bins\)"):
        read_ptu_histograms(tmp_path / "j.ptu", L, bin_width=BW, sync_channel=3)
    # (a period of 127.3 tags: the rounding alone moves each gap by up to a tag, a twelfth of
    # a tag squared per sync, which is no jitter)
    _syncs_file(tmp_path / "s.ptu", np.rint(n * (L + 0.3) + 50).astype(int), sync_as_channel=3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_ptu_histograms(tmp_path / "s.ptu", L, bin_width=BW, sync_channel=3,
                            check_sync_period=False)


@pytest.mark.parametrize("rectype", [HH_T2_V2, HH_T2_V1, GENERIC_T2])
def test_the_sync_on_a_detector_input_read_with_sync_channel(t3_file, tmp_path, rectype):
    """The code generator's sync recorded on detector channel 5 (no sync records), read with
    ``sync_channel=5``, is its T3 file exactly: the same histograms, dwells and photons
    (channel 5's events are the syncs, not photons), in any chunking; the file's own sync
    records, where it has them too, are not read."""
    ref = read_ptu_histograms(t3_file, L, bin_width=BW)
    t2 = tmp_path / "c5.ptu"
    _as_t2(t3_file, t2, rectype, k=4, start=1000, sync_as_channel=5)
    for chunk in (2**20, 777):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # (no sync record of its own: nothing to say)
            _same(read_ptu_histograms(t2, L, bin_width=BW, allow_binning=True, sync_channel=5,
                                      chunk_records=chunk), ref)
    with pytest.raises(ConfigError, match="its channel 5 holds periodic events"):
        read_ptu_histograms(t2, L, bin_width=BW, allow_binning=True)
    # sync records too, at another period (an idle input's): channel 5 is the sync
    both = tmp_path / "both.ptu"
    t, kind, value = _as_t2(t3_file, both, rectype, k=4, start=1000, sync_as_channel=5)
    other = np.arange(5, int(t.max()), 3 * L * 4 + 7)
    tt = np.concatenate([t, other])
    kk = np.concatenate([kind, np.full(other.size, _SYNC)])
    vv = np.concatenate([value, np.zeros(other.size, np.int64)])
    order = np.lexsort((np.arange(tt.size), tt))
    rec = _encode(rectype, tt[order], kk[order], vv[order])
    both.write_bytes(_header(rectype, rec.size, BW / 4, BW / 4) + rec.tobytes())
    # (said: they were ignored without a word, an outside audit of stop 67)
    with pytest.warns(RuntimeWarning, match=r"--sync-channel 5: the file holds sync records "
                                            r"of its own \(\d+ in its first \d+ records\), "
                                            r"which are ignored"):
        _same(read_ptu_histograms(both, L, bin_width=BW, allow_binning=True, sync_channel=5),
              ref)


def test_sync_channel_refusals(t3_file, tmp_path):
    """--sync-channel on a T3 file, a PicoHarp T2 file, a channel no record holds, one
    without events, one that is not periodic, or named as --channel too: one line each."""
    t2 = tmp_path / "c5.ptu"
    _as_t2(t3_file, t2, HH_T2_V2, sync_as_channel=5)
    ph = tmp_path / "ph.ptu"
    _as_t2(t3_file, ph, PH_T2, k=16, start=160)
    cases = [(t3_file, 5, {}, "holds T3 records .* which count the syncs themselves"),
             (ph, 1, {}, "PicoHarp T2 file, whose input 0 is read as the sync"),
             (t2, 64, {}, "--sync-channel 64: HydraHarp2T2 records number detector channels "
                          "0..63"),
             (t2, -1, {}, "must be a detector channel number >= 0"),
             (t2, True, {}, "must be a detector channel number >= 0"),
             (t2, 7, {}, r"its channel 7 \(--sync-channel\) holds no event.*channels with "
                         r"events: 0, 5\)"),
             (t2, 0, {}, "the events of its channel 0, read as the sync "
                         "\\(--sync-channel\\), are not periodic"),
             (t2, 5, {"channel": [0, 5]}, "--channel 5 is the --sync-channel")]
    for path, c, extra, said in cases:
        with pytest.raises(ConfigError, match=said) as info:
            read_ptu_histograms(path, L, bin_width=BW, sync_channel=c, **extra)
        assert "\n" not in str(info.value), said


def test_a_photon_before_the_first_sync_in_any_chunking(tmp_path):
    """A photon 2 tags before the file's first sync, recorded after it: placed back from it
    in every chunking (a review found it refused as time running backwards where the first
    sync ended a chunk)."""
    n = np.arange(300)
    sync_t = n * L + 50
    rng = np.random.default_rng(5)
    phot = np.sort(rng.integers(60, int(sync_t[-1]), 1000))
    t = np.concatenate([[50, 50, 48], sync_t[1:], phot])
    kind = np.concatenate([[_SYNC, _MARK, _PHOT], np.full(n.size - 1, _SYNC),
                           np.full(phot.size, _PHOT)])
    order = np.concatenate([[0, 1, 2], 3 + np.lexsort((kind[3:], t[3:]))])
    t, kind = t[order], kind[order]
    value = np.where(kind == _MARK, 1, 0)
    rec = _encode(HH_T2_V2, t, kind, value)
    path = tmp_path / "early.ptu"
    path.write_bytes(_header(HH_T2_V2, rec.size, BW, BW) + rec.tobytes())
    ref = read_ptu_histograms(path, L, bin_width=BW)
    assert ref.n_photons == 1001
    for chunk in (1, 2, 3, 97):
        _same(read_ptu_histograms(path, L, bin_width=BW, chunk_records=chunk), ref)


def test_a_picoharps_sync_on_a_detector_input_is_told_to_go_to_input_0(tmp_path):
    """A PicoHarp T2 file whose sync went to detector input 3 (channel 2): the refusal names
    the channel and says to connect the sync to input 0, not --sync-channel, which a
    PicoHarp file refuses (an outside audit of stop 67)."""
    _syncs_file(tmp_path / "ph.ptu", (np.arange(3000) * L + 50) * 16, rectype=PH_T2,
                sync_as_channel=2)
    with pytest.raises(ConfigError, match=r"its channel 2 holds periodic events .*a PicoHarp "
                                          r"reads its sync on input 0: connect it there") as info:
        read_ptu_histograms(tmp_path / "ph.ptu", L, bin_width=BW)
    assert "--sync-channel" not in str(info.value)
