"""The pattern stage's contract: a set of DMD patterns is a linear operator.

The ``M`` patterns shown on the DMD are the rows of the measurement operator Phi of eq. (7).
Downstream stages (the forward model, QCR centring, the noise level, the solvers) use only
what this contract offers: products with Phi and its adjoint (any ``LinearOperator``), the
mean pattern (for QCR, eq. 11-17), products of a block of rows (the simulation streams over
blocks of patterns), the centred operator, and a cast to the solve precision. Dense pattern
sets (:mod:`.dense`) keep their matrix; implicit ones (a fast Hadamard transform) never form it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..arrays import floating_dtype, real_array
from ..operators import LinearOperator

__all__ = ["CentredPatterns", "PatternOperator", "pattern_dtype"]


def pattern_dtype(dtype: Any) -> np.dtype:
    """``dtype`` as the real floating type patterns are held in, or a one-line
    :class:`~spslidar.errors.ConfigError` naming ``dtype``: what every built-in pattern kind
    takes (an integer dtype made Gaussian patterns of all zeros; Hadamard patterns took ``int``
    and ``complex`` and failed at their first product: audits).

    Parameters
    ----------
    dtype : numpy dtype
        Any NumPy spelling (``"float32"``, ``np.float32``...).

    Returns
    -------
    numpy.dtype
    """
    return floating_dtype(dtype, why=" (patterns are mirror states in [0, 1])")


class PatternOperator(LinearOperator):
    """Base class of pattern sets: an ``(M, Q)`` operator with entries in [0, 1] (the DMD's
    transmittances; a differential Hadamard set's rows are the difference of its two frames,
    in [-1, 1], and the frames it shows are its ``exposures()``).

    Subclasses implement ``_matvec``/``_rmatvec`` and may override the methods below with
    cheaper or exact forms.

    Attributes
    ----------
    kind : str
        The registered pattern kind that made it.
    """

    kind = "base"

    @property
    def n_patterns(self) -> int:
        return self.shape[0]

    @property
    def n_pixels(self) -> int:
        return self.shape[1]

    def mean_pattern(self) -> np.ndarray:
        """``mu = (1/M) Phi^T 1``: each pixel's mean over the patterns, float64, shape (Q,)."""
        ones = np.ones((self.shape[0], 1), dtype=self.dtype)
        return np.asarray(self.rmatvec(ones), dtype=np.float64)[:, 0] / self.shape[0]

    def apply_rows(self, rows: slice, x: np.ndarray) -> np.ndarray:
        """``Phi[rows] @ x`` in float64 for a float64 block ``x`` of shape ``(Q, S)``.

        The default computes the whole product once and keeps it for the next blocks of the
        same ``x`` (the simulation asks for consecutive row blocks of one product); each block
        is a copy, so a caller's edit of it leaves the kept product as it was.
        """
        rows, x = self._rows_block(rows, x)
        return self._product_rows(x, rows, lambda v: np.asarray(
            self.matvec(np.asarray(v, dtype=self.dtype)), dtype=np.float64))

    def _rows_block(self, rows: slice, x: Any) -> tuple[slice, np.ndarray]:
        """:meth:`apply_rows`' arguments as its contract has them, or one line: a 1-D ``x``
        or an integer ``rows`` was taken by some kinds and failed deep in others, an ``x``
        of other pixels was numpy's matmul error (an audit of the Python API, 2026-11-29)."""
        if not isinstance(rows, slice):
            raise ValueError(f"rows must be a slice of the patterns (e.g. slice(0, 64)), got "
                             f"{rows!r}")
        x = real_array(x, "x", ndim=2)
        if x.shape[0] != self.shape[1]:
            raise ValueError(f"x of shape {x.shape} for patterns of {self.shape[1]} pixels: "
                             f"(Q, S), one row per pixel")
        return rows, x

    def _product_rows(self, x: np.ndarray, rows: slice, product) -> np.ndarray:
        """A copy of rows ``rows`` of ``product(x)``, the product kept for the next row blocks
        of the same ``x`` (a block handed out as a view and zeroed by its caller zeroed the
        next call's, an audit of 2026-11-30).

        Keyed by content as well as identity: an ``x`` changed in place between two calls (a
        notebook reusing its buffer) got the old product back. The CRC-32 of its bytes
        (7 GB/s, no copy; a change that keeps it is a 2^-32 chance) costs 0.2 s over the 1 024
        row blocks of a 256x256 simulation, the product ``M`` passes (or a transform)."""
        import zlib

        arr = np.ascontiguousarray(x)
        key = (id(x), arr.shape, arr.dtype.str, zlib.crc32(arr.view(np.uint8).ravel()))
        cache = getattr(self, "_rows_cache", None)
        if cache is None or cache[0] != key:
            cache = (key, product(x))
            self._rows_cache = cache
        return cache[1][rows].copy()

    def centred(self, norm: float = 1.0, dtype=np.float32) -> LinearOperator:
        """``(Phi - 1 mu^T) / norm`` in ``dtype``: the operator of the centred QCR data term."""
        return CentredPatterns(self, norm, dtype)

    def as_dtype(self, dtype) -> LinearOperator:
        """Phi itself in the solve precision ``dtype`` (the operator without QCR)."""
        return self if np.dtype(dtype) == self.dtype else _Cast(self, dtype)

    @property
    def nbytes(self) -> int:
        """Memory held by the pattern set (0 for implicit operators without tables)."""
        return 0


class _Cast(LinearOperator):
    def __init__(self, op: LinearOperator, dtype):
        super().__init__(op.shape, dtype)
        self.op = op

    def _matvec(self, x):
        return np.asarray(self.op._matvec(x), dtype=self.dtype)

    def _rmatvec(self, y):
        return np.asarray(self.op._rmatvec(y), dtype=self.dtype)


class CentredPatterns(LinearOperator):
    """``(Phi - 1 mu^T) / norm`` applied implicitly: ``Phi x - 1 (mu . x)`` and its adjoint
    ``Phi^T y - mu (1 . y)`` (eq. 11: the patterns' mean removed, never forming Phi_c)."""

    def __init__(self, phi: PatternOperator, norm: float = 1.0, dtype=np.float32):
        super().__init__(phi.shape, dtype)
        self.phi = phi
        self.norm = float(norm)
        self.mu = phi.mean_pattern()

    def _matvec(self, x):
        x64 = np.asarray(x, dtype=np.float64)
        out = np.asarray(self.phi._matvec(np.asarray(x, dtype=self.phi.dtype)), np.float64)
        out -= (self.mu @ x64)[None, :]
        return (out / self.norm).astype(self.dtype, copy=False)

    def _rmatvec(self, y):
        y64 = np.asarray(y, dtype=np.float64)
        out = np.asarray(self.phi._rmatvec(np.asarray(y, dtype=self.phi.dtype)), np.float64)
        out -= np.outer(self.mu, y64.sum(axis=0))
        return (out / self.norm).astype(self.dtype, copy=False)
