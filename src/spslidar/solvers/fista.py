"""FISTA (Beck & Teboulle 2009) for equation (18), batched over column blocks."""

from __future__ import annotations

import numpy as np

from ..operators.base import power_norm
from .base import SolveInfo, Solver, StopRule, col_dot, registered_defaults

__all__ = ["FISTA", "fista"]


def _work_dtype(A) -> np.dtype:
    dt = np.dtype(getattr(A, "dtype", np.float64))
    return dt if dt in (np.float32, np.float64) else np.dtype(np.float64)


def _col_objective(r: np.ndarray, x: np.ndarray, reg, lam: float) -> np.ndarray:
    """Per-column ``1/2 ||r_k||^2 + lam R(x_k)`` accumulated in float64."""
    data = 0.5 * col_dot(r, r)
    if lam == 0.0:
        return data
    return data + lam * np.asarray(reg.values(x), dtype=np.float64)


def _start(A, y, x0, dtype):
    """Cast the data, build the starting block and its image ``A x0``."""
    y = np.asarray(y, dtype=dtype)
    n, k = A.shape[1], y.shape[1]
    if x0 is None:
        x = np.zeros((n, k), dtype=dtype)
        ax = np.zeros_like(y)
    else:
        x = np.array(np.broadcast_to(x0, (n, k)), dtype=dtype)
        ax = np.asarray(A.matvec(x), dtype=dtype)
    return y, x, ax


def _lipschitz(A, L: float | None) -> float:
    """``L`` as given, else ``power_norm(A) ** 2``; 1 for a zero operator, whose data term has
    no gradient, so that any step is exact and the iteration is the prox's own fixed-point
    iteration (zero from zero), as TVAL3 and GPSR solve it (FISTA and TwIST refused it
    where those returned zeros: an audit)."""
    if L is None:
        L = power_norm(A) ** 2
        if L == 0.0:
            return 1.0
    L = float(L)
    if not np.isfinite(L) or L <= 0:
        raise ValueError(f"Lipschitz constant must be positive and finite, got {L}")
    return L


