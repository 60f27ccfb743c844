"""A region's corner that the per-slice TV rounded off, given back where the evidence, read
relative to each surface's own level, holds it (the MRF's last step).

Each range slice is solved on its own with a TV prior (eq. 18), and a TV pays for an edge by
its length: it cuts a region's convex corner in the region's own slice, and fills the
concave corner of the surface around it in that surface's slice. At a corner the two add.
Measured on the room at m_n = 5, 50 % patterns, seed 139: at the dark shelf's top-left
corner the shelf's slice reads 2.3 noise units against 4.6-7 inside the shelf, while the
wall's slice reads 19.4 against 84-92 on the wall around it, so the corner pixel holds
0.4-0.6 of the shelf's level and 0.2 of the wall's. Read as they stand, 2.3 against 8.4 at
the wall's own slice, the wall wins, and the MRF gave the corner's three pixels the wall
1.2 m behind; the halo discount (:mod:`.halo`), which follows one bright side's fall-off,
misses the corner by 1-5 % (the halo there comes from two sides). On the room's 96
measurements of seeds 32-63 and 80-143 the shelf's top corners were the most common failure
left (in 8 of the 17 above 0.03 m).

:func:`fill_corners` gives a pixel the label of a region ``B`` of which it is a notch: two
perpendicular 4-neighbours and the pixel diagonal between them at one depth (within a
slice), its two opposite 4-neighbours and itself more than ``GAP`` slices from it. It takes
``B`` where its evidence at ``B`` (+-1 slice), relative to the two ``B`` neighbours' there,
is more than :data:`CORNER_MARGIN` times its evidence at its own label relative to what its
two other neighbours hold at theirs, and at least :data:`CORNER_LEAST` of the ``B``
neighbours' (a halo holds about a fifth), where those hold :data:`CORNER_LEVEL` noise maxima.
A filled notch makes the next pixel a notch, so a corner rounded two or three pixels deep is
filled in :data:`CORNER_PASSES` passes. The rule reads the evidence only: no library models
the corners of a per-slice TV.

Chosen on 2026-11-27 on the room at m_n = 5, 50 %, seeds 32-63 and 80-143 (96
measurements), procedural seeds 0-19 at m_n 5 and 10, 25 and 50 % (with 110, 116, 136 and
147: 96), the camera and the motorcycle at m_n = 10, 25 and 50 %, seeds 0-2, and Fig. 3's two
cases, among margins 1, 1.5 and 2 and least shares 0 to 0.4: at 1.5, against the labelling
without it, the room from 79 to 86 of 96 at 0.03 m or below (44 better, none worse; mean
0.0182 -> 0.0140 m), procedural 9 better and 4 worse by 2-4 %, the camera and the motorcycle
unchanged within 0.4 %, Fig. 3 0.1301 / 0.1142 -> 0.1293 / 0.1138 m. A margin of 1 took
the room a little further (49 better) but lost procedural seed 4 at m_n = 5, 50 % by 16 %
(a pixel between two surfaces that neither holds, given the farther) and the motorcycle
2 %; the least share keeps such pixels, whose evidence at ``B`` is a fifth of ``B``'s level,
at their label. Summing the halo of two bright sides in :func:`~.halo.halo_discount` instead
(the other reading of the same corner) lost as much as it gained (room 14 better, 12 worse):
in the shelf's own slice its corner is the dimmer pixel between two brighter ones, and was
discounted as their halo.

Held out (measured the same day on the same cached slices, against the labelling without
this step): fresh room seeds 144-159 7 better (seed 154 0.030 -> 0.012 m, 159 0.016 -> 0.004
m), none worse, mean 0.0200 -> 0.0174 m (14 of 16 at 0.03 m before and after: the two left
lose the lamp pole); procedural seeds 100-149 at m_n 5 and 10 and 100-119 at m_n 1 and 2
(280) 37 better (to 0.10), 18 worse by 2-26 % (the largest 0.0072 -> 0.0091 m, seed 105 at
m_n = 1, 50 %; then 8 %, 7 % and 7 %), the median ratio to argmax 0.529 -> 0.524 and the
four measurements more than 5 % worse than argmax the same four, by the same ratios. The
paper's reproduction loses a little, every verdict the same: Fig. 2's camera at 5 % patterns
0.0768 -> 0.0786 m, Fig. 6's stand-in at m_n = 8 0.0454 -> 0.0466 m (with the line stage's
fixes of the same day).

A corner rounded two pixels deep leaves the notch's other two neighbours as weak as the notch
(room seeds 44 and 88: 1.7 noise units at the wall's slice beside the notch, 9.5 on the wall
one pixel further), so its own surface's level is read one pixel further on where that pixel
holds more than twice the neighbour (:func:`_level`), and a pixel given back is not tested
again in a later pass (two deep, the pixels filled around it made it a notch of the surface
it left). Measured on 2026-11-27 against the step without these two (with the line stage's
rules of that day): room seeds 0-223 at m_n = 5, 50 %, 4 better (88 0.038 -> 0.006 m, 44
0.044 -> 0.029 m, 115 and 147), none worse; procedural seeds 0-19 (m_n 5 and 10, 25 and
50 %) 13 of 80 better (to 0.95), 4 worse by 0.7 % at most, seed 0 at m_n = 10, 25 % back
within 5 % of argmax; held out, procedural 100-149 and 100-119 (m_n 1 and 2) 29 of 280
better (to 0.89), 32 worse, geometric mean 0.999, the worst seed 108 at m_n = 1, 50 %,
0.050 -> 0.058 m (1.02 of argmax): a front surface whose edge columns are dim (2-4 noise
units against 20 inside) reads as a cut two deep, and its corner pixel goes to the surface
behind. The street at m_n = 1, 25 % 0.2 % worse; the camera, the motorcycle, the fence and
Fig. 6 unchanged. Letting a dark region's pixels around a notch agree within 3 slices, not
1, across a depth edge gave room seed 201 its shelf's corners (0.033 -> 0.020 m) but cost
the paper's Fig. 6 stand-in at m_n = 5 0.0254 -> 0.0266 m, even limited to regions under
1.2 noise maxima: it is not used.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CORNER_LEAST", "CORNER_LEVEL", "CORNER_MARGIN", "CORNER_PASSES", "fill_corners",
           "near_slice"]

#: how many times better, relative to each surface's level, the evidence at ``B`` must be
CORNER_MARGIN = 1.5
#: the least evidence at ``B``, as a share of the ``B`` neighbours' (a halo holds about 0.2)
CORNER_LEAST = 0.25
#: the ``B`` neighbours' least evidence, in noise maxima
CORNER_LEVEL = 0.5
#: passes: a corner rounded ``n`` pixels deep needs about ``n`` of them
CORNER_PASSES = 3
#: a pixel more than this many slices from ``B`` is not at its depth
GAP = 3
_SPAN = np.arange(-1, 2)


def near_slice(z3: np.ndarray, y: np.ndarray, x: np.ndarray, b: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's evidence at slice ``b`` (``1 <= b < K - 1``) or either of its neighbours,
    and which of those three slices holds it: the corner and rim steps' reading of a surface
    ``b`` at a pixel, and the slice a pixel given back to ``b`` takes. Read only at the
    pixels given (a ``(N1, N2, K)`` copy would add a block to the MRF's peak).

    Parameters
    ----------
    z3 : ndarray, shape (N1, N2, K)
        Evidence per pixel and slice.
    y, x, b : ndarray of int, shape (C,)
        The pixels and the slice read at each.

    Returns
    -------
    at_b : ndarray, shape (C,)
        The largest evidence of the three slices.
    slice_b : ndarray of int, shape (C,)
        The slice that holds it.
    """
    window = z3[y[:, None], x[:, None], b[:, None] + _SPAN]
    best = np.argmax(window, axis=1)
    return np.take_along_axis(window, best[:, None], axis=1)[:, 0], b - 1 + best


