"""The Python API under a notebook user's inputs (an outside audit of 2026-12-02): what was a
silent wrong result, an edited result saved beside its old metrics, or a loop over a window
no slice reaches, is now refused in one line or done right."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spslidar.errors import ConfigError


@pytest.fixture(scope="module")
def result():
    import spslidar

    return spslidar.run(scene="camera", size=8, code_length=255, noise=1, seed=0)


def test_a_results_arrays_are_read_only_and_its_files_agree_with_its_metrics(result, tmp_path):
    """depth.npy was saved as edited (all zeros) under metrics.json's RMSE of the run."""
    for name in ("depth", "confidence", "low_confidence", "reflectivity", "slices", "corr",
                 "lags"):
        a = getattr(result, name)
        assert not a.flags.writeable, name
        with pytest.raises(ValueError, match="read-only"):
            a[(0,) * a.ndim] = 0
    out = result.save(tmp_path / "run", figure=False)
    depth = np.load(out / "depth.npy")
    rmse = json.loads((out / "metrics.json").read_text())["depth_rmse_m"]
    ok = np.isfinite(depth) & np.isfinite(result.truth)
    assert np.sqrt(np.mean((depth - result.truth)[ok] ** 2)) == pytest.approx(rmse, rel=1e-9)


def test_an_array_put_into_a_result_stays_the_callers_to_edit(result):
    """The result holds a read-only view; the caller's own array is not frozen."""
    import dataclasses

    mine = np.array(result.depth)
    r = dataclasses.replace(result, depth=mine)
    assert not r.depth.flags.writeable and mine.flags.writeable
    mine[0, 0] = 7.0  # the caller's edit of its own array is its choice, and it shows
    assert r.depth[0, 0] == 7.0


def test_matched_filter_refuses_an_integer_output_dtype():
    """out_dtype=int truncated the correlations (3.03 to 3)."""
    from spslidar.correlate import make_replica, matched_filter

    code = np.array([1, 0, 1, 1, 0, 0, 1, 0], float)
    f = make_replica(code)
    hist = np.random.default_rng(0).poisson(3.0, (2, 8)).astype(float)
    good = matched_filter(hist, f, np.arange(8), out_dtype=np.float64)
    assert good.dtype == np.float64
    for bad in (int, np.int32, complex, "text"):
        with pytest.raises(ValueError, match="out_dtype"):
            matched_filter(hist, f, np.arange(8), out_dtype=bad)


def test_correlation_noise_sigma_refuses_a_replica_of_another_length():
    from spslidar.correlate import correlation_noise_sigma

    hist = np.ones((3, 8))
    assert correlation_noise_sigma(hist, np.ones(8)).shape == (3,)
    with pytest.raises(ValueError, match="replica of shape"):
        correlation_noise_sigma(hist, np.ones(7))


def test_write_ply_takes_one_string_as_one_comment(tmp_path):
    """A string was written one header line per character."""
    from spslidar.products import write_ply

    path = write_ply(tmp_path / "p.ply", np.zeros((2, 3)), np.ones(2), comments="my scan")
    head = path.read_bytes().split(b"end_header")[0].decode()
    assert "comment my scan\n" in head
    assert "comment m\n" not in head


def test_reflectivity_image_reads_only_the_offsets_that_reach_a_slice():
    """A half_window of 10**12 did not end; any window past the gate sums the same slices."""
    from spslidar.products import reflectivity_image

    rng = np.random.default_rng(1)
    slices = rng.random((4, 10))
    depth = np.full(4, 0.015 * 1003.5)  # inside the gate of lags 1000-1009 at 100 ps
    lags = np.arange(1000, 1010)
    wide = reflectivity_image(slices, depth, lags, 1e-10, half_window=10)
    assert np.allclose(wide, slices.sum(axis=1))
    huge = reflectivity_image(slices, depth, lags, 1e-10, half_window=10 ** 12)
    assert np.array_equal(huge, wide)


def test_rays_and_points_refuse_what_gave_empty_or_dropped_points():
    from spslidar.products import pixel_rays, point_cloud

    with pytest.raises(ValueError, match="shape"):
        pixel_rays((-2, 4), 10.0)
    depth = np.full((2, 2), 3.0)
    assert point_cloud(depth)[0].shape == (4, 3)
    depth[0, 0] = np.inf
    with pytest.raises(ValueError, match="infinite"):
        point_cloud(depth)


