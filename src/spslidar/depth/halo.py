"""The per-slice TV's halo, discounted before the MRF weighs the slices.

Each range slice is solved on its own with a TV prior (eq. 18). Where a slice holds a bright
region, its reconstruction leaks into the pixels just outside that region: a halo of a
quarter or so of the region's level on the first pixel, falling off beyond it. Those pixels
belong to another surface, whose own slice the same TV has eroded at its edge (the TV pays
for an edge in every slice), so at the edge between a dark near object and a bright far wall
the wall's halo can outweigh the object's own return. Measured on the built-in ``room`` (64 x
64, m_n = 5, 50 % patterns, seed 0): the dark shelf's edge column reads 7.0 noise units in the
wall's slice, beside the wall's 26.9, against 2.6 in its own slice beside the shelf's 4.7, so
the MRF gave four of its pixels the wall 1.2 m behind (half the scene's squared error).

:func:`halo_discount` lowers the evidence of a pixel in a slice where it is below ``ratio`` of
a 4-neighbour's and falls off again on the opposite side (a gradient leading away from a
bright region, not a plateau of the same surface), by ``(z / (ratio m)) ** power``. The rule is
local and by hand: no library models the halo of a per-slice TV. It feeds only the MRF's data
cost; the argmax, the line rules (:mod:`.lines`) and the noise statistics still read the
evidence as it is.

The two constants were chosen on procedural scenes 0-19 (``procedural:SEED``, m_n 5 and 10,
25 and 50 % patterns) and the built-in scenes (seeds 0-2), among ratios 0.3-0.5 and powers
1-4, for the lowest mean RMSE without losing the built-in ``fence``'s front panel (a ratio of
0.4 takes two of its edge pixels, which sit beside a brighter post, to the wall: 0.0043 ->
0.023 m at m_n = 10, 50 %). ``benchmarks/depth_quality.py`` reports them on held-out seeds
100-149. A non-directional variant (any brighter neighbour, the MRF's data cost lowered by
a share of the difference) lost up to 3.5 times on textured far walls of ``street``, where a
bright pixel of a surface is next to dimmer pixels of the same surface.
"""

from __future__ import annotations

import numpy as np

__all__ = ["HALO_POWER", "HALO_RATIO", "halo_discount"]

#: a slice's value below this share of a 4-neighbour's reads as that neighbour's halo
HALO_RATIO = 0.35
#: the discount ``(z / (HALO_RATIO * m)) ** HALO_POWER``
HALO_POWER = 2.0


def halo_discount(z: np.ndarray, ratio: float = HALO_RATIO,
                  power: float = HALO_POWER) -> np.ndarray:
    """Evidence with the per-slice TV's halo discounted.

    For each pixel ``p`` and slice, ``m`` is the largest value among its 4-neighbours ``q``
    whose opposite neighbour (``p - (q - p)``, zero beyond the image) is below half of
    ``p``'s value: a bright region on one side, the value falling off on the other. Where
    ``p``'s positive value ``z`` is below ``ratio * m`` it becomes
    ``z * (z / (ratio * m)) ** power``; everything else is unchanged.

    Parameters
    ----------
    z : ndarray, shape (K, N1, N2)
        Evidence per slice (labels leading, as :func:`~spslidar.depth.mrf.min_sum_bp`).
    ratio : float
        In (0, 1].
    power : float
        >= 0; 0 leaves ``z`` unchanged.

    Returns
    -------
    ndarray, shape (K, N1, N2)
        A new array of ``z``'s dtype.

    Notes
    -----
    About five ``(K, N1, N2)`` blocks at its peak (the padded copy, the neighbours' maximum,
    the result and a temporary), all freed before the BP allocates its own; 0.9 s for
    256 x 256 x 200 float32 on one core (the MRF's time at 64 x 64 is unchanged within its
    noise, 0.25 s for 208 slices).
    """
    if not 0.0 < ratio <= 1.0 or power < 0.0:
        raise ValueError("halo ratio must be in (0, 1] and power >= 0")
    z = np.asarray(z)
    if z.ndim != 3:
        raise ValueError("z must have shape (K, N1, N2)")
    pad = np.pad(z, ((0, 0), (1, 1), (1, 1)))
    up, down = pad[:, :-2, 1:-1], pad[:, 2:, 1:-1]
    left, right = pad[:, 1:-1, :-2], pad[:, 1:-1, 2:]
    half = z * z.dtype.type(0.5)
    source = np.zeros_like(z)
    for q, opposite in ((up, down), (down, up), (left, right), (right, left)):
        np.maximum(source, np.where(opposite < half, q, 0), out=source)
    scale = z.dtype.type(ratio) * source
    lowered = (z > 0) & (z < scale)
    out = z.copy()
    out[lowered] = z[lowered] * (z[lowered] / scale[lowered]) ** z.dtype.type(power)
    return out
