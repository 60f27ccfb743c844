"""PicoQuant T3 PTU reading (via ptufile) and writing (spslidar.io.ptu)."""

from __future__ import annotations

import struct
import sys

import numpy as np
import pytest

from spslidar.errors import ConfigError
from spslidar.io import (
    ptu_info,
    read_ptu_histograms,
    write_acquisition_ptu,
    write_ptu_t3,
)

ptufile = pytest.importorskip("ptufile")

L = 63
BW = 250e-12


def _random_acquisition(seed: int, n_patterns: int = 6, periods: int = 700):
    rng = np.random.default_rng(seed)
    events, hist = [], np.zeros((n_patterns, L))
    for k in range(n_patterns):
        n = int(rng.integers(0, 300)) if k != 2 else 0  # pattern 2 has no photons
        ev = np.stack([rng.integers(0, periods, n), rng.integers(0, L, n)], axis=1)
        events.append(ev)
        np.add.at(hist[k], ev[:, 1], 1)
    return events, hist


# --- independent PTU construction (PicoQuant tag header format, not spslidar's writer) ------


def _ptu_bytes(tags: list[tuple[str, str, object]], records: list[int] | np.ndarray) -> bytes:
    """A PTU file from (ident, kind, value) tags and raw 32-bit records."""
    out = [b"PQTTTR\0\0", b"1.0.00\0\0"]
    for ident, kind, value in tags:
        head = ident.encode().ljust(32, b"\0") + struct.pack("<i", -1)
        if kind == "int":
            out.append(head + struct.pack("<Iq", 0x10000008, value))
        elif kind == "float":
            out.append(head + struct.pack("<Id", 0x20000008, value))
        elif kind == "str":
            data = value.encode() + b"\0" * (8 - len(value) % 8)
            out.append(head + struct.pack("<Iq", 0x4001FFFF, len(data)) + data)
    out.append(b"Header_End".ljust(32, b"\0") + struct.pack("<iIq", -1, 0xFFFF0008, 0))
    return b"".join(out) + np.asarray(records, "<u4").tobytes()


def _tags(rectype: int, n_records: int, res: float, period: float, mode: int = 3):
    return [
        ("File_Comment", "str", "hand-made test file"),
        ("Measurement_Mode", "int", mode),
        ("Measurement_SubMode", "int", 0),
        ("MeasDesc_Resolution", "float", res),
        ("MeasDesc_GlobalResolution", "float", period),
        ("TTResult_SyncRate", "int", round(1 / period)),
        ("TTResult_NumberOfRecords", "int", n_records),
        ("TTResultFormat_TTTRRecType", "int", rectype),
        ("TTResultFormat_BitsPerRecord", "int", 32),
    ]


def _ph(ch: int, dt: int, ns: int) -> int:  # PicoHarp T3: channel 4 | dtime 12 | nsync 16
    return (ch << 28) | (dt << 16) | ns


def _hh(special: int, ch: int, dt: int, ns: int) -> int:  # HydraHarp T3: 1 | 6 | 15 | 10
    return (special << 31) | (ch << 25) | (dt << 10) | ns


# --- round trip ------------------------------------------------------------------------------


