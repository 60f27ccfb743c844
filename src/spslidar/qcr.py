"""Quadratic Correlation Reconstruction (QCR), eq. (11)-(17).

QCR correlates the measurements with the patterns *after removing their means*:

    Delta = <C Phi> - <C><Phi> = Phi_c^T C_c / M                       (eq. 11, 16)
    H     = cov(Phi, Phi)      = Phi_c^T Phi_c / M                     (eq. 12-13, 17)

with ``Phi_c = Phi - mean_i Phi`` and ``C_c = C - mean_i C`` (means over the M patterns), and
solves ``Delta = H p`` (eq. 17) with the sparse/TV solver (eq. 18). Anything common to all
patterns (the DC part of the signal, and background that does not depend on the pattern) drops
out. ``H`` is Q x Q: it is applied as ``Phi_c^T (Phi_c x) / M`` and never formed.

Two equivalent data terms are offered:

* ``form='covariance'``: the paper's literal eq. (18), ``1/2 ||Delta - H p||^2``.
* ``form='centred'`` (default): ``1/2 ||C_c - Phi_c p||^2 / M``. Its gradient is
  ``H p - Delta``, so its unregularised minimisers are exactly the solutions of eq. (17), but its
  condition number is the square root of the covariance form's, and each iteration costs two
  products with Phi instead of four.
"""

from __future__ import annotations

import numpy as np

from .errors import ConfigError
from .operators import LinearOperator, MatrixOperator

QCR_FORMS = ("centred", "covariance")


def centre(a: np.ndarray) -> np.ndarray:
    """Subtract the mean over patterns (axis 0)."""
    a = np.asarray(a)
    return a - a.mean(axis=0, keepdims=True)


def qcr_delta(patterns: np.ndarray, corr: np.ndarray) -> np.ndarray:
    """``Delta = Phi_c^T C_c / M`` (eq. 11, 16): the covariance of the measurements with each
    pixel's pattern values, shape ``(Q, K)``."""
    phi_c = centre(patterns)
    return phi_c.T @ centre(corr) / patterns.shape[0]


class CovarianceOperator(LinearOperator):
    """``H = Phi_c^T Phi_c / M`` (eq. 17), applied implicitly (never formed)."""

    def __init__(self, patterns: np.ndarray, dtype=np.float32):
        phi_c = centre(np.asarray(patterns, dtype=np.float64)).astype(dtype)
        self.m = patterns.shape[0]
        self._phi = MatrixOperator(phi_c)
        q = patterns.shape[1]
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
    """
    m = patterns.shape[0]
    if form == "centred":
        phi_c = centre(np.asarray(patterns, dtype=np.float64)) / np.sqrt(m)
        return MatrixOperator(phi_c, dtype=dtype), (centre(corr) / np.sqrt(m)).astype(dtype)
    if form == "covariance":
        return CovarianceOperator(patterns, dtype=dtype), qcr_delta(patterns, corr).astype(dtype)
    raise ConfigError(f"unknown QCR form {form!r}; choose centred or covariance")


def plain_problem(patterns: np.ndarray, corr: np.ndarray,
                  dtype=np.float32) -> tuple[LinearOperator, np.ndarray]:
    """Eq. (7) without QCR: ``C = Phi p``."""
    return MatrixOperator(patterns, dtype=dtype), np.asarray(corr, dtype=dtype)
