"""Bad inputs of the Python API's patterns, operators, solvers, codes and QCR: each refused in
one line naming the argument, not a silent wrong result (an outside audit of 2026-12-02)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from spslidar.codes.sequences import MAX_CODE_LENGTH, make_code, periodic_xcorr
from spslidar.errors import ConfigError
from spslidar.operators import MatrixOperator, Wavelet2D, dottest, power_norm
from spslidar.operators.hadamard import fwht
from spslidar.patterns import build_patterns
from spslidar.patterns.dense import centred_patterns
from spslidar.patterns.hadamard import HadamardPatterns
from spslidar.qcr import qcr_delta, qcr_problem
from spslidar.solvers import StopRule, get_solver, solve
from spslidar.solvers.regularisers import L1, TV, make_wavelet_l1


def _operator(m: int = 6, n: int = 16, seed: int = 0) -> MatrixOperator:
    return MatrixOperator(np.random.default_rng(seed).random((m, n)))


# -- 1. pattern factories ---------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["gaussian", "bernoulli", "hadamard"])
@pytest.mark.parametrize("n_side", [-2, 0])
def test_a_side_below_one_is_refused(kind, n_side):
    """-2 made a (4, 4) Gaussian set: (-2)**2 pixels."""
    with pytest.raises(ConfigError, match=r"^n_side must be an integer >= 1, got"):
        build_patterns(kind, 4, n_side, np.random.default_rng(0))


def test_a_count_of_patterns_below_one_is_refused_by_name():
    with pytest.raises(ConfigError, match=r"^n_patterns must be an integer >= 1"):
        build_patterns("gaussian", -1, 4, np.random.default_rng(0))


@pytest.mark.parametrize("dtype", [int, complex, bool])
@pytest.mark.parametrize("kind", ["hadamard", "scrambled-hadamard"])
def test_hadamard_patterns_refuse_the_dtypes_the_dense_kinds_refuse(kind, dtype):
    """int was taken, then ``p @ x`` failed with numpy's "Cannot cast ... same_kind"."""
    with pytest.raises(ConfigError, match=r"^dtype must be a real floating type .*mirror states"):
        build_patterns(kind, 4, 4, np.random.default_rng(0), dtype=dtype)
    p = build_patterns(kind, 4, 4, np.random.default_rng(0), dtype="float64")  # still taken
    assert p.dtype == np.float64
    np.testing.assert_allclose(p @ np.ones(16), p.todense() @ np.ones(16), atol=1e-12)


