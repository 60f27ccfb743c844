"""``spslidar inspect`` and :func:`spslidar.io.ptu_scan.scan_ptu`: what a PTU file holds,
counted against files whose content is known (written here, or the real files' README table,
decoded independently), and the options it says ``reconstruct`` needs."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.errors import ConfigError
from spslidar.io import scan_ptu, write_acquisition_ptu

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "realdata"
L, BW = 127, 100e-12  # code bits, seconds per bit


@pytest.fixture(scope="module")
def acquisition(tmp_path_factory):
    """12 patterns on marker input 2, dwells of 40-400 code periods, 3-300 photons each on
    channel 0; the events as written."""
    d = tmp_path_factory.mktemp("inspect")
    rng = np.random.default_rng(7)
    dwell = rng.integers(40, 400, 12)
    events = []
    for p in range(12):
        m = int(rng.integers(3, 300))
        ev = np.column_stack([rng.integers(0, dwell[p], m), rng.integers(0, L, m)])
        events.append(ev[np.argsort(ev[:, 0], kind="stable")])
    write_acquisition_ptu(d / "a.ptu", events, L, BW, periods_per_pattern=dwell, marker=2)
    return d / "a.ptu", events, dwell


def test_counts_equal_what_was_written(acquisition):
    path, events, dwell = acquisition
    got = scan_ptu(path)
    counts = np.array([len(e) for e in events])
    assert got["mode"] == "T3"
    assert got["photons"] == {0: int(counts.sum())}
    assert got["markers"][2] == 12
    b = got["blocks"][2]
    # the blocks between consecutive markers are patterns 0..10: their dwells and photons
    period = L * BW
    assert b["dwell_s"]["median"] == pytest.approx(np.median(dwell[:-1]) * period, rel=1e-9)
    assert b["dwell_s"]["min"] == pytest.approx(dwell[:-1].min() * period, rel=1e-9)
    assert b["photons_per_block"] == {"median": float(np.median(counts[:-1])),
                                      "min": float(counts[:-1].min()),
                                      "max": float(counts[:-1].max())}
    assert b["photons_before_first"] == 0 and b["photons_after_last"] == counts[-1]
    assert b["empty_blocks"] == 0
    assert got["dtime_max"] == max(int(e[:, 1].max()) for e in events)
    assert got["header"]["record_type"] == "HydraHarp2T3"


def test_nothing_depends_on_the_chunk_size(acquisition):
    path = acquisition[0]
    a, b = scan_ptu(path, chunk_records=97), scan_ptu(path)
    np.testing.assert_array_equal(a.pop("dtime_counts"), b.pop("dtime_counts"))
    assert a == b


@pytest.mark.skipif(not REAL.is_dir(), reason="../shared/realdata is absent")
@pytest.mark.parametrize("name,photons,markers", [
    ("hazelnut_z1.ptu", {0: 150363}, {1: 1280, 2: 1280, 3: 5}),
    ("tttrlib_MT200_HH400_beads.ptu", {0: 52833, 1: 20954}, {3: 50, 4: 50}),
    ("feda_H2O_300s.ptu", {0: 45652, 1: 22988, 2: 77582, 3: 23161}, {}),
    ("libpicoquant_hh_v30_t2.ptu", {0: 305565}, {}),
])
def test_real_files_counts_equal_their_readme(name, photons, markers):
    """The counts of ``../shared/realdata/README.md``, which an independent decoder wrote."""
    got = scan_ptu(REAL / name, chunk_records=4099)
    assert got["photons"] == photons and got["markers"] == markers


@pytest.mark.skipif(not REAL.is_dir(), reason="../shared/realdata is absent")
def test_real_files_what_reconstruct_is_told(capsys):
    """The beads file's two marker inputs (line start and stop) are named as a start and an
    end; the hazelnut's 132-bit code is the one its sync period fits; a T2 file without
    syncs is told it needs them."""
    assert main(["inspect", str(REAL / "tttrlib_MT200_HH400_beads.ptu"),
                 str(REAL / "hazelnut_z1.ptu"), str(REAL / "libpicoquant_hh_v30_t2.ptu")]) == 0
    out = capsys.readouterr().out
    assert "--marker 3, or --marker 4 --marker-edge end" in out
    assert "a 132-bit code fits it" in out
    assert "no sync records: reconstruct reads a T2 file from the code's sync" in out
    assert "photons per --channel (from 0): 0: 52 833" in out


def test_cli_text_and_json(acquisition, capsys):
    path = str(acquisition[0])
    assert main(["inspect", path]) == 0
    out = capsys.readouterr().out
    assert "--marker 2: 12 markers" in out and "--bit-rate 1e+10" in out
    assert "a 127-bit code fits it" in out
    assert main(["inspect", "--json", path]) == 0
    (got,) = json.loads(capsys.readouterr().out)
    assert got["path"] == path and got["markers"]["2"] == 12
    assert got["photons"] == {"0": sum(len(e) for e in acquisition[1])}


def test_bad_files_are_one_line_and_nothing_is_printed_before(acquisition, tmp_path, capsys):
    bad = tmp_path / "notes.ptu"
    bad.write_text("not a PTU file\n")
    for argv in (["inspect", str(acquisition[0]), str(bad)],
                 ["inspect", str(tmp_path / "missing.ptu")]):
        assert main(argv) == 2
        cap = capsys.readouterr()
        assert cap.out == ""
        assert cap.err.count("\n") == 1 and cap.err.startswith("spslidar inspect: error:")
    with pytest.raises(ConfigError, match="chunk_records"):
        scan_ptu(acquisition[0], chunk_records=0)


# -- T2 ---------------------------------------------------------------------------------------

def _t2_file(path: Path, t: np.ndarray, kind: np.ndarray, value: np.ndarray) -> None:
    """A HydraHarp T2 (v2) file of events at tags ``t`` (< 2^25, 1 ps each: no overflow);
    ``kind`` 0 photon on channel ``value``, 1 sync, 2 marker bits ``value``."""
    word = np.where(kind == 0, (value << 25) | t,
                    (1 << 31) | (np.where(kind == 1, 0, value) << 25) | t).astype("<u4")
    tags = [("Measurement_Mode", 0x10000008, 2), ("MeasDesc_Resolution", 0x20000008, 1e-12),
            ("MeasDesc_GlobalResolution", 0x20000008, 1e-12),
            ("TTResult_NumberOfRecords", 0x10000008, word.size),
            ("TTResultFormat_TTTRRecType", 0x10000008, 0x01010204),
            ("TTResultFormat_BitsPerRecord", 0x10000008, 32), ("Header_End", 0xFFFF0008, 0)]
    head = [b"PQTTTR\0\0", b"1.0.00\0\0"] + [
        struct.pack("<32siId" if typ == 0x20000008 else "<32siIq", n.encode(), -1, typ, v)
        for n, typ, v in tags]
    path.write_bytes(b"".join(head) + word.tobytes())


def test_t2_sync_on_a_detector_input_is_named(tmp_path, capsys):
    """No sync record, and channel 3's events every 12 700 tags: the sync recorded on a
    detector input, named with the option that reads it."""
    rng = np.random.default_rng(3)
    sync = np.arange(2000) * 12700 + 50
    phot = np.sort(rng.integers(0, int(sync[-1]), 3000))
    t = np.concatenate([sync, phot, [60, 12760]])
    kind = np.concatenate([np.zeros(sync.size + phot.size, int), [2, 2]])
    value = np.concatenate([np.full(sync.size, 3), np.zeros(phot.size, int), [1, 1]])
    order = np.argsort(t, kind="stable")
    _t2_file(tmp_path / "s.ptu", t[order], kind[order], value[order])
    got = scan_ptu(tmp_path / "s.ptu")
    assert got["mode"] == "T2" and got["sync_records"] == 0
    assert got["photons"] == {0: 3000, 3: 2000} and got["markers"] == {1: 2}
    assert got["periodic_channel"]["channel"] == 3
    assert got["periodic_channel"]["period_s"] == pytest.approx(12.7e-9, rel=1e-6)
    assert main(["inspect", str(tmp_path / "s.ptu")]) == 0
    assert "--sync-channel 3" in capsys.readouterr().out


def test_t2_sync_records_and_their_period(tmp_path):
    sync = np.arange(500) * 25000 + 7
    t = np.concatenate([sync, sync[::50] + 3])
    kind = np.concatenate([np.ones(sync.size, int), np.zeros(10, int)])
    order = np.argsort(t, kind="stable")
    _t2_file(tmp_path / "y.ptu", t[order], kind[order], np.zeros(t.size, int)[order])
    got = scan_ptu(tmp_path / "y.ptu")
    assert got["sync_records"] == 500 and got["photons"] == {0: 10}
    assert got["sync_period_s"] == pytest.approx(25e-9, rel=1e-9)
    assert got["span_s"] == pytest.approx(499 * 25e-9, rel=1e-9)


# -- count rate and dead time -----------------------------------------------------------------

def _photons(rate: float, n_periods: int, dead: float, seed: int) -> list[np.ndarray]:
    """A pattern of ``n_periods`` code periods at ``rate`` photons per period, uniform over
    the bins, each detection ``dead`` seconds dead after it (non-paralysable: a photon within
    that time of the last one kept is dropped); no two photons in one bin."""
    rng = np.random.default_rng(seed)
    sync = np.repeat(np.arange(n_periods), rng.poisson(rate, n_periods))
    dt = rng.integers(0, L, sync.size)
    t = np.unique(sync * L + dt)
    keep = np.zeros(t.size, bool)
    last = -np.inf
    for i, ti in enumerate(t * BW):  # (the dead time's own rule: a loop over the photons)
        if ti - last >= dead:
            keep[i], last = True, ti
    return [np.column_stack(np.divmod(t[keep], L))]


def test_a_dead_time_and_pile_up_are_said(tmp_path, capsys):
    """A detector at 0.3 photons per code period (24 M/s) that goes dead for 40 ns after each
    detection: the shortest gap is the dead time, and the rate says pile-up matters. Without
    a dead time, at 0.03 photons per period, its shortest gap is no dead time, and a
    100 ns dead time would still lose 19 % to pile-up."""
    write_acquisition_ptu(tmp_path / "dead.ptu", _photons(0.3, 40000, 40e-9, 11), L, BW,
                          periods_per_pattern=40000)
    write_acquisition_ptu(tmp_path / "free.ptu", _photons(0.03, 40000, 0.0, 12), L, BW,
                          periods_per_pattern=40000)
    dead = scan_ptu(tmp_path / "dead.ptu")
    assert 40e-9 - 1e-15 <= dead["gaps"][0]["shortest_s"] < 41e-9
    assert main(["inspect", str(tmp_path / "dead.ptu")]) == 0
    out = capsys.readouterr().out
    assert "channel 0: no two detections closer than 40" in out
    assert "to pile-up: give its --dead-time" in out
    free = scan_ptu(tmp_path / "free.ptu")
    assert 0 < free["gaps"][0]["shortest_s"] < 2e-9
    assert main(["inspect", str(tmp_path / "free.ptu")]) == 0
    out = capsys.readouterr().out
    assert "no two detections closer" not in out and "loses 18 % of them to pile-up" in out


def test_empty_and_irregular_blocks_are_counted(tmp_path, capsys):
    """Ten patterns of 100 code periods but one of 250 (a marker missed) and one of 30 (a
    bounce), and one without photons: each counted and said."""
    rng = np.random.default_rng(5)
    dwell = np.array([100, 100, 250, 100, 30, 100, 100, 100, 100, 100])
    events = [np.column_stack([np.sort(rng.integers(0, d, 50)), rng.integers(0, L, 50)])
              for d in dwell]
    events[6] = np.zeros((0, 2), np.int64)
    write_acquisition_ptu(tmp_path / "b.ptu", events, L, BW, periods_per_pattern=dwell)
    b = scan_ptu(tmp_path / "b.ptu")["blocks"][1]
    assert b["markers"] == 10 and b["empty_blocks"] == 1 and b["irregular_blocks"] == 2
    assert b["dwell_s"]["max"] == pytest.approx(250 * L * BW, rel=1e-9)
    assert main(["inspect", str(tmp_path / "b.ptu")]) == 0
    out = capsys.readouterr().out
    assert "1 empty; 2 over 1.5 times the median length or under its two thirds" in out


@pytest.mark.parametrize("m,said", [
    (12, "cuts 12 blocks: one per pattern"), (6, "cuts 12 blocks: --repeats 2"),
    (4, "--repeats 3"), (11, "one per pattern and one more (an arming or end"),
    (5, "--repeats 2, and two more"), (7, "no whole number of sequences"),
    (20, "fewer blocks than patterns"),
])
def test_blocks_against_the_patterns(acquisition, tmp_path, capsys, m, said):
    np.save(tmp_path / "p.npy", np.zeros((m, 4, 4)))
    assert main(["inspect", str(acquisition[0]), "--patterns", str(tmp_path / "p.npy")]) == 0
    out = capsys.readouterr().out
    assert f"--patterns holds {m} patterns and --marker 2 cuts 12 blocks" in out and said in out


# -- where the returns are --------------------------------------------------------------------

def _psst_file(path: Path, code: np.ndarray, lags: list[int], k: int = 1, seed: int = 0,
               signal: int = 3000, background: int = 3000) -> None:
    """8 blocks of a PSST acquisition: ``signal`` photons per block at each of ``lags`` (bits),
    each in a bit where the code delayed by the lag is 1, and ``background`` uniform ones;
    TDC bins of 1/``k`` bit."""
    rng = np.random.default_rng(seed)
    on = np.flatnonzero(code)
    events = []
    for _ in range(8):
        bits = np.concatenate([(rng.choice(on, signal) + d) % code.size for d in lags]
                              + [rng.integers(0, code.size, background)])
        dt = bits * k + rng.integers(0, k, bits.size)
        events.append(np.column_stack([np.sort(rng.integers(0, 200, dt.size)), dt]))
    write_acquisition_ptu(path, events, code.size * k, BW / k, periods_per_pattern=200)


@pytest.mark.parametrize("k", [1, 4])
def test_the_returns_delays_and_a_gate_around_them(tmp_path, k):
    """Two returns at bits 40 and 90 of a 127-bit m-sequence (one TDC bin a bit, or four):
    both found at their bits, the gate holding both and little more."""
    from spslidar.cli_inspect import GATE_MARGIN_BINS, returns_in_file
    from spslidar.codes.sequences import make_code

    code = make_code("mseq", L)
    _psst_file(tmp_path / "r.ptu", code, [40, 90], k)
    found = returns_in_file(scan_ptu(tmp_path / "r.ptu"), code, 1 / BW)
    metre = 299_792_458.0 * BW / 2
    assert found["ok"] and sorted(p["lag"] for p in found["peaks"]) == [40, 90]
    assert min(p["sigmas"] for p in found["peaks"]) > 20
    lo, hi = found["gate_m"]
    assert lo == pytest.approx((40 - GATE_MARGIN_BINS) * metre, abs=1e-9)
    assert hi == pytest.approx((90 + GATE_MARGIN_BINS) * metre, abs=1e-9)
    assert found["unambiguous_m"] == pytest.approx(L * metre)


def test_returns_refused_where_they_cannot_be_read(tmp_path, capsys):
    """A bit rate whose bit is no whole number of TDC bins, a code period the sync's is not,
    and --code without --bit-rate. (Another code of the same length is not told apart: a
    strong return correlated with it stands out too, 27 standard deviations here.)"""
    from spslidar.cli_inspect import returns_in_file
    from spslidar.codes.sequences import make_code

    code = make_code("mseq", L)
    _psst_file(tmp_path / "r.ptu", code, [40])
    scan = scan_ptu(tmp_path / "r.ptu")
    assert "no whole fraction" in returns_in_file(scan, code, 1 / (2.5 * BW))["why"]
    assert "is not 255 bits" in returns_in_file(scan, make_code("mseq", 255), 1 / BW)["why"]
    np.save(tmp_path / "c.npy", code)
    assert main(["inspect", str(tmp_path / "r.ptu"), "--code", str(tmp_path / "c.npy")]) == 2
    assert "--code and --bit-rate go together" in capsys.readouterr().err
    assert main(["inspect", str(tmp_path / "r.ptu"), "--code", str(tmp_path / "c.npy"),
                 "--bit-rate", "10e9"]) == 0
    assert "returns (the photons of every block, correlated with the code): 0.5996 m (" in (
        capsys.readouterr().out)
    assert main(["inspect", str(tmp_path / "r.ptu"), "--code", "mseq", "--code-length", "127",
                 "--bit-rate", "10e9", "--json"]) == 0
    (got,) = json.loads(capsys.readouterr().out)
    assert got["returns"]["peaks"][0]["lag"] == 40 and "dtime_counts" not in got
