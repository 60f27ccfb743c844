"""TVAL3: total-variation reconstruction by an augmented Lagrangian with alternating directions.

A from-the-paper implementation of Li, Yin, Jiang & Zhang (2013) for the TV form of eq. (18) of
Shen et al. (pseudo-random spread-spectrum single-pixel ToF lidar), batched over the K range
slices. Written by hand because no Python TVAL3 exists (the reference implementation is
Chengbo Li's MATLAB package); nothing here is translated from that code.
"""

from __future__ import annotations

import numpy as np

from ..operators.base import LinearOperator, power_norm
from ..operators.image import Gradient2D
from .base import Monitor, SolveInfo, Solver, StopRule, register
from .regularisers import TV

__all__ = ["TVAL3", "tval3"]

_TINY = 1e-30
#: inner iterations between recomputations of the incrementally updated residual A x - y
_REFRESH = 100


def _colsum(a: np.ndarray) -> np.ndarray:
    """Column sums of a 2-D block, accumulated in float64."""
    return np.sum(a, axis=0, dtype=np.float64)


def _coldot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-column inner products ``<a[:, k], b[:, k]>`` in float64."""
    return np.einsum("ik,ik->k", a, b, dtype=np.float64)


def _huber(v: np.ndarray, beta: float, isotropic: bool, q: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-column values and gradient of ``sum_i H_beta(v_i)`` for ``v`` of shape ``(2Q, K)``.

    ``H_beta(v_i) = min_w ||w|| + beta/2 ||v_i - w||^2`` is the Huber function of the pixel
    vector ``v_i = (v[i], v[Q + i])`` (isotropic) or of each entry (anisotropic): equal to
    ``||v_i|| - 1/(2 beta)`` outside the ball of radius ``1/beta`` and ``beta/2 ||v_i||^2``
    inside. Its gradient ``beta (v - shrink(v, 1/beta))`` is returned in the dtype of ``v``.
    """
    dt = v.dtype
    thr = 1.0 / beta
    if isotropic:
        mag = np.sqrt(v[:q] * v[:q] + v[q:] * v[q:])
    else:
        mag = np.abs(v)
    outside = mag > thr
    scale = np.where(outside, 1.0 / np.maximum(mag, dt.type(_TINY)), dt.type(beta)).astype(
        dt, copy=False
    )
    val = np.where(outside, mag - dt.type(0.5 * thr), dt.type(0.5 * beta) * mag * mag)
    if isotropic:
        grad = v * np.concatenate([scale, scale], axis=0)
    else:
        grad = v * scale
    return _colsum(val), grad


def _tv_values(dx: np.ndarray, isotropic: bool, q: int) -> np.ndarray:
    """Per-column TV from the stacked gradient ``dx = [D_y x; D_x x]``."""
    if isotropic:
        return _colsum(np.sqrt(dx[:q] * dx[:q] + dx[q:] * dx[q:]))
    return _colsum(np.abs(dx))