@pytest.mark.parametrize("record_type", ["HydraHarp2T3", "HydraHarpT3", "PicoHarpT3", "generic"])
def test_round_trip_exact_histograms(tmp_path, record_type):
    events, hist = _random_acquisition(1)
    # pattern 4 lasts 2.5 M periods: > 1023 wraps, several HydraHarp-v2 overflow records
    periods = [700, 700, 700, 700, 2_500_000, 700]
    events[4][:, 0] *= 3000
    path = tmp_path / "acq.ptu"
    n_rec = write_acquisition_ptu(path, events, L, BW, periods_per_pattern=periods,
                                  record_type=record_type)
    starts = np.concatenate([[0], np.cumsum(periods)[:-1]])
    results = [read_ptu_histograms(path, L, bin_width=BW, n_patterns=6, chunk_records=c)
               for c in (2**22, 97, 1)]
    for acq in results:
        assert acq.histograms.dtype == np.float32 and acq.histograms.shape == (6, L)
        np.testing.assert_array_equal(acq.histograms, hist)
        np.testing.assert_array_equal(acq.counts_per_pattern, hist.sum(1))
        np.testing.assert_array_equal(acq.pattern_start_sync, starts)
        assert acq.n_records == n_rec and acq.n_markers == 6 and acq.n_photons == hist.sum()
        assert acq.n_dropped_before_first_marker == acq.n_out_of_range == 0
        assert acq.resolution_s == pytest.approx(BW, rel=1e-12)
        assert acq.sync_period_s == pytest.approx(L * BW, rel=1e-12)
        assert acq.n_overflows > 0
    assert results[0].last_sync == results[1].last_sync == results[2].last_sync
    # without n_patterns: as many patterns as markers
    np.testing.assert_array_equal(read_ptu_histograms(path, L).histograms, hist)


