"""Depth as the labelling of a Markov random field over the image grid (loopy belief
propagation over every range slice).

Each pixel takes one of the ``K`` gated slices as its label. The energy of a labelling ``k`` is::

    E(k) = sum_p D_p(k_p) + sum_{p~q} min(s |k_p - k_q|, T)

with the data cost ``D_p(k) = -z_p(k)``, the pulse-matched profile in units of its noise
scale (:func:`~spslidar.depth.profile.pulse_filter`, :func:`~spslidar.depth.profile.noise_scale`;
for Gaussian noise a matched-filter log-likelihood up to a constant), and a truncated-linear
smoothness over the 4-neighbour grid: small depth steps (slanted surfaces) cost little, a depth
edge costs at most ``T``, so surfaces stay piecewise smooth while edges, poles and thin slanted
bands survive wherever their own data supports them. A weak pixel (a dark or distant surface
whose return is below the noise spikes of its own profile) is outvoted by its neighbours, while
a strong one keeps its own depth. ``T`` is set from the data (:func:`auto_truncation`): half the
typical noise maximum of a profile, so that a one-pixel line, which pays ``T`` on two sides,
survives wherever its evidence beats its profile's noise.

Contrast-sensitive weights (a weaker coupling across edges of the return-strength image, where
depth edges are likely) were tried and left out: a weak pixel's peak is mostly noise, so the
guide image is noise exactly where the prior matters, and every weight tried made the
motorcycle worse. An 8-connected grid was worse too.

The energy is minimised by min-sum loopy belief propagation with the linear-time message
update of Felzenszwalb and Huttenlocher (a lower envelope by two running minima along the
range axis), vectorised over the whole image, so every iteration costs a few passes over the
``(N, N, K)`` block.
"""

from __future__ import annotations

import numpy as np

from .base import DepthContext, DepthEstimate, DepthEstimator, option
from .profile import (
    grid_shape,
    index_to_depth,
    no_return,
    noise_maxima,
    noise_scale,
    pulse_filter,
    refine_subbin,
    typical_noise_maximum,
)

__all__ = ["MRFDepth", "min_sum_bp", "truncated_linear_envelope"]


def truncated_linear_envelope(h: np.ndarray, slope: float, cap: float,
                              axis: int = -1) -> np.ndarray:
    """``m(k) = min_j h(j) + min(slope |k - j|, cap)`` along ``axis``, normalised to
    ``min_k m(k) = 0``.

    A forward and a backward pass ``m(k) = min(m(k), m(k -+ 1) + slope)`` give the lower
    envelope of the cones ``h(j) + slope |k - j|`` in ``O(K)``; the truncation is a minimum
    with ``min h + cap``.

    References
    ----------
    P. F. Felzenszwalb and D. P. Huttenlocher, "Efficient belief propagation for early
    vision", Int. J. Comput. Vis. 70(1), 41-54 (2006), Sec. 3.
    """
    lead = np.moveaxis(np.asarray(h), axis, 0)
    out = np.empty(lead.shape, lead.dtype)
    _envelope(lead, slope, cap, out)
    return np.moveaxis(out, 0, axis)


def _envelope(h: np.ndarray, slope: float, cap: float, out: np.ndarray) -> None:
    """:func:`truncated_linear_envelope` along axis 0, into ``out`` (not aliasing ``h``).

    The passes loop over the labels with whole-image operations: with the labels leading,
    each step is one vectorised operation over an image plane, several times faster than
    ``np.minimum.accumulate`` along the label axis.
    """
    k = h.shape[0]
    s = h.dtype.type(slope)
    tmp = np.empty_like(h[0])
    out[0] = h[0]
    for i in range(1, k):
        np.add(out[i - 1], s, out=tmp)
        np.minimum(h[i], tmp, out=out[i])
    for i in range(k - 2, -1, -1):
        np.add(out[i + 1], s, out=tmp)
        np.minimum(out[i], tmp, out=out[i])
    floor = h.min(axis=0)
    floor += h.dtype.type(cap)
    np.minimum(out, floor, out=out)
    out -= out.min(axis=0)


