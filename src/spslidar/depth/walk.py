"""The walk of :func:`spslidar.depth.lines.track_lines`: one structure of the labelling
followed beyond its ends, pixel by pixel along its line, with the bridges and stretches that
carry it past pixels whose own evidence fails.

The rules, and the scenes and seeds they were chosen on, are in :mod:`spslidar.depth.lines`'s
docstring; this module holds their code (moved out of it when it reached 700 lines) and the
constants of the bridges and stretches. A walk is a loop over the pixels of one line with a
few tests each, written by hand: no library walks a line through a labelling's evidence.
"""

from __future__ import annotations

import numpy as np

#: :func:`_walk`: the most pixels a straight line's walk bridges to a surface at its own
#: depth (a leg to its table top), and how many slices behind the line they must be labelled
BRIDGE_REACH, BRIDGE_BEHIND = 4, 10
#: :func:`_walk`: where neither that bridge nor a stretch holds, a bridge of up to this
#: many pixels that stands ``STRETCH_CONTRAST`` above its sides on average, not merely above
#: them (a leg under its table top whose top 7-12 rows the TV left at 0.6-2 noise maxima)
BRIDGE_LONG = 12
#: :func:`_walk`: where a walk stops, a stretch of at most ``STRETCH_REACH`` pixels is
#: taken where its summed evidence less ``STRETCH_LEVEL`` a pixel reaches ``STRETCH_TOTAL``
#: and it stands ``STRETCH_CONTRAST`` above its sides on average (in ``nu``; :func:`_stretch`)
STRETCH_REACH, STRETCH_LEVEL, STRETCH_TOTAL, STRETCH_CONTRAST = 16, 0.5, 3.0, 0.3
#: :func:`_walk`: a straight line's walk also bridges up to ``BRIDGE_REACH`` pixels to a
#: surface *nearer* than the line (a pole that ends behind a table top) where each bridged
#: pixel holds, at its own label, less than this share of what its two pixels beside the
#: line hold there (the surface it is labelled with is hidden there, as in
#: :data:`spslidar.depth.gaps.HOLE`: room seed 186 at m_n = 5, 50 %, 0.09-0.2), or less than
#: at the line's slice (the data prefer the line: seed 107, 0.6-0.75 against 0.8-1.2)
OCCLUDED = 0.5


