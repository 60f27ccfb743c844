"""Holes: a pixel that returns nothing at any of its neighbours' surfaces, though they
return strongly, keeps its own argmax against the MRF (the MRF's last step, after the dots).

A small object in front of a surface (a dot, a 2 x 2 blob, a leaf) occludes that surface at
its pixels: in the surface's range slice the pixel is a hole, which the per-slice TV of the
reconstruction (eq. 18) fills only in part (to 0.03-0.5 of the surface's level around it on
the scenes below). The MRF then gives the pixel the surface around it, and where the object's
own return is weak (a dark or distant object: 1-2.5 noise maxima) neither the dots' level
(:data:`~.dots.DOT_LEVEL`) nor their count (:func:`~.dots.weak_dots` keeps none of fewer
than :data:`~.dots.WEAK_DOT_COUNT`) keeps it. One such pixel is enough to lose to argmax many
times over on a scene argmax gets right: a ramp at 1.5-3.5 m with 5 % of its pixels at
depths drawn from 1.2-3.8 m (not a scene of the project's; m_n = 5, 50 % patterns) read
0.0042 m with argmax and 0.0366 m with the MRF, from four dots at 1.5-2.3 noise maxima whose
evidence at the ramp's slice was 0.03-0.19 of their neighbours'.

What tells the hole from a spike: a noise spike on a surface leaves the pixel's own return at
the surface's slice, as strong as its neighbours'; a dark pixel on a dark surface is no hole,
since its neighbours return weakly too. So a pixel is a *hole* where its 4-neighbours' own
returns (each at its own label) have a median of at least :data:`HOLE_LEVEL` noise maxima
and the pixel's evidence within ``near`` slices of every neighbour's label, and at its own,
is at most :data:`HOLE_SHARE` of that median. A hole whose argmax lies more than ``exclude``
slices from its label, in a group of at most :data:`HOLE_SIZE` pixels
(:func:`~.dots.argmax_groups`), at :data:`HOLE_DOT_LEVEL` noise maxima or more and at least
its evidence at the label, and not the halo of a brighter 8-neighbour at the same slice (its
evidence there at least :data:`HALO_SHARE` of the neighbour's), is a candidate; the
candidates are kept together by the Benjamini-Hochberg step of :func:`~.dots.weak_dots`
at the dots' false-discovery rate, with the noise's expected argmaxes counted over the holes
only (:func:`~.dots.expected_spikes`), and a count of one allowed: a hole is itself evidence,
which the street's lone spike of :data:`~.dots.WEAK_DOT_COUNT` was not (its wall returned at
the spike's pixel as around it).

Chosen on 2026-12-03 (``benchmarks/depth_quality.py``'s cached slices, 64 x 64, m_n 5 and 10,
25 and 50 % patterns) among shares 0.5 / 0.6 / 0.7, neighbour levels 3 / 4 / 5, least evidence
1 / 1.5, groups of 2 / 4 and a search of 1 / 2 slices, on five outside scene kinds (seeds 11-12,
40 measurements: more than 5 % worse than argmax on 7 -> 5, worst 8.64 -> 1.81, none worse
than the MRF before), the seven built-ins (28, unchanged) and procedural seeds 150-174 (100: 6
better, 2 worse by 0.3-0.4 %). Held out: the five kinds at seed 13 and two kinds written after
the choice (28: 10 -> 7 more than 5 % worse, worst 4.25 -> 1.62, none worse than before) and
procedural seeds 100-124 (100: none more than 5 % worse either way; 3 better, 2 worse by at
most 1.3 %). A pixel on a dim structure the label holds is no hole (``_dim_alike``:
without it the room's dark lamp pole lost a pixel to a noise spike, seed 267 at m_n = 5, 50 %,
0.0078 -> 0.0114 m; the room's seeds 256-287 and the camera and motorcycle at m_n = 10 are
unchanged with it). The user guide's ``depth.md``, "Holes in a surface", has the table and what is
left. The rule reads the evidence only; no library models the per-slice TV's filling of a
hole.
"""

from __future__ import annotations

import warnings

import numpy as np

from .dots import DOT_FDR, argmax_groups, step_up
from .profile import noise_maxima, shift2d

__all__ = ["HALO_SHARE", "HOLE_DOT_LEVEL", "HOLE_LEVEL", "HOLE_SHARE", "HOLE_SIZE",
           "hole_dots", "holes"]

#: a hole's evidence near its neighbours' surfaces, at most this share of their returns
HOLE_SHARE = 0.6
#: the least median return of a hole's neighbours, in median noise maxima
HOLE_LEVEL = 4.0
#: the least evidence of a hole's own argmax, in median noise maxima
HOLE_DOT_LEVEL = 1.0
#: the most pixels a group of argmax returns in holes may hold (a 2 x 2 blob)
HOLE_SIZE = 4
#: a candidate's evidence at least this share of any 8-neighbour's at the same slice whose
#: argmax is there too (else it is that neighbour's halo)
HALO_SHARE = 0.5

