"""Regularisers ``R`` of equation (18) with their proximal operators, batched over column blocks.

Every regulariser acts on a block ``x`` of shape ``(Q, K)`` (K images of ``Q = Ny * Nx``
pixels, one per range slice, flattened in C order) or on a single column ``(Q,)``:

* ``reg(x)`` is the unweighted value ``R(x)`` summed over the columns;
* ``reg.values(x)`` is the per-column value, shape ``(K,)`` (used by the monotone solvers,
  which accept or reject steps column by column since the K problems are independent);
* ``reg.prox(v, t)`` is ``argmin_z 1/2 ||z - v||^2 + t R(z)``, column by column.

With ``nonneg=True`` the regulariser is ``R(x) + i_{x >= 0}(x)``; the indicator is left out of
the reported value (iterates produced by the proxes are always feasible).
"""

from __future__ import annotations

import threading
import warnings
from typing import Any

import numpy as np

from ..arrays import pair_shape, positive_number, real_array, real_scalar
from ..capture import carried
from ..operators import parallel as _parallel
from ..operators.base import LinearOperator
from ..operators.image import Gradient2D, forward_differences_into
from .base import as_block as _as_block

__all__ = ["Regulariser", "TV", "L1", "Zero", "make_tv", "make_tv_aniso", "make_l1",
           "make_wavelet_l1"]


def _sqnorm(a: np.ndarray) -> float:
    """Squared 2-norm of a contiguous array.

    float32 goes through BLAS ``sdot``; float64 through ``einsum``, because OpenBLAS' threaded
    ``ddot`` on long vectors was measured 100x slower than single-threaded on a loaded 2-core
    machine (thread hand-off), which made the FGP loop crawl.
    """
    a = a.ravel()
    if a.dtype == np.float32:
        return float(np.dot(a, a))
    return float(np.einsum("i,i->", a, a))


def _colsum(a: np.ndarray) -> np.ndarray:
    """Column sums of a 2-D block as float64.

    float32 goes through BLAS (``sgemv`` with a vector of ones, float32 accumulation with a
    relative error of about 1e-6, five times faster than NumPy's strided float64 reduction);
    float64 through ``einsum``.
    """
    if a.dtype == np.float32:
        return (np.ones(a.shape[0], dtype=np.float32) @ a).astype(np.float64)
    return np.einsum("qk->k", a, dtype=np.float64)


def _float_dtype(x: np.ndarray) -> np.dtype:
    return x.dtype if x.dtype in (np.float32, np.float64) else np.dtype(np.float64)


def image_cube(x: np.ndarray, image_shape: tuple[int, int], what: str = "TV") -> np.ndarray:
    """A ``(Q, K)`` block as its ``(Ny, Nx, K)`` images; one clear error where ``Q`` is not
    ``Ny * Nx`` (the TVs' shared check)."""
    ny, nx = image_shape
    if x.shape[0] != ny * nx:
        raise ValueError(f"{what} on {ny}x{nx} images applied to {x.shape[0]} rows")
    return x.reshape(ny, nx, x.shape[1])


