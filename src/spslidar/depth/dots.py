"""One- and two-pixel objects: a strong return that no neighbour shares, kept against the
MRF (the MRF's last step).

The MRF's smoothness makes a pixel whose depth differs from all four neighbours pay the
truncation ``T`` four times (about two noise maxima, :func:`~.mrf.auto_truncation`), and the
per-slice TV of the reconstruction (eq. 18) has already spread the surface around it into
its own profile: a bright wall's slice holds, at a one-pixel dot surrounded by that wall,
most of the dot's own evidence. So a dot whose return stands far above any noise maximum is
still given the wall. The line rules (:mod:`.lines`) keep a dot only where it lines up with
others. Measured on a wall at 2 m with 10 % of its pixels at depths drawn from 1-3 m (not a
scene of the project's; 64 x 64, m_n 5 and 10, 25 % patterns, seeds 1-2): the MRF overrode
56-73 pixels per measurement that argmax had right, at 6.6-15 noise maxima each, and was
1.12-1.37 times argmax's RMSE.

:func:`keep_dots` keeps a pixel's argmax where the MRF moved it, its argmax belongs to a
group of at most :data:`DOT_SIZE` pixels (4-neighbours joined where their argmax slices are
within one of each other: the line rules' grouping, :func:`.lines._groups`, a
connected-components pass of :mod:`scipy.sparse.csgraph`), its evidence there reaches
:data:`DOT_LEVEL` times the block's median noise maximum ``nu``, and it is at least the
pixel's evidence at the MRF's label (the pixel's own profile prefers it). Half of the
profiles' noise maxima are below ``nu``, so a dot stands six times above the typical one; a
halo of a bright neighbour is at that neighbour's slice, so it is part of the neighbour's
group, not a dot. The rule reads the evidence only: no library models the per-slice TV's
spread around a dot.

Chosen on 2026-12-02 (``benchmarks/depth_quality.py``'s cached slices; 64 x 64, m_n 5 and
10, 25 and 50 % patterns) among group sizes 1-3, levels 2, 3, 4, 6 and 8 (of ``nu``, and of
the median noise maximum more than 8 slices from each tallest return) and three tests
against the label (none; the evidence at the label; the same halo-discounted), on two scenes
that are not the project's (the dots above and a text image at 1.5 / 2.5 m whose letters'
1-2 pixel pieces the MRF gave the wall behind; seeds 1-2), the seven built-in scenes at m_n
1, 5 and 10 (seed 0) and procedural seeds 150-174. On those, against the MRF without this
step: the two outside scenes from 10 of 16 measurements more than 5 % worse than argmax
(median ratio 1.097, worst 1.371) to 2 (median 0.999, worst 1.059, the text at m_n = 10,
25 %); the built-ins and procedural seeds unchanged within 0.4 %. Without the test against
the label the camera at m_n = 5, 25 % lost a pixel to a 6.5 ``nu`` spike beside its own
surface's 8.4 (1.23 times the MRF); at level 3 the street at m_n = 1, 50 % lost 3.1 times, at
2 the room 7-12 times.

Held out: procedural seeds 100-124 (100 measurements) unchanged (at level 4 seed 112 lost
27 %); four more outside scenes (32 measurements: a slanted floor with 3 % dark and bright
dots in front, 2 x 2 blobs on a wall, dark dots in front of a bright wall, a photograph of
coins as depth) unchanged but for 3 measurements better by 0.2-1.1 %: their dots are 1-4
``nu``, below any level the built-ins allow, and the MRF stays up to 4.1 times argmax there
(``docs/user_guide/known_limits.md``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["DOT_LEVEL", "DOT_SIZE", "argmax_groups", "keep_dots"]

#: the most pixels a group of argmax returns may hold and still be a dot
DOT_SIZE = 2
#: the least evidence of a dot, in median noise maxima
DOT_LEVEL = 6.0


def argmax_groups(a: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Per pixel, the size of its group: the pixels joined to it through 4-neighbours whose
    slices ``a`` differ by at most one.

    Parameters
    ----------
    a : ndarray of int, shape (Q,)
        Each pixel's slice (row-major over ``shape``).
    shape : tuple of int
        ``(N1, N2)``, with ``N1 * N2 == Q``.

    Returns
    -------
    ndarray of int, shape (Q,)
    """
    from .lines import _groups

    _, group, _ = _groups(np.ones(len(a), dtype=bool), np.asarray(a), shape, step=1,
                          diagonals=False)
    return np.bincount(group)[group]


def keep_dots(a: np.ndarray, label: np.ndarray, z: np.ndarray, nu: float,
              shape: tuple[int, int], size: int = DOT_SIZE, level: float = DOT_LEVEL
              ) -> tuple[np.ndarray, int]:
    """The labels with each dot's argmax kept (see the module docstring).

    Parameters
    ----------
    a : ndarray of int, shape (Q,)
        Each pixel's argmax slice.
    label : ndarray of int, shape (Q,)
        The MRF's labels so far.
    z : ndarray, shape (Q, K)
        Evidence (the pulse-matched profile in noise units).
    nu : float
        The block's median noise maximum.
    shape : tuple of int
        ``(N1, N2)``.
    size, level : int, float
        :data:`DOT_SIZE`, :data:`DOT_LEVEL`.

    Returns
    -------
    label : ndarray of int, shape (Q,)
        A new array.
    kept : int
        How many pixels were given their argmax.
    """
    rows = np.arange(label.size)
    za = z[rows, a]
    moved = (label != a) & (za >= level * nu) & (za >= z[rows, label])
    if not moved.any():
        return label.copy(), 0
    keep = moved & (argmax_groups(a, shape) <= size)
    return np.where(keep, a, label), int(keep.sum())
