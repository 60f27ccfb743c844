"""The calibration target's tilt read from each pattern's response centroid (step 3 of
:mod:`spslidar.pipeline.target`): a wall turned about a vertical or horizontal axis moves
the round trip linearly across the image, and each pattern's centroid is the round trip
averaged over its light, so a least-squares fit of the centroids to the light-weighted image
coordinates gives the tilt and its standard error, which ``measure_geometry`` then scans
about.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["tilt_of_target"]


def _coordinates(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's image coordinates ``x`` (right) and ``y`` (down) in ``[-1, 1]``,
    flattened row-major."""
    rows, cols = (int(n) for n in shape)
    y, x = np.meshgrid(2.0 * (np.arange(rows) + 0.5) / rows - 1.0,
                       2.0 * (np.arange(cols) + 0.5) / cols - 1.0, indexing="ij")
    return x.ravel(), y.ravel()


def tilt_of_target(g: np.ndarray, patterns: np.ndarray, shape: tuple[int, int]
                   ) -> dict[str, Any] | None:
    """The target's round trips from each pattern's response centroid (module docstring,
    step 3).

    Parameters
    ----------
    g : ndarray, shape (M, W)
        Each pattern's response with the code removed and its background subtracted, on a
        window of the period that holds the whole return (:func:`_code_removed`).
    patterns : ndarray, shape (M, Q)
    shape : (int, int)

    Returns
    -------
    dict or None
        ``tilt_bins`` (the round trip's change from the axis to the image's right and lower
        edge, bins), ``tilt_z`` (each over its standard error) and ``curvature_bins`` (a
        facing wall's: the change from the axis to ``x^2 + y^2 = 1``); None where the
        centroids cannot be read (too few patterns, a response without a peak).
    """
    m = g.shape[0]
    total = g.sum(axis=0)
    if m < 12 or not total.max() > 0:
        return None
    # the return's support: the contiguous run about the peak above 5 % of it, and 2 bins
    # (the window rolled to put the peak in its middle: a period's response wraps)
    shift = total.size // 2 - int(np.argmax(total))
    g, total = np.roll(g, shift, axis=1), np.roll(total, shift)
    peak = int(np.argmax(total))
    above = total > 0.05 * total[peak]
    lo = peak
    while lo > 0 and above[lo - 1]:
        lo -= 1
    hi = peak
    while hi < total.size - 1 and above[hi + 1]:
        hi += 1
    lo, hi = max(0, lo - 2), min(total.size - 1, hi + 2)
    win = g[:, lo:hi + 1]
    mass = win.sum(axis=1)
    pats = np.asarray(patterns, dtype=np.float64)
    lit = pats.sum(axis=1)
    ok = mass > 0.05 * np.median(mass[mass > 0]) if np.any(mass > 0) else mass > 0
    ok &= lit > 0  # (a dark frame's light-weighted means are 0/0: calibrate crashed in
    # LAPACK where its noise passed the mass test, a review of 2026-11-29)
    if ok.sum() < 12:
        return None
    t = np.arange(lo, hi + 1, dtype=np.float64)
    mu = (win[ok] @ t) / mass[ok]
    x, y = _coordinates(shape)
    # (x^2, y^2 and xy apart, as a tilt's square adds them, fitted the noise: a 5 degree
    # tilt's delay 0.35 ns off and its IRF 3.6 bins wide against 0.08 ns and 2.1 bins)
    terms = np.stack([x, y, x * x + y * y], axis=1)  # (Q, 3)
    design = np.column_stack([np.ones(int(ok.sum())),
                              (pats[ok] @ terms) / lit[ok, None]])
    if not np.all(np.isfinite(design)) or not np.all(np.isfinite(mu)):
        return None
    try:
        coef, *_ = np.linalg.lstsq(design, mu, rcond=None)
        resid = mu - design @ coef
        dof = max(design.shape[0] - design.shape[1], 1)
        cov = float(resid @ resid) / dof * np.linalg.inv(design.T @ design)
    except np.linalg.LinAlgError:  # patterns that do not vary their light's position
        return None
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    z = np.divide(coef, se, out=np.zeros_like(coef), where=se > 0)
    return {"tilt_bins": [float(coef[1]), float(coef[2])],
            "tilt_z": [float(z[1]), float(z[2])], "curvature_bins": float(coef[3]),
            "curvature_z": float(z[3])}
