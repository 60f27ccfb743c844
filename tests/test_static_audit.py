"""Findings of the static-analysis audit of 2026-11-30: arguments cast without a word (a
fractional count of periods truncated, fractional lags, rows and shapes read as whole ones, a
bool tag written as an integer) and a PTU writer whose last pattern read back short. Each
test fails without its guard."""

from __future__ import annotations

import struct

import numpy as np
import ptufile
import pytest

from spslidar.detectors.events import simulate_events
from spslidar.detectors.gmapd import GMAPD
from spslidar.errors import ConfigError
from spslidar.io import ptu_info, read_ptu_histograms, write_acquisition_ptu, write_ptu_t3
from spslidar.operators.image import Wavelet2D
from spslidar.patterns.hadamard import HadamardPatterns

L = 63
BW = 250e-12


# --- 1. simulate_events: a whole number of periods, and of warm-up periods --------------------


def _lam(n_periods: int) -> np.ndarray:
    return np.full(50, 0.02 * n_periods)


@pytest.mark.parametrize("n_periods", [3.9, 0.5, 0, -2, True, np.bool_(True), float("nan"),
                                       "4", np.array([4, 4])])
def test_simulate_events_refuses_a_count_of_periods_that_is_no_whole_number(n_periods):
    """3.9 periods were simulated as 3, with ``lam_row`` spread over the 3 (1.3 times the
    flux per period)."""
    det = GMAPD(dead_time=20e-9, bin_width=1e-9)
    with pytest.raises(ValueError, match=r"^n_periods must be a whole number >= 1") as err:
        simulate_events(_lam(4), n_periods, det, np.random.default_rng(0))
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("warmup", [1.5, -1, True, np.bool_(False), float("inf"), "1", [1]])
def test_simulate_events_refuses_a_warmup_that_is_no_whole_number(warmup):
    """A warm-up of 1.5 was simulated as 1 period but 1.5 discarded (497 detections where
    600 were expected)."""
    det = GMAPD(dead_time=20e-9, bin_width=1e-9)
    with pytest.raises(ValueError, match=r"^warmup_periods must be a whole number >= 0 of "
                                         r"code periods") as err:
        simulate_events(_lam(4), 4, det, np.random.default_rng(0), warmup_periods=warmup)
    assert "\n" not in str(err.value)


def test_simulate_events_takes_whole_numbers_whatever_their_type():
    det = GMAPD(dead_time=20e-9, bin_width=1e-9)
    ref = simulate_events(_lam(4), 4, det, np.random.default_rng(1), warmup_periods=2)
    for n, w in ((4.0, 2.0), (np.int32(4), np.int64(2)), (np.float64(4), 2)):
        got = simulate_events(_lam(4), n, det, np.random.default_rng(1), warmup_periods=w)
        np.testing.assert_array_equal(got[0], ref[0])
        np.testing.assert_array_equal(got[1], ref[1])
    hist, _ = simulate_events(_lam(4), 4, det, np.random.default_rng(1), warmup_periods=0)
    assert hist.sum() > 0


# --- 2. simulate_correlations: whole lags -----------------------------------------------------


def _simulate(lags):
    from spslidar import pipeline
    from spslidar.detectors.counting import NoiseModel
    from spslidar.detectors.linear import LinearDetector

    meas = pipeline.measure(scene="steps", size=8, code_length=127, compression=1.0, seed=3)
    cfg = meas.config
    noise = NoiseModel(cfg.noise, tuple(cfg.noise_split), cfg.ambient, cfg.background_rate,
                       cfg.dark_count_rate)
    det = LinearDetector(dead_time=cfg.dead_time)
    lags = meas.ulags[:4] if lags is None else lags(meas.ulags[:4])
    return meas, pipeline.simulate_correlations(meas.patterns, meas.scene, meas.acq, lags,
                                                noise, det, cfg.pulse_width,
                                                np.random.default_rng(5), noiseless=True)


def test_simulate_correlations_refuses_fractional_lags():
    """Fractional lags were cast to the bin below without a word, where matched_filter and
    the gate refused them."""
    with pytest.raises(ValueError, match=r"^lags must be whole bins"):
        _simulate(lambda u: u + 0.5)
    with pytest.raises(ValueError, match=r"^lags must be whole bins"):
        _simulate(lambda u: np.append(u[:-1].astype(float), np.nan))


