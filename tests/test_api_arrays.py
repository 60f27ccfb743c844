"""The chain's public helpers under the arrays a numpy user passes (an outside audit of the
Python API, 2026-11-29): integer and boolean inputs give the float answer, fractional or NaN
delays, complex numbers and mismatched shapes are refused in one line naming the argument,
and a run leaves the caller's warning filters as they were."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from spslidar import correlate as C
from spslidar import forward as F
from spslidar import metrics as M
from spslidar import products as PR
from spslidar import qcr as Q
from spslidar.codes.sequences import periodic_xcorr
from spslidar.depth import ml_depth
from spslidar.detectors import build_detector
from spslidar.operators import Gradient2D, Identity, MatrixOperator, Wavelet2D
from spslidar.pipeline.gate import occupied_lags, unique_lags
from spslidar.solvers import solve
from spslidar.solvers.regularisers import TV


def test_remove_plateau_reads_integer_and_boolean_profiles_as_numbers():
    # (cast back to the input's dtype: [[3, 1, 1]] came out [[2, 0, 0]], booleans all True)
    want = C.remove_plateau(np.array([[3.0, 1.0, 1.0]]), 0.3)
    np.testing.assert_allclose(C.remove_plateau(np.array([[3, 1, 1]]), 0.3), want)
    got = C.remove_plateau(np.array([[True, False, False]]), 0.3)
    assert got.dtype == np.float64
    np.testing.assert_allclose(got, C.remove_plateau(np.array([[1.0, 0.0, 0.0]]), 0.3))
    assert C.remove_plateau(np.ones((2, 3), np.float32), 0.3).dtype == np.float32
    with pytest.raises(ValueError, match="slices must have 2 dimensions"):
        C.remove_plateau(np.ones(5), 0.3)


def test_write_ply_refuses_points_that_are_not_rows_of_xyz(tmp_path):
    pts = np.arange(15.0).reshape(5, 3)
    PR.write_ply(tmp_path / "a.ply", pts, np.arange(5.0))
    np.testing.assert_allclose(PR.read_ply(tmp_path / "a.ply")[0], pts)  # float32 exact here
    for bad in (pts.T, pts.ravel()[:6]):  # ((3, N) was written as scrambled points)
        with pytest.raises(ValueError, match=r"points must be \(P, 3\)"):
            PR.write_ply(tmp_path / "b.ply", bad, np.arange(bad.shape[-1] if bad.ndim == 2
                                                            else 2.0))
    assert not (tmp_path / "b.ply").exists()


@pytest.mark.parametrize("call", [
    lambda lags: C.replica_matrix(np.ones(31), lags),
    lambda lags: F.shifted_codes(np.ones(31), lags),
    lambda lags: unique_lags(lags, 31),
])
def test_fractional_or_nan_delays_are_refused(call):
    # (1.9 was read as bin 1, a NaN as an arbitrary bin, 1.5 / 2.5 as "distinct" delays)
    for lags in ([1.9], [np.nan], np.array([1.5, 2.5, 33.5])):
        with pytest.raises(ValueError, match="whole bins"):
            call(lags)
    call(np.array([1.0, 2.0]))  # whole numbers in a float array are delays


def test_unique_lags_needs_a_period():
    with pytest.raises(ValueError, match="period must be a whole number"):
        unique_lags(np.arange(4), 0)


def test_ml_depth_checks_its_delays_as_the_estimators_do():
    sl = np.zeros((4, 3))
    sl[:, 2] = 1.0
    with pytest.raises(ValueError, match="increasing"):
        ml_depth(sl, np.array([12, 11, 10]), 1e-9)
    with pytest.raises(ValueError, match="finite delays"):
        ml_depth(sl, np.full(3, np.nan), 1e-9)
    with pytest.raises(ValueError, match="bin_width must be a positive number"):
        ml_depth(sl, np.arange(3), "1e-9")
    d, _ = ml_depth(sl, np.array([10, 11, 12]), 1e-9)
    np.testing.assert_allclose(d, F.delay_to_depth(12 + 0.5 - 0.25, 1e-9))


def test_reflectivity_image_checks_its_delays_and_window():
    slices = np.arange(26.0)[None, :].repeat(2, axis=0)
    depth = np.full(2, F.delay_to_depth(110.0, 1e-10))
    lags = np.arange(100, 126)
    want = PR.reflectivity_image(slices, depth, lags, 1e-10)
    np.testing.assert_allclose(want, [9.0 + 10 + 11] * 2)
    for bad, why in ((lags[:5], "5 lags for slices of 26"),
                     (np.arange(100, 130), "30 lags for slices of 26"),
                     (lags[::-1], "consecutive"),
                     (lags.astype(float) + 0.5 * (lags % 2), "consecutive")):
        with pytest.raises(ValueError, match=why):
            PR.reflectivity_image(slices, depth, bad, 1e-10)
    for hw in (-1, 1.5, True):
        with pytest.raises(ValueError, match="half_window"):
            PR.reflectivity_image(slices, depth, lags, 1e-10, half_window=hw)
    # a calibrated acquisition's delays hold a fraction of a bin: still consecutive
    PR.reflectivity_image(slices, depth, lags + 0.37, 1e-10)


def test_pulse_overlaps_refuses_a_nan_delay():
    # (bin -2^63 with a NaN weight and numpy's cast warning)
    with pytest.raises(ValueError, match="delay holds a NaN"):
        F.pulse_overlaps(np.array([np.nan]), 0.5)


@pytest.mark.parametrize("call", [
    lambda z: C.matched_filter(z * np.ones((2, 7)), np.ones(7), [0, 1]),
    lambda z: C.make_replica(z * np.ones(7)),
    lambda z: Q.qcr_problem(np.eye(3), z * np.ones((3, 2))),
    lambda z: Q.qcr_delta(np.eye(3), z * np.ones((3, 2))),
    lambda z: M.depth_errors(z * np.ones(4), np.ones(4)),
    lambda z: M.sobel_edges(z * np.ones((4, 4))),
    lambda z: PR.point_cloud(np.ones((2, 2)), 10, z * np.ones((2, 2))),
    lambda z: F.expected_counts(z * np.ones((1, 1)), [0], np.ones(7), 1.0, 0.1),
    lambda z: solve(MatrixOperator(np.eye(3)), z * np.ones((3, 1)), TV((3, 1)), 0.1),
    lambda z: build_detector("linear").detect(z * np.ones((2, 3)), 0),
    lambda z: build_detector("gmapd").detect(z * np.ones((2, 3)), np.random.default_rng(0)),
    lambda z: periodic_xcorr(z * np.ones(7), np.ones(7)),
])
def test_complex_input_is_refused_not_cast(call):
    call(1.0)  # the real input is taken
    with pytest.raises(ValueError, match="complex|real"):
        call(1.0 + 1e-3j)


@pytest.mark.parametrize("call, name", [
    (lambda: F.return_weights(np.ones(5), np.ones(4), 0.5, 31), "reflectivity"),
    (lambda: F.return_amplitudes(np.ones((4, 5)), np.ones(6), np.ones(6), 0.5, 31),
     "patterns"),
    (lambda: F.expected_counts(np.ones((3, 1)), [0], np.ones(7), 1.0, np.ones(4)),
     "noise_per_bin"),
    (lambda: F.expected_counts(np.ones((3, 2)), [0], np.ones(7), 1.0, 0.1), "amp"),
    (lambda: C.correlation_noise_sigma(np.ones(7), np.ones(7)), "hist"),
    (lambda: C.correlation_gain(np.ones(3), np.ones(4)), "replica"),
    (lambda: C.replica_plateau(np.ones((2, 3)), "unipolar"), "code"),
    (lambda: C.matched_filter(np.ones((2, 7)), np.ones(7), np.ones((2, 2), int)), "lags"),
    (lambda: Q.qcr_delta(np.eye(3), np.ones((3, 2, 1))), "corr"),
    (lambda: Q.qcr_problem(np.eye(3), np.ones((5, 2, 3))), "corr"),
    (lambda: Q.MeanEliminated(MatrixOperator(np.ones((3, 2)) + np.eye(3, 2))).recover(
        np.ones(2), np.ones(3)), "corr"),
    (lambda: Q.MeanEliminated(MatrixOperator(np.ones((3, 2)) + np.eye(3, 2))).recover(
        np.ones((3, 1)), np.ones((3, 1))), "z of shape"),
    (lambda: occupied_lags(np.ones(5), np.ones(1)), "corr"),
    (lambda: occupied_lags(np.ones((4, 5)), np.ones(9)), "sigma"),
    (lambda: PR.point_cloud(np.ones((8, 8)), 10, np.ones((4, 4))), "intensity"),
    (lambda: build_detector("gmapd").detect(np.ones(3) * 0.1, np.random.default_rng(0)),
     "lam"),
])
def test_mismatched_shapes_are_refused_naming_the_argument(call, name):
    with pytest.raises(ValueError, match=name):
        call()


def test_a_flat_intensity_is_one_value_per_pixel():
    pts, vals = PR.point_cloud(np.full((2, 2), 3.0), 10, np.arange(4.0))
    np.testing.assert_array_equal(vals, np.arange(4.0))
    assert pts.shape == (4, 3)


def test_solve_refuses_empty_data_and_a_missing_regulariser():
    A = MatrixOperator(np.eye(3))
    with pytest.raises(ValueError, match="empty"):
        solve(A, np.zeros((3, 0)), TV((3, 1)), 0.1)
    with pytest.raises(ValueError, match="reg must be a regulariser"):
        solve(A, np.ones(3), None, 0.1)


def test_metric_masks_and_gates_are_checked():
    e = np.arange(16.0).reshape(4, 4)
    with pytest.raises(ValueError, match="mask must be a boolean mask"):
        M.edge_agreement(e, e, np.full((4, 4), 0.3))  # (0.3 and NaN read as True)
    with pytest.raises(ValueError, match="valid must be a boolean mask"):
        M.truth_edge_mask(np.full((4, 4), 0.5))  # (read as "every pixel known")
    with pytest.raises(ValueError, match="2-D mask"):
        M.truth_edge_mask(np.ones(16, bool))
    for gate in ((5.0, 3.0), (np.nan, 3.0), (1.0, 2.0, 3.0)):
        with pytest.raises(ValueError, match="gate must be"):
            M.chance_rmse(np.ones((2, 2)), gate)


@pytest.mark.parametrize("call, name", [
    (lambda: F.expected_counts(np.ones((1, 1)), [0], np.ones(7), 1.0, 0.1, n_periods=-1),
     "n_periods"),
    (lambda: F.expected_counts(np.ones((1, 1)), [0], np.ones(7), np.nan, 0.1), "signal"),
    (lambda: F.depth_to_delay(1.0, 0), "bin_width"),
    (lambda: F.delay_to_depth(1.0, -1e-10), "bin_width"),
    (lambda: C.matched_filter(np.ones((2, 7)), np.ones(7), [0], gain=0), "gain"),
    (lambda: C.matched_filter(np.ones((2, 7)), np.ones(7), [0], gain=np.nan), "gain"),
    (lambda: C.noise_sigma_from_totals(np.array([-1.0]), np.ones(7)), "negative"),
    (lambda: C.make_replica(np.array([])), "empty"),
    (lambda: C.auto_replica(np.array([np.nan, 1.0])), "NaN"),
    (lambda: periodic_xcorr(np.array([3, 0, 3]), np.array([1, 0, 1])), "0/1 bits"),
])
def test_impossible_parameters_are_refused(call, name):
    with pytest.raises(ValueError, match=name):
        call()


def test_operators_answer_integer_boolean_and_half_inputs_in_floats():
    x = np.array([1, 0, 2])
    assert Identity(3).matvec(x).dtype == np.float64
    assert Identity(3).matvec(x.astype(bool)).dtype == np.float64
    g = Gradient2D((2, 2))
    np.testing.assert_allclose(g.matvec(np.array([1, 0, 0, 1], bool)),
                               g.matvec(np.array([1.0, 0.0, 0.0, 1.0])))
    w = Wavelet2D((4, 4))
    half = w.matvec(np.ones(16, np.float16))
    assert half.dtype == np.float32
    np.testing.assert_allclose(half, w.matvec(np.ones(16)), rtol=1e-6)


def test_a_run_leaves_the_callers_warning_filters_as_they_were():
    import spslidar

    spslidar.run(scene="steps", size=8, noise=1)
    # (a NUL-pattern filter was left behind for good; the libraries the run imports add
    # their own, SciPy's among them, which are theirs to keep)
    assert not [f for f in warnings.filters if getattr(f[1], "pattern", None) == "\x00"]


def test_a_second_capture_still_sees_a_warning_shown_once_per_place():
    # the registries' reset, which now takes its filter out again, must still reset them
    from spslidar.capture import captured_warnings

    def warn_here():
        warnings.warn("once per place", UserWarning, stacklevel=1)

    logs = []
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        for _ in range(2):
            with captured_warnings() as log:
                warn_here()
            logs.append([str(w.message) for w in log])
    assert logs == [["once per place"], ["once per place"]]


@pytest.mark.parametrize("kind", ["dense", "hadamard"])
def test_apply_rows_takes_its_contracts_arguments_only(kind):
    # (a 1-D x or an integer rows was taken by some kinds and failed deep in others; an x of
    # other pixels was numpy's matmul error)
    from spslidar.patterns import build_patterns

    op = build_patterns("gaussian" if kind == "dense" else "hadamard", 5, 4,
                        np.random.default_rng(0))
    x = np.random.default_rng(1).random((16, 2))
    want = np.asarray(op.matvec(np.eye(16)), dtype=np.float64) @ x  # the rows, shown
    # (the shown rows are float32 mirror states: the two products agree to its precision)
    np.testing.assert_allclose(op.apply_rows(slice(0, 5), x), want, rtol=1e-6)
    for rows, arg, why in ((slice(0, 3), np.ones((15, 2)), "16 pixels"),
                           (slice(0, 3), np.ones(16), "2 dimensions"),
                           (2, x, "rows must be a slice")):
        with pytest.raises(ValueError, match=why):
            op.apply_rows(rows, arg)


def test_differential_scrambled_hadamard_on_another_backend_counts_its_matrix():
    # (the device path builds every differential Hadamard kind as a matrix; scrambled-hadamard
    # was left out of the estimate: 0.32 GB said, 0.49 GB at its peak, an audit of 2026-11-29)
    from spslidar.pipeline import preflight

    base = dict(size=128, compression=0.1, hadamard_realisation="differential", periods=2,
                backend="array-api-strict")
    plain = preflight(patterns="hadamard", **base)
    scrambled = preflight(patterns="scrambled-hadamard", **base)
    assert "patterns" in scrambled.parts
    assert scrambled.parts["patterns"] == pytest.approx(plain.parts["patterns"], rel=1e-12)


def test_fwht_refuses_complex_input():
    from spslidar.operators.hadamard import fwht

    np.testing.assert_allclose(fwht(np.ones(4)), [4.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="real arrays"):
        fwht(np.ones(4, complex))


def test_shapes_that_worked_before_the_checks_still_work():
    # (a review of the checks found these refused: a 1-D corr, one slice, which the solvers
    # take and answer 1-D; an (M, 1) noise column; one reflectivity for every pixel; a gain
    # per pattern)
    rng = np.random.default_rng(0)
    phi = rng.random((40, 16))
    x = np.zeros(16)
    x[5] = 1.0
    corr = phi @ x
    A, y = Q.qcr_problem(phi, corr)
    assert y.shape == (40,)
    est, _ = solve(A, y, TV((4, 4)), 1e-3)
    assert est.shape == (16,) and int(np.argmax(est)) == 5
    A2, y2 = Q.qcr_problem(phi, corr[:, None])
    np.testing.assert_allclose(y, y2[:, 0])
    assert Q.qcr_delta(phi, corr).shape == (16,)
    amp, code = np.ones((3, 1)), np.ones(7)
    np.testing.assert_array_equal(
        F.expected_counts(amp, [0], code, 1.0, np.full((3, 1), 0.5)),
        F.expected_counts(amp, [0], code, 1.0, np.full(3, 0.5)))
    shifts, w = F.return_weights(1.0, np.array([1.2, 3.4]), 1.0, 31)
    np.testing.assert_array_equal(w, F.return_weights(np.ones(2), np.array([1.2, 3.4]), 1.0,
                                                      31)[1])
    totals = np.array([4.0, 9.0, 16.0, 25.0])
    np.testing.assert_allclose(C.noise_sigma_from_totals(totals, np.ones(7), np.full(4, 2.0)),
                               np.sqrt(totals) / 2.0)
    with pytest.raises(ValueError, match="gain must be positive"):
        C.noise_sigma_from_totals(totals, np.ones(7), np.array([1.0, 0.0, 1.0, 1.0]))


def test_dense_patterns_refuse_transmittances_outside_0_1():
    """A DMD shows transmittances in [0, 1]: `reconstruct --patterns` refused others, the
    Python class took them (an audit of 2026-11-29); grey levels and the edges pass."""
    from spslidar.patterns import DensePatterns

    DensePatterns(np.array([[0.0, 0.25, 1.0], [1.0, 0.5, 0.0]]))
    for bad, says in ((np.array([[0.0, 1.5]]), "from 0 to 1.5"),
                      (np.array([[-1.0, 1.0]]), "from -1 to 1"),
                      (np.array([[0, 255]], dtype=np.uint8), "from 0 to 255")):
        with pytest.raises(ValueError, match=f"transmittances in \\[0, 1\\], got values {says}"):
            DensePatterns(bad)


@pytest.mark.parametrize("shape", [(0, 4), (3, 0), (0, 0)])
def test_matrix_operator_refuses_an_empty_matrix(shape):
    from spslidar.operators import MatrixOperator
    from spslidar.patterns import DensePatterns

    with pytest.raises(ValueError, match="at least one row and one column"):
        MatrixOperator(np.zeros(shape))
    with pytest.raises(ValueError, match="at least one row and one column"):
        DensePatterns(np.zeros(shape))
