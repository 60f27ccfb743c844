"""Independent references shared by the solver tests (not collected: no ``test_`` prefix)."""

import numpy as np


def fista_tv(a: np.ndarray, y: np.ndarray, lam: float, reg, n_iter: int) -> np.ndarray:
    """Plain FISTA on ``||a x - y||^2 / 2 + lam reg(x)`` with ``reg``'s prox, written without
    the solver classes: the reference their TV optimum is checked against."""
    lip = np.linalg.norm(a, 2) ** 2
    x = np.zeros((a.shape[1], y.shape[1]))
    v, t = x.copy(), 1.0
    for _ in range(n_iter):
        xn = reg.prox(v - a.T @ (a @ v - y) / lip, lam / lip)
        tn = 0.5 * (1 + np.sqrt(1 + 4 * t * t))
        v, x, t = xn + (t - 1) / tn * (xn - x), xn, tn
    return x