class FISTA(Solver):
    """Fast iterative shrinkage-thresholding (FISTA / MFISTA) on a block of columns.

    Parameters
    ----------
    stop : StopRule, optional
    L : float, optional
        Lipschitz constant of the data-term gradient, ``||A||_2^2``; default
        ``power_norm(A) ** 2`` computed at every solve (nothing is cached between solves;
        1 for a zero operator, whose data term has no gradient). The step is ``1 / L``.
    restart : bool
        O'Donoghue & Candes (2015) gradient restart: a column's momentum is reset when
        ``<y_k - z_k, z_k - x_{k-1}> > 0``. Default False.
    monotone : bool
        MFISTA (Beck & Teboulle 2009b): a column keeps its previous iterate when the prox step
        would increase its objective, and the extrapolation uses both points. Default False.

    Notes
    -----
    Minimises the objective of eq. (18) of Shen et al. (the paper reproduced by spslidar),

        F(x) = 1/2 ||A x - y||_2^2 + lam R(x),

    summed over the K columns of ``x`` (K independent problems solved in one pass; momentum,
    restart and monotonicity decisions are taken per column). The batched solve follows the
    iterates of K separate ones but for the regulariser's prox where it is itself iterative:
    the TV prox's inner stop test (``inner_tol``) reads the whole block, so a column may get one
    inner iteration more or fewer than alone (measured on a random 40 x 64 problem, 200
    iterations, a column 100 times weaker than its neighbour: 1e-4 to 2e-3 of its peak apart
    from its own solve; the pipeline's 3 inner iterations ran in full in all 60 prox calls of
    the default run, where the test never fired). One iteration (Beck & Teboulle, SIAM J.
    Imaging Sci. 2(1), 2009) is

        z_k     = prox_{lam/L R}(y_k - A^T (A y_k - y) / L)
        x_k     = z_k                (FISTA)  or the better of z_k, x_{k-1} (MFISTA)
        t_{k+1} = (1 + sqrt(1 + 4 t_k^2)) / 2
        y_{k+1} = x_k + t_k/t_{k+1} (z_k - x_k) + (t_k - 1)/t_{k+1} (x_k - x_{k-1})

    It costs one product with ``A`` and one with ``A^T``: ``A z_k`` is computed once and
    ``A y_{k+1}`` is formed from ``A z_k``, ``A x_k`` and ``A x_{k-1}`` by linearity, so the
    objective is available every iteration without extra products.

    The objective recorded in ``info.objective`` is ``F(x_k)`` at the current iterate (never at
    the extrapolated point ``y_k``). Plain FISTA is *not* monotone: its history can go up
    (ripples), restart reduces but does not remove this. ``monotone=True`` gives a
    non-increasing history by construction (with an inexact prox such as TV's, steps that the
    prox error makes worse are simply rejected). With a very inexact prox the plain iteration
    can climb far from its best: the TV of :func:`~spslidar.solvers.regularisers.make_tv`
    (3 inner iterations, the pipeline's) on a random 64 x 256 problem at a weight of half
    ``max|A^T y|`` reached 33.9 at iteration 15 and 111 at 1000, against an optimum
    of 28.37 that ``monotone=True`` (28.37) and :class:`TV`'s default of 20 inner iterations
    (28.41) reach. The pipeline's solves climb a little (an audit of 2026-11-30: the 16x16
    camera at m_n = 1 reads 4.0149 / 4.0285 / 4.0314 at 60 / 300 / 2000 iterations, where
    ``monotone=True`` reads 4.0058 / 4.0048 / 4.0047 and ``restart=True`` 4.0128 / 4.0085 /
    4.0070; the 64x64 motorcycle at m_n = 10 and 300 iterations 41.821 against 41.669 and
    41.820), by too little to move the depth beyond the noise (camera 64x64 at 600 iterations:
    0.0050 m either way); ``--monotone on`` and ``--restart on`` set them. For MFISTA the
    iterate-change test of ``StopRule.rtol`` compares ``z_k`` with ``x_{k-1}`` (``x_k`` may
    legitimately stay put for one iteration).

    Works in the dtype of ``A`` (float32 stays float32), in place where it can: the step
    ``x_k - x_{k-1}`` of the stop test is formed once and turned into the extrapolated point
    in the buffer of the previous one. The objective is evaluated at every iteration (its data
    term comes free from ``A z_k``; the regulariser's value costs a few passes over the block,
    about 3 % of an iteration with the TV of the default run), so ``info.objective`` has one
    entry per iteration and the ``obj_rtol`` and ``target`` rules can act at any iteration.
    ``info.extra`` holds ``L``, ``restarts`` (column restarts), ``rejected`` (MFISTA column
    rejections) and ``threads`` (see :class:`~spslidar.solvers.base.Solver`).
    """

    name = "fista"
    default_iterations, default_lam_scale, default_regulariser = registered_defaults("fista")

    def _setup(self, A, y, reg, lam, x0):
        opts = dict(self.options)
        L = _lipschitz(A, opts.pop("L", None))
        self._restart = bool(opts.pop("restart", False))
        self._monotone = bool(opts.pop("monotone", False))
        if opts:
            raise TypeError(f"unknown FISTA options: {', '.join(sorted(opts))}")
        dt = _work_dtype(A)
        y, x, ax = _start(A, y, x0, dt)
        self.y, self._dt, self._L = y, dt, L
        self._inv_l = dt.type(1.0 / L)
        self._thr = lam / L
        self._f = _col_objective(ax - y, x, reg, lam)
        self._t = np.ones(y.shape[1])
        self._x, self._ax = x, ax
        self._yk, self._ayk = x, ax  # the extrapolated point and its image
        self._spare = None  # a free (n, K) array for the next extrapolated point
        self._n_restart = self._n_reject = 0

    def _step(self) -> str:
        A, y, reg, lam, dt = self.A, self.y, self.reg, self.lam, self._dt
        x, ax, f, t = self._x, self._ax, self._f, self._t
        yk, ayk = self._yk, self._ayk
        # gradient step from the extrapolated point: g = y_k - A^T (A y_k - y) / L
        g = np.asarray(A.rmatvec(ayk - y), dtype=dt)
        g *= -self._inv_l
        g += yk
        z = np.asarray(reg.prox(g, self._thr), dtype=dt)
        del g
        az = np.asarray(A.matvec(z), dtype=dt)
        fz = _col_objective(az - y, z, reg, lam)
        if self._monotone:
            keep = fz > f
            if keep.any():
                self._n_reject += int(keep.sum())
                x_new = np.where(keep, x, z)
                ax_new = np.where(keep, ax, az)
                f_new = np.where(keep, f, fz)
            else:
                x_new, ax_new, f_new = z, az, fz
        else:
            x_new, ax_new, f_new = z, az, fz
        t_new = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * t * t))
        if self._restart:
            # gradient-mapping test of O'Donoghue & Candes, per column
            cond = col_dot(yk - z, z - x) > 0
            if cond.any():
                self._n_restart += int(cond.sum())
                t = np.where(cond, 1.0, t)
                t_new = np.where(cond, 1.0, t_new)
        c_m = (t - 1.0) / t_new
        c_z = t / t_new
        x_old, ax_old = x, ax
        x, ax, f, t = x_new, ax_new, f_new, t_new
        self._x, self._ax, self._f, self._t = x, ax, f, t
        mon = self.monitor
        if self._monotone:
            reason = mon.check(self.it, z, x_old, float(np.sum(f)))
            if reason:
                return reason
            # y_{k+1} = x_k + t_k/t_{k+1} (z_k - x_k) + (t_k - 1)/t_{k+1} (x_k - x_{k-1})
            cz, cm = c_z.astype(dt), c_m.astype(dt)
            self._yk = x + cz * (z - x) + cm * (x - x_old)
            self._ayk = ax + cz * (az - ax) + cm * (ax - ax_old)
            return ""
        # plain FISTA: d = x_k - x_{k-1} is both the step of the stop test and, scaled,
        # the extrapolation y_{k+1} = x_k + c (x_k - x_{k-1}), formed in place in a
        # spare buffer (the previous y_k, whose last use was the gradient step)
        d = self._spare if self._spare is not None else np.empty_like(x)
        np.subtract(x, x_old, out=d)
        reason = mon.check(self.it, x, x_old, float(np.sum(f)), step=d)
        if reason:
            return reason
        if np.all(c_m == c_m[0]):
            d *= dt.type(c_m[0])
        else:
            d *= c_m.astype(dt)
        d += x
        self._spare = yk  # its last use was this iteration's gradient step
        self._yk = d
        self._ayk = ax + c_m.astype(dt) * (ax - ax_old)
        return ""

    def _finish(self) -> np.ndarray:
        self.monitor.info.extra.update(L=self._L, restarts=self._n_restart,
                                       rejected=self._n_reject)
        return self._x


def fista(
    A,
    y: np.ndarray,
    reg,
    lam: float,
    x0: np.ndarray | None = None,
    stop: StopRule | None = None,
    **options,
) -> tuple[np.ndarray, SolveInfo]:
    """Solve eq. (18) with :class:`FISTA`; ``options`` are ``L``, ``restart``, ``monotone``.

    Returns
    -------
    x : ndarray
        Shaped like ``A.H @ y``.
    info : SolveInfo
    """
    return FISTA(stop=stop, **options).solve(A, y, reg, lam, x0=x0)
