"""Image-space operators: the 2-D finite-difference gradient (for TV) and an orthonormal
wavelet transform (for l1 sparsity). Both act on column blocks ``(Ny*Nx, K)`` whose columns are
images flattened in C order, one per range slice.
"""

from __future__ import annotations

import numpy as np

from ..arrays import pair_shape
from . import parallel as _parallel
from .base import LinearOperator


def forward_differences_into(
    u: np.ndarray, down: np.ndarray, right: np.ndarray, rows: tuple[int, int] | None = None
) -> None:
    """The two components of :class:`Gradient2D` written into preallocated arrays.

    ``down[i, j] = u[i + 1, j] - u[i, j]`` (zero on the last row) and ``right[i, j] =
    u[i, j + 1] - u[i, j]`` (zero on the last column), for ``u``, ``down``, ``right`` of shape
    ``(Ny, Nx, K)``; only image rows ``rows = (a, b)`` when given (reading row ``b`` of ``u``
    too), so that bands of rows can be filled concurrently. No temporaries.
    """
    ny = u.shape[0]
    a, b = (0, ny) if rows is None else rows
    e = min(b, ny - 1)  # rows with a vertical difference
    if e > a:
        np.subtract(u[a + 1 : e + 1], u[a:e], out=down[a:e])
    if b == ny:
        down[-1] = 0
    np.subtract(u[a:b, 1:], u[a:b, :-1], out=right[a:b, :-1])
    right[a:b, -1] = 0


class Gradient2D(LinearOperator):
    """Forward-difference gradient with Neumann boundary, ``R^{Q} -> R^{2Q}``.

    ``G x = [D_y x; D_x x]`` where ``D_y`` and ``D_x`` take forward differences along image rows
    and columns, with the last difference set to zero (Neumann). Its adjoint is the negative
    divergence. The isotropic TV of eq. (18) is ``sum_q sqrt((D_y x)_q^2 + (D_x x)_q^2)``.

    Parameters
    ----------
    shape : (Ny, Nx)
    dtype : dtype
        The operator's dtype (default float64); products keep the precision of their input
        (``result_type(x.dtype, dtype)``).
    """

    def __init__(self, shape: tuple[int, int], dtype=np.float64):
        self.image_shape = pair_shape(shape, "Gradient2D's image shape", 1)
        q = self.image_shape[0] * self.image_shape[1]
        super().__init__((2 * q, q), dtype)

    def _matvec(self, x):
        ny, nx = self.image_shape
        k = x.shape[1]
        g = np.empty((2, ny, nx, k), dtype=np.result_type(x.dtype, self.dtype))
        forward_differences_into(x.reshape(ny, nx, k), g[0], g[1])
        return g.reshape(2 * ny * nx, k)

    def _rmatvec(self, y):
        ny, nx = self.image_shape
        k = y.shape[1]
        g = y.reshape(2, ny, nx, k)
        out = np.zeros((ny, nx, k), dtype=np.result_type(y.dtype, self.dtype))
        out[:-1] -= g[0, :-1]
        out[1:] += g[0, :-1]
        out[:, :-1] -= g[1, :, :-1]
        out[:, 1:] += g[1, :, :-1]
        return out.reshape(ny * nx, k)


def no_level_message(shape: tuple[int, int], what: str, becomes: str) -> str:
    """The warning that a wavelet transform of ``shape`` images has no periodized level (an
    odd side), so that ``what`` is ``becomes``: said by :class:`Wavelet2D` (the identity) and by
    :func:`~spslidar.solvers.regularisers.make_wavelet_l1` (the pixel l1), one wording.

    Parameters
    ----------
    shape : (Ny, Nx)
    what : str
        What needs the even side (``"Wavelet2D"``, ``"the wavelet regulariser"``).
    becomes : str
        What it is instead.

    Returns
    -------
    str
    """
    return (f"{what} needs an even image side: at {shape[0]}x{shape[1]} it has no level and is "
            f"{becomes}")


def periodized_levels(ny: int, nx: int) -> int:
    """The periodized levels ``Ny x Nx`` images allow (sides divisible by ``2**level``), at
    most 4: 0 where a side is odd."""
    levels = 0
    while levels < 4 and ny % 2 ** (levels + 1) == 0 and nx % 2 ** (levels + 1) == 0:
        levels += 1
    return levels


