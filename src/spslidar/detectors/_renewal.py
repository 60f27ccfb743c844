"""Numerical kernels of the GMAPD's renewal model (:mod:`spslidar.detectors.pileup`): the
per-bin special functions, the afterpulse coefficients of
:func:`~spslidar.detectors.pileup.bin_map`, the chunked closed-form scan of
``x_{t+1} = e^{-c_t} x_t + F_t`` and its periodic solution, the dead-time window and the
per-bin Newton inverse of the photon map.

Private: the model, its inverse and their documentation are in
:mod:`spslidar.detectors.pileup`; these are its building blocks (kept apart so that neither
module grows past the project's size limit). No maintained library gives them: they are the
closed forms of the model's equations (R1)-(R2).
"""

from __future__ import annotations

import numpy as np

#: largest exponent summed in one chunk (e^600 < float64 max e^709)
_EXP_BUDGET = 600.0
#: exponents per bin are clipped here (e^-700 is 0 to float64 precision against 1)
_MU_CLIP = 700.0


def _phi(mu: np.ndarray) -> np.ndarray:
    """``(1 - exp(-mu)) / mu`` (1 at 0): the mean of ``exp(-mu u)`` for ``u`` uniform in [0, 1)."""
    mu = np.asarray(mu, dtype=np.float64)
    out = np.ones_like(mu)
    nz = mu > 0
    out[nz] = -np.expm1(-mu[nz]) / mu[nz]
    return out


def _one_minus_phi(mu: np.ndarray) -> np.ndarray:
    """``1 - phi(mu)`` without cancellation (series below 0.01)."""
    mu = np.asarray(mu, dtype=np.float64)
    small = mu < 1e-2
    out = np.empty_like(mu)
    m = mu[small]
    out[small] = m * (0.5 - m * (1 / 6 - m * (1 / 24 - m / 120)))
    out[~small] = 1.0 + np.expm1(-mu[~small]) / mu[~small]
    return out


def _chi(mu: np.ndarray) -> np.ndarray:
    """``d(1 - phi)/dmu = int_0^1 u exp(-mu u) du = (1 - e^-mu (1 + mu)) / mu^2``."""
    mu = np.asarray(mu, dtype=np.float64)
    small = mu < 1e-2
    out = np.empty_like(mu)
    m = mu[small]
    out[small] = 0.5 - m * (1 / 3 - m * (1 / 8 - m / 30))
    m = mu[~small]
    out[~small] = (-np.expm1(-m) - m * np.exp(-m)) / (m * m)
    return out


class _Coefficients:
    """Per-bin coefficients of :func:`bin_map` with afterpulsing."""

    def __init__(self, mu: np.ndarray, prob: float, rate: float):
        kappa = mu + rate
        self.ekap = np.exp(-np.minimum(kappa, _MU_CLIP))
        self.dexp = np.exp(-np.minimum(mu, _MU_CLIP)) - self.ekap
        phi = _phi(mu)
        b = prob / kappa  # gamma_inf / g
        # gamma1 = e^-kappa gamma0 + g b (1 - e^-kappa)
        self.coef_gamma = b * -np.expm1(-np.minimum(kappa, _MU_CLIP))
        # h = p alpha0 + g (1 - phi + phi P r / kappa - b dexp) + gamma0 dexp
        self.hcoef_g = _one_minus_phi(mu) + phi * prob * rate / kappa - b * self.dexp
        # afterpulse detections beyond the photon-only map: A = g (phi P r/kappa - b dexp) + ...
        self.ap_g = phi * prob * rate / kappa - b * self.dexp


def _chunks(cmax: np.ndarray, max_len: int) -> list[tuple[int, int]]:
    """Split ``range(L)`` into chunks of at most ``max_len`` bins whose summed exponent
    ``cmax`` (per bin, the largest over rows) stays within the float64 budget."""
    cs = np.concatenate(([0.0], np.cumsum(cmax)))
    out, k, n = [], 0, cmax.size
    while k < n:
        e = min(k + max_len, n, int(np.searchsorted(cs, cs[k] + _EXP_BUDGET, side="right")) - 1)
        e = max(e, k + 1)
        out.append((k, e))
        k = e
    return out


