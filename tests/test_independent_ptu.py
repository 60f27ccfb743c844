"""A measured acquisition that nobody here wrote: a PicoHarp T3 PTU file produced by a writer
written in this test from PicoQuant's published record layout (not spslidar.io's writer), of a
scene simulated here by its own model (not spslidar.forward), reconstructed by
``spslidar reconstruct`` *without* a ground truth, and scored afterwards against the scene.

PicoHarp T3 record (32 bits, little-endian): bits 0-15 the sync counter, 16-27 dtime (TDC bins
since the sync), 28-31 the channel: 1-4 a photon, 15 special, where dtime 0 is an overflow of
the sync counter (+65536) and dtime 1-15 a marker bit mask.
"""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from spslidar.cli import main

C = 299_792_458.0
BIT_RATE = 10e9
N, M, L, DWELL = 32, 256, 2047, 40


def _tag(ident: str, typ: int, value: bytes) -> bytes:
    return struct.pack("<32siI", ident.encode("ascii"), -1, typ) + value


def write_picoharp_t3(path, sync, dtime, marker, resolution, sync_rate) -> int:
    """Write time-ordered events (``marker`` True: a marker on input 1 at that sync) as a
    PicoHarp T3 PTU file; returns the number of records."""
    sync = np.asarray(sync, np.int64)
    wrap = sync >> 16
    n_ofl = np.diff(np.concatenate([[0], wrap]))  # overflow records before each event
    assert np.all(n_ofl >= 0), "events must be time-ordered"
    low = (sync & 0xFFFF).astype(np.uint32)
    ev = np.where(marker, (np.uint32(15) << 28) | (np.uint32(1) << 16) | low,
                  (np.uint32(1) << 28) | (dtime.astype(np.uint32) << 16) | low).astype(np.uint32)
    ofl = np.uint32(15 << 28)  # channel 15, dtime 0, nsync 0: one overflow
    # interleave: each event preceded by its overflow records
    counts = n_ofl + 1
    records = np.full(int(counts.sum()), ofl, dtype=np.uint32)
    records[np.cumsum(counts) - 1] = ev
    int8, float8, empty = 0x10000008, 0x20000008, 0xFFFF0008
    tags = [("Measurement_Mode", int8, 3), ("Measurement_SubMode", int8, 0),
            ("MeasDesc_BinningFactor", int8, 1),
            ("MeasDesc_Resolution", float8, resolution),
            ("MeasDesc_GlobalResolution", float8, 1.0 / sync_rate),
            ("TTResult_SyncRate", int8, int(round(sync_rate))),
            ("TTResult_NumberOfRecords", int8, records.size),
            ("TTResultFormat_TTTRRecType", int8, 0x00010303),
            ("TTResultFormat_BitsPerRecord", int8, 32)]
    header = b"PQTTTR\x00\x001.0.00\x00\x00"
    for ident, typ, value in tags:
        header += _tag(ident, typ, struct.pack("<q" if typ == int8 else "<d", value))
    header += _tag("Header_End", empty, bytes(8))
    with open(path, "wb") as fh:
        fh.write(header)
        fh.write(records.tobytes())
    return int(records.size)


def _scene():
    """32x32 at 29.8-30.6 m: a back wall, a slanted panel, a box and a one-pixel pole, and
    reflectivities from 0.3 to 1."""
    depth = np.full((N, N), 30.6)
    refl = np.full((N, N), 0.8)
    depth[:, :12] = np.linspace(29.9, 30.4, N)[:, None]  # slanted panel
    refl[:, :12] = 0.5
    depth[14:26, 16:28] = 29.8  # box
    refl[14:26, 16:28] = 1.0
    depth[:, 30] = 30.1  # pole
    refl[:, 30] = 0.3
    return depth, refl


