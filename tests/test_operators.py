"""One conformance suite run over every linear operator: adjoint, linearity, norm, batching,
dtype, no side effects. It discovers every ``LinearOperator`` subclass in the package and fails
when one has no example here, so a new operator cannot go untested."""

import importlib
import pkgutil

import numpy as np
import pytest

import spslidar
from spslidar.operators import (
    Gradient2D,
    Identity,
    MatrixOperator,
    Wavelet2D,
    dottest,
    power_norm,
)
from spslidar.operators.base import LinearOperator
from spslidar.operators.hadamard import WalshHadamard
from spslidar.patterns import CentredPatterns, DensePatterns, PatternOperator
from spslidar.patterns.hadamard import hadamard_patterns
from spslidar.qcr import CovarianceOperator, qcr_problem


def _phi(m=30, q=64, seed=0):
    return np.clip(0.5 + 0.25 * np.random.default_rng(seed).standard_normal((m, q)), 0, 1)


class _Implicit(PatternOperator):
    """A pattern set known only through its products: exercises the contract's defaults."""

    def __init__(self, matrix):
        super().__init__(matrix.shape, matrix.dtype)
        self._m = matrix

    def _matvec(self, x):
        return self._m @ x

    def _rmatvec(self, y):
        return self._m.T @ y


OPERATORS = {
    "matrix": lambda: MatrixOperator(np.random.default_rng(1).standard_normal((7, 11))),
    "matrix32": lambda: MatrixOperator(_phi(), dtype=np.float32),
    "identity": lambda: Identity(9),
    "gradient": lambda: Gradient2D((6, 5)),
    "wavelet-haar": lambda: Wavelet2D((8, 8), "haar"),
    "wavelet-db2": lambda: Wavelet2D((16, 8), "db2"),
    "covariance": lambda: CovarianceOperator(_phi(), dtype=np.float64),
    "qcr-centred": lambda: qcr_problem(_phi(), np.zeros((30, 1)), "centred", np.float64)[0],
    "composite": lambda: MatrixOperator(_phi()) @ Wavelet2D((8, 8)).H * 2.0
    + MatrixOperator(_phi(seed=3)),
    "adjoint": lambda: MatrixOperator(_phi()).H @ MatrixOperator(_phi()) - Identity(64),
    "dense-patterns": lambda: DensePatterns(_phi()),
    "centred-patterns": lambda: CentredPatterns(DensePatterns(_phi()), 2.0, np.float64),
    "patterns-cast": lambda: DensePatterns(_phi()).as_dtype(np.float32),
    "implicit-patterns-cast": lambda: _Implicit(_phi()).as_dtype(np.float32),
    "implicit-patterns-centred": lambda: _Implicit(_phi()).centred(3.0, np.float64),
    "qcr-plain": lambda: __import__("spslidar.qcr").qcr.plain_problem(
        _phi(), np.zeros((30, 1)), np.float64)[0],
    "mean-eliminated": lambda: __import__("spslidar.qcr").qcr.MeanEliminated(
        DensePatterns(_phi())),
    "walsh-hadamard": lambda: WalshHadamard(32),
    "hadamard-patterns": lambda: hadamard_patterns(
        "hadamard", 20, 8, np.random.default_rng(0), dtype=np.float64),
    "scrambled-hadamard-differential": lambda: hadamard_patterns(
        "scrambled-hadamard", 20, 8, np.random.default_rng(0), dtype=np.float64,
        realisation="differential"),
    "hadamard-frames-centred": lambda: hadamard_patterns(
        "hadamard", 20, 8, np.random.default_rng(0), dtype=np.float32,
        realisation="differential").exposures()[0].centred(2.0, np.float32),
    "placed-returns": lambda: __import__("spslidar.refit").refit.PlacedReturns(
        MatrixOperator(_phi()), np.random.default_rng(2).uniform(0, 1, (64, 5))
        * (np.random.default_rng(3).uniform(0, 1, (64, 5)) < 0.4)),
    "placed-returns32": lambda: __import__("spslidar.refit").refit.PlacedReturns(
        MatrixOperator(_phi(), dtype=np.float32), np.eye(64, 3)),
    "hadamard-centred": lambda: hadamard_patterns(
        "scrambled-hadamard", 20, 8, np.random.default_rng(0), dtype=np.float64).centred(
        3.0, np.float64),
}


def _all_operator_classes():
    for mod in pkgutil.walk_packages(spslidar.__path__, "spslidar."):
        importlib.import_module(mod.name)
    seen, todo = set(), [LinearOperator]
    while todo:
        for sub in todo.pop().__subclasses__():
            if sub not in seen and sub.__module__.startswith("spslidar."):
                seen.add(sub)
                todo.append(sub)
    # abstract bases (no products of their own) are covered through their subclasses
    return {c for c in seen if c._matvec is not LinearOperator._matvec}


def _classes_in(op, seen=None):
    seen = set() if seen is None else seen
    if isinstance(op, LinearOperator) and id(op) not in {id(o) for o in seen}:
        seen.add(op)
        for v in vars(op).values():
            _classes_in(v, seen)
    return {type(o) for o in seen}


def test_every_operator_class_has_an_example():
    covered = set()
    for make in OPERATORS.values():
        covered |= _classes_in(make())
    missing = sorted(c.__qualname__ for c in _all_operator_classes() - covered)
    assert not missing, f"LinearOperator subclasses without an example in OPERATORS: {missing}"


