"""Reflectivity with the depth held: eq. (18) solved again over the depth map's support.

The solve of eq. (18) regularises each range slice on its own: a slanted surface is a thin
band in each slice, and the slice's TV spreads it over the neighbouring pixels, which lie at
other depths. Summed over each pixel's own return (:func:`spslidar.products.reflectivity_image`)
the image then shows the depth's gradients: the camera scene, of uniform reflectivity 1, read
0.13-1.58 at 64x64 (median 0.94), an audit of 2026-11-28.

Once the depth map is known, the cube has one unknown per pixel: the strength ``r_j`` of the
return at that pixel's delays, with the shape ``h_j(tau)`` the solve gave it there (its
non-negative profile over the depth's bin and one on each side, summing to 1). The data of
eq. (18) are then linear in ``r``,

    C(tau) ~ A (r * h(tau)),   for every gated delay tau,

and the reflectivity image is the solution of that problem with a TV prior on the image
``r`` itself (not on each slice) and ``r >= 0`` (:func:`refit_reflectivity`). It is the
"debiasing" step of compressive sensing (a least-squares fit on the support a first solve
found) with the image prior a reflectivity map calls for; nothing in PyLops, PyProximal or
scikit-image fits a cube held to a support, so :class:`PlacedReturns` writes the operator
and the solve is spslidar's own FISTA + TV.

Measured (2026-12-01; the weight, :data:`EDGE_BINS` and :data:`APART_PIXELS` chosen on the
camera, the steps and the fence at m_n = 1-10, seeds 0-1): the default run (camera 64x64,
m_n = 10, 25 % patterns) reads its uniform reflectivity of 1 over 5-95 % of the pixels at
0.58-1.20 by the window's sum, 0.93-1.07 refitted (seeds 0-1), an RMSE against the truth of
0.205 -> 0.045 on the pixels whose depth is right. On scenes nobody tuned it on (procedural
200-209, m_n = 5 and 10 at 25 %, m_n = 5 at 50 %: 30 measurements) the refit's RMSE is
0.34-0.70 times the window's (median 0.53). Where it loses (an outside audit): a textured
plane (a photograph, a checkerboard: 1.01-1.26 times the window's RMSE), a dark surface at
low signal-to-noise (a 0.1 wall behind a bright box 7.5 cm before it, 32x32 at 2047 bits:
1.48 times, the wall read 2.8 times its reflectivity), because each pixel's shape is read
off its own noisy profile and the fit follows that noise upwards.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .operators.base import LinearOperator

__all__ = ["APART_PIXELS", "EDGE_BINS", "REFIT_ITERATIONS", "REFIT_SCALE", "PlacedReturns",
           "apart", "depth_edges", "refit_reflectivity", "return_shapes"]

#: FISTA iterations of the refit, warm-started from the window's sum (the default run's
#: camera: an RMSE against the truth of 0.061 / 0.045 / 0.047 after 10 / 20 / 100, the steps
#: 0.022 / 0.023 / 0.023; 2026-12-01)
REFIT_ITERATIONS = 20

#: a cube's value further than this (pixels) from every window at its delay is another
#: surface's return, taken out of the refit's data (:func:`apart`)
APART_PIXELS = 2

#: neighbours whose return delays differ by more than this many bins are on two surfaces:
#: the refit's TV does not join them (:func:`depth_edges`)
EDGE_BINS = 10

#: the refit's TV weight over the noise that reaches its prox (the main solve's noise level
#: times each pixel's shape norm); chosen among 0.25-4 on the camera and the steps at
#: m_n = 1 and 10, on the rule's first version (an isotropic TV, nothing taken out: the
#: camera's RMSE at m_n = 1 0.094 / 0.052 / 0.035 at 0.25 / 1 / 2, the steps' at m_n = 10
#: 0.055 / 0.033 / 0.037: 1 for both)
REFIT_SCALE = 1.0


class PlacedReturns(LinearOperator):
    """``r -> A (r[:, None] * H)``, flattened: eq. (18)'s operator applied to a cube whose
    pixel ``j`` holds a return of strength ``r_j`` shaped ``H[j, :]`` over the delays.

    Parameters
    ----------
    op : LinearOperator
        The ``(M, Q)`` operator of eq. (18) (after QCR, or the plain one).
    shapes : ndarray, shape (Q, K)
        Each pixel's return shape over the ``K`` delays of the data (rows of zeros for
        pixels without a return).

    Notes
    -----
    Its output is the ``(M, K)`` data block read row by row (``C.reshape(-1)``), so a
    solver sees a problem of one column. ``||B||^2 <= ||A||^2 max_j ||H_j||^2``
    (:meth:`lipschitz_bound`).
    """

    def __init__(self, op: LinearOperator, shapes: np.ndarray):
        shapes = np.asarray(shapes)
        if shapes.ndim != 2 or shapes.shape[0] != op.shape[1]:
            raise ValueError(f"shapes must be ({op.shape[1]}, K) for an operator of "
                             f"{op.shape[1]} pixels, got {shapes.shape}")
        super().__init__((op.shape[0] * shapes.shape[1], op.shape[1]), op.dtype)
        self._op = op
        self._shapes = shapes.astype(op.dtype)

    def _matvec(self, x: np.ndarray) -> np.ndarray:
        cols = [np.asarray(self._op.matvec(x[:, j:j + 1] * self._shapes)).reshape(-1)
                for j in range(x.shape[1])]
        return np.stack(cols, axis=1)

    def _rmatvec(self, y: np.ndarray) -> np.ndarray:
        m, k = self._op.shape[0], self._shapes.shape[1]
        cols = [np.einsum("qk,qk->q", np.asarray(self._op.rmatvec(y[:, j].reshape(m, k))),
                          self._shapes) for j in range(y.shape[1])]
        return np.stack(cols, axis=1)

    def lipschitz_bound(self, op_norm_sq: float) -> float:
        """``||A||^2 max_j ||H_j||^2``, an upper bound of ``||B||^2`` from ``||A||^2``:
        ``||B r||^2 = sum_k ||A (r * H_k)||^2 <= ||A||^2 sum_j r_j^2 ||H_j||^2``."""
        norms = np.einsum("qk,qk->q", self._shapes, self._shapes, dtype=np.float64)
        return float(op_norm_sq) * float(norms.max(initial=0.0))


def return_shapes(profiles: np.ndarray, centre: np.ndarray, have: np.ndarray,
                  half: int = 1) -> np.ndarray:
    """Each pixel's return shape: its profile's non-negative values over the delays
    ``centre - half .. centre + half``, summing to 1 (the centre delay alone where those
    hold nothing); rows of zeros where ``have`` is False or the centre lies off the delays.

    Parameters
    ----------
    profiles : ndarray, shape (Q, K)
        The reconstructed cube over the data's delays.
    centre : ndarray of int, shape (Q,)
        Index of each pixel's return delay among the ``K``.
    have : ndarray of bool, shape (Q,)
        Pixels with a return.
    half : int
        Delays on each side of the centre.
    """
    q, k = profiles.shape
    out = np.zeros((q, k))
    rows = np.arange(q)
    on = have & (centre >= 0) & (centre < k)
    for off in range(-half, half + 1):
        idx = centre + off
        ok = on & (idx >= 0) & (idx < k)
        out[rows[ok], idx[ok]] = np.clip(profiles[rows[ok], idx[ok]], 0.0, None)
    total = out.sum(axis=1)
    shaped = total > 0
    out[shaped] /= total[shaped, None]
    bare = on & ~shaped
    out[rows[bare], centre[bare]] = 1.0
    return out


def apart(profiles: np.ndarray, support: np.ndarray, image_shape: tuple[int, int],
          reach: int | None = None) -> np.ndarray:
    """The cube's returns that the refit's model does not hold: its values outside every
    pixel's return window and more than ``reach`` pixels (:data:`APART_PIXELS`, in rows and
    columns) from any pixel whose window holds that delay; zeros elsewhere.

    A second surface (a wall seen through a fence, behind half its pixels) puts returns at
    delays where its pixels have no window: left in the data, the refit gives their light to
    the pixels that do have one there (the fence's wall read 0.27 and 0.51 for 0.15, an RMSE
    of 0.094 against the window's 0.047). The solve's own estimate of them is taken out of
    the data first. What lies within ``reach`` of a window is the solve's TV bleed of that
    return into its neighbours (a slanted surface's band spread sideways), which the data do
    not hold and the refit is there to undo: it is left in.
    """
    from scipy.ndimage import binary_dilation

    reach = APART_PIXELS if reach is None else int(reach)
    ny, nx = image_shape
    k = profiles.shape[1]
    near = binary_dilation(np.asarray(support, dtype=bool).reshape(ny, nx, k),
                           structure=np.ones((2 * reach + 1, 2 * reach + 1, 1), dtype=bool))
    return np.where(near.reshape(-1, k), 0.0, profiles)


def depth_edges(centre: np.ndarray, have: np.ndarray, image_shape: tuple[int, int],
                step: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The refit's TV weights: 1 between neighbouring pixels whose return delays differ by at
    most ``step`` bins (:data:`EDGE_BINS`), 0 across a larger step and beside a pixel
    without a return, so that an object's reflectivity is not smoothed into the surface
    behind it (:class:`~spslidar.solvers.weighted_tv.EdgeWeightedTV`).

    Returns
    -------
    weights_y, weights_x : ndarray, shapes (Ny - 1, Nx) and (Ny, Nx - 1)
    """
    step = EDGE_BINS if step is None else int(step)
    c = np.asarray(centre, dtype=np.int64).reshape(image_shape)
    h = np.asarray(have, dtype=bool).reshape(image_shape)
    wy = (np.abs(c[1:] - c[:-1]) <= step) & h[1:] & h[:-1]
    wx = (np.abs(c[:, 1:] - c[:, :-1]) <= step) & h[:, 1:] & h[:, :-1]
    return wy.astype(np.float64), wx.astype(np.float64)


def refit_reflectivity(op: LinearOperator, data: np.ndarray, solution: np.ndarray,
                       profiles: np.ndarray, centre: np.ndarray, have: np.ndarray,
                       image_shape: tuple[int, int], *, columns: np.ndarray | None = None,
                       sigma_eff: float, op_norm_sq: float | None = None,
                       start: np.ndarray | None = None, scale: float | None = None,
                       iterations: int | None = None, half: int = 1,
                       take_apart: bool = True, floor_share: float = 0.0,
                       floored_factor: int = 1) -> tuple[np.ndarray, dict[str, Any]]:
    """Each pixel's return strength with its delay held: ``min_r 1/2 ||B r - C'||^2 +
    lam TV_w(r)``, ``r >= 0``, ``B`` the :class:`PlacedReturns` of the depth's delays,
    ``C'`` the data without the other surfaces' returns (:func:`apart`) and ``TV_w`` cut
    at the depth's steps (:func:`depth_edges`).

    Parameters
    ----------
    op, data : LinearOperator, ndarray of shape (M, J)
        Eq. (18)'s operator and data, as the depth's solve had them.
    solution : ndarray, shape (Q, J)
        That solve's cube over the data's ``J`` delays.
    profiles : ndarray, shape (Q, K)
        The same cube over the gate's ``K`` consecutive delays (the shapes' source,
        :func:`return_shapes`).
    centre, have : ndarray, shape (Q,)
        Each pixel's return delay (index among the ``K``) and whether it has one.
    image_shape : tuple of int
        The image's rows and columns (``Q`` pixels in all).
    columns : ndarray of int, shape (K,), optional
        The data's column of each of the ``K`` delays, -1 where it was not solved (an
        automatic gate's); delays one code period apart share a column. By default the
        ``K`` delays are the ``J`` columns.
    sigma_eff : float
        The noise level that reached the solve's prox (RMS of ``A^H e``,
        :func:`spslidar.pipeline.weights.noise_level`); 0 for noiseless data, whose weight is
        the floor.
    op_norm_sq : float, optional
        ``||A||^2`` where known (the solve's Lipschitz constant), else a power iteration.
    start : ndarray, shape (Q,), optional
        The warm start (the window's sum; NaN read as 0).
    scale, iterations, half : float, int, int
        The weight over the noise (:data:`REFIT_SCALE`), FISTA's iterations
        (:data:`REFIT_ITERATIONS`, times ``floored_factor`` where the weight is its floor),
        the shape's half width in delays.
    floor_share, floored_factor : float, int
        The weight's floor, a share of ``max |B^H C|`` (the pipeline passes the solve's,
        ``LAM_FLOOR``, 0.3 %), and the factor on the iterations where the floor sets the
        weight (the solve's ``FLOORED_ITERATIONS``, 5): FISTA's slow tail at a small weight
        (noiseless 16x16 steps at 25 % read a correlation with the truth of 0.66 after 20
        iterations, 0.93 after 100).
    take_apart : bool
        Take the other surfaces' returns out of the data first (:func:`apart`): for a TV
        solve, whose bleed the rule reads; a pixel-wise one (l1, wavelets, GPSR) spreads a
        return along its own delays instead, which the rule took for another surface's light
        (the camera through GPSR read a median 0.76 of its reflectivity with it, 0.97
        without, an outside audit of 2026-12-01).

    Returns
    -------
    r : ndarray, shape (Q,)
        The return strengths (the same unit as the cube's); NaN where ``have`` is False or
        the pixel's return lies on no solved delay.
    info : dict
        ``weight``, ``iterations``, ``delays`` (the data's delays a return touches).
    """
    from .solvers import StopRule, get_solver
    from .solvers.weighted_tv import EdgeWeightedTV

    solution = np.asarray(solution, dtype=np.float64)
    profiles = np.asarray(profiles, dtype=np.float64)
    n_data = solution.shape[1]
    cols = (np.arange(profiles.shape[1]) if columns is None
            else np.asarray(columns, dtype=np.int64))
    if cols.shape != (profiles.shape[1],) or cols.max(initial=-1) >= n_data:
        raise ValueError(f"columns must give each of the {profiles.shape[1]} delays a data "
                         f"column below {n_data} (or -1)")
    lagged = return_shapes(profiles, centre, have, half)
    shapes = np.zeros((lagged.shape[0], n_data))
    on = cols >= 0
    np.add.at(shapes.T, cols[on], lagged[:, on].T)  # (aliased delays share a column)
    placed = shapes.any(axis=1)
    data = np.asarray(data)
    far = apart(solution, shapes > 0, image_shape) if take_apart else None
    if far is not None and far.any():  # the other surfaces' returns, as the solve placed them
        data = data - np.asarray(op.matvec(np.ascontiguousarray(far, dtype=op.dtype)))
    used = shapes.any(axis=0)
    r = np.full(shapes.shape[0], np.nan)
    info: dict[str, Any] = {"weight": None, "iterations": 0, "delays": int(used.sum())}
    if not used.any():
        return r, info
    dtype = op.dtype
    B = PlacedReturns(op, shapes[:, used])
    y = np.ascontiguousarray(data[:, used], dtype=dtype).reshape(-1, 1)
    norms = np.einsum("qk,qk->q", shapes, shapes)[placed]
    noise = float(sigma_eff) * float(np.sqrt(norms.mean()))
    lam_max = float(np.abs(np.asarray(B.rmatvec(y))).max(initial=0.0))
    floor = float(floor_share) * lam_max
    lam = max(float(REFIT_SCALE if scale is None else scale) * noise, floor)
    if not lam_max > 0:  # no data at the returns' delays
        r[placed] = 0.0
        info["weight"] = 0.0
        return r, info
    reg = EdgeWeightedTV(tuple(image_shape), *depth_edges(centre, placed, image_shape),
                         nonneg=True)
    L = B.lipschitz_bound(op_norm_sq) if op_norm_sq else None
    x0 = None
    if start is not None:
        x0 = np.nan_to_num(np.asarray(start, dtype=np.float64).ravel(), nan=0.0,
                           posinf=0.0, neginf=0.0).clip(0.0).astype(dtype).reshape(-1, 1)
    if iterations is None:
        iterations = REFIT_ITERATIONS * (int(floored_factor) if lam == floor else 1)
    x, sinfo = get_solver("fista")(stop=StopRule(max_iter=int(iterations), rtol=0.0),
                                   **({"L": L} if L else {})).solve(B, y, reg, lam, x0=x0)
    r[placed] = np.asarray(x, dtype=np.float64).ravel()[placed]
    info.update(weight=lam, iterations=int(sinfo.iterations))
    return r, info