def fill_corners(z: np.ndarray, label: np.ndarray, nu: float, shape: tuple[int, int], *,
                 margin: float = CORNER_MARGIN, least: float = CORNER_LEAST,
                 level: float = CORNER_LEVEL, passes: int = CORNER_PASSES
                 ) -> tuple[np.ndarray, int]:
    """Notches of a region that the per-slice TV cut from its corners, given back to it
    (module docstring).

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
    margin, least, level : float
        :data:`CORNER_MARGIN`, :data:`CORNER_LEAST`, :data:`CORNER_LEVEL`.
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
    out = np.array(label, dtype=np.int64, copy=True)
    if nu <= 0 or k < 3 or n1 < 3 or n2 < 3:
        return out, 0
    z3 = np.asarray(z).reshape(n1, n2, k)

    yy, xx = np.mgrid[1:n1 - 1, 1:n2 - 1]  # a notch has all four neighbours in the image
    filled = 0
    # a pixel given back is not tested again: two deep, the pixels filled around it in the
    # next pass would make it a notch of the surface it left
    done = np.zeros((n1, n2), dtype=bool)
    for _ in range(passes):
        lab = out.reshape(shape)
        new = lab.copy()
        for dy, dx in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
            a = lab[yy, xx]
            b = lab[yy + dy, xx]  # the region: p + dy, p + dx and the diagonal between
            ov, oh = lab[yy - dy, xx], lab[yy, xx - dx]
            notch = ((np.abs(lab[yy, xx + dx] - b) <= 1) & (np.abs(lab[yy + dy, xx + dx] - b) <= 1)
                     & (np.abs(a - b) > GAP) & (np.abs(ov - b) > GAP) & (np.abs(oh - b) > GAP)
                     & (b >= 1) & (b < k - 1) & ~done[yy, xx])
            y, x, a, b, ov, oh = (v[notch] for v in (yy, xx, a, b, ov, oh))
            if not y.size:
                continue
            at_b, slice_b = near_slice(z3, y, x, b)
            b_level = 0.5 * (near_slice(z3, y + dy, x, b)[0] + near_slice(z3, y, x + dx, b)[0])
            own = z3[y, x, a]
            own_level = 0.5 * (_level(z3, lab, y - dy, x, -dy, 0, ov)
                               + _level(z3, lab, y, x - dx, 0, -dx, oh))
            take = ((b_level >= level * nu) & (own_level > 0) & (at_b >= least * b_level)
                    & (at_b * own_level > margin * own * b_level))
            y, x = y[take], x[take]
            new[y, x] = slice_b[take]
            done[y, x] = True
        n = int(np.count_nonzero(new != lab))
        out = new.ravel()
        filled += n
        if not n:
            break
    return out, filled


def _level(z3: np.ndarray, lab: np.ndarray, y: np.ndarray, x: np.ndarray, dy: int, dx: int,
           k: np.ndarray) -> np.ndarray:
    """What the neighbour at ``(y, x)`` holds at its label ``k``, or the pixel one further
    on (``+ (dy, dx)``) at that label where it is labelled within ``GAP`` of it and holds
    more than twice as much: a corner rounded two pixels deep leaves the notch's neighbours
    as weak as the notch, and the surface's level is read past them (room seeds 44 and 88 at
    m_n = 5, 50 %: 1.7 noise units beside the notch, 9.5 on the wall one pixel further).
    Read past any neighbour, a front surface's own corner pixel, beside its interior, was
    given to the surface behind (procedural seed 108 at m_n = 1, 50 %: 8 % worse)."""
    n1, n2 = lab.shape
    near = z3[y, x, k]
    y2, x2 = y + dy, x + dx
    ok = (y2 >= 0) & (y2 < n1) & (x2 >= 0) & (x2 < n2)
    y2, x2 = np.clip(y2, 0, n1 - 1), np.clip(x2, 0, n2 - 1)
    far = z3[y2, x2, k]
    ok &= (np.abs(lab[y2, x2] - k) <= GAP) & (near < 0.5 * far)
    return np.where(ok, far, near)