@pytest.mark.parametrize("flips", [[1, 1j, 1], np.array([1, -1j, 1]), ["1", "1", "1"]])
def test_hadamard_flips_must_be_real_signs(flips):
    """1j passed ``|flip| == 1`` and was cast to 0: row 1 a constant 0.5."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ConfigError, match=r"^flips "):
            HadamardPatterns(4, [0, 1, 2], flips=flips)
    got = HadamardPatterns(4, [0, 1, 2], flips=[1.0, -1.0, 1.0]).todense()
    ref = HadamardPatterns(4, [0, 1, 2]).todense()
    np.testing.assert_array_equal(got[1], 1.0 - ref[1])


# -- 2. solvers and their regularisers ----------------------------------------------------------
@pytest.mark.parametrize("reg", [TV((4, 4)), L1()], ids=["tv", "l1"])
@pytest.mark.parametrize("t", [np.nan, np.inf, -1.0, "1", None])
def test_prox_refuses_a_threshold_that_is_no_finite_non_negative_number(reg, t):
    """NaN gave all NaN."""
    v = np.random.default_rng(1).random(16)
    with pytest.raises(ConfigError, match=r"^prox threshold t must be finite and non-negative"):
        reg.prox(v, t)


@pytest.mark.parametrize("reg", [TV((4, 4)), L1()], ids=["tv", "l1"])
def test_prox_refuses_complex_input(reg):
    v = np.random.default_rng(2).random(16) + 1e-3j
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (not numpy's ComplexWarning)
        with pytest.raises(ValueError, match=r"^v holds complex numbers"):
            reg.prox(v, 0.1)


@pytest.mark.parametrize("name", ["fista", "twist", "gpsr", "tval3"])
def test_every_solver_refuses_a_complex_x0(name):
    reg = L1() if name == "gpsr" else TV((4, 4))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=r"^x0 must be real numbers"):
            solve(_operator(), np.ones(6), reg, 0.1, method=name, x0=np.ones(16) + 1j)


@pytest.mark.parametrize("kwargs, match", [
    (dict(image_shape=(4.7, 4)), r"^TV's image_shape must be a pair of whole numbers"),
    (dict(image_shape=(4, 4), inner_tol=np.nan), r"^inner_tol must be finite and non-negative"),
    (dict(image_shape=(4, 4), inner_tol=-1), r"^inner_tol must be finite and non-negative"),
    (dict(image_shape=(4, 4), inner_tol="1e-3"), r"^inner_tol must be"),
    (dict(image_shape=(4, 4), threads=1.5), r"^threads must be a whole number >= 1"),
    (dict(image_shape=(4, 4), max_inner=2.5), r"^max_inner must be a whole number >= 1"),
])
def test_tv_refuses_settings_it_would_have_rounded_or_ignored(kwargs, match):
    with pytest.raises(ValueError, match=match):
        TV(**kwargs)
    v = np.random.default_rng(3).random((16, 2))  # whole numbers as floats: taken as before
    a = TV((4.0, 4), threads=2.0, max_inner=5.0).prox(v, 0.1)
    np.testing.assert_array_equal(a, TV((4, 4), threads=2, max_inner=5).prox(v, 0.1))


@pytest.mark.parametrize("lam", ["0.1", None, np.ones(2), True, 1j])
def test_solve_refuses_a_weight_that_is_no_number_by_name(lam):
    with pytest.raises(ConfigError, match=r"^lam must be finite and non-negative, got"):
        solve(_operator(), np.ones(6), TV((4, 4)), lam)
    a = _operator()  # a matrix and NumPy scalars: taken as before
    y = np.random.default_rng(5).random(6)
    x1, _ = solve(a.A, y, TV((4, 4)), np.float64(0.01), stop=StopRule(20, rtol=np.float32(0)))
    x2, _ = solve(a, y, TV((4, 4)), 0.01, stop=StopRule(20, rtol=0.0))
    np.testing.assert_array_equal(x1, x2)


@pytest.mark.parametrize("field", ["rtol", "obj_rtol", "target", "max_time"])
def test_stop_rule_refuses_text_by_name(field):
    with pytest.raises(ConfigError, match=rf"^{field} must be"):
        StopRule(**{field: "1e-3"})


def test_solver_threads_must_be_a_whole_number():
    with pytest.raises(ValueError, match=r"^threads must be a whole number >= 1"):
        get_solver("fista")(threads=1.5)


@pytest.mark.parametrize("A", [[[1.0, 0.0], [0.0, 1.0]], None, "A"])
def test_solve_refuses_an_operator_that_is_none_by_name(A):
    """A list was an AttributeError on 'shape'."""
    with pytest.raises(ConfigError, match=r"^A must be a LinearOperator"):
        solve(A, np.ones(2), L1(), 0.1)


def test_solve_reads_the_method_case_insensitively():
    a, y = _operator(), np.random.default_rng(4).random(6)
    x1, _ = solve(a, y, TV((4, 4)), 0.01, method="FISTA", stop=StopRule(20))
    x2, _ = solve(a, y, TV((4, 4)), 0.01, method="fista", stop=StopRule(20))
    np.testing.assert_array_equal(x1, x2)
    assert get_solver("TwIST") is get_solver("twist")


# -- 3. operators -----------------------------------------------------------------------------
@pytest.mark.parametrize("n_iter", [0, -1, 2.5, "50"])
def test_power_norm_needs_at_least_one_iteration(n_iter):
    """0 returned 0.0, so that a 1/L step became infinite."""
    with pytest.raises(ValueError, match=r"^n_iter must be a whole number >= 1"):
        power_norm(_operator(), n_iter=n_iter)


@pytest.mark.parametrize("n_cols", [0, -2, 1.5])
def test_dottest_needs_at_least_one_column(n_cols):
    """0 returned 0.0: a pass on empty blocks."""
    with pytest.raises(ValueError, match=r"^n_cols must be a whole number >= 1"):
        dottest(_operator(), n_cols=n_cols)


@pytest.mark.parametrize("factor", ["2", b"2", True, 2j, np.nan])
def test_an_operator_is_scaled_by_real_numbers_only(factor):
    a = _operator()
    with pytest.raises(TypeError, match=r"^an operator is scaled by a finite real number"):
        a * factor  # noqa: B018
    with pytest.raises(TypeError, match=r"^an operator is scaled by a finite real number"):
        factor * a  # noqa: B018
    x = np.random.default_rng(6).random(16)  # numbers: as before
    np.testing.assert_array_equal((a * 2) @ x, 2.0 * (a @ x))
    np.testing.assert_array_equal((a * np.float32(2)) @ x, 2.0 * (a @ x))


def test_wavelet2d_warns_where_it_is_the_identity_as_the_regulariser_does():
    with pytest.warns(UserWarning, match=r"^Wavelet2D needs an even image side: at 5x5 it has "
                                         r"no level and is the identity"):
        w = Wavelet2D((5, 5))
    assert w.level == 0
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        make_wavelet_l1((5, 5))
    assert [str(m.message) for m in said] == [
        "the wavelet regulariser needs an even image side: at 5x5 it has no level and is the "
        "pixel l1 (--regulariser l1)"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # asked for, or with levels: no warning
        Wavelet2D((5, 5), level=0)
        Wavelet2D((8, 8))


@pytest.mark.parametrize("x", [np.float64(1), np.array(2.0), 3])
def test_fwht_refuses_a_0d_input_by_name(x):
    """An IndexError on x.shape[0]."""
    with pytest.raises(ValueError, match=r"^fwht: x must be an array of shape \(Q,\)"):
        fwht(x)


# -- 4. codes ---------------------------------------------------------------------------------
def test_periodic_xcorr_refuses_counts_whose_correlation_would_not_be_exact():
    """[2**40, 1] with itself read [-2**63, 2.2e12] with numpy's cast warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ConfigError, match=r"^periodic_xcorr computes correlations below "
                                              r"2\^44 exactly"):
            periodic_xcorr([2**40, 1], [2**40, 1], bipolar=False)
    rng = np.random.default_rng(7)  # below it: exact
    a, b = rng.integers(0, 2**16, 64), rng.integers(0, 2**16, 64)
    got = periodic_xcorr(a, b, bipolar=False)
    want = [sum(int(a[t]) * int(b[(t + k) % 64]) for t in range(64)) for k in range(64)]
    assert got.tolist() == want


