"""Quadratic Correlation Reconstruction (QCR), equations (11)-(17).

QCR correlates the measurements with the patterns *after removing their means*:

    Delta = <C Phi> - <C><Phi> = Phi_c^T C_c / M                       (eq. 11, 16)
    H     = cov(Phi, Phi)      = Phi_c^T Phi_c / M                     (eq. 12-13, 17)

with ``Phi_c = Phi - mean_i Phi`` and ``C_c = C - mean_i C`` (means over the M patterns), and
solves ``Delta = H p`` (eq. 17) with the sparse/TV solver (eq. 18). Anything common to all
patterns (the DC part of the signal, and background that does not depend on the pattern) drops
out. ``H`` is Q x Q: it is applied as ``Phi_c^T (Phi_c x) / M`` and never formed.

Two data terms with the same unregularised solutions are offered (with a regulariser at the
same weight their optima differ: the terms are scaled differently):

* ``form='covariance'``: the paper's literal eq. (18), ``1/2 ||Delta - H p||^2``.
* ``form='centred'`` (default): ``1/2 ||C_c - Phi_c p||^2 / M``. Its gradient is
  ``H p - Delta``, so its unregularised minimisers are exactly the solutions of eq. (17), but its
  condition number is the square root of the covariance form's, and each iteration costs two
  products with Phi instead of four.
"""

from __future__ import annotations

import numpy as np

from .arrays import real_array
from .errors import ConfigError
from .operators import LinearOperator
from .patterns.dense import centred_patterns  # noqa: F401 - re-exported (eq. 11's Phi_c)

QCR_FORMS = ("centred", "covariance")


def centre(a: np.ndarray) -> np.ndarray:
    """Subtract the mean over patterns (axis 0)."""
    a = np.asarray(a)
    return a - a.mean(axis=0, keepdims=True)


def _check_rows(patterns, corr) -> np.ndarray:
    """``corr`` as a real ``(M, K)`` array (or ``(M,)``, one slice: the solvers take a 1-D
    ``y`` and give a 1-D ``x`` back), one measurement row per pattern, or one line (a
    ``corr`` of other rows was taken, and broadcast or failed deep inside; a 3-D one gave a
    3-D ``y``, a complex one a complex ``Delta``: audits of 2026-11-29)."""
    corr = real_array(corr, "corr")
    if corr.ndim not in (1, 2):
        raise ValueError(f"corr must be (M, K) correlations, or (M,) for one slice, got shape "
                         f"{corr.shape}")
    if corr.shape[0] != patterns.shape[0]:
        raise ValueError(f"corr has {corr.shape[0]} rows for {patterns.shape[0]} patterns: "
                         f"one row of correlations per pattern")
    return corr


def qcr_delta(patterns, corr: np.ndarray) -> np.ndarray:
    """``Delta = Phi_c^T C_c / M`` (eq. 11, 16): the covariance of the measurements with each
    pixel's pattern values, shape ``(Q, K)``. ``patterns``: an ``(M, Q)`` array or a
    :class:`~spslidar.patterns.PatternOperator`; an array's values are mirror transmittances
    in [0, 1], as :func:`qcr_problem` takes them (zero-mean patterns were taken here and
    refused there: an audit of 2026-12-02)."""
    if not hasattr(patterns, "rmatvec"):  # (a list had no 'rmatvec')
        from .patterns import as_patterns

        patterns = real_array(patterns, "patterns", ndim=2, floating=True)
        as_patterns(patterns, copy=False)  # the check of qcr_problem's (DensePatterns')
    corr = _check_rows(patterns, corr)
    if isinstance(patterns, np.ndarray):
        return centre(patterns).T @ centre(corr) / patterns.shape[0]
    # Phi_c^T C_c = Phi^T C_c: the centred data sum to zero over the patterns
    cc = centre(np.asarray(corr, dtype=np.float64))
    return np.asarray(patterns.rmatvec(cc), dtype=np.float64) / patterns.shape[0]


class CovarianceOperator(LinearOperator):
    """``H = Phi_c^T Phi_c / M`` (eq. 17), applied implicitly (never formed)."""

    def __init__(self, patterns, dtype=np.float32):
        from .patterns import as_patterns

        phi = as_patterns(patterns, copy=False)
        self.m = phi.shape[0]
        self._phi = phi.centred(1.0, dtype=dtype)
        q = phi.shape[1]
        super().__init__((q, q), dtype)

    def _matvec(self, x):
        return self._phi._rmatvec(self._phi._matvec(x)) / self.m

    _rmatvec = _matvec  # symmetric


