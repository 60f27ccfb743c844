"""A front region's rim that the per-slice TV wore away, given back where the evidence, read
relative to each surface's own level nearby, holds it (the MRF's last step).

Each range slice is solved on its own with a TV prior (eq. 18). In a dark region's slice the
TV lowers the region's rim, and in the slice of a bright surface behind it the TV spreads
that surface into the rim. Read as they stand, the rim's evidence for the surface behind
(its spread) beats the dark region's own (its worn rim), and the MRF gives the rim the
surface behind. Measured on the room at m_n = 5, 50 % patterns: seed 230, the dark shelf's
top row (columns 50-53) reads 0.25-0.76 noise maxima at the shelf's slice, where the shelf
holds 1.3 nearby, and 0.45-1.2 at the wall's, where the wall holds 6-10; seed 233, a 3 x 3
block at the shelf's top-right corner reads 0.5-1.4 at the shelf's slice and 0.8-1.3 at the
wall's. Relative to each surface's level the shelf holds 3-10 times more. The corner step
(:mod:`.corner`) gives back a notch one pixel at a time from its two neighbours' levels; a
rim worn along an edge, or a block whose neighbours are as weak as itself, is no notch.

:func:`fill_edges` tests each pixel labelled ``a`` beside a 4-neighbour labelled ``b``
nearer by more than :data:`GAP` slices, where

* the pixel holds under :data:`EDGE_OWN` noise maxima at ``a`` (a return standing well above
  the noise is the pixel's own: room seed 3, a floor pixel at 4.4 beside a table leg);
* the region's edge goes on along the pixel's row (beside a region above or below it) or
  column within :data:`ALONG` pixels: a worn stretch of a straight edge or a rounded corner,
  not a surface's own dim rim along a region's whole side (procedural seed 109);
* ``b``'s level, the median over the pixels within :data:`REACH` labelled within ``GAP`` of
  ``b`` (the pixel itself and pixels given back in an earlier pass left out; at least
  :data:`LEVEL_PIXELS` of them) of their evidence at their own label, reaches
  :data:`EDGE_LEVEL` noise maxima (a weaker "region" is noise: procedural seed 4);
* the pixel's evidence at ``b`` (+-1 slice) is at least :data:`EDGE_LEAST` of ``b``'s level
  (a halo holds about a fifth) and more than :data:`EDGE_MARGIN` times its evidence at ``a``
  relative to ``a``'s level, read the same way.

It then takes ``b`` (its tallest slice within one of it). Passes repeat on the labels the
last one left (a rim two or three pixels deep); a pixel given back is not tested again.
Only towards a nearer surface: a front surface's spread into what lies behind it is what
the halo discount (:mod:`.halo`) follows. The rule reads the evidence only; no library
models a per-slice TV's worn rims.

Chosen on 2026-11-28 on the room at m_n = 5, 50 %, fresh seeds 224-239 (where the shelf's
top rims were 3 of the 4 failures), procedural seeds 0-19 (m_n 5 and 10, 25 and 50 %) and
the motorcycle at m_n = 10, 25 %, seeds 0-2, among margins 1.5-3, least shares 0.25-0.4,
levels 0.5-1.25 noise maxima, reaches 2-3 and the edge test off or at 2, 3, 5: against the
labelling without it, 16 of 101 better (with room seeds 3 and 4, which the own-evidence
test came from), none worse (room 224-239 12 -> 14 of 16 at 0.03 m, seed 233 0.055 -> 0.008
m; without the edge test 31 better, 5 worse, and on the held-out
seeds below 38 worse, up to 14 %). Held out (the same day, on the same cached slices): room
seeds 0-223 216 -> 218 of 224 at 0.03 m (18 better, none worse); fresh room seeds 240-255
14 of 16 before and after (1 better); procedural 100-149 (m_n 5, 10) and 100-119 (m_n 1, 2)
28 of 280 better, 7 worse (up to 4.4 %), geometric mean 0.997, the losses to argmax the same
4; fresh procedural 150-174 (100) 3 better, 2 worse (up to 1.6 %); the built-ins (6 scenes
and the fence at m_n 1, 5, 10, 25 %) 3 better, none worse. The paper's Fig. 6 stand-in
without QCR at m_n = 10 loses one pixel of the motorcycle's blended edge to the front: 0.0941
-> 0.1007 m (with QCR, the default, 0.0466 -> 0.0467 m at m_n = 8, the rest unchanged).

A pixel's own level is read within :data:`GAP` of its label; where no surface there gives one
(a label the rim's spread left a few slices off the surface behind, or a steep slanted
surface's), it is read within :data:`OWN_GAP`, and where none gives one there either the
pixel is not tested. Room seed 248 (m_n = 5, 50 %): the shelf's top-right corner, labelled
199 and 204 beside the wall's 203, had no level of its own, so the step never tested it and
the pixels inward of it in turn; read within 8 slices it goes back, 0.0333 -> 0.0077 m.
Chosen (2026-11-28) on room seeds 224-255 (8 slices, with the pixels without a level read as
holding nothing: 10 better, none worse; the built-in motorcycle at m_n = 10, 25 %, seed 0,
then 0.0665 -> 0.0726 m, its small parts' labels unlike all around them, so those are not
tested). Held out the same day: room seeds 224-255 2 better (234 0.0204 -> 0.0050 m), room
seeds 256-287 3 better (281 0.0303 -> 0.0178 m: 30 -> 31 of 32 at 0.03 m), procedural
100-124 and 150-199 (m_n 5 and 10, 25 and 50 %; 300) 3 better, none worse by more than
0.9 %; the built-ins at 25 % (7 scenes x m_n 1 / 5 / 10), the paper's Fig. 6 stand-in and
the instrument benchmark's seeds 3-5 unchanged (Fig. 4's 1023-bit code 0.0929 -> 0.0931 m).
"""