def test_make_code_refuses_a_random_code_past_its_documented_maximum():
    """10**12 bits was a MemoryError (7.28 TiB)."""
    with pytest.raises(ConfigError, match=rf"too long: random codes are at most "
                                          rf"{MAX_CODE_LENGTH} \(2\^24\) bits"):
        make_code("random", 10**12, rng=0)
    with pytest.raises(ConfigError, match="too long"):
        make_code("random", MAX_CODE_LENGTH + 1, rng=0)


# -- 5. QCR -----------------------------------------------------------------------------------
def test_qcr_delta_refuses_zero_mean_patterns_as_qcr_problem_does():
    phi = np.random.default_rng(8).standard_normal((10, 16))
    corr = np.ones((10, 2))
    for fn in (qcr_problem, qcr_delta):
        with pytest.raises(ValueError, match=r"^patterns must hold mirror transmittances in "
                                             r"\[0, 1\]"):
            fn(phi, corr)


# -- 6. centred_patterns ----------------------------------------------------------------------
@pytest.mark.parametrize("dtype", [int, np.uint8, bool, complex])
def test_centred_patterns_refuse_a_dtype_that_is_not_real_floating(dtype):
    """int gave all zeros."""
    m = np.random.default_rng(9).random((10, 16))
    with pytest.raises(ValueError, match=r"^dtype must be a real floating type"):
        centred_patterns(m, dtype=dtype)


@pytest.mark.parametrize("norm", [0.0, np.inf, np.nan, -1.0, "2"])
def test_centred_patterns_refuse_a_norm_that_is_no_positive_number(norm):
    """0.0 gave infinities."""
    m = np.random.default_rng(10).random((10, 16))
    with pytest.raises(ValueError, match=r"^norm must be a positive number"):
        centred_patterns(m, norm)
