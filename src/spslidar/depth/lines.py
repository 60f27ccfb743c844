"""Thin structures the MRF smooths away: lines of argmax returns in front of its surface.

A one-pixel pole, wire or table leg in front of a wall costs the MRF of
:class:`~spslidar.depth.mrf.MRFDepth` a depth edge on both sides of every pixel, so where
its returns are weak the MRF gives those pixels the wall behind them, while the paper's
argmax keeps them wherever their own slice is the tallest. A pixel's argmax in front of the
MRF's surface is also what a noise spike looks like, one pixel at a time; what noise does
not do is line up. :func:`thin_structures` therefore keeps the argmax of the pixels that
form, together, a line:

* each candidate's argmax lies more than ``gap`` slices in front of the MRF's label and
  reaches ``floor`` times the block's typical noise maximum ``nu`` (a weak but real return);
* candidates are joined to their neighbours whose argmax is within ``step`` slices, in three
  passes (:data:`PASSES`): 8-neighbours with a small step (a structure at one depth: a pole,
  a leg, a fence slat), 8-neighbours with a large one (a slanted wire, whose depth changes
  by up to 16 slices a pixel), and neighbours up to two pixels away with the large step (a
  wire found on every other pixel), this last with stricter size and evidence tests;
* a group is kept when it has at least the pass's minimum of pixels, is ``elongation`` times
  longer than wide (the square root of the ratio of its coordinates' principal variances),
  its argmax depth is a linear function of the position along it to within ``residual``
  slices, and its evidence sums to the pass's total times ``nu``.

Chosen on the procedural scenes of seeds 0-19 (64x64, m_n 5 and 10, 25 % and 50 %
patterns; ``benchmarks/depth_quality.py``) among minimum sizes 3-6, elongations 2.5-3.5,
evidence totals 0-12 ``nu`` and reaches of 1-2 pixels, as the setting that never made a
scene of those seeds or of the built-in scenes more than 1 % worse than the MRF alone (the
numbers it gives on held-out seeds are in the README). The connected groups are
SciPy's (:func:`scipy.sparse.csgraph.connected_components`); the line test is a few lines
of NumPy per group, written here because no library tests a pixel group's shape and depth
together.
"""

from __future__ import annotations

import numpy as np

__all__ = ["thin_structures"]

#: defaults of :func:`thin_structures` (see the module docstring for how they were chosen)
GAP, FLOOR, ELONGATION, RESIDUAL = 3, 0.8, 3.5, 2.0
#: the joining passes: (step in slices, reach in pixels, minimum pixels, evidence total in nu)
PASSES = ((2, 1, 3, 5.0), (16, 1, 3, 5.0), (16, 2, 4, 12.0))


def _groups(cand: np.ndarray, a: np.ndarray, shape: tuple[int, int], step: int,
            reach: int = 1) -> tuple[np.ndarray, np.ndarray, int]:
    """Candidates (flat indices), their group labels and the number of groups: candidates up
    to ``reach`` pixels apart (in x and in y) joined where their argmax slices differ by at
    most ``step``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n1, n2 = shape
    pix = np.flatnonzero(cand)
    where = np.full(n1 * n2, -1)
    where[pix] = np.arange(pix.size)
    grid = where.reshape(shape)
    lag = a.reshape(shape)
    rows, cols = [], []
    ys, xs = np.divmod(pix, n2)
    half = [(dy, dx) for dy in range(reach + 1) for dx in range(-reach, reach + 1)
            if dy > 0 or dx > 0]  # each pair once
    for dy, dx in half:
        y2, x2 = ys + dy, xs + dx
        ok = (y2 < n1) & (x2 >= 0) & (x2 < n2)
        y1, x1, y2, x2 = ys[ok], xs[ok], y2[ok], x2[ok]
        ok = (grid[y2, x2] >= 0) & (np.abs(lag[y1, x1] - lag[y2, x2]) <= step)
        rows.append(grid[y1[ok], x1[ok]])
        cols.append(grid[y2[ok], x2[ok]])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(r.size), (r, c)), shape=(pix.size, pix.size))
    n, labels = connected_components(graph, directed=False)
    return pix, labels, n


def thin_structures(a: np.ndarray, label: np.ndarray, strength: np.ndarray, nu: float,
                    shape: tuple[int, int], *, gap: int = GAP, floor: float = FLOOR,
                    elongation: float = ELONGATION, residual: float = RESIDUAL,
                    passes: tuple[tuple[int, int, int, float], ...] = PASSES) -> np.ndarray:
    """Pixels whose argmax belongs to a line in front of the MRF's surface.

    Parameters
    ----------
    a : ndarray of int, shape (Q,)
        Each pixel's argmax slice.
    label : ndarray of int, shape (Q,)
        The MRF's slice.
    strength : ndarray, shape (Q,)
        The evidence at ``a`` (in the units of ``nu``).
    nu : float
        The block's typical noise maximum (the median over the pixels of the largest evidence
        away from each profile's return).
    shape : (int, int)
        The image grid.
    gap, floor, elongation, residual, passes
        The tests of the module docstring; ``passes`` holds, per joining pass, the step in
        slices, the reach in pixels, the minimum number of pixels and the evidence total.

    Returns
    -------
    ndarray of bool, shape (Q,)
        True where the argmax is to be kept.
    """
    a = np.asarray(a)
    keep = np.zeros(a.size, dtype=bool)
    if nu <= 0 or a.size == 0:
        return keep
    z = np.asarray(strength, dtype=np.float64) / nu
    cand = (a < np.asarray(label) - gap) & (z >= floor)
    n2 = shape[1]
    for step, reach, min_pixels, total in passes:
        if cand.sum() < min_pixels:
            continue
        pix, groups, n = _groups(cand, a, shape, step, reach)
        sizes = np.bincount(groups, minlength=n)
        sums = np.bincount(groups, weights=z[pix], minlength=n)
        for g in np.flatnonzero((sizes >= min_pixels) & (sums >= total)):
            members = pix[groups == g]
            yx = np.stack(np.divmod(members, n2), axis=1).astype(np.float64)
            var, vec = np.linalg.eigh(np.cov(yx.T) + np.eye(2) / 12.0)  # a pixel's own spread
            if var[1] < elongation ** 2 * var[0]:
                continue
            t = (yx - yx.mean(axis=0)) @ vec[:, 1]
            lag = a[members].astype(np.float64)
            fit = np.polyval(np.polyfit(t, lag, 1), t)
            if np.abs(fit - lag).max() <= residual:
                keep[members] = True
    return keep
