"""A timing drift over a measured acquisition (``spslidar.pipeline.drift``): read from the
returns' delay group by group of patterns, said by ``reconstruct`` and ``calibrate``, kept
in ``metrics.json`` (an outside audit of 2026-11-30: half a bin of drift made a 16x16 map
four times worse without a word)."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.forward import expected_counts
from spslidar.instrument import instrument_weights
from spslidar.io import write_acquisition_ptu
from spslidar.pipeline import measure
from spslidar.pipeline.drift import drift_note, timing_drift
from spslidar.pipeline.export import write_measurement_arrays
from spslidar.pipeline.real import reconstruct_ptu

SCAN = {"scene": "steps", "depth_min": 5.2, "depth_max": 6.0, "size": 16,
        "code_length": 1023, "compression": 0.5, "signal": 0.5, "noise": 0.01,
        "range_gate": [4.8, 6.4], "seed": 4}


def _drifted_ptu(path, meas, drift: float, seed: int = 0) -> None:
    """``meas``'s acquisition photon by photon, each pattern's photons ``drift * k / (M - 1)``
    bins late (a continuous shift, floored into the TDC's bins)."""
    acq, cfg = meas.acq, meas.config
    shifts, weights = instrument_weights(meas.scene, acq, cfg)
    pats = meas.patterns
    m = pats.shape[0]
    noise = np.asarray(meas.sim["noise_per_bin"], np.float64)
    rng = np.random.default_rng(seed)

    def events():
        for k in range(m):
            amp = np.asarray(pats.apply_rows(slice(k, k + 1), weights), np.float64)
            lam = expected_counts(amp, shifts, acq.code, acq.signal_per_pulse, noise[k:k + 1],
                                  acq.n_periods)[0]
            counts = rng.poisson(lam)
            t = np.repeat(np.arange(acq.period), counts) + rng.random(int(counts.sum()))
            bins = np.floor(t + drift * k / (m - 1)).astype(np.int64) % acq.period
            yield np.stack([rng.integers(0, acq.n_periods, bins.size), bins], axis=1)

    write_acquisition_ptu(path, events(), acq.period, acq.bin_width,
                          periods_per_pattern=acq.n_periods)


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    d = tmp_path_factory.mktemp("drift")
    meas = measure(SCAN)
    out = {}
    for drift in (0.0, 1.5):
        path = d / f"d{drift}.ptu"
        _drifted_ptu(path, meas, drift)
        p, c = write_measurement_arrays(meas, path)
        out[drift] = (path, np.load(p), np.load(c))
    return meas, out


def test_a_shift_across_the_patterns_is_read_back():
    """Histograms of one return profile, pattern k shifted by ``s k / (M - 1)`` bins (by
    linear interpolation): the fitted drift is ``s`` within the interpolation's bias; none
    reads near 0."""
    rng = np.random.default_rng(1)
    code = (rng.random(511) < 0.5).astype(float)
    profile = np.zeros(511)
    profile[[40, 41, 90, 150]] = [3.0, 1.0, 2.0, 1.5]
    base = np.real(np.fft.ifft(np.fft.fft(code) * np.fft.fft(profile)))
    m = 64
    for s, lo, hi in ((0.0, -0.02, 0.02), (1.0, 0.9, 1.05), (-3.0, -3.1, -2.9), (-8.0, -8.1, -7.9)):
        rows = []
        for k in range(m):
            x = s * k / (m - 1)
            f = int(np.floor(x))
            a = x - f
            rows.append((1 - a) * np.roll(base, f) + a * np.roll(base, f + 1) + 0.5)
        got = timing_drift(rng.poisson(200 * np.array(rows)), code)
        assert lo <= got[0] <= hi
        assert (drift_note(got, 1e-10) is None) == (s == 0)
    assert timing_drift(np.zeros((64, 511)), code) is None
    assert timing_drift(np.ones((8, 511)), code) is None  # too few patterns to group
    # under 64 patterns a group's subsets could be empty, and their shift of 0 shrank the
    # noise (9 of 40 16-pattern files without a drift were said to drift): not read
    assert timing_drift(rng.poisson(200 * np.array(rows[:48]) + 5), code) is None


@pytest.mark.parametrize("name,offset,said", [
    ("warm-up", lambda u: 1.0 - np.exp(-u / 0.1), True),
    ("half-bin warm-up", lambda u: 0.5 * (1.0 - np.exp(-u / 0.1)), True),
    ("oscillation", lambda u: 0.5 * np.sin(2 * np.pi * u), True),
    ("there and back", lambda u: 0.5 * np.sin(np.pi * u), True),  # (no line: the span)
    ("steady", lambda u: 0.0 * u, False),
])
def test_a_drift_that_is_no_line_is_said(name, offset, said):
    """A warm-up (an exponential settling over a tenth of the acquisition) and an
    oscillation were read through a line whose scatter hid them (a 1-bin warm-up as 0.47 +-
    0.19, a sine as -0.92 from first to last, neither said); the groups' span, against each
    group's own photon noise, says them."""
    rng = np.random.default_rng(5)
    code = (rng.random(511) < 0.5).astype(float)
    profile = np.zeros(511)
    profile[[40, 90, 150]] = [3.0, 2.0, 1.5]
    base = np.real(np.fft.ifft(np.fft.fft(code) * np.fft.fft(profile)))
    m = 128
    f = np.fft.rfftfreq(511)
    rows = [np.fft.irfft(np.fft.rfft(base) * np.exp(-2j * np.pi * f * offset(k / (m - 1))),
                         n=511) for k in range(m)]
    got = timing_drift(rng.poisson(np.maximum(50 * np.array(rows), 0) + 25), code)
    assert (drift_note(got, 1e-10) is not None) == said, (got.bins, got.span, got.sigma)


@pytest.mark.parametrize("seed", range(6))
def test_faint_returns_without_a_drift_are_not_said_to_drift(seed):
    """Faint returns over a background: each group's shift is noisy (and jumps now and then),
    so the groups span a third of a bin or more without any drift; against their own noise
    nothing is said."""
    rng = np.random.default_rng(40 + seed)
    code = (rng.random(511) < 0.5).astype(float)
    profile = np.zeros(511)
    profile[[40, 90, 150]] = [3.0, 2.0, 1.5]
    base = np.real(np.fft.ifft(np.fft.fft(code) * np.fft.fft(profile)))
    got = timing_drift(rng.poisson(np.maximum(0.2 * base, 0) + 5, (128, 511)), code)
    assert got is None or drift_note(got, 1e-10) is None


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("rate", [0.1, 3.0])
def test_noise_alone_is_no_drift(seed, rate):
    """A file of background only has no return to time: nothing is read (noise's peaks, read
    as shifts, spanned 0.6 bins and were said as a drift on 2 of 5 such files)."""
    rng = np.random.default_rng(seed)
    code = (rng.random(1023) < 0.5).astype(float)
    assert timing_drift(rng.poisson(rate, (256, 1023)), code) is None


def test_reconstruct_says_a_drift_and_not_its_absence(scan):
    meas, files = scan
    said = {}
    for drift, (path, p, c) in files.items():
        r = reconstruct_ptu(path, p, c, 10e9, (4.8, 6.4), truth=meas.scene.depth)
        said[drift] = ([w for w in r.warnings if "timing drift" in w],
                       r.metrics["ptu"]["timing_drift_bins"], r.metrics["depth_rmse_m"])
    assert said[0.0][0] == [] and abs(said[0.0][1]) < 0.1
    assert len(said[1.5][0]) == 1 and 1.2 <= said[1.5][1] <= 1.6
    assert "bins later, +-" in said[1.5][0][0] and "moves by up to 1." in said[1.5][0][0]
    # the drift is what the warning says it is: it costs the map (measured 0.09 -> 0.19 m)
    assert said[1.5][2] > 1.3 * said[0.0][2]


def test_calibrate_says_a_drift_over_the_wall(tmp_path, capsys):
    """A drift over the calibration wall's acquisition widens the response it reads: said,
    and kept in the calibration file."""
    import json

    from spslidar.cli import main

    np.save(tmp_path / "wall.npy", np.full((16, 16), 5.5))
    meas = measure({k: v for k, v in SCAN.items() if k not in ("depth_min", "depth_max")}
                   | {"scene": str(tmp_path / "wall.npy")})
    for drift in (0.0, 1.5):
        path = tmp_path / f"w{drift}.ptu"
        _drifted_ptu(path, meas, drift)
        p, c = write_measurement_arrays(meas, path)
        assert main(["calibrate", "--ptu", str(path), "--patterns", p, "--code", c,
                     "--bit-rate", "10e9", "--distance", "5.5", "--target", "range",
                     "--out", str(tmp_path / f"cal{drift}.json")]) == 0
        err = capsys.readouterr().err
        got = json.loads((tmp_path / f"cal{drift}.json").read_text())["timing_drift_bins"]
        assert ("timing drift" in err) == (drift > 0)
        assert got == pytest.approx(drift, abs=0.15)