class Wavelet2D(LinearOperator):
    """Orthonormal 2-D discrete wavelet transform (PyWavelets, periodization mode).

    With ``mode='periodization'`` and image sides divisible by ``2**level`` the transform is
    orthonormal, so its adjoint is its inverse (checked by the dot test in the test suite).

    Parameters
    ----------
    shape : (Ny, Nx)
    wavelet : str
        Any orthogonal PyWavelets family (``'haar'``, ``'db2'``, ``'db4'``, ``'sym4'``...).
    level : int, optional
        Decomposition depth, a whole number >= 0 (0: the identity); default: as deep as the
        image sides allow periodized levels (at most 4), but no deeper than PyWavelets'
        ``dwtn_max_level`` for the filter's length (a 16 x 16 image: 4 levels of ``haar``, 2
        of ``db2``, 1 of ``db8``). An odd side allows none: the default is then the identity,
        with a ``UserWarning`` (pass ``level=0`` to ask for it without one).
    dtype : numpy dtype
        The operator's dtype (default float64).

    Notes
    -----
    The Haar transform is computed directly in NumPy on the whole ``(Ny, Nx, K)`` block
    (sums and differences of the four pixels of each 2 x 2 cell, level by level), with the
    same coefficients and the same layout as PyWavelets' ``wavedec2`` + ``coeffs_to_array``
    (checked in the tests); it is about ten times faster than going through PyWavelets,
    which matters to GPSR (two transforms per iteration). Other wavelets use PyWavelets.
    """

    def __init__(self, shape: tuple[int, int], wavelet: str = "haar", level: int | None = None,
                 dtype=np.float64):
        import pywt

        # (a shape of (8.9, 8.9) was taken as 8 x 8, where Gradient2D refused it; level=1.7
        # was a raw TypeError and level=-1 pywt's own error: an audit of 2026-11-30)
        ny, nx = pair_shape(shape, "Wavelet2D's image shape", 1)
        if level is not None:
            from ..arrays import positive_number

            level = positive_number(level, "Wavelet2D's level", integer=True, unit="levels",
                                    zero=True)
        w = pywt.Wavelet(wavelet)
        if not w.orthogonal:
            raise ValueError(f"wavelet {wavelet!r} is not orthogonal")
        max_level = periodized_levels(ny, nx)
        if level is None:
            level = max(1, min(max_level, pywt.dwtn_max_level((ny, nx), w))) if max_level else 0
            if not max_level:  # (it was silently the identity: an audit of 2026-12-02)
                import warnings

                warnings.warn(no_level_message((ny, nx), "Wavelet2D", "the identity (pass "
                                               "level=0 to ask for it)"), stacklevel=2)
        if level > max_level:
            raise ValueError(f"image {ny}x{nx} allows at most {max_level} periodized levels")
        self.image_shape = (ny, nx)
        self.wavelet = wavelet
        self.level = level
        coeffs = pywt.wavedec2(np.zeros((ny, nx)), wavelet, mode="periodization", level=level)
        _, self._slices = pywt.coeffs_to_array(coeffs)
        super().__init__((ny * nx, ny * nx), dtype)

    def _matvec(self, x):
        import pywt  # (not kept on the operator: a module does not pickle)
        ny, nx = self.image_shape
        k = x.shape[1]
        if self.level == 0:
            return x.copy()
        if self.wavelet == "haar":
            return _haar_split(_haar_forward, x.reshape(ny, nx, k), self.level).reshape(ny * nx, k)
        c = pywt.wavedec2(x.reshape(ny, nx, k), self.wavelet, mode="periodization",
                          level=self.level, axes=(0, 1))
        arr, _ = pywt.coeffs_to_array(c, axes=(0, 1))
        return arr.reshape(ny * nx, k)

    def _rmatvec(self, y):
        import pywt  # (not kept on the operator: a module does not pickle)
        ny, nx = self.image_shape
        k = y.shape[1]
        if self.level == 0:
            return y.copy()
        if self.wavelet == "haar":
            return _haar_split(_haar_inverse, y.reshape(ny, nx, k), self.level).reshape(ny * nx, k)
        c = pywt.array_to_coeffs(y.reshape(ny, nx, k), self._slices, output_format="wavedec2")
        return pywt.waverec2(c, self.wavelet, mode="periodization", axes=(0, 1)).reshape(ny * nx, k)