def _walk(zn: np.ndarray, label: np.ndarray, thin: np.ndarray, shape: tuple[int, int],
          centre: np.ndarray, v: np.ndarray, coef: np.ndarray, t: np.ndarray, gap: int,
          window: int, tau: float, lo: float, back: int, contrast: float,
          interior: bool = False) -> int:
    """:func:`~spslidar.depth.lines.track_lines` for one structure (``zn`` the evidence in
    ``nu``): the pixels of its line across the image (one per step of the major coordinate),
    walked outward from both ends, through pixels behind the line that the evidence supports
    and one-pixel-wide pixels (``thin``) on it, never through a surface at the line's depth (a
    table leg's walk would cross the table top and take the top's bleed into the wall above);
    relabels ``label`` in place and returns how many pixels it took."""
    n1, n2 = shape
    k = zn.shape[1]
    major = 0 if abs(v[0]) >= abs(v[1]) else 1
    s = np.arange(n1 if major == 0 else n2)
    tt = (s - centre[major]) / v[major]
    other = np.rint(centre[1 - major] + tt * v[1 - major]).astype(np.int64)
    ks = np.rint(np.polyval(coef, tt)).astype(np.int64)
    inside = (other >= 0) & (other < (n2 if major == 0 else n1)) & (ks >= 1) & (ks < k - 1)
    ys, xs = (s, other) if major == 0 else (other, s)
    flat = np.where(inside, ys * n2 + xs, 0)
    near = np.clip(ks, 1, k - 2)[:, None] + np.arange(-1, 2)  # the line's slice +-1
    around = zn[flat[:, None], near]
    e = np.where(inside, around.max(axis=1), 0.0)
    # the two pixels across the line (its minor coordinate), found once for both readings
    across = [_across(inside, s, other, major, shape, off)[0] for off in (-1, 1)]

    def beside(slices: np.ndarray) -> np.ndarray:
        """The mean of the two pixels across the line, each at the most over ``slices``."""
        return 0.5 * zn[across[0][:, None], slices].max(1) \
            + 0.5 * zn[across[1][:, None], slices].max(1)

    # the same beside the line: a line stands above its sides at its slice, a blob of the
    # reconstruction's bleed does not
    side = beside(near)
    cur = label[flat]
    at_depth = inside & (np.abs(cur - ks) <= gap)
    # on the line: one pixel wide, or with at most one more pixel at its depth within two
    # across it (a pole and its bleed; a table top, crossed by a leg's walk, has four)
    on = at_depth & (thin[flat] | (_across_at_depth(label, ks, s, other, inside, major, shape,
                                                     gap) <= 1))
    behind = inside & (cur > ks + gap)
    front = inside & (cur < ks - gap)  # a nearer surface hides the line there
    # each pixel's evidence at its own label against its two pixels beside the line there:
    # under OCCLUDED, the surface it is labelled with is hidden there (by the line); or
    # under its evidence at the line's slice, which the data then prefer
    lab = np.clip(cur, 1, k - 2)[:, None] + np.arange(-1, 2)
    own = zn[flat[:, None], lab].max(1)
    hidden = inside & ((own < OCCLUDED * beside(lab)) | (own < e))
    ends = np.rint(centre[major] + t * v[major]).astype(np.int64)
    taken: list[int] = []

    def holds(i: int, direction: int) -> bool:  # the evidence tests at pixel i
        ahead = np.arange(i - direction * back, i + direction * (window - back), direction)
        full = ((ahead >= 0) & (ahead < s.size)).all() and inside[ahead].all()
        if full:  # the window leaves out what a nearer surface hides (a leg under its top)
            ahead = ahead[~front[ahead]]
        return bool(behind[i] and e[i] >= lo and full and e[ahead].mean() >= tau
                    and e[i] - side[i] >= contrast)

    def mends(b: int, i: int, j: int) -> bool:  # i, between two of the line's own pixels
        return bool((on[b] or b in taken) and on[j] and abs(int(ks[b]) - int(ks[j])) <= 1
                    and other[b] == other[i] == other[j])

    # along a row or a column at one depth (nothing inside: a line at the gate's first or
    # last slice, which the walk cannot test)
    straight = bool(inside.any()) and np.ptp(other) == 0 and np.ptp(ks[inside]) <= 1
    if interior:  # the gaps between a row's or a column's pieces
        for i in range(ends.min() + 1, ends.max()):
            if not on[i] and behind[i] and (holds(i, 1) or mends(i - 1, i, i + 1)):
                taken.append(i)
    for start, direction in ((ends.max() + 1, 1), (ends.min() - 1, -1)):
        i = start
        while 0 <= i < s.size and inside[i]:
            if holds(i, direction):
                taken.append(i)
            elif not on[i]:
                # one pixel behind the line that fails the tests is stepped over where the
                # line's own pixels hold the next two, and taken where the line runs through
                # it straight and at one depth (a pole's or a leg's weak pixel between two of
                # its pieces)
                j, jj = i + direction, i + 2 * direction
                if not (behind[i] and 0 <= jj < s.size and on[j] and on[jj]):
                    far = cur > ks + BRIDGE_BEHIND
                    # a bridge to the table top a leg stops short of; else a weak stretch
                    # whose summed evidence holds; else a longer bridge to the table top
                    got = _bridge(i, direction, inside, far, at_depth, e, side) if straight \
                        else []
                    if not got and straight:  # or to a nearer surface the line ends behind,
                        # through pixels whose own surface is hidden there
                        got = _bridge(i, direction, inside, far & hidden, front, e, side)
                    bridged = bool(got)
                    if not got:
                        got = _stretch(i, direction, behind, e, side, lo)
                    if not got and straight:
                        got = _bridge(i, direction, inside, far, at_depth, e, side,
                                      BRIDGE_LONG, STRETCH_CONTRAST)
                        bridged = True
                    taken.extend(got)
                    nxt = got[-1] + direction if got else -1
                    # a bridge ends at a surface at the line's depth: the walk goes on only
                    # where that is a piece of the line itself (two pixels one pixel wide),
                    # not a table top
                    two = np.array([nxt, nxt + direction])
                    piece = bool(((two >= 0) & (two < s.size)).all() and on[two].all())
                    if not got or (bridged and not piece):
                        break
                    i = nxt
                    continue
                if mends(i - direction, i, j):
                    taken.append(i)
            i += direction
    for i in taken:  # the best of the line's slice and its two neighbours
        label[flat[i]] = ks[i] - 1 + int(np.argmax(around[i]))
    return len(taken)


