"""The range gate after the matched filter: the automatic gate (occupied delays found before
any reconstruction) and the distinct delays modulo the code period."""

from __future__ import annotations

import numpy as np


def gate_text(gate) -> str:
    """A range gate in metres as the messages say it, ``19.955-20.845``: 6 significant
    digits, more where they would print the two ends alike (a scene at 900 km read "the
    range gate 900000-900000 m", an audit)."""
    lo, hi = float(gate[0]), float(gate[1])
    for digits in range(6, 18):
        a, b = f"{lo:.{digits}g}", f"{hi:.{digits}g}"
        if a != b or lo == hi:
            return f"{a}-{b}"
    return f"{lo!r}-{hi!r}"


#: with auto_gate unset, gates with more distinct slices than this are pruned automatically
AUTO_GATE_MIN_SLICES = 256
#: detection threshold of the automatic range gate, in standard deviations of the
#: pattern-averaged matched-filter output
AUTO_GATE_SIGMAS = 5.0
#: bins kept on each side of every occupied delay
AUTO_GATE_DILATE = 2


def occupied_lags(corr: np.ndarray, sigma: np.ndarray, n_sigmas: float = AUTO_GATE_SIGMAS,
                  dilate: int = AUTO_GATE_DILATE) -> np.ndarray:
    """Automatic range gate: which delays hold a return, found before any reconstruction.

    The matched-filter output averaged over the patterns is ``mean_i C_i(tau) =
    sum_j mean(Phi_j) alpha_j w_j(tau)``: the scene's reflectivity-weighted depth histogram
    (plus a constant background). Delays where it rises more than ``n_sigmas`` standard
    deviations (of that mean, ``sqrt(mean sigma_i^2 / M)``) above its median are occupied; each
    is widened by ``dilate`` bins. Returns a boolean mask over the columns of ``corr``.
    """
    profile = np.asarray(corr, dtype=np.float64).mean(axis=0)
    noise = float(np.sqrt(np.mean(np.asarray(sigma) ** 2) / corr.shape[0]))
    base = float(np.median(profile))
    hit = profile - base > n_sigmas * max(noise, 1e-300)
    if not hit.any():
        hit[np.argmax(profile)] = True
    keep = hit.copy()
    for d in range(1, dilate + 1):
        keep[d:] |= hit[:-d]
        keep[:-d] |= hit[d:]
    return keep


def unique_lags(lags: np.ndarray, period: int) -> tuple[np.ndarray, np.ndarray]:
    """Distinct delays modulo the code period, and the map back to the gate's lags."""
    u, inv = np.unique(np.mod(lags, period), return_inverse=True)
    return u, inv
