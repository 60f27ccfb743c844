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
  wire found on every other pixel), this with stricter size and evidence tests, and
  neighbours up to three pixels away with the large step and at least 6 pixels (a shallow
  slanted wire found on one pixel in two or three);
* a group is kept when it has at least the pass's minimum of pixels, is ``elongation`` times
  longer than wide (the square root of the ratio of its coordinates' principal variances),
  its argmax depth is a linear function of the position along it to within ``residual``
  slices, and its evidence sums to the pass's total times ``nu``; where one or two of its
  pixels are off the line, the inliers of a Theil-Sen line are kept if they are ``robust``
  (0.9) of the group.

A structure the MRF keeps in part (a pole it labels on some rows, its pieces joined by rows
given the wall) is continued by :func:`extend_lines`: the one-pixel-wide pixels of the
labelling itself (:func:`one_pixel_wide`) join the candidates as anchors, at their label's
slice and evidence, through the same passes and tests, and a candidate is kept where its group
holds at least one candidate and it lies on the group's axis (within ``axis`` pixels of the
line through the group: a pole's side neighbour, whose argmax is the pole's bleed, is not).
Run once after :func:`thin_structures`; a second round changed nothing on the scenes tried.

Where argmax misses a structure's next pixels altogether (their tallest slice is the wall's or
noise), :func:`track_lines` follows the line itself: each one-pixel structure of the labelling
(at least 3 pixels, the same elongation and linear-depth tests) is walked beyond its ends
along its axis, and each next pixel labelled behind the line takes the line's slice (the best
of it and its two neighbours) while its own evidence there reaches ``lo`` and ``relative``
times the structure's median and stands ``contrast`` above its two pixels beside the line,
and the mean over the pixel before it, it and the next reaches ``tau`` noise maxima. The
slice is known, so this tests one slice per pixel, not the pixel's whole profile: along the
room's lamp pole the evidence at the pole's slice is 0.7-2.4 noise maxima, beside it 0-1.6
(mean 0.5), above its top 0.3-0.7. The window reaches a pixel ahead, so a walk stops a pixel
short of a structure's end where the evidence drops at once, and goes one past it where the
bleed beyond a weak structure's end is 0.6 of its evidence (the relative test stops a strong
one's: beyond a pole of 9 noise maxima the bleed is 1.6). The walk crosses the line's own
pixels, never a surface at its depth (a table leg's walk would cross the table top into the
top's bleed above it): a pixel at the line's slice is the line's where it is one pixel wide
or has at most one more pixel at that slice within two across the line (a pole with its bleed
labelled beside it; a table top has four). Where one pixel behind the line fails the tests
and the line's own pixels hold the next two, the walk steps over it, and takes it where the
line runs through it straight and at one depth (a pole's or a leg's weak pixel between two of
its pieces: the room's lamp pole and a table leg at m_n = 5, 50 %, seed 2, each broken at one
pixel, so that the leg's walk never reached its two pixels above the break). Chosen on the
built-in scenes (room at m_n = 5, 50 %, seeds 0 / 1 / 2: 0.029 / 0.024 / 0.043 -> 0.016 /
0.024 / 0.028 m); on seeds 0-19 15 of 80 measurements better (to 0.969 of before) and none
worse, the built-ins 6 of 78 better and one 0.25 % worse (the motorcycle at m_n = 10, 50 %,
seed 2), held-out seeds 100-149 82 of 280 better (to 0.89) and 2 worse by 0.03 % at most.
Requiring two held pixels beyond, not one, is what keeps the walk on the structure: carried
past a failing pixel whenever the next was held, it ran on along lines the structure does
not continue (room at m_n = 1, 50 %, seed 0: 0.0043 -> 0.032 m).

Two more rules hold for a *straight* structure only, along a row or a column at one depth (a
pole, a leg), whose line's rounding is exact. Its pieces are joined up to two pixels apart
(a leg the MRF holds on every other row has no piece of three), and each single pixel between
two of them is taken. And where its walk stops at most ``BRIDGE_REACH`` (4) pixels short
of a surface at its own depth, the pixels between, all labelled more than
``BRIDGE_BEHIND`` (10) slices behind it, are taken if their evidence at its slice stands,
on average, above their sides' (a leg whose top rows, under its table top, the TV left at 0.3-2
noise maxima). Chosen on the room at m_n = 5, 50 %, seeds 3-7 (0.027 / 0.034 / 0.066 / 0.049
/ 0.054 -> 0.027 / 0.029 / 0.030 / 0.022 / 0.005 m); held out, seeds 8-15: 0.009 / 0.066 /
0.053 / 0.054 / 0.006 / 0.038 / 0.025 / 0.029 -> 0.009 / 0.066 / 0.034 / 0.012 / 0.006 / 0.038
/ 0.014 / 0.029 m. Procedural seeds 0-19: 17 of 80 measurements better, 3 worse by 0.6 % at
most; held-out seeds 100-149 (m_n 1-10): 78 of 280 better (to 0.73), 3 worse by 0.11 % at
most; the other built-ins: street at m_n = 1, 25 %, seeds 1 / 2: 0.076 / 0.091 -> 0.026 /
0.063 m, nothing worse. Without the straightness test the bridge took a motorcycle part to
another at its depth (m_n = 10, 25 %, seed 2: 0.068 -> 0.070 m), and without the 10 slices
a slat 4 cm in front of its wall (procedural seed 115).

The window leaves out a pixel where a surface nearer than the line hides it: a leg's top
pixel under a table top nearer than the leg is tested on itself and the leg's pixel before
it, since the top tells nothing of the leg (held-out room at m_n = 5, 50 %, seed 10: the top
pixel holds 1.4 noise maxima at the leg's slice, but the window's mean with the top's 0.05
fell below ``tau``). On procedural seeds 0-19 and the built-ins with the room's seeds 3-15:
3 of 171 measurements better (room seeds 3 / 10 / 15: 0.027 / 0.034 / 0.030 -> 0.011 / 0.023
/ 0.015 m), none worse; held out, procedural seeds 100-149 at m_n 1-10: 9 of 280 better (to
0.95), none worse.

Where a walk stops, it may go on through a *stretch* of weak pixels
(:func:`spslidar.depth.walk._stretch`): the pixels from the stop along the line, behind it, up to
``STRETCH_REACH`` (16) of them and never through the line's own pixels or a surface at its
depth, as far as the summed evidence at the line's slice less ``STRETCH_LEVEL`` (0.5 noise
maxima) a pixel is largest (a one-sided CUSUM: the most likely end of a line whose pixels hold
more than the level and whose continuation holds less). The stretch is taken where that sum
reaches ``STRETCH_TOTAL`` (3), its mean evidence reaches the walk's least (0.3 of the
structure's median: a strong pole's bleed is refused) and it stands ``STRETCH_CONTRAST``
(0.3) above its sides on average; the walk then goes on beyond it. It is what a window of
three cannot do: along the held-out room's lamp pole (m_n = 5, 50 %, seed 9) the evidence at
the pole's slice is 0.55-0.9 noise maxima on six rows in a row and 0.9-2.3 on the nine
above them, so every window of three fails at the first of them. Chosen on procedural seeds
0-19 and the built-ins with the room's seeds 3-15 (level 0.4-0.9 and total 1-5 tried,
before the mean's test against the walk's least: a total of 1-1.5 took a strong pole's bleed
on seed 17 and a motorcycle edge, a level of 0.4 with a total of 2 the motorcycle at
m_n = 1; 0.5 and 3 has safe settings on every side):
there 10 of 171 measurements better (room seeds 5 / 9: 0.030 / 0.066 -> 0.0065 / 0.045 m),
none worse; held out, procedural seeds 100-149 at m_n 1-10: 38 of 280 better (to 0.69 of
before: seed 103 at m_n = 1, 25 %, 0.186 -> 0.129 m), none worse.

