"""Two detector channels behind cables of different lengths (``spslidar.pipeline.skew``): the
reader gives each channel's photons over the period, the delay between them is read from
their cross-correlation, said, and taken out by ``channel_shifts`` / ``--align-channels``
exactly: the aligned file's histograms are those of the same photons on one channel."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.codes import make_code
from spslidar.errors import ConfigError
from spslidar.io import read_ptu_histograms
from spslidar.io.ptu_write import write_ptu_t3
from spslidar.pipeline.skew import (
    MIN_PHOTONS,
    align_note,
    channel_delays,
    channel_shifts,
    describe,
    skew_note,
)

L, N, M, PERIODS, BW = 127, 8, 48, 200, 1e-10


def _photons(seed: int = 0, signal: float = 0.02):
    """A two-plane 8x8 scene (4.0 / 4.3 m) through 48 binary patterns of a 127-bit
    m-sequence: each pattern's photons as (period, bin), and the patterns and code."""
    rng = np.random.default_rng(seed)
    code = make_code("mseq", L, 0.5).astype(np.float64)
    depth = np.full((N, N), 4.0)
    depth[:, N // 2:] = 4.3
    delay = np.round(depth / (299792458.0 * BW / 2)).astype(int).ravel()
    pats = (rng.random((M, N, N)) < 0.5).astype(np.float32)
    flat = pats.reshape(M, -1).astype(np.float64)
    lam = np.zeros((M, L))
    for j, d in enumerate(delay):
        lam += signal * flat[:, j: j + 1] * np.roll(code, d)[None]
    counts = rng.poisson((lam + 0.01) * PERIODS)
    events = []
    for k in range(M):
        bins = np.repeat(np.arange(L), counts[k])
        events.append((rng.integers(0, PERIODS, bins.size), bins))
    return events, pats, code.astype(np.uint8), depth


def _write(path, events, shift: int = 0, split: bool = True, seed: int = 1,
           first: int = 0, monitor: float = 0.0) -> None:
    """The photons as a T3 file, a marker per pattern; with ``split`` each photon on channel
    0 or 1 at random (from pattern ``first`` on), channel 1's ``shift`` bins later around
    the period (its cable)."""
    rng = np.random.default_rng(seed)
    ns, dt, ch, mk = [], [], [], []
    code = make_code("mseq", L, 0.5).astype(bool)
    for k, (period, bins) in enumerate(events):
        if monitor:  # (a laser monitor on channel 2: the code, alike in every pattern)
            extra = rng.poisson(monitor * PERIODS * code / code.sum())
            mon = np.repeat(np.arange(L), extra)
            period = np.concatenate([period, rng.integers(0, PERIODS, mon.size)])
            bins = np.concatenate([bins, mon])
            tag = np.concatenate([np.zeros(bins.size - mon.size, bool), np.ones(mon.size, bool)])
        else:
            tag = np.zeros(bins.size, bool)
        order = np.argsort(period, kind="stable")
        c = (rng.random(bins.size) < 0.45).astype(np.int64) if split and k >= first else \
            np.zeros(bins.size, np.int64)
        c[tag] = 2
        ns += [[k * PERIODS], k * PERIODS + period[order]]
        dt += [[0], ((bins + shift * c) % L)[order]]
        ch += [[0], c[order]]
        mk += [[1], np.zeros(bins.size, np.int64)]
    write_ptu_t3(path, nsync=np.concatenate(ns), dtime=np.concatenate(dt),
                 channel=np.concatenate(ch), marker=np.concatenate(mk), resolution_s=BW,
                 sync_rate_hz=1 / (L * BW))


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("skew")
    events, pats, code, depth = _photons()
    _write(d / "one.ptu", events, split=False)
    _write(d / "skew.ptu", events, shift=23)
    _write(d / "even.ptu", events, shift=0)
    _write(d / "late.ptu", events, shift=23, first=30)
    scene = sum(b.size for _, b in events) / len(events) / PERIODS  # (photons a period)
    _write(d / "monitor.ptu", events, split=False, monitor=2.5 * scene)
    np.save(d / "patterns.npy", pats)
    np.save(d / "code.npy", code)
    np.save(d / "truth.npy", depth)
    return d


def test_the_delay_between_channels_is_read_and_taken_out_exactly(files):
    """Channel 1, 23 bins late, reads +23 bins (to a tenth of a bin) against channel 0; moved
    back by the reader, the two channels' histograms sum to the one-channel file's, bin for
    bin; a file without a delay reads 0."""
    one = read_ptu_histograms(files / "one.ptu", L, bin_width=BW)
    assert one.channel_histograms == {}  # (one channel: nothing to compare)
    skew = read_ptu_histograms(files / "skew.ptu", L, bin_width=BW)
    assert sorted(skew.channel_histograms) == [0, 1]
    np.testing.assert_array_equal(sum(skew.channel_histograms.values()),
                                  skew.histograms.sum(axis=0))
    delays = channel_delays(skew.channel_histograms)
    assert delays[0] == 0.0 and delays[1] == pytest.approx(23.0, abs=0.1)
    assert channel_shifts(delays) == {1: 23}
    moved = read_ptu_histograms(files / "skew.ptu", L, bin_width=BW, channel_shifts={1: 23})
    np.testing.assert_array_equal(moved.histograms, one.histograms)
    assert moved.channel_shifts == {1: 23}
    even = channel_delays(read_ptu_histograms(files / "even.ptu", L, bin_width=BW)
                          .channel_histograms)
    assert abs(even[1]) < 0.2 and channel_shifts(even) == {}
    # a second channel that comes in a later chunk: the first's photons before it counted
    spreads = []
    for chunk in (2**20, 500, 37):
        late = read_ptu_histograms(files / "late.ptu", L, bin_width=BW, chunk_records=chunk)
        spreads.append(late.channel_spread)  # (each block's photons by channel, alike)
        np.testing.assert_array_equal(sum(late.channel_histograms.values()),
                                      late.histograms.sum(axis=0))
        assert late.channel_histograms[1].sum() < late.channel_histograms[0].sum()
        np.testing.assert_array_equal(read_ptu_histograms(
            files / "late.ptu", L, bin_width=BW, chunk_records=chunk,
            channel_shifts={1: 23}).histograms, one.histograms)
    assert spreads[1] == spreads[0] and spreads[2] == spreads[0]
    # a shift of a whole period either way is none; one channel alone is read as it is
    np.testing.assert_array_equal(read_ptu_histograms(
        files / "skew.ptu", L, bin_width=BW, channel_shifts={1: 23 - 2 * L}).histograms,
        one.histograms)


def test_delays_are_read_only_where_the_data_hold_them():
    """A channel of too few photons, or of noise without the code's structure, gets no
    delay; a delay of half a period reads within half a period either way; the sub-bin
    part comes from the parabola."""
    rng = np.random.default_rng(3)
    base = np.roll(np.repeat(make_code("mseq", 255, 0.5).astype(float), 4), 9) * 50 + 20
    smooth = np.convolve(np.tile(base, 3), np.ones(4) / 4, "same")[base.size: 2 * base.size]
    late = np.interp(np.arange(base.size) - 7.5, np.arange(-base.size, 2 * base.size),
                     np.tile(smooth, 3))
    hists = {0: rng.poisson(smooth), 2: rng.poisson(late), 5: rng.poisson(np.full(base.size, 40)),
             7: rng.poisson(smooth * (MIN_PHOTONS / 2) / smooth.sum())}
    delays = channel_delays(hists)
    assert set(delays) == {0, 2}
    assert delays[2] == pytest.approx(7.5, abs=0.25)
    back = channel_delays({0: hists[0], 1: rng.poisson(np.roll(smooth, -base.size // 2 + 3))})
    assert back[1] == pytest.approx(-base.size // 2 + 3, abs=0.25)
    assert channel_delays({0: hists[0]}) == {}
    # where no channel's rate follows the patterns (two detectors at their dead-time limit
    # count more evenly than Poisson: spreads 0.6-0.8), every channel is read; both were
    # taken for monitors, their skew neither said nor aligned (an outside audit of stop 68)
    even = {0: 0.7, 2: 0.6}
    assert channel_delays({0: hists[0], 2: hists[2]}, even)[2] == pytest.approx(7.5, abs=0.25)
    assert set(channel_delays({0: hists[0], 2: hists[2]}, {0: 30.0, 2: 0.6})) == set()
    note = skew_note({0: 0.0, 2: 7.5}, BW, spread=even)
    assert "a laser monitor cannot be told from a detector here" in note
    assert "cannot be told" not in skew_note({0: 0.0, 2: 7.5}, BW, spread={0: 30.0, 2: 20.0})
    assert channel_delays({0: hists[7], 1: hists[7]}) == {}  # (too few photons in any)


def test_the_skew_is_said_with_what_to_do():
    note = skew_note({0: 0.0, 1: 23.04}, BW)
    assert "channel 1 +23.0 bins (+2.3 ns, +0.345 m)" in note and "--align-channels" in note
    assert "\n" not in note
    assert skew_note({0: 0.0, 1: 0.6}, BW) is None  # (a merged return a bin wider)
    assert "channel 1 +1.2 bins" in skew_note({0: 0.0, 1: 1.21}, BW)  # (an audit's 1.4 bins)
    assert "cables changed since the calibration" in skew_note({0: 0.0, 1: 23.0}, BW, after=True)
    assert skew_note({0: 0.0}, BW) is None
    assert describe({0: 0.0, 1: 23.04}, {1: 23}, {0: 30.0, 1: 20.0}) == {
        "delays_bins": {"0": 0.0, "1": 23.04}, "shifts_bins": {"1": 23},
        "rate_spread": {"0": 30.0, "1": 20.0}}
    assert describe({}, {}) is None


def test_what_align_channels_could_not_do_is_said():
    """--align-channels on one channel's photons, beside a monitor, or on a channel whose
    delay could not be read did nothing without a word (an outside audit of stop 67)."""
    h = np.ones(8)
    assert "are one detector channel's (one --channel is read, or the file has one)" in (
        align_note({}, {}, {}))
    assert "one detector channel's (0)" in align_note({0: h, 3: 0 * h}, None, {})  # (empty 3)
    monitor = align_note({0: h, 1: h}, {0: 30.0, 1: 1.0}, {})
    assert "only channel 0 of 0, 1 follows the patterns" in monitor and "monitor's" in monitor
    lost = align_note({0: h, 2: h, 7: h}, None, {0: 0.0, 2: 7.5})
    assert "the delay of channel(s) 7 could not be read" in lost and "\n" not in lost
    assert align_note({0: h, 2: h}, {0: 30.0, 2: 20.0}, {0: 0.0, 2: 7.5}) is None
    # two channels read through a TDC bin split, where no channel's histogram is kept (a
    # HydraHarp file's two channels were said to be one: found on a real file, 2026-11-30)
    split = align_note({}, {}, {}, [0, 1])
    assert "channels 0, 1 are read, but their delays are not read through a TDC bin" in split
    assert "one detector channel's" in align_note({}, {}, {}, [0])
    assert align_note({0: h, 2: h}, {0: 0.7, 2: 0.6}, {0: 0.0, 2: 7.5}) is None  # (both read)


def test_shifts_the_reader_refuses(files):
    for bad in ({1: 2.5}, {1: True}, {"a": 1}, {-1: 2}, {128: 1}):
        with pytest.raises(ConfigError, match="channel_shifts must map channel numbers"):
            read_ptu_histograms(files / "skew.ptu", L, bin_width=BW, channel_shifts=bad)
    with pytest.raises(ConfigError, match="cannot be aligned through a TDC bin split"):
        read_ptu_histograms(files / "skew.ptu", L - 20, bin_width=BW * L / (L - 20),
                            allow_binning=True, channel_shifts={1: 3})


def _run(files, ptu, out, *extra):
    from spslidar.cli import main

    return main(["reconstruct", "--ptu", str(files / ptu), "--patterns",
                 str(files / "patterns.npy"), "--code", str(files / "code.npy"),
                 "--bit-rate", "10e9", "--range-gate", "3.5", "4.8", "--no-figure",
                 "--out", str(files / out), *extra])


def _run_two(files, out):
    """reconstruct of the skewed file and the one-channel file as two passes."""
    from spslidar.cli import main

    return main(["reconstruct", "--ptu", str(files / "skew.ptu"), str(files / "one.ptu"),
                 "--patterns", str(files / "patterns.npy"), "--code", str(files / "code.npy"),
                 "--bit-rate", "10e9", "--range-gate", "3.5", "4.8", "--no-figure",
                 "--out", str(files / out)])


def test_reconstruct_says_the_skew_and_aligns_with_the_option(files, capsys):
    """Merged as recorded, channel 1's 23 bins read as a second surface 0.34 m behind, and
    the warning says so with the option; --align-channels gives the one-channel file's map
    exactly and records the shift; --channel 0 alone needs neither."""
    import json

    assert _run(files, "one.ptu", "r_one") == 0
    one = np.load(files / "r_one" / "depth.npy")
    capsys.readouterr()
    assert _run(files, "skew.ptu", "r_skew") == 0
    err = capsys.readouterr().err
    assert "channel 1 +23.0 bins (+2.3 ns, +0.345 m)" in err and "--align-channels" in err
    assert _run(files, "skew.ptu", "r_aligned", "--align-channels") == 0
    err = capsys.readouterr().err
    assert "do not arrive together" not in err
    np.testing.assert_array_equal(np.load(files / "r_aligned" / "depth.npy"), one)
    record = json.loads((files / "r_aligned" / "metrics.json").read_text())["ptu"]["channels"]
    assert record["shifts_bins"] == {"1": 23} and abs(record["delays_bins"]["1"]) < 0.2
    merged = json.loads((files / "r_skew" / "metrics.json").read_text())["ptu"]["channels"]
    assert merged["shifts_bins"] == {} and merged["delays_bins"]["1"] == pytest.approx(23, abs=.1)
    assert "--align-channels:" not in err
    assert _run(files, "one.ptu", "r_one2", "--align-channels") == 0  # (one channel: as is)
    assert "--align-channels: the photons read are one detector" in capsys.readouterr().err
    np.testing.assert_array_equal(np.load(files / "r_one2" / "depth.npy"), one)
    # of two files, each one's record (the first one's stood for both: an audit of stop 67)
    assert _run_two(files, "r_two") == 0
    two = json.loads((files / "r_two" / "metrics.json").read_text())["ptu"]["channels"]
    assert two[0]["delays_bins"]["1"] == pytest.approx(23, abs=.1) and two[1] is None
    assert _run(files, "skew.ptu", "r_ch1", "--align-channels", "--channel", "0") == 0
    assert "one --channel is read, or the file has one), so there is nothing to align" in (
        capsys.readouterr().err)
    assert json.loads((files / "r_one2" / "metrics.json").read_text())["ptu"]["channels"] is None


def test_a_calibration_keeps_its_channel_shifts(files, capsys):
    """calibrate --align-channels records the shifts; reconstruct through that calibration
    applies them without the option (the response was measured through them), says where
    the scan's cables no longer fit them, and refuses --align-channels with a calibration of
    the channels merged as recorded."""
    import json

    from spslidar.cli import main

    def calibrate(name, *extra):
        return main(["calibrate", "--ptu", str(files / "skew.ptu"), "--patterns",
                     str(files / "patterns.npy"), "--code", str(files / "code.npy"),
                     "--bit-rate", "10e9", "--distance", "4.0", "--target", "range",
                     "--out", str(files / name), *extra])

    assert calibrate("cal_aligned.json", "--align-channels") == 0
    assert calibrate("cal_merged.json") == 0
    cal = json.loads((files / "cal_aligned.json").read_text())
    assert cal["channel_shifts_bins"] == {"1": 23}
    assert json.loads((files / "cal_merged.json").read_text())["channel_shifts_bins"] == {}
    capsys.readouterr()
    assert _run(files, "skew.ptu", "c_skew", "--calibration", str(files / "cal_aligned.json")) == 0
    assert "do not arrive together" not in capsys.readouterr().err
    metrics = json.loads((files / "c_skew" / "metrics.json").read_text())
    assert metrics["ptu"]["channels"]["shifts_bins"] == {"1": 23}
    # the same calibration on a file whose channel 1 arrives with channel 0: it no longer fits
    assert _run(files, "even.ptu", "c_even", "--calibration", str(files / "cal_aligned.json")) == 0
    assert "cables changed since the calibration" in capsys.readouterr().err
    assert _run(files, "skew.ptu", "c_bad", "--align-channels", "--calibration",
                str(files / "cal_merged.json")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "merged as recorded" in err[0]
    assert not (files / "c_bad").exists()


def test_a_damaged_channel_shift_field_is_refused(files):
    """A CAL.json whose channel_shifts_bins is not channel numbers to whole bins is refused
    in one line (from a dict too), and a calibration without the field (older files) has
    none."""
    import json

    from spslidar.cli import main
    from spslidar.pipeline.calibration_file import calibration_shifts, check_calibration

    path = files / "cal_damaged_base.json"
    assert main(["calibrate", "--ptu", str(files / "skew.ptu"), "--patterns",
                 str(files / "patterns.npy"), "--code", str(files / "code.npy"),
                 "--bit-rate", "10e9", "--distance", "4.0", "--target", "range",
                 "--align-channels", "--out", str(path)]) == 0
    cal = json.loads(path.read_text())
    code = np.load(files / "code.npy")
    assert calibration_shifts(check_calibration(dict(cal), "cal", 10e9, code)) == {1: 23}
    old = {k: v for k, v in cal.items() if k != "channel_shifts_bins"}
    assert calibration_shifts(check_calibration(old, "cal", 10e9, code)) == {}
    for bad in ([1, 2], {"x": 1}, {"1": 2.5}, {"1": True}, {"200": 1}, "23"):
        with pytest.raises(ConfigError, match="channel_shifts_bins is damaged"):
            check_calibration(dict(cal, channel_shifts_bins=bad), "cal", 10e9, code)


def test_a_laser_monitor_is_no_cable_delay(files, capsys):
    """A laser monitor on channel 2 (the code, alike in every pattern, 2.5 times the
    scene's photons) was read as a 29.5-bin cable delay, and --align-channels, as the
    warning advised, moved the scene 4.3 m (an outside audit of stop 67): its rate does not
    follow the patterns, so it is named as such, given no delay and moves nothing."""
    import json

    data = read_ptu_histograms(files / "monitor.ptu", L, bin_width=BW)
    assert data.channel_spread[2] < 2 and data.channel_spread[0] > 10
    assert channel_delays(data.channel_histograms) != {}  # (read blind, the monitor has one)
    assert channel_delays(data.channel_histograms, data.channel_spread) == {}
    assert _run(files, "monitor.ptu", "m_plain") == 0
    err = capsys.readouterr().err
    assert "detector channel(s) 2 (" in err and "does not follow the patterns" in err
    assert "--channel 0 reads the scene alone" in err and "do not arrive together" not in err
    assert _run(files, "monitor.ptu", "m_aligned", "--align-channels") == 0
    np.testing.assert_array_equal(np.load(files / "m_aligned" / "depth.npy"),
                                  np.load(files / "m_plain" / "depth.npy"))
    record = json.loads((files / "m_aligned" / "metrics.json").read_text())["ptu"]["channels"]
    assert record["delays_bins"] == {} and record["shifts_bins"] == {}
    assert record["rate_spread"]["2"] < 2 < record["rate_spread"]["0"]
    truth = np.load(files / "truth.npy")
    assert np.nanmedian(np.abs(np.load(files / "m_aligned" / "depth.npy") - truth)) < 0.03