def min_sum_bp(cost: np.ndarray, slope: float, cap: float, iterations: int,
               patience: int = 2) -> tuple[np.ndarray, int]:
    """Beliefs of min-sum loopy BP on a 4-connected grid with truncated-linear pairwise costs.

    Parameters
    ----------
    cost : ndarray, shape (K, N1, N2)
        Data cost of each label (leading axis) at each pixel.
    slope, cap : float
        Pairwise cost ``min(slope |k_p - k_q|, cap)``.
    iterations : int
        Cap on the synchronous (parallel) message-passing sweeps.
    patience : int
        Stop once the MAP labels have not changed for this many sweeps (0: run all).

    Returns
    -------
    belief : ndarray, shape (K, N1, N2)
        Beliefs (data cost plus incoming messages); the MAP estimate is their argmin.
    sweeps : int
        Sweeps run.

    Notes
    -----
    No library in the project's stack (SciPy, scikit-image) runs inference on a grid MRF
    with many labels, and graph-cut libraries would add a compiled dependency for a
    64 x 64 x K problem that vectorised BP solves in a fraction of a second. All blocks are
    preallocated (about eleven ``(K, N1, N2)`` blocks in all).
    """
    k, n1, n2 = cost.shape
    # msg[0]: from the pixel above, [1]: from below, [2]: from the left, [3]: from the right;
    # each sweep writes the next messages into `new` from `msg`, then the two swap
    msg = np.zeros((4, k, n1, n2), cost.dtype)
    new = np.zeros_like(msg)
    belief = cost.copy()
    h = np.empty_like(cost)
    label = np.argmin(belief, axis=0)
    # (message written, message left out of the sender's belief, senders, receivers)
    plan = []
    if n1 > 1:
        plan += [(0, 1, np.s_[:, :-1], np.s_[:, 1:]), (1, 0, np.s_[:, 1:], np.s_[:, :-1])]
    if n2 > 1:
        plan += [(2, 3, np.s_[:, :, :-1], np.s_[:, :, 1:]),
                 (3, 2, np.s_[:, :, 1:], np.s_[:, :, :-1])]
    still = sweeps = 0
    while sweeps < int(iterations):
        for target, back, send, recv in plan:
            hs = np.subtract(belief[send], msg[back][send], out=h[send])
            _envelope(hs, slope, cap, new[target][recv])
        msg, new = new, msg
        np.sum(msg, axis=0, out=belief)
        belief += cost
        sweeps += 1
        if patience > 0:
            new_label = np.argmin(belief, axis=0)
            still = still + 1 if np.array_equal(new_label, label) else 0
            label = new_label
            if still >= patience:
                break
    return belief, sweeps


