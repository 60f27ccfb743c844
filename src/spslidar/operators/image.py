"""Image-space operators: the 2-D finite-difference gradient (for TV) and an orthonormal
wavelet transform (for l1 sparsity). Both act on column blocks ``(Ny*Nx, K)`` whose columns are
images flattened in C order, one per range slice.
"""

from __future__ import annotations

import numpy as np

from .base import LinearOperator


class Gradient2D(LinearOperator):
    """Forward-difference gradient with Neumann boundary, ``R^{Q} -> R^{2Q}``.

    ``G x = [D_y x; D_x x]`` where ``D_y`` and ``D_x`` take forward differences along image rows
    and columns, with the last difference set to zero (Neumann). Its adjoint is the negative
    divergence. The isotropic TV of eq. (18) is ``sum_q sqrt((D_y x)_q^2 + (D_x x)_q^2)``.

    Parameters
    ----------
    shape : (Ny, Nx)
    """

    def __init__(self, shape: tuple[int, int], dtype=np.float64):
        self.image_shape = (int(shape[0]), int(shape[1]))
        q = self.image_shape[0] * self.image_shape[1]
        super().__init__((2 * q, q), dtype)

    def _matvec(self, x):
        ny, nx = self.image_shape
        k = x.shape[1]
        u = x.reshape(ny, nx, k)
        g = np.zeros((2, ny, nx, k), dtype=np.result_type(x.dtype, self.dtype))
        g[0, :-1] = u[1:] - u[:-1]
        g[1, :, :-1] = u[:, 1:] - u[:, :-1]
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
        Decomposition depth; default: as deep as the image sides allow (at most 4).
    """

    def __init__(self, shape: tuple[int, int], wavelet: str = "haar", level: int | None = None,
                 dtype=np.float64):
        import pywt

        ny, nx = int(shape[0]), int(shape[1])
        w = pywt.Wavelet(wavelet)
        if not w.orthogonal:
            raise ValueError(f"wavelet {wavelet!r} is not orthogonal")
        max_level = 0
        while max_level < 4 and ny % 2 ** (max_level + 1) == 0 and nx % 2 ** (max_level + 1) == 0:
            max_level += 1
        if level is None:
            level = max(1, min(max_level, pywt.dwtn_max_level((ny, nx), w))) if max_level else 0
        if level > max_level:
            raise ValueError(f"image {ny}x{nx} allows at most {max_level} periodized levels")
        self.image_shape = (ny, nx)
        self.wavelet = wavelet
        self.level = level
        self._pywt = pywt
        coeffs = pywt.wavedec2(np.zeros((ny, nx)), wavelet, mode="periodization", level=level)
        _, self._slices = pywt.coeffs_to_array(coeffs)
        super().__init__((ny * nx, ny * nx), dtype)

    def _matvec(self, x):
        pywt = self._pywt
        ny, nx = self.image_shape
        k = x.shape[1]
        if self.level == 0:
            return x.copy()
        c = pywt.wavedec2(x.reshape(ny, nx, k), self.wavelet, mode="periodization",
                          level=self.level, axes=(0, 1))
        arr, _ = pywt.coeffs_to_array(c, axes=(0, 1))
        return arr.reshape(ny * nx, k)

    def _rmatvec(self, y):
        pywt = self._pywt
        ny, nx = self.image_shape
        k = y.shape[1]
        if self.level == 0:
            return y.copy()
        c = pywt.array_to_coeffs(y.reshape(ny, nx, k), self._slices, output_format="wavedec2")
        return pywt.waverec2(c, self.wavelet, mode="periodization", axes=(0, 1)).reshape(ny * nx, k)
