"""The PTU reader on files nobody here wrote (issue 20, items 5 and 7): real PicoQuant
recordings from public repositories in ``../shared/realdata/`` (never copied into the
project; skipped where the folder is absent; a test that needs a changed file writes it to
pytest's temporary folder). Per-block photon counts, histograms, marker syncs and dwells must
equal an independent decoder written here from PicoQuant's published record layouts; the
files the reader cannot use are refused in one line.

Record layouts (32-bit little-endian words), from PicoQuant's PTU demo readers:

* PicoHarp T3 (``0x00010303``): bits 0-15 nsync, 16-27 dtime, 28-31 channel; channel 15 is
  special: dtime 0 an overflow (+65536 syncs), else a marker bit mask in dtime's low 4 bits;
  photon channels 1-4 are 0-3 in the 0-based numbering the reader uses.
* HydraHarp T3 v1 (``0x00010304``): bits 0-9 nsync, 10-24 dtime, 25-30 channel, 31 special;
  special channel 63 is an overflow of 1024 syncs, special channels 1-15 marker bit masks;
  photon channels are 0-based.
* HydraHarp T3 v2 (``0x01010304``; TimeHarp 260 N/P ``0x00010305/6`` and generic T3
  ``0x00010307`` alike): as v1, but an overflow adds ``1024 * nsync`` syncs (0 counts as 1).
* HydraHarp T2 v2 (``0x01010204``): bits 0-24 time tag, 25-30 channel, 31 special; only its
  photon count is checked (it has no sync record: the reader refuses it).
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.errors import ConfigError
from spslidar.io import ptu_info, read_ptu_histograms

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "realdata"
pytestmark = pytest.mark.skipif(not REAL.is_dir(), reason="../shared/realdata is absent")

_AnsiString, _WideString, _Blob = 0x4001FFFF, 0x4002FFFF, 0xFFFFFFFF
PICOHARP_T3, HYDRAHARP_T3_V1, HYDRAHARP_T3_V2, HYDRAHARP_T2_V2 = (
    0x00010303, 0x00010304, 0x01010304, 0x01010204)
_V2_LIKE = {HYDRAHARP_T3_V2, 0x00010305, 0x00010306, 0x00010307}


def _header(data: bytes) -> tuple[dict, int, int]:
    """The tags of a PTU header, the byte offset of its first record and the byte offset of
    the record-type tag's value."""
    assert data[:6] == b"PQTTTR"
    pos, tags, at = 16, {}, -1
    while True:
        # a tag: 32-byte ident, int32 index, uint32 type, then an 8-byte value (a length for
        # strings and blobs, whose bytes follow)
        ident, _idx, typ = struct.unpack_from("<32siI", data, pos)
        name = ident.split(b"\0")[0].decode()
        value = struct.unpack_from("<d" if typ == 0x20000008 else "<q", data, pos + 40)[0]
        if name == "TTResultFormat_TTTRRecType":
            at = pos + 40
        pos += 48
        if typ in (_AnsiString, _WideString, _Blob):
            pos += int(value)
            value = None
        tags[name] = value
        if name == "Header_End":
            return tags, pos, at


def _records(data: bytes) -> tuple[int, np.ndarray]:
    tags, offset, _ = _header(data)
    return tags["TTResultFormat_TTTRRecType"], np.frombuffer(data[offset:], "<u4").astype(
        np.int64)


