"""Dense DMD pattern sets (the paper's): the rows of the measurement matrix Phi of equation (7).

A DMD only switches mirrors on or off, so every pattern here is non-negative:

* ``gaussian``: the paper's "Gaussian patterns", realised as grey-level transmittances
  ``clip(0.5 + sigma * N(0, 1), 0, 1)`` (displayed on a real DMD by pulse-width modulation over
  the exposure). With the default ``sigma = 0.25`` about 4.6 % of the values are clipped.
* ``bernoulli``: binary patterns, each mirror on with probability ``on_fraction``.
"""

from __future__ import annotations

import numpy as np

from ..errors import ConfigError
from ..operators.base import _product, float_matrix
from ..randomness import as_generator
from .base import PatternOperator

PATTERN_KINDS = ("gaussian", "bernoulli")


def n_patterns_for(compression: float, n_pixels: int) -> int:
    """Number of patterns ``M = round(compression * Q)`` (at least 1).

    Parameters
    ----------
    compression : float
        The paper's compression proportion M / Q, in (0, 1].
    n_pixels : int
        Q = N^2.
    """
    if not (0.0 < compression <= 1.0) or not np.isfinite(compression):
        raise ConfigError(f"compression must be in (0, 1], got {compression}")
    return max(1, int(round(compression * n_pixels)))


def make_patterns(
    kind: str,
    n_patterns: int,
    n_pixels: int,
    rng: np.random.Generator | int | None = None,
    sigma: float = 0.25,
    on_fraction: float = 0.5,
    dtype=np.float32,
) -> np.ndarray:
    """Generate ``M`` DMD patterns as the rows of an ``(M, Q)`` matrix with entries in [0, 1].

    Parameters
    ----------
    kind : {'gaussian', 'bernoulli'}
    n_patterns : int
        M.
    n_pixels : int
        Q = N^2 (patterns are flattened in C order, like the images).
    rng : Generator or int or None
        Random source.
    sigma : float
        Standard deviation of the grey levels of ``gaussian`` patterns around 0.5.
    on_fraction : float
        Probability that a mirror is on in ``bernoulli`` patterns.
    dtype : numpy dtype
        Output precision.

    Notes
    -----
    Phi in eq. (7) and (11)-(17). The paper assumes zero-mean Gaussian entries (RIP argument);
    non-negative patterns carry a large common (DC) component, which QCR removes (eq. 11).
    """
    rng = as_generator(rng)
    dtype = np.dtype(dtype)  # a string "float32" drew float64 normals: other patterns
    if not np.issubdtype(dtype, np.floating):  # (int: gaussian patterns of all zeros, an audit)
        raise ConfigError(f"patterns are mirror states in [0, 1]: dtype {dtype} holds none but "
                          f"0 and 1; use float32 or float64")
    if n_patterns < 1 or n_pixels < 1:
        raise ConfigError("need at least one pattern and one pixel")
    if kind == "gaussian":
        if not sigma > 0:
            raise ConfigError(f"pattern sigma must be positive, got {sigma}")
        # drawn in float32 whatever the dtype, so that --dtype (the solve's precision) does not
        # change the acquisition: float64 draws gave other patterns, 0.3 % more photons and
        # RMSE 0.028 against 0.044 m (an outside audit, options paired; a DMD's grey levels
        # are 8-bit, far coarser than float32's)
        phi = rng.standard_normal((n_patterns, n_pixels), dtype=np.float32).astype(dtype)
        # (1e308 overflowed the float32 cast, with NumPy's warning: past 1e30 every value
        # but an exact zero clips to 0 or 1 alike, so the product is taken there)
        phi *= min(float(sigma), 1e30)
        phi += 0.5
        np.clip(phi, 0.0, 1.0, out=phi)
        return phi.astype(dtype, copy=False)
    if kind == "bernoulli":
        if not 0.0 < on_fraction < 1.0:
            raise ConfigError(f"pattern on-fraction must be in (0, 1), got {on_fraction}")
        return (rng.random((n_patterns, n_pixels)) < on_fraction).astype(dtype)
    raise ConfigError(f"unknown pattern kind {kind!r}; choose one of {', '.join(PATTERN_KINDS)}")