_FOUR = ((0, 1), (0, -1), (1, 0), (-1, 0))
_EIGHT = tuple((dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx)


def _neighbours(shape: tuple[int, int], offsets) -> list[tuple[np.ndarray, np.ndarray]]:
    """For each ``(dy, dx)`` of ``offsets``: each pixel's neighbour there (row-major index;
    the pixel's own outside the image) and whether it is inside (the index image moved by
    :func:`~.profile.shift2d`)."""
    index = np.arange(shape[0] * shape[1]).reshape(shape)
    out = []
    for dy, dx in offsets:
        nb = shift2d(index, dy, dx, fill=-1).ravel()
        inside = nb >= 0
        out.append((np.where(inside, nb, index.ravel()), inside))
    return out


def _surroundings(label: np.ndarray, z: np.ndarray, four: list
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's evidence at its label, and the median of its 4-neighbours' (``four``,
    :func:`_neighbours` of :data:`_FOUR`; NaN where it has none)."""
    own = z[np.arange(z.shape[0]), label]
    around = np.array([np.where(inside, own[nb], np.nan) for nb, inside in four])
    with warnings.catch_warnings():  # (a 1 x 1 image has no neighbour: no hole)
        warnings.simplefilter("ignore", RuntimeWarning)
        typical = np.nanmedian(around, axis=0)
    return own, typical


def holes(label: np.ndarray, z: np.ndarray, nu: float, shape: tuple[int, int],
          share: float = HOLE_SHARE, level: float = HOLE_LEVEL, near: int = 1
          ) -> np.ndarray:
    """Which pixels are holes in their neighbours' surfaces (see the module docstring).

    Parameters
    ----------
    label : ndarray of int, shape (Q,)
        The labels so far.
    z : ndarray, shape (Q, K)
        Evidence (noise units).
    nu : float
        The block's median noise maximum.
    shape : tuple of int
        ``(N1, N2)``.
    share, level : float
        :data:`HOLE_SHARE`, :data:`HOLE_LEVEL` (in ``nu``).
    near : int
        Slices either side of a neighbour's label searched at the pixel.

    Returns
    -------
    ndarray of bool, shape (Q,)
    """
    four = _neighbours(shape, _FOUR)
    return _holes(label, z, nu, four, *_surroundings(label, z, four), share, level, near)


def _holes(label: np.ndarray, z: np.ndarray, nu: float, four: list, own: np.ndarray,
           typical: np.ndarray, share: float, level: float, near: int) -> np.ndarray:
    """:func:`holes` on the neighbours and surroundings already computed."""
    q, k = z.shape
    rows = np.arange(q)
    seen = own.copy()  # the pixel's evidence at its own label and near each neighbour's
    for nb, inside in four:
        for o in range(-near, near + 1):
            at = np.clip(label[nb] + o, 0, k - 1)
            seen = np.where(inside, np.maximum(seen, z[rows, at]), seen)
    return np.isfinite(typical) & (typical >= level * nu) & (seen <= share * typical)


def _dim_alike(a: np.ndarray, label: np.ndarray, four: list, own: np.ndarray,
               typical: np.ndarray, share: float, near: int = 1, exclude: int = 2
               ) -> np.ndarray:
    """Pixels with a 4-neighbour at their own label (within ``near`` slices) whose return
    there is as weak as theirs against the same surroundings (at most ``share`` of the
    median of the pixel's neighbours' returns, and at most ``1 / share`` times the pixel's
    own) and whose own tallest return is that label
    (within ``exclude`` slices): a dim structure the label holds (a dark pole before a
    bright wall, whose pixels return at the pole), not an object's hole (whose pixels'
    argmaxes are the object's)."""
    alike = np.zeros(own.size, dtype=bool)
    for nb, inside in four:
        alike |= (inside & (np.abs(label[nb] - label) <= near) & (own[nb] <= share * typical)
                  & (share * own[nb] <= own) & (np.abs(a[nb] - label[nb]) <= exclude))
    return alike


def hole_dots(a: np.ndarray, label: np.ndarray, z: np.ndarray, nu: float,
              shape: tuple[int, int], size: int = HOLE_SIZE, fdr: float = DOT_FDR,
              level: float = HOLE_DOT_LEVEL, halo: float = HALO_SHARE, exclude: int = 2
              ) -> np.ndarray:
    """Which holes keep their argmax: the Benjamini-Hochberg step over the candidates'
    evidence, the noise's expected argmaxes counted over the holes.

    Parameters
    ----------
    a, label : ndarray of int, shape (Q,)
        Each pixel's argmax slice; the labels so far.
    z : ndarray, shape (Q, K)
        Evidence (noise units).
    nu : float
        The block's median noise maximum.
    shape : tuple of int
        ``(N1, N2)``.
    size, fdr, level, halo : int, float, float, float
        :data:`HOLE_SIZE`, :data:`~.dots.DOT_FDR`, :data:`HOLE_DOT_LEVEL` (in ``nu``),
        :data:`HALO_SHARE`.
    exclude : int
        Slices either side of the label that belong to its surface.

    Returns
    -------
    ndarray of bool, shape (Q,)
        The pixels to give their argmax.
    """
    q = z.shape[0]
    za = z[np.arange(q), a]
    four = _neighbours(shape, _FOUR)
    r, typical = _surroundings(label, z, four)  # (r: each pixel's evidence at its label)
    hole = _holes(label, z, nu, four, r, typical, HOLE_SHARE, HOLE_LEVEL, 1)
    cand = hole & (np.abs(a - label) > exclude) & (za >= level * nu) & (za >= r)
    if not cand.any():
        return cand
    brighter = np.zeros(q)  # the tallest 8-neighbour at the pixel's argmax, argmax there too
    for nb, inside in _neighbours(shape, _EIGHT):
        there = inside & (np.abs(a[nb] - a) <= 1)
        brighter = np.maximum(brighter, np.where(there, z[nb, a], 0.0))
    cand &= (za >= halo * brighter) & (argmax_groups(a, shape) <= size)
    if not cand.any():
        return cand
    cand &= ~_dim_alike(a, label, four, r, typical, HOLE_SHARE)
    if not cand.any():
        return cand
    return step_up(za, cand, noise_maxima(z, exclude, centre=label), r[hole], fdr)