def _haar_split(fn, x: np.ndarray, level: int) -> np.ndarray:
    """``fn(x, level)`` on a ``(Ny, Nx, K)`` block, as two halves of the K columns run
    concurrently inside a :func:`~spslidar.operators.parallel.parallel` context (the
    transform acts on each column separately, so the result is the same)."""
    dt = x.dtype if x.dtype.kind == "f" else np.dtype(np.float64)
    k = x.shape[2]
    if k < 2 or x.size < _parallel.BAND_MIN_SIZE or _parallel.current() is None:
        return fn(x, level)
    out = np.empty(x.shape, dtype=dt)
    halves = [slice(0, k // 2), slice(k // 2, k)]
    _parallel.run_parts(lambda i: fn(x[:, :, halves[i]], level, out[:, :, halves[i]]), 2)
    return out


def _haar_forward(x: np.ndarray, level: int, out: np.ndarray | None = None) -> np.ndarray:
    """Orthonormal 2-D Haar analysis of a ``(Ny, Nx, K)`` block, laid out as PyWavelets'
    ``coeffs_to_array(wavedec2(x, 'haar', mode='periodization', level, axes=(0, 1)))``.

    Per level, with ``a_rc`` the pixel of parity (row r, column c) of each 2 x 2 cell:
    approximation ``(a00 + a01 + a10 + a11) / 2``, detail along rows ('da', stored below the
    approximation) ``(a00 + a01 - a10 - a11) / 2``, along columns ('ad', stored right of it)
    ``(a00 - a01 + a10 - a11) / 2`` and diagonal ('dd') ``(a00 - a01 - a10 + a11) / 2``.
    """
    dt = x.dtype if x.dtype.kind == "f" else np.dtype(np.float64)
    if out is None:
        out = np.empty(x.shape, dtype=dt)
    half = dt.type(0.5)
    a = x if x.dtype == dt else x.astype(dt)  # integers: their sums computed in float
    for _ in range(level):
        h, w = a.shape[0] // 2, a.shape[1] // 2
        s0 = a[0::2, 0::2] + a[0::2, 1::2]  # even rows: column-pair sums and differences
        d0 = a[0::2, 0::2] - a[0::2, 1::2]
        s1 = a[1::2, 0::2] + a[1::2, 1::2]  # odd rows
        d1 = a[1::2, 0::2] - a[1::2, 1::2]
        np.subtract(s0, s1, out=out[h : 2 * h, :w])
        np.add(d0, d1, out=out[:h, w : 2 * w])
        np.subtract(d0, d1, out=out[h : 2 * h, w : 2 * w])
        s0 += s1
        out[h : 2 * h, : 2 * w] *= half
        out[:h, w : 2 * w] *= half
        s0 *= half
        a = s0
    out[: a.shape[0], : a.shape[1]] = a
    return out


def _haar_inverse(c: np.ndarray, level: int, out: np.ndarray | None = None) -> np.ndarray:
    """Inverse (= adjoint) of :func:`_haar_forward` (written into ``out`` when given)."""
    dt = c.dtype if c.dtype.kind == "f" else np.dtype(np.float64)
    ny, nx = c.shape[:2]
    h, w = ny >> level, nx >> level
    half = dt.type(0.5)
    a = np.array(c[:h, :w], dtype=dt)
    for lev in range(level):
        ch, cv, cd = c[h : 2 * h, :w], c[:h, w : 2 * w], c[h : 2 * h, w : 2 * w]
        s0 = a + ch  # 2 x (even-row pair sum), and so on
        s1 = a - ch
        d0 = cv + cd
        d1 = cv - cd
        if lev == level - 1 and out is not None:
            nxt = out
        else:
            nxt = np.empty((2 * h, 2 * w) + c.shape[2:], dtype=dt)
        np.add(s0, d0, out=nxt[0::2, 0::2])
        np.subtract(s0, d0, out=nxt[0::2, 1::2])
        np.add(s1, d1, out=nxt[1::2, 0::2])
        np.subtract(s1, d1, out=nxt[1::2, 1::2])
        nxt *= half
        a = nxt
        h, w = 2 * h, 2 * w
    return a