@pytest.mark.parametrize("width", [np.nan, -1.0, 0.0, "0.5", None])
def test_lag_to_depth_refuses_a_pulse_width_that_is_not_positive(width):
    """NaN made every depth NaN ('no return'); -1 shifted every depth."""
    from spslidar.forward import lag_to_depth

    assert np.isfinite(lag_to_depth(np.arange(3), 1e-10, 0.5)).all()
    with pytest.raises(ValueError, match="pulse_width"):
        lag_to_depth(np.arange(3), 1e-10, width)


@pytest.mark.parametrize("fraction", [2.0, -1.0, np.nan, "0.1"])
def test_ml_depth_refuses_a_peak_fraction_outside_0_1(fraction):
    """2 gave an all-NaN map, NaN and -1 were taken."""
    from spslidar.depth.argmax import ml_depth

    slices = np.random.default_rng(2).random((4, 6))
    lags = np.arange(100, 106)
    assert np.isfinite(ml_depth(slices, lags, 1e-10, min_peak_fraction=1.0)[0]).any()
    with pytest.raises(ValueError, match="min_peak_fraction"):
        ml_depth(slices, lags, 1e-10, min_peak_fraction=fraction)


def test_a_depth_context_takes_a_list_of_lags_and_refuses_a_bad_shape():
    """A list failed in estimate() on '.size'; (16, 16, 1) as 'too many values to unpack'."""
    from spslidar.depth import DepthContext
    from spslidar.depth.argmax import ArgmaxDepth

    slices = np.random.default_rng(3).random((4, 6))
    ctx = DepthContext(list(range(100, 106)), 1e-10, shape=(2, 2))
    ref = DepthContext(np.arange(100, 106), 1e-10, shape=(2, 2))
    assert isinstance(ctx.lags, np.ndarray)
    assert np.array_equal(ArgmaxDepth().estimate(slices, ctx).depth,
                          ArgmaxDepth().estimate(slices, ref).depth)
    for shape in ((16, 16, 1), (-2, 2), (2.5, 2), "22", (True, 2)):
        with pytest.raises(ConfigError, match="shape"):
            DepthContext(np.arange(100, 106), 1e-10, shape=shape)


def test_argmax_refuses_an_option_it_does_not_have():
    from spslidar.depth.argmax import ArgmaxDepth

    with pytest.raises(TypeError):
        ArgmaxDepth(foo=1)


def _counts_inputs():
    from spslidar.codes import make_code
    from spslidar.forward import depth_to_delay, return_amplitudes

    code = make_code("mseq", 127)
    delay = depth_to_delay(np.full((2, 2), 3.0), bin_width=1e-10)
    shifts, amp = return_amplitudes(np.ones((1, 4)), np.ones((2, 2)), delay, 0.5, code.size)
    return code, shifts, amp


def test_expected_counts_refuses_means_no_photon_count_has():
    from spslidar.codes import make_code
    from spslidar.forward import expected_counts, shifted_codes

    code, shifts, amp = _counts_inputs()
    lam = expected_counts(amp, shifts, code, 5.0, 0.1)
    assert lam.shape == (1, 127) and (lam >= 0).all()
    other = shifted_codes(make_code("mseq", 255), shifts)
    with pytest.raises(ValueError, match="code_matrix"):
        expected_counts(amp, shifts, code, 5.0, 0.1, code_matrix=other)
    with pytest.raises(ValueError, match="bits"):
        expected_counts(amp, shifts, np.arange(127.0), 5.0, 0.1)
    for noise in (-0.1, np.nan, np.inf):
        with pytest.raises(ValueError, match="noise_per_bin"):
            expected_counts(amp, shifts, code, 5.0, noise)
    for signal in (None, [5.0], "5", -1.0, np.nan):
        with pytest.raises(ValueError, match="signal"):
            expected_counts(amp, shifts, code, signal, 0.1)


@pytest.mark.parametrize("gate", [(20.0, 21.0, 99.0), "25", ("20", 21.0), (True, 21.0), [20.0]])
def test_gate_lags_takes_two_numbers(gate):
    """A 3-tuple's third value and a string were taken."""
    from spslidar.correlate import gate_lags

    assert gate_lags([20.0, 21.0], 1e-10).size == gate_lags((20.0, 21.0), 1e-10).size
    with pytest.raises(ConfigError, match="range gate"):
        gate_lags(gate, 1e-10)


