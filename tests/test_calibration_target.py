"""The calibration target's own geometry (:mod:`spslidar.pipeline.target`): a flat wall facing
the lidar is farther at the corners than on the axis, and ``calibrate`` removes that spread
instead of reading it as the instrument's response (found by an audit, 2026-11-28: a 10 degree
wall at 25 m gave 14.236 ns for 13.74 and an IRF 8.29 bins wide)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.codes.sequences import lfsr_sequence
from spslidar.errors import ConfigError
from spslidar.pipeline.calibration import code_response, measure_response
from spslidar.pipeline.target import (
    measure_geometry,
    plane_offsets,
    plane_ranges,
    range_free_response,
)
from spslidar.products import point_cloud

sys.path.insert(0, str(Path(__file__).resolve().parent))


def test_a_facing_plane_lies_at_its_distance_through_the_pinhole():
    """Independent of the module: the points of ``points.ply``'s pinhole from the plane's
    ranges all have z = D (a facing wall) or z = D + a x + b y (a tilted one)."""
    rng = plane_ranges((9, 9), 25.0, 30.0)
    pts, _ = point_cloud(rng, fov_deg=30.0)
    np.testing.assert_allclose(pts[:, 2], 25.0, rtol=1e-12)  # float64 throughout
    assert rng[4, 4] == 25.0  # the centre pixel of an odd image looks along the axis
    corner = 4 * 2 * np.tan(np.radians(15.0)) / 9  # u = v of the corner pixel's ray
    assert rng[0, 0] == pytest.approx(25.0 * np.sqrt(1 + 2 * corner**2), rel=1e-12)
    tilted = plane_ranges((8, 8), 10.0, 20.0, slopes=(0.1, -0.2))
    p, _ = point_cloud(tilted, fov_deg=20.0)
    np.testing.assert_allclose(p[:, 2], 10.0 + 0.1 * p[:, 0] - 0.2 * p[:, 1], rtol=1e-12)


def test_a_plane_behind_a_pixel_is_refused():
    with pytest.raises(ConfigError, match="in front of the lidar"):
        plane_ranges((8, 8), 10.0, 120.0, slopes=(0.9, 0.0))


def _histograms(phi, code, irf, offsets, delay, rng=None, photons=None):
    """Each pattern's histogram: its pixels' returns, each the IRF at ``delay + s_p`` (whole
    bins, so the kernel's two-bin split is exact), circularly convolved with the code."""
    period = code.size
    resp = np.zeros((phi.shape[1], period))
    for p, s in enumerate(offsets):
        resp[p, (delay + int(s) + np.arange(irf.size)) % period] = irf
    amp = phi @ resp
    hist = np.fft.irfft(np.fft.rfft(amp, axis=1) * np.fft.rfft(code)[None, :], period, axis=1)
    if rng is not None:
        lam = np.clip(hist, 0.0, None)  # (round-off of the FFT below 0)
        hist = rng.poisson(photons * lam / lam.sum(axis=1, keepdims=True)).astype(float)
    return hist


def test_range_free_response_recovers_the_irf_exactly_without_noise():
    """Noiseless, offsets on whole bins: the Wiener estimate without regularisation is the
    IRF at the axis's delay to round-off, where the patterns' sum is smeared over the
    spread (its peak holds 0.19 of the IRF's 0.6)."""
    rng = np.random.default_rng(0)
    code = lfsr_sequence(7).astype(float)  # 127 bits
    phi = (rng.random((96, 64)) < 0.5).astype(float)
    offsets = rng.integers(0, 6, 64).astype(float)
    irf = np.array([0.1, 0.6, 0.2, 0.1])
    hist = _histograms(phi, code, irf, offsets, delay=40)
    g = range_free_response(hist, phi, code, offsets, reg=0.0)
    g = g / g.sum()  # (the shape: its scale is the patterns' mean light)
    want = np.zeros(code.size)
    want[40:44] = irf
    np.testing.assert_allclose(g, want, atol=1e-9)
    summed = code_response(hist.sum(axis=0), code)
    summed = summed - np.median(summed)
    assert summed.max() / summed.sum() < 0.25  # the spread smears the sum's peak


def test_geometry_finds_a_walls_spread_and_one_range():
    """Poisson photons through the same model: the scan finds the spread within its half-bin
    step and keeps the plane; a target at one range stays one range."""
    rng = np.random.default_rng(1)
    code = lfsr_sequence(9).astype(float)  # 511 bits
    phi = (rng.random((128, 256)) < 0.5).astype(float)
    bin_width = 1e-10
    off = plane_offsets((16, 16), 25.0, 16.0, bin_width)
    whole = np.round(off)  # the data on whole bins, the scan's candidates fractional
    irf = np.array([0.05, 0.5, 0.3, 0.1, 0.05])
    hist = _histograms(phi, code, irf, whole, delay=100, rng=rng, photons=4e5)
    geo = measure_geometry(hist, phi, code, bin_width, 25.0, (16, 16))
    assert geo["model"] == "plane"
    assert abs(geo["spread_bins"] - (whole.max() - whole.min())) <= 1.0
    assert geo["fov_deg"] == pytest.approx(16.0, abs=1.0)
    flat = _histograms(phi, code, irf, np.zeros(256), delay=100, rng=rng, photons=4e5)
    one = measure_geometry(flat, phi, code, bin_width, 25.0, (16, 16))
    assert one["model"] == "range" and one["spread_bins"] == 0.0 and one["offsets"] is None
    assert one["fov_deg"] is None  # (not the rejected plane's)
    given = measure_geometry(hist, phi, code, bin_width, 25.0, (16, 16), fov_deg=16.0)
    assert given["model"] == "plane" and given["z"] is None
    np.testing.assert_allclose(given["offsets"], off)


@pytest.fixture(scope="module")
def plane_wall(tmp_path_factory):
    """The independent instrument of ``test_independent_ptu`` (its own PicoHarp writer, delay
    and jittered, tailed IRF) on a flat wall 25 m ahead through a 10 degree field of view:
    its corners 0.179 m (11.9 bins) farther than its centre at 32x32."""
    import test_independent_ptu as indep

    path = tmp_path_factory.mktemp("plane_wall")
    u = (np.arange(indep.N) + 0.5 - indep.N / 2) * 2 * np.tan(np.radians(5.0)) / indep.N
    ranges = 25.0 * np.sqrt(1 + u[:, None] ** 2 + u[None, :] ** 2)  # written here, not by
    indep._acquire_instrument(path, "wall", ranges, np.full_like(ranges, 0.8), 1)  # spslidar
    files = ["--ptu", str(path / "wall.ptu"), "--patterns", str(path / "wall_patterns.npy"),
             "--code", str(path / "wall_code.npy"), "--bit-rate", "10e9", "--distance", "25"]
    return path, files, indep.SYSTEM_DELAY_BINS / indep.BIT_RATE


def test_calibrate_removes_a_flat_walls_spread(plane_wall, capsys):
    """Measured: the delay within 0.02 ns of the written 13.74 ns (0.14 ns is a quarter bin
    of pulse convention plus the tail, as for a wall at one range), the IRF 2.0-2.6 bins
    wide as the one-range wall's 1.9, the field of view fitted to 10.0 degrees; read as one
    range the same file gives 14.24 ns and 8.3 bins."""
    path, files, delay = plane_wall
    assert main(["calibrate", *files, "--out", str(path / "auto.json")]) == 0
    assert "a wall facing the lidar, fitted" in capsys.readouterr().out
    cal = json.loads((path / "auto.json").read_text())
    assert cal["target"]["model"] == "plane"
    assert cal["target"]["fov_deg"] == pytest.approx(10.0, abs=0.5)
    assert cal["delay_s"] == pytest.approx(delay, abs=0.3e-10)
    assert cal["irf_fwhm_bins"] < 3.0
    assert main(["calibrate", *files, "--target", "range", "--out", str(path / "r.json")]) == 0
    one = json.loads((path / "r.json").read_text())
    assert one["delay_s"] - delay > 3e-10 and one["irf_fwhm_bins"] > 6.0  # what it mends
    # the record of one range asked for has the keys of one range found (it held only
    # model and reason: a review of 2026-12-03)
    assert one["target"] == {"model": "range", "fov_deg": None, "spread_bins": 0.0, "z": None,
                             "phase_bins": None, "reason": "--target range"}
    assert main(["calibrate", *files, "--fov", "10", "--out", str(path / "fov.json")]) == 0
    given = json.loads((path / "fov.json").read_text())
    assert given["target"]["model"] == "plane" and given["target"]["z"] is None
    assert given["delay_s"] == pytest.approx(delay, abs=0.3e-10)


@pytest.mark.parametrize("args, match", [
    (["--target", "range", "--fov", "10"], "does not go with --target range"),
    (["--fov", "0"], "must lie in"),
    (["--target", "sphere"], "invalid choice"),
])
def test_calibrate_refuses_a_target_it_cannot_read(plane_wall, args, match, capsys):
    path, files, _ = plane_wall
    try:
        rc = main(["calibrate", *files, *args, "--out", str(path / "x.json")])
    except SystemExit as exc:  # (argparse's own refusals exit from the parser)
        rc = exc.code
    assert rc == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err
    assert not (path / "x.json").exists()


def test_measure_response_reads_a_given_response_as_its_own():
    """``response=`` is the code-free response the histogram would give: the same numbers."""
    code = lfsr_sequence(8).astype(float)
    irf = np.array([0.2, 0.7, 0.1])
    hist = _histograms(np.ones((1, 1)), code, irf, [0.0], delay=30)[0] + 5.0
    a = measure_response(hist, code, 1e-10, 0.0)
    b = measure_response(hist, code, 1e-10, 0.0, response=code_response(hist, code))
    assert a == b


def test_one_pattern_shown_throughout_reads_as_one_range():
    """Patterns that all light the same pixels give every pattern the same kernel: nothing
    tells the wall's spread from the instrument's, so ``auto`` reads one range."""
    rng = np.random.default_rng(2)
    code = lfsr_sequence(9).astype(float)
    phi = np.ones((32, 256))
    whole = np.round(plane_offsets((16, 16), 25.0, 16.0, 1e-10))
    hist = _histograms(phi, code, np.array([0.2, 0.6, 0.2]), whole, delay=100, rng=rng,
                       photons=4e5)
    geo = measure_geometry(hist, phi, code, 1e-10, 25.0, (16, 16))
    assert geo["model"] == "range" and geo["offsets"] is None
    assert geo["fov_deg"] is None and geo["spread_bins"] == 0.0  # (the 16 degrees unread)


def test_geometry_fits_a_tilted_wall_that_no_facing_wall_fits():
    """A wall tilted by 5 degrees about the vertical axis, 16x16 through 10 degrees, Poisson
    photons: the scan of facing walls read it as one range (an audit: the IRF 16 bins wide
    for 1.7, the delay 1.8 cm short and every calibrated depth 30 cm off, nothing said). The
    patterns' response centroids give the tilt's direction and the residual scan its size:
    within a bin of the round trip the tilt adds at the right edge (12.8 bins here), and
    the response of one range comes back as the IRF. A facing wall and a target at one range
    are not read as tilted."""
    rng = np.random.default_rng(3)
    code = lfsr_sequence(9).astype(float)  # 511 bits
    phi = (rng.random((128, 256)) < 0.5).astype(float)
    bin_width = 1e-10
    slope = np.tan(np.radians(5.0))
    off = np.round(plane_offsets((16, 16), 25.0, 10.0, bin_width, slopes=(slope, 0.0)))
    irf = np.array([0.05, 0.5, 0.3, 0.1, 0.05])
    hist = _histograms(phi, code, irf, off, delay=100, rng=rng, photons=4e5)
    geo = measure_geometry(hist, phi, code, bin_width, 25.0, (16, 16))
    assert geo["model"] == "plane" and "tilted" in geo["reason"]
    # the odd part of the round trips between the outer columns, at the image's edge (their
    # centres lie at x = +-15/16)
    edge = (off.reshape(16, 16)[:, -1].mean() - off.reshape(16, 16)[:, 0].mean()) / 2 / 0.9375
    assert geo["tilt_bins"][0] == pytest.approx(edge, abs=1.0)
    assert abs(geo["tilt_bins"][1]) <= 1.0
    resp = range_free_response(hist, phi, code, geo["offsets"])
    resp = np.roll(resp, -100)[:8] / resp.sum()
    assert np.argmax(resp) == 1 and resp[1] == pytest.approx(0.5, abs=0.12)
    for offsets in (np.round(plane_offsets((16, 16), 25.0, 10.0, bin_width)), np.zeros(256)):
        other = measure_geometry(_histograms(phi, code, irf, offsets, delay=100, rng=rng,
                                             photons=4e5), phi, code, bin_width, 25.0, (16, 16))
        assert "tilt_bins" not in other


def test_a_tilt_too_weak_to_fit_is_said(monkeypatch):
    """Where the centroids move across the field but no tilt fits better than a facing wall,
    calibrate says so (the independent instrument's 32x32 wall at 5 degrees was read as one
    range, its IRF 15 bins wide, without a word)."""
    import warnings

    import spslidar.pipeline.target as target

    monkeypatch.setattr(target, "_tilt_scan", lambda *a, **k: None)
    rng = np.random.default_rng(3)
    code = lfsr_sequence(9).astype(float)
    phi = (rng.random((128, 256)) < 0.5).astype(float)
    off = np.round(plane_offsets((16, 16), 25.0, 10.0, 1e-10,
                                 slopes=(np.tan(np.radians(5.0)), 0.0)))
    hist = _histograms(phi, code, np.array([0.2, 0.6, 0.2]), off, delay=100, rng=rng,
                       photons=4e5)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        geo = measure_geometry(hist, phi, code, 1e-10, 25.0, (16, 16))
    assert "tilt_bins" not in geo
    assert any("may be tilted" in str(w.message) for w in said)


def test_geometry_fits_a_wall_tilted_about_both_axes_and_survives_a_dark_frame():
    """A wall tilted 5 degrees about both axes: the centroids' direction (56 degrees for 45)
    and curvature are noisy, and a single scan along them stopped at a third of the tilt (a
    review: IRF 3-5 bins wide); the coordinate scans find both components within a bin. A
    dark frame among the patterns (0/0 in the centroids' design) crashed in LAPACK."""
    rng = np.random.default_rng(5)
    code = lfsr_sequence(9).astype(float)
    phi = (rng.random((128, 256)) < 0.5).astype(float)
    phi[0] = 0.0  # a dark frame
    t5 = np.tan(np.radians(5.0))
    off = np.round(plane_offsets((16, 16), 25.0, 10.0, 1e-10, slopes=(t5, t5)))
    irf = np.array([0.05, 0.5, 0.3, 0.1, 0.05])
    lam = np.clip(_histograms(phi, code, irf, off, delay=100), 0.0, None)
    rows = lam.sum(axis=1, keepdims=True)
    lam = np.where(rows > 0, 4e5 * lam / np.where(rows > 0, rows, 1.0), 20.0)  # dark: background
    hist = rng.poisson(lam).astype(float)
    geo = measure_geometry(hist, phi, code, 1e-10, 25.0, (16, 16))
    grid = off.reshape(16, 16)
    right = (grid[:, -1].mean() - grid[:, 0].mean()) / 2 / 0.9375
    down = (grid[-1].mean() - grid[0].mean()) / 2 / 0.9375
    assert "tilted" in geo["reason"]
    assert geo["tilt_bins"] == pytest.approx([right, down], abs=1.0)


def test_the_centroids_leave_out_a_dark_frame():
    """A dark frame whose response noise passes the mass test put 0/0 in the centroids'
    design and calibrate ended in LAPACK's traceback (a review: 93 of 200 seeds at 8x8)."""
    from spslidar.pipeline.target_tilt import tilt_of_target

    rng = np.random.default_rng(0)
    phi = rng.random((40, 64))
    phi[0] = 0.0
    g = np.zeros((40, 50))
    g[:, 20:25] = 1.0 + rng.random((40, 5))  # every row, the dark one too, holds a response
    out = tilt_of_target(g, phi, (8, 8))
    assert out is not None and np.all(np.isfinite(out["tilt_bins"]))


def test_a_wall_seen_through_a_response_narrower_than_a_bin(tmp_path, capsys):
    """An ideal instrument (no jitter: each pixel's half-bin pulse falls in one bin or two
    by where it starts in its bin) on a 10 degree wall at 25 m: the linear split of the
    kernels found no plane (0.39 deviations) and the delay was read 3.7 bins late (3.670 ns
    for 3.30; an audit found 4.7 bins at 32 x 32). The spreads scanned again with the pulse
    at each place in its bin find the wall and the delay."""
    np.save(tmp_path / "wall.npy", plane_ranges((16, 16), 25.0, 10.0))
    assert main(["run", "--scene", str(tmp_path / "wall.npy"), "--size", "16",
                 "--code-length", "1023", "--system-delay", "3.3e-9", "--range-gate", "1", "30",
                 "--signal", "0.1", "--noise", "0.002", "--no-figure",
                 "--save-ptu", str(tmp_path / "wall.ptu"), "--out", str(tmp_path / "r")]) == 0
    assert main(["calibrate", "--ptu", str(tmp_path / "wall.ptu"),
                 "--patterns", str(tmp_path / "wall_patterns.npy"),
                 "--code", str(tmp_path / "wall_code.npy"), "--bit-rate", "10e9",
                 "--distance", "25", "--out", str(tmp_path / "cal.json")]) == 0
    cal = json.loads((tmp_path / "cal.json").read_text())
    assert cal["target"]["model"] == "plane" and cal["target"]["phase_bins"] is not None
    assert cal["target"]["spread_bins"] == pytest.approx(11.9, abs=1.0)
    assert abs(cal["delay_s"] - 3.3e-9) < 0.02e-9  # a fifth of a bin
    assert cal["irf_fwhm_bins"] < 2.0  # the spread's smear read as the IRF: 7.6


def _sharp_wall(tmp_path, distance, delay, irf=None, seed=0):
    np.save(tmp_path / "w.npy", plane_ranges((16, 16), distance, 10.0))
    inst = ["--size", "16", "--code-length", "1023", "--signal", "1", "--noise", "0.02",
            "--compression", "0.5", "--system-delay", str(delay), "--seed", str(seed),
            *(["--irf", irf] if irf else [])]
    assert main(["run", "--scene", str(tmp_path / "w.npy"), *inst, "--range-gate",
                 str(distance - 1), str(distance + 2), "--save-ptu", str(tmp_path / "w.ptu"),
                 "--out", str(tmp_path / "r"), "--no-figure"]) == 0
    assert main(["calibrate", "--ptu", str(tmp_path / "w.ptu"),
                 "--patterns", str(tmp_path / "w_patterns.npy"),
                 "--code", str(tmp_path / "w_code.npy"), "--bit-rate", "10e9",
                 "--distance", str(distance), "--out", str(tmp_path / "c.json")]) == 0
    return json.loads((tmp_path / "c.json").read_text())


def test_a_sharp_walls_phase_is_scanned_where_the_linear_split_finds_a_plane(tmp_path):
    """At 10 m (16 x 16, 10 degrees, no jitter, a delay of 3.35 ns: the pulse in the second
    half of its bin) the linear split fitted a 1-bin spread for 4.5 and read the delay 0.72
    bin late, with an IRF 2.8 bins wide and no word (an audit: five of eight sub-bin delays
    so); the phase scan runs whatever the linear split found."""
    cal = _sharp_wall(tmp_path, 10.0, 3.35e-9)
    assert cal["target"]["phase_bins"] is not None
    assert cal["target"]["spread_bins"] == pytest.approx(4.5, abs=0.5)
    assert abs(cal["delay_s"] - 3.35e-9) < 0.01e-9  # a tenth of a bin
    assert cal["irf_fwhm_bins"] < 2.0


def test_a_delay_the_data_cannot_pin_down_is_said(tmp_path, capsys):
    """A 10-bin IRF's wall at 25 m (seed 1) is fitted at 1.2 deviations with a spread of 8
    bins for 11.9 and its delay 1.1 bins late: that was said nowhere (an audit). The spreads
    within one deviation of the best (1.5-11 bins) are read for the delay too, which moves
    by 2.4 bins over them (3.31-3.66 ns against 3.41 fitted): said, with the way out, and
    kept in the JSON."""
    cal = _sharp_wall(tmp_path, 25.0, 3.30e-9, irf="gaussian:1e-9", seed=1)
    lo, hi = cal["target"]["spread_band_bins"]
    assert lo < cal["target"]["spread_bins"] < hi
    band = [d for d in cal["target"]["delay_band_s"] if d is not None]
    assert max(abs(d - cal["delay_s"]) for d in band) > 0.25e-10  # a quarter of a bin
    err = capsys.readouterr().err
    assert "cannot tell the wall's spread" in err and "--fov" in err


def test_a_delay_the_data_pin_down_is_not_doubted(tmp_path, capsys):
    """A sharp wall at 7 m (7 degrees, 0.1 photons per pulse) fitted at 2.4 deviations has its
    delay within 0.01 bin: the warning by deviations alone doubted it (a review); read by
    the delay over the spreads the data allow, nothing is said."""
    np.save(tmp_path / "w.npy", plane_ranges((16, 16), 7.0, 7.0))
    inst = ["--size", "16", "--code-length", "1023", "--signal", "0.1", "--noise", "0.02",
            "--compression", "0.5", "--system-delay", "3.3625e-9"]
    assert main(["run", "--scene", str(tmp_path / "w.npy"), *inst, "--range-gate", "5", "10",
                 "--save-ptu", str(tmp_path / "w.ptu"), "--out", str(tmp_path / "r"),
                 "--no-figure"]) == 0
    capsys.readouterr()
    assert main(["calibrate", "--ptu", str(tmp_path / "w.ptu"),
                 "--patterns", str(tmp_path / "w_patterns.npy"),
                 "--code", str(tmp_path / "w_code.npy"), "--bit-rate", "10e9",
                 "--distance", "7", "--out", str(tmp_path / "c.json")]) == 0
    cal = json.loads((tmp_path / "c.json").read_text())
    assert abs(cal["delay_s"] - 3.3625e-9) < 0.01e-9
    assert "spread" not in capsys.readouterr().err


def test_a_tilted_wall_seen_without_jitter_is_fitted(tmp_path):
    """A wall turned 5 degrees about the vertical axis (16 x 16, 25 m, 10 degrees, seed 1,
    no jitter) was read as one range, its IRF 10 bins wide and its delay 2.0 bins early (an
    audit): a response narrower than a bin leaves the tilt scan's coarse grid a flat
    residual. The tilt is scanned on the responses smoothed over 1.5 bins, then the pulse's
    place in its bin fitted on them as they are."""
    np.save(tmp_path / "w.npy", plane_ranges((16, 16), 25.0, 10.0,
                                             slopes=(np.tan(np.radians(5.0)), 0.0)))
    inst = ["--size", "16", "--code-length", "1023", "--signal", "1", "--noise", "0.02",
            "--compression", "0.5", "--system-delay", "3.3e-9", "--seed", "1"]
    assert main(["run", "--scene", str(tmp_path / "w.npy"), *inst, "--range-gate", "23", "28",
                 "--save-ptu", str(tmp_path / "w.ptu"), "--out", str(tmp_path / "r"),
                 "--no-figure"]) == 0
    assert main(["calibrate", "--ptu", str(tmp_path / "w.ptu"),
                 "--patterns", str(tmp_path / "w_patterns.npy"),
                 "--code", str(tmp_path / "w_code.npy"), "--bit-rate", "10e9",
                 "--distance", "25", "--out", str(tmp_path / "c.json")]) == 0
    cal = json.loads((tmp_path / "c.json").read_text())
    assert cal["target"]["tilt_bins"][0] == pytest.approx(12.7, abs=1.0)  # seeds 0-1: 12.5-13.0
    assert abs(cal["delay_s"] - 3.3e-9) < 0.02e-9 and cal["irf_fwhm_bins"] < 2.0
