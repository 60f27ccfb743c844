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
    is widened by ``dilate`` bins. Returns a boolean mask over the columns of ``corr``, all
    False where no delay rises (:func:`with_reference` adds the noise's sample).
    """
    profile = np.asarray(corr, dtype=np.float64).mean(axis=0)
    noise = float(np.sqrt(np.mean(np.asarray(sigma) ** 2) / corr.shape[0]))
    base = float(np.median(profile))
    hit = profile - base > n_sigmas * max(noise, 1e-300)
    # (none may rise: the gate then holds nothing this acquisition tells from the background.
    # The noisiest delay was kept instead, and its profiles, zero everywhere else, read as
    # returns at full confidence: a black scene came out a wall, said nowhere, an audit)
    return _dilated(hit, dilate)


def _dilated(mask: np.ndarray, d: int) -> np.ndarray:
    """``mask`` widened by ``d`` entries on each side."""
    out = mask.copy()
    for j in range(1, d + 1):
        out[j:] |= mask[:-j]
        out[:-j] |= mask[j:]
    return out


#: delays of the automatic gate kept beside the occupied ones as the noise's sample (spread
#: evenly over the rest of the gate): without them the unsolved delays are zeros, so every
#: profile's noise maximum beside its peak was 0 and the noise verdict and the confidence
#: read any peak as a return (estimate_budget prices 32 slices beyond the scene's window)
AUTO_GATE_REFERENCE = 32


def with_reference(keep: np.ndarray, n: int = AUTO_GATE_REFERENCE,
                   margin: int = AUTO_GATE_DILATE) -> np.ndarray:
    """``keep`` (the occupied delays, :func:`occupied_lags`) and up to ``n`` more, evenly
    spaced over the delays at least ``margin`` beyond every occupied one: the noise floor the
    noise verdict and the estimators' confidence read each pixel's return against."""
    keep = np.asarray(keep, dtype=bool)
    free = np.flatnonzero(~_dilated(keep, margin))
    if not free.size or n <= 0:
        return keep.copy()
    pick = free[np.unique(np.linspace(0, free.size - 1, min(n, free.size)).round().astype(int))]
    out = keep.copy()
    out[pick] = True
    return out


def unique_lags(lags: np.ndarray, period: int) -> tuple[np.ndarray, np.ndarray]:
    """Distinct delays modulo the code period, and the map back to the gate's lags."""
    u, inv = np.unique(np.mod(lags, period), return_inverse=True)
    return u, inv
