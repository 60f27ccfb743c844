"""An image of noise is said to be one: ``peak_to_noise`` and the pipeline's warning.

The depth estimators' no-return rule is relative to the brightest pixels, so a black scene, a
range gate that misses the scene or too little signal came out as a full depth map with 0 %
of pixels without a return and no word of it.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import spslidar
from spslidar.cli import main
from spslidar.depth.profile import (
    NOISE_ONLY_MARGIN,
    NOISE_ONLY_MIN_SLICES,
    NOISE_VERDICT_PIXELS,
    effective_slices,
    noise_only_ratio,
    peak_to_noise,
)

WARNING = "the depth map is mostly noise"


def test_peak_to_noise_on_profiles_of_known_peaks():
    """The tallest pulse-filtered slice over the tallest one outside +-2 slices of it."""
    x = np.zeros((4, 30))
    x[0, 5], x[0, 20] = 10.0, 4.0  # 10 / 4 (isolated spikes: the filter keeps their heights)
    x[1, 5], x[1, 6] = 3.0, 3.0    # a split return (filtered 4.5 at both) and no noise: inf
    x[1, 25] = 0.0
    x[3, 10], x[3, 11], x[3, 25] = 2.0, 2.0, 1.0  # filtered peak 3.0, noise maximum 1.0
    r = peak_to_noise(x)
    assert r[0] == pytest.approx(2.5)
    assert r[1] == np.inf
    assert r[2] == 1.0  # an empty profile says nothing of a return
    assert r[3] == pytest.approx(3.0)
    np.testing.assert_array_equal(peak_to_noise(x, block=1), r)  # blocks change nothing
    assert np.all(peak_to_noise(np.ones((3, 5))) == 1.0)  # no room beside the peak


def test_noise_only_ratio_falls_with_the_number_of_slices():
    """Non-negative white noise: the peak over the noise maximum beside it, 90th percentile,
    falls as the noise maximum is taken over more slices (measured 2.45 at 16 slices, 1.48 at
    68, 1.23 at 1023; a fixed threshold would miss noise at a narrow gate), is NaN where too
    few slices are left beside the peak, and does not depend on the draw by more than the
    4096-pixel sampling error (under 0.05)."""
    r = [noise_only_ratio(k) for k in (16, 28, 68, 200, 1023)]
    assert np.all(np.diff(r) < 0)
    assert 2.2 < r[0] < 2.8 and 1.1 < r[-1] < 1.4
    assert np.isnan(noise_only_ratio(NOISE_ONLY_MIN_SLICES - 1))
    assert noise_only_ratio(68, pixels=4096, seed=3) == pytest.approx(r[2], abs=0.05)


def test_effective_slices_counts_correlated_noise_as_fewer():
    """Non-negative white noise is its own reference (within the draw's error); the same
    noise averaged over 3 lags, as a spread IRF's matched filter correlates it, counts as
    fewer slices (its integrated autocorrelation is longer), and never as more than K."""
    rng = np.random.default_rng(11)
    white = np.maximum(rng.standard_normal((4096, 120)), 0.0)
    assert 108 <= effective_slices(white) <= 120
    g = rng.standard_normal((4096, 122))
    smooth = np.maximum((g[:, :-2] + g[:, 1:-1] + g[:, 2:]) / 3.0, 0.0)
    assert effective_slices(smooth) < 0.75 * 120
    assert effective_slices(white[:, :10]) == 10  # too few to judge: K itself


def test_noise_verdict_of_a_large_image_reads_a_fixed_subset():
    """Beyond NOISE_VERDICT_PIXELS pixels the verdict reads a fixed random subset: the same
    verdict on every call, equal to the full image's within the percentile's sampling error
    (the 90th percentile of 40 000 pixels against 32 768 of them), and an image of noise with
    a tenth of its pixels holding a strong return on either side of the floor as it should."""
    from spslidar.depth.profile import noise_verdict

    rng = np.random.default_rng(5)
    q, k = 40_000, 40
    assert q > NOISE_VERDICT_PIXELS
    noise = np.maximum(rng.standard_normal((q, k)), 0.0)
    a, b = noise_verdict(noise), noise_verdict(noise)
    full = noise_verdict(noise, max_pixels=q)
    assert a == b and a[0] != full[0]  # the subset is read, and the same one each time
    assert a[0] == pytest.approx(full[0], rel=0.02) and a[1] == pytest.approx(full[1], rel=0.02)
    assert a[0] < a[1]  # noise: under the floor
    scene = noise.copy()
    scene[::5, 20] += 30.0  # a fifth of the pixels hold a return
    s = noise_verdict(scene)
    assert s[0] > s[1]


def _warned(result) -> list[str]:
    return [w for w in result.warnings if w.startswith(WARNING)]


def _black(tmp_path):
    depth = np.full((16, 16), 12.0)
    depth[4:10, 4:10] = 11.0
    np.savez(tmp_path / "black.npz", depth=depth, reflectivity=np.zeros((16, 16)))
    return str(tmp_path / "black.npz")


@pytest.mark.parametrize("gate", [None, (11.85, 12.15)])
def test_a_black_scene_is_said_to_be_noise(tmp_path, gate):
    """A scene that reflects nothing, through its default gate (73 slices) and a narrow one
    (22 slices, where noise alone reaches 2.3-2.4, above any fixed threshold that the default
    gate's 1.7-1.8 would suggest): the map is nearly full (the relative no-return rule keeps
    the pixels) and the run says, once, that it is noise."""
    r = spslidar.run(scene=_black(tmp_path), size=16, code_length=1023, seed=1,
                     range_gate=gate)
    assert np.mean(np.isfinite(r.depth)) > 0.9
    assert r.metrics["peak_to_noise_p90"] < r.metrics["peak_to_noise_floor"]
    assert len(_warned(r)) == 1
    if gate is None:
        assert "range gate 10.955-12.045 m" in _warned(r)[0]


def test_too_narrow_a_gate_is_not_judged(tmp_path):
    """Under 16 slices too few are left beside a peak to tell a return from noise: no
    verdict (None), and a warning that says the check did not run (it ran silently)."""
    r = spslidar.run(scene=_black(tmp_path), size=16, code_length=1023, seed=1,
                     range_gate=(11.95, 12.05))
    assert r.metrics["n_slices"] < NOISE_ONLY_MIN_SLICES
    assert r.metrics["peak_to_noise_p90"] is None and not _warned(r)
    said = [w for w in r.warnings if "too few beside a return" in w]
    assert len(said) == 1 and "11.95-12.05 m holds" in said[0]


def test_a_flat_wall_of_noise_is_judged_through_its_default_gate(tmp_path):
    """A flat wall's window padded by three bins held 8 slices, so an image of pure noise
    (m_s = 1e-6) was reported as a wall (RMSE 0.034 m, mean reflectivity 8e5) with no word
    (found by a sweep of unusual regimes). The default gate now holds at least 16 slices;
    the wall itself stays where it was (0.0046 m at 8 and at 20 slices)."""
    wall = tmp_path / "wall.npy"
    np.save(wall, np.full((32, 32), 12.0))
    noise = spslidar.run(scene=str(wall), size=32, code_length=1023, seed=0, signal=1e-6)
    assert noise.metrics["n_slices"] >= NOISE_ONLY_MIN_SLICES
    assert len(_warned(noise)) == 1
    lit = spslidar.run(scene=str(wall), size=32, code_length=1023, seed=0)
    assert not _warned(lit) and lit.depth_rmse < 0.0075  # half a bin
    assert not any("too few beside a return" in w for w in lit.warnings)


@pytest.mark.parametrize("k", [1, 2, 3, 4, 5])
def test_a_gate_of_a_few_slices_runs_without_a_verdict(tmp_path, k, capsys):
    """Gates of 2-3 slices ended in a traceback: the noise's autocorrelation was read at lags
    up to 4 whatever the number of slices (found by a user's ``--range-gate 20.4 20.41``).
    The statistics take the lags there are; the CLI runs, with no verdict."""
    rng = np.random.default_rng(k)
    from spslidar.depth.profile import _noise_stats, noise_verdict

    ratio, tau = _noise_stats(rng.random((64, k)))
    assert ratio.shape == (64,) and np.isfinite(tau)
    assert noise_verdict(rng.random((64, k))) is None
    bw = 3e8 / 2 / 10e9  # a bin at the default 10 Gb/s, in metres
    gate = ["20.4", f"{20.4 + (k - 0.5) * bw:.6f}"]
    assert main(["run", "--size", "8", "--code-length", "1023", "--no-figure",
                 "--out", str(tmp_path / "o"), "--range-gate", *gate]) == 0
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["n_slices"] <= k + 3 and m["peak_to_noise_p90"] is None


def test_a_range_gate_that_misses_the_scene_is_said_to_be_noise():
    """The camera (20-20.8 m by default) through a gate at 30-31 m; through its own gate it
    stands far above the noise (11.6 at 32x32, 7-13 at 64x64 with m_n = 10)."""
    missed = spslidar.run(size=32, range_gate=(30.0, 31.0), seed=1)
    assert _warned(missed)
    seen = spslidar.run(size=32, seed=1)
    assert not _warned(seen)
    assert seen.metrics["peak_to_noise_p90"] > 2 * seen.metrics["peak_to_noise_floor"]
    assert seen.metrics["peak_to_noise_floor"] == pytest.approx(
        NOISE_ONLY_MARGIN * noise_only_ratio(effective_slices(seen.slices)))


def test_the_warning_reaches_the_cli_and_metrics(tmp_path, capsys):
    assert main(["run", "--scene", _black(tmp_path), "--size", "16",
                 "--code-length", "1023", "--no-figure", "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert err.count(f"spslidar: warning: {WARNING}") == 1
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert any(w.startswith(WARNING) for w in m["warnings"])
    assert m["peak_to_noise_p90"] < m["peak_to_noise_floor"]


def test_the_figure_title_says_so(tmp_path):
    """depth.png's title said "100% of pixels" of an image of noise; it now says that no
    return stands above the noise, and says nothing of it for a scene."""
    from spslidar.figures import _title

    r = spslidar.run(scene=_black(tmp_path), size=16, code_length=1023, seed=1)
    assert "MOSTLY NOISE" in _title(r)
    assert "MOSTLY NOISE" not in _title(spslidar.run(size=16, code_length=1023, seed=1))


def test_a_small_object_in_an_empty_field_is_what_the_warning_says(tmp_path):
    """The verdict reads the brightest tenth of the pixels: a 3x3 target (0.9 % of a 32x32
    field, the rest black) is called mostly noise, and the warning says at most a tenth of the
    pixels hold a return, which is what is true of it; its own pixels keep their depth."""
    depth = np.full((32, 32), 12.0)
    depth[:, :16] = 11.0
    refl = np.zeros((32, 32))
    refl[5:8, 5:8] = 1.0
    np.savez(tmp_path / "small.npz", depth=depth, reflectivity=refl)
    r = spslidar.run(scene=str(tmp_path / "small.npz"), size=32, seed=1)
    assert len(_warned(r)) == 1 and "at most a tenth of the pixels hold a return" in _warned(r)[0]
    err = np.abs(r.depth[5:8, 5:8] - 11.0)
    assert np.all(err < 0.05)  # 3 bins (1.5 cm each)


# ---------------------------------------------------------------- the automatic range gate
# (gates of more than 256 delays are pruned to the occupied ones before the solve; an audit of
# 2026-11-29 found that a gate in which none rose kept the noisiest delay, whose profiles,
# zero at every other delay, read as returns at full confidence: a black scene 30-35 m away
# came out a wall at 35.0 m over 92 % of the pixels, 0.4 % low-confidence, said nowhere)

AUTO = "the automatic range gate found no delay"


def test_occupied_lags_keeps_nothing_where_nothing_rises():
    """Pure noise: no delay 5 sigma above the median (358 delays of N(0, 1) correlations,
    whose largest mean over 64 patterns stands about 3 sigma up), so the mask is empty; a
    return 10 sigma up is kept with two delays either side."""
    from spslidar.pipeline.gate import occupied_lags

    rng = np.random.default_rng(3)
    corr, sigma = rng.standard_normal((64, 358)), np.ones(64)
    assert not occupied_lags(corr, sigma).any()
    corr[:, 100] += 10.0 / np.sqrt(64) * 8  # the mean rises 10 of its sigmas (1/8)
    assert np.flatnonzero(occupied_lags(corr, sigma)).tolist() == [98, 99, 100, 101, 102]


def test_with_reference_samples_the_noise_beside_the_occupied_delays():
    """Up to 32 delays, evenly spaced, none within the margin of an occupied one; the
    occupied ones kept; an empty mask gets the sample alone; no room, nothing added."""
    from spslidar.pipeline.gate import AUTO_GATE_REFERENCE, with_reference

    keep = np.zeros(1000, dtype=bool)
    keep[500:505] = True
    out = with_reference(keep)
    added = np.flatnonzero(out & ~keep)
    assert out[500:505].all() and added.size == AUTO_GATE_REFERENCE
    assert np.min(np.abs(added[:, None] - np.arange(500, 505)[None, :])) > 2
    assert np.ptp(np.diff(added)) <= 35  # evenly spread (the occupied run and margin skipped)
    assert with_reference(np.zeros(40, dtype=bool)).sum() == 32
    assert not (with_reference(np.ones(40, dtype=bool)) ^ np.ones(40, dtype=bool)).any()


def _far_black(tmp_path):
    x = np.arange(16)[None, :] * np.ones((16, 1))
    np.savez(tmp_path / "far.npz", depth=30 + 0.35 * x, reflectivity=np.zeros((16, 16)))
    return str(tmp_path / "far.npz")


def test_a_black_scene_through_an_automatic_gate_has_no_return(tmp_path):
    """The audit's scene (358 delays, so the gate is automatic): it is said that nothing
    rises, the verdict reads the noise's sample (it read zeros: 1000, the cap, against a
    floor of 1.7) and calls the map noise, and no pixel is given a depth."""
    r = spslidar.run(scene=_far_black(tmp_path), size=16, seed=0)
    assert r.metrics["auto_gate"] and r.metrics["n_slices"] > 256
    assert sum(w.startswith(AUTO) for w in r.warnings) == 1
    assert len(_warned(r)) == 1 and "the 32 slices solved of" in _warned(r)[0]
    assert r.metrics["peak_to_noise_p90"] < r.metrics["peak_to_noise_floor"]
    assert not np.isfinite(r.depth).any()


def test_a_dim_wide_scene_through_an_automatic_gate_is_said_to_be_noise(tmp_path):
    """A 3-20 m ramp with a box at 5 m at m_s = 0.05: came back a confident wall (RMSE
    7.8 m, 0.4 % low-confidence, no word); through --no-auto-gate it was said to be noise.
    Both say so now."""
    y = np.mgrid[0:16, 0:16][0]
    d = 3 + 17 * y / 15
    d[4:9, 4:8] = 5.0
    np.save(tmp_path / "ramp.npy", d)
    for auto in (None, False):
        r = spslidar.run(scene=str(tmp_path / "ramp.npy"), size=16, signal=0.05, seed=0,
                         auto_gate=auto)
        assert r.metrics["auto_gate"] is (auto is None)
        assert len(_warned(r)) == 1, auto


def test_the_noise_sample_leaves_a_lit_scenes_depths_as_they_were(monkeypatch):
    """Solved beside the occupied delays, the sample is read by the verdict and then left
    out: the camera (20-20.8 m) through a 15-40 m gate (1670 delays, 59 occupied) gives the
    depth map it gives without the sample, and no noise verdict."""
    import spslidar.pipeline.chain as chain

    with_sample = spslidar.run(size=32, range_gate=(15.0, 40.0), seed=1)
    assert with_sample.metrics["auto_gate"] and not _warned(with_sample)
    monkeypatch.setattr(chain, "with_reference", lambda keep: keep)
    without = spslidar.run(size=32, range_gate=(15.0, 40.0), seed=1)
    assert with_sample.metrics["n_slices_solved"] == without.metrics["n_slices_solved"] + 32
    # the same depths (the solve's columns are independent problems; its stopping rule reads
    # them all, so a few pixels may differ by a bin's fraction)
    same = np.isclose(with_sample.depth, without.depth, atol=1e-3, equal_nan=True)
    assert same.mean() > 0.99
    assert with_sample.depth_rmse == pytest.approx(without.depth_rmse, rel=0.02)


def test_the_unipolar_plateau_of_an_automatic_gate_is_read_over_the_delays_solved():
    """The plateau a unipolar replica leaves was removed after the noise sample was taken,
    and over the whole gate, whose unsolved delays are zeros: a 2.8 cm map was called noise
    and its reflectivity read 3.61 for 0.83 (a review). Now the automatic gate reads as the
    full one."""
    from spslidar.pipeline.chain import measure, reconstruct

    m = measure(size=32, code_length=2047, replica="unipolar", seed=1, depth_min=10,
                depth_max=10.3, range_gate=(8.0, 14.0))
    auto, full = reconstruct(m), reconstruct(m, auto_gate=False)
    assert auto.metrics["auto_gate"] and not _warned(auto) and not _warned(full)
    assert auto.metrics["mean_reflectivity"] == pytest.approx(
        full.metrics["mean_reflectivity"], rel=0.05)
    assert auto.depth_rmse < 0.04


def test_a_forced_automatic_gate_says_how_many_slices_it_solved(tmp_path):
    """A 19-slice gate forced automatic solved 15: the warning said the gate "holds 15
    slices" and to widen it; it now says 15 of 19 were solved, and --no-auto-gate."""
    np.save(tmp_path / "flat.npy",
            np.where(np.arange(16)[None, :] < 8, 10.0, 10.05) * np.ones((16, 1)))
    r = spslidar.run(scene=str(tmp_path / "flat.npy"), size=16, range_gate=(9.9, 10.16),
                     auto_gate=True, seed=0)
    (said,) = [w for w in r.warnings if "to tell it from noise" in w]
    n, k = r.metrics["n_slices_solved"], r.metrics["n_slices"]
    assert f"solved {n} of the {k} slices" in said and "--no-auto-gate" in said and n < k


def test_an_empty_map_s_figure_title_says_there_is_no_depth_to_score(tmp_path):
    """depth.png's title of a map without any depth read "RMSE = nan m over 0% of pixels"
    (an empty automatic gate makes one); it says what the summary line says."""
    from spslidar.figures import _title

    r = spslidar.run(scene=_far_black(tmp_path), size=16, seed=0)
    assert "no depth to score" in _title(r) and "nan" not in _title(r)


@pytest.mark.parametrize("light, said", [(["--noise", "1000", "--signal", "0.001"], True),
                                         (["--noise", "1000", "--signal", "0.03"], False),
                                         (["--noise", "10"], False)])
def test_a_noiseless_runs_float32_rounding_of_its_background_is_said(tmp_path, capsys, light,
                                                                     said):
    """A noiseless run's expected counts are float32: under a background of 2.6e5 counts a
    bin their rounding outweighed the signal (RMSE 0.19-0.21 m against 0.0015 m without the
    background; an audit of 2026-11-29) with no word. It is said where it reaches a tenth of
    a pixel's signal (measured: 0.12 of it, 0.0095 m; 0.04, 0.0015 m)."""
    assert main(["run", "--scene", "steps", "--size", "16", "--noiseless", "--compression", "1",
                 *light, "--no-figure", "--out", str(tmp_path / "o")]) == 0
    assert ("rounding of its background" in capsys.readouterr().err) is said


def test_the_device_path_says_the_noiseless_rounding_too(tmp_path, capsys):
    """The array-API simulation's noiseless branch gave the same 0.20 m map without the
    host's warning (a review)."""
    assert main(["run", "--scene", "steps", "--size", "16", "--noiseless", "--compression", "1",
                 "--noise", "1000", "--signal", "0.001", "--backend", "array-api-strict",
                 "--no-figure", "--out", str(tmp_path / "o")]) == 0
    assert "rounding of its background" in capsys.readouterr().err


def test_a_measured_map_of_noise_prints_no_mean_reflectivity(tmp_path, capsys):
    """A map of noise has no reflectivity to speak of: ``reconstruct`` printed its mean
    beside the warning (37 photons per pulse for a true 1 at m_s = 0.01, an audit); a map
    with returns still prints it."""
    ptu = tmp_path / "a.ptu"
    common = ["--size", "16", "--code-length", "1023", "--noise", "0.02", "--no-figure",
              "--save-ptu", str(ptu)]
    rec = ["reconstruct", "--ptu", str(ptu), "--patterns", str(tmp_path / "a_patterns.npy"),
           "--code", str(tmp_path / "a_code.npy"), "--bit-rate", "10e9", "--range-gate",
           "19.9", "20.9", "--no-figure"]
    for signal, noisy in (("0.003", True), ("1", False)):
        assert main(["run", *common, "--signal", signal, "--out", str(tmp_path / f"r{signal}"),
                     "--overwrite"]) == 0
        capsys.readouterr()
        assert main([*rec, "--out", str(tmp_path / f"q{signal}")]) == 0
        out, err = capsys.readouterr()
        assert (WARNING in err) is noisy
        assert ("mean reflectivity" in out) is not noisy, out


def test_the_confidence_panel_of_a_map_of_noise_says_it_is_per_pixel(tmp_path, capsys):
    """depth.png without a truth showed 93 % of a map of noise confident under its MOSTLY
    NOISE title (an outside audit on a real file): each pixel's confidence reads its profile
    against its own noise, and the panel says the map is noise; a map with returns keeps the
    plain title."""
    from spslidar.figures import _panels
    from spslidar.pipeline.real import reconstruct_ptu

    ptu = tmp_path / "a.ptu"
    titles = {}
    for signal in ("0.003", "1"):
        assert main(["run", "--size", "16", "--code-length", "1023", "--noise", "0.02",
                     "--no-figure", "--save-ptu", str(ptu), "--signal", signal, "--out",
                     str(tmp_path / f"r{signal}"), "--overwrite"]) == 0
        r = reconstruct_ptu(ptu, tmp_path / "a_patterns.npy", tmp_path / "a_code.npy", 10e9,
                            (19.9, 20.9))
        titles[signal] = next(p[1] for p in _panels(r) if p[0] == "confidence")
    assert titles == {"0.003": "confidence (per pixel; the map is mostly noise)",
                      "1": "confidence"}


def test_pixels_beyond_a_given_gate_are_said_to_read_ghost_depths(tmp_path):
    """A 5-60 m ramp through a 20-40 m gate: 458 of its 672 pixels outside the gate were given
    depths inside it with a median confidence of 0.95 (an outside audit of scenes), under a
    warning that said only that their returns "alias into the gate or are lost". It says
    that such pixels may read depths the confidence does not flag."""
    np.save(tmp_path / "wide.npy", np.tile(np.linspace(5, 60, 16), (16, 1)))
    r = spslidar.run(scene=str(tmp_path / "wide.npy"), size=16, code_length=2047,
                     range_gate=(20, 40), seed=0)
    (said,) = [w for w in r.warnings if "lie outside the range gate" in w]
    assert "depths inside the gate all the same" in said and "widen the gate" in said
    outside = (r.truth < 20) | (r.truth > 40)
    assert np.isfinite(r.depth[outside]).mean() > 0.3  # (what the warning says may happen)
