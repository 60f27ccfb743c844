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
bright region, not a plateau of the same surface), by ``(z / (ratio m)) ** power``. A halo
may be two pixels deep: along the shelf's top edge in the same measurement the wall's slice
reads 26.4 on the wall, then 3.4 and 3.4 on the shelf's first two rows, then 1.0, so the
fall-off may also come one pixel later. The tests read each slice with its two neighbours
added, since a return spans two or three slices and a discount that differed between them
would move its peak (a dark window of the noiseless ``street`` moved by a bin without it).
The rule is local and by hand: no library models the halo of a per-slice TV. It feeds only
the MRF's data cost; the argmax, the line rules (:mod:`.lines`) and the noise statistics
still read the evidence as it is.

The constants were chosen on procedural scenes 0-19 (``procedural:SEED``, m_n 5 and 10, 25
and 50 % patterns) and the built-in scenes (seeds 0-2), among ratios 0.3-0.5 and powers 1-4,
for the lowest mean RMSE without losing the built-in ``fence``'s front panel (a ratio of 0.4
takes two of its edge pixels, which sit beside a brighter post, to the wall: 0.0043 -> 0.023 m
at m_n = 10, 50 %); the two-pixel reach then took the room at m_n = 5, 50 % from 0.039 /
0.045 / 0.043 m to 0.029 / 0.024 / 0.043 m (seeds 0-2; 0.054 / 0.045 / 0.053 m without the
discount) and seeds 0-19 to a mean ratio of 0.992 against one pixel's reach (0.975 against
no discount). ``benchmarks/depth_quality.py`` reports it on held-out seeds 100-149, where the
two-pixel reach is neutral (mean ratio 1.004 against one pixel's, 0.996 against no
discount). A non-directional variant (any brighter neighbour, the MRF's data cost lowered by
a share of the difference) lost up to 3.5 times on textured far walls of ``street``, where a
bright pixel of a surface is next to dimmer pixels of the same surface.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d

__all__ = ["HALO_POWER", "HALO_RATIO", "HALO_SLACK", "halo_discount"]

#: a slice's value below this share of a 4-neighbour's reads as that neighbour's halo
HALO_RATIO = 0.35
#: the discount ``(z / (HALO_RATIO * m)) ** HALO_POWER``
HALO_POWER = 2.0
#: a halo two pixels deep: the next pixel away may hold up to this multiple of the value
HALO_SLACK = 1.2


def halo_discount(z: np.ndarray, ratio: float = HALO_RATIO,
                  power: float = HALO_POWER) -> np.ndarray:
    """Evidence with the per-slice TV's halo discounted.

    Every test reads ``y``, each slice plus its two neighbours along the slices. For each
    pixel ``p`` and slice, ``m`` is the largest ``y`` among its 4-neighbours ``q`` beyond
    which, on the opposite side, ``y`` falls off: the opposite neighbour (``p - (q - p)``,
    zero beyond the image) is below half of ``p``'s, or it holds at most :data:`HALO_SLACK`
    times ``p``'s and the pixel after it (``p - 2 (q - p)``) is below half (a halo two pixels
    deep). Where ``y < ratio * m`` at ``p`` (and ``z > 0``), ``z`` becomes
    ``z * (y / (ratio * m)) ** power``; everything else is unchanged.

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
    About eight ``(K, N1, N2)`` blocks at its peak (the summed slices and their padded copy,
    the half and slack levels, the neighbours' maximum, the result and temporaries), all
    freed before the BP allocates its own eleven; 1.3 s for 256 x 256 x 200 float32 on one
    core (the MRF's time at 64 x 64 is unchanged within its noise, 0.25 s for 208 slices).
    """
    if not 0.0 < ratio <= 1.0 or power < 0.0:
        raise ValueError("halo ratio must be in (0, 1] and power >= 0")
    z = np.asarray(z)
    if z.ndim != 3:
        raise ValueError("z must have shape (K, N1, N2)")
    n1, n2 = z.shape[1:]
    # the tests read each slice with its two neighbours added: a return spans two or three
    # slices, and a factor that differed between them would move its peak
    zp = uniform_filter1d(z, 3, axis=0, mode="constant") * z.dtype.type(3.0)
    pad = np.pad(zp, ((0, 0), (2, 2), (2, 2)))

    def shifted(dy: int, dx: int) -> np.ndarray:
        return pad[:, 2 + dy:2 + dy + n1, 2 + dx:2 + dx + n2]

    half = zp * z.dtype.type(0.5)
    slack = zp * z.dtype.type(HALO_SLACK)
    source = np.zeros_like(z)
    for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        q, once, twice = shifted(dy, dx), shifted(-dy, -dx), shifted(-2 * dy, -2 * dx)
        falls = (once < half) | ((once <= slack) & (twice < half))
        np.maximum(source, np.where(falls, q, 0), out=source)
    scale = z.dtype.type(ratio) * source
    lowered = (zp > 0) & (zp < scale) & (z > 0)
    out = z.copy()
    out[lowered] = z[lowered] * (zp[lowered] / scale[lowered]) ** z.dtype.type(power)
    return out
