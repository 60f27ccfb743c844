"""Pattern sets on a backend's device: dense matrices, and Walsh-Hadamard rows applied by a
transform (never formed), with the products the chain needs (return amplitudes of a block of
patterns, the centred QCR operator).

The Hadamard transform is written as two matrix products: for ``Q = N^2`` the Sylvester matrix
is ``H_Q = H_N (x) H_N``, so ``H_Q x = vec(H_N X H_N)`` for the image ``X`` of ``x`` (rows
``i``, columns ``j``, C order). On a GPU the two products with the ``N x N`` matrix of +-1
(``2 N^3 K`` flops each) run on the matrix units and cost less than the ``log2 Q`` passes of a
butterfly transform over the ``(Q, K)`` block.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .kernels import DenseOperator, centred_matrix

__all__ = ["DeviceHadamard", "DevicePatterns", "device_patterns", "fwht", "host_patterns"]


class DevicePatterns:
    """A dense pattern set held on the device as its ``(M, Q)`` matrix.

    Parameters
    ----------
    matrix : array, shape (M, Q)
    backend : Backend
    kind : str
    host : PatternOperator, optional
        The host operator the matrix was copied from (None: drawn on the device).
    """

    def __init__(self, matrix: Any, backend: Any, kind: str, host: Any = None):
        self.matrix, self.backend, self.kind = matrix, backend, kind
        self.shape = tuple(matrix.shape)
        self.dtype = matrix.dtype
        #: the host operator it was copied from (None: drawn on the device)
        self.host = host

    @property
    def nbytes(self) -> int:
        """Bytes of the matrix (on the device)."""
        itemsize = 4 if self.dtype == self.backend.xp.float32 else 8
        return int(self.shape[0] * self.shape[1] * itemsize)

    def rows_apply(self, a: int, e: int, w: Any) -> Any:
        """``Phi[a:e] @ w`` in float64 (``w`` float64, shape ``(Q, S)``)."""
        xp = self.backend.xp
        return xp.astype(self.matrix[a:e, ...], xp.float64) @ w

    def centred(self, norm: float, dtype: Any) -> DenseOperator:
        """``(Phi - mean_i Phi) / norm`` as an operator (:func:`centred_matrix`)."""
        return DenseOperator(centred_matrix(self.backend.xp, self.matrix, norm, dtype))


def hadamard_matrix(xp: Any, n: int, dtype: Any, device: Any) -> Any:
    """The ``n x n`` Sylvester Hadamard matrix (``n`` a power of two) on ``device``."""
    h = np.ones((1, 1))
    while h.shape[0] < n:
        h = np.block([[h, h], [h, -h]])
    return xp.asarray(h, dtype=dtype, device=device)


def fwht(xp: Any, x: Any, h: Any) -> Any:
    """``H_Q x`` for ``x`` of shape ``(Q, K)``, ``Q = N^2``, given ``h = H_N``: two matrix
    products (rows of the image, then its columns)."""
    n = h.shape[0]
    k = x.shape[1]
    y = xp.reshape(h @ xp.reshape(x, (n, n * k)), (n, n, k))  # along the image rows
    return xp.reshape(h @ y, (n * n, k))  # batched over rows: along the image columns


class DeviceHadamard:
    """``M`` rows of a (scrambled) Walsh-Hadamard matrix shown as ``(1 + h)/2`` on the DMD
    (the ``shifted`` and ``complementary`` realisations of
    :class:`spslidar.patterns.hadamard.HadamardPatterns`; the latter's row signs are part of
    ``h``), applied on the device.

    Parameters
    ----------
    host : HadamardPatterns
        The host operator (its rows, signs and permutation are copied to the device).
    backend : Backend
    """

    def __init__(self, host: Any, backend: Any):
        xp, dev = backend.xp, backend.device
        self.backend, self.kind = backend, host.kind
        self.shape = tuple(host.shape)
        q, m = self.shape[1], self.shape[0]
        self.n = int(host.n_side)
        self.rows = backend.asarray(np.asarray(host.rows, dtype=np.int64))
        # S^T y as a gather: row r of H_Q takes y[pos[r]], or the appended zero row
        pos = np.full(q, m, dtype=np.int64)
        pos[np.asarray(host.rows)] = np.arange(m)
        self.scatter = backend.asarray(pos)
        self.signs = (None if host.signs is None
                      else backend.asarray(np.asarray(host.signs, np.float64).reshape(-1, 1)))
        flips = getattr(host, "flips", None)
        self.flips = (None if flips is None
                      else backend.asarray(np.asarray(flips, np.float64).reshape(-1, 1)))
        self.perm = self.inv_perm = None
        if host.perm is not None:
            inv = np.empty(q, dtype=np.int64)
            inv[np.asarray(host.perm)] = np.arange(q)
            self.perm, self.inv_perm = backend.asarray(host.perm), backend.asarray(inv)
        self._h = {}
        self.dtype = xp.float32
        self._dev = dev
        #: the host operator (a stage with no device kernel runs on it)
        self.host = host

    @property
    def nbytes(self) -> int:
        """Bytes of the index and sign tables (on the device)."""
        return int(8 * (self.shape[0] * (1 + (self.flips is not None)) + 3 * self.shape[1]))

    def _hmat(self, dtype: Any) -> Any:
        key = str(dtype)
        if key not in self._h:
            self._h[key] = hadamard_matrix(self.backend.xp, self.n, dtype, self._dev)
        return self._h[key]

    def h(self, x: Any) -> Any:
        """``S H D P x`` for ``x`` of shape ``(Q, K)``."""
        xp = self.backend.xp
        z = x if self.perm is None else xp.take(x, self.perm, axis=0)
        if self.signs is not None:
            z = z * xp.astype(self.signs, z.dtype)
        z = xp.take(fwht(xp, z, self._hmat(z.dtype)), self.rows, axis=0)
        return z if self.flips is None else z * xp.astype(self.flips, z.dtype)

    def ht(self, y: Any) -> Any:
        """``P^T D H S^T y`` for ``y`` of shape ``(M, K)``."""
        xp = self.backend.xp
        zero = xp.zeros((1, y.shape[1]), dtype=y.dtype, device=y.device)
        if self.flips is not None:
            y = y * xp.astype(self.flips, y.dtype)
        z = xp.take(xp.concat([y, zero], axis=0), self.scatter, axis=0)
        z = fwht(xp, z, self._hmat(z.dtype))
        if self.signs is not None:
            z = z * xp.astype(self.signs, z.dtype)
        return z if self.inv_perm is None else xp.take(z, self.inv_perm, axis=0)

    def apply(self, x: Any) -> Any:
        """``Phi x = (1 1^T x + h x) / 2``."""
        xp = self.backend.xp
        return (self.h(x) + xp.sum(x, axis=0, keepdims=True)) * 0.5

    def apply_t(self, y: Any) -> Any:
        """``Phi^T y = (h^T y + 1 1^T y) / 2``."""
        xp = self.backend.xp
        return (self.ht(y) + xp.sum(y, axis=0, keepdims=True)) * 0.5

    def rows_apply(self, a: int, e: int, w: Any) -> Any:
        """``Phi[a:e] @ w`` in float64 (one transform of ``w`` serves every block)."""
        cache = getattr(self, "_rows_cache", None)
        if cache is None or cache[0] is not w:
            self._rows_cache = cache = (w, self.apply(w))
        return cache[1][a:e, ...]

    def centred(self, norm: float, dtype: Any) -> _CentredHadamard:
        """``(Phi - 1 mu^T) / norm`` with ``mu`` the mean pattern."""
        xp = self.backend.xp
        m = self.shape[0]
        ones = xp.ones((m, 1), dtype=xp.float64, device=self._dev)
        mu = xp.astype(self.apply_t(ones) / m, dtype)
        return _CentredHadamard(self, mu, float(norm), dtype)


class _CentredHadamard:
    """The centred QCR operator of a :class:`DeviceHadamard` pattern set."""

    def __init__(self, pats: DeviceHadamard, mu: Any, norm: float, dtype: Any):
        self.pats, self.mu, self.norm, self.dtype = pats, mu, norm, dtype
        self.shape = pats.shape

    def matvec(self, x: Any) -> Any:
        xp = self.pats.backend.xp
        x2 = x if x.ndim == 2 else xp.reshape(x, (-1, 1))
        out = (self.pats.apply(x2) - xp.sum(self.mu * x2, axis=0, keepdims=True)) / self.norm
        return out if x.ndim == 2 else out[:, 0]

    def rmatvec(self, y: Any) -> Any:
        xp = self.pats.backend.xp
        y2 = y if y.ndim == 2 else xp.reshape(y, (-1, 1))
        out = (self.pats.apply_t(y2) - self.mu * xp.sum(y2, axis=0, keepdims=True)) / self.norm
        return out if y.ndim == 2 else out[:, 0]


def device_patterns(be: Any, stream: Any, cfg: Any, m: int) -> Any:
    """The run's pattern set on the device: drawn there (``gaussian``, ``bernoulli`` on a
    device stream), or built on the host by the registry and copied (dense kinds) or turned
    into a :class:`DeviceHadamard` (``hadamard``, ``scrambled-hadamard``)."""
    xp = be.xp
    dtype = xp.float32 if cfg.dtype == "float32" else xp.float64
    if not stream.host and cfg.patterns in ("gaussian", "bernoulli"):
        return DevicePatterns(stream.device_patterns(cfg.patterns, m, cfg.size,
                                                     cfg.pattern_sigma, dtype), be, cfg.patterns)
    from ..config import chosen_stage_options
    from ..patterns import build_patterns

    options = {"sigma": cfg.pattern_sigma, **chosen_stage_options(cfg, "patterns")}
    for key in ("hadamard_order", "hadamard_realisation"):
        if hasattr(cfg, key):
            options[key.split("_", 1)[1]] = getattr(cfg, key)
    host = build_patterns(cfg.patterns, m, cfg.size, stream.host_generator(),
                          dtype=np.float32 if cfg.dtype == "float32" else np.float64, **options)
    from ..patterns.dense import check_pattern_set

    # (a plugin's set, checked on the host path only, ran on array-api-strict with negative
    # mirror states and half its rows: a review of 2026-11-30)
    check_pattern_set(host, cfg.patterns, m, cfg.size)
    if hasattr(host, "matrix"):
        return DevicePatterns(be.asarray(host.matrix), be, cfg.patterns, host)
    if hasattr(host, "rows") and getattr(host, "mode", "shifted") == "shifted":
        return DeviceHadamard(host, be)
    return DevicePatterns(be.asarray(host.todense()), be, cfg.patterns, host)


def host_patterns(patterns: Any) -> Any:
    """The NumPy pattern operator of a device pattern set, for a stage that runs on the
    host: the operator it was built from, or its matrix brought back (patterns drawn on the
    device); a NumPy operator is returned as it is."""
    from ..patterns import as_patterns

    if not isinstance(patterns, (DevicePatterns, DeviceHadamard)):
        return patterns
    if patterns.host is not None:
        return patterns.host
    return as_patterns(patterns.backend.to_numpy(patterns.matrix), copy=False)
