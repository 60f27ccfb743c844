"""Lines that hang from the end of a surface at its depth, where the labelling holds none of
them: a table leg under its top's corner (the MRF's line stage, after
:mod:`spslidar.depth.lines`).

A leg the labelling holds on none of its rows, or on pieces too short to walk
(:func:`~spslidar.depth.lines.track_lines` needs three), has no anchor for the line stage; its
table top is one. :func:`hang_lines` reads, from each pixel that ends its surface (a pixel
beside it, across the direction, is not at its slice) and has a neighbour labelled more than
``BRIDGE_BEHIND`` slices behind, the pixels beyond at that slice, and takes them as a stretch
(``_stretch`` of :mod:`spslidar.depth.lines`: summed evidence less 0.5 noise maxima a pixel
reaching 3, 0.3 above their sides on average) where their evidence there is also at least
``HANG_OWN`` (0.8) of what they hold at their own labels and the run is not along the image's
border. The first test is what a strong surface's sidelobe fails. The camera's steep edges
hold about 1 noise maximum at the nearer surface's slice over returns of several (with no
such test the camera at m_n = 10, 25 % went 0.0049 -> 0.0175 m). A random Bernoulli code's
correlation sidelobes hold 6-9 noise maxima at a nearer surface's slice over returns of 9-14
(the paper's Fig. 3 as `spslidar reproduce fig3` runs it: the camera with 2048-bit codes of
ones ratio 0.1 and 0.3 at m_n = 1 went 0.131 / 0.116 -> 0.239 / 0.192 m at 0.5, and is 0.130
/ 0.114 m at 0.8). The second test keeps out runs with one side to compare with (held-out
procedural seed 135 at m_n = 10, 25 % lost 16 % on a run along its top row).

Chosen on 2026-11-27 (FISTA's 0.45 weight) on the room at m_n = 5, 50 %, seeds 32-63 (seeds
32-47 13 -> 15 of 16 at 0.03 m, mean 0.027 -> 0.019 m; 48-63 11 of 16 before and after, mean
0.030 -> 0.025 m, seeds 58 / 59 0.078 / 0.086 -> 0.034 / 0.048 m), procedural seeds 0-19, the
built-in scenes and Fig. 3's two cases (12 of 107 measurements better, none worse);
``HANG_OWN`` among 0.5, 0.8 and 1.0 after Fig. 3 showed the sidelobes (1.0 lost seeds 73
and 75 of the room set below, so that set is not fully held out from this one number).
Held out: fresh room seeds 64-79 13 -> 15 of 16 at 0.03 m (mean 0.022 ->
0.014 m, worst 0.076 -> 0.043 m), room seeds 0-31 unchanged, procedural seeds 100-149 at m_n
5 and 10 and 100-119 at m_n 1 and 2 41 of 280 measurements better (to 0.47) and one worse by
4.3 % (seed 149 at m_n = 5, 25 %), the camera's 36 measurements (seeds 0-5) and the
motorcycle's unchanged.

A pixel of the line that the labelling already holds (at its slice, one pixel wide: both
pixels beside it elsewhere) does not end the stretch, which goes on through it. On the room
at m_n = 5, 50 %, seed 140 a table leg's one labelled row ended it 0.05 noise maxima short of
``STRETCH_TOTAL``, and the leg's 13 rows above it kept the floor and the wall (RMSE 0.067 ->
0.0049 m). Measured on 2026-11-27 against ending there: the room's seeds 32-63 and 80-143
(96 measurements) 8 better (to 0.07 of before), none worse, 76 -> 79 at 0.03 m; procedural
seeds 0-19 at m_n 5 and 10, 25 and 50 % 7 better, none worse; the camera and the motorcycle
at m_n = 10 (seeds 0-2) unchanged within 0.2 %; Fig. 3 0.1301 / 0.1143 -> 0.1301 / 0.1142 m.
Held out: procedural seeds 100-149 at m_n 5 and 10 and 100-119 at m_n 1 and 2 (280) 33
better (to 0.68), none worse; fresh room seeds 144-159 unchanged.
"""

from __future__ import annotations

import numpy as np

from .lines import GAP, LO
from .walk import BRIDGE_BEHIND, STRETCH_LEVEL, STRETCH_REACH, STRETCH_TOTAL, _across, _stretch

__all__ = ["HANG_FILL", "HANG_OWN", "hang_lines", "walk_on"]

#: a hanging line's least evidence relative to what its pixels hold at their own labels (a
#: weak or wrong label, not a strong surface's sidelobe)
HANG_OWN = 0.8
#: :func:`walk_on`: a pixel whose own label holds less than this share of the most a
#: 4-neighbour holds at that label is the TV's fill behind a line, not that surface
HANG_FILL = 0.5