@register
class TVAL3(Solver):
    """TV-regularised least squares by TVAL3 (augmented Lagrangian, alternating directions).

    Solves eq. (18) with ``R = TV``: ``min_x 1/2 ||A x - y||^2 + lam TV(x)`` for every column
    of the block at once, in the equivalent penalty form of TVAL3 (see Notes).

    Parameters
    ----------
    stop : StopRule, optional
        ``max_iter`` counts inner (alternating-direction) iterations, each costing one product
        with ``A`` and one with ``A^H``; the ``rtol`` test compares the iterates at the ends of
        two consecutive outer (multiplier) iterations and is only applied once the
        continuation on ``beta`` and ``mu`` has reached its final values.
    beta : float, optional
        Final splitting penalty ``beta``. Default ``beta_scale * mu * ||A||^2``, which keeps the
        algorithm invariant to a rescaling of ``A``, ``y`` or ``x``.
    beta_scale : float
        See ``beta`` (default 1.0).
    mu0_factor, beta0_factor : float
        Continuation: start from ``mu0_factor * mu`` and ``beta0_factor * beta`` and multiply
        both by ``rate_ctn`` after every outer iteration until they reach ``mu`` and ``beta``
        (defaults 1/16 and 1/16; 1.0 disables the continuation).
    rate_ctn : float
        Continuation rate (default 2).
    tol_inner : float
        An inner loop ends when the relative change of every column,
        ``||x_k - x_{k-1}|| / ||x_k||``, falls below ``tol_inner`` (default 1e-3), or after
        ``max_inner`` iterations (default 50).
    eta : float
        Zhang-Hager nonmonotonicity parameter in [0, 1] (default 0.6; 0 gives a monotone
        Armijo search).
    delta : float
        Armijo sufficient-decrease constant (default 1e-5).
    backtrack : float
        Step reduction factor of the line search (default 0.5), at most ``max_backtrack``
        reductions (default 30).
    nonneg : bool, optional
        Project the x steps onto ``x >= 0``; default ``reg.nonneg``.
    opnorm : float, optional
        ``||A||_2`` if known (otherwise estimated by power iteration).

    Notes
    -----
    TVAL3 (Li, Yin, Jiang & Zhang, "An efficient augmented Lagrangian method with applications
    to total variation minimization", Comput. Optim. Appl. 56:507-530, 2013) solves the TV/L2
    model

        min_x TV(x) + mu/2 ||A x - y||^2,      mu = 1 / lam,

    which has the same minimisers as ``1/2 ||A x - y||^2 + lam TV(x)``; the latter (eq. 18 of
    Shen et al.) is the objective recorded in ``info.objective``. With the splitting
    ``w_i = D_i x`` (``D_i x`` the forward-difference gradient of pixel ``i``, see
    :class:`~spslidar.operators.Gradient2D`) the augmented Lagrangian is

        L(w, x; nu) = sum_i ||w_i|| - nu_i^T (D_i x - w_i) + beta/2 ||D_i x - w_i||^2
                      + mu/2 ||A x - y||^2,

    and each outer iteration (approximately) minimises it over ``(w, x)`` then updates the
    multipliers ``nu <- nu - beta (D x - w)``. The inner minimisation alternates

    * the w-subproblem, solved exactly by isotropic (pixel-wise 2-D) or anisotropic shrinkage
      ``w_i = max(||v_i|| - 1/beta, 0) v_i / ||v_i||`` with ``v_i = D_i x - nu_i / beta``;
    * one steepest-descent step in x with a Barzilai-Borwein step length and the nonmonotone
      line search of Zhang & Hager (SIAM J. Optim. 14, 2004): accept ``x + t d`` when
      ``psi(x + t d) <= C_k + delta t <grad psi, d>``, with the reference value
      ``C_{k+1} = (eta Q_k C_k + psi_{k+1}) / Q_{k+1}``, ``Q_{k+1} = eta Q_k + 1``.

    Here ``psi(x) = min_w L(w, x; nu)`` is the function that the alternating scheme descends;
    eliminating ``w`` makes it a Huber function of ``D x - nu / beta`` plus the data term, so
    it is continuously differentiable, and its gradient is exactly the x-gradient of ``L`` at
    the shrunk ``w``. Because ``A (x + t d) = A x + t A d``, a line search costs no extra
    products with ``A``: one ``A`` and one ``A^H`` product per inner iteration. With the
    non-negativity constraint the direction is the projected one, ``d = P(x - alpha g) - x``
    (spectral projected gradient), so every trial point stays feasible.

    As in TVAL3, ``mu`` and ``beta`` follow a continuation (both multiplied by ``rate_ctn``
    per outer iteration up to their final values). Since the multiplier update makes this a
    method of multipliers, the iterates converge to the TV/L2 minimiser for the final
    ``beta`` (no need for ``beta -> infinity``).

    Batching: the K columns are independent problems. Step lengths, line-search steps and
    nonmonotone reference values are kept per column (vectors of length K), so a column's
    iterates do not depend on the others except through the shared inner/outer stopping
    decisions.

    The reported objective is not monotone (the algorithm descends ``psi``, not eq. 18, and
    the multiplier and continuation updates change ``psi``); within one inner loop the
    Zhang-Hager reference values ``C_k`` (recorded in ``info.extra['merit']``) are
    non-increasing.
    """

    name = "tval3"
    default_lam_scale = 1.0

    _defaults = {
        "beta": None,
        "beta_scale": 1.0,
        "mu0_factor": 1.0 / 16.0,
        "beta0_factor": 1.0 / 16.0,
        "rate_ctn": 2.0,
        "tol_inner": 1e-3,
        "max_inner": 50,
        "eta": 0.6,
        "delta": 1e-5,
        "backtrack": 0.5,
        "max_backtrack": 30,
        "nonneg": None,
        "opnorm": None,
    }

    def __init__(self, stop: StopRule | None = None, **options):
        unknown = set(options) - set(self._defaults)
        if unknown:
            raise TypeError(f"unknown TVAL3 option(s): {', '.join(sorted(unknown))}")
        super().__init__(stop=stop, **options)

    def _solve(self, A: LinearOperator, y, reg, lam, x0, mon: Monitor):
        if not isinstance(reg, TV):
            raise ValueError(
                f"TVAL3 solves the TV problem only: reg must be a TV instance, got {reg!r}"
            )
        if lam <= 0:
            raise ValueError("TVAL3 needs lam > 0 (it solves TV(x) + 1/(2 lam) ||Ax - y||^2)")
        o = {**self._defaults, **self.options}
        n = A.shape[1]
        ny, nx = reg.image_shape
        q = ny * nx
        if q != n:
            raise ValueError(f"TV on {ny}x{nx} images but the operator has {n} columns")
        dt = np.dtype(A.dtype) if np.dtype(A.dtype).kind == "f" else np.dtype(np.float64)
        y = np.asarray(y).astype(dt, copy=False)
        k = y.shape[1]
        iso = bool(reg.isotropic)
        nonneg = bool(reg.nonneg if o["nonneg"] is None else o["nonneg"])
        D = Gradient2D(reg.image_shape, dtype=dt)
        eta, delta, shrink_t = float(o["eta"]), float(o["delta"]), float(o["backtrack"])
        rate = float(o["rate_ctn"])
        slack = 10.0 * float(np.finfo(dt).eps)  # rounding allowance in the Armijo test
        if rate < 1.0:
            raise ValueError("rate_ctn must be >= 1")

        mu_f = 1.0 / lam
        if o["beta"] is not None:
            beta_f = float(o["beta"])
        else:
            norm_a = float(o["opnorm"]) if o["opnorm"] is not None else power_norm(A)
            beta_f = float(o["beta_scale"]) * mu_f * max(norm_a, _TINY) ** 2
        mu = min(mu_f, mu_f * float(o["mu0_factor"]))
        beta = min(beta_f, beta_f * float(o["beta0_factor"]))

        # -- state ---------------------------------------------------------------------
        if x0 is None:
            x = np.zeros((n, k), dtype=dt)
        else:
            x = np.array(np.broadcast_to(x0, (n, k)), dtype=dt)
            if nonneg:
                np.maximum(x, 0, out=x)
        nu = np.zeros((2 * q, k), dtype=dt)

        def refresh(x):
            r = A.matvec(x).astype(dt, copy=False) - y
            return r, A.rmatvec(r).astype(dt, copy=False)

        def merit(dx, r, mu, beta):
            """psi per column (without the constant -||nu||^2 / (2 beta)) and grad H."""
            hv, hg = _huber(dx - nu * dt.type(1.0 / beta), beta, iso, q)
            return hv + 0.5 * mu * _coldot(r, r), hg

        r, ga = refresh(x)
        dx = D.matvec(x)
        psi, hg = merit(dx, r, mu, beta)
        g = D.rmatvec(hg) + dt.type(mu) * ga
        if nonneg:  # projected gradient direction for the first (Cauchy) step
            g0 = np.where((x > 0) | (g < 0), g, 0).astype(dt, copy=False)
        else:
            g0 = g
        ag0, dg0 = A.matvec(g0), D.matvec(g0)
        curv = mu * _coldot(ag0, ag0) + beta * _coldot(dg0, dg0)
        gg = _coldot(g0, g0)
        alpha = np.where(curv > 0, gg / np.maximum(curv, _TINY), 1.0 / max(beta * 8.0, _TINY))
        c_ref, q_ref = psi.copy(), np.ones(k)

        it = 0
        outer = 0
        x_outer = x.copy()
        merit_hist: list[float] = []
        inner_counts: list[int] = []
        n_backtracks = 0
        last_refresh = 0
        max_inner = int(o["max_inner"])
        tol_inner = float(o["tol_inner"])
        while True:
            outer += 1
            final = mu >= mu_f and beta >= beta_f
            for inner in range(1, max_inner + 1):
                it += 1
                # direction
                a_dt = alpha.astype(dt)
                if nonneg:
                    d = np.maximum(x - a_dt * g, 0) - x
                else:
                    d = -a_dt * g
                ad = A.matvec(d).astype(dt, copy=False)
                dd = D.matvec(d)
                gd = _coldot(g, d)
                t = np.ones(k)
                for _ in range(int(o["max_backtrack"]) + 1):
                    t_dt = t.astype(dt)
                    dx_t = dx + t_dt * dd
                    r_t = r + t_dt * ad
                    psi_t, hg_t = merit(dx_t, r_t, mu, beta)
                    ok = psi_t <= c_ref + delta * t * gd + slack * np.abs(c_ref)
                    if ok.all():
                        break
                    t = np.where(ok, t, t * shrink_t)
                    n_backtracks += 1
                s = t.astype(dt) * d
                x_new = x + s
                r = r_t
                dx = dx_t
                psi = psi_t
                ga = A.rmatvec(r).astype(dt, copy=False)
                g_new = D.rmatvec(hg_t) + dt.type(mu) * ga
                # Barzilai-Borwein step (BB1), per column
                ss = _coldot(s, s)
                sy = _coldot(s, g_new - g)
                alpha = np.where((sy > 0) & (ss > 0), ss / np.maximum(sy, _TINY), alpha)
                # Zhang-Hager reference value
                q_new = eta * q_ref + 1.0
                c_ref = (eta * q_ref * c_ref + psi) / q_new
                q_ref = q_new
                merit_hist.append(float(np.sum(c_ref)))
                x, g = x_new, g_new
                # inner stopping (per-column relative change, all columns)
                xn = np.sqrt(_coldot(x, x))
                rel = np.sqrt(ss) / np.maximum(xn, _TINY)
                inner_done = bool(np.all(rel <= tol_inner)) or inner == max_inner
                obj = 0.5 * float(np.sum(_coldot(r, r))) + lam * float(
                    np.sum(_tv_values(dx, iso, q))
                )
                ref = x_outer if (inner_done and final) else None
                reason = mon.check(it, x, ref, obj)
                if reason or inner_done:
                    inner_counts.append(inner)
                if reason:
                    mon.info.extra.update(
                        {
                            "outer_iterations": outer,
                            "inner_iterations": inner_counts,
                            "mu": mu,
                            "beta": beta,
                            "nonneg": nonneg,
                            "backtracks": n_backtracks,
                            "merit": merit_hist,
                        }
                    )
                    return x, reason
                if inner_done:
                    break
            x_outer = x.copy()
            # multiplier update: nu <- nu - beta (D x - w) = -grad H(D x - nu / beta), where
            # hg_t is grad H at the current x (computed in its line search)
            nu = -hg_t
            # continuation
            old = (mu, beta)
            mu = min(mu * rate, mu_f)
            beta = min(beta * rate, beta_f)
            if (mu, beta) != old:
                alpha = alpha * (old[1] / beta)
            if it - last_refresh >= _REFRESH:
                # recompute the residual, updated incrementally so far (float32 drift)
                r, ga = refresh(x)
                dx = D.matvec(x)
                last_refresh = it
            # gradient and merit for the new nu, mu, beta (no product with A needed)
            psi, hg = merit(dx, r, mu, beta)
            g = D.rmatvec(hg) + dt.type(mu) * ga
            c_ref, q_ref = psi.copy(), np.ones(k)


