"""TVAL3: total-variation reconstruction by an augmented Lagrangian with alternating directions.

A from-the-paper implementation of Li, Yin, Jiang & Zhang (2013) for the TV form of eq. (18) of
Shen et al. (pseudo-random spread-spectrum single-pixel ToF lidar), batched over the K range
slices. Written by hand because no Python TVAL3 exists (the reference implementation is
Chengbo Li's MATLAB package); nothing here is translated from that code.
"""

from __future__ import annotations

import numpy as np

from ..operators.base import LinearOperator, power_norm
from ..operators.image import forward_differences_into
from ..operators.parallel import row_bands, run_parts, sum_parts
from .base import SolveInfo, Solver, StopRule, _axpy, col_dot, registered_defaults
from .regularisers import TV

__all__ = ["TVAL3", "tval3"]

_TINY = 1e-30
#: share of columns failing the line search above which it re-evaluates the whole block
_WHOLE_BLOCK_SHARE = 0.2
#: inner iterations between recomputations of the incrementally updated residual A x - y
_REFRESH = 100


def _colsum_nd(a: np.ndarray) -> np.ndarray:
    """Per-column (last axis) sums of a 2-D or 3-D array (any strides), in float64."""
    return np.einsum("ik->k" if a.ndim == 2 else "jik->k", a, dtype=np.float64)