def hang_lines(z: np.ndarray, label: np.ndarray, nu: float, shape: tuple[int, int], *,
               least: float = LO) -> tuple[np.ndarray, int]:
    """Lines that hang from the end of a surface at its depth where the labelling holds none
    of the line (module docstring).

    From each labelled pixel ``p`` whose neighbour in a direction ``d`` is labelled more than
    ``BRIDGE_BEHIND`` slices behind it, and which ends its surface across ``d`` (a pixel
    beside it in the image, across ``d``, is not at its slice), the pixels ``p + d,
    p + 2d, ...`` are read at ``p``'s slice (+-1) and taken as a stretch
    (``_stretch`` of :mod:`spslidar.depth.lines`: summed evidence less ``STRETCH_LEVEL`` a pixel
    reaching ``STRETCH_TOTAL``, ``STRETCH_CONTRAST`` above their sides on average, mean
    evidence ``least``, all in ``nu``) where their mean evidence there is at least
    ``HANG_OWN`` of their mean at their own labels.

    Parameters
    ----------
    z : ndarray, shape (Q, K)
        Evidence per pixel and slice (the MRF's data term).
    label : ndarray of int, shape (Q,)
        The labelling.
    nu : float
        The block's typical noise maximum.
    shape : (int, int)
        The image grid.
    least : float
        A taken run's least mean evidence (in ``nu``).

    Returns
    -------
    label : ndarray of int, shape (Q,)
        The labelling with the lines taken.
    added : int
        Pixels relabelled.
    """
    n1, n2 = shape
    k = z.shape[1]
    out = np.array(label, dtype=np.int64, copy=True)
    if nu <= 0 or k < 3:
        return out, 0
    lab = out.reshape(shape)
    reach = np.arange(1, STRETCH_REACH + 1)
    added = 0
    for dy, dx in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        ys, xs = np.nonzero(lab >= 0)
        ny, nx = ys + dy, xs + dx
        ok = (ny >= 0) & (ny < n1) & (nx >= 0) & (nx < n2)
        ys, xs, ny, nx = ys[ok], xs[ok], ny[ok], nx[ok]
        s = lab[ys, xs]
        ok = (lab[ny, nx] > s + BRIDGE_BEHIND) & (s >= 1) & (s < k - 1)
        # a run along the image's border has one side to compare with: none is tried
        ok &= (ys > 0) & (ys < n1 - 1) if dx else (xs > 0) & (xs < n2 - 1)
        ends = np.zeros(ok.shape, dtype=bool)
        for off in (-1, 1):  # across d: a pixel beside p, in the image, not at its slice
            by, bx = ys + off * dx, xs + off * dy
            in_img = (by >= 0) & (by < n1) & (bx >= 0) & (bx < n2)
            by, bx = np.clip(by, 0, n1 - 1), np.clip(bx, 0, n2 - 1)
            ends |= in_img & (np.abs(lab[by, bx] - s) > GAP)
        major = 0 if dy else 1  # the run's axis, for the pixels beside it (_across)
        ys, xs, s = ys[ok & ends], xs[ok & ends], s[ok & ends]
        keep = _may_stretch(z, ys, xs, s, (dy, dx), nu, shape)
        for y0, x0, s0 in zip(ys[keep], xs[keep], s[keep], strict=True):
            ry, rx = y0 + reach * dy, x0 + reach * dx
            inside = (ry >= 0) & (ry < n1) & (rx >= 0) & (rx < n2)  # a prefix of the run
            ry, rx = ry[inside], rx[inside]
            if not ry.size:
                continue
            flat = ry * n2 + rx
            near = s0 + np.arange(-1, 2)
            e = z[flat[:, None], near].max(axis=1) / nu
            along, across = (ry, rx) if major == 0 else (rx, ry)
            side, count = np.zeros_like(e), np.zeros_like(e)
            # a piece of the line that the labelling holds (at its slice, one pixel wide) is
            # passed through, not an end (room seed 140: a leg's one labelled row stopped the
            # stretch 0.05 noise maxima short of STRETCH_TOTAL)
            piece = np.abs(lab[ry, rx] - s0) <= 1
            for off in (-1, 1):  # the pixels beside the run that lie in the image
                idx, in_img = _across(np.ones(ry.size, dtype=bool), along, across, major,
                                      shape, off)
                side += in_img * (z[idx[:, None], near].max(axis=1) / nu)
                count += in_img
                piece &= ~in_img | (np.abs(out[idx] - s0) > GAP)
            side /= count
            behind = lab[ry, rx] > s0 + BRIDGE_BEHIND
            got = _stretch(0, 1, behind | piece, e, side, least)
            own = z[flat[got], lab[ry[got], rx[got]]] / nu  # the run's own labels' evidence
            if got and np.mean(e[got]) < HANG_OWN * np.mean(own):
                continue
            got = [i for i in got if behind[i]]  # a piece keeps its label
            for i in got:
                lab[ry[i], rx[i]] = s0 - 1 + int(np.argmax(z[flat[i], near]))
            added += len(got)
    return out, added


