"""One-pixel gaps the MRF closes: lines of argmax returns *behind* its surface, between two
sides of it.

The mirror of :func:`spslidar.depth.lines.thin_structures`. A fence's one-pixel gap between
two slats, a slot in a panel or the wall seen between two table legs costs the MRF of
:class:`~spslidar.depth.mrf.MRFDepth` a depth edge on both sides of every pixel, as a pole
does; where the far surface's return through the gap is weak the MRF gives the gap the slats'
depth, while the paper's argmax keeps it wherever the far slice is the pixel's tallest.
Procedural seed 19 (m_n = 5, 50 % patterns): a fence at 2.7-2.9 m with one-pixel gaps onto a
wall at 4.8 m, each gap pixel holding 1.2-2.6 noise maxima at the wall's slice and 0.4-0.7 at
the slats'; the MRF closed 66 gap pixels, 1.22 times argmax's RMSE.

:func:`gap_lines` keeps the argmax of the pixels that, together, form such a line: each
candidate's argmax lies more than ``gap`` slices behind its MRF label and reaches ``floor``
noise maxima, and the MRF labels *both* of its neighbours along a row or a column (a diagonal
gap has its sides along both) more than ``gap`` slices in front of that argmax, the other candidates
read at their own argmax (so that the line's own pixels are no sides of it), while the pixel
itself holds, at those two sides' slices, less than ``hole`` (:data:`HOLE`, 0.5) of what
they hold there, and ``drop`` (:data:`DROP`, 3) noise maxima less: the front surface is
missing at the pixel, by more than noise. Without that test, procedural seed 16 (m_n = 5,
50 %) lost six pixels of a dark slanted panel to a column of argmax returns 1.4 m behind it,
lined up and at one depth but no gap: the pixels held 0.9-1.2 of their sides' evidence at the
panel's slice, where seed 19's gaps hold 0.04-0.12. The sides' own slices are read, not the
pixel's label, which the MRF gives a gap from its noise near the sides' depth. The drop keeps
out a weak pixel of a dark surface between two as weak (seeds 0 and 3: 0.2-0.4 of its sides,
but 1.5-2 noise maxima below them, at the end of a gap the labelling holds or between two
poles; seed 19's gaps are 13-21 noise maxima below their slats). The pixels of
such a gap that the MRF holds already join the candidates as anchors, at their label, as
:func:`spslidar.depth.lines.extend_lines` continues a structure in front: a gap's argmax
breaks where the slats' halo or noise wins a pixel, and the pieces between, of one or two
pixels, pass no line test alone. A surface's own edge
column, read behind where the pixel is a mixture, has the far surface on one side and is no
candidate; neither is a noise spike, which lines up with nothing. The candidates then go
through the same joining passes and line tests as the thin structures in front (size,
elongation, a depth linear along the line, the evidence total), since noise lines up no more
behind a surface than in front of it.

The line test is :mod:`spslidar.depth.lines`'s; this module adds the candidate test.
"""

from __future__ import annotations

import numpy as np

from .lines import AXIS, ELONGATION, FLOOR, GAP, PASSES, RESIDUAL, ROBUST, _line_keep

__all__ = ["DROP", "HOLE", "between_sides", "gap_lines"]

#: a candidate's evidence at its two sides' slices, as a share of theirs there, below which
#: the sides' surface is missing at the candidate, and the least that the two sides together
#: hold more than it there, in noise maxima (seed 19's gaps: 0.03-0.10 and 13-21; what the
#: rule must not take, a dark surface's weak pixel between two as weak: 0.2-0.4 and 1.5-2)
HOLE, DROP = 0.5, 3.0

#: the two axes, as the offsets of a pixel's two neighbours across it: a row's and a column's.
#: A diagonal gap has its sides along both too; a pixel between two sides along a diagonal
#: only is a region's corner, not a gap (procedural seed 0 at m_n = 10, 25 %: such corners
#: anchored a rail's two pixels to the wall behind it)
_AXES = (((-1, 0), (1, 0)), ((0, -1), (0, 1)))


def _sides(a: np.ndarray, label: np.ndarray, shape: tuple[int, int], gap: int) -> np.ndarray:
    """``(2, N1, N2)``: per axis, whether both neighbours across it are labelled more than
    ``gap`` slices in front of ``a`` (the image border is no side)."""
    n1, n2 = shape
    big = np.iinfo(np.int64).min  # a border neighbour is never in front
    lab = np.pad(np.asarray(label).reshape(shape).astype(np.int64), 1, constant_values=big)
    ref = np.asarray(a).reshape(shape).astype(np.int64) - gap
    out = np.zeros((len(_AXES), n1, n2), dtype=bool)
    for i, ((ay, ax), (by, bx)) in enumerate(_AXES):
        side_a = lab[1 + ay:1 + ay + n1, 1 + ax:1 + ax + n2]
        side_b = lab[1 + by:1 + by + n1, 1 + bx:1 + bx + n2]
        out[i] = (side_a > big) & (side_b > big) & (side_a < ref) & (side_b < ref)
    return out