class _Scan:
    """Closed-form solution of ``x_{t+1} = e^{-c_t} x_t + F_t`` over chunks:
    ``x_{k+j+1} = e^{-C_{j+1}} (x_k + sum_{i<=j} F_{k+i} e^{C_{i+1}})``, ``C`` the within-chunk
    cumulative sum of ``c``."""

    def __init__(self, c: np.ndarray, chunks: list[tuple[int, int]]):
        c = np.minimum(c, _MU_CLIP)
        cum = np.empty_like(c)
        for k, e in chunks:
            np.cumsum(c[:, k:e], axis=1, out=cum[:, k:e])
        self.grow = np.exp(cum)
        self.decay = np.exp(-cum)

    def run(self, k: int, e: int, forcing: np.ndarray, x0: np.ndarray) -> np.ndarray:
        """States ``x_{k+1} .. x_e`` from ``x_k = x0`` and ``F_k .. F_{e-1}``."""
        s = np.cumsum(forcing * self.grow[:, k:e], axis=1)
        s += x0[:, None]
        s *= self.decay[:, k:e]
        return s


def _shifted_left(x0: np.ndarray, nxt: np.ndarray) -> np.ndarray:
    """States at the bins' starts ``x_k .. x_{e-1}`` from ``x_k`` and ``x_{k+1} .. x_e``."""
    return np.concatenate((x0[:, None], nxt[:, :-1]), axis=1)


def _circular_window(h: np.ndarray, d: int, f: float) -> np.ndarray:
    """``W_t = sum_{j=1}^{d} h_{t-j} + f h_{t-d-1}`` on rows of a periodic sequence."""
    period = h.shape[1]
    n_full, r = divmod(d, period)
    w = n_full * h.sum(axis=1, keepdims=True) + np.zeros_like(h)
    if r:
        ext = np.concatenate((h[:, period - r :], h), axis=1)
        cs = np.concatenate((np.zeros((h.shape[0], 1)), np.cumsum(ext, axis=1)), axis=1)
        w += cs[:, r : r + period] - cs[:, :period]
    if f:
        w += f * np.roll(h, d + 1, axis=1)
    return w


def _invert_photon_map(target, alpha, g, n_iter: int = 60, tol: float = 1e-14,
                       min_armed: float = 0.0):
    """Solve ``alpha p(mu) + g (1 - phi(mu)) = target`` for ``mu >= 0`` (Newton from the lower
    bound ``-log(1 - target / (alpha + g))``: the map is increasing and concave, so the
    iterates increase monotonically to the root). A negative ``target`` (counts less their
    expected afterpulses) continues the map through 0 along its slope there, ``alpha +
    g / 2``: ``mu = target / (alpha + g / 2)``, so that the estimate stays unbiased where a
    bin's counts are few; only where the bin was armed ``min_armed`` of the periods or more
    (one period's worth: a bin that was dead throughout holds no information, and the
    continuation through its vanishing slope read -1.6e13 photons inside a bright return, a
    review), 0 elsewhere."""
    shape = np.shape(target)
    target, alpha, g = (np.ravel(v) for v in (target, alpha, g))
    limit = alpha + g
    ok = limit > 0
    ratio = np.where(ok, target / np.where(ok, limit, 1.0), 0.0)
    mu = -np.log1p(-np.clip(ratio, 0.0, 1.0 - 1e-15))
    live = np.flatnonzero(ok & (g > 0) & (target > 0))
    for _ in range(n_iter):
        if not live.size:
            break
        m, a, gg, t = mu[live], alpha[live], g[live], target[live]
        res = a * -np.expm1(-m) + gg * _one_minus_phi(m) - t
        mu[live] = m - res / (a * np.exp(-m) + gg * _chi(m))
        live = live[np.abs(res) > tol * np.maximum(t, 1e-300)]
    slope = alpha + 0.5 * g
    below = (target < 0) & (slope > 0) & (limit >= max(min_armed, 1e-300))
    mu = np.where(below, target / np.where(below, slope, 1.0), np.maximum(mu, 0.0))
    return mu.reshape(shape)