def test_ptufile_decodes_written_records(tmp_path):
    rng = np.random.default_rng(2)
    nsync = np.sort(rng.integers(0, 5000, 400))
    dtime = rng.integers(0, 32768, 400)
    channel = rng.integers(0, 8, 400)
    marker = np.where(rng.random(400) < 0.05, rng.integers(1, 16, 400), 0)
    path = tmp_path / "raw.ptu"
    n_rec = write_ptu_t3(path, nsync=nsync, dtime=dtime, channel=channel, marker=marker,
                         resolution_s=1e-12, sync_rate_hz=20e6)
    with ptufile.PtuFile(path) as f:
        assert f.record_type == ptufile.PtuRecordType.HydraHarp2T3 and f.is_t3
        assert f.number_records == n_rec
        assert f.tcspc_resolution == 1e-12
        assert f.global_resolution == pytest.approx(50e-9)
        assert f.frequency == pytest.approx(20e6)
        d = f.decode_records()
    events = (d["channel"] >= 0) | (d["marker"] > 0)
    assert np.count_nonzero(~events) == (nsync[-1] // 1024)  # one overflow record per wrap
    d = d[events]
    photon = marker == 0
    np.testing.assert_array_equal(d["time"], nsync)
    np.testing.assert_array_equal(d["dtime"][photon], dtime[photon])
    np.testing.assert_array_equal(d["channel"][photon], channel[photon])
    np.testing.assert_array_equal(d["channel"][~photon], -1)
    np.testing.assert_array_equal(d["marker"], marker)


def test_pattern_starts_match_ptufile_full_decode(tmp_path):
    events, _ = _random_acquisition(3, n_patterns=9, periods=1500)
    path = tmp_path / "acq.ptu"
    write_acquisition_ptu(path, events, L, BW, periods_per_pattern=1500, marker=3)
    acq = read_ptu_histograms(path, L, bin_width=BW, marker=3, chunk_records=64)
    with ptufile.PtuFile(path) as f:
        d = f.decode_records()
    np.testing.assert_array_equal(acq.pattern_start_sync, d["time"][d["marker"] == 4])
    photons = d["time"][d["channel"] >= 0]
    assert acq.last_sync == int(photons[-1])


# --- files spslidar did not write ------------------------------------------------------------


def test_foreign_picoharp_t3_file(tmp_path):
    # hand-built PicoHarp T3: photons before the first marker, a second detector channel,
    # marker 1 noise, pattern markers on input 2, 16-bit sync wrap, 8 ps dtime unit
    res, n_bins = 8e-12, 100
    recs = [_ph(1, 10, 5), _ph(15, 2, 6)]  # photon before any pattern; marker-2 starts pattern 0
    expected = np.zeros((3, n_bins))
    recs += [_ph(1, 7, 7), _ph(1, 99, 8), _ph(2, 40, 9), _ph(15, 1, 10), _ph(1, 7, 11)]
    np.add.at(expected[0], [7, 99, 7], 1)  # the channel-2 photon (ptufile 1) is not kept
    recs += [_ph(15, 0, 0), _ph(15, 0, 0), _ph(15, 3, 12), _ph(1, 0, 13), _ph(1, 55, 65535)]
    np.add.at(expected[1], [0, 55], 1)  # marker bits 3 = inputs 1 and 2 together
    recs += [_ph(15, 0, 0), _ph(15, 2, 1), _ph(1, 12, 2), _ph(1, 12, 3), _ph(1, 120, 3)]
    expected[2, 12] += 2  # dtime 120 >= n_bins: out of range
    path = tmp_path / "foreign.ptu"
    path.write_bytes(_ptu_bytes(_tags(0x00010303, len(recs), res, n_bins * res), recs))

    acq = read_ptu_histograms(path, n_bins, bin_width=res, marker=2, channel=0)
    np.testing.assert_array_equal(acq.histograms, expected)
    np.testing.assert_array_equal(acq.pattern_start_sync, [6, 2 * 65536 + 12, 3 * 65536 + 1])
    assert acq.n_dropped_before_first_marker == 1 and acq.n_out_of_range == 1
    assert acq.n_overflows == 3 and acq.n_photons == 9
    assert acq.header["record_type"] == "PicoHarpT3"
    assert acq.header["comment"] == "hand-made test file"
    # both channels; only the first two patterns (the rest counted as dropped)
    acq2 = read_ptu_histograms(path, n_bins, bin_width=res, marker=2, n_patterns=2)
    assert acq2.counts_per_pattern.tolist() == [4, 2]
    assert acq2.n_dropped_after_last_pattern == 3
    # 16 ps bins from 8 ps dtime units, only with allow_binning
    with pytest.raises(ConfigError, match="allow_binning"):
        read_ptu_histograms(path, 50, bin_width=2 * res, marker=2)
    acq3 = read_ptu_histograms(path, 50, bin_width=2 * res, marker=2, allow_binning=True)
    assert acq3.binning == 2 and acq3.histograms[0, 3] == 2 and acq3.histograms[2, 6] == 2


def test_foreign_hydraharp_v2_file_without_record_count(tmp_path):
    # HydraHarp v2 overflow records carry a wrap count (0 means 1); TTResult_NumberOfRecords
    # is 0 as in some third-party files, so the record count comes from the file size
    recs = [_hh(1, 1, 0, 0), _hh(0, 0, 3, 0), _hh(1, 63, 0, 0), _hh(0, 0, 4, 1),
            _hh(1, 63, 0, 1000), _hh(1, 1, 0, 2), _hh(0, 3, 31, 5)]
    path = tmp_path / "hh.ptu"
    path.write_bytes(_ptu_bytes(_tags(0x01010304, 0, 1e-9, 32e-9), recs))
    acq = read_ptu_histograms(path, 32, bin_width=1e-9, chunk_records=3)
    assert acq.n_records == 7 and acq.n_overflows == 2
    np.testing.assert_array_equal(acq.pattern_start_sync, [0, 1001 * 1024 + 2])
    np.testing.assert_array_equal(np.flatnonzero(acq.histograms[0]), [3, 4])
    np.testing.assert_array_equal(np.flatnonzero(acq.histograms[1]), [31])
    assert acq.last_sync == 1001 * 1024 + 5


def test_ptu_info(tmp_path):
    path = tmp_path / "a.ptu"
    write_acquisition_ptu(path, [np.array([[0, 1]])], L, BW, record_type="PicoHarpT3")
    info = ptu_info(path)
    assert info["record_type"] == "PicoHarpT3" and info["measurement_mode"] == "T3"
    assert info["n_records"] == info["n_records_in_file"] == 2
    assert info["bins_per_period"] == pytest.approx(L)
    assert info["creator"] == "spslidar"


# --- bad input -------------------------------------------------------------------------------


def _raises(match: str, *args, **kwargs) -> str:
    with pytest.raises(ConfigError, match=match) as info:
        read_ptu_histograms(*args, **kwargs)
    message = str(info.value)
    assert "\n" not in message
    return message


def test_bad_files_raise_config_error(tmp_path):
    text = tmp_path / "notes.ptu"
    text.write_text("this is not a PTU file\n")
    _raises("not a readable PicoQuant PTU file", text, L)
    _raises("not found", tmp_path / "missing.ptu", L)

    t2 = tmp_path / "t2.ptu"
    t2.write_bytes(_ptu_bytes(_tags(0x01010204, 2, 1e-12, 1e-6, mode=2), [5, 6]))
    _raises("T2 records", t2, L)

    good = tmp_path / "good.ptu"
    events, _ = _random_acquisition(4)
    write_acquisition_ptu(good, events, L, BW)
    cut = tmp_path / "cut.ptu"
    cut.write_bytes(good.read_bytes()[:-10])
    msg = _raises("truncated", cut, L)
    assert "records" in msg
    cut.write_bytes(good.read_bytes()[:300])  # inside the tag header
    _raises("truncated or corrupt PTU tag header", cut, L)

    # no markers at all, and markers only on another input
    nomark = tmp_path / "nomark.ptu"
    write_ptu_t3(nomark, nsync=[0, 1, 2], dtime=[1, 2, 3], resolution_s=BW,
                 sync_rate_hz=1 / (L * BW))
    _raises("no markers at all", nomark, L)
    _raises("markers present on inputs \\[1\\]", good, L, marker=2)

    _raises("6 marker-delimited blocks .* fewer than n_patterns=7", good, L, n_patterns=7)

    _raises("dtime resolution .* does not match bin_width", good, L, bin_width=1.5 * BW)
    _raises("sync period .* != code period", good, L - 1, bin_width=BW)
    _raises("sync period", good, 2 * L)
    # the check can be switched off: the extra bins just stay empty
    wide = read_ptu_histograms(good, 2 * L, check_sync_period=False)
    assert not wide.histograms[:, L:].any()


def test_bad_arguments(tmp_path, monkeypatch):
    path = tmp_path / "a.ptu"
    write_acquisition_ptu(path, [np.array([[0, 1]])], L, BW)
    _raises("marker must be", path, L, marker=0)
    _raises("n_bins must be", path, 0)
    with pytest.raises(ConfigError, match="non-decreasing"):
        write_ptu_t3(path, nsync=[3, 2], dtime=[0, 0], resolution_s=BW, sync_rate_hz=1e6)
    with pytest.raises(ConfigError, match="dtime out of range 0..4095"):
        write_ptu_t3(path, nsync=[0], dtime=[5000], resolution_s=BW, sync_rate_hz=1e6,
                     record_type="PicoHarpT3")
    with pytest.raises(ConfigError, match="unknown T3 record type"):
        write_acquisition_ptu(path, [], L, BW, record_type="HydraHarpT2")
    with pytest.raises(ConfigError, match="bins in 0..62"):
        write_acquisition_ptu(path, [np.array([[0, L]])], L, BW)
    monkeypatch.setitem(sys.modules, "ptufile", None)
    _raises("pip install ptufile", path, L)


def test_negative_record_count_is_refused(tmp_path):
    """A header announcing -5 records was read as if it gave none (issue 24, item 4)."""
    import struct

    from spslidar.io import write_acquisition_ptu

    path = tmp_path / "neg.ptu"
    write_acquisition_ptu(path, [np.array([[0, 5]]), np.array([[0, 6]])], 127, 1e-10,
                          periods_per_pattern=1)
    data = bytearray(path.read_bytes())
    at = data.find(b"TTResult_NumberOfRecords")
    struct.pack_into("<q", data, at + 40, -5)  # the tag's 8-byte value follows its 40 bytes
    path.write_bytes(bytes(data))
    with pytest.raises(ConfigError, match="-5 records"):
        read_ptu_histograms(path, 127, bin_width=1e-10)