class Regulariser:
    """Base class: subclasses implement :meth:`values` and :meth:`_prox` on ``(Q, K)`` blocks.

    Attributes
    ----------
    nonneg : bool
        Whether the prox also projects onto ``x >= 0``.
    """

    nonneg: bool = False

    def values(self, x: np.ndarray) -> np.ndarray:
        """Per-column values ``R(x[:, k])``, shape ``(K,)`` (``(1,)`` for a 1-D ``x``)."""
        xb, _ = _as_block(x)
        return self._values(xb)

    def __call__(self, x: np.ndarray) -> float:
        """Unweighted value ``R(x)`` summed over all columns."""
        return float(np.sum(self.values(x)))

    def prox(self, v: np.ndarray, t: float) -> np.ndarray:
        """``argmin_z 1/2 ||z - v||^2 + t R(z)`` for each column of ``v``.

        Parameters
        ----------
        v : ndarray, shape (Q,) or (Q, K)
        t : float
            Finite non-negative threshold (``lam * step`` inside a proximal-gradient solver).

        Returns
        -------
        ndarray
            Same shape as ``v``; float32 or float64 as ``v`` (any other dtype, float16 or
            integers, in float64).

        Raises
        ------
        ValueError
            For a ``t`` that is not a finite non-negative number, or a ``v`` that is not real
            (a NaN ``t`` gave all NaN, a complex ``v`` was cast to its real part with numpy's
            warning: an audit of 2026-12-02).
        """
        real_scalar(t, "prox threshold t", low=0.0, finite=True)
        v = real_array(v, "v")
        vb, was_1d = _as_block(v)
        vb = vb.astype(_float_dtype(vb), copy=False)
        z = self._prox(vb, float(t))
        if np.shape(z) != vb.shape:
            # (a plugin's wrong shape ended as an operator's shape error in the solver's next
            # product, a traceback: an outside audit of 2026-12-01)
            from ..errors import ConfigError

            raise ConfigError(f"the regulariser {type(self).__module__}."
                              f"{type(self).__qualname__}: its _prox() returned an array of "
                              f"shape {np.shape(z)} for one of {vb.shape}")
        return z[:, 0] if was_1d else z

    def reset(self) -> None:
        """Forget any warm-start state (no-op for stateless regularisers)."""

    # -- to implement ----------------------------------------------------------------------
    def _values(self, x: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _prox(self, v: np.ndarray, t: float) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError


class Zero(Regulariser):
    """``R = 0``: plain (optionally non-negative) least squares.

    Parameters
    ----------
    nonneg : bool
        If true the prox is the projection ``max(v, 0)``, otherwise the identity.

    Notes
    -----
    ``prox(v, t) = argmin_z 1/2 ||z - v||^2 + i_{z >= 0}(z)`` (nonneg) or ``v``.
    """

    def __init__(self, nonneg: bool = False):
        self.nonneg = bool(nonneg)

    def _values(self, x):
        return np.zeros(x.shape[1])

    def _prox(self, v, t):
        return np.maximum(v, 0) if self.nonneg else v.copy()

    def __repr__(self) -> str:
        return f"Zero(nonneg={self.nonneg})"


class L1(Regulariser):
    """Sparsity in an orthonormal basis, ``R(x) = ||W x||_1``.

    Parameters
    ----------
    basis : LinearOperator or None
        Orthonormal analysis operator ``W`` (e.g. :class:`~spslidar.operators.Wavelet2D`);
        ``None`` means the identity (sparsity in the pixel domain).
    nonneg : bool
        Add the constraint ``x >= 0``. Only available with the identity basis, where the prox
        stays in closed form (``max(v - t, 0)``); with a general basis it is not separable.

    Notes
    -----
    For orthonormal ``W`` (``W^H W = W W^H = I``),

        prox_{t R}(v) = argmin_z 1/2 ||z - v||^2 + t ||W z||_1 = W^H soft(W v, t),

    with ``soft(u, t) = sign(u) max(|u| - t, 0)``, because the change of variables ``c = W z``
    preserves the quadratic term. The basis is *not* checked for orthonormality.
    """

    def __init__(self, basis: LinearOperator | None = None, nonneg: bool = False):
        if nonneg and basis is not None:
            raise ValueError("nonneg L1 is only available with the identity basis")
        self.basis = basis
        self.nonneg = bool(nonneg)

    def _check(self, x: np.ndarray) -> None:
        # (a basis of other images ran on the problem's, as TV's row check refuses, an audit)
        if self.basis is not None and x.shape[0] != self.basis.shape[1]:
            raise ValueError(f"the l1 basis takes {self.basis.shape[1]} pixels, the problem "
                             f"has {x.shape[0]} rows")

    def _values(self, x):
        self._check(x)
        c = x if self.basis is None else self.basis.matvec(x)
        return np.sum(np.abs(c), axis=0, dtype=np.float64)

    def _prox(self, v, t):
        self._check(v)
        if self.basis is None:
            if self.nonneg:
                return np.maximum(v - np.asarray(t, dtype=v.dtype), 0)
            return _soft(v, t)
        c = self.basis.matvec(v)
        return self.basis.rmatvec(_soft(c, t)).astype(v.dtype, copy=False)

    def __repr__(self) -> str:
        return f"L1(basis={self.basis!r}, nonneg={self.nonneg})"


def _soft(u: np.ndarray, t: float) -> np.ndarray:
    """Soft thresholding ``sign(u) max(|u| - t, 0)``."""
    out = np.abs(u)
    out -= np.asarray(t, dtype=out.dtype)
    np.maximum(out, 0, out=out)
    out *= np.sign(u)
    return out


class TV(Regulariser):
    """Total variation of each image column, with a fast warm-started batched prox.

    ``TV(x) = sum_q sqrt((D_y x)_q^2 + (D_x x)_q^2)`` (isotropic) or
    ``sum_q |(D_y x)_q| + |(D_x x)_q|`` (anisotropic), with the forward differences and
    Neumann boundary of :class:`~spslidar.operators.Gradient2D` (the TV of eq. 18).

    Parameters
    ----------
    image_shape : (Ny, Nx)
        Shape of each image; the columns have ``Q = Ny * Nx`` entries in C order.
    isotropic : bool
        Isotropic (pixel-wise Euclidean norm of the gradient) or anisotropic TV.
    nonneg : bool
        Constrain the prox output to ``z >= 0`` (Beck & Teboulle's constrained variant).
    max_inner : int
        Maximum number of FGP iterations per prox call (a whole number >= 1).
    inner_tol : float
        Finite, non-negative: FGP stops when ``||p_k - p_{k-1}|| <= inner_tol * ||p_k||``
        for the dual iterate ``p`` (norms over the whole block: the columns stop together, so
        a column's prox depends a little on the others' when the test fires before
        ``max_inner``).
    warm_start : bool
        Start each prox from the dual variable of the previous call when the shapes match.
    threads : int or None
        Threads used by the prox of large blocks (at least :attr:`SPLIT_MIN_SIZE` entries),
        which are processed as two bands of image rows. ``None`` (default): the threads of the
        active :func:`~spslidar.operators.parallel.parallel` context (which the solvers enter
        for large problems, with BLAS held to one thread), one outside it. The result does
        not depend on it (the bands, and the order in which their partial norms are added,
        are fixed by the shape).

    Attributes
    ----------
    image_shape : tuple of int
    isotropic, nonneg : bool
    gradient : Gradient2D
        The gradient ``G`` defining the TV. It is built with ``dtype=float32`` so that its
        products keep the precision of their input (``result_type(float32, x.dtype)``): a
        float32 block stays float32, a float64 block stays float64.
    last_inner_iterations : int
        FGP iterations used by the most recent prox call.

    Notes
    -----
    The prox solves, for each column ``v`` and threshold ``t``,

        z* = argmin_z 1/2 ||z - v||^2 + t TV(z)   [+ i_{z >= 0}(z)],

    through its dual: with ``TV(z) = max_{p in P} <p, G z>`` (``P`` = pixel-wise unit balls of
    R^2 for isotropic TV, unit boxes for anisotropic) the primal solution is
    ``z(p) = P_C(v - t G^T p)`` and the dual problem is smooth with gradient Lipschitz constant
    ``t^2 ||G||^2 <= 8 t^2``. We run the fast gradient projection (FGP) of Beck & Teboulle,
    "Fast gradient-based algorithms for constrained total variation image denoising and
    deblurring problems", IEEE TIP 18(11), 2009 (their FGP / constrained FGP with
    ``lambda = t``):

        p_k     = P_P(r_k + 1/(8 t) G P_C(v - t G^T r_k))
        s_{k+1} = (1 + sqrt(1 + 4 s_k^2)) / 2
        r_{k+1} = p_k + (s_k - 1) / s_{k+1} (p_k - p_{k-1})

    on all K columns at once (arrays of shape ``(Ny, Nx, K)`` and ``(2, Ny, Nx, K)``, no loop
    over slices, preallocated buffers and in-place arithmetic, in the dtype of ``v``).

    Implementation: the loop runs on the normalised dual ``p`` (``|p_q| <= 1``) and the scaled
    primal ``z / t = P_C(v / t - G^T r)``, the same iteration with the radius ``t`` divided
    out, so the projection is onto unit balls and the step ``1/8`` costs one pass over the
    primal array. The dual arrays keep zeros on the edges where the forward differences
    vanish, which makes the divergence a few in-place passes; the last inner iteration skips
    the extrapolation and the stop test (whose result would not be used). Large blocks are
    split into two bands of image rows, each of which computes one halo row of ``z`` itself
    and writes its extrapolated dual into alternating buffers, so the bands only meet once
    per inner iteration (to add their partial norms for the stop test): with two threads
    the prox uses both cores of a 2-core machine (NumPy releases the GIL in its loops).

    It is written by hand rather than taken from PyProximal because ``pyproximal.TV.prox``
    restarts its iterative solve from zero at every call and handles one image per call: inside
    FISTA/TwIST, which call the prox every iteration with slowly changing input, warm-starting
    the dual variable from the previous call (kept in this object) is what makes the inner
    solve cheap. Consequently the object is stateful: do not share one instance between solves
    running concurrently in threads (this includes :meth:`values`, which uses the prox's work
    buffers); :meth:`reset` drops the state. With the default ``max_inner`` the prox is
    inexact; repeated on one input it converges (the dual keeps improving across calls), but
    inside plain FISTA, whose input moves with its momentum, the iteration settles a little
    above the minimum (0.2-0.7 % of the objective in the pipeline's solves, with 3 inner
    iterations: see :class:`~spslidar.solvers.fista.FISTA`'s ``monotone``); tighter settings
    give an accurate prox for a one-off denoising.

    The paper being reproduced is Shen et al., pseudo-random spread-spectrum single-pixel ToF
    lidar, eq. (18).
    """

    #: blocks with at least this many entries (Ny * Nx * K) are processed as two row bands
    SPLIT_MIN_SIZE = 1 << 17

    def __init__(
        self,
        image_shape: tuple[int, int],
        isotropic: bool = True,
        nonneg: bool = False,
        max_inner: int = 20,
        inner_tol: float = 1e-3,
        warm_start: bool = True,
        threads: int | None = None,
    ):
        # (a shape of (4.7, 4) was taken as 4 x 4, inner_tol NaN or -1 and threads 1.5 (as 1)
        # were taken: an audit of 2026-12-02)
        self.image_shape = pair_shape(image_shape, "TV's image_shape", 1)
        self.isotropic = bool(isotropic)
        self.nonneg = bool(nonneg)
        self.max_inner = positive_number(max_inner, "max_inner", integer=True)
        self.inner_tol = real_scalar(inner_tol, "inner_tol", low=0.0, finite=True)
        self.warm_start = bool(warm_start)
        self.threads = (None if threads is None
                        else positive_number(threads, "threads", integer=True))
        self.gradient = Gradient2D(self.image_shape, dtype=np.float32)
        self.last_inner_iterations = 0
        # FGP state kept between calls: work buffers and the (normalised) dual of the last call
        self._buf: dict[str, Any] = {}
        self._p: np.ndarray | None = None
        self._scratch: tuple[np.ndarray, np.ndarray] | None = None  # flat, for values()

    def __repr__(self) -> str:
        return (
            f"TV(image_shape={self.image_shape}, isotropic={self.isotropic}, nonneg={self.nonneg})"
        )

    def reset(self) -> None:
        """Drop the warm-start dual variable and the work buffers."""
        self._buf = {}
        self._p = None
        self._scratch = None

    @property
    def dual(self) -> np.ndarray | None:
        """Dual variable ``p`` of the last prox call, shape ``(2, Ny, Nx, K)`` (a copy).

        ``p`` lies in the pixel-wise unit balls (boxes); the prox output was
        ``P_C(v - t G^T p)``. ``None`` before the first call, after :meth:`reset` or when
        ``warm_start`` is off.
        """
        return None if self._p is None else self._p.copy()

    # -- work buffers ---------------------------------------------------------------------
    def _bands(self, shape3: tuple[int, int, int]) -> list[tuple[int, int]]:
        """Row bands ``[(a, e), ...]`` of the FGP loop (fixed by the shape alone)."""
        ny = shape3[0]
        if ny >= 4 and shape3[0] * shape3[1] * shape3[2] >= self.SPLIT_MIN_SIZE:
            h = ny // 2
            return [(0, h), (h, ny)]
        return [(0, ny)]

    def _buffers(self, shape3: tuple[int, int, int], dt: np.dtype) -> dict[str, Any]:
        """Work arrays of the FGP loop, kept between calls of the same shape and dtype.

        The dual arrays ``p``, ``q``, ``ra``, ``rb`` (shape ``(2, Ny, Nx, K)``) are created
        zero and their edges ``[0, -1]`` and ``[1, :, -1]`` (where the forward differences
        vanish) are never written with anything but zeros: the divergence relies on it. Each
        row band ``(a, e)`` has its own primal work array with one halo row (``z``) and a
        scratch array (``w``).
        """
        b = self._buf
        if not b or b["vt"].shape != shape3 or b["vt"].dtype != dt:
            ny, nx, k = shape3
            b = {name: np.zeros((2,) + shape3, dtype=dt) for name in ("p", "q", "ra", "rb")}
            b["vt"] = np.empty(shape3, dtype=dt)
            b["bands"] = self._bands(shape3)
            b["z"] = [np.empty((min(e + 1, ny) - a, nx, k), dtype=dt) for a, e in b["bands"]]
            b["w"] = [np.empty((e - a, nx, k), dtype=dt) for a, e in b["bands"]]
            self._buf = b
            self._p = None
        return b

    def _scratch_pair(self, shape3: tuple[int, int, int], dt: np.dtype):
        """Two scratch arrays of ``shape3`` for :meth:`values` (the prox's when they fit)."""
        b = self._buf
        if b and b["vt"].shape == shape3 and b["vt"].dtype == dt and len(b["bands"]) == 1:
            return b["w"][0], b["vt"]
        size = shape3[0] * shape3[1] * shape3[2]
        s = self._scratch
        if s is None or s[0].size < size or s[0].dtype != dt:
            # flat, grown as needed: values() of column subsets (monotone solvers) of varying
            # width reuse them
            s = (np.empty(size, dtype=dt), np.empty(size, dtype=dt))
            self._scratch = s
        return s[0][:size].reshape(shape3), s[1][:size].reshape(shape3)

    def _n_threads(self, n_bands: int):
        """``(threads, pool)``: the threads for ``n_bands`` bands, and the pool of the active
        parallel context to run them in (``None``: start threads)."""
        if n_bands < 2:
            return 1, None
        if self.threads is not None:
            return max(1, min(n_bands, self.threads)), None
        ctx = _parallel.current()
        if ctx is None:
            return 1, None
        return max(1, min(n_bands, ctx.threads)), ctx.pool

    # -- helpers on (Ny, Nx, K) / (2, Ny, Nx, K) arrays -------------------------------------
    def _cube(self, x: np.ndarray) -> np.ndarray:
        return image_cube(x, self.image_shape)

    @staticmethod
    def _neg_div_rows(p: np.ndarray, a: int, e: int, out: np.ndarray,
                      v: np.ndarray | None = None) -> np.ndarray:
        """``out = (v - G^T p)[a:e]`` (``v`` taken as zero when ``None``): the divergence.

        Requires the edges ``p[0, -1]`` and ``p[1, :, -1]`` to be zero (as for every dual
        array of :meth:`_buffers`): then ``(-G^T p)_{i,j} = p0[i,j] - p0[i-1,j] + p1[i,j] -
        p1[i,j-1]`` with the out-of-range terms dropped. In-place passes only (NumPy's
        in-place arithmetic is markedly faster than three-operand arithmetic here).
        """
        p0, p1 = p[0], p[1]
        if v is None:
            np.copyto(out, p0[a:e])
        else:
            np.copyto(out, v[a:e])
            out += p0[a:e]
        out += p1[a:e]
        lo = max(a, 1)
        if lo < e:
            out[lo - a:] -= p0[lo - 1 : e - 1]
        out[:, 1:] -= p1[a:e, :-1]
        return out

    # -- Regulariser interface ----------------------------------------------------------
    def _values(self, x):
        x = np.asarray(x)
        x = x.astype(_float_dtype(x), copy=False)
        z = self._cube(x)
        d0, d1 = self._scratch_pair(z.shape, z.dtype)
        bands = _parallel.row_bands(z.shape[0], z.size)
        # image-row bands (concurrently inside a parallel context), their per-column partial
        # sums added in band order (the bands depend on the shape only)
        parts = _parallel.run_parts(
            lambda i: self._values_rows(z, *bands[i], d0, d1), len(bands)
        )
        return parts[0] if len(parts) == 1 else sum(parts[1:], parts[0])

    def _values_rows(self, z, a, e, d0, d1) -> np.ndarray:
        """Per-column TV of image rows ``[a, e)`` of ``z`` (Ny, Nx, K) (reading row ``e``
        too), with the same rows of ``d0``, ``d1`` as scratch."""
        forward_differences_into(z, d0, d1, (a, e))
        v, h = d0[a:e], d1[a:e]
        if self.isotropic:
            np.square(v, out=v)
            np.square(h, out=h)
            v += h
            np.sqrt(v, out=v)
        else:
            np.abs(v, out=v)
            np.abs(h, out=h)
            v += h
        return _colsum(v.reshape(-1, z.shape[2]))

    def _prox(self, v, t):
        dt = v.dtype
        v3 = self._cube(v)
        # the prox moves each value by at most 4 t (|p| <= 1, four differences per pixel): a
        # t below round-off of the largest |v| is the identity, and computed as such (the dual's
        # v / t overflowed float32 for t below ~1e-38 and gave NaN everywhere)
        # (|v|'s largest from two reductions, no |v| array: this runs every iteration)
        if (t == 0.0 or t * float(np.finfo(dt).max) < 1.0
                or 8.0 * t <= np.finfo(dt).eps * max(float(v3.max(initial=0.0)),
                                                      -float(v3.min(initial=0.0)))):
            self.last_inner_iterations = 0
            z = np.maximum(v3, 0) if self.nonneg else v3.copy()
            return z.reshape(v.shape)
        b = self._buffers(v3.shape, dt)
        if not (self.warm_start and self._p is not None):
            b["p"].fill(0)
        np.multiply(v3, dt.type(1.0 / t), out=b["vt"])
        out = np.empty_like(v3)
        bands = b["bands"]
        n_threads, pool = self._n_threads(len(bands))
        # per-band partial squared norms ||p_k - p_{k-1}||^2 and ||p_k||^2 (added in band
        # order, so the stop test does not depend on the number of threads)
        # (two sets, by iteration parity: a band may start the next iteration while another
        # still reads the sums of this one)
        norms = np.zeros((2, len(bands), 2))
        if n_threads == 1:
            p_final, it = self._fgp(b, v3, t, out, range(len(bands)), norms, None)
        else:
            p_final, it = self._fgp_threaded(b, v3, t, out, norms, n_threads, pool)
        self.last_inner_iterations = it
        if p_final is b["q"]:
            b["p"], b["q"] = b["q"], b["p"]
        self._p = p_final if self.warm_start else None
        return out.reshape(v.shape)

    def _fgp_threaded(self, b, v3, t, out, norms, n_threads, pool):
        """Run the FGP loop with one thread per group of row bands (the caller's thread
        takes the first), in ``pool`` or in threads started for this call."""
        groups = [tuple(g) for g in np.array_split(np.arange(len(b["bands"])), n_threads)]
        barrier = threading.Barrier(len(groups))
        results: list[Any] = [None] * len(groups)

        def run(i):
            try:
                results[i] = self._fgp(b, v3, t, out, groups[i], norms, barrier)
            except BaseException as exc:  # release the other threads, re-raised below
                results[i] = exc
                barrier.abort()

        if pool is not None:
            helpers = [pool.submit(carried(run), i) for i in range(1, len(groups))]
            run(0)
            for f in helpers:
                f.result()
        else:
            threads = [threading.Thread(target=run, args=(i,), daemon=True)
                       for i in range(1, len(groups))]
            for th in threads:
                th.start()
            run(0)
            for th in threads:
                th.join()
        for r in results:  # the original error rather than the other band's BrokenBarrierError
            if isinstance(r, BaseException) and not isinstance(r, threading.BrokenBarrierError):
                raise r
        for r in results:
            if isinstance(r, BaseException):
                raise r
        return results[0]

    def _fgp(self, b, v3, t, out, ids, norms, barrier):
        """FGP iterations on the row bands ``ids``; writes the prox of those bands into ``out``.

        Every band's thread runs this loop with identical control flow: the decisions depend
        only on the iteration count and on ``norms``, which all bands fill before meeting at
        ``barrier``. Returns ``(p, iterations)``.
        """
        dt = b["vt"].dtype
        vt, bands = b["vt"], b["bands"]
        P, Q, Ra, Rb = b["p"], b["q"], b["ra"], b["rb"]
        rr = P  # extrapolated dual r_1 = p_0
        tol2 = self.inner_tol**2
        s = 1.0
        it = 0
        for it in range(1, self.max_inner + 1):  # noqa: B007 - returned
            last = it == self.max_inner
            s_new = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * s * s))
            c = (s - 1.0) / s_new
            for i in ids:
                a, e = bands[i]
                self._fgp_band(
                    vt, rr, P, Q, Ra, a, e, b["z"][i], b["w"][i], c, last, norms[it % 2, i]
                )
            if barrier is not None:
                barrier.wait()
            P, Q = Q, P
            if last:
                break
            if c > 0.0:  # r_{k+1} was written into Ra; the next one goes to the other buffer
                rr, Ra, Rb = Ra, Rb, Ra
            else:
                rr = P
            s = s_new
            dn2, pn2 = norms[it % 2].sum(axis=0)
            if dn2 <= tol2 * max(pn2, 1e-60):
                break
        # z = P_C(v - t G^T p) on these bands (the other bands' p is complete: barrier above)
        for i in ids:
            a, e = bands[i]
            ob = self._neg_div_rows(P, a, e, out[a:e])
            ob *= dt.type(t)
            ob += v3[a:e]
            if self.nonneg:
                np.maximum(ob, 0, out=ob)
        return P, it

    def _fgp_band(self, vt, rr, P, Q, R, a, e, z, w, c, last, norms):
        """One FGP iteration on image rows ``[a, e)``: ``Q = P(rr + G z / 8)`` with
        ``z = P_C(vt - G^T rr) `` (computed on one halo row more), then, unless ``last``,
        ``R = Q + c (Q - P)`` and the partial norms ``(||Q - P||^2, ||Q||^2)``."""
        dt = vt.dtype
        ny = vt.shape[0]
        e1 = min(e + 1, ny)
        self._neg_div_rows(rr, a, e1, z, vt)
        if self.nonneg:
            np.maximum(z, 0, out=z)
        z *= dt.type(0.125)
        n = e - a
        ee = min(e, ny - 1) - a  # rows of this band with a vertical difference
        q0 = Q[0, a : a + ee]
        np.subtract(z[1 : ee + 1], z[:ee], out=q0)
        q0 += rr[0, a : a + ee]
        q1 = Q[1, a:e, :-1]
        np.subtract(z[:n, 1:], z[:n, :-1], out=q1)
        q1 += rr[1, a:e, :-1]
        qb = Q[:, a:e]
        one = dt.type(1.0)
        if self.isotropic:
            np.einsum("i...,i...->...", qb, qb, out=w)
            np.maximum(w, one, out=w)
            np.sqrt(w, out=w)
            np.divide(qb, w, out=qb)
        else:
            np.clip(qb, -one, one, out=qb)
        if last:
            return
        rb = R[:, a:e]
        np.subtract(qb, P[:, a:e], out=rb)
        norms[0] = _sqnorm(rb[0]) + _sqnorm(rb[1])
        norms[1] = _sqnorm(qb[0]) + _sqnorm(qb[1])
        if c > 0.0:
            rb *= dt.type(c)
            rb += qb


