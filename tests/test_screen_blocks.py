"""Marker blocks in which the instrument was not measuring (a detector or laser dropout, a
stall) and histograms that cover part of the code period (a gated detector, a TDC range
shorter than the period): ``spslidar.pipeline.screen``, on files written here by the
independent PicoHarp writer of ``test_independent_ptu`` (an outside TCSPC audit of
2026-11-30 found each read as a measurement, or as returns outside the gate, without a word).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_independent_ptu import write_picoharp_t3  # (tests/ is on sys.path under pytest)

from spslidar.cli import main
from spslidar.pipeline.screen import (
    dropouts,
    empty_window,
    tdc_range_note,
)

C = 299_792_458.0
BIT_RATE = 10e9
N, M, L, DWELL = 16, 192, 511, 2000


def random_scan(rng, m: int, depth: np.ndarray, refl: np.ndarray, length: int | None = None):
    """A balanced random code of ``length`` bits (default ``L``), ``m`` random binary
    patterns of the scene's size, and each pattern's returns over the code period per unit
    of signal, ``(m, length)``: the code circularly convolved with the patterns' light at
    each pixel's delay (shared with ``test_first_pattern``)."""
    length = L if length is None else length
    code = np.zeros(length)
    code[rng.permutation(length)[: length // 2 + 1]] = 1.0
    pats = (rng.random((m,) + depth.shape) < 0.5).astype(np.float32)
    delay = np.rint(2 * depth.ravel() / (C / BIT_RATE)).astype(int)
    amp = np.zeros((m, length))
    w = pats.reshape(m, -1) * refl.ravel()[None, :]
    for d in np.unique(delay):
        amp[:, d % length] += w[:, delay == d].sum(axis=1)
    spectrum = np.fft.ifft(np.fft.fft(amp, axis=1) * np.fft.fft(code)[None, :], axis=1).real
    return code, pats, spectrum

def _scene():
    depth = np.full((N, N), 3.6)
    refl = np.full((N, N), 0.8)
    depth[:, :6] = np.linspace(3.0, 3.4, N)[:, None]  # a slanted panel
    refl[:, :6] = 0.5
    depth[6:12, 8:14] = 3.2  # a box
    refl[6:12, 8:14] = 1.0
    return depth, refl


def _acquire(path, case="ok", seed=0, wall=False, m=M, signal=6e-5):
    """A 16x16 acquisition of random binary patterns and a balanced random code (about 1 100
    photons per pattern, 200 of them background), ``case``: ``dropout`` (blocks 60-79 hold
    no photon over their dwell), ``stall`` (block 60 lasts 10**7 code periods, its photons in
    its first 2 000), ``gated`` (no photon outside bins 150-349), ``tdcrange`` (a 6.25 ps TDC
    step whose 4096 steps cover half the period), ``late`` (the first 20 % of each dwell
    shows the previous pattern); ``wall``: a flat wall at 3.6 m; ``m`` patterns, ``signal``
    photons per bin per period of a unit return. Returns the truth."""
    rng = np.random.default_rng(seed)
    depth, refl = _scene()
    if wall:
        depth[:], refl[:] = 3.6, 0.8
    code, pats, spectrum = random_scan(rng, m, depth, refl)
    lam = np.clip(DWELL * (signal * spectrum + 2e-4), 0, None)
    counts = rng.poisson(lam)
    dwell = np.full(m, DWELL, np.int64)
    if case == "dropout":
        counts[60:80] = 0
    elif case == "stall":
        dwell[60] = 10**7
    elif case == "gated":
        counts[:, :150] = 0
        counts[:, 350:] = 0
    binning = 16 if case == "tdcrange" else 1
    syncs, dtimes, markers, start = [], [], [], 0
    for k in range(m):
        t = np.repeat(np.arange(L), counts[k])
        s = start + rng.integers(0, DWELL, t.size)
        if case == "late":  # the previous pattern's photons over the first fifth
            early = np.repeat(np.arange(L), rng.poisson(0.2 * lam[k - 1]))
            t = np.concatenate([early, np.repeat(np.arange(L), rng.poisson(0.8 * lam[k]))])
            s = start + np.concatenate([rng.integers(0, DWELL // 5, early.size),
                                        rng.integers(DWELL // 5, DWELL, t.size - early.size)])
        if binning > 1:  # each photon at a random step of its bin; past the TDC's range: lost
            t = t * binning + rng.integers(0, binning, t.size)
            s, t = s[t < 4096], t[t < 4096]
        order = np.argsort(s, kind="stable")
        syncs += [np.array([start]), s[order]]
        dtimes += [np.zeros(1, int), t[order]]
        markers += [np.ones(1, bool), np.zeros(t.size, bool)]
        start += int(dwell[k])
    write_picoharp_t3(path / "scan.ptu", np.concatenate(syncs), np.concatenate(dtimes),
                      np.concatenate(markers), 1 / (BIT_RATE * binning), BIT_RATE / L)
    np.save(path / "patterns.npy", pats)
    np.save(path / "code.npy", code.astype(np.uint8))
    return depth


def _reconstruct(path, capsys, *extra):
    out = path / "rec"
    assert main(["reconstruct", "--ptu", str(path / "scan.ptu"), "--patterns",
                 str(path / "patterns.npy"), "--code", str(path / "code.npy"), "--bit-rate",
                 "10e9", "--range-gate", "2.5", "4", "--out", str(out), "--no-figure",
                 *extra]) == 0
    err = capsys.readouterr().err
    return json.loads((out / "metrics.json").read_text()), np.load(out / "depth.npy"), err


def _rmse(est, truth):
    return float(np.sqrt(np.nanmean((est - truth) ** 2)))


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The same acquisition without a dropout: its depth RMSE (about 4 cm)."""
    path = tmp_path_factory.mktemp("ok")
    truth = _acquire(path)
    out = path / "rec"
    assert main(["reconstruct", "--ptu", str(path / "scan.ptu"), "--patterns",
                 str(path / "patterns.npy"), "--code", str(path / "code.npy"), "--bit-rate",
                 "10e9", "--range-gate", "2.5", "4", "--out", str(out), "--no-figure"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["ptu"]["blocks_left_out"] == []
    return _rmse(np.load(out / "depth.npy"), truth)


def test_blocks_without_photons_over_their_dwell_are_left_out_and_said(tmp_path, capsys,
                                                                          reference):
    """20 blocks of 192 without a photon (a detector's overload shutdown): read as patterns
    that saw nothing they made this map 5 times worse (22 cm against 4 cm, measured on three
    seeds of the audit's 16x16 scene); left out, the map is within a tenth of the one
    without the dropout (the solve has 172 patterns instead of 192: a little worse is fair)."""
    truth = _acquire(tmp_path, "dropout")
    m, est, err = _reconstruct(tmp_path, capsys)
    assert "the blocks of 20 pattern(s) (60, 61, 62, 63, 64, ...) hold almost no photons" in err
    assert m["ptu"]["blocks_left_out"] == list(range(60, 80))
    assert m["ptu"]["n_patterns_solved"] == M - 20
    assert len(m["ptu"]["counts_per_pattern"]) == M - 20
    assert _rmse(est, truth) <= 1.5 * reference


def test_a_stalled_block_is_left_out_and_the_others_keep_their_scale(tmp_path, capsys,
                                                                      reference):
    """A TCSPC running on for 10**7 code periods while the DMD waited: that block's photons
    scaled to the mean dwell were nothing, and every other block was scaled up by the stall's
    share of the mean (a map 1.7 times worse); left out, the map is the reference's."""
    truth = _acquire(tmp_path, "stall")
    m, est, err = _reconstruct(tmp_path, capsys)
    assert "the blocks of 1 pattern(s) (60) hold almost no photons" in err
    assert "over 10000000 code periods" in err
    assert m["ptu"]["blocks_left_out"] == [60]
    assert m["n_periods"] == DWELL  # (the mean dwell without the stall)
    assert _rmse(est, truth) <= 1.2 * reference


def test_a_gated_detector_is_said_and_not_read_as_returns_outside_the_gate(tmp_path, capsys):
    """No photon in 61 % of the period: the partial period's sidelobes read as 77 % of the
    returns outside a gate that held the whole scene ("widen --range-gate", which did not
    help); now the empty part is named and the outside share is not read."""
    _acquire(tmp_path, "gated")
    m, _, err = _reconstruct(tmp_path, capsys)
    assert "the histograms hold no photon in bins 350-149 of the 511-bin code period" in err
    assert "lie outside the range gate" not in err
    assert m["ptu"]["blocks_left_out"] == []


def test_a_tdc_range_shorter_than_the_period_is_said(tmp_path, capsys):
    """A PicoHarp's 4096 steps of 6.25 ps cover 25.6 ns of a 51.1 ns period: the photons of
    the other half are never recorded (the file cannot hold them), which the header says."""
    _acquire(tmp_path, "tdcrange")
    _, _, err = _reconstruct(tmp_path, capsys, "--allow-binning")
    assert "the TDC records delays up to 25.6 ns (4096 steps of 6.25 ps" in err
    assert "of the 51.1 ns sync period: 50% of the period is never recorded" in err
    assert "lie outside the range gate" not in err


def test_calibrate_leaves_a_dropout_out_and_names_a_gated_detector(tmp_path, capsys):
    """``calibrate`` screens its wall's blocks as ``reconstruct`` does: the dropout's blocks
    are said and their photons are not the calibration's; a gated detector is named (it
    said "acquire the target longer", which would not help)."""
    _acquire(tmp_path, "dropout", wall=True)
    cal = tmp_path / "cal.json"
    args = ["calibrate", "--ptu", str(tmp_path / "scan.ptu"), "--patterns",
            str(tmp_path / "patterns.npy"), "--code", str(tmp_path / "code.npy"),
            "--bit-rate", "10e9", "--distance", "3.6", "--target", "range"]
    assert main([*args, "--settle", "1e-6", "--out", str(cal)]) == 0
    assert "the blocks of 20 pattern(s) (60, 61, 62, 63, 64, ...) hold almost no photons" in \
        capsys.readouterr().err
    assert abs(json.loads(cal.read_text())["delay_bins"]) < 0.5
    assert json.loads(cal.read_text())["measured_from"]["settle_s"] == 1e-6  # (recorded)
    _acquire(tmp_path, "gated", wall=True)
    assert main([*args, "--out", str(tmp_path / "cal2.json")]) == 0
    assert "the histograms hold no photon in bins" in capsys.readouterr().err


def test_dropouts_reads_the_background_not_the_patterns():
    """Blocks of Poisson photons at any pattern's light over a background are never flagged
    (1 000 acquisitions, the dimmest pattern a tenth of the brightest); an empty block is,
    where its dwell gives DROPOUT_EXPECTED background photons or more; a dark frame (a
    pattern without light) and an acquisition without background are not screened."""
    rng = np.random.default_rng(0)
    for _ in range(1000):
        m = int(rng.integers(3, 60))
        light = rng.uniform(0.1, 1.0, m)
        n = rng.integers(500, 5000, m)
        total = rng.poisson(n.sum() * (0.02 + 0.05 * rng.random(64)))  # per-bin floor
        counts = rng.poisson(n * (64 * 0.02 + 200 * light))
        assert dropouts(counts, n, light[:, None], total).size == 0
    n = np.full(8, 1000)
    total = np.full(64, 8 * 1000 * 0.01)  # 0.64 background photons per period: 640 a block
    counts = np.full(8, 5000)
    counts[3] = 0
    patterns = np.ones((8, 4))
    assert dropouts(counts, n, patterns, total).tolist() == [3]
    counts[3] = 6  # (under 1 % of 640)
    assert dropouts(counts, n, patterns, total).tolist() == [3]
    counts[3] = 7
    assert dropouts(counts, n, patterns, total).size == 0
    dark = patterns.copy()
    dark[3] = 0.0
    counts[3] = 0
    assert dropouts(counts, n, dark, total).size == 0
    # too short a dwell for its few photons to say anything
    short = n.copy()
    short[3] = 40  # (29 background photons: 40 periods of 80 / 7040 photons in 64 bins)
    assert dropouts(counts, short, patterns, total).size == 0
    # every block flagged is no dropout but a wrong floor: none is left out
    assert dropouts(np.zeros(8), n, patterns, total).size == 0
    # no background at all: a pattern lighting nothing bright may rightly hold nothing
    assert dropouts(counts, n, patterns, np.zeros(64)).size == 0


def test_empty_window_is_no_run_of_the_codes_own_zeros():
    """A flat target without background leaves the code's zeros empty: the longest such run
    (and one bin more, for a return between two bins) is no gated window; a run past twice
    it is, where the rest holds photons enough to say so."""
    rng = np.random.default_rng(1)
    code = (rng.random(511) < 0.5).astype(float)
    flat = 100.0 * np.roll(code, 37)
    assert empty_window(flat, code) is None
    gated = 100.0 + 50.0 * np.roll(code, 37)
    gated[150:350] = 0.0
    assert empty_window(gated, code) == (150, 200)
    wraps = 100.0 + 0.0 * code
    wraps[:10] = wraps[-30:] = 0.0  # one run across the period's end
    assert empty_window(wraps, code) == (481, 40)
    assert empty_window(0.1 * gated, code) is None  # (10 photons a bin: too few)


def test_tdc_range_note_reads_the_record_type():
    """The range is the record type's delay field (PicoHarp 12 bits, HydraHarp 15) times the
    resolution; an unknown record type says nothing."""
    picoharp = {"record_type_code": 0x00010303}
    assert tdc_range_note(picoharp, 4e-12, 51.1e-9) is not None
    assert tdc_range_note(picoharp, 16e-12, 51.1e-9) is None  # (4096 x 16 ps = 65.5 ns)
    hydraharp = {"record_type_code": 0x01010304}  # (32768 steps)
    assert "up to 32.77 ns (32768 steps of 1 ps" in tdc_range_note(hydraharp, 1e-12, 51.1e-9)
    assert tdc_range_note(hydraharp, 2e-12, 51.1e-9) is None  # (65.5 ns)
    assert tdc_range_note({"record_type_code": None}, 1e-12, 51.1e-9) is None


@pytest.mark.parametrize("edge", ["start", "end"])
def test_settle_drops_each_blocks_first_syncs_and_shortens_its_dwell(tmp_path, edge):
    """``settle_s`` of 7 code periods (rounded up from 6.5): each block's photons in its first
    7 syncs are dropped and counted, every exposure is 7 shorter, the rest of the histogram is
    the photons' own (each photon's bin is its sync's distance from its block's start); with
    markers at the patterns' ends, a block starts after the marker before it."""
    from spslidar.io import read_ptu_histograms, write_ptu_t3

    rng = np.random.default_rng(3)
    m, dwell, bins, res = 6, 50, 64, 1e-10
    events = []  # (sync, marker first at its sync where markers start patterns, dtime)
    for k in range(m):
        start = k * dwell + (edge == "end")
        if edge == "start":
            events.append((start, 0, 0, 1))
        for p in rng.integers(start, start + dwell - (edge == "end"), 40):
            events.append((int(p), 1, int(p - start), 0))
        if edge == "end":
            events.append((start + dwell - 1, 2, 0, 1))
    events.sort()
    nsync, _, dtime, marker = (np.array(v) for v in zip(*events, strict=True))
    path = tmp_path / "s.ptu"
    write_ptu_t3(path, nsync=nsync, dtime=dtime, marker=marker, resolution_s=res,
                 sync_rate_hz=1 / (bins * res))
    plain = read_ptu_histograms(path, bins, bin_width=res, marker_edge=edge)
    settled = read_ptu_histograms(path, bins, bin_width=res, marker_edge=edge,
                                  settle_s=6.5 * bins * res)
    assert settled.n_dropped_settling == int(np.sum(dtime[marker == 0] < 7)) > 0
    # (the markers' spacing stays what the block checks read; the exposure is 7 shorter)
    assert settled.periods_per_pattern.tolist() == plain.periods_per_pattern.tolist()
    assert settled.exposure_periods.tolist() == (plain.periods_per_pattern - 7).tolist()
    assert plain.exposure_periods is plain.periods_per_pattern
    assert np.array_equal(settled.histograms[:, 7:], plain.histograms[:, 7:])
    assert not settled.histograms[:, :7].any()


def test_settle_refusals(tmp_path, capsys):
    """A settling time as long as the blocks' typical dwell leaves nothing (refused, naming
    both); a negative, NaN or infinite one, or a bool, is one line and status 2, before any
    output is written."""
    from spslidar.errors import ConfigError
    from spslidar.io import read_ptu_histograms, write_ptu_t3

    path = tmp_path / "s.ptu"
    write_ptu_t3(path, nsync=np.array([0, 1, 5, 10, 12]), dtime=np.array([0, 2, 3, 0, 4]),
                 marker=np.array([1, 0, 0, 1, 0]), resolution_s=1e-10, sync_rate_hz=1e10 / 31)
    with pytest.raises(ConfigError, match="as long as the blocks' median dwell of 6.5 syncs"):
        read_ptu_histograms(path, 31, bin_width=1e-10, settle_s=31e-10 * 8)
    # a time under a sync is left out as one whole sync, and said so (an audit of 2026-12-03)
    write_ptu_t3(tmp_path / "one.ptu", nsync=np.array([0, 1, 1, 2, 2]),
                 dtime=np.array([0, 2, 3, 0, 4]), marker=np.array([1, 0, 1, 1, 0]),
                 resolution_s=1e-10, sync_rate_hz=1e10 / 31)
    with pytest.raises(ConfigError, match=r"1e-10 s \(rounded up to 1 whole sync of 3.1e-09 s\)"):
        read_ptu_histograms(tmp_path / "one.ptu", 31, bin_width=1e-10, settle_s=1e-10)
    assert read_ptu_histograms(path, 31, bin_width=1e-10,
                               settle_s=31e-10 * 1.5).n_dropped_settling == 1
    np.save(tmp_path / "p.npy", np.stack([np.eye(4), 1 - np.eye(4)]))
    np.save(tmp_path / "c.npy", (np.arange(31) % 2).astype(np.uint8))
    for bad in ("-1", "nan", "inf"):
        assert main(["reconstruct", "--ptu", str(path), "--patterns", str(tmp_path / "p.npy"),
                     "--code", str(tmp_path / "c.npy"), "--bit-rate", "10e9", "--range-gate",
                     "0.1", "0.4", "--settle", bad, "--out", str(tmp_path / "o")]) == 2
        assert "--settle must be a number of seconds >= 0" in capsys.readouterr().err
        assert not (tmp_path / "o").exists()
    from spslidar.pipeline.blocks import read_blocks

    with pytest.raises(ConfigError, match="--settle must be"):
        read_blocks(path, 2, 31, bin_width=1e-10, settle=True)


def test_settle_gives_back_the_map_of_a_late_dmd(tmp_path, capsys):
    """The first 20 % of each dwell shows the previous pattern (a DMD settling, or a marker
    early against its mirrors): 128 patterns, the audit's scene with five times the light;
    RMSE 4.5 cm, and 0.40 cm with ``--settle`` 21 us (the dwell is 102 us), as without the
    late pattern (0.38 cm; seed 4 of the measured 3-5: 2.2 / 4.5 / 3.1 -> 0.50 / 0.40 /
    0.51 cm)."""
    truth = _acquire(tmp_path, "late", seed=4, m=128, signal=4e-4)
    _, late, _ = _reconstruct(tmp_path, capsys)
    _, settled, err = _reconstruct(tmp_path, capsys, "--settle", "2.1e-5", "--overwrite")
    assert _rmse(settled, truth) <= 0.3 * _rmse(late, truth)
    assert _rmse(settled, truth) <= 0.01


def test_a_marker_a_frame_of_patterns_is_named(tmp_path):
    """A DLP's trigger once a frame of 8 patterns: 32 markers for 256 patterns was refused as
    too few blocks with nothing of why; the refusal now names the whole ratio."""
    from spslidar.errors import ConfigError
    from spslidar.io import read_ptu_histograms, write_ptu_t3

    marks = np.arange(4) * 100
    photons = np.arange(4)[:, None] * 100 + np.arange(1, 99, 7)[None, :]
    nsync = np.concatenate([marks, photons.ravel()])
    marker = np.concatenate([np.ones(4, int), np.zeros(photons.size, int)])
    order = np.lexsort((-marker, nsync))
    path = tmp_path / "f.ptu"
    write_ptu_t3(path, nsync=nsync[order], dtime=np.full(nsync.size, 3), marker=marker[order],
                 resolution_s=1e-10, sync_rate_hz=1e10 / 31)
    with pytest.raises(ConfigError, match="the 8 patterns are 2 times the 4 blocks: a marker a "
                                          "frame of 2 patterns, or an acquisition stopped"):
        read_ptu_histograms(path, 31, bin_width=1e-10, n_patterns=8)
    with pytest.raises(ConfigError, match="fewer than the 7 patterns$"):
        read_ptu_histograms(path, 31, bin_width=1e-10, n_patterns=7)
    one = tmp_path / "one.ptu"  # (one block is no frame of patterns)
    write_ptu_t3(one, nsync=np.array([0, 5, 9]), dtime=np.array([0, 3, 3]),
                 marker=np.array([1, 0, 0]), resolution_s=1e-10, sync_rate_hz=1e10 / 31)
    with pytest.raises(ConfigError, match="fewer than the 2 patterns$"):
        read_ptu_histograms(one, 31, bin_width=1e-10, n_patterns=2)


@pytest.mark.parametrize("background", [0.0, 1e-8, 3e-8, 1e-7])
def test_a_dark_nights_blocks_that_light_nothing_are_kept(background):
    """A 4x4 object alone in range, 0/1 Hadamard patterns (the all-ones row among them), a
    100 counts/s dark rate at 10 Gb/s (1e-8 per bin and period) or less: the patterns that
    light none of the object rightly hold (almost) nothing. The floor read from the occupied
    bins alone was the signal's, and all eight such blocks were left out as dropouts (a
    review of 2026-11-30)."""
    from scipy.linalg import hadamard

    rng = np.random.default_rng(5)
    pats = (hadamard(256) > 0).astype(np.float32)
    obj = np.zeros((16, 16), bool)
    obj[6:10, 6:10] = True
    lit = pats[:, obj.ravel()].sum(axis=1)
    code = (rng.random(L) < 0.5).astype(float)
    dwell = np.full(256, 2000)
    lam = dwell[:, None] * (1e-3 * lit[:, None] * np.roll(code, 40)[None, :] + background)
    hist = rng.poisson(lam)
    assert (lit == 0).sum() == 8
    assert dropouts(hist.sum(axis=1), dwell, pats, hist.sum(axis=0), code).size == 0


def test_the_counts_per_pattern_are_the_solved_rows(tmp_path, capsys):
    """After blocks are left out, ``ptu.counts_per_pattern`` holds the counts of the rows
    solved (it held the first rows' of the file), in their order."""
    from spslidar.io import read_ptu_histograms

    _acquire(tmp_path, "dropout")
    m, _, _ = _reconstruct(tmp_path, capsys)
    read = read_ptu_histograms(tmp_path / "scan.ptu", L, bin_width=1 / BIT_RATE)
    kept = np.setdiff1d(np.arange(M), np.arange(60, 80))
    assert m["ptu"]["counts_per_pattern"] == read.counts_per_pattern[kept].tolist()