def _periodic_scan(c: np.ndarray, forcing: np.ndarray) -> np.ndarray:
    """Periodic solution ``x_t`` (states at bin starts) of ``x_{t+1} = e^{-c_t} x_t + F_t``."""
    period = c.shape[1]
    chunks = _chunks(np.max(c, axis=0), period)
    scan = _Scan(c, chunks)

    def run(x0):
        out = np.empty_like(forcing)
        x = x0
        for k, e in chunks:
            nxt = scan.run(k, e, forcing[:, k:e], x)
            out[:, k:e] = _shifted_left(x, nxt)
            x = nxt[:, -1]
        return out, x

    _, x_end = run(np.zeros(c.shape[0]))
    total = np.minimum(c, _MU_CLIP).sum(axis=1)
    x0 = x_end / -np.expm1(-total)
    return run(x0)[0]


def _dots(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of two ``(B, n)`` arrays (batched BLAS)."""
    return (a[:, None, :] @ b[:, :, None])[:, 0, 0]


class _Anderson:
    """Anderson mixing (type II, Walker & Ni 2011) of ``B`` independent fixed-point
    iterations ``x -> out``, each row solving its own least-squares problem over the last
    ``depth`` differences of iterates and residuals.

    The Gram matrix of the residuals' differences is kept and updated by one new column per
    iterate (``depth`` dot products of the state's length), not rebuilt from the stacked
    history: at a state of 20 003 values per row (a dead time of 2 µs at 10 GHz) rebuilding
    it cost 85 % of the renewal model's time (an audit, 2026-11-30). SciPy's
    ``anderson`` solves one system, not a batch with per-row safeguards, hence by hand.
    """

    def __init__(self, depth: int):
        self.depth = depth
        self.clear()

    def clear(self) -> None:
        """Forget the history (a restart)."""
        self.last: tuple[np.ndarray, np.ndarray] | None = None
        self.d_x: list[np.ndarray] = []
        self.d_r: list[np.ndarray] = []
        self.gram = None

    def push(self, out: np.ndarray, res: np.ndarray):
        """Record the iterate ``out`` and its residual ``res``; return the per-row mixing
        ``(coeffs (B, k), d_x)`` of the differences held (``k = 0`` on the first push), with
        ``out - sum_i coeffs[:, i] d_x[i]`` the mixed iterate."""
        if self.last is not None:
            dr = res - self.last[1]
            self.d_x.append(out - self.last[0])
            cross = np.stack([_dots(v, dr) for v in self.d_r] + [_dots(dr, dr)], axis=1)
            k = len(self.d_r) + 1
            gram = np.empty((res.shape[0], k, k))
            if k > 1:
                gram[:, :-1, :-1] = self.gram
            gram[:, -1, :], gram[:, :, -1] = cross, cross
            self.d_r.append(dr)
            if k > self.depth:
                self.d_x.pop(0)
                self.d_r.pop(0)
                gram = gram[:, 1:, 1:]
            self.gram = gram
        self.last = (out, res)
        if not self.d_r:
            return np.zeros((res.shape[0], 0)), self.d_x
        rhs = np.stack([_dots(v, res) for v in self.d_r], axis=1)
        gram = self.gram
        reg = 1e-10 * np.trace(gram, axis1=1, axis2=2)[:, None, None] + 1e-300
        coeffs = np.linalg.solve(gram + reg * np.eye(gram.shape[1]), rhs[..., None])[..., 0]
        return coeffs, self.d_x
