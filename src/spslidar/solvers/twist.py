"""TwIST, two-step iterative shrinkage/thresholding (Bioucas-Dias & Figueiredo 2007).

The solver used by Shen et al. for eq. (18); batched over column blocks.
"""

from __future__ import annotations

import numpy as np

from .base import SolveInfo, Solver, StopRule, _axpy, registered_defaults
from .fista import _col_objective, _lipschitz, _start, _work_dtype
from .regularisers import L1

__all__ = ["TwIST", "twist", "twist_parameters"]


def twist_parameters(lambda_1: float = 1e-4, lambda_n: float = 1.0) -> tuple[float, float]:
    """TwIST weights ``(alpha, beta)`` for the spectrum ``[lambda_1, lambda_n]`` of ``A^T A / L``.

    Notes
    -----
    As in the authors' ``TwIST.m``: with ``kappa = lambda_1 / lambda_n``,
    ``rho = (1 - kappa) / (1 + kappa)``, ``alpha = 2 / (1 + sqrt(1 - rho^2))`` and
    ``beta = 2 alpha / (lambda_1 + lambda_n)``. This equals the optimal choice of the
    convergence analysis of Bioucas-Dias & Figueiredo (2007), ``alpha = rho_bar^2 + 1`` with
    ``rho_bar = (1 - sqrt(kappa)) / (1 + sqrt(kappa))``. ``lambda_1 = lambda_n`` gives
    ``alpha = beta = 1``, i.e. plain IST.
    """
    if not 0 < lambda_1 <= lambda_n:
        raise ValueError("need 0 < lambda_1 <= lambda_n")
    kappa = lambda_1 / lambda_n
    rho = (1.0 - kappa) / (1.0 + kappa)
    alpha = 2.0 / (1.0 + np.sqrt(1.0 - rho * rho))
    beta = 2.0 * alpha / (lambda_1 + lambda_n)
    return float(alpha), float(beta)


#: share of fallback columns above which the IST objective is computed for the whole block
_WHOLE_BLOCK_SHARE = 0.25
#: a non-negative problem's two-step point is projected where an entry is below -NEG_TOL
#: times its column's largest magnitude (smaller negatives are clipped on return: projecting
#: them too made the pipeline's TwIST solve 1.6 times as long for the same objective)
NEG_TOL = 1e-3


