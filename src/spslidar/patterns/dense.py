"""Dense DMD pattern sets (the paper's): the rows of the measurement matrix Phi of equation (7).

A DMD only switches mirrors on or off, so every pattern here is non-negative:

* ``gaussian``: the paper's "Gaussian patterns", realised as grey-level transmittances
  ``clip(0.5 + sigma * N(0, 1), 0, 1)`` (displayed on a real DMD by pulse-width modulation over
  the exposure). With the default ``sigma = 0.25`` about 4.6 % of the values are clipped.
* ``bernoulli``: binary patterns, each mirror on with probability ``on_fraction``.
"""

from __future__ import annotations

import numpy as np

from ..arrays import floating_dtype
from ..errors import ConfigError
from ..operators.base import _product, float_matrix
from ..randomness import as_generator
from .base import PatternOperator, pattern_dtype

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
    # (a string "float32" drew float64 normals: other patterns; int: gaussian patterns of all
    # zeros, an audit)
    dtype = pattern_dtype(dtype)
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
    """The registry's factory for ``gaussian`` and ``bernoulli`` pattern sets (``n_side``
    a whole number >= 1: -2 made ``(-2)**2 = 4`` pixels, an audit)."""
    from . import pattern_count

    n_side = pattern_count(n_side, "n_side")
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
        Output precision, a real floating type.

    Returns
    -------
    ndarray, shape (M, Q)
        Bitwise the values of ``(centre(patterns.astype(float64)) / norm).astype(dtype)``,
        without its full-size float64 temporaries: the work is done in float64 a block of rows
        at a time.

    Raises
    ------
    ValueError
        Where ``norm`` is not a finite positive number, or ``dtype`` not a real floating type
        (an integer dtype gave all zeros, a norm of 0 infinities: an audit of 2026-12-02).
    """
    from ..arrays import positive_number

    norm = positive_number(norm, "norm")
    dtype = floating_dtype(dtype, why=" for centred patterns (values either side of 0)")
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


#: the columns :func:`check_pattern_set` reads the mirror states of
_PROBE_COLUMNS = 16


def check_pattern_set(op: object, kind: str, n_patterns: int, n_side: int) -> None:
    """A run's pattern set as the chain takes it, or a one-line ConfigError naming the kind:
    a plugin's factory of ``M // 2`` rows ran ("32 fewrows patterns"), one of mirror states
    in [-1, 0] ran with a negative signal, one whose adjoint was 1.1 times the operator's
    transpose ran (an outside audit of 2026-11-30; the kit, ``spslidar check``, finds them,
    runs did not). Cheap, beside drawing the patterns: one product with a few columns and one
    dot test.

    * the shape ``(M, N * N)``, and that of its products;
    * the mirror states the DMD shows (of :meth:`exposures` where a set has it: differential
      Hadamard patterns are the +-1 operator of two frames in {0, 1}; every built-in kind's
      frames are in [0, 1]) in [0, 1], read in ``_PROBE_COLUMNS`` columns of a fixed-seed
      sample (a set wrong in a few entries only is the kit's to find; a dense set's
      constructor reads them all, and its columns are read from its matrix). Tolerance
      1e-5: float32 round-off of a transform's sums, far below a DMD's grey step (1/255);
    * the adjoint: ``<A x, y>`` against ``<x, A^T y>`` for fixed-seed Gaussian ``x`` and
      ``y``, within 1e-3 of ``||A x|| ||y|| / sqrt(M)`` (the size ``<A x, y>`` has): float32
      round-off of products over 4 million pixels is about 1e-4 of it (``eps sqrt(Q)``), an
      adjoint 10 % off misses it only where ``|<A x, y>|`` falls below a hundredth of its
      size (a chance of 1 in 100 for a seed). Not for a dense set of :class:`DensePatterns`'
      own products: its adjoint is its matrix's transpose, whose copy (``_rmatvec``'s)
      would cost 4 GB at 256 x 256 and 0.5 s at 128 x 128.
    """
    q = n_side * n_side
    what = f"the pattern kind {kind!r}"
    shape = tuple(getattr(op, "shape", ()))
    if shape != (n_patterns, q):
        raise ConfigError(f"{what} made patterns of shape {shape} for {n_patterns} patterns "
                          f"over {n_side} x {n_side} mirrors: a pattern kind makes "
                          f"({n_patterns}, {q}) (M, N * N)")
    dtype = np.dtype(getattr(op, "dtype", np.float64))
    rng = np.random.default_rng(0)
    shown = op.exposures()[0] if hasattr(op, "exposures") else op
    cols = np.sort(rng.choice(q, size=min(q, _PROBE_COLUMNS), replace=False))
    # a dense set's products are its matrix's, unless a subclass says otherwise
    own = isinstance(op, DensePatterns) and type(op)._matvec is DensePatterns._matvec
    if own:
        states = np.asarray(op.matrix[:, cols], dtype=np.float64)
    else:
        probe = np.zeros((q, cols.size), dtype=dtype)
        probe[cols, np.arange(cols.size)] = 1
        states = np.asarray(shown.matvec(probe), dtype=np.float64)
    if states.shape != (shown.shape[0], cols.size):
        raise ConfigError(f"{what}: its matvec gave shape {states.shape} for {cols.size} "
                          f"columns of ({q},): ({shown.shape[0]}, {cols.size}) expected")
    low, high = (float(states.min()), float(states.max())) if states.size else (0.0, 0.0)
    if not (np.isfinite(low) and np.isfinite(high)) or low < -1e-5 or high > 1 + 1e-5:
        raise ConfigError(f"{what} made mirror states in [{low:g}, {high:g}] (in {cols.size} "
                          f"of its columns), not [0, 1]: a DMD shows each mirror between off "
                          f"(0) and on (1)")
    if own and type(op)._rmatvec is DensePatterns._rmatvec:
        return  # its adjoint is its matrix's transpose (a dot test would copy the matrix)
    x = rng.standard_normal((q, 1)).astype(dtype)
    y = rng.standard_normal((n_patterns, 1)).astype(dtype)
    ax = np.asarray(op.matvec(x), dtype=np.float64)
    aty = np.asarray(op.rmatvec(y), dtype=np.float64)
    if ax.shape != (n_patterns, 1) or aty.shape != (q, 1):
        raise ConfigError(f"{what}: its products gave shapes {ax.shape} and {aty.shape} "
                          f"(matvec, rmatvec of one column): ({n_patterns}, 1) and ({q}, 1) "
                          f"expected")
    lhs = float(np.vdot(ax, y.astype(np.float64)))
    rhs = float(np.vdot(x.astype(np.float64), aty))
    size = float(np.linalg.norm(ax) * np.linalg.norm(y)) / np.sqrt(n_patterns)
    if not abs(lhs - rhs) <= 1e-3 * size:  # (NaN fails too)
        raise ConfigError(f"{what}: its adjoint is not its transpose: <A x, y> = {lhs:.8g}, "
                          f"<x, A^T y> = {rhs:.8g} (a dot test with fixed-seed Gaussian x, y)")