from __future__ import annotations

import warnings

import numpy as np

from .corner import GAP, near_slice

__all__ = ["ALONG", "EDGE_LEAST", "EDGE_LEVEL", "EDGE_MARGIN", "EDGE_OWN", "EDGE_PASSES", "GAP",
           "LEVEL_PIXELS", "OWN_GAP", "REACH", "fill_edges", "local_level"]

#: how many times more, relative to each surface's level, the evidence at ``b`` must be
EDGE_MARGIN = 2.0
#: the least evidence at ``b``, as a share of ``b``'s level (a halo holds about 0.2)
EDGE_LEAST = 0.25
#: ``b``'s least level, in noise maxima
EDGE_LEVEL = 1.0
#: the most evidence, in noise maxima, a pixel may hold at its own label to be tested: a worn
#: rim's is weak, while a return standing well above the noise is the pixel's own
EDGE_OWN = 2.0
#: how far along its row (column) a pixel beside the region (above or below it; left or
#: right) must find the region's edge going on: a worn stretch of a straight edge or a
#: rounded corner, not a surface's own rim beside a region's side
ALONG = 3
#: the window's half side: levels are read over the (2 REACH + 1)^2 pixels around
REACH = 3
#: the fewest pixels of a surface in the window that give it a level
LEVEL_PIXELS = 3
#: passes: a rim worn ``n`` pixels deep needs about ``n`` of them
EDGE_PASSES = 3
#: where no surface within ``GAP`` of a pixel's label gives it a level (a steep slanted
#: surface, whose label changes by several slices a pixel, or a label the rim's spread left
#: a few slices off the surface behind: room seed 248, the shelf's corner pixels labelled
#: 199 and 204 beside the wall's 203), its level is read within this many slices; where
#: none gives one there either the pixel is not tested (a label unlike all around it: the
#: motorcycle's small parts, whose own returns hold them, lost 9 % when taken)
OWN_GAP = 8


def local_level(own: np.ndarray, lab: np.ndarray, y: np.ndarray, x: np.ndarray,
                k: np.ndarray, reach: int = REACH, least: int = LEVEL_PIXELS,
                skip: np.ndarray | None = None, gap: int = GAP) -> np.ndarray:
    """The median of ``own`` (each pixel's evidence at its own label) over the pixels within
    ``reach`` of each ``(y, x)``, the pixel itself and those in ``skip`` left out, whose label
    is within :data:`GAP` of ``k``; NaN where fewer than ``least`` pixels are.

    Parameters
    ----------
    own : ndarray, shape (N1, N2)
        Evidence of each pixel at its own label.
    lab : ndarray of int, shape (N1, N2)
        The labelling.
    y, x, k : ndarray of int, shape (C,)
        The pixels and the surface (a slice) whose level is read around each.
    reach, least : int
        :data:`REACH`, :data:`LEVEL_PIXELS`.
    skip : ndarray of bool, shape (N1, N2), optional
        Pixels not counted (those a rim step gave back: their evidence is the worn rim's).
    gap : int
        How many slices from ``k`` a pixel's label may be (:data:`GAP`).
    """
    n1, n2 = lab.shape
    span = np.arange(-reach, reach + 1)
    dy, dx = (v.ravel() for v in np.meshgrid(span, span, indexing="ij"))
    off = (dy != 0) | (dx != 0)
    dy, dx = dy[off], dx[off]
    yy, xx = y[:, None] + dy[None, :], x[:, None] + dx[None, :]
    inside = (yy >= 0) & (yy < n1) & (xx >= 0) & (xx < n2)
    yy, xx = np.clip(yy, 0, n1 - 1), np.clip(xx, 0, n2 - 1)
    on = inside & (np.abs(lab[yy, xx] - k[:, None]) <= gap)
    if skip is not None:
        on &= ~skip[yy, xx]
    vals = np.where(on, own[yy, xx], np.nan)
    enough = on.sum(axis=1) >= least
    out = np.full(y.shape, np.nan)
    if enough.any():
        with warnings.catch_warnings():  # rows are all-NaN only where not enough
            warnings.simplefilter("ignore", RuntimeWarning)
            out[enough] = np.nanmedian(vals[enough], axis=1)
    return out