def _decode(data: bytes):
    """(absolute sync, dtime, channel (-1: marker), marker mask) of every photon and marker
    record, in file order, and the number of overflow records."""
    rtype, rec = _records(data)
    if rtype == PICOHARP_T3:
        nsync, dtime, chan = rec & 0xFFFF, (rec >> 16) & 0xFFF, rec >> 28
        special = chan == 15
        ofl = special & (dtime == 0)
        wraps = np.where(ofl, 65536, 0)
        mark = np.where(special & ~ofl, dtime & 0xF, 0)
        photon_ch = chan - 1
    elif rtype == HYDRAHARP_T3_V1 or rtype in _V2_LIKE:
        nsync, dtime, chan = rec & 0x3FF, (rec >> 10) & 0x7FFF, (rec >> 25) & 0x3F
        special = (rec >> 31) == 1
        ofl = special & (chan == 63)
        per = 1 if rtype == HYDRAHARP_T3_V1 else np.maximum(nsync, 1)
        wraps = np.where(ofl, 1024 * per, 0)
        mark = np.where(special & ~ofl & (chan >= 1) & (chan <= 15), chan, 0)
        photon_ch = chan
    else:
        raise ValueError(f"not a T3 record type: {rtype:#x}")
    sync = np.cumsum(wraps) - wraps + nsync  # overflows before each record, plus its nsync
    keep = ~ofl
    return (sync[keep], dtime[keep], np.where(special, -1, photon_ch)[keep], mark[keep],
            int(ofl.sum()))


def _reference(data: bytes, n_bins: int, marker: int, channel: int | None = None):
    """Per-block histograms (block k = photons from marker k on input ``marker`` to the
    next), the markers' syncs, the blocks' dwells and the photons before the first marker."""
    sync, dtime, ch, mark, _ = _decode(data)
    is_mark = (mark & (1 << (marker - 1))) != 0
    block = np.cumsum(is_mark) - 1
    photon = (ch >= 0) if channel is None else (ch == channel)
    before = int((photon & (block < 0)).sum())
    photon &= block >= 0
    ok = dtime[photon] < n_bins
    hist = np.zeros((int(is_mark.sum()), n_bins), np.int64)
    np.add.at(hist, (block[photon][ok], dtime[photon][ok]), 1)
    starts = sync[is_mark]
    events = (ch >= 0) | (mark != 0)
    last = int(sync[events][-1])
    dwell = np.diff(np.append(starts, last + 1))
    return hist, starts, dwell, before, last


@pytest.mark.parametrize("name,n_bins,marker", [
    ("hazelnut_z1.ptu", 132, 1),        # PicoHarp T3, line-start markers
    ("hazelnut_z1.ptu", 132, 2),        # line stops: every line's tail is an empty block
    ("hazelnut_z1.ptu", 4096, 1),       # many bins over few photons: the sparse path
    ("hazelnut_z10.ptu", 132, 3),       # 5 frame markers, 0.7 M records
    ("tttrlib_MT200_HH400_beads.ptu", 1563, 3),  # HydraHarp T3 v2
])
def test_blocks_equal_an_independent_decoder(name, n_bins, marker):
    data = (REAL / name).read_bytes()
    hist, starts, dwell, before, last = _reference(data, n_bins, marker)
    for chunk in (2**20, 997):  # nothing may depend on the chunk size
        got = read_ptu_histograms(REAL / name, n_bins, marker=marker, chunk_records=chunk,
                                  check_sync_period=False)
        assert got.histograms.shape == hist.shape
        np.testing.assert_array_equal(got.counts_per_pattern, hist.sum(axis=1))
        np.testing.assert_array_equal(got.histograms, hist)
        np.testing.assert_array_equal(got.pattern_start_sync, starts)
        np.testing.assert_array_equal(got.periods_per_pattern, dwell)
        assert got.last_sync == last and got.n_dropped_before_first_marker == before
        assert got.n_markers == hist.shape[0]


def test_first_blocks_only_with_n_patterns():
    data = (REAL / "hazelnut_z1.ptu").read_bytes()
    hist, starts, _dwell, _before, _last = _reference(data, 132, 1)
    got = read_ptu_histograms(REAL / "hazelnut_z1.ptu", 132, marker=1, n_patterns=100,
                              check_sync_period=False)
    np.testing.assert_array_equal(got.histograms, hist[:100])
    np.testing.assert_array_equal(got.periods_per_pattern, np.diff(starts[:101]))
    assert got.n_dropped_after_last_pattern >= hist[100:].sum()
    assert got.warnings == []


