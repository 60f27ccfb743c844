"""Dense Markov-chain reference of the GMAPD's stationary histogram (Rapp, Ma, Dawson &
Goyal, "Dead time compensation for high-flux ranging", IEEE Trans. Signal Process. 67(13),
2019): the chain on the bin of each detection modulo the period, built as an ``L x L``
transition matrix and solved for its stationary law.

It is the peer of :func:`spslidar.detectors.pileup.renewal_detection` (which avoids the matrix
by sweeping the expectation's time evolution) for tests and ``benchmarks/gmapd_model.py``,
not for use in the chain: ``O(L^2)`` memory and ``O(L^3)`` time per row.

The process is (R2)'s, for a whole number of dead bins ``d`` and no afterpulsing: a
detection in bin ``s`` (at a uniform time within it) re-arms the detector at the same time
of bin ``s + d``, which is then armed for a uniform fraction of it, so its detection
probability there is ``1 - phi(mu)`` (``phi(mu) = (1 - e^-mu) / mu``); each later bin,
armed throughout, detects with ``p = 1 - e^-mu``. From the re-arming bin ``a`` the next
detection is at bin ``a + k``, the unrolled bins wrapping over the period as many times as
the detector stays armed without a photon (a geometric series of the period's survival
``S = e^{-sum mu}``), so each row of the matrix is in closed form; the stationary law ``pi``
solves ``pi T = pi``, ``sum pi = 1`` (one dense solve), and the detections per period are
``L`` over the mean bins between detections. NumPy does the algebra; the matrix is this
module's (no library builds this chain).
"""

from __future__ import annotations

import numpy as np

from ._renewal import _one_minus_phi, _phi

__all__ = ["chain_detection"]


def _chain(mu: np.ndarray, d: int) -> tuple[np.ndarray, np.ndarray]:
    """Transition matrix ``T[s, j]`` of one row's chain and the mean bins from a detection in
    bin ``s`` to the next."""
    n = mu.size
    a = (np.arange(n) + d) % n  # the re-arming bin of a detection in bin s
    cum = np.concatenate(([0.0], np.cumsum(np.tile(mu, 2))))  # cum[m]: flux of bins < m
    k = np.arange(1, n + 1)
    # armed throughout bins a + 1 .. a + k - 1, detecting in bin a + k (k = 1 .. n: one pass)
    start = a[:, None] + 1
    cols = (a[:, None] + k[None, :]) % n
    survive = np.exp(-(cum[start + k[None, :] - 1] - cum[start]))
    v = survive * -np.expm1(-mu[cols])
    lost = -np.expm1(-mu.sum())  # 1 - S: a pass's chance of a detection
    phi_a = _phi(mu[a])
    t = np.zeros((n, n))
    # every later pass repeats the first, scaled by S per pass
    np.put_along_axis(t, cols, phi_a[:, None] * v / lost, axis=1)
    t[np.arange(n), a] += _one_minus_phi(mu[a])
    passes = np.exp(-mu.sum()) / lost  # S / (1 - S)
    mean_k = phi_a * ((v * k).sum(axis=1) + n * v.sum(axis=1) * passes) / lost
    return t, d + mean_k


def chain_detection(mu: np.ndarray, dead_bins: int) -> np.ndarray:
    """Mean detections per bin per period of a free-running non-paralysable GMAPD, from the
    dense Markov chain of its detections' bins (see the module docstring).

    Parameters
    ----------
    mu : ndarray, shape (B, L) or (L,)
        Mean photons plus dark counts per bin per code period, each row with some flux.
    dead_bins : int
        Dead time, a whole number of bins of at least 1.

    Returns
    -------
    ndarray, same shape as ``mu``
        What :func:`~spslidar.detectors.pileup.renewal_detection` gives without afterpulsing.
    """
    mu = np.asarray(mu, dtype=np.float64)
    if int(dead_bins) != dead_bins or dead_bins < 1:
        raise ValueError(f"dead_bins must be a whole number of at least 1, got {dead_bins}")
    rows = np.atleast_2d(mu)
    if not (np.isfinite(rows).all() and (rows >= 0).all() and (rows.sum(axis=1) > 0).all()):
        raise ValueError("mu must be finite, non-negative, and hold flux in every row")
    out = np.empty_like(rows)
    n = rows.shape[1]
    for r, row in enumerate(rows):
        t, gap = _chain(row, int(dead_bins))
        lhs = t.T - np.eye(n)
        lhs[-1] = 1.0  # one equation replaced by sum(pi) = 1
        rhs = np.zeros(n)
        rhs[-1] = 1.0
        pi = np.linalg.solve(lhs, rhs)
        out[r] = pi * n / (pi @ gap)
    return out[0] if mu.ndim == 1 else out
