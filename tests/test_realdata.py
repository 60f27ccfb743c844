"""The PTU reader on files nobody here wrote (issue 20, items 5 and 7): real PicoQuant
recordings from public repositories in ``../shared/realdata/`` (never copied into the
project; skipped where the folder is absent). Per-block photon counts and histograms must
equal an independent decoder written here from PicoQuant's published record layouts; the
files the reader cannot use are refused in one line.

Record layouts (32-bit little-endian):

* PicoHarp T3: bits 0-15 nsync, 16-27 dtime, 28-31 channel; channel 15 is special: dtime 0 an
  overflow (+65536 syncs), else a marker bit mask in dtime's low 4 bits; photon channels 1-4
  are 0-3 in the file's 0-based numbering.
* HydraHarp T3 v2: bits 0-9 nsync, 10-24 dtime, 25-30 channel, 31 special; special channel 63
  is an overflow of ``nsync`` (``1024 * max(nsync, 1)`` syncs), special channels 1-15 marker
  bit masks; photon channels are 0-based.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from spslidar.errors import ConfigError
from spslidar.io import read_ptu_histograms

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "realdata"
pytestmark = pytest.mark.skipif(not REAL.is_dir(), reason="../shared/realdata is absent")

_AnsiString, _WideString, _Blob = 0x4001FFFF, 0x4002FFFF, 0xFFFFFFFF


def _header(path: Path) -> tuple[dict, int]:
    """The tags of a PTU header and the byte offset of its first record."""
    data = path.read_bytes()
    assert data[:6] == b"PQTTTR"
    pos, tags = 16, {}
    while True:
        # a tag: 32-byte ident, int32 index, uint32 type, then an 8-byte value (a length for
        # strings and blobs, whose bytes follow)
        ident, _idx, typ = struct.unpack_from("<32siI", data, pos)
        name = ident.split(b"\0")[0].decode()
        value = struct.unpack_from("<d" if typ == 0x20000008 else "<q", data, pos + 40)[0]
        pos += 48
        if typ in (_AnsiString, _WideString, _Blob):
            pos += int(value)
            value = None
        tags[name] = value
        if name == "Header_End":
            return tags, pos


def _decode(path: Path):
    """(absolute sync, dtime, channel, marker mask) per record, photons and markers only."""
    tags, offset = _header(path)
    rec = np.frombuffer(path.read_bytes()[offset:], "<u4").astype(np.int64)
    rtype = tags["TTResultFormat_TTTRRecType"]
    if rtype == 0x00010303:  # PicoHarp T3
        nsync, dtime, chan = rec & 0xFFFF, (rec >> 16) & 0xFFF, rec >> 28
        special = chan == 15
        ofl = special & (dtime == 0)
        wraps = np.where(ofl, 65536, 0)
        mark = np.where(special & ~ofl, dtime & 0xF, 0)
        photon_ch = chan - 1
    elif rtype in (0x01010304, 0x01010204):  # HydraHarp / TimeHarp260 T3 v2
        nsync, dtime, chan = rec & 0x3FF, (rec >> 10) & 0x7FFF, (rec >> 25) & 0x3F
        special = (rec >> 31) == 1
        ofl = special & (chan == 63)
        wraps = np.where(ofl, 1024 * np.maximum(nsync, 1), 0)
        mark = np.where(special & ~ofl & (chan >= 1) & (chan <= 15), chan, 0)
        photon_ch = chan
    else:
        raise ValueError(f"not a T3 record type: {rtype:#x}")
    base = np.cumsum(wraps) - wraps  # overflows before each record
    sync = base + nsync
    keep = ~ofl
    return sync[keep], dtime[keep], np.where(special, -1, photon_ch)[keep], mark[keep]


def _reference(path: Path, n_bins: int, marker: int, binning: int = 1):
    """Per-block photon histograms: block k = photons after marker k (on input ``marker``)."""
    _sync, dtime, ch, mark = _decode(path)
    is_mark = (mark & (1 << (marker - 1))) != 0
    block = np.cumsum(is_mark) - 1
    photon = (ch >= 0) & (block >= 0)
    bins = dtime[photon] // binning
    ok = bins < n_bins
    n_blocks = int(is_mark.sum())
    hist = np.zeros((n_blocks, n_bins), np.int64)
    np.add.at(hist, (block[photon][ok], bins[ok]), 1)
    return hist


@pytest.mark.parametrize("name,n_bins,marker", [
    ("hazelnut_z1.ptu", 132, 1),        # PicoHarp T3, line-start markers
    ("hazelnut_z1.ptu", 132, 2),        # line stops: every line's tail is an empty block
    ("tttrlib_MT200_HH400_beads.ptu", 1562, 3),  # HydraHarp T3 v2
])
def test_blocks_equal_an_independent_decoder(name, n_bins, marker):
    path = REAL / name
    ref = _reference(path, n_bins, marker)
    for chunk in (2**22, 997):  # the row count must not depend on the chunk size
        got = read_ptu_histograms(path, n_bins, marker=marker, chunk_records=chunk,
                                  check_sync_period=False)
        assert got.histograms.shape == ref.shape
        np.testing.assert_array_equal(got.counts_per_pattern, ref.sum(axis=1))
        np.testing.assert_array_equal(got.histograms, ref)


def test_readme_counts_of_the_files():
    """The decoded counts the folder's README gives (photons per channel, markers)."""
    _s, _d, ch, mark = _decode(REAL / "hazelnut_z1.ptu")
    assert int((ch == 0).sum()) == 150_363
    assert [int(((mark >> b) & 1).sum()) for b in range(3)] == [1280, 1280, 5]
    _s, _d, ch, mark = _decode(REAL / "tttrlib_MT200_HH400_beads.ptu")
    assert (int((ch == 0).sum()), int((ch == 1).sum())) == (52_833, 20_954)


def test_channel_selection_and_a_channel_without_photons():
    path = REAL / "tttrlib_MT200_HH400_beads.ptu"
    one = read_ptu_histograms(path, 1562, marker=3, channel=1, check_sync_period=False)
    _s, _d, ch, mark = _decode(path)
    block = np.cumsum((mark & 4) != 0) - 1
    assert int(one.counts_per_pattern.sum()) == int(((ch == 1) & (block >= 0)
                                                    & (_d < 1562)).sum())
    with pytest.raises(ConfigError, match="no photons on channel 7"):
        read_ptu_histograms(path, 1562, marker=3, channel=7, check_sync_period=False)


@pytest.mark.parametrize("name,match", [
    ("feda_H2O_300s.ptu", "no marker"),
    ("libpicoquant_hh_v30_t2.ptu", "T2"),
    ("libpicoquant_hh_v20.ht3", "not a readable PicoQuant PTU"),
    ("README.md", "not a readable PicoQuant PTU"),
])
def test_refusals_are_one_line(name, match):
    with pytest.raises(ConfigError, match=match) as info:
        read_ptu_histograms(REAL / name, 100, check_sync_period=False)
    assert "\n" not in str(info.value)
