"""The numeric core on any array-API namespace: simulation, matched filter, centred QCR,
power norm, FISTA with the TV prox, and the argmax depth.

Every function takes arrays of one namespace ``xp`` on one device and keeps them there (the
only host round trips are the scalars of the stop tests, one small vector per FISTA iteration).
Each mirrors a NumPy kernel of the package, operation for operation where that matters for
round-off, so that with the NumPy random streams (``array-api-strict``, ``--backend numpy``
through this path) the results agree with the NumPy path to float32 precision:

* :func:`simulate_block` - :func:`spslidar.pipeline.simulate._simulate_fast`'s block
  (:func:`spslidar.forward.expected_counts`, :func:`spslidar.correlate.matched_filter`);
* :func:`centred_matrix` - :func:`spslidar.patterns.dense.centred_patterns`;
* :func:`power_norm` - :func:`spslidar.operators.base.power_norm`;
* :class:`TVProx` - the FGP loop of :class:`spslidar.solvers.regularisers.TV`
  (isotropic, warm-started);
* :func:`fista_tv` - plain :class:`spslidar.solvers.fista.FISTA` with its stop rules.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["DenseOperator", "TVProx", "argmax_peaks", "centre", "centred_matrix", "fista_tv",
           "power_norm", "simulate_block"]

#: rows per block of the float64 work in :func:`centred_matrix` and :func:`row_mean`
_ROWS = 1024


def centre(xp: Any, a: Any) -> Any:
    """Subtract the mean over axis 0 (the patterns)."""
    return a - xp.mean(a, axis=0, keepdims=True)


def row_mean(xp: Any, a: Any) -> Any:
    """Mean over axis 0 accumulated in float64, a block of rows at a time (no full-size
    float64 copy)."""
    acc = None
    n = a.shape[0]
    for r in range(0, n, _ROWS):
        s = xp.sum(xp.astype(a[r:min(r + _ROWS, n), ...], xp.float64), axis=0)
        acc = s if acc is None else acc + s
    return acc / a.shape[0]


def centred_matrix(xp: Any, phi: Any, norm: float, dtype: Any) -> Any:
    """``(Phi - mean_i Phi) / norm`` in ``dtype``, computed in float64 a block at a time.

    Parameters
    ----------
    xp : namespace
    phi : array, shape (M, Q)
    norm : float
        ``sqrt(M)`` for the centred data term.
    dtype : dtype of ``xp``

    Returns
    -------
    array, shape (M, Q)
    """
    mean = row_mean(xp, phi)
    n, norm = phi.shape[0], float(norm)
    parts = [xp.astype((xp.astype(phi[r:min(r + _ROWS, n), ...], xp.float64) - mean) / norm,
                       dtype)
             for r in range(0, n, _ROWS)]
    return parts[0] if len(parts) == 1 else xp.concat(parts, axis=0)


class DenseOperator:
    """``A`` held as a matrix: ``matvec(x) = A @ x``, ``rmatvec(y) = A^T @ y``.

    Parameters
    ----------
    matrix : array, shape (M, N)
    """

    def __init__(self, matrix: Any):
        self.matrix = matrix
        self.shape = tuple(matrix.shape)
        self.dtype = matrix.dtype

    def matvec(self, x: Any) -> Any:
        """``A @ x`` for ``x`` of shape ``(N,)`` or ``(N, K)``."""
        return self.matrix @ x

    def rmatvec(self, y: Any) -> Any:
        """``A^T @ y`` for ``y`` of shape ``(M,)`` or ``(M, K)``."""
        return self.matrix.T @ y


def simulate_block(xp: Any, amp: Any, code_matrix: Any, noise_bin: Any,
                   signal: float, n_periods: int) -> tuple[Any, Any]:
    """Expected counts per TDC bin of a block of patterns (eq. 4).

    Parameters
    ----------
    xp : namespace
    amp : array, float64, shape (B, S)
        The block's return amplitudes ``Phi[block] @ W`` (``W`` of
        :func:`spslidar.forward.return_weights`).
    code_matrix : array, float32, shape (S, L)
        :func:`spslidar.forward.shifted_codes`.
    noise_bin : array, shape (B,)
        Noise counts per bin per period.
    signal : float
        ``m_s``.
    n_periods : int

    Returns
    -------
    amp : array, float64, shape (B, S)
    lam : array, float32, shape (B, L)
        ``n_periods * (m_s * amp @ code_matrix + noise)``, as
        :func:`spslidar.forward.expected_counts` forms it.
    """
    signal, n_periods = float(signal), int(n_periods)
    lam = (signal * xp.astype(amp, code_matrix.dtype)) @ code_matrix
    lam = lam + xp.reshape(xp.astype(noise_bin, code_matrix.dtype), (-1, 1))
    if n_periods != 1:
        lam = lam * n_periods
    return amp, lam


def scalars(be: Any, *values: Any) -> list[float]:
    """0-d device arrays as Python floats in one transfer."""
    xp = be.xp
    stacked = xp.stack([xp.astype(v, xp.float64) for v in values])
    return [float(v) for v in be.to_numpy(stacked)]


#: power iterations per host round trip on operators of fewer entries than
#: :data:`POWER_CHUNK_MAX_SIZE` (small problems are bound by the round trips; on large ones a
#: product costs more than a round trip, and iterations past convergence would be wasted)
POWER_CHUNK = 8
POWER_CHUNK_MAX_SIZE = 1 << 24


def power_norm(be: Any, A: DenseOperator, n_iter: int = 50, rtol: float = 1e-4,
               seed: int = 0) -> float:
    """``||A||_2`` by power iteration on ``A^T A`` (1.01 x the converged value), from the
    NumPy path's start vector (``default_rng(seed).standard_normal``).

    The same iterates and stop as :func:`spslidar.operators.base.power_norm`; on small
    operators the norms of :data:`POWER_CHUNK` iterations come back in one transfer and the
    first that meets the test is taken (the ones after it are discarded).
    """
    xp = be.xp
    x0 = np.random.default_rng(seed).standard_normal(A.shape[1])
    x = xp.astype(be.asarray(x0 / np.linalg.norm(x0)), A.dtype)
    chunk = POWER_CHUNK if A.shape[0] * A.shape[1] < POWER_CHUNK_MAX_SIZE else 1
    s_old = s = 0.0
    done = 0
    while done < n_iter:
        norms = []
        for _ in range(min(chunk, n_iter - done)):
            z = xp.astype(A.rmatvec(A.matvec(x)), xp.float64)
            sd = xp.sqrt(xp.sum(z * z))
            norms.append(sd)
            x = xp.astype(z / sd, A.dtype)
        for s in scalars(be, *norms):
            if s == 0.0:
                return 0.0
            if abs(s - s_old) <= rtol * s:
                return 1.01 * math.sqrt(s)
            s_old = s
        done += len(norms)
    return 1.01 * math.sqrt(s)


class TVProx:
    """Isotropic or anisotropic TV (forward differences, Neumann edges) with the warm-started
    FGP prox of :class:`spslidar.solvers.regularisers.TV`, on ``(Q, K)`` blocks of any
    namespace.

    Parameters
    ----------
    xp : namespace
    image_shape : (Ny, Nx)
    isotropic : bool
        Project the dual onto unit disks (isotropic TV, ``--regulariser tv``) or unit boxes
        (anisotropic, ``tv-aniso``).
    nonneg : bool
        Project the prox onto ``z >= 0``.
    max_inner : int
        FGP iterations per prox call.
    inner_tol : float
        FGP stops when ``||p_k - p_{k-1}|| <= inner_tol ||p_k||``.
    be : Backend
        The backend that brings the stopping test's scalars to the host, one transfer each
        (``scalars``); every caller passes it.
    """

    def __init__(self, xp: Any, image_shape: tuple[int, int], nonneg: bool = True,
                 max_inner: int = 20, inner_tol: float = 1e-3, be: Any = None,
                 isotropic: bool = True):
        self.xp, self.be = xp, be
        self.isotropic = bool(isotropic)
        self.image_shape = (int(image_shape[0]), int(image_shape[1]))
        self.nonneg = bool(nonneg)
        self.max_inner = int(max_inner)
        self.inner_tol = float(inner_tol)
        self._p: tuple[Any, Any] | None = None
        self.last_inner_iterations = 0

    def reset(self) -> None:
        """Drop the warm-start dual."""
        self._p = None

    def _cube(self, x: Any) -> Any:
        ny, nx = self.image_shape
        return self.xp.reshape(x, (ny, nx, x.shape[1]))

    def _zeros_like_edge(self, a: Any, axis: int) -> Any:
        shape = list(a.shape)
        shape[axis] = 1
        return self.xp.zeros(tuple(shape), dtype=a.dtype, device=a.device)

    def gradient(self, z: Any) -> tuple[Any, Any]:
        """Forward differences ``(down, right)`` of ``(Ny, Nx, K)`` images, zero on the last
        row / column."""
        xp = self.xp
        g0 = xp.concat([z[1:, ...] - z[:-1, ...], self._zeros_like_edge(z, 0)], axis=0)
        g1 = xp.concat([z[:, 1:, ...] - z[:, :-1, ...], self._zeros_like_edge(z, 1)], axis=1)
        return g0, g1

    def neg_div(self, p0: Any, p1: Any, v: Any = None) -> Any:
        """``v - G^T p`` (``v`` zero when ``None``); ``p0``'s last row and ``p1``'s last
        column must be zero."""
        xp = self.xp
        out = p0 if v is None else v + p0
        out = out + p1
        out = out - xp.concat([self._zeros_like_edge(p0, 0), p0[:-1, ...]], axis=0)
        return out - xp.concat([self._zeros_like_edge(p1, 1), p1[:, :-1, ...]], axis=1)

    def values(self, x: Any) -> Any:
        """Per-column TV, shape ``(K,)`` (float64)."""
        xp = self.xp
        g0, g1 = self.gradient(self._cube(x))
        mag = xp.sqrt(g0 * g0 + g1 * g1) if self.isotropic else xp.abs(g0) + xp.abs(g1)
        return xp.astype(xp.sum(xp.reshape(mag, (-1, x.shape[1])), axis=0), xp.float64)

    def project(self, q0: Any, q1: Any) -> tuple[Any, Any]:
        """The dual ``(q0, q1)`` projected onto the pixel-wise unit disks (isotropic) or unit
        boxes (anisotropic)."""
        xp = self.xp
        if not self.isotropic:
            return xp.clip(q0, min=-1.0, max=1.0), xp.clip(q1, min=-1.0, max=1.0)
        w = xp.sqrt(xp.clip(q0 * q0 + q1 * q1, min=1.0))
        return q0 / w, q1 / w

    def prox(self, v: Any, t: float) -> Any:
        """``argmin_z 1/2 ||z - v||^2 + t TV(z)`` (``+ i_{z >= 0}``) per column of ``v``."""
        xp = self.xp
        v3 = self._cube(v)
        # (a t below round-off of the largest |v| is the identity, as on the host: v / t gave
        # NaN in float32 at --lam 1e-39, said as a diverged solve, an audit of 2026-11-29; the
        # first mend, t * finfo.max < 1 alone, left 3e-39 diverging, a review. |v|'s largest
        # is read off the device only for a t that small)
        fi = xp.finfo(v3.dtype)
        if (t == 0.0 or t * float(fi.max) < 1.0
                or (t < 1e-20 and 8.0 * t <= float(fi.eps) * float(
                    scalars(self.be, xp.max(xp.abs(v3)))[0]))):
            z = xp.clip(v3, min=0.0) if self.nonneg else v3
            return xp.reshape(z, v.shape)
        if self._p is None or self._p[0].shape != v3.shape:
            z0 = xp.zeros(v3.shape, dtype=v.dtype, device=v.device)
            self._p = (z0, z0)
        p0, p1 = self._p
        vt = v3 * (1.0 / t)
        r0, r1 = p0, p1
        tol2 = self.inner_tol ** 2
        s = 1.0
        it = 0
        for it in range(1, self.max_inner + 1):  # noqa: B007 - reported
            last = it == self.max_inner
            s_new = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * s * s))
            c = (s - 1.0) / s_new
            z = self.neg_div(r0, r1, vt)
            if self.nonneg:
                z = xp.clip(z, min=0.0)
            z = z * 0.125
            g0, g1 = self.gradient(z)
            q0, q1 = g0 + r0, g1 + r1
            q0, q1 = self.project(q0, q1)
            if last:
                p0, p1 = q0, q1
                break
            d0, d1 = q0 - p0, q1 - p1
            dn2, pn2 = scalars(self.be, xp.sum(d0 * d0) + xp.sum(d1 * d1),
                               xp.sum(q0 * q0) + xp.sum(q1 * q1))
            if c > 0.0:
                r0, r1 = q0 + c * d0, q1 + c * d1
            else:
                r0, r1 = q0, q1
            p0, p1 = q0, q1
            s = s_new
            if dn2 <= tol2 * max(pn2, 1e-60):
                break
        self._p = (p0, p1)
        self.last_inner_iterations = it
        out = self.neg_div(p0, p1) * t + v3
        if self.nonneg:
            out = xp.clip(out, min=0.0)
        return xp.reshape(out, v.shape)


@dataclass
class FistaInfo:
    """What :func:`fista_tv` reports (the fields of :class:`spslidar.solvers.SolveInfo`)."""

    iterations: int = 0
    objective: list[float] = field(default_factory=list)
    stop_reason: str = ""
    L: float = 0.0


def stop_reason(finite: bool, dn2: float, xn2: float, it: int, rtol: float,
                max_iter: int) -> str:
    """Why FISTA stops after iteration ``it`` (``""``: go on): ``'diverged'`` if the
    objective or norms are not finite, ``'rtol'`` if ``||x_k - x_{k-1}|| <= rtol ||x_k||``
    (from the second iteration), ``'max_iter'`` at the cap; the rules of
    :class:`~spslidar.solvers.base.StopRule`, shared by :func:`fista_tv` and the CUDA-graph
    loop (:mod:`spslidar.backends.torch_graph`)."""
    if not finite:
        return "diverged"
    if rtol > 0 and it > 1 and math.sqrt(dn2) <= rtol * max(math.sqrt(xn2), 1e-300):
        return "rtol"
    if it >= max_iter:
        return "max_iter"
    return ""


def fista_tv(be: Any, A: DenseOperator, y: Any, reg: TVProx, lam: float, max_iter: int,
             rtol: float, L: float | None = None) -> tuple[Any, FistaInfo]:
    """Plain FISTA on ``1/2 ||A x - y||^2 + lam TV(x)``, all columns at once.

    The iteration, the in-place extrapolation order, the objective per iteration and the stop
    rules (``rtol`` on the relative change of the iterate from the second iteration on, then
    ``max_iter``) are those of :class:`spslidar.solvers.fista.FISTA`; one host round trip per
    iteration carries the objective and the two norms of the stop test.

    Returns
    -------
    x : array, shape (N, K)
    info : FistaInfo
    """
    xp = be.xp
    if L is None:
        L = power_norm(be, A) ** 2
    if not (math.isfinite(L) and L > 0):
        raise ValueError(f"Lipschitz constant must be positive and finite, got {L}")
    L, lam = float(L), float(lam)
    info = FistaInfo(L=L)
    n, k = A.shape[1], y.shape[1]
    x = xp.zeros((n, k), dtype=y.dtype, device=y.device)
    ax = xp.zeros(y.shape, dtype=y.dtype, device=y.device)
    yk, ayk = x, ax
    neg_inv_l = -1.0 / L
    thr = lam / L
    t = 1.0
    for it in range(1, max_iter + 1):
        g = A.rmatvec(ayk - y) * neg_inv_l + yk
        z = reg.prox(g, thr)
        az = A.matvec(z)
        r = az - y
        obj = 0.5 * xp.sum(r * r) + lam * xp.sum(reg.values(z))
        t_new = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * t * t))
        c_m = (t - 1.0) / t_new
        x_old, ax_old = x, ax
        x, ax, t = z, az, t_new
        d = x - x_old
        f, dn2, xn2 = scalars(be, obj, xp.sum(d * d), xp.sum(x * x))
        info.objective.append(f)
        info.iterations = it
        reason = stop_reason(math.isfinite(f), dn2, xn2, it, rtol, max_iter)
        if reason:
            info.stop_reason = reason
            break
        yk = d * c_m + x
        ayk = ax + c_m * (ax - ax_old)
    return x, info


def argmax_peaks(xp: Any, slices: Any) -> tuple[Any, Any, Any, Any]:
    """Each row's first maximum and the values either side of it.

    Returns
    -------
    idx : array of int, shape (Q,)
        ``argmax`` over axis 1 (the first of equal maxima).
    peak, below, above : arrays, shape (Q,)
        The values at ``idx``, ``idx - 1`` and ``idx + 1`` (clipped to the row).
    """
    idx = xp.argmax(slices, axis=1)
    peak = xp.max(slices, axis=1)
    k = slices.shape[1]
    lo = xp.clip(idx - 1, min=0, max=k - 1)
    hi = xp.clip(idx + 1, min=0, max=k - 1)
    below = xp.take_along_axis(slices, xp.reshape(lo, (-1, 1)), axis=1)[:, 0]
    above = xp.take_along_axis(slices, xp.reshape(hi, (-1, 1)), axis=1)[:, 0]
    return idx, peak, below, above