class DensePatterns(PatternOperator):
    """A pattern set held as its ``(M, Q)`` matrix (Gaussian grey levels, Bernoulli binary).

    Parameters
    ----------
    matrix : ndarray, shape (M, Q)
        Mirror transmittances in [0, 1].
    kind : str
        The pattern kind that made it.
    copy : bool
        Take a copy of ``matrix`` where it is the caller's array (default), so that the
        products and the adjoint keep to the patterns given; False shares it.

    Examples
    --------
    16 Gaussian grey-level patterns over 8x8 mirrors, as an operator on flattened images:

    >>> import numpy as np
    >>> from spslidar.patterns.dense import DensePatterns, make_patterns
    >>> phi = DensePatterns(make_patterns("gaussian", 16, 64, rng=0), "gaussian")
    >>> phi.shape, phi.dtype
    ((16, 64), dtype('float32'))
    >>> x = np.random.default_rng(0).random(64)  # an 8x8 image, flattened
    >>> (phi @ x).shape, (phi.H @ np.ones(16)).shape
    ((16,), (64,))
    >>> np.allclose(phi @ x, phi.todense() @ x)
    True
    """

    def __init__(self, matrix: np.ndarray, kind: str = "dense", *, copy: bool = True):
        matrix = float_matrix(matrix, "patterns", "transmittances", copy=copy)
        low, high = float(matrix.min()), float(matrix.max())
        if low < 0 or high > 1:
            # (a DMD shows transmittances in [0, 1]; values outside were taken from Python,
            # where `reconstruct --patterns` refused them: an audit of 2026-11-29. Centred or
            # differential (+1/-1) patterns are operators of their own: ``centred``)
            raise ValueError(f"patterns must hold mirror transmittances in [0, 1], got values "
                             f"from {low:g} to {high:g}")
        super().__init__(matrix.shape, matrix.dtype)
        self.matrix = matrix
        self.kind = kind
        self._T = None

    def _matvec(self, x):
        return _product(self.matrix, x.astype(self.dtype, copy=False))

    def _rmatvec(self, y):
        if self._T is None:
            self._T = np.ascontiguousarray(self.matrix.T)
        return _product(self._T, y.astype(self.dtype, copy=False))

    def todense(self) -> np.ndarray:
        return self.matrix.copy()

    def mean_pattern(self) -> np.ndarray:
        return self.matrix.mean(axis=0, dtype=np.float64)

    def apply_rows(self, rows: slice, x: np.ndarray) -> np.ndarray:
        rows, x = self._rows_block(rows, x)
        return np.asarray(self.matrix[rows], dtype=np.float64) @ x

    def centred(self, norm: float = 1.0, dtype=np.float32):
        from ..operators import MatrixOperator

        return MatrixOperator(centred_patterns(self.matrix, norm, dtype=dtype), dtype=dtype,
                              copy=False)

    def as_dtype(self, dtype):
        from ..operators import MatrixOperator

        return MatrixOperator(self.matrix, dtype=dtype, copy=False)  # (the patterns' own)

    @property
    def nbytes(self) -> int:
        return int(self.matrix.nbytes)


def dense_patterns(kind: str, n_patterns: int, n_side: int, rng: np.random.Generator,
                   dtype=np.float32, sigma: float = 0.25, on_fraction: float = 0.5,
                   **_: object) -> DensePatterns:
    """The registry's factory for ``gaussian`` and ``bernoulli`` pattern sets."""
    return DensePatterns(make_patterns(kind, n_patterns, n_side * n_side, rng, sigma=sigma,
                                       on_fraction=on_fraction, dtype=dtype), kind, copy=False)


#: rows per block in :func:`centred_patterns` (a float64 block of 4096 pixels stays in cache)
_CENTRE_ROWS = 128


def centred_patterns(patterns: np.ndarray, norm: float = 1.0, dtype=np.float32) -> np.ndarray:
    """``(Phi - mean_i Phi) / norm`` in ``dtype``: :func:`spslidar.qcr.centre` in float64.

    Parameters
    ----------
    patterns : ndarray, shape (M, Q)
    norm : float
        Divides the centred patterns (``sqrt(M)`` for the centred data term).
    dtype : numpy dtype
        Output precision.

    Returns
    -------
    ndarray, shape (M, Q)
        Bitwise the values of ``(centre(patterns.astype(float64)) / norm).astype(dtype)``,
        without its full-size float64 temporaries: the work is done in float64 a block of rows
        at a time.
    """
    phi = np.asarray(patterns)
    mean = phi.mean(axis=0, dtype=np.float64, keepdims=True)
    out = np.empty(phi.shape, dtype=dtype)
    for r in range(0, phi.shape[0], _CENTRE_ROWS):
        blk = np.subtract(phi[r:r + _CENTRE_ROWS], mean, dtype=np.float64)
        if norm != 1.0:
            blk /= norm
        out[r:r + _CENTRE_ROWS] = blk
    return out


def as_patterns(patterns, *, copy: bool = True) -> PatternOperator:
    """A :class:`~spslidar.patterns.base.PatternOperator` from an operator or an ``(M, Q)``
    array (wrapped as :class:`DensePatterns`, a copy of the caller's array unless ``copy``
    is False: for a use within one call, where the array cannot change meanwhile)."""
    if isinstance(patterns, PatternOperator):
        return patterns
    return DensePatterns(patterns if isinstance(patterns, np.ndarray) else np.asarray(patterns),
                         copy=copy)