def _acquire(tmp_path, seed=0, name="scan", binning=1):
    rng = np.random.default_rng(seed)
    depth, refl = _scene()
    code = np.zeros(L)
    code[rng.permutation(L)[: L // 2 + 1]] = 1.0  # a balanced random code, not an m-sequence
    pats = (rng.random((M, N, N)) < 0.5).astype(np.float32)
    delay = np.rint(2 * depth.ravel() / (C / BIT_RATE)).astype(int)  # whole bins
    # expected photons per bin per period: sum_j phi_kj alpha_j code(t - d_j) + background
    amp = np.zeros((M, L))
    w = pats.reshape(M, -1) * refl.ravel()[None, :]
    for d in np.unique(delay):
        amp[:, d % L] += w[:, delay == d].sum(axis=1)
    spectrum = np.fft.ifft(np.fft.fft(amp, axis=1) * np.fft.fft(code)[None, :], axis=1).real
    counts, n = _write_acquisition(tmp_path / f"{name}.ptu", spectrum, DWELL, rng, binning)
    np.save(tmp_path / "patterns.npy", pats)
    np.save(tmp_path / "code.npy", code.astype(np.uint8))
    return depth, int(counts.sum()), n


def _write_acquisition(path, spectrum, dwell, rng, binning=1):
    """Poisson photons of ``dwell`` code periods per pattern at ``2e-3 spectrum + 0.05`` per
    bin per period, each at a random sync of its pattern's dwell, after the pattern's marker;
    written as PicoHarp T3 whose dtime unit is ``1 / binning`` of a bin (each photon at a
    random unit of its bin). Returns the counts and the number of records."""
    counts = rng.poisson(np.clip(dwell * (2e-3 * spectrum + 0.05), 0, None))
    syncs, dtimes, markers = [], [], []
    for k in range(M):
        t = np.repeat(np.arange(L), counts[k])
        s = k * dwell + rng.integers(0, dwell, t.size)
        if binning > 1:
            t = t * binning + rng.integers(0, binning, t.size)
        order = np.argsort(s, kind="stable")
        syncs += [np.array([k * dwell]), s[order]]
        dtimes += [np.zeros(1, int), t[order]]
        markers += [np.ones(1, bool), np.zeros(t.size, bool)]
    n = write_picoharp_t3(path, np.concatenate(syncs), np.concatenate(dtimes),
                          np.concatenate(markers), 1 / (BIT_RATE * binning), BIT_RATE / L)
    return counts, n


def test_independent_picoharp_file_reconstructs_without_truth(tmp_path, capsys):
    """Median error within one 1.5 cm bin, RMSE <= 0.15 m and returns in >= 95 % of pixels
    (the targets of issue 20 for a hidden acquisition of this kind); the photon count read
    equals the one written."""
    depth, photons, _ = _acquire(tmp_path)
    out = tmp_path / "rec"
    assert main(["reconstruct", "--ptu", str(tmp_path / "scan.ptu"), "--patterns",
                 str(tmp_path / "patterns.npy"), "--code", str(tmp_path / "code.npy"),
                 "--bit-rate", "10e9", "--range-gate", "29.5", "30.9", "--out", str(out)]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert int(sum(m["ptu"]["counts_per_pattern"])) == photons
    assert m["depth_rmse_m"] is None and m["coverage"] >= 0.95
    est = np.load(out / "depth.npy")
    err = est - depth
    assert np.nanmedian(np.abs(err)) <= 0.015
    assert np.sqrt(np.nanmean(err ** 2)) <= 0.15


# the hidden instrument of issue 20: photons arrive 13.74 ns late (cables, electronics) and
# spread by a Gaussian jitter of 1.5 bins FWHM, 30 % of them with a 4-bin exponential tail
SYSTEM_DELAY_BINS, SIGMA_BINS, TAIL_BINS, TAIL_WEIGHT = 137.4, 1.5 / 2.3548, 4.0, 0.3


def _irf_share(frac: float, offsets: np.ndarray) -> np.ndarray:
    """Share of bin ``floor(tau) + offset`` of a return at ``tau`` (``frac`` its part of a
    bin), by the jitter's CDF from SciPy (not spslidar.instrument)."""
    from scipy.stats import exponnorm, norm

    lo, hi = offsets - frac, offsets + 1 - frac
    gauss = norm.cdf(hi, scale=SIGMA_BINS) - norm.cdf(lo, scale=SIGMA_BINS)
    k = TAIL_BINS / SIGMA_BINS
    tail = exponnorm.cdf(hi, k, scale=SIGMA_BINS) - exponnorm.cdf(lo, k, scale=SIGMA_BINS)
    return (1 - TAIL_WEIGHT) * gauss + TAIL_WEIGHT * tail


def _acquire_instrument(path, name, depth, refl, seed, dwell=60):
    """As :func:`_acquire`, through the instrument above, delays below a bin kept."""
    rng = np.random.default_rng(seed)
    code = np.zeros(L)
    code[rng.permutation(L)[: L // 2 + 1]] = 1.0
    pats = (rng.random((M, N, N)) < 0.5).astype(np.float32)
    tau = 2 * depth.ravel() / (C / BIT_RATE) + SYSTEM_DELAY_BINS
    amp = np.zeros((M, L))
    w = pats.reshape(M, -1) * refl.ravel()[None, :]
    offsets = np.arange(-10, 60)
    for j in range(tau.size):
        base = int(np.floor(tau[j]))
        np.add.at(amp, (slice(None), (base + offsets) % L),
                  w[:, j:j + 1] * _irf_share(tau[j] - base, offsets)[None, :])
    spectrum = np.fft.ifft(np.fft.fft(amp, axis=1) * np.fft.fft(code)[None, :], axis=1).real
    _write_acquisition(path / f"{name}.ptu", spectrum, dwell, rng)
    np.save(path / f"{name}_patterns.npy", pats)
    np.save(path / f"{name}_code.npy", code.astype(np.uint8))


def test_independent_instrument_calibrated_on_a_wall(tmp_path, capsys):
    """Issue 20's hidden instrument, written and jittered here: calibrated on a flat wall at
    25 m, the scene reconstructs without truth with the delay gone. Measured (seed 0, 12.9 M
    photons): bias 1.2 cm, median 4.9 mm, RMSE 0.100 m (0.049 m without the one-pixel pole,
    which no estimator recovers at 25 % patterns, ideal instrument included: its +0.5 m over
    32 pixels is the bias); removing the offset by hand instead: 0.146 m; uncalibrated the
    depths fall outside the gate. ``benchmarks/instrument.py`` gives seeds 0-5 with and
    without the pole."""
    depth, refl = _scene()
    _acquire_instrument(tmp_path, "wall", np.full((N, N), 25.0), np.full((N, N), 0.8), 1)
    _acquire_instrument(tmp_path, "scan", depth, refl, 0)

    def files(name):
        return ["--ptu", str(tmp_path / f"{name}.ptu"), "--patterns",
                str(tmp_path / f"{name}_patterns.npy"), "--code",
                str(tmp_path / f"{name}_code.npy"), "--bit-rate", "10e9"]

    assert main(["calibrate", *files("wall"), "--distance", "25", "--out",
                 str(tmp_path / "cal.json")]) == 0
    cal = json.loads((tmp_path / "cal.json").read_text())
    # the writer's photon has no pulse width, spslidar's model a half-bin pulse: a quarter
    # bin of convention (3.7 mm) on top of the peak's tail shift
    assert cal["delay_s"] == pytest.approx(SYSTEM_DELAY_BINS / BIT_RATE, abs=0.3 / BIT_RATE)
    out = tmp_path / "rec"
    assert main(["reconstruct", *files("scan"), "--range-gate", "29.5", "30.9", "--calibration",
                 str(tmp_path / "cal.json"), "--out", str(out), "--no-figure"]) == 0
    err = np.load(out / "depth.npy") - depth
    assert np.nanmedian(np.abs(err)) <= 0.008  # 8.9 mm on the lags' grid, 4.9 mm below it
    assert abs(np.nanmean(err)) <= 0.02  # the lost pole alone is +1.6 cm
    assert np.sqrt(np.nanmean(err ** 2)) <= 0.125
    assert np.sqrt(np.nanmean(np.delete(err, 30, axis=1) ** 2)) <= 0.085
    capsys.readouterr()


def test_a_tdc_finer_than_the_code_bits_is_merged_on_request(tmp_path, capsys):
    """A TDC of twice the code's bit rate (5 ps units, one photon at a random unit of its
    bin): without --allow-binning one line naming the flag, exit 2, nothing written; with it
    the histograms, and so the depth map, are those of the same photons at the bits' own
    resolution."""
    _acquire(tmp_path)  # scan.ptu, patterns.npy, code.npy at the bits' resolution
    _acquire(tmp_path, name="fine", binning=2)  # the same photons (drawn before the units)

    def rec(ptu, out, *extra):
        return main(["reconstruct", "--ptu", str(tmp_path / ptu), "--patterns",
                     str(tmp_path / "patterns.npy"), "--code", str(tmp_path / "code.npy"),
                     "--bit-rate", "10e9", "--range-gate", "29.5", "30.9", "--out",
                     str(tmp_path / out), "--no-figure", *extra])

    capsys.readouterr()
    assert rec("fine.ptu", "refused") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--allow-binning" in err[0]
    assert not (tmp_path / "refused").exists()
    assert rec("fine.ptu", "fine", "--allow-binning") == 0
    assert rec("scan.ptu", "coarse") == 0
    np.testing.assert_array_equal(np.load(tmp_path / "fine" / "depth.npy"),
                                  np.load(tmp_path / "coarse" / "depth.npy"))
