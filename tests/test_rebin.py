"""A TDC whose bin is no whole fraction of the code's bit (a MultiHarp 150's 80 ps under a
10 GHz code's 100 ps), or a code clock a little off the TDC's: ``--allow-binning`` splits
each TDC bin between the bits it overlaps. Both were refused, with advice that led to a
second refusal (an outside audit of 2026-11-30)."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.errors import ConfigError
from spslidar.forward import expected_counts
from spslidar.instrument import instrument_weights
from spslidar.io import read_ptu_histograms, write_ptu_t3
from spslidar.pipeline import measure
from spslidar.pipeline.export import write_measurement_arrays
from spslidar.pipeline.real import reconstruct_ptu

L = 1023
BIT = 100e-12


def _tdc_file(path, times_per_pattern, res: float, period_s: float, periods: int = 50,
              seed: int = 0) -> None:
    """Photons at continuous times within the code period (seconds), per pattern, each in a
    random period of the pattern's dwell, recorded by a TDC of ``res`` seconds."""
    rng = np.random.default_rng(seed)
    nsync, dtime, marker = [], [], []
    for k, t in enumerate(times_per_pattern):
        syncs = k * periods + rng.integers(0, periods, t.size)
        order = np.argsort(syncs, kind="stable")
        nsync += [k * periods] + list(syncs[order])
        dtime += [0] + list(np.floor(t[order] / res).astype(np.int64))
        marker += [1] + [0] * t.size
    write_ptu_t3(path, nsync=np.array(nsync), dtime=np.array(dtime), marker=np.array(marker),
                 resolution_s=res, sync_rate_hz=1.0 / period_s)


def test_80_ps_bins_are_split_between_100_ps_bits(tmp_path):
    """Each 80 ps bin's photons go to the bits it overlaps in proportion: the histogram is
    the TDC's through the overlap matrix (computed here bin by bin), and no photon is
    lost."""
    rng = np.random.default_rng(1)
    times = [rng.uniform(0, L * BIT, 3000) for _ in range(3)]
    f = tmp_path / "mh.ptu"
    _tdc_file(f, times, 80e-12, L * BIT)
    with pytest.raises(ConfigError, match="--allow-binning splits its 8e-11 s bins between"):
        read_ptu_histograms(f, L, bin_width=BIT)
    got = read_ptu_histograms(f, L, bin_width=BIT, allow_binning=True)
    assert got.histograms.shape == (3, L) and got.bin_width_s == BIT and got.binning == 1
    for k, t in enumerate(times):
        tdc = np.bincount(np.floor(t / 80e-12).astype(int), minlength=1279)
        want = np.zeros(L)
        for j, c in enumerate(tdc):  # bin j covers [0.8 j, 0.8 (j + 1)) bits
            lo, hi = 0.8 * j, min(0.8 * (j + 1), L)
            a = int(lo)
            first = min(a + 1, hi) - lo
            want[a] += c * first / (hi - lo)
            if a + 1 < L:
                want[a + 1] += c * (1 - first / (hi - lo))
        np.testing.assert_allclose(got.histograms[k], want, rtol=1e-5, atol=1e-4)
        assert got.histograms[k].sum() == pytest.approx(t.size, rel=1e-6)
        assert got.counts_per_pattern[k] == t.size


def test_a_fine_tdc_is_merged_first_then_split(tmp_path):
    """A 4 ps TDC under bits of 100.06 ps (a code clock 600 ppm slow): merged into 24 ps bins,
    at most a quarter bit, then split; photons away from their bit's edges stay in it."""
    bit = BIT * (1 + 6e-4)
    rng = np.random.default_rng(2)
    k = rng.integers(0, L, 4000)
    times = [(k + rng.uniform(0.3, 0.7, k.size)) * bit]  # away from the bits' edges
    f = tmp_path / "hh.ptu"
    _tdc_file(f, times, 4e-12, L * bit)
    with pytest.raises(ConfigError, match=r"its bits come at 9\.99400\d*e\+09 Hz.*--allow-binning"):
        read_ptu_histograms(f, L, bin_width=BIT, allow_binning=True)  # (4 ps: 25 units)
    got = read_ptu_histograms(f, L, bin_width=bit, allow_binning=True)
    assert got.binning == 6
    np.testing.assert_allclose(got.histograms[0], np.bincount(k, minlength=L), atol=1e-4)