class TwIST(Solver):
    """Two-step IST (TwIST) with the regulariser's prox as denoiser, on a block of columns.

    Parameters
    ----------
    stop : StopRule, optional
    L : float, optional
        ``||A||_2^2`` (default ``power_norm(A) ** 2``, computed at every solve). ``A`` is used
        as ``A / sqrt(L)``, whose largest eigenvalue of ``A^T A`` is then ``lambda_N = 1``.
    lambda_1 : float
        Assumed smallest eigenvalue of ``A^T A / L`` (``1e-4``, the default of the authors'
        ``TwIST.m``; use a larger value for well-conditioned ``A``, e.g. ``1`` for the
        identity).
    alpha, beta : float, optional
        Override the two-step weights derived from ``lambda_1`` (:func:`twist_parameters`).
    monotone : bool
        Monotone variant (default True, as in ``TwIST.m``): a column whose objective would
        increase after a two-step update takes the plain IST step instead.
    sparse : bool or None
        Zero the two previous iterates where the current IST estimate is zero (``TwIST.m``'s
        ``sparse`` trick for sparsity priors). ``None`` (default): on for :class:`L1` in the
        pixel basis, off otherwise (TV images, or wavelet-domain sparsity where pixel zeros
        mean nothing).

    Notes
    -----
    Minimises eq. (18) of Shen et al. (the paper reproduced by spslidar, where TwIST is the
    reconstruction method),

        F(x) = 1/2 ||A x - y||_2^2 + lam R(x),

    summed over the K columns of ``x``; the K problems are independent and every decision
    (monotone fallback) is taken per column. Following J. M. Bioucas-Dias and
    M. A. T. Figueiredo, "A new TwIST: two-step iterative shrinkage/thresholding algorithms for
    image restoration", IEEE TIP 16(12), 2007, with the denoiser
    ``Psi(u) = prox_{lam/L R}(u)``::

        x_1     = Psi(x_0 + A^T (y - A x_0) / L)                             (IST step)
        x_{k+1} = (1 - alpha) x_{k-1} + (alpha - beta) x_k
                  + beta Psi(x_k + A^T (y - A x_k) / L)                      (TwIST step)

    Monotone variant (as in the authors' code): if ``F(x_{k+1}) > F(x_k)`` for a column, that
    column takes the IST step ``Psi(x_k + A^T (y - A x_k) / L)`` instead. Departure from
    ``TwIST.m``: where even the IST step increases ``F`` (only possible through rounding or an
    inexact prox, since ``L >= ||A||^2``) the column keeps ``x_k`` for this iteration instead of
    doubling the step estimate. The recorded objective is ``F(x_k)`` at the current iterate
    and is non-increasing in the monotone variant; for the ``StopRule.rtol`` test a kept
    column counts with the step it tried, so a rejection is not mistaken for convergence.

    One iteration costs one product with ``A^T`` and one with ``A``: ``A x_ist`` is computed
    and ``A x_{k+1}`` formed from it, ``A x_k`` and ``A x_{k-1}`` by linearity, so the
    columns that fall back to IST need no further product (with ``sparse`` the two-step
    point is masked, ``A x_{k+1}`` is computed and the fallback columns cost one more
    product). Works in the dtype of ``A``. ``info.extra`` holds ``L``,
    ``alpha``, ``beta``, ``ist_fallbacks`` and ``rejected`` (column counts).
    """

    name = "twist"
    default_iterations, default_lam_scale, default_regulariser = registered_defaults("twist")

    def _setup(self, A, y, reg, lam, x0):
        opts = dict(self.options)
        L = _lipschitz(A, opts.pop("L", None))
        lambda_1 = float(opts.pop("lambda_1", 1e-4))
        alpha, beta = twist_parameters(lambda_1, 1.0)
        a_opt, b_opt = opts.pop("alpha", None), opts.pop("beta", None)
        alpha = alpha if a_opt is None else float(a_opt)
        beta = beta if b_opt is None else float(b_opt)
        self._monotone = bool(opts.pop("monotone", True))
        self._nonneg = bool(getattr(reg, "nonneg", False))
        sparse = opts.pop("sparse", None)
        if opts:
            raise TypeError(f"unknown TwIST options: {', '.join(sorted(opts))}")
        if sparse is None:
            sparse = isinstance(reg, L1) and reg.basis is None
        self._sparse = bool(sparse)
        dt = _work_dtype(A)
        y, x, ax = _start(A, y, x0, dt)
        self.y, self._dt, self._L, self._alpha, self._beta = y, dt, L, alpha, beta
        self._inv_l = dt.type(1.0 / L)
        self._thr = lam / L
        self._c = tuple(dt.type(c) for c in (1.0 - alpha, alpha - beta, beta))
        self._f = _col_objective(ax - y, x, reg, lam)
        self._x, self._ax = x, ax
        self._xm, self._axm = x, ax  # the previous iterate and its image
        self._n_fallback = self._n_reject = 0

    def _step(self) -> str:
        A, y, reg, lam, dt, it = self.A, self.y, self.reg, self.lam, self._dt, self.it
        x, ax, f, xm, axm = self._x, self._ax, self._f, self._xm, self._axm
        c_prev, c_cur, c_ist = self._c
        g = np.asarray(A.rmatvec(ax - y), dtype=dt)
        g *= -self._inv_l
        g += x
        x_ist = np.asarray(reg.prox(g, self._thr), dtype=dt)
        del g
        a_ist = None  # A x_ist, when computed
        if it == 1:
            x_new = x_ist
            ax_new = a_ist = np.asarray(A.matvec(x_ist), dtype=dt)
        elif self._sparse:
            mask = x_ist != 0
            x_new = c_prev * (xm * mask) + c_cur * (x * mask) + c_ist * x_ist
            ax_new = np.asarray(A.matvec(x_new), dtype=dt)
        else:
            # (1 - alpha) x_{k-1} + (alpha - beta) x_k + beta x_ist (one scaling and two
            # BLAS axpy updates), and its image by linearity from A x_ist, A x_k, A x_{k-1}:
            # one product with A per iteration, also when columns fall back to IST below
            a_ist = np.asarray(A.matvec(x_ist), dtype=dt)
            x_new = np.multiply(x_ist, c_ist)
            _axpy(x, x_new, c_cur)
            _axpy(xm, x_new, c_prev)
            ax_new = np.multiply(a_ist, c_ist)
            _axpy(ax, ax_new, c_cur)
            _axpy(axm, ax_new, c_prev)
        f_new = _col_objective(ax_new - y, x_new, reg, lam)
        x_tried = None
        if it > 1 and self._nonneg:
            # the two-step combination weighs x_{k-1} by 1 - alpha < 0, so it can leave the
            # non-negative set, and the objective without the constraint's indicator kept
            # such points (non-negative least squares ended 27 % above scipy's nnls with
            # entries of -0.025, an outside audit): an infeasible column is projected back
            # and its image recomputed (below NEG_TOL of the column's largest entry,
            # round-off, is taken as it is and clipped on return; the IST step instead slowed
            # the pipeline's solve, the camera 0.0049 -> 0.0084 m at 60 iterations)
            top = np.maximum(np.abs(x_new).max(axis=0), np.finfo(dt).tiny)
            out = np.flatnonzero(x_new.min(axis=0) < -NEG_TOL * top)
            if out.size:
                x_new[:, out] = np.maximum(x_new[:, out], 0)
                ax_new[:, out] = np.asarray(A.matvec(x_new[:, out]), dtype=dt)
                f_new[out] = _col_objective(ax_new[:, out] - y[:, out], x_new[:, out], reg, lam)
        if self._monotone:
            bad = f_new > f
            if it > 1 and bad.any():
                # two-step update failed on these columns: take the IST step there
                self._n_fallback += int(bad.sum())
                if a_ist is not None and bad.mean() > _WHOLE_BLOCK_SHARE:
                    # most columns: masked copies and the objective of the whole IST
                    # block (a gather of strided columns costs more than the extra ones)
                    np.copyto(x_new, x_ist, where=bad[None, :])
                    np.copyto(ax_new, a_ist, where=bad[None, :])
                    f_new = np.where(bad, _col_objective(a_ist - y, x_ist, reg, lam), f_new)
                else:
                    cols = np.flatnonzero(bad)
                    x_new[:, cols] = x_ist[:, cols]
                    if a_ist is not None:
                        ax_new[:, cols] = a_ist[:, cols]
                    else:
                        ax_new[:, cols] = np.asarray(A.matvec(x_ist[:, cols]), dtype=dt)
                    f_new[cols] = _col_objective(
                        ax_new[:, cols] - y[:, cols], x_ist[:, cols], reg, lam
                    )
                bad = f_new > f
            if bad.any():
                # even IST went up (rounding / inexact prox): keep the current iterate;
                # the stop test still measures the step that was tried
                self._n_reject += int(bad.sum())
                cols = np.flatnonzero(bad)
                x_tried = x_new.copy()
                x_new[:, cols] = x[:, cols]
                ax_new[:, cols] = ax[:, cols]
                f_new[cols] = f[cols]
        x_old = x
        # (a rejected column has x == xm: its next two-step update restarts from itself)
        self._xm, self._axm = x, ax
        self._x, self._ax, self._f = x_new, ax_new, f_new
        return self.monitor.check(
            it, x_new if x_tried is None else x_tried, x_old, float(np.sum(f_new))
        )

    def _finish(self) -> np.ndarray:
        self.monitor.info.extra.update(
            L=self._L, alpha=self._alpha, beta=self._beta, ist_fallbacks=self._n_fallback,
            rejected=self._n_reject,
        )
        # (feasible to the last entry: the round-off negatives below NEG_TOL go)
        return np.maximum(self._x, 0) if self._nonneg else self._x


def twist(
    A,
    y: np.ndarray,
    reg,
    lam: float,
    x0: np.ndarray | None = None,
    stop: StopRule | None = None,
    **options,
) -> tuple[np.ndarray, SolveInfo]:
    """Solve eq. (18) with :class:`TwIST`; ``options``: ``L``, ``lambda_1``, ``alpha``,
    ``beta``, ``monotone``, ``sparse``.

    Returns
    -------
    x : ndarray
        Shaped like ``A.H @ y``.
    info : SolveInfo
    """
    return TwIST(stop=stop, **options).solve(A, y, reg, lam, x0=x0)