@pytest.mark.parametrize("code", [[2, 2, 0], [1, -1, 1, -1], [0.5, 1, 0]])
def test_replicas_refuse_a_code_that_is_not_bits(code):
    """[2, 2, 0] was called balanced and given the bipolar replica."""
    from spslidar.correlate import auto_replica, make_replica

    assert auto_replica([1, 1, 0]) == "bipolar"
    with pytest.raises(ValueError, match="bits"):
        auto_replica(code)
    with pytest.raises(ValueError, match="bits"):
        make_replica(code)


def test_a_bit_rate_of_true_and_a_fractional_weighted_tv_shape_are_refused():
    from spslidar.codes import unambiguous_range
    from spslidar.solvers.weighted_tv import EdgeWeightedTV

    assert unambiguous_range(1023, 10e9) == pytest.approx(15.33, abs=0.01)
    with pytest.raises(ConfigError, match="bit rate"):
        unambiguous_range(1023, True)
    EdgeWeightedTV((4, 4), np.ones((3, 4)), np.ones((4, 3)))
    with pytest.raises(ValueError, match="image_shape"):
        EdgeWeightedTV((4.7, 4), np.ones((3, 4)), np.ones((4, 3)))
    with pytest.raises(ValueError, match="max_inner"):
        EdgeWeightedTV((4, 4), np.ones((3, 4)), np.ones((4, 3)), max_inner=2.5)


def test_reflectivity_image_of_a_depth_far_beyond_the_gate_ends_and_agrees():
    """One pixel 3e7 bins beyond the gate, inside a window of 1e8 bins, kept a loop of 3e7
    turns (a review); both passes give the same sums as a plain reference."""
    from spslidar.forward import delay_to_depth
    from spslidar.products import reflectivity_image

    rng = np.random.default_rng(4)
    slices = rng.random((3, 10)) - 0.2
    lags = np.arange(1000, 1010)
    depth = delay_to_depth(np.array([1003.0, 1000.0 + 3e7, 1008.0]), 1e-10)  # slices 3, -, 8
    got = reflectivity_image(slices, depth, lags, 1e-10, half_window=10 ** 8)
    assert np.allclose(got, np.clip(slices, 0, None).sum(axis=1))
    narrow = reflectivity_image(slices, depth, lags, 1e-10, half_window=1)
    pos = np.clip(slices, 0, None)
    assert np.isclose(narrow[0], pos[0, 2:5].sum()) and np.isnan(narrow[1])
    assert np.isclose(narrow[2], pos[2, 7:10].sum())


def test_a_subclass_of_argmax_keeps_its_registered_options():
    """ArgmaxDepth's own refusal of options broke a plugin's subclass that declares one (the
    registry's documented pattern; a review)."""
    from spslidar.depth.argmax import ArgmaxDepth

    class Smooth(ArgmaxDepth):
        name = "smooth-argmax"

    assert Smooth(window=3).options == {"window": 3}
    with pytest.raises(TypeError, match="no options"):
        ArgmaxDepth(window=3)


def test_a_copied_or_unpickled_result_is_read_only_too(result):
    import copy
    import pickle

    for r in (copy.deepcopy(result), pickle.loads(pickle.dumps(result))):
        assert not r.depth.flags.writeable and not r.slices.flags.writeable
        np.testing.assert_array_equal(r.depth, result.depth)


def test_expected_counts_refuses_an_empty_code_as_the_replicas_do():
    from spslidar.correlate import make_replica
    from spslidar.forward import expected_counts

    for call in (lambda: make_replica([]),
                 lambda: expected_counts(np.ones((1, 1)), [0], [], 1.0, 0.1)):
        with pytest.raises(ValueError, match="code is empty"):
            call()


@pytest.mark.parametrize("shape", [(True, 4), (4.7, 4), (2.7, 3)])
def test_image_shapes_are_read_alike_everywhere(shape):
    """TV took (True, 4) as (1, 4); pixel_rays (2.7, 3) as (2, 3); DepthContext refused
    both (a review)."""
    from spslidar.depth import DepthContext
    from spslidar.products import pixel_rays
    from spslidar.solvers.regularisers import TV

    for call in (lambda: TV(shape), lambda: pixel_rays(shape, 10.0),
                 lambda: DepthContext(np.arange(3), 1e-10, shape=shape)):
        with pytest.raises(ConfigError, match="pair of whole numbers"):
            call()