def test_hydraharp_v1_records(tmp_path):
    """No HydraHarp T3 v1 file is at hand: the v2 beads file's records, with the header's
    record type set to v1, are a v1 file whose overflow records count 1024 syncs each (the
    v2 reading counts 1024 * nsync). Marker syncs follow the record type."""
    data = bytearray((REAL / "tttrlib_MT200_HH400_beads.ptu").read_bytes())
    _tags, _offset, at = _header(bytes(data))
    struct.pack_into("<q", data, at, HYDRAHARP_T3_V1)
    path = tmp_path / "beads_v1.ptu"
    path.write_bytes(bytes(data))
    hist, starts, dwell, _before, last = _reference(bytes(data), 1563, 3)
    _h2, starts_v2, *_ = _reference((REAL / "tttrlib_MT200_HH400_beads.ptu").read_bytes(),
                                    1563, 3)
    assert not np.array_equal(starts, starts_v2)  # the two layouts do read differently here
    got = read_ptu_histograms(path, 1563, marker=3, chunk_records=4099,
                              check_sync_period=False)
    assert got.header["record_type"] == "HydraHarpT3"
    np.testing.assert_array_equal(got.histograms, hist)
    np.testing.assert_array_equal(got.pattern_start_sync, starts)
    np.testing.assert_array_equal(got.periods_per_pattern, dwell)
    assert got.last_sync == last


def test_readme_counts_of_the_files():
    """The counts the folder's README gives: records, photons per channel, markers per input
    (and the decoder's overflow records are the rest of the records)."""
    readme = {  # name: (records, photons per 0-based channel, markers per input 1-4)
        "hazelnut_z1.ptu": (155_398, {0: 150_363}, [1280, 1280, 5, 0]),
        "hazelnut_z10.ptu": (731_977, {0: 726_942}, [1280, 1280, 5, 0]),
        "tttrlib_MT200_HH400_beads.ptu": (104_776, {0: 52_833, 1: 20_954}, [0, 0, 50, 50]),
        "feda_H2O_300s.ptu": (336_332, {0: 45_652, 1: 22_988, 2: 77_582, 3: 23_161},
                              [0, 0, 0, 0]),
        "feda_bg_HighFRET_30s.ptu": (66_940, {0: 9252, 1: 5228, 2: 16_425, 3: 3048},
                                     [0, 0, 0, 0]),
    }
    for name, (records, photons, markers) in readme.items():
        data = (REAL / name).read_bytes()
        _s, _d, ch, mark, n_ofl = _decode(data)
        assert ptu_info(REAL / name)["n_records"] == records
        assert ch.size + n_ofl == records
        assert {int(c): int((ch == c).sum()) for c in np.unique(ch[ch >= 0])} == photons
        assert [int(((mark >> b) & 1).sum()) for b in range(4)] == markers
    rtype, rec = _records((REAL / "libpicoquant_hh_v30_t2.ptu").read_bytes())
    assert rtype == HYDRAHARP_T2_V2 and rec.size == 435_319
    assert int(((rec >> 31 == 0) & ((rec >> 25) & 0x3F == 0)).sum()) == 305_565


@pytest.mark.parametrize("name,n_bins,photons", [
    ("hazelnut_z10.ptu", 132, {0: 726_942}),
    ("tttrlib_MT200_HH400_beads.ptu", 1563, {0: 52_833, 1: 20_954}),
])
def test_photons_per_channel_and_the_word_on_merged_channels(name, n_bins, photons):
    """The reader's photons per channel are the README's (decoded independently); read
    without --channel, a file with photons on two channels says they are merged, and one
    channel chosen says nothing of it."""
    from spslidar.pipeline.blocks import read_blocks

    got = read_ptu_histograms(REAL / name, n_bins, marker=3, check_sync_period=False)
    assert got.photons_per_channel == photons
    width = got.bin_width_s
    _, notes = read_blocks(REAL / name, got.n_patterns, n_bins, bin_width=width, marker=3)
    merged = [n for n in notes if "merged into one histogram" in n]
    assert len(merged) == (len(photons) > 1)
    if merged:
        assert "channels 0 (71.6 %), 1 (28.4 %)" in merged[0]
        _, notes = read_blocks(REAL / name, got.n_patterns, n_bins, bin_width=width,
                               marker=3, channel=1)
        assert not any("merged into one histogram" in n for n in notes)