class MRFDepth(DepthEstimator):
    """MAP depth of a truncated-linear MRF over the image, by loopy belief propagation.

    Parameters
    ----------
    smoothness : float
        Slope ``s`` of the pairwise cost per bin of depth difference, in units of the noise
        scale ``sigma`` (see :func:`~spslidar.depth.profile.noise_scale`).
    truncation : float or None
        Cap ``T`` of the pairwise cost (the price of a depth edge), in units of ``sigma``;
        None (default): :func:`auto_truncation`.
    iterations : int
        Cap on the BP sweeps; BP stops earlier once the labels are stable for 2 sweeps
        (8-12 sweeps on the built-in scenes).
    subbin : bool or None
        Place the return below the chosen slice (:func:`~.profile.refine_subbin`; ``None``:
        follow ``ctx.subbin``).
    lines : bool
        Keep the argmax of pixels that line up in front of the MRF's surface (a pole, a wire,
        a leg the smoothness would give the wall behind), then of those that continue a
        one-pixel structure the labelling holds in part, then follow each such structure
        beyond its ends where the evidence at its slice holds (:mod:`spslidar.depth.lines`),
        take lines hanging from a surface's end (:mod:`spslidar.depth.hang`) and walk them on
        in turn; ``info['thin_structure_pixels']`` counts the pixels relabelled. Last, a pixel
        that holds its own surface as strongly as beside the line gets its label back
        (:mod:`spslidar.depth.own_surface`; ``info['own_surface_pixels']``). Default True.
    gaps : bool
        With ``lines``, also keep the argmax of pixels that line up *behind* the MRF's
        surface in a one-pixel gap between two sides of it that the pixel's evidence shows
        missing there (a fence's gap onto the wall behind; :mod:`spslidar.depth.gaps`;
        ``info['gap_pixels']``, counted in ``thin_structure_pixels`` too). Default True.
    halo : bool
        Discount, in the MRF's data cost only, a pixel's evidence in a slice where it reads as
        the halo the per-slice TV leaves around a brighter neighbour's region
        (:func:`spslidar.depth.halo.halo_discount`). Default True.
    corners : bool
        Give a region's corner that the per-slice TV rounded off back to the region where
        the evidence, read relative to each surface's own level, holds it
        (:mod:`spslidar.depth.corner`; ``info['corner_pixels']``). Default True.
    edges : bool
        Last, give a front region's rim that the per-slice TV wore away (and the surface
        behind filled) back to it where the evidence, relative to each surface's level
        nearby, holds it (:mod:`spslidar.depth.edges`; ``info['edge_pixels']``). Default
        True.
    dots : bool
        Last, keep the argmax of a pixel (or two) whose strong return no neighbour shares
        where the MRF gave it the surface around it, and of weaker such dots together where
        noise cannot give as many (:mod:`spslidar.depth.dots`;
        ``info['dot_pixels']``). Default True.
    holes : bool
        Last, keep the argmax of a pixel (or up to four together) that returns nothing at any
        of its neighbours' surfaces, though they return strongly, where the MRF filled that
        hole with the surface around it (an object in front whose own return is weak), the
        holes' argmaxes kept together where noise cannot give as many
        (:mod:`spslidar.depth.holes`; ``info['hole_pixels']``). Default True.
    low_confidence : float
        Confidence below which a pixel is flagged.

    Notes
    -----
    Confidence is the pixel's BP pseudo-marginal of its depth: ``exp(-(B - min B))``
    normalised over the labels and summed over the chosen slice and its two neighbours
    (``B`` the beliefs, in units of ``sigma``). It is high where the pixel's own return or
    its agreeing neighbours make the chosen depth clearly better than any other, low where
    another depth is nearly as good.

    Pixels whose profile has no positive value above 5 % of the 99th percentile of all
    peaks (as :func:`~spslidar.depth.argmax.ml_depth`) get NaN and confidence 0.

    Memory: about eleven ``(N1, N2, K)`` float32 blocks (messages, beliefs, temporaries);
    time: 0.2-0.5 s for 64 x 64 x 183 slices.

    References
    ----------
    P. F. Felzenszwalb and D. P. Huttenlocher, "Efficient belief propagation for early
    vision", Int. J. Comput. Vis. 70(1), 41-54 (2006).
    Y. Boykov, O. Veksler and R. Zabih, "Fast approximate energy minimization via graph
    cuts", IEEE TPAMI 23(11), 1222-1239 (2001) (truncated-linear smoothness, discontinuity
    preserving).

    Examples
    --------
    An 8x8 step (slices 5 and 20 of 32 gated delays) over weak noise: its edge is kept.

    >>> import numpy as np
    >>> from spslidar.depth import DepthContext
    >>> from spslidar.depth.mrf import MRFDepth
    >>> from spslidar.forward import delay_to_depth
    >>> lags = np.arange(1000, 1032)  # absolute delays in 100 ps bins
    >>> true = np.where(np.arange(64) % 8 < 4, 5, 20)  # each pixel's slice
    >>> slices = 0.05 * np.random.default_rng(0).random((64, 32))
    >>> slices[np.arange(64), true] += 1.0
    >>> est = MRFDepth().estimate(slices, DepthContext(lags, bin_width=1e-10, shape=(8, 8)))
    >>> np.allclose(est.depth, delay_to_depth(lags[true] + 0.25, 1e-10))
    True
    >>> int(est.low_confidence.sum()), est.info["changed_from_argmax"]
    (0, 0.0)
    """

    name = "mrf"
    LOW_CONFIDENCE = 0.5
    #: slope per slice, chosen on the motorcycle and camera scenes (benchmarks/depth_quality.py)
    SMOOTHNESS = 0.04
    ITERATIONS = 30

    def __init__(self, low_confidence: float | None = None, *,
                 smoothness: float = SMOOTHNESS, truncation: float | None = None,
                 iterations: int = ITERATIONS,
                 subbin: bool | None = None, lines: bool = True, halo: bool = True,
                 corners: bool = True, gaps: bool = True, edges: bool = True,
                 dots: bool = True, holes: bool = True):
        super().__init__(low_confidence)
        self.smoothness = option("smoothness", smoothness)
        self.truncation = None if truncation is None else option("truncation", truncation)
        self.iterations = option("iterations", iterations, integer=True)
        self.subbin = subbin
        self.lines = bool(lines)
        self.halo = bool(halo)
        self.corners = bool(corners)
        self.gaps = bool(gaps)
        self.edges = bool(edges)
        self.dots = bool(dots)
        self.holes = bool(holes)

    def labelling(self, x: np.ndarray, z: np.ndarray, shape: tuple[int, int]
                  ) -> tuple[np.ndarray, np.ndarray, dict]:
        """The MRF's slice per pixel (loopy BP), with the thin structures' argmax kept where
        ``lines``; also the beliefs ``(Q, K)`` and numbers for ``info``. Shared by the
        estimators built on this MRF (``guarded``, ``evidence``)."""
        q, k = x.shape
        later = self.lines or self.corners or self.edges or self.dots or self.holes
        # the block's noise maxima, once: the truncation's and the later steps' typical one
        null = noise_maxima(z) if later or self.truncation is None else None
        cap = (self.truncation if self.truncation is not None
               else auto_truncation(z, null=null))
        if self.halo:  # the per-slice TV's halo around bright regions (halo.py)
            from .halo import halo_discount

            cost = halo_discount(z.T.reshape(k, *shape))  # labels leading; a new array
            np.negative(cost, out=cost)
        else:
            cost = np.ascontiguousarray(-z.T).reshape(k, *shape)
        belief, sweeps = min_sum_bp(cost, self.smoothness, cap, self.iterations)
        belief = belief.reshape(k, q).T
        mrf_label = label = np.argmin(belief, axis=1)
        thin = own = corner = gaps = 0
        if later:  # the block's typical noise maximum
            nu = typical_noise_maximum(null)
        if self.lines or self.dots or self.holes:  # each pixel's own tallest slice
            a = np.argmax(x, axis=1)
        if self.lines:  # lines of argmax returns in front of the MRF's surface (lines.py)
            from .hang import hang_lines, walk_on
            from .lines import extend_lines, thin_structures, track_lines
            from .own_surface import keep_own_surface

            rows = np.arange(q)
            za = z[rows, a]
            keep = thin_structures(a, label, za, nu, shape)
            label = np.where(keep, a, label)
            if self.gaps:  # and lines of them behind it, between two sides (gaps.py)
                from .gaps import gap_lines

                gapped = gap_lines(a, label, z, nu, shape)
                label = np.where(gapped, a, label)
                gaps = int(gapped.sum())
            more = extend_lines(a, label, za, z[rows, label], nu, shape)
            label, tracked = track_lines(z, np.where(more, a, label), nu, shape)
            before_hang = label
            label, hung = hang_lines(z, label, nu, shape)
            if hung:  # a hung line is a structure like any other: walk on from its end,
                # with the hanging rule's test against a code's sidelobes (hang.walk_on)
                walked, _ = track_lines(z, label, nu, shape, within=label != before_hang)
                ok = walk_on(z, label, walked, nu, shape)
                label = np.where(ok, walked, label)
                hung += int(ok.sum())
            tracked += hung
            thin = int(keep.sum() + more.sum()) + tracked + gaps
            # a line does not hide a pixel that holds its own surface (own_surface.py)
            label, own = keep_own_surface(mrf_label, label, z, nu, shape)
        if self.corners:  # a region's corner the per-slice TV rounded off (corner.py)
            from .corner import fill_corners

            label, corner = fill_corners(z, label, nu, shape)
        edge = 0
        if self.edges:  # a front region's rim the per-slice TV wore away (edges.py)
            from .edges import fill_edges

            label, edge = fill_edges(z, label, nu, shape)
        dot = 0
        if self.dots:  # one- and two-pixel objects' returns (dots.py)
            from .dots import keep_dots

            label, dot = keep_dots(a, label, z, nu, shape)
        hole = 0
        if self.holes:  # holes in the neighbours' surfaces the MRF filled (holes.py)
            from .holes import hole_dots

            kept = hole_dots(a, label, z, nu, shape)
            label, hole = np.where(kept, a, label), int(kept.sum())
        return label, belief, {"sweeps": sweeps, "truncation": cap,
                               "thin_structure_pixels": thin, "own_surface_pixels": own,
                               "corner_pixels": corner, "gap_pixels": gaps,
                               "edge_pixels": edge, "dot_pixels": dot,
                               "hole_pixels": hole}

    def estimate(self, slices: np.ndarray, ctx: DepthContext) -> DepthEstimate:
        x = np.asarray(slices, dtype=np.float32)
        q, k = x.shape
        n1, n2 = grid_shape(ctx, q)
        peak = x.max(axis=1).astype(np.float64)
        z = self.evidence(x)
        label, belief, found = self.labelling(x, z, (n1, n2))
        conf = _pseudo_marginal(belief, label)
        subbin = ctx.subbin if self.subbin is None else self.subbin
        index = (refine_subbin(x, label, pulse_width=ctx.pulse_width, lags=ctx.lags)
                 if subbin and k >= 3 else label.astype(np.float64))
        depth = index_to_depth(index, ctx)
        missing = no_return(peak)
        depth[missing] = np.nan
        conf[missing] = 0.0
        strength = x[np.arange(q), label].astype(np.float64)
        changed = float(np.mean(label != np.argmax(x, axis=1))) if q else 0.0
        info = {**found, "changed_from_argmax": changed, "smoothness": self.smoothness,
                "iterations": self.iterations}
        return DepthEstimate(depth, conf, strength, self._flag(depth, conf), info)

    def evidence(self, x: np.ndarray) -> np.ndarray:
        """Per-pixel, per-slice evidence of a return: the pulse-matched profile over its
        noise scale."""
        y = pulse_filter(x)
        return y / np.float32(noise_scale(y))