def test_simulate_correlations_takes_whole_lags_as_floats():
    _, ref = _simulate(None)
    _, got = _simulate(lambda u: u.astype(np.float64))
    np.testing.assert_array_equal(got["corr"], ref["corr"])


# --- 3. write_acquisition_ptu: whole periods per pattern --------------------------------------


def _events(rng, n_patterns=4, per=20, dwell=40):
    return [np.stack([rng.integers(0, dwell, per), rng.integers(0, L, per)], axis=1)
            for _ in range(n_patterns)]


@pytest.mark.parametrize("periods", [2.9, 0, -3, True, np.bool_(True), float("nan"), "40",
                                     [40, 40, 2.9, 40], [40, 40, 40, 0], [40, 40, -1, 40],
                                     [True] * 4, [40, 40, 40], np.full(4, 40.5)])
def test_write_acquisition_ptu_refuses_fractional_or_nonpositive_dwells(tmp_path, periods):
    """2.9 periods per pattern were written, and read back, as 2 (a scalar through int(),
    one per pattern through an int64 array), while a period_bins of 2.5 was refused."""
    ev = [e[e[:, 0] < 2] for e in _events(np.random.default_rng(0))]
    path = tmp_path / "a.ptu"
    with pytest.raises(ConfigError, match=r"periods_per_pattern") as err:
        write_acquisition_ptu(path, ev, L, BW, periods_per_pattern=periods)
    assert "\n" not in str(err.value) and not path.exists()


def test_write_acquisition_ptu_takes_whole_dwells_as_floats(tmp_path):
    ev = _events(np.random.default_rng(1))
    for k, periods in enumerate((40.0, np.int32(40), [40.0, 40, 40, np.int64(40)])):
        path = tmp_path / f"{k}.ptu"
        write_acquisition_ptu(path, ev, L, BW, periods_per_pattern=periods)
        acq = read_ptu_histograms(path, L, bin_width=BW)
        assert acq.periods_per_pattern.tolist() == [40] * 4


# --- 4. tags: bools as tyBool8 ----------------------------------------------------------------


def _tag_types(path) -> dict[str, int]:
    """Each tag's type code, read from the header's 48-byte tags (PicoQuant's layout)."""
    data = path.read_bytes()
    at, out = 16, {}
    while True:
        ident = data[at:at + 32].split(b"\0")[0].decode("ascii")
        typ, value = struct.unpack("<Iq", data[at + 36:at + 48])
        out[ident] = typ
        at += 48
        if ident == "Header_End":
            return out
        if typ == 0x4001FFFF:  # an AnsiString's data follows
            at += value


def test_bool_tags_are_written_as_bool8_and_read_back_as_bools(tmp_path):
    """True and False were written as tyInt8, read back as 1 and 0."""
    path = tmp_path / "b.ptu"
    tags = {"Flag_On": True, "Flag_Off": False, "Np_On": np.bool_(True),
            "Np_Off": np.bool_(False), "Count": 3, "NpCount": np.int16(-2)}
    write_ptu_t3(path, nsync=[0, 5], dtime=[0, 7], marker=[1, 0], resolution_s=BW,
                 sync_rate_hz=1 / (L * BW), extra_tags=tags)
    types = _tag_types(path)
    for key, value in tags.items():
        assert types[key] == (0x00000008 if isinstance(value, bool | np.bool_)
                              else 0x10000008), key
    with ptufile.PtuFile(path) as f:
        got = f.tags
    for key, value in tags.items():
        assert type(got[key]) is (bool if isinstance(value, bool | np.bool_) else int), key
        assert got[key] == value, key
    # the project's reader walks the header (tyBool8 is a fixed-size type) and reads the file
    info = ptu_info(path)
    assert info["record_type"] == "HydraHarp2T3" and info["n_records"] == 2
    acq = read_ptu_histograms(path, L, bin_width=BW)
    assert acq.histograms[0, 7] == 1 and acq.n_markers == 1