# -- factories of the registry entries (spslidar.solvers.REGULARISERS) -------------------------
def make_tv(shape: tuple[int, int], nonneg: bool = False, max_inner: int = 3) -> TV:
    """The isotropic TV of eq. (18) on ``shape`` images (``--regulariser tv``).

    ``nonneg`` is False here, as the bare regulariser; the pipeline's is non-negative
    (:func:`spslidar.pipeline.build_regulariser`, range slices are photon counts). A chain
    built by hand with ``make_tv(shape)`` differed from ``reconstruct`` by up to 0.78 m (an
    audit of 2026-11-29): pass ``nonneg=True``, or take ``build_regulariser(cfg, shape)``."""
    return TV(shape, nonneg=nonneg, max_inner=max_inner)


def make_tv_aniso(shape: tuple[int, int], nonneg: bool = False, max_inner: int = 3) -> TV:
    """The anisotropic TV ``sum_q |(D_y x)_q| + |(D_x x)_q|`` on ``shape`` images
    (``--regulariser tv-aniso``): a choice of the regulariser kappa of eq. (18).

    Its cost of an edge grows with its length in the l1 metric, so axis-aligned edges and
    corners (walls, boxes, poles, table legs) cost less than under the isotropic TV, and a
    diagonal edge sqrt(2) times more. The same FGP prox as :func:`make_tv`, projecting the
    dual onto unit boxes instead of unit disks.
    """
    return TV(shape, isotropic=False, nonneg=nonneg, max_inner=max_inner)


def make_l1(shape: tuple[int, int], nonneg: bool = False, max_inner: int = 3) -> L1:
    """The pixel l1 norm (``--regulariser l1``)."""
    return L1(None, nonneg=nonneg)


def make_wavelet_l1(shape: tuple[int, int], nonneg: bool = False, max_inner: int = 3) -> L1:
    """The l1 norm of the Haar wavelet coefficients (``--regulariser wavelet``). The prox of a
    wavelet l1 norm under a non-negativity constraint has no closed form: ``nonneg`` is
    ignored (it applies to the TV and pixel-l1 regularisers only)."""
    from ..operators import Wavelet2D
    from ..operators.image import no_level_message, periodized_levels

    # (its own warning, not Wavelet2D's: it is the pixel l1 here, not an identity)
    ny, nx = pair_shape(shape, "make_wavelet_l1's shape", 1)
    w = Wavelet2D(shape, "haar", level=None if periodized_levels(ny, nx) else 0)
    if w.level == 0:  # it was silently the pixel l1
        warnings.warn(no_level_message(shape, "the wavelet regulariser",
                                       "the pixel l1 (--regulariser l1)"), stacklevel=2)
    return L1(w)