def _with_record_count(tmp_path, count: int) -> tuple[Path, bytes]:
    """The beads file, copied to ``tmp_path`` with its header's TTResult_NumberOfRecords set
    to ``count`` (an int64 tag: its value follows the tag's 40 bytes); and its bytes."""
    data = bytearray((REAL / "tttrlib_MT200_HH400_beads.ptu").read_bytes())
    at = data.find(b"TTResult_NumberOfRecords")
    assert at > 0 and struct.unpack_from("<q", data, at + 40)[0] == 104_776
    struct.pack_into("<q", data, at + 40, count)
    path = tmp_path / f"beads_{count}.ptu"
    path.write_bytes(bytes(data))
    return path, bytes(data)


def test_records_past_the_headers_count_are_said(tmp_path):
    """The header set to 1 000 records of the file's 104 776: the first 1 000 were read and
    the rest left out without a word (an audit's reconstruct read '491 photons'). They are
    still left out, as ptufile and PicoQuant's readers do, with a warning naming both
    counts; what is read equals the independent decoder's first 1 000 records."""
    path, data = _with_record_count(tmp_path, 1000)
    _tags, offset, _ = _header(data)
    with pytest.warns(RuntimeWarning) as said:
        got = read_ptu_histograms(path, 1563, marker=3, check_sync_period=False)
    lines = [str(w.message) for w in said]
    assert len(lines) == 1 and "the header says 1000 records (TTResult_NumberOfRecords) but " \
        "the file holds 104776 whole records after the header: only the first 1000 are " \
        "read" in lines[0], lines
    hist, starts, *_ = _reference(data[:offset + 4 * 1000], 1563, 3)
    assert got.n_records == 1000
    np.testing.assert_array_equal(got.histograms, hist)
    np.testing.assert_array_equal(got.pattern_start_sync, starts)
    assert ptu_info(path)["n_records_in_file"] == 104_776


def test_a_header_count_of_zero_reads_every_record(tmp_path):
    """An unfinished acquisition's header count, 0: every record is read, as ptufile reads
    it, and said."""
    path, data = _with_record_count(tmp_path, 0)
    with pytest.warns(RuntimeWarning, match="is 0, as an acquisition that did not finish"):
        got = read_ptu_histograms(path, 1563, marker=3, check_sync_period=False)
    hist, *_ = _reference(data, 1563, 3)
    assert got.n_records == 104_776
    np.testing.assert_array_equal(got.histograms, hist)


def test_a_sync_period_mismatch_names_the_code_that_fits():
    """The beads file's 25 ns sync period is 1562.50 16-ps bins: a 1562-bit code misses it
    by half a bin and more; the refusal says which code length fits."""
    with pytest.raises(ConfigError, match=r"\+0\.502 bins, tolerance 0\.5") as info:
        read_ptu_histograms(REAL / "tttrlib_MT200_HH400_beads.ptu", 1562, marker=3,
                            bin_width=16e-12)
    assert "the file's sync period is 1562.50 bins at 62.5 GHz: a 1563-bit code fits it" \
        in str(info.value)


def test_channel_selection_and_a_channel_without_photons():
    path = REAL / "tttrlib_MT200_HH400_beads.ptu"
    hist, *_ = _reference(path.read_bytes(), 1563, 3, channel=1)
    one = read_ptu_histograms(path, 1563, marker=3, channel=1, check_sync_period=False)
    np.testing.assert_array_equal(one.histograms, hist)
    with pytest.raises(ConfigError, match="no photons on channel 7") as info:
        read_ptu_histograms(path, 1563, marker=3, channel=7, check_sync_period=False)
    assert "photons on 0, 1" in str(info.value)
    # each listed channel must hold photons, not one of them (found 2026-11-28)
    with pytest.raises(ConfigError, match="no photons on channel 2 "):
        read_ptu_histograms(path, 1563, marker=3, channel=[0, 2], check_sync_period=False)
    with pytest.raises(ConfigError, match="PicoHarpT3 records number detector channels 0..3"):
        read_ptu_histograms(REAL / "hazelnut_z1.ptu", 132, channel=4,
                            check_sync_period=False)