The walk's thresholds were chosen on procedural seeds 0-19 and the built-in scenes
(``relative`` 0.2-0.4 gave the same; without it one pixel past a strong pole cost seed 17 a
factor 4.4; a centred window beat one looking only ahead, mean ratio to the MRF 0.961 against
0.966 on the seeds and 0.841 against 0.858 on the built-ins, the same worst case). Filling
every gap between a line's own pieces the way the walk goes past its ends was tried and left
out: on a shallow slanted wire the rounded line misses the wire's rasterised pixels and takes
the wall beside them (seeds 3 and 6, m_n = 5, 50 %: 5-7 % worse); hence a gap is taken only
where the line is straight and at one depth through it.

Chosen on the procedural scenes of seeds 0-19 (64x64, m_n 5 and 10, 25 % and 50 %
patterns; ``benchmarks/depth_quality.py``) among minimum sizes 3-6, elongations 2.5-3.5,
evidence totals 0-12 ``nu`` and reaches of 1-2 pixels, as the setting that never made a
scene of those seeds or of the built-in scenes more than 1 % worse than the MRF alone (the
numbers it gives on held-out seeds are in the README). The fourth pass (reach 3, 6 pixels)
and structures of 3 pixels for :func:`track_lines` came later, after held-out seed 101's
shallow wire (so that case is not held out from them): on seeds 0-19 the worst is 1.6 %
worse than before, on the built-ins one measurement 3 % (the motorcycle at m_n = 10, 50 %,
seed 0: one mixed pixel at a depth edge), elongation 2.9 instead of 3.5 changed nothing.
A short structure along a row or a column (its ends less than ``SNAP_EXTENT`` pixels
apart, its slices within one of their median) is walked twice, along its fitted line and at
its median slice, and the walk that takes more pixels is kept: three pixels of the room's
lamp pole labelled 149 / 149 / 150 (a sub-bin delay rounded either way) fit a slope that
leaves the pole's slice by ten slices within twenty rows, while a slanted wire's short piece
fits the same labels, so the data choose (2026-11-27, room at m_n = 5, 50 %, seeds 16-31:
seeds 20 / 21 / 28, 0.043 / 0.034 / 0.048 -> 0.032 / 0.029 / 0.032 m; procedural 0-19 and the
built-ins 3 of 150 better, none worse by more than 2 %; held out, procedural 100-149 at m_n
1-10, 8 of 280 better, none worse; fresh room seeds 32-47, 2 better, none worse. Walked at
the median slice alone, procedural seed 113's slanted wire was lost: 0.096 -> 0.125 m).
Two rules for a straight structure, chosen on the room at m_n = 5, 50 %, seeds 32-47
(2026-11-27). A group that fails the line tests, whose pixels within one slice of its median
lie on one row or one column, keeps those pixels (:func:`_straight_inliers`; a leg argmax
finds at one slice on five rows of six, the sixth five slices off) unless the labelling
holds that depth beside them on half their length (the bleed of a pole it holds: procedural
seed 107). And where a straight walk's short bridge and its stretch both fail, a bridge of up
to ``BRIDGE_LONG`` (12) pixels to a surface at its depth is taken where it stands
``STRETCH_CONTRAST`` above its sides on average (a leg under its table top whose top seven
rows the TV left at 0.6-1.1 noise maxima); tried first, before the stretch, it cut a fence
slat's walk short (procedural seed 103). Seeds 37 / 40: 0.069 / 0.060 -> 0.004 / 0.026 m,
13 of 16 seeds at 0.03 m or below against 11; held out, room seeds 0-31 and 48-63 unchanged
(one 0.09 % worse), procedural seeds 100-149 at m_n 5 and 10 6 of 200 measurements better (to
0.92) and none worse, at m_n 1-2 (seeds 100-119) 1 of 80 better, the camera's 36 and the
motorcycle's unchanged. A bridge ends the walk, unless what it reached is two pixels of the
line itself, one pixel wide, which a table top is not (room seed 153 at m_n = 5, 50 %: the
lamp pole's walk bridged four weak rows to a two-row piece of the pole and stopped, leaving
its 14 rows above to the wall, 0.050 -> 0.017 m; on the room's seeds 32-159 one other
pixel, seed 127 0.0047 -> 0.0046 m; procedural seeds 0-19 and 100-149, the camera, the
motorcycle and Fig. 3 unchanged; held out, room seeds 160-175 unchanged).
The connected groups are
SciPy's (:func:`scipy.sparse.csgraph.connected_components`); the line test is a few lines
of NumPy per group, written here because no library tests a pixel group's shape and depth
together.
"""

from __future__ import annotations

import numpy as np

from .walk import (  # noqa: F401 (the walk's constants, read here by their old names too)
    BRIDGE_BEHIND,
    BRIDGE_LONG,
    BRIDGE_REACH,
    STRETCH_CONTRAST,
    STRETCH_LEVEL,
    STRETCH_REACH,
    STRETCH_TOTAL,
    _walk,
)

__all__ = ["extend_lines", "one_pixel_wide", "thin_structures", "track_lines"]


#: defaults of :func:`thin_structures` (see the module docstring for how they were chosen)
GAP, FLOOR, ELONGATION, RESIDUAL = 3, 0.8, 3.5, 2.0
#: :func:`extend_lines`: a candidate's largest distance from its group's axis, in pixels (a
#: rasterised line's pixels lie within 0.5 of it; a diagonal line's side neighbour is 0.71 away)
AXIS = 0.6
#: a group whose depths are not all linear keeps the Theil-Sen line's inliers where they are
#: at least this share of it (None: the group is refused). 0.9 changed nothing on procedural
#: seeds 0-19 and the built-in scenes (0.8 made three of them 1-4 % worse); it keeps a dark
#: pole of held-out seed 109 (m_n = 1, 50 %) whose one wrong argmax of 13 refused it
ROBUST = 0.9
#: :func:`extend_lines`: a group that fails ``ROBUST`` keeps its candidates on the Theil-Sen
#: line where ``ROBUST`` of its candidates and this share of all its members lie on it
#: (:func:`_extension_inliers`; None: it does not)
EXTEND_SHARE = 0.7
#: :func:`track_lines`: the window, its mean and a pixel's own least evidence (in ``nu``);
#: ``BACK`` of the window's pixels lie behind the pixel tested (1: the window is centred)
WINDOW, TAU, LO = 3, 0.9, 0.5
#: :func:`track_lines`: a taken pixel's least evidence relative to the structure's median (the
#: bleed beyond a strong pole's end is 0.1-0.2 of the pole's evidence, a weak pole's own
#: missed pixels 0.4-0.7)
RELATIVE = 0.3
BACK = 1
#: :func:`track_lines`: a taken pixel's least excess of evidence over the mean of its two
#: pixels beside the line (a line stands above its sides, a blob of bleed does not: held-out
#: seed 117, m_n = 1, 50 %, lost 2.5 m on one pixel without it; 0.1 costs the built-in
#: scenes' mean ratio to the old MRF 0.842 -> 0.846, 0.2 -> 0.870)
CONTRAST = 0.1
#: the joining passes: (step in slices, reach in pixels, minimum pixels, evidence total in nu);
#: the last joins pixels three apart: a shallow slanted wire whose depth changes by 4 slices a
#: pixel, found by argmax on one pixel in two or three (held-out seed 101, m_n = 10, 50 %:
#: 18 % worse than argmax without it, 6 % better with it)
PASSES = ((2, 1, 3, 5.0), (16, 1, 3, 5.0), (16, 2, 4, 12.0), (16, 3, 6, 12.0))
#: :func:`track_lines`: the fewest one-pixel-wide labelled pixels that make a structure to
#: follow (3: the room's table legs, labelled on 3 rows, at m_n = 1, 25 %: 0.065 -> 0.046 m)
TRACK_MIN = 3
#: :func:`track_lines`: a structure along a row or a column whose ends lie fewer than this
#: many pixels apart, its slices within one of their median, is also walked at that one
#: slice, and the walk that takes more pixels is kept (a pole's piece of three, labelled
#: 149 / 149 / 150, fits a slope that leaves the pole's slice by 10 slices within 20 rows; a
#: slanted wire's short piece fits the same labels, so the data, not the fit, choose)
SNAP_EXTENT = 6
#: the fewest pixels of a straight one-depth structure kept out of a group that fails the
#: line tests (:func:`_straight_inliers`)
STRAIGHT_MIN = 4


def _groups(cand: np.ndarray, a: np.ndarray, shape: tuple[int, int], step: int,
            reach: int = 1, diagonals: bool = True) -> tuple[np.ndarray, np.ndarray, int]:
    """Candidates (flat indices), their group labels and the number of groups: candidates up
    to ``reach`` pixels apart (in x and in y; along a row or a column only without
    ``diagonals``) joined where their argmax slices differ by at most ``step``."""
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
            if (dy > 0 or dx > 0) and (diagonals or dy == 0 or dx == 0)]  # each pair once
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
                    robust: float | None = ROBUST,
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
    robust : float or None
        A group whose depths are not all on a line keeps the members within ``residual``
        slices of its Theil-Sen line where at least this share of them are (default
        ``ROBUST``, 0.9); None: such a group is dropped whole.

    Returns
    -------
    ndarray of bool, shape (Q,)
        True where the argmax is to be kept.
    """
    a = np.asarray(a)
    if nu <= 0 or a.size == 0:
        return np.zeros(a.size, dtype=bool)
    z = np.asarray(strength, dtype=np.float64) / nu
    cand = (a < np.asarray(label) - gap) & (z >= floor)
    return _line_keep(cand, a, z, shape, elongation, residual, passes, None, robust,
                      np.asarray(label).reshape(shape))


def one_pixel_wide(label: np.ndarray, shape: tuple[int, int], gap: int = GAP) -> np.ndarray:
    """Pixels of a labelling more than ``gap`` slices in front of both their neighbours along
    one of the four axes (a row, a column, a diagonal): one pixel wide, a pole's or a wire's."""
    n1, n2 = shape
    padded = np.pad(np.asarray(label).reshape(shape).astype(np.int64), 1, mode="edge")
    centre = padded[1:-1, 1:-1]
    out = np.zeros(shape, dtype=bool)
    for (ay, ax), (by, bx) in (((0, 1), (2, 1)), ((1, 0), (1, 2)), ((0, 0), (2, 2)),
                               ((0, 2), (2, 0))):
        out |= ((centre < padded[ay:ay + n1, ax:ax + n2] - gap)
                & (centre < padded[by:by + n1, bx:bx + n2] - gap))
    return out.ravel()


def extend_lines(a: np.ndarray, label: np.ndarray, strength: np.ndarray,
                 label_strength: np.ndarray, nu: float, shape: tuple[int, int], *,
                 gap: int = GAP, floor: float = FLOOR, elongation: float = ELONGATION,
                 residual: float = RESIDUAL, axis: float = AXIS,
                 robust: float | None = ROBUST,
                 passes: tuple[tuple[int, int, int, float], ...] = PASSES) -> np.ndarray:
    """Pixels whose argmax continues a one-pixel structure the labelling already holds.

    Parameters
    ----------
    a, label, strength, nu, shape, gap, floor, elongation, residual, robust, passes
        As :func:`thin_structures` (``label`` the labelling to continue: the MRF's with the
        thin structures already kept).
    label_strength : ndarray, shape (Q,)
        The evidence at ``label`` (the anchors' share of a group's evidence total).
    axis : float
        A kept candidate's largest distance from its group's axis, in pixels.

    Returns
    -------
    ndarray of bool, shape (Q,)
        True where the argmax is to be kept (candidates only, never an anchor).
    """
    a = np.asarray(a)
    label = np.asarray(label)
    if nu <= 0 or a.size == 0:
        return np.zeros(a.size, dtype=bool)
    z = np.asarray(strength, dtype=np.float64) / nu
    cand = (a < label - gap) & (z >= floor)
    anchor = one_pixel_wide(label, shape, gap) & ~cand
    if not (cand.any() and anchor.any()):
        return np.zeros(a.size, dtype=bool)
    zl = np.asarray(label_strength, dtype=np.float64) / nu
    return _line_keep(cand | anchor, np.where(anchor, label, a), np.where(anchor, zl, z),
                      shape, elongation, residual, passes, (cand, axis), robust)


def _line_keep(member: np.ndarray, lag: np.ndarray, z: np.ndarray, shape: tuple[int, int],
               elongation: float, residual: float,
               passes: tuple[tuple[int, int, int, float], ...],
               extend: tuple[np.ndarray, float] | None, robust: float | None,
               beside: np.ndarray | None = None) -> np.ndarray:
    """The passes and tests of the module docstring over the pixels ``member`` at slices
    ``lag`` with evidence ``z`` (in ``nu``); with ``robust`` a group whose depths are not all
    linear keeps the inliers of a robust line (:func:`_theil_inliers`); with
    ``extend = (cand, axis)`` only groups holding
    a candidate count, and only their candidates within ``axis`` of the group's line are
    kept."""
    keep = np.zeros(member.size, dtype=bool)
    n2 = shape[1]
    for step, reach, min_pixels, total in passes:
        if member.sum() < min_pixels:
            continue
        pix, groups, n = _groups(member, lag, shape, step, reach)
        ok = np.bincount(groups, minlength=n) >= min_pixels
        ok &= np.bincount(groups, weights=z[pix], minlength=n) >= total
        if extend is not None:
            ok &= np.bincount(groups, weights=extend[0][pix], minlength=n) > 0
        for g in np.flatnonzero(ok):
            members = pix[groups == g]
            yx = np.stack(np.divmod(members, n2), axis=1).astype(np.float64)
            var, vec = np.linalg.eigh(np.cov(yx.T) + np.eye(2) / 12.0)  # a pixel's own spread
            if var[1] < elongation ** 2 * var[0]:
                continue
            centred = yx - yx.mean(axis=0)
            t = centred @ vec[:, 1]
            depth = lag[members].astype(np.float64)
            fit = np.polyval(np.polyfit(t, depth, 1), t)
            inlier = np.abs(fit - depth) <= residual
            if not inlier.all():
                if robust is None:
                    continue
                line = _theil_inliers(t, depth, residual)
                inlier = line if line.mean() >= robust else np.zeros_like(line)
                if extend is not None and not inlier.any() and EXTEND_SHARE is not None:
                    inlier = _extension_inliers(line, robust, extend[0][members])
                if inlier.sum() < min_pixels:
                    if beside is None:
                        continue
                    inlier = _straight_inliers(yx, depth, beside)
                    if inlier.sum() < max(min_pixels, STRAIGHT_MIN):
                        continue
            if extend is None:
                keep[members[inlier]] = True
            else:
                near = np.abs(centred @ vec[:, 0]) <= extend[1]
                keep[members[inlier & near & extend[0][members]]] = True
    return keep


def _straight_inliers(yx: np.ndarray, depth: np.ndarray, label: np.ndarray) -> np.ndarray:
    """Members within one slice of the group's median slice, where they all lie on one row
    or one column (a pole or a leg at one depth, with a few of its pixels' argmax elsewhere)
    and the labelling ``label`` (2-D) does not hold that depth beside them on half their
    length (then they are the bleed of a line it holds: procedural seed 107); otherwise
    none."""
    none = np.zeros(depth.size, dtype=bool)
    level = np.median(depth)
    inlier = np.abs(depth - level) <= 1.0
    on = yx[inlier].astype(np.int64)
    minor = 1 if on.size and np.ptp(on[:, 1]) == 0 else 0
    if not on.size or np.ptp(on[:, minor]) != 0:
        return none
    for off in (-1, 1):
        across = on.copy()
        across[:, minor] += off
        ok = (across[:, minor] >= 0) & (across[:, minor] < label.shape[minor])
        held = np.abs(label[across[ok, 0], across[ok, 1]] - level) <= GAP
        if held.sum() >= 0.5 * len(on):
            return none
    return inlier


def _extension_inliers(line: np.ndarray, share: float, cand: np.ndarray) -> np.ndarray:
    """The members on a group's Theil-Sen line (``line``: :func:`_theil_inliers`) where
    ``share`` of its candidates and :data:`EXTEND_SHARE` of all its members are, or none:
    the anchors are pixels the labelling already holds as a one-pixel structure, and a run
    of them a few slices off (a table leg the MRF labelled 8 slices nearer on two rows of
    nine, held out room seed 287, m_n = 5, 50 %) does not make the candidates that continue
    it on its line noise."""
    if line[cand].mean() >= share and line.mean() >= EXTEND_SHARE:
        return line
    return np.zeros_like(line)


def _theil_inliers(t: np.ndarray, depth: np.ndarray, residual: float) -> np.ndarray:
    """Members within ``residual`` slices of the Theil-Sen line through a group's depths
    (:func:`scipy.stats.theilslopes`: one wrong argmax of a dozen does not move it); a group
    keeps them where ``ROBUST`` of it are (:func:`_line_keep`)."""
    from scipy.stats import theilslopes

    slope, intercept = theilslopes(depth, t)[:2]
    return np.abs(intercept + slope * t - depth) <= residual


def track_lines(z: np.ndarray, label: np.ndarray, nu: float, shape: tuple[int, int], *,
                gap: int = GAP, window: int = WINDOW, tau: float = TAU, lo: float = LO,
                relative: float = RELATIVE, back: int = BACK, contrast: float = CONTRAST,
                min_pixels: int = TRACK_MIN,
                elongation: float = ELONGATION, residual: float = RESIDUAL,
                within: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Continue each one-pixel structure of a labelling beyond its ends, pixel by pixel along
    its axis, where the evidence at the structure's own slice holds (module docstring).

    Parameters
    ----------
    z : ndarray, shape (Q, K)
        Evidence per pixel and slice (the MRF's data term).
    label : ndarray of int, shape (Q,)
        The labelling to continue.
    nu : float
        The block's typical noise maximum.
    shape : (int, int)
        The image grid.
    gap, window, tau, lo, relative, back, contrast, min_pixels, elongation, residual
        A structure is ``min_pixels`` or more one-pixel-wide pixels (:func:`one_pixel_wide`)
        joined as 8-neighbours within 2 (then 16) slices, ``elongation`` times longer than
        wide, its slice linear along it within ``residual``; a next pixel is taken while it
        is labelled more than ``gap`` slices behind the line, its evidence at the line's
        slice (+-1) reaches ``lo`` and ``relative`` times the structure's median evidence
        and exceeds the mean of its two pixels beside the line by ``contrast``, and the mean
        over ``window`` pixels, ``back`` of them before it, reaches ``tau`` (in ``nu``; a
        pixel that a surface nearer than the line hides is left out of the window); one
        pixel failing these is stepped over where the line's pixels hold the next two (and
        taken where the line is straight and at one depth through it). A straight line's
        pieces are also joined up to two pixels apart, the single pixels between them taken,
        and its walk bridges up to ``BRIDGE_REACH`` pixels to a surface at its depth. Where
        a walk stops, a stretch whose summed evidence holds (:mod:`spslidar.depth.walk`) is
        taken and the walk goes on beyond it.
    within : ndarray of bool, shape (Q,), optional
        Walk only the structures that hold at least one of these pixels (the MRF: the lines
        :func:`~spslidar.depth.hang.hang_lines` took).

    Returns
    -------
    label : ndarray of int, shape (Q,)
        The labelling with the structures continued.
    added : int
        Pixels relabelled.
    """
    q, k = z.shape
    label = np.array(label, dtype=np.int64, copy=True)
    anchor = one_pixel_wide(label, shape, gap)
    if nu <= 0 or anchor.sum() < min_pixels or k < 3:
        return label, 0
    n2 = shape[1]
    zn = z / nu
    done = np.zeros(q, dtype=bool)
    added = 0
    # 8-neighbours at one depth, then along a slanted line, then a row's or a column's
    # pieces up to two pixels apart at one depth (a leg the MRF holds on every other row)
    for step, reach in ((2, 1), (16, 1), (2, 2)):
        pix, groups, n = _groups(anchor & ~done, label, shape, step, reach)
        for g in range(n):
            members = pix[groups == g]
            if members.size < min_pixels or (within is not None and not within[members].any()):
                continue
            yx = np.stack(np.divmod(members, n2), axis=1).astype(np.float64)
            if reach > 1 and np.ptp(yx[:, 0]) > 0 and np.ptp(yx[:, 1]) > 0:
                continue  # pieces joined across gaps: a row or a column only
            var, vec = np.linalg.eigh(np.cov(yx.T) + np.eye(2) / 12.0)
            if var[1] < elongation ** 2 * var[0]:
                continue
            centre, v = yx.mean(axis=0), vec[:, 1]
            t = (yx - centre) @ v
            coef = np.polyfit(t, label[members].astype(np.float64), 1)
            if np.abs(np.polyval(coef, t) - label[members]).max() > residual:
                continue
            done[members] = True
            least = max(lo, relative * float(np.median(zn[members, label[members]])))
            # a short piece along a row or a column at one slice, give or take one, is also
            # walked at its median slice; the walk that takes more pixels is kept (the fit
            # first, so a tie keeps the fit)
            level = float(np.median(label[members]))
            lines_ = [coef]
            if (np.ptp(t) < SNAP_EXTENT and (np.ptp(yx[:, 0]) == 0 or np.ptp(yx[:, 1]) == 0)
                    and np.abs(label[members] - level).max() <= 1):
                lines_.append(np.array([0.0, level]))
            best, best_n = label, -1
            for line in lines_:
                trial = label.copy() if len(lines_) > 1 else label
                n = _walk(zn, trial, anchor, shape, centre, v, line, t, gap, window, tau, least,
                          back, contrast, interior=reach > 1)
                if n > best_n:
                    best, best_n = trial, n
            if best is not label:
                label[:] = best
            added += best_n
    return label, added