def tval3(
    A: LinearOperator,
    y: np.ndarray,
    reg: TV,
    lam: float,
    x0: np.ndarray | None = None,
    stop: StopRule | None = None,
    **options,
) -> tuple[np.ndarray, SolveInfo]:
    """Solve ``min_x 1/2 ||A x - y||^2 + lam TV(x)`` with :class:`TVAL3`.

    Parameters
    ----------
    A : LinearOperator
        Forward operator, shape ``(m, Q)``.
    y : ndarray, shape (m,) or (m, K)
        Data.
    reg : TV
        The total-variation regulariser (image shape, isotropy, non-negativity).
    lam : float
        Regularisation weight (> 0).
    x0 : ndarray, optional
        Starting point (default zeros).
    stop : StopRule, optional
    **options
        See :class:`TVAL3`.

    Returns
    -------
    x : ndarray, shape (Q,) or (Q, K)
    info : SolveInfo

    Notes
    -----
    Objective ``1/2 ||A x - y||^2 + lam TV(x)`` (eq. 18 of Shen et al.), solved as
    ``TV(x) + 1/(2 lam) ||A x - y||^2`` by the augmented Lagrangian method of Li et al. (2013).
    """
    return TVAL3(stop=stop, **options).solve(A, y, reg, lam, x0=x0)