def _may_stretch(z: np.ndarray, ys: np.ndarray, xs: np.ndarray, s: np.ndarray,
                 d: tuple[int, int], nu: float, shape: tuple[int, int],
                 chunk: int = 16_384) -> np.ndarray:
    """Which anchors' runs can hold a stretch at all: the largest prefix sum of ``e -
    STRETCH_LEVEL`` over the run's pixels inside the image reaches ``STRETCH_TOTAL``.

    ``_stretch`` sums the same values from the run's first pixel and stops earlier where a
    pixel is not behind the line, so its largest sum is at most this one: an anchor that
    fails here is one :func:`hang_lines` would reject whatever the labelling, and dropping it
    before the loop changes nothing (the same floats in the same order; tested bit for bit
    against the loop alone). On a labelling of pure noise the loop went through every anchor
    in Python (7.8 s at 256x256, 2026-11-27); the anchors are now tested together, in chunks
    of ``chunk`` (16 x 3 evidence values each)."""
    n1, n2 = shape
    dy, dx = d
    reach = np.arange(1, STRETCH_REACH + 1)
    keep = np.zeros(ys.size, dtype=bool)
    for lo in range(0, ys.size, chunk):
        y0, x0, s0 = ys[lo:lo + chunk, None], xs[lo:lo + chunk, None], s[lo:lo + chunk, None]
        ry, rx = y0 + reach * dy, x0 + reach * dx
        inside = (ry >= 0) & (ry < n1) & (rx >= 0) & (rx < n2)
        flat = np.clip(ry, 0, n1 - 1) * n2 + np.clip(rx, 0, n2 - 1)
        e = np.maximum(np.maximum(z[flat, s0 - 1], z[flat, s0]), z[flat, s0 + 1]) / nu
        # (a NaN holds the loop's sum at NaN from there on, which never counts: the prefix
        # before it is what can)
        inside &= np.cumsum(np.isnan(e), axis=1) == 0
        total = np.cumsum(np.where(inside, e - STRETCH_LEVEL, 0.0), axis=1)
        total[~inside] = -np.inf  # (inside is a prefix of each run)
        keep[lo:lo + chunk] = total.max(axis=1, initial=-np.inf) >= STRETCH_TOTAL
    return keep


def walk_on(z: np.ndarray, label: np.ndarray, walked: np.ndarray, nu: float,
            shape: tuple[int, int], *, own: float = HANG_OWN, fill: float = HANG_FILL,
            least: float = LO) -> np.ndarray:
    """Which pixels of a walk on from a hung line (``walked``, the MRF's second
    :func:`~spslidar.depth.lines.track_lines` over the lines :func:`hang_lines` took) to keep.

    A pixel is kept where its evidence at the walk's label is at least ``own`` (``HANG_OWN``)
    of its evidence at its own label: a random code's correlation sidelobes hold 6-9 noise
    maxima at a nearer surface's slice over returns of 9-14 (module docstring; unguarded, the
    paper's Fig. 3 went 0.130 / 0.114 -> 0.131 / 0.118 m). It is also kept where its own
    label holds under ``fill`` (``HANG_FILL``, 0.5) of the most any 4-neighbour holds at that
    label, and its evidence at the walk's label reaches ``least`` (``LO``) noise maxima: such
    a label is the per-slice TV's fill of the surface behind a line, not that surface's
    return, and no test against it means anything. On the room at m_n = 5, 50 %, seed 110
    the lamp pole's upper rows held 1.0-2.0 noise maxima at its slice against 1.9-2.8 at the
    wall's, whose pixels beside it held 10: 0.038 -> 0.0057 m (seed 146 0.041 -> 0.027 m).

    Parameters
    ----------
    z : ndarray, shape (Q, K)
        Evidence per pixel and slice.
    label, walked : ndarray of int, shape (Q,)
        The labelling before the walk on, and after it.
    nu : float
        The block's typical noise maximum.
    shape : (int, int)
        The image grid.
    own, fill, least : float
        :data:`HANG_OWN`, :data:`HANG_FILL` and ``spslidar.depth.lines.LO`` (the tests above).

    Returns
    -------
    ndarray of bool, shape (Q,)
        The walked pixels to keep (False where the walk left a pixel's label).
    """
    q = z.shape[0]
    rows = np.arange(q)
    label = np.asarray(label)
    walked = np.asarray(walked)
    at_own = z[rows, label]
    at_walk = z[rows, walked]
    n1, n2 = shape
    lab = label.reshape(shape)
    z3 = z.reshape(n1, n2, -1)
    beside = np.zeros(shape, dtype=np.float64)
    ys, xs = np.arange(n1)[:, None], np.arange(n2)[None, :]
    for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):  # the image's edge repeats itself
        ny, nx = np.clip(ys + dy, 0, n1 - 1), np.clip(xs + dx, 0, n2 - 1)
        np.maximum(beside, z3[ny, nx, lab], out=beside)
    filled = (at_own < fill * beside.ravel()) & (at_walk >= least * nu)
    return (walked != label) & ((at_walk >= own * at_own) | filled)
