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
discount).

Where the bright region is far brighter, its halo reaches a third pixel: in the room at
m_n = 5, 50 %, seed 9, the wall's slice reads 26.4 on the wall, then 4.4, 3.2 and 3.2 on the
dark shelf's first three columns, and the MRF gave four pixels of the shelf's edge column the
wall 1.2 m behind (RMSE 0.045 m). A three-pixel reach counts only below
:data:`HALO_DEEP_RATIO` (0.2) of the bright neighbour, only where its fall-off lies inside the
image, and with the neighbour's value taken as its largest over a return's three slices, so
that one return gets one factor (without that, a bright row of the noiseless ``street``'s
textured wall moved a dim row's return by a bin). Measured on the same cached
reconstructions as a whole MRF (2026-11-27), against the two-pixel reach: the room at
m_n = 5, 50 %, seeds 0-15, from 14 to 16 at 0.03 m or below (seeds 9 / 13: 0.045 / 0.038 ->
0.027 / 0.026 m; chosen there), fresh seeds 16-31 2 better, none worse; the choice set
(procedural 0-19 at m_n 5 and 10 and the built-in motorcycle, room and street at m_n 1, 5 and
10, seeds 0-2: 150 measurements) a geometric-mean ratio of 0.994 (7 better, 5 worse by more
than 2 %, the worst 1.15); held out, procedural 100-149 (280 measurements at m_n 1-10) 0.998
(27 better, 20 worse, the worst 1.14: seed 116 at m_n = 1, 50 %). Tried: the reach at the
first two pixels' ratio, 0.35 (choice set 0.989, held out 1.000), at 0.25 (0.991 / 1.000),
four pixels deep (choice set worst 1.16), and the image's border taken as a fall-off at three
pixels (held out worst 1.16, a steep side wall at the border). A
non-directional variant (any brighter neighbour, the MRF's data cost lowered by
a share of the difference) lost up to 3.5 times on textured far walls of ``street``, where a
bright pixel of a surface is next to dimmer pixels of the same surface.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import maximum_filter1d, uniform_filter1d

__all__ = ["HALO_DEEP_RATIO", "HALO_POWER", "HALO_RATIO", "HALO_SLACK", "halo_discount"]

#: a slice's value below this share of a 4-neighbour's reads as that neighbour's halo
HALO_RATIO = 0.35
#: the discount ``(z / (HALO_RATIO * m)) ** HALO_POWER``
HALO_POWER = 2.0
#: a halo two pixels deep: the next pixel away may hold up to this multiple of the value
HALO_SLACK = 1.2
#: a halo three pixels deep is discounted below this (smaller) share of the bright neighbour
HALO_DEEP_RATIO = 0.2


def halo_discount(z: np.ndarray, ratio: float = HALO_RATIO,
                  power: float = HALO_POWER) -> np.ndarray:
    """Evidence with the per-slice TV's halo discounted.

    Every test reads ``y``, each slice plus its two neighbours along the slices. For each
    pixel ``p`` and slice, ``m`` is the largest ``y`` among its 4-neighbours ``q`` beyond
    which, on the opposite side, ``y`` falls off: the opposite neighbour (``p - (q - p)``,
    zero beyond the image) is below half of ``p``'s, or it holds at most :data:`HALO_SLACK`
    times ``p``'s and the pixel after it (``p - 2 (q - p)``) is below half (a halo two pixels
    deep). Where ``y < ratio * m`` at ``p`` (and ``z > 0``), ``z`` becomes
    ``z * (y / (ratio * m)) ** power``. A halo three pixels deep (the two pixels after ``p``
    at most :data:`HALO_SLACK` times its ``y``, the third, inside the image, below half)
    counts where ``y < HALO_DEEP_RATIO * m``, with that ratio in the factor and ``m`` the
    largest such neighbour over the slice and its two neighbours (one factor for one return).
    Everything else is unchanged.

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
    About eight ``(K, N1, N2)`` blocks at its peak (7.5 measured: the summed slices and their
    padded copy, the half and slack levels, the two reaches' neighbour maxima, the result
    and temporaries), all freed before the BP allocates its own eleven; 1.3 s for 256 x 256
    x 200 float32 on one core, 1.7 times the two-pixel reach alone (measured side by side,
    2026-11-27; the MRF's time at 64 x 64 is unchanged within its noise, 0.25 s for 208
    slices).
    """
    if not 0.0 < ratio <= 1.0 or power < 0.0:
        raise ValueError("halo ratio must be in (0, 1] and power >= 0")
    z = np.asarray(z)
    if z.ndim != 3:
        raise ValueError("z must have shape (K, N1, N2)")
    # the tests read each slice with its two neighbours added: a return spans two or three
    # slices, and a factor that differed between them would move its peak
    zp = uniform_filter1d(z, 3, axis=0, mode="constant") * z.dtype.type(3.0)
    near, deep = _sources(zp)
    deep = maximum_filter1d(deep, 3, axis=0, mode="constant")  # one factor per return
    scale = z.dtype.type(ratio) * near
    np.maximum(scale, z.dtype.type(HALO_DEEP_RATIO) * deep, out=scale)
    del near, deep
    lowered = (zp > 0) & (zp < scale) & (z > 0)
    out = z.copy()
    out[lowered] = z[lowered] * (zp[lowered] / scale[lowered]) ** z.dtype.type(power)
    return out


def _sources(zp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each pixel and slice, the largest 4-neighbour ``q`` of ``zp`` beyond which, on
    the opposite side, ``zp`` falls below half of the pixel's within two pixels (``near``),
    and within exactly three (``deep``: the two pixels after ``p`` hold at most
    :data:`HALO_SLACK` times its value, the third, inside the image, is below half; the
    image's border is not a fall-off this deep, where a surface may simply leave the
    view)."""
    n1, n2 = zp.shape[1:]
    pad = np.pad(zp, ((0, 0), (3, 3), (3, 3)))

    def shifted(dy: int, dx: int) -> np.ndarray:
        return pad[:, 3 + dy:3 + dy + n1, 3 + dx:3 + dx + n2]

    half = zp * zp.dtype.type(0.5)
    slack = zp * zp.dtype.type(HALO_SLACK)
    near, deep = np.zeros_like(zp), np.zeros_like(zp)
    for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        q = shifted(dy, dx)
        once, twice, thrice = (shifted(-k * dy, -k * dx) for k in (1, 2, 3))
        run = (once <= slack) & (twice <= slack)
        np.maximum(near, np.where((once < half) | ((once <= slack) & (twice < half)), q, 0),
                   out=near)
        inside = np.zeros((n1, n2), bool)  # the third pixel lies in the image
        inside[max(3 * dy, 0):n1 + min(3 * dy, 0), max(3 * dx, 0):n2 + min(3 * dx, 0)] = True
        np.maximum(deep, np.where(run & (thrice < half) & inside, q, 0), out=deep)
    return near, deep