def test_a_tdc_coarser_than_the_bit_is_refused(tmp_path):
    f = tmp_path / "coarse.ptu"
    _tdc_file(f, [np.array([1e-9, 2e-9])], 250e-12, L * BIT)
    with pytest.raises(ConfigError, match="wider than the code's bit cannot be split"):
        read_ptu_histograms(f, L, bin_width=BIT, allow_binning=True)


def test_a_scene_through_an_80_ps_tdc_reconstructs_as_through_100_ps(tmp_path):
    """The same photons (continuous times) recorded by a 100 ps and an 80 ps TDC give the same
    median depth error, and the split's blur (a photon in a bin that straddles two bits is
    shared between them) costs a few per cent of the pixels within 5 cm (measured, 16x16
    steps, 128 patterns, seeds 4 / 5 / 6: median 0.4 mm either way; within 5 cm 0.871 /
    0.945 / 0.965 at 100 ps, 0.883 / 0.918 / 0.922 at 80 ps; RMSE 0.20 / 0.10 / 0.11 against
    0.18 / 0.14 / 0.18 m, outliers)."""
    meas = measure({"scene": "steps", "depth_min": 5.2, "depth_max": 6.0, "size": 16,
                    "code_length": L, "compression": 0.5, "signal": 0.5, "noise": 0.01,
                    "range_gate": [4.8, 6.4], "seed": 4})
    acq = meas.acq
    shifts, weights = instrument_weights(meas.scene, acq, meas.config)
    noise = np.asarray(meas.sim["noise_per_bin"], np.float64)
    rng = np.random.default_rng(3)
    times = []
    for k in range(meas.patterns.shape[0]):
        amp = np.asarray(meas.patterns.apply_rows(slice(k, k + 1), weights), np.float64)
        lam = expected_counts(amp, shifts, acq.code, acq.signal_per_pulse, noise[k:k + 1],
                              acq.n_periods)[0]
        counts = rng.poisson(lam)
        # (the half-bit pulse: each photon in the first half of its bit)
        t = (np.repeat(np.arange(L), counts) + 0.5 * rng.random(int(counts.sum()))) * BIT
        times.append(t)
    err = {}
    for res in (100e-12, 80e-12):
        path = tmp_path / f"t{res:g}.ptu"
        _tdc_file(path, times, res, L * BIT, periods=acq.n_periods)
        p, c = write_measurement_arrays(meas, path)
        r = reconstruct_ptu(path, np.load(p), np.load(c), 1e10, (4.8, 6.4),
                            truth=meas.scene.depth, allow_binning=True)
        err[res] = np.abs(r.depth - meas.scene.depth)
        # (the split's leak, which beats with the two grids, read as returns at every delay:
        # 76 % "outside" a gate that held the whole scene; not read through a split)
        if res == 80e-12:
            assert r.metrics["returns_outside_gate_fraction"] is None
            assert not any("outside the range gate" in w for w in r.warnings)
    assert np.nanmedian(err[80e-12]) == pytest.approx(np.nanmedian(err[100e-12]), abs=5e-4)
    assert np.mean(err[80e-12] < 0.05) >= 0.85


def test_a_sync_divider_with_a_split_bin_is_refused(tmp_path):
    """The fold is of whole bins: through a split, a code's two periods were squeezed into
    one (correlation -0.19 with the code), after the hint had offered that bit rate (a
    review)."""
    rng = np.random.default_rng(4)
    bit = 1.003e-10
    t = [rng.uniform(0, 2 * 127 * bit, 500)]
    f = tmp_path / "divsplit.ptu"
    nsync = np.concatenate([[0], np.sort(rng.integers(0, 50, 500))])
    write_ptu_t3(f, nsync=nsync, dtime=np.concatenate([[0], np.floor(t[0] / 1e-10)]).astype(int),
                 marker=np.concatenate([[1], np.zeros(500, int)]), resolution_s=1e-10,
                 sync_rate_hz=1 / (2 * 127 * bit), extra_tags={"HWSync_Divider": 2})
    with pytest.raises(ConfigError, match="a sync divider \\(2\\) with a TDC bin split"):
        read_ptu_histograms(f, 127, bin_width=bit, allow_binning=True)
    with pytest.raises(ConfigError, match="sync period") as err:
        read_ptu_histograms(f, 127, bin_width=1e-10, allow_binning=True)
    assert "--allow-binning splits" not in str(err.value)  # (no bit rate offered past a divider)