def test_dtype_and_no_side_effects(op):
    rng = np.random.default_rng(7)
    x = rng.standard_normal((op.shape[1], 2)).astype(op.dtype)
    y = rng.standard_normal((op.shape[0], 2)).astype(op.dtype)
    x0, y0 = x.copy(), y.copy()
    a, b = op @ x, op.H @ y
    np.testing.assert_array_equal(x, x0)
    np.testing.assert_array_equal(y, y0)
    assert np.asarray(a).dtype == op.dtype and np.asarray(b).dtype == op.dtype
    np.testing.assert_array_equal(op @ x, a)  # no hidden state between calls


@pytest.fixture(params=sorted(OPERATORS))
def op(request):
    return OPERATORS[request.param]()


def test_adjoint(op):
    dottest(op, n_cols=1, rng=0)
    dottest(op, n_cols=4, rng=1)


def test_linearity(op):
    rng = np.random.default_rng(2)
    x, z = rng.standard_normal((2, op.shape[1]))
    a, b = 1.7, -0.3
    tol = 1e-4 if op.dtype == np.float32 else 1e-10
    lhs = op @ (a * x + b * z)
    rhs = a * (op @ x) + b * (op @ z)
    assert np.linalg.norm(lhs - rhs) <= tol * max(np.linalg.norm(rhs), 1.0)


def test_batched_columns_equal_single_vectors(op):
    rng = np.random.default_rng(3)
    x = rng.standard_normal((op.shape[1], 3))
    y = op @ x
    assert y.shape == (op.shape[0], 3)
    for k in range(3):
        np.testing.assert_allclose(y[:, k], op @ x[:, k], rtol=1e-5, atol=1e-6)
    yh = op.H @ rng.standard_normal((op.shape[0], 3))
    assert yh.shape == (op.shape[1], 3)


def test_power_norm_matches_dense_spectral_norm(op):
    dense = np.asarray(op.todense(), dtype=np.float64)
    exact = np.linalg.norm(dense, 2)
    est = power_norm(op, n_iter=500, rtol=1e-9, rng=0)
    assert exact <= est <= 1.02 * exact + 1e-12


def test_shape_mismatch_is_an_error():
    # (matched: NumPy's own matmul error passed a bare ValueError with the check removed)
    with pytest.raises(ValueError, match=r"shape \(3, 4\) applied to array of shape \(5,\)"):
        MatrixOperator(np.ones((3, 4))) @ np.ones(5)
    with pytest.raises(ValueError, match=r"cannot compose \(3, 4\) with \(3, 4\)"):
        MatrixOperator(np.ones((3, 4))) @ MatrixOperator(np.ones((3, 4)))


def test_wavelet_is_orthonormal():
    w = Wavelet2D((16, 16), "db2")
    x = np.random.default_rng(0).standard_normal((256, 2))
    np.testing.assert_allclose(w.H @ (w @ x), x, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(w @ x), np.linalg.norm(x))


def test_gradient_matches_pylops():
    import pylops
    g = Gradient2D((6, 5))
    ref = pylops.FirstDerivative((6, 5), axis=0, kind="forward", edge=False)
    x = np.random.default_rng(0).standard_normal(30)
    ours = (g @ x)[:30].reshape(6, 5)
    theirs = (ref @ x).reshape(6, 5)
    np.testing.assert_allclose(ours[:-1], theirs[:-1], atol=1e-12)
    assert np.all(ours[-1] == 0)


def test_todense_matches_the_products(op):
    # column j of the dense form is op @ e_j, for every operator (MatrixOperator returns its
    # matrix directly, the others go through products with the identity)
    dense = np.asarray(op.todense(), dtype=np.float64)
    assert dense.shape == op.shape
    rng = np.random.default_rng(5)
    x = rng.standard_normal(op.shape[1])
    tol = 1e-4 if op.dtype == np.float32 else 1e-10
    np.testing.assert_allclose(dense @ x, np.asarray(op @ x, dtype=np.float64),
                               rtol=tol, atol=tol * np.abs(dense).sum(axis=1).max())


def test_matrix_operator_todense_is_a_copy_of_its_matrix():
    a = np.arange(12.0).reshape(3, 4)
    op = MatrixOperator(a)
    d = op.todense()
    np.testing.assert_array_equal(d, a)
    d[0, 0] = 99.0
    assert op.A[0, 0] == 0.0


def test_pattern_contract_defaults_match_the_dense_forms():
    phi = _phi()
    imp, dense = _Implicit(phi), DensePatterns(phi)
    np.testing.assert_allclose(imp.mean_pattern(), phi.mean(axis=0), rtol=1e-12)
    x = np.random.default_rng(0).standard_normal((64, 3))
    np.testing.assert_allclose(imp.apply_rows(slice(5, 9), x), phi[5:9] @ x, rtol=1e-12)
    np.testing.assert_allclose(imp.centred(2.0, np.float64) @ x,
                               dense.centred(2.0, np.float64) @ x, rtol=1e-10, atol=1e-12)
    y = np.random.default_rng(1).standard_normal((30, 2))
    np.testing.assert_allclose(imp.centred(2.0, np.float64).H @ y,
                               (phi - phi.mean(axis=0)).T @ y / 2.0, rtol=1e-10, atol=1e-12)


def test_todense_in_blocks_equals_the_identity_product():
    """todense applied the operator to the whole n x n identity (16 GB at 256x256); it now
    goes a block of columns at a time, with the same matrix."""
    from spslidar.operators import Wavelet2D
    from spslidar.operators.base import LinearOperator

    w = Wavelet2D((64, 64))  # 4 096 columns: four blocks of 1 024
    np.testing.assert_array_equal(LinearOperator.todense(w), w.matvec(np.eye(4096)))