def between_sides(a: np.ndarray, label: np.ndarray, shape: tuple[int, int],
                  gap: int = GAP) -> np.ndarray:
    """Pixels whose slice ``a`` lies more than ``gap`` slices behind the labels ``label`` of
    both their neighbours along a row or a column; the image border is no side."""
    return _sides(a, label, shape, gap).any(axis=0).ravel()


def _holes(pix: np.ndarray, label: np.ndarray, z: np.ndarray, shape: tuple[int, int],
           hole: float, drop: float) -> np.ndarray:
    """``(2, P)``: per axis, whether each pixel of ``pix`` holds, at its two neighbours'
    slices across that axis (the most over each and its two neighbouring slices), less than
    ``hole`` of what those neighbours hold there, and ``drop`` less: the surface of its two
    sides is missing at the pixel."""
    n1, n2 = shape
    k = z.shape[1]
    label = np.asarray(label)
    ys, xs = np.divmod(pix, n2)
    span = np.arange(-1, 2)[None, :]

    def side(dy: int, dx: int) -> tuple[np.ndarray, np.ndarray]:
        q = np.clip(ys + dy, 0, n1 - 1) * n2 + np.clip(xs + dx, 0, n2 - 1)
        ks = np.clip(label[q][:, None] + span, 0, k - 1)
        return z[pix[:, None], ks].max(axis=1), z[q[:, None], ks].max(axis=1)

    out = np.zeros((len(_AXES), pix.size), dtype=bool)
    for i, ((ay, ax), (by, bx)) in enumerate(_AXES):
        own_a, at_a = side(ay, ax)
        own_b, at_b = side(by, bx)
        own, at = own_a + own_b, at_a + at_b
        out[i] = (own < hole * at) & (at - own >= drop)
    return out


def gap_lines(a: np.ndarray, label: np.ndarray, z: np.ndarray, nu: float,
              shape: tuple[int, int], *, gap: int = GAP, floor: float = FLOOR,
              hole: float = HOLE, drop: float = DROP, elongation: float = ELONGATION,
              residual: float = RESIDUAL, axis: float = AXIS, robust: float | None = ROBUST,
              passes: tuple[tuple[int, int, int, float], ...] = PASSES) -> np.ndarray:
    """Pixels whose argmax belongs to a one-pixel line behind the MRF's surface, between two
    sides of it.

    Parameters
    ----------
    a : ndarray of int, shape (Q,)
        Each pixel's argmax slice.
    label : ndarray of int, shape (Q,)
        The MRF's slice.
    z : ndarray, shape (Q, K)
        The evidence (the pulse-matched profile over its noise scale).
    nu : float
        The block's typical noise maximum.
    shape : (int, int)
        The image grid.
    hole, drop : float
        A candidate's largest evidence at its two sides' slices, as a share of theirs there
        (:data:`HOLE`), and the least that they hold more than it there, in the units of
        ``nu`` (:data:`DROP`).
    gap, floor, elongation, residual, axis, robust, passes
        As :func:`spslidar.depth.lines.extend_lines`.

    Returns
    -------
    ndarray of bool, shape (Q,)
        True where the argmax is to be kept (candidates only, never an anchor).
    """
    a = np.asarray(a)
    label = np.asarray(label)
    if nu <= 0 or a.size == 0:
        return np.zeros(a.size, dtype=bool)
    z = np.asarray(z)
    rows = np.arange(a.size)
    za = z[rows, a].astype(np.float64) / nu
    cand = (a > label + gap) & (za >= floor)
    # the sides are read with the candidates at their argmax, so that a line's own pixels,
    # which the MRF labels in front too, are no sides of it: only what lies across it is
    seen = np.where(cand, a, label)
    pix = np.flatnonzero(cand)
    sides = _sides(a, seen, shape, gap).reshape(len(_AXES), -1)[:, pix]
    cand[pix] = (sides & _holes(pix, label, z, shape, hole, drop * nu)).any(axis=0)
    if not cand.any():
        return cand
    # the gap's pixels the MRF holds already join it as anchors, at their label
    anchor = between_sides(label, seen, shape, gap) & ~cand
    zl = z[rows, label].astype(np.float64) / nu
    return _line_keep(cand | anchor, np.where(anchor, label, a), np.where(anchor, zl, za),
                      shape, elongation, residual, passes, (cand, axis), robust,
                      label.reshape(shape))