def qcr_problem(patterns: np.ndarray, corr: np.ndarray, form: str = "centred",
                dtype=np.float32) -> tuple[LinearOperator, np.ndarray]:
    """The operator and data of eq. (18) after QCR.

    Returns
    -------
    A : LinearOperator
        ``Phi_c / sqrt(M)`` (centred) or ``H`` (covariance).
    y : ndarray
        ``C_c / sqrt(M)`` (centred) or ``Delta`` (covariance).

    Examples
    --------
    >>> import numpy as np
    >>> from spslidar.qcr import qcr_problem
    >>> rng = np.random.default_rng(0)
    >>> phi = rng.random((32, 64))  # 32 patterns over 8x8 mirrors
    >>> p = rng.random((64, 3))  # 3 range slices
    >>> corr = phi @ p + 7.0  # plus a background common to every pattern
    >>> A, y = qcr_problem(phi, corr, dtype=np.float64)
    >>> A.shape, y.shape
    ((32, 64), (32, 3))
    >>> np.allclose(A @ p, y)  # the background has dropped out
    True
    """
    from .patterns import as_patterns

    phi = as_patterns(patterns, copy=False)
    corr = _check_rows(phi, corr)
    m = phi.shape[0]
    if form == "centred":
        return phi.centred(np.sqrt(m), dtype=dtype), (centre(corr) / np.sqrt(m)).astype(dtype)
    if form == "covariance":
        return CovarianceOperator(phi, dtype=dtype), qcr_delta(patterns, corr).astype(dtype)
    raise ConfigError(f"unknown QCR form {form!r}; choose centred or covariance")


def plain_problem(patterns: np.ndarray, corr: np.ndarray,
                  dtype=np.float32) -> tuple[LinearOperator, np.ndarray]:
    """Eq. (7) without QCR: ``C = Phi p``."""
    from .patterns import as_patterns

    phi = as_patterns(patterns)
    corr = _check_rows(phi, corr)
    return phi.as_dtype(dtype), corr.astype(dtype)


class MeanEliminated(LinearOperator):
    """``B = (I - v v^T) A`` with ``v = A 1 / ||A 1||``: the operator of eq. (7) without QCR,
    its dominant direction removed exactly (variable projection).

    Without QCR the patterns' mean gives ``A = Phi`` one singular value far above the others
    (along the constant image; default Gaussian patterns at 64x64: 44 times the second, 132
    times the smallest), so a first-order solver stepping at
    ``1 / ||A||^2`` barely moves in every other direction. A TV-regularised problem is
    invariant to adding a constant to each slice, so write ``p = z + c 1``: for any ``z`` the
    best ``c`` is ``c(z) = v^T (C - A z) / ||A 1||`` (a least-squares fit of the constant), and
    eliminating it leaves ``min_z ||B z - (I - v v^T) C||^2 + lam TV(z)``, which has exactly
    the optimum of eq. (18) (``p = z + c(z) 1``, :meth:`recover`) and the conditioning of the
    centred problem. The non-negativity constraint couples ``c`` to ``z`` and is not applied
    on this path.

    Parameters
    ----------
    op : LinearOperator
        ``A`` (``(M, Q)``), the plain operator of :func:`plain_problem`.
    """

    def __init__(self, op: LinearOperator):
        super().__init__(op.shape, op.dtype)
        self.op = op
        a1 = np.asarray(op.matvec(np.ones((op.shape[1], 1), dtype=op.dtype)), np.float64)[:, 0]
        self.norm_a1 = float(np.linalg.norm(a1))
        if self.norm_a1 == 0.0:
            raise ConfigError("the patterns sum to zero: no mean direction to eliminate")
        self.v = a1 / self.norm_a1

    def _project(self, r: np.ndarray) -> np.ndarray:
        r64 = np.asarray(r, dtype=np.float64)
        return r64 - self.v[:, None] * (self.v @ r64)[None, :]

    def _matvec(self, x):
        return self._project(self.op.matvec(x)).astype(self.dtype, copy=False)

    def _rmatvec(self, y):
        return self.op.rmatvec(self._project(y).astype(self.dtype, copy=False))

    def data(self, corr: np.ndarray) -> np.ndarray:
        """The reduced data ``(I - v v^T) C``."""
        return self._project(self._corr(corr)).astype(self.dtype, copy=False)

    def _corr(self, corr: np.ndarray) -> np.ndarray:
        corr = _check_rows(self, corr)  # (a broadcast error named neither: an audit)
        if corr.ndim != 2:  # (its projection is of (M, K) blocks)
            raise ValueError(f"corr must be (M, K) correlations, got shape {corr.shape}")
        return corr

    def recover(self, z: np.ndarray, corr: np.ndarray) -> np.ndarray:
        """``p = z + c(z) 1`` with each column's best constant ``c(z)`` (the optimum of eq. 18
        when ``z`` minimises the reduced problem)."""
        corr = self._corr(corr)
        z = real_array(z, "z", ndim=2)
        if z.shape != (self.shape[1], corr.shape[1]):
            raise ValueError(f"z of shape {z.shape} for {self.shape[1]} pixels and "
                             f"{corr.shape[1]} columns of corr")
        z64 = z.astype(np.float64)
        resid = corr.astype(np.float64) - np.asarray(self.op.matvec(z), np.float64)
        c = (self.v @ resid) / self.norm_a1
        return (z64 + c[None, :]).astype(np.asarray(z).dtype, copy=False)