def fill_edges(z: np.ndarray, label: np.ndarray, nu: float, shape: tuple[int, int], *,
               margin: float = EDGE_MARGIN, least: float = EDGE_LEAST,
               level: float = EDGE_LEVEL, own_max: float = EDGE_OWN, reach: int = REACH,
               passes: int = EDGE_PASSES, least_pixels: int = LEVEL_PIXELS,
               along: int = ALONG, own_gap: int = OWN_GAP) -> tuple[np.ndarray, int]:
    """A front region's rim that the per-slice TV wore away, given back to it (module
    docstring).

    Parameters
    ----------
    z : ndarray, shape (Q, K)
        Evidence per pixel and slice (the MRF's data term, noise units).
    label : ndarray of int, shape (Q,)
        The labelling.
    nu : float
        The block's typical noise maximum.
    shape : (int, int)
        The image grid, ``Q = N1 N2``.
    margin, least, level, own_max : float
        :data:`EDGE_MARGIN`, :data:`EDGE_LEAST`, :data:`EDGE_LEVEL`, :data:`EDGE_OWN`.
    reach, least_pixels, along : int
        :data:`REACH`, :data:`LEVEL_PIXELS`, :data:`ALONG` (0: no edge test).
    own_gap : int
        :data:`OWN_GAP` (at most ``GAP``: a pixel without a level of its own within ``GAP``
        is not tested).
    passes : int
        At most this many passes (each over the labels the last one left).

    Returns
    -------
    label : ndarray of int, shape (Q,)
        A new array.
    filled : int
        Pixels relabelled.
    """
    n1, n2 = shape
    k = z.shape[1]
    out = np.array(label, dtype=np.int64, copy=True).reshape(shape)
    if nu <= 0 or k < 3:
        return out.ravel(), 0
    z3 = np.asarray(z).reshape(n1, n2, k)
    yy, xx = np.mgrid[0:n1, 0:n2]
    done = np.zeros(shape, dtype=bool)
    filled = 0
    for _ in range(passes):
        lab = out
        own = z3[yy, xx, lab]
        weak = own < own_max * nu  # a return well above the noise is the pixel's own
        ys, xs, bs = [], [], []
        for dy, dx in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            qy, qx = yy + dy, xx + dx
            ok = (qy >= 0) & (qy < n1) & (qx >= 0) & (qx < n2)
            b = lab[np.clip(qy, 0, n1 - 1), np.clip(qx, 0, n2 - 1)]
            ok &= (b < lab - GAP) & (b >= 1) & (b < k - 1) & weak & ~done
            if along:  # the region's edge goes on along the pixel's row (column)
                on_edge = np.zeros_like(ok)
                for j in range(1, along + 1):
                    for sgn in (-1, 1):
                        ey, ex = yy + sgn * j * dx, xx + sgn * j * dy
                        inside = (ey >= 0) & (ey < n1) & (ex >= 0) & (ex < n2)
                        e = lab[np.clip(ey, 0, n1 - 1), np.clip(ex, 0, n2 - 1)]
                        on_edge |= inside & (np.abs(e - b) <= GAP)
                ok &= on_edge
            ys.append(yy[ok])
            xs.append(xx[ok])
            bs.append(b[ok])
        y, x, b = np.concatenate(ys), np.concatenate(xs), np.concatenate(bs)
        if not y.size:
            break
        a = lab[y, x]
        level_b = local_level(own, lab, y, x, b, reach, least_pixels, skip=done)
        level_a = local_level(own, lab, y, x, a, reach, least_pixels, skip=done)
        at_b, slice_b = near_slice(z3, y, x, b)
        if own_gap > GAP:  # no surface of its own within GAP: read it within own_gap
            redo = np.isnan(level_a)
            if redo.any():
                level_a[redo] = local_level(own, lab, y[redo], x[redo], a[redo], reach,
                                            least_pixels, skip=done, gap=own_gap)
        ok = (level_b >= level * nu) & (level_a > 0)  # False where a level is NaN
        rel_b = np.where(ok, at_b / np.where(ok, level_b, 1.0), 0.0)
        rel_a = np.where(ok, own[y, x] / np.where(ok, level_a, 1.0), 0.0)
        take = ok & (rel_b >= least) & (rel_b > margin * np.maximum(rel_a, 0.0))
        if not take.any():
            break
        y, x, slice_b, rel_b = y[take], x[take], slice_b[take], rel_b[take]
        # a pixel beside two nearer surfaces goes to the one it holds more of
        order = np.lexsort((-rel_b, y * n2 + x))
        first = np.ones(order.size, dtype=bool)
        key = (y * n2 + x)[order]
        first[1:] = key[1:] != key[:-1]
        pick = order[first]
        y, x = y[pick], x[pick]
        new = lab.copy()
        new[y, x] = slice_b[pick]
        done[y, x] = True
        n = int(np.count_nonzero(new != lab))
        out = new
        filled += n
        if not n:
            break
    return out.ravel(), filled