def _across(line_px: np.ndarray, s: np.ndarray, other: np.ndarray, major: int,
            shape: tuple[int, int], off: int) -> tuple[np.ndarray, np.ndarray]:
    """Flat indices of the pixels ``off`` across a line's pixels (clipped to the image; 0 off
    the line), and which of them lie inside the image."""
    n1, n2 = shape
    o2 = other + off
    ok = line_px & (o2 >= 0) & (o2 < (n2 if major == 0 else n1))
    o2 = np.clip(o2, 0, (n2 if major == 0 else n1) - 1)
    return np.where(line_px, (s * n2 + o2) if major == 0 else (o2 * n2 + s), 0), ok


def _across_at_depth(label: np.ndarray, ks: np.ndarray, s: np.ndarray, other: np.ndarray,
                     inside: np.ndarray, major: int, shape: tuple[int, int],
                     gap: int) -> np.ndarray:
    """For each pixel of a line, how many of the four pixels one and two across it are
    labelled within ``gap`` slices of the line's slice there."""
    count = np.zeros(s.size, dtype=np.int64)
    for off in (-2, -1, 1, 2):
        flat, ok = _across(inside, s, other, major, shape, off)
        count += ok & (np.abs(label[flat] - ks) <= gap)
    return count


def _bridge(i: int, direction: int, inside: np.ndarray, behind: np.ndarray,
            at_depth: np.ndarray, e: np.ndarray, side: np.ndarray, reach: int = BRIDGE_REACH,
            margin: float = 0.0) -> list[int]:
    """The pixels from ``i`` up to a surface at the line's depth at most ``reach`` pixels on,
    where all are behind the line and their evidence at its slice stands, on average, more
    than ``margin`` above their sides' (a leg that meets its table top); else none."""
    gap_px = []
    for n in range(reach + 1):
        j = i + n * direction
        if not (0 <= j < inside.size and inside[j]):
            return []
        if at_depth[j]:
            break
        if not behind[j]:
            return []
        gap_px.append(j)
    else:
        return []
    if not gap_px or np.mean(e[gap_px]) - np.mean(side[gap_px]) <= margin:
        return []
    return gap_px


def _stretch(i: int, direction: int, behind: np.ndarray, e: np.ndarray, side: np.ndarray,
             least: float) -> list[int]:
    """Where a walk stops at pixel ``i``, the stretch of pixels from ``i`` on whose summed
    evidence at the line's slice holds (a pole's weak middle rows, and its stronger rows
    beyond them); else none.

    Over at most ``STRETCH_REACH`` pixels behind the line (``behind``: so never through its
    own pixels, a surface at its depth or one in front), the stretch ends where
    ``sum (e - STRETCH_LEVEL)`` from ``i`` is largest: the most likely end of a line whose
    pixels hold more than ``STRETCH_LEVEL`` and whose continuation beyond holds less (a
    one-sided CUSUM). It is taken where that sum reaches ``STRETCH_TOTAL``, its mean evidence
    reaches the walk's least (``least``: a strong pole's bleed beyond its end is refused, as
    by the walk), and it stands on average ``STRETCH_CONTRAST`` above its pixels beside the
    line.
    """
    total, best, best_n = 0.0, -np.inf, -1
    for n in range(STRETCH_REACH):
        j = i + n * direction
        if not (0 <= j < behind.size and behind[j]):
            break
        total += e[j] - STRETCH_LEVEL
        if total > best:
            best, best_n = total, n
    if best_n < 0 or best < STRETCH_TOTAL:
        return []
    px = np.arange(best_n + 1) * direction + i
    if np.mean(e[px] - side[px]) < STRETCH_CONTRAST or np.mean(e[px]) < least:
        return []
    return px.tolist()