@pytest.mark.parametrize("name,match", [
    ("feda_H2O_300s.ptu", "the file has no markers at all"),
    ("libpicoquant_hh_v30_t2.ptu", r"holds T2 records \(HydraHarp2T2\) with no sync record"),
    # named (it was "not a readable PicoQuant PTU file (... magic=b'HydraHar')")
    ("libpicoquant_hh_v20.ht3", "is a legacy HydraHarp .ht3 file .* which spslidar does not "
                                "read: convert it to PTU"),
    ("README.md", "not a readable PicoQuant PTU"),
])
def test_refusals_are_one_line(name, match):
    with pytest.raises(ConfigError, match=match) as info:
        read_ptu_histograms(REAL / name, 100, check_sync_period=False)
    assert "\n" not in str(info.value)


def test_a_real_t2_files_detector_channel_is_no_sync():
    """The real T2 file's only channel read as the sync (--sync-channel 0): its photons
    are no code generator's clock, refused in one line with the share off the period."""
    with pytest.raises(ConfigError, match=r"the events of its channel 0, read as the sync "
                                          r"\(--sync-channel\), are not periodic: \d+ of the "
                                          r"first 4096 intervals") as info:
        read_ptu_histograms(REAL / "libpicoquant_hh_v30_t2.ptu", 100, sync_channel=0,
                            check_sync_period=False)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("name,match", [
    ("libpicoquant_hh_v30_t2.ptu", "holds T2 records (HydraHarp2T2) with no sync record"),
    ("libpicoquant_hh_v20.ht3", "a legacy HydraHarp .ht3 file"),
    ("hazelnut_z1.ptu", "dtime resolution"),  # 96.97 ps bins are not --bit-rate 10e9's
])
def test_reconstruct_refuses_them_in_one_line(tmp_path, capsys, name, match):
    pats = np.random.default_rng(0).integers(0, 2, (8, 4, 4)).astype(np.float32)
    np.save(tmp_path / "p.npy", pats)
    out = tmp_path / "out"
    assert main(["reconstruct", "--ptu", str(REAL / name), "--patterns", str(tmp_path / "p.npy"),
                 "--code", "mseq", "--code-length", "127", "--bit-rate", "10e9",
                 "--range-gate", "1", "2", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0], err
    assert not out.exists()


def _hazelnut_inputs(tmp_path, rows: int) -> list[str]:
    rng = np.random.default_rng(0)
    np.save(tmp_path / "p.npy", rng.integers(0, 2, (rows, 8, 8)).astype(np.float32))
    np.save(tmp_path / "c.npy", rng.integers(0, 2, 132))
    return ["reconstruct", "--ptu", str(REAL / "hazelnut_z1.ptu"), "--patterns",
            str(tmp_path / "p.npy"), "--code", str(tmp_path / "c.npy"), "--bit-rate",
            "10.3125e9", "--range-gate", "0.5", "1.5", "--no-figure", "--out",
            str(tmp_path / "o")]


def test_one_row_short_keeps_the_last_patterns_own_dwell(tmp_path, capsys):
    """1 280 line markers, 1 279 pattern rows: the last row's dwell was recomputed to the
    file's end, through the 1 280th line (twice its own, its histogram halved), and that
    line's 22 photons were in no account (an audit of 2026-11-28)."""
    import json

    assert main(_hazelnut_inputs(tmp_path, 1279)) == 0
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    ref = read_ptu_histograms(REAL / "hazelnut_z1.ptu", 132, n_patterns=1279)
    np.testing.assert_array_equal(m["ptu"]["periods_per_pattern"], ref.periods_per_pattern)
    assert m["ptu"]["n_dropped_after_last_pattern"] == ref.n_dropped_after_last_pattern == 22
    assert any("is a row missing from --patterns" in w for w in m["warnings"])


def test_an_end_marker_block_is_left_out_of_the_solve(tmp_path, capsys):
    """Line-stop markers (2): the 1 280th block holds no photons and lasts one period. It was
    solved as a pattern that saw no light, under a warning that it was 'scaled up'."""
    import json

    assert main([*_hazelnut_inputs(tmp_path, 1280), "--marker", "2"]) == 0
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["ptu"]["n_patterns_solved"] == m["n_patterns"] == 1279
    assert len(m["ptu"]["periods_per_pattern"]) == len(m["ptu"]["counts_per_pattern"]) == 1279
    assert min(m["ptu"]["periods_per_pattern"]) > 1
    assert any("left out of the solve" in w for w in m["warnings"])
    assert not any("scaled up" in w for w in m["warnings"])


def test_a_measured_configuration_holds_only_what_applied(tmp_path, capsys):
    """metrics.json's config of a real file gave the simulation's defaults (scene 'camera',
    signal 5, noise 10, gaussian patterns) as if they had been measured."""
    import json

    assert main(_hazelnut_inputs(tmp_path, 1280)) == 0
    cfg = json.loads((tmp_path / "o" / "metrics.json").read_text())["config"]
    assert cfg["size"] == 8 and cfg["code_length"] == 132 and cfg["range_gate"] == [0.5, 1.5]
    assert cfg["bit_rate"] == 10.3125e9 and cfg["depth"] == "mrf" and cfg["solver"] == "fista"
    for key in ("scene", "signal", "noise", "patterns", "code", "detector", "lidar"):
        assert key not in cfg, key


def test_ptu_info_of_a_t2_file_gives_no_sync_period():
    """A T2 file's global resolution is its time tag's unit, not a sync period (it was given
    as a 1 ps sync period of 0.125 bins); a header's acquisition time of 0 is none."""
    from spslidar.io import ptu_info

    t2 = REAL / "libpicoquant_hh_v30_t2.ptu"
    if not t2.exists():
        pytest.skip("../shared/realdata is absent")
    info = ptu_info(t2)
    assert info["measurement_mode"] == "T2"
    assert info["sync_period_s"] is None and info["bins_per_period"] is None
    assert info["time_unit_s"] == pytest.approx(1e-12)
    hz = REAL / "hazelnut_z1.ptu"
    if hz.exists():
        assert ptu_info(hz)["acquisition_time_s"] is None and ptu_info(hz)["sync_period_s"] > 0


def test_align_channels_on_the_beads_files_two_channels_through_a_tdc_split():
    """The HydraHarp beads file's two channels (16 ps TDC bins, split between 200 ps bits
    under --allow-binning, where no channel's histogram is kept): --align-channels said they
    were one channel's photons; it says why their delays are not read."""
    from spslidar.pipeline.blocks import read_blocks

    _, notes = read_blocks(REAL / "tttrlib_MT200_HH400_beads.ptu", 50, 125, bin_width=2e-10,
                           marker=3, allow_binning=True, align_channels=True)
    said = [n for n in notes if n.startswith("--align-channels")]
    assert len(said) == 1 and "channels 0, 1 are read, but their delays are not read" in said[0]


def test_a_fluorescence_file_read_as_a_calibration_is_said_to_be_no_flat_target(tmp_path):
    """The hazelnut FLIM scan through a one-pulse 132-bit code (its sync period at
    10.3125 GHz) was written as a calibration with only its width warned of: its decay still
    stands 40 bins after the peak, past a quarter of the period, which is said now (an
    outside audit of a lab's real files)."""
    from spslidar.pipeline.calibration import calibrate_ptu

    code = np.zeros(132, np.uint8)
    code[0] = 1
    pats = (np.random.default_rng(0).random((1280, 16, 16)) < 0.5).astype(np.uint8)
    with pytest.warns(RuntimeWarning) as said:
        calibrate_ptu(REAL / "hazelnut_z1.ptu", pats, code, 1.03125e10, 1.0, marker=1)
    assert any("still stands above the background 40 bins after its peak" in str(w.message)
               and "a flat target's response is narrower" in str(w.message) for w in said)