def _huber(v: np.ndarray, beta: float, isotropic: bool, q: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-column values and gradient of ``sum_i H_beta(v_i)`` for ``v`` of shape ``(2Q, K)``.

    ``H_beta(v_i) = min_w ||w|| + beta/2 ||v_i - w||^2`` is the Huber function of the pixel
    vector ``v_i = (v[i], v[Q + i])`` (isotropic) or of each entry (anisotropic): equal to
    ``||v_i|| - 1/(2 beta)`` outside the ball of radius ``1/beta`` and ``beta/2 ||v_i||^2``
    inside. Its gradient ``beta (v - shrink(v, 1/beta)) = v / max(||v_i||, 1/beta)`` is
    returned in the dtype of ``v``. (Reference form of the kernels the solver runs on bands
    of pixels with preallocated buffers.)
    """
    v2 = v.reshape(2, q, v.shape[1])
    shp = v2.shape[1:] if isotropic else v2.shape
    mag, w1, w2 = (np.empty(shp, dtype=v.dtype) for _ in range(3))
    val = _huber_sum(v2, beta, isotropic, mag, w1, w2)
    grad = np.empty_like(v)
    _huber_grad(v2, beta, mag, grad.reshape(v2.shape))
    return val, grad


def _huber_value(v: np.ndarray, beta: float, isotropic: bool, q: int) -> np.ndarray:
    """Per-column ``sum_i H_beta(v_i)`` of ``v`` (2Q, K) (float64), with its own scratch."""
    v2 = v.reshape(2, q, v.shape[1])
    shp = v2.shape[1:] if isotropic else v2.shape
    mag, w1, w2 = (np.empty(shp, dtype=v.dtype) for _ in range(3))
    return _huber_sum(v2, beta, isotropic, mag, w1, w2)


def _magnitude(v2: np.ndarray, isotropic: bool, out: np.ndarray) -> np.ndarray:
    """``out = ||v_i||`` (isotropic, ``out`` (P, K)) or ``|v|`` (``out`` (2, P, K)) for the
    stacked gradient ``v2`` of shape ``(2, P, K)``."""
    if isotropic:
        np.einsum("iqk,iqk->qk", v2, v2, out=out)
        np.sqrt(out, out=out)
    else:
        np.abs(v2, out=out)
    return out


def _huber_sum(v2, beta, isotropic, mag, w1, w2) -> np.ndarray:
    """Per-column ``sum_i H_beta(v_i)`` (float64) as ``||v_i|| - m + beta/2 m^2`` with
    ``m = min(||v_i||, 1/beta)``, which equals both branches of the definition; ``mag``
    receives ``||v_i||``, ``w1`` and ``w2`` are scratch (all shaped like ``mag``)."""
    dt = v2.dtype
    _magnitude(v2, isotropic, mag)
    np.minimum(mag, dt.type(1.0 / beta), out=w1)
    np.multiply(w1, w1, out=w2)
    w2 *= dt.type(0.5 * beta)
    w2 += mag
    w2 -= w1
    return _colsum_nd(w2)


def _huber_grad(v2, beta, mag, out2) -> np.ndarray:
    """``out2 = v / max(||v_i||, 1/beta)`` (the Huber gradient); ``mag`` holds ``||v_i||``
    and is overwritten."""
    np.maximum(mag, v2.dtype.type(1.0 / beta), out=mag)
    np.divide(v2, mag, out=out2)
    return out2


def _grad_into(x: np.ndarray, shape: tuple[int, int], out: np.ndarray, rows=None) -> np.ndarray:
    """``out = D x`` (as :class:`~spslidar.operators.Gradient2D`) for ``x`` (Q, K), ``out``
    (2Q, K), without temporaries; only image rows ``rows = (a, b)`` of ``out`` when given
    (reading row ``b`` of ``x`` too)."""
    ny, nx = shape
    k = x.shape[1]
    o = out.reshape(2, ny, nx, k)
    forward_differences_into(x.reshape(ny, nx, k), o[0], o[1], rows)
    return out


def _grad_adj_into(p: np.ndarray, shape: tuple[int, int], out: np.ndarray, rows=None) -> np.ndarray:
    """``out = D^T p`` (as :class:`~spslidar.operators.Gradient2D`; the entries of ``p`` on
    the zero rows of ``D`` are ignored) for ``p`` (2Q, K), ``out`` (Q, K); only image rows
    ``rows = (a, b)`` of ``out`` when given (reading row ``a - 1`` of ``p`` too)."""
    ny, nx = shape
    k = p.shape[1]
    a, b = (0, ny) if rows is None else rows
    g = p.reshape(2, ny, nx, k)
    o = out.reshape(ny, nx, k)
    e = min(b, ny - 1)
    if e > a:
        np.negative(g[0, a:e], out=o[a:e])
    if b == ny:
        o[-1] = 0
    lo = max(a, 1)
    if lo < b:
        o[lo:b] += g[0, lo - 1 : b - 1]
    o[a:b, :-1] -= g[1, a:b, :-1]
    o[a:b, 1:] += g[1, a:b, :-1]
    return out


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
        See ``beta`` (default 1/4).
    mu0_factor, beta0_factor : float
        Continuation: start from ``mu0_factor * mu`` and ``beta0_factor * beta`` and multiply
        both by ``rate_ctn`` after every outer iteration until they reach ``mu`` and ``beta``
        (defaults 1/4 and 1/4; 1.0 disables the continuation). Measured on the lidar problems
        (camera at m_n = 2 and 10, motorcycle at m_n = 5 and 10; iterations to an objective
        within 1 % of the optimum): ``beta_scale = 1/4`` with a two-step continuation needs
        49-81 iterations where ``beta_scale = 1`` with a four-step continuation (1/16) needed
        about 140; the x-steps see the Hessian ``mu A^T A + beta D^T D``, whose TV part
        reaches ``8 beta`` against ``mu ||A||^2`` for the data part, so ``beta_scale = 1``
        makes them 8x worse conditioned than the data alone; 1/8 was no faster (the multiplier
        updates then converge more slowly). See
        ``benchmarks/tval3_parameters.py``.
    rate_ctn : float
        Continuation rate (default 2).
    tol_inner : float
        An inner loop ends when the relative change of every column,
        ``||x_k - x_{k-1}|| / ||x_k||``, falls below ``tol_inner`` (default 1e-3), or after
        ``max_inner`` iterations (default 15). The authors' code caps only the total
        (``maxit``); with the pipeline's budget of 100 iterations a cap of 50 left the
        continuation two doublings short of the final ``mu`` (objective twice the optimum on
        the default problem, depth RMSE 0.050 m), 15 lets it finish (objective within 2 % of
        FISTA's, depth RMSE 0.0066 m).
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
    default_iterations, default_lam_scale, default_regulariser = registered_defaults("tval3")

    _defaults = {
        "beta": None,
        "beta_scale": 0.25,
        "mu0_factor": 0.25,
        "beta0_factor": 0.25,
        "rate_ctn": 2.0,
        "tol_inner": 1e-3,
        "max_inner": 15,
        "eta": 0.6,
        "delta": 1e-5,
        "backtrack": 0.5,
        "max_backtrack": 30,
        "nonneg": None,
        "opnorm": None,
    }

    def __init__(self, stop: StopRule | None = None, threads: int | None = None, **options):
        unknown = set(options) - set(self._defaults)
        if unknown:
            raise TypeError(f"unknown TVAL3 option(s): {', '.join(sorted(unknown))}")
        super().__init__(stop=stop, threads=threads, **options)

    def _setup(self, A: LinearOperator, y, reg, lam, x0):
        if not isinstance(reg, TV):
            raise ValueError(
                f"TVAL3 solves the TV problem only: reg must be a TV instance, got {reg!r}"
            )
        if lam <= 0 and np.any(np.asarray(y)):
            # (a measurement without photons has max|A^H y| = 0 and so a default weight of 0:
            # its solution is 0 at any weight, below; it ended in this error, an audit)
            raise ValueError("TVAL3 needs lam > 0 (it solves TV(x) + 1/(2 lam) ||Ax - y||^2)")
        lam = lam if lam > 0 else 1.0  # y = 0: x = 0 at every weight
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
        rate = float(o["rate_ctn"])
        if rate < 1.0:
            raise ValueError("rate_ctn must be >= 1")
        self.y, self._dt, self._q, self._iso, self._nonneg = y, dt, q, iso, nonneg
        self._eta, self._delta = float(o["eta"]), float(o["delta"])
        self._shrink_t, self._rate = float(o["backtrack"]), rate
        self._slack = 10.0 * float(np.finfo(dt).eps)  # rounding allowance in the Armijo test
        self._max_inner = int(o["max_inner"])
        self._max_bt = int(o["max_backtrack"])
        self._tol_inner = float(o["tol_inner"])

        mu_f = 1.0 / lam
        if o["beta"] is not None:
            beta_f = float(o["beta"])
        else:
            norm_a = float(o["opnorm"]) if o["opnorm"] is not None else power_norm(A)
            beta_f = float(o["beta_scale"]) * mu_f * max(norm_a, _TINY) ** 2
        self._mu_f, self._beta_f = mu_f, beta_f
        mu = self._mu = min(mu_f, mu_f * float(o["mu0_factor"]))
        beta = self._beta = min(beta_f, beta_f * float(o["beta0_factor"]))

        # -- state ---------------------------------------------------------------------
        # All (Q, K) / (2Q, K) arrays are preallocated and updated in place. The element-wise
        # work is done on bands of image rows (concurrently inside a parallel context); a
        # (2Q, K) array is seen as (2, Q, K) and a band of pixels [p0, p1) covers both halves.
        shape = self._shape = reg.image_shape
        self._rbands = row_bands(ny, 2 * q * k)  # image rows
        self._pbands = [(a * nx, b * nx) for a, b in self._rbands]  # pixels
        self._nb = len(self._rbands)
        if x0 is None:
            x = np.zeros((n, k), dtype=dt)
        else:
            x = np.array(np.broadcast_to(x0, (n, k)), dtype=dt)
            if nonneg:
                np.maximum(x, 0, out=x)
        self._x = x
        self._nu = np.zeros((2 * q, k), dtype=dt)
        self._nu_b = np.zeros_like(self._nu)  # nu / beta for the current beta
        self._dx, self._dx_t, self._dd, self._v = (
            np.empty((2 * q, k), dtype=dt) for _ in range(4)
        )
        self._hg = np.empty((2 * q, k), dtype=dt)  # grad H at the current x
        self._g, self._g_new, self._d = (np.empty((n, k), dtype=dt) for _ in range(3))
        mshape = (q, k) if iso else (2, q, k)
        self._mag, self._w1, self._w2 = (np.empty(mshape, dtype=dt) for _ in range(3))
        self._cur: dict = {}  # per-iteration scalars shared with the band functions

        self._set_beta(beta)
        self._r, self._ga = self._refresh(x)
        _grad_into(x, shape, self._dx)
        psi = self._merit_and_grad(self._dx, self._r, mu, beta)
        g = self._g
        if nonneg:  # projected gradient direction for the first (Cauchy) step
            g0 = np.where((x > 0) | (g < 0), g, 0).astype(dt, copy=False)
        else:
            g0 = g
        ag0, dg0 = A.matvec(g0), _grad_into(g0, shape, self._dd)
        curv = mu * col_dot(ag0, ag0) + beta * col_dot(dg0, dg0)
        gg = col_dot(g0, g0)
        self._alpha = np.where(
            curv > 0, gg / np.maximum(curv, _TINY), 1.0 / max(beta * 8.0, _TINY)
        )
        self._c_ref, self._q_ref = psi.copy(), np.ones(k)

        self._outer = 0
        self._x_outer = x.copy()
        self._merit_hist: list[float] = []
        self._inner_counts: list[int] = []
        self._n_backtracks = 0
        self._last_refresh = 0
        self._begin_outer()

    # -- band kernels (pixel / image-row bands of the state arrays) -------------------------
    def _two(self, a: np.ndarray, i: int) -> np.ndarray:
        """Pixel band ``i`` of a (2Q, K) array, as a (2, P, K) view."""
        p0, p1 = self._pbands[i]
        return a.reshape(2, self._q, a.shape[1])[:, p0:p1]

    def _msl(self, a: np.ndarray, i: int) -> np.ndarray:
        """Pixel band ``i`` of a magnitude-shaped buffer."""
        p0, p1 = self._pbands[i]
        return a[p0:p1] if self._iso else a[:, p0:p1]

    def _huber_band(self, i: int, beta: float) -> np.ndarray:
        """Per-column Huber sum of ``v`` on pixel band ``i`` (``mag`` filled there)."""
        return _huber_sum(self._two(self._v, i), beta, self._iso, self._msl(self._mag, i),
                          self._msl(self._w1, i), self._msl(self._w2, i))

    def _grad_h_band(self, i: int, beta: float, fresh_mag: bool) -> None:
        """``hg = grad H(v)`` on pixel band ``i``."""
        mb = self._msl(self._mag, i)
        if not fresh_mag:
            _magnitude(self._two(self._v, i), self._iso, mb)
        _huber_grad(self._two(self._v, i), beta, mb, self._two(self._hg, i))

    def _gradient_band(self, i: int, mu: float, out: np.ndarray) -> None:
        """``out = D^T hg + mu A^T r`` (with ``ga = A^T r``) on row band ``i``."""
        _grad_adj_into(self._hg, self._shape, out, self._rbands[i])
        p0, p1 = self._pbands[i]
        _axpy(self._ga[p0:p1], out[p0:p1], mu)

    def _refresh(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        dt = self._dt
        r = self.A.matvec(x).astype(dt, copy=False) - self.y
        return r, self.A.rmatvec(r).astype(dt, copy=False)

    def _set_beta(self, beta: float) -> None:
        np.multiply(self._nu, self._dt.type(1.0 / beta), out=self._nu_b)

    def _merit_and_grad(self, dx: np.ndarray, r: np.ndarray, mu: float,
                        beta: float) -> np.ndarray:
        """psi per column at ``dx`` (without the constant -||nu||^2 / (2 beta)); grad H
        into ``hg`` and the gradient of psi into ``g``."""
        nb = self._nb
        np.subtract(dx, self._nu_b, out=self._v)
        hv = sum_parts(run_parts(lambda i: (self._huber_band(i, beta),), nb))[0]
        run_parts(lambda i: self._grad_h_band(i, beta, True), nb)
        run_parts(lambda i: self._gradient_band(i, mu, self._g), nb)
        return hv + 0.5 * mu * col_dot(r, r)

    def _direction_band(self, i: int):
        """``d = P(x - alpha g) - x`` (or ``-alpha g``) on band ``i``; partial ``<g, d>``."""
        p0, p1 = self._pbands[i]
        db, xb, gb = self._d[p0:p1], self._x[p0:p1], self._g[p0:p1]
        np.multiply(gb, self._cur["neg_alpha"], out=db)
        if self._nonneg:
            db += xb
            np.maximum(db, 0, out=db)
            db -= xb
        return (col_dot(gb, db),)

    def _point_band(self, i: int, tb):
        """The trial point ``dx_t = dx + t dd`` on band ``i`` (``tb``: the per-column
        steps ``t``, ``None`` for t = 1), ``v = dx_t - nu/beta`` and the partial Huber
        sum."""
        two = self._two
        dxt = two(self._dx_t, i)
        if tb is None:
            np.add(two(self._dx, i), two(self._dd, i), out=dxt)
        else:
            np.multiply(two(self._dd, i), tb, out=dxt)
            dxt += two(self._dx, i)
        np.subtract(dxt, two(self._nu_b, i), out=two(self._v, i))
        return (self._huber_band(i, self._cur["beta"]),)

    def _trial_band(self, i: int):
        """``dd = D d`` and the trial point at t = 1 on band ``i``."""
        _grad_into(self._d, self._shape, self._dd, self._rbands[i])
        return self._point_band(i, None)

    def _retry_band(self, i: int):
        """The trial point at every column's current step on band ``i``."""
        return self._point_band(i, self._cur["t_vec"])

    def _update_band(self, i: int):
        """Accept the step on band ``i``: ``s = t d`` (in ``d``), ``x += s``, the new
        gradient ``g_new``; partial ``||s||^2``, ``<s, g_new - g>``, ``||x||^2`` and TV."""
        p0, p1 = self._pbands[i]
        cur = self._cur
        sb, xb = self._d[p0:p1], self._x[p0:p1]
        if cur["t_cols"] is not None:
            cols = cur["t_cols"]
            sb[:, cols] *= cur["t_dt"][cols]
        xb += sb
        self._gradient_band(i, cur["mu"], self._g_new)
        gn, go = self._g_new[p0:p1], self._g[p0:p1]
        sy = col_dot(sb, gn) - col_dot(sb, go)
        tv = _colsum_nd(_magnitude(self._two(self._dx, i), self._iso, self._msl(self._w1, i)))
        return col_dot(sb, sb), sy, col_dot(xb, xb), tv

    # -- the iteration -------------------------------------------------------------------
    def _begin_outer(self) -> None:
        """Start an outer (multiplier) iteration."""
        self._outer += 1
        self._inner = 0
        self._final = self._mu >= self._mu_f and self._beta >= self._beta_f
        self._cur["beta"], self._cur["mu"] = self._beta, self._mu

    def _end_outer(self) -> None:
        """Multiplier update and continuation after an inner loop."""
        mu, beta = self._mu, self._beta
        self._x_outer = self._x.copy()
        # multiplier update: nu <- nu - beta (D x - w) = -grad H(D x - nu / beta), where
        # hg is grad H at the current x (computed after its line search)
        np.negative(self._hg, out=self._nu)
        # continuation
        old = (mu, beta)
        mu = self._mu = min(mu * self._rate, self._mu_f)
        beta = self._beta = min(beta * self._rate, self._beta_f)
        if (mu, beta) != old:
            self._alpha = self._alpha * (old[1] / beta)
        self._set_beta(beta)
        if self.it - self._last_refresh >= _REFRESH:
            # recompute the residual, updated incrementally so far (float32 drift)
            self._r, self._ga = self._refresh(self._x)
            _grad_into(self._x, self._shape, self._dx)
            self._last_refresh = self.it
        # gradient and merit for the new nu, mu, beta (no product with A needed)
        psi = self._merit_and_grad(self._dx, self._r, mu, beta)
        self._c_ref, self._q_ref = psi.copy(), np.ones(self.y.shape[1])

    def _step(self) -> str:
        A, y, dt, cur, nb = self.A, self.y, self._dt, self._cur, self._nb
        k, q, iso = y.shape[1], self._q, self._iso
        mu, beta, r, c_ref = self._mu, self._beta, self._r, self._c_ref
        delta, slack, shrink_t, max_bt = self._delta, self._slack, self._shrink_t, self._max_bt
        self._inner += 1
        inner = self._inner
        # direction d = P(x - alpha g) - x (projected) or -alpha g, per-column alpha
        cur["neg_alpha"] = -self._alpha.astype(dt)
        (gd,) = sum_parts(run_parts(self._direction_band, nb))
        ad = A.matvec(self._d).astype(dt, copy=False)
        # nonmonotone Armijo line search, per column: every column is evaluated at
        # t = 1, then only the columns that fail are evaluated again at smaller t
        t = np.ones(k)
        (hv,) = sum_parts(run_parts(self._trial_band, nb))
        r_t = r + ad
        psi_t = hv + 0.5 * mu * col_dot(r_t, r_t)
        fresh_mag = True  # mag holds ||v_i|| of every column
        bad = np.flatnonzero(~(psi_t <= c_ref + delta * t * gd + slack * np.abs(c_ref)))
        if bad.size > _WHOLE_BLOCK_SHARE * k:
            # most columns fail: re-evaluate the whole block at the per-column steps
            # (accepted columns keep t and their values), no strided gathers
            live = np.zeros(k, dtype=bool)
            live[bad] = True
            n_bt = 0
            while live.any() and n_bt < max_bt:
                n_bt += 1
                self._n_backtracks += 1
                t[live] *= shrink_t
                cur["t_vec"] = t.astype(dt)
                (hv,) = sum_parts(run_parts(self._retry_band, nb))
                np.multiply(ad, cur["t_vec"], out=r_t)
                r_t += r
                psi_new = hv + 0.5 * mu * col_dot(r_t, r_t)
                psi_t[live] = psi_new[live]
                ok = psi_t <= c_ref + delta * t * gd + slack * np.abs(c_ref)
                live &= ~ok
            # dx_t, v, mag and r_t all hold the final steps of every column
        elif bad.size:
            # the failing columns, gathered once (strided gathers from the (2Q, K)
            # arrays are the expensive part); the trial points at smaller t are
            # formed on these compact copies, and written back once at the end
            dx_c, dd_c, nub_c = self._dx[:, bad], self._dd[:, bad], self._nu_b[:, bad]
            r_c, ad_c = r[:, bad], ad[:, bad]
            live = np.arange(bad.size)
            n_bt = 0
            while live.size and n_bt < max_bt:
                n_bt += 1
                self._n_backtracks += 1
                cols = bad[live]
                t[cols] *= shrink_t
                tl = t[cols].astype(dt)
                vt = dx_c[:, live] + tl * dd_c[:, live]
                vt -= nub_c[:, live]
                rt = r_c[:, live] + tl * ad_c[:, live]
                psi_t[cols] = _huber_value(vt, beta, iso, q) + 0.5 * mu * col_dot(rt, rt)
                ok = psi_t[cols] <= c_ref[cols] + delta * t[cols] * gd[cols] + slack * (
                    np.abs(c_ref[cols])
                )
                live = live[~ok]
            tb = t[bad].astype(dt)
            dxb = dx_c + tb * dd_c
            self._dx_t[:, bad] = dxb
            self._v[:, bad] = dxb - nub_c
            r_t[:, bad] = r_c + tb * ad_c
            fresh_mag = False
        # accept: grad H at the new point, then s = t d, x += s and the new gradient
        r = self._r = r_t
        self._dx, self._dx_t = self._dx_t, self._dx
        psi = psi_t
        run_parts(lambda i, fm=fresh_mag, bt=beta: self._grad_h_band(i, bt, fm), nb)
        self._ga = A.rmatvec(r).astype(dt, copy=False)
        moved = np.flatnonzero(t != 1.0)
        cur["t_cols"] = moved if moved.size else None
        cur["t_dt"] = t.astype(dt)
        ss, sy, xn2, tv = sum_parts(run_parts(self._update_band, nb))
        # Barzilai-Borwein step (BB1), per column
        self._alpha = np.where((sy > 0) & (ss > 0), ss / np.maximum(sy, _TINY), self._alpha)
        # Zhang-Hager reference value
        q_new = self._eta * self._q_ref + 1.0
        self._c_ref = (self._eta * self._q_ref * c_ref + psi) / q_new
        self._q_ref = q_new
        self._merit_hist.append(float(np.sum(self._c_ref)))
        self._g, self._g_new = self._g_new, self._g
        # inner stopping (per-column relative change, all columns)
        rel = np.sqrt(ss) / np.maximum(np.sqrt(xn2), _TINY)
        inner_done = bool(np.all(rel <= self._tol_inner)) or inner == self._max_inner
        obj = 0.5 * float(np.sum(col_dot(r, r))) + self.lam * float(np.sum(tv))
        ref = self._x_outer if (inner_done and self._final) else None
        reason = self.monitor.check(self.it, self._x, ref, obj)
        if reason or inner_done:
            self._inner_counts.append(inner)
        if reason:
            return reason
        if inner_done:
            self._end_outer()
            self._begin_outer()
        return ""

    def _finish(self) -> np.ndarray:
        self.monitor.info.extra.update(
            {
                "outer_iterations": self._outer,
                "inner_iterations": self._inner_counts,
                "mu": self._mu,
                "beta": self._beta,
                "nonneg": self._nonneg,
                "backtracks": self._n_backtracks,
                "merit": self._merit_hist,
            }
        )
        return self._x


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