def auto_truncation(z: np.ndarray, exclude: int = 2, null: np.ndarray | None = None
                    ) -> float:
    """Half the median, over the pixels, of the largest evidence outside each profile's
    tallest return (+-``exclude`` slices): the typical noise maximum of a profile, halved
    (:func:`~.profile.typical_noise_maximum`: over the profiles that hold noise).

    A one-pixel-wide structure pays the truncation ``T`` on its two sides, an isolated pixel
    on four. With ``2 T`` at the typical noise maximum, a thin line survives wherever its
    evidence beats the noise spikes of its own profile, while an isolated spike, paying
    ``4 T``, is outvoted unless it is twice as tall. The noise maximum grows with the number
    of slices (about 2.8 noise scales for 61 slices, 3.6 for 200 on the built-in scenes).
    ``null``, where given, is ``noise_maxima(z, exclude)`` already computed.
    """
    if z.shape[1] <= 2 * exclude + 1:
        return 1.0
    return 0.5 * typical_noise_maximum(noise_maxima(z, exclude) if null is None else null)


def _pseudo_marginal(belief: np.ndarray, label: np.ndarray, half: int = 1) -> np.ndarray:
    """Normalised ``exp(-(B - min B))`` summed over ``label +- half``."""
    q, k = belief.shape
    b = belief - belief.min(axis=1, keepdims=True)
    p = np.exp(-b.astype(np.float64))
    p /= p.sum(axis=1, keepdims=True)
    cols = np.clip(label[:, None] + np.arange(-half, half + 1)[None, :], 0, k - 1)
    cols_ok = np.abs(cols - label[:, None]) <= half
    # clipped duplicates at the edges are counted once
    uniq = np.concatenate([np.ones((q, 1), bool), np.diff(cols, axis=1) != 0], axis=1)
    return np.clip((p[np.arange(q)[:, None], cols] * (cols_ok & uniq)).sum(axis=1), 0.0, 1.0)