# --- 5. the last pattern's dwell --------------------------------------------------------------


@pytest.mark.parametrize("record_type", ["HydraHarp2T3", "HydraHarpT3", "PicoHarpT3"])
@pytest.mark.parametrize("marker", [1, 4])
def test_a_low_count_acquisition_reads_back_every_blocks_full_dwell(tmp_path, record_type,
                                                                   marker):
    """About 20 photons per pattern over 40 periods: nothing was written after the last
    photon, so the last pattern's dwell read to that photon's period (38 periods instead of
    40 in 2 of 4 block orders, and reconstruct scaled that row up about 5 %)."""
    ev = _events(np.random.default_rng(0))  # last periods 38, 39, 35, 39: 2 of 4 short
    hist = np.zeros((4, L))
    for k, e in enumerate(ev):
        np.add.at(hist[k], e[:, 1], 1)
    closing = 0
    for order in range(4):  # each block last in turn
        perm = np.roll(np.arange(4), -order)
        blocks = [ev[i] for i in perm]
        for periods in (40, [40] * 4):
            path = tmp_path / f"{order}.ptu"
            write_acquisition_ptu(path, blocks, L, BW, periods_per_pattern=periods,
                                  marker=marker, record_type=record_type)
            acq = read_ptu_histograms(path, L, bin_width=BW, marker=marker)
            assert acq.periods_per_pattern.tolist() == [40] * 4, (order, periods)
            assert acq.n_markers == 4 and acq.warnings == []
            np.testing.assert_array_equal(acq.histograms, hist[perm])
            np.testing.assert_array_equal(acq.pattern_start_sync, [0, 40, 80, 120])
        # a closing record is no photon and no block: a marker on another input, at its
        # pattern's last period
        with ptufile.PtuFile(path) as f:
            d = f.decode_records()
        is_mark = (d["channel"] < 0) & (d["marker"] > 0)
        starts = is_mark & ((d["marker"] & (1 << (marker - 1))) != 0)
        assert d["time"][starts].tolist() == [0, 40, 80, 120]
        assert np.count_nonzero(d["channel"] >= 0) == 80
        assert (d["time"][is_mark & ~starts] % 40 == 39).all()
        assert int(d["time"][(d["channel"] >= 0) | is_mark].max()) == 159
        closing += int(np.count_nonzero(is_mark & ~starts))
    assert closing > 0


def test_the_last_dwell_reads_whole_with_empty_patterns_and_a_generator(tmp_path):
    """An empty last pattern read as a one-period block (and was said to be an
    end-of-acquisition marker); a generator's last pattern reads its whole dwell too."""
    ev = _events(np.random.default_rng(12))
    ev[-1] = np.zeros((0, 2), np.int64)
    path = tmp_path / "e.ptu"
    write_acquisition_ptu(path, ev, L, BW, periods_per_pattern=40)
    acq = read_ptu_histograms(path, L, bin_width=BW)
    assert acq.periods_per_pattern.tolist() == [40] * 4 and acq.warnings == []
    assert acq.counts_per_pattern.tolist() == [20, 20, 20, 0]
    write_acquisition_ptu(path, (e for e in ev[:3]), L, BW, periods_per_pattern=40)
    assert read_ptu_histograms(path, L).periods_per_pattern.tolist() == [40] * 3


# --- 6. HadamardPatterns: rows, signs and permutation ---------------------------------------


@pytest.mark.parametrize("rows, words", [
    ([1.7], "rows must be whole row numbers"),
    ([-1], r"rows must be Hadamard row numbers in 0\.\.15, got -1"),
    ([3, 16], r"rows must be Hadamard row numbers in 0\.\.15, got 16"),
    ([2, 5, 2], "rows must be distinct"),
    ([True, False], "need between 1 and 16 Hadamard rows"),
    ([[1, 2]], "need between 1 and 16 Hadamard rows"),
])
def test_hadamard_patterns_refuse_rows_that_are_no_row_numbers(rows, words):
    """Rows were cast to int64: 1.7 showed row 1, -1 the last row and 16 (at n_side 4) was a
    raw IndexError at the first product."""
    with pytest.raises(ConfigError, match=words) as err:
        HadamardPatterns(4, rows)
    assert "\n" not in str(err.value)


def test_hadamard_patterns_refuse_signs_that_are_not_plus_or_minus_one():
    """Signs were cast to int8: 0.5 became 0, dropping that pixel's Hadamard term."""
    good = np.ones(16)
    for signs in (np.where(np.arange(16) == 3, 0.5, 1.0), np.ones(15), np.zeros(16),
                  2 * good, np.ones(16, bool), np.ones((4, 4))):
        with pytest.raises(ConfigError, match=r"^signs must be 16 signs, each \+1 or -1"):
            HadamardPatterns(4, [0, 1], signs=signs)


def test_hadamard_patterns_refuse_a_perm_that_is_no_permutation():
    """``perm`` was never checked: a repeated pixel showed one pixel twice and another never."""
    for perm in (np.zeros(16, int), np.arange(1, 17), np.arange(15), np.arange(16) + 0.5,
                 np.arange(16) - 1):
        with pytest.raises(ConfigError, match=r"^perm must be"):
            HadamardPatterns(4, [0, 1], perm=perm)


def test_hadamard_patterns_take_whole_numbers_as_floats():
    rng = np.random.default_rng(3)
    rows, signs, perm = [0, 5, 9], np.where(rng.random(16) < 0.5, -1, 1), rng.permutation(16)
    ref = HadamardPatterns(4, rows, signs, perm).todense()
    got = HadamardPatterns(4, np.array(rows, float), signs.astype(float),
                           perm.astype(float)).todense()
    np.testing.assert_array_equal(got, ref)


# --- 7. Wavelet2D: a shape and a level of whole numbers ---------------------------------------


def test_wavelet2d_refuses_a_shape_that_is_no_pair_of_whole_numbers():
    """(8.9, 8.9) was taken as 8 x 8, where Gradient2D refused it."""
    for shape in ((8.9, 8.9), (8, 8.5), (0, 8), 8):
        with pytest.raises(ValueError, match=r"^Wavelet2D's image shape must be a pair of "
                                             r"whole numbers"):
            Wavelet2D(shape)


@pytest.mark.parametrize("level", [1.7, -1, True, "2", float("nan"), [1]])
def test_wavelet2d_refuses_a_level_that_is_no_whole_number(level):
    """level=1.7 was a raw TypeError, level=-1 PyWavelets' own error."""
    with pytest.raises(ValueError, match=r"^Wavelet2D's level must be a whole number >= 0 of "
                                         r"levels") as err:
        Wavelet2D((8, 8), level=level)
    assert "\n" not in str(err.value)


def test_wavelet2d_takes_whole_levels():
    x = np.random.default_rng(4).standard_normal((64, 2))
    np.testing.assert_array_equal(Wavelet2D((8.0, 8), level=2.0) @ x,
                                  Wavelet2D((8, 8), level=2) @ x)
    np.testing.assert_array_equal(Wavelet2D((8, 8), level=0) @ x, x)


def test_hadamard_patterns_say_which_row_repeats_how_often_and_which_flip_is_wrong():
    """"got row 1 3 times" for a row given twice (the largest count was said), and flips of
    the right shape but wrong values were said to be of the wrong shape (a review of
    2026-11-30)."""
    from spslidar.errors import ConfigError
    from spslidar.patterns.hadamard import HadamardPatterns

    with pytest.raises(ConfigError, match=r"got row 1 2 times$"):
        HadamardPatterns(4, rows=[1, 1, 2, 2, 2])
    with pytest.raises(ConfigError, match=r"flips must be \+1 or -1, got np.int64\(0\) at row 1$"
                       r"|flips must be \+1 or -1, got 0 at row 1$"):
        HadamardPatterns(4, rows=[0, 1, 2], flips=[1, 0, 1])


def test_the_closing_line_of_a_folder_that_cannot_be_listed(tmp_path):
    """Under a umask of 0777 the written folder cannot be listed (non-root), and the closing
    line's listing made the written run exit 2 (a review of 2026-11-30)."""
    from spslidar.cli_common import _written

    assert _written(tmp_path / "unlistable") == [
        "(the folder's mode, from the umask, forbids listing it)"]
