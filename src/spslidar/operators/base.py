"""A small real linear-operator base class, its algebra and the adjoint (dot) test.

Modelled on PyLops' ``LinearOperator``: subclasses implement ``_matvec`` and ``_rmatvec``; users
call ``op @ x``, ``op.H @ y``, compose with ``@``, scale with ``*`` and add with ``+``.

Every operator in spslidar acts on a *block of columns*: ``x`` has shape ``(n,)`` or ``(n, K)``
(K range slices reconstructed at once), and the result has shape ``(m,)`` or ``(m, K)``. This
is what lets every solver work on all slices of eq. (7) in one matrix product instead of K
separate solves. We do not subclass PyLops' operator because its ``matmat`` path goes through
per-call checks and reshapes that cost more than the products themselves at our sizes, and we
want a dependency-light core; the tests compare against PyLops where it applies.
"""

from __future__ import annotations

import numpy as np

from ..arrays import floating_dtype, pair_shape
from ..randomness import as_generator
from . import parallel as _parallel


class LinearOperator:
    """Real linear map from R^n to R^m acting on vectors or column blocks.

    Parameters
    ----------
    shape : tuple of int
        ``(m, n)``: output and input sizes.
    dtype : numpy dtype, optional
        Working precision of the operator.

    Examples
    --------
    A subclass implements ``_matvec`` and ``_rmatvec`` on column blocks; ``@``, ``.H``,
    sums, products and :func:`~spslidar.operators.dottest` come with it:

    >>> import numpy as np
    >>> from spslidar.operators import LinearOperator, dottest
    >>> class Diff(LinearOperator):  # forward differences, R^n -> R^(n-1)
    ...     def __init__(self, n):
    ...         super().__init__((n - 1, n))
    ...     def _matvec(self, x):
    ...         return x[1:] - x[:-1]
    ...     def _rmatvec(self, y):
    ...         return np.concatenate([-y[:1], y[:-1] - y[1:], y[-1:]])
    >>> D = Diff(5)
    >>> (D @ np.arange(5.0)).tolist(), (D.H @ D).shape
    ([1.0, 1.0, 1.0, 1.0], (5, 5))
    >>> dottest(D, n_cols=3) < 1e-10  # <D x, y> == <x, D^H y>
    True
    """

    def __init__(self, shape: tuple[int, int], dtype=np.float64):
        self.shape = pair_shape(shape, "shape", 0)  # (Identity(-1) was taken, an audit)
        self.dtype = np.dtype(dtype)

    # -- to implement --------------------------------------------------------------------
    def _matvec(self, x: np.ndarray) -> np.ndarray:  # x: (n, K)
        raise NotImplementedError

    def _rmatvec(self, y: np.ndarray) -> np.ndarray:  # y: (m, K)
        raise NotImplementedError

    # -- public --------------------------------------------------------------------------
    def matvec(self, x: np.ndarray) -> np.ndarray:
        """Apply the operator to ``x`` of shape ``(n,)`` or ``(n, K)``."""
        x = _real_input(x, "x")
        if x.ndim not in (1, 2) or x.shape[0] != self.shape[1]:
            raise ValueError(f"operator of shape {self.shape} applied to array of shape "
                             f"{x.shape} (it takes ({self.shape[1]},) or ({self.shape[1]}, K))")
        if x.ndim == 1:
            return self._matvec(x[:, None])[:, 0]
        return self._matvec(x)

    def rmatvec(self, y: np.ndarray) -> np.ndarray:
        """Apply the adjoint to ``y`` of shape ``(m,)`` or ``(m, K)``."""
        y = _real_input(y, "y")
        if y.ndim not in (1, 2) or y.shape[0] != self.shape[0]:
            raise ValueError(f"adjoint of shape {self.shape[::-1]} applied to array {y.shape} "
                             f"(it takes ({self.shape[0]},) or ({self.shape[0]}, K))")
        if y.ndim == 1:
            return self._rmatvec(y[:, None])[:, 0]
        return self._rmatvec(y)

    @property
    def H(self) -> LinearOperator:  # noqa: N802 - PyLops' name
        """The adjoint operator."""
        return _Adjoint(self)

    T = H

    def __matmul__(self, other):
        if isinstance(other, LinearOperator):
            return _Product(self, other)
        return self.matvec(other)

    def __mul__(self, scalar):
        if np.isscalar(scalar):
            return _Scaled(self, _scale(scalar))
        return NotImplemented

    __rmul__ = __mul__

    def __add__(self, other):
        if isinstance(other, LinearOperator):
            return _Sum(self, other)
        return NotImplemented

    def __sub__(self, other):
        if isinstance(other, LinearOperator):
            return _Sum(self, _Scaled(other, -1.0))
        return NotImplemented

    def todense(self) -> np.ndarray:
        """The operator as an explicit ``(m, n)`` matrix, applied to the identity's columns a
        block at a time (the whole ``n x n`` identity was 16 GB for a 256x256 image's
        operator, beside a result of ``m x n``)."""
        m, n = self.shape
        step = max(1, min(n, (1 << 22) // max(1, n)))  # identity blocks of ~32 MB
        out = None
        for j in range(0, n, step):
            k = min(step, n - j)
            eye = np.zeros((n, k), dtype=self.dtype)
            eye[np.arange(j, j + k), np.arange(k)] = 1
            part = np.asarray(self.matvec(eye))
            if out is None:
                out = np.empty((m, n), dtype=part.dtype)
            out[:, j:j + k] = part
        return out

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.shape[0]}x{self.shape[1]} {self.dtype}>"


def _scale(scalar) -> float:
    """A scalar factor of an operator as a float, or one ``TypeError`` naming it: the string
    ``"2"`` was taken as 2.0 (an audit of 2026-12-02), ``True`` as 1.0."""
    from ..arrays import real_number

    value = real_number(scalar)
    if value is None or not np.isfinite(value):
        raise TypeError(f"an operator is scaled by a finite real number, got {scalar!r}")
    return value


class _Adjoint(LinearOperator):
    def __init__(self, op: LinearOperator):
        super().__init__(op.shape[::-1], op.dtype)
        self.op = op

    def _matvec(self, x):
        return self.op._rmatvec(x)

    def _rmatvec(self, y):
        return self.op._matvec(y)

    @property
    def H(self):  # noqa: N802
        return self.op


class _Product(LinearOperator):
    def __init__(self, a: LinearOperator, b: LinearOperator):
        if a.shape[1] != b.shape[0]:
            raise ValueError(f"cannot compose {a.shape} with {b.shape}")
        super().__init__((a.shape[0], b.shape[1]), np.result_type(a.dtype, b.dtype))
        self.a, self.b = a, b

    def _matvec(self, x):
        return self.a._matvec(self.b._matvec(x))

    def _rmatvec(self, y):
        return self.b._rmatvec(self.a._rmatvec(y))


class _Scaled(LinearOperator):
    def __init__(self, op: LinearOperator, s: float):
        super().__init__(op.shape, op.dtype)
        self.op, self.s = op, s

    def _matvec(self, x):
        return self.s * self.op._matvec(x)

    def _rmatvec(self, y):
        return self.s * self.op._rmatvec(y)


class _Sum(LinearOperator):
    def __init__(self, a: LinearOperator, b: LinearOperator):
        if a.shape != b.shape:
            raise ValueError(f"cannot add {a.shape} and {b.shape}")
        super().__init__(a.shape, np.result_type(a.dtype, b.dtype))
        self.a, self.b = a, b

    def _matvec(self, x):
        return self.a._matvec(x) + self.b._matvec(x)

    def _rmatvec(self, y):
        return self.a._rmatvec(y) + self.b._rmatvec(y)


class MatrixOperator(LinearOperator):
    """An explicit dense matrix (the DMD pattern matrix Phi of eq. 7 is one).

    Parameters
    ----------
    A : ndarray, shape (m, n)
    dtype : numpy dtype, optional
        Cast ``A`` to this precision (float32 halves the cost of the products); a real
        floating type.
    copy : bool
        Take a copy of ``A`` where it is the caller's array (default), so that the products
        and the adjoint keep to the matrix given; False shares it (the caller must then not
        change it).

    Notes
    -----
    Inside a :func:`~spslidar.operators.parallel.parallel` context (which the solvers enter
    for large problems) a large product is computed as bands of output rows, one
    single-threaded BLAS call per thread; outside it, one BLAS call.
    """

    def __init__(self, A: np.ndarray, dtype=None, *, copy: bool = True):
        A = float_matrix(A, "A", "entries", dtype, copy)
        super().__init__(A.shape, A.dtype)
        self.A = A
        self._AT = np.ascontiguousarray(A.T)

    def _matvec(self, x):
        return _product(self.A, x.astype(self.dtype, copy=False))

    def _rmatvec(self, y):
        return _product(self._AT, y.astype(self.dtype, copy=False))

    def todense(self) -> np.ndarray:
        """A copy of the matrix (rather than its products with the identity)."""
        return self.A.copy()


def _real_input(a, what: str) -> np.ndarray:
    """``a`` as a floating array for a product, or one line: a masked array (its mask was
    dropped without a word) or complex numbers (cast to their real part with a library
    warning: the operators are real linear maps), an audit of 2026-11-29. Integers and
    booleans come as float64, float16 as float32, as :func:`float_matrix` casts a matrix."""
    if isinstance(a, np.ma.MaskedArray):
        raise ValueError(f"{what} is a masked array: an operator applies to every entry (fill "
                         f"the masked ones first, e.g. x.filled(0))")
    a = np.asarray(a)
    if np.iscomplexobj(a):
        raise ValueError(f"{what} holds complex numbers: the operators are real linear maps "
                         f"(apply them to the real and imaginary parts apart)")
    if a.dtype.kind in "biu":  # (Identity gave int or bool back, Gradient2D failed on bool)
        return a.astype(np.float64)
    if a.dtype == np.float16:  # (Wavelet2D answered in float16: audits of 2026-11-29)
        return a.astype(np.float32)
    if a.dtype.kind != "f":
        raise ValueError(f"{what} must hold numbers, got dtype {a.dtype}")
    return a


def float_matrix(a, what: str = "matrix", values: str = "entries", dtype=None,
                 copy: bool = True) -> np.ndarray:
    """``a`` as the real, finite ``(M, N)`` floating matrix an operator keeps, or one line
    naming ``what`` (its ``values``: "entries", "transmittances").

    Cast to ``dtype`` (a real floating type) where given, else integers and booleans to
    float64 and float16 to float32: an operator computes in its matrix's dtype, so a 0/1
    ``uint8`` or ``bool`` matrix gave products cast back to it (``[0.9, 1.2]`` read ``[0, 0]``
    or ``[True, True]``), and an integer ``dtype`` truncated every product to 0. A complex
    matrix is refused (the adjoint of these real maps is the plain transpose; ``.H`` was
    wrong and dottest passed on reals), and so is a NaN or an infinity (TVAL3 then answered
    all NaN, GPSR part NaN, FISTA "Lipschitz constant ... nan"). With ``copy``, a caller's
    array is copied (a transpose kept beside it is a snapshot: a matrix edited by its owner
    afterwards gave products and adjoints of two matrices); without, it is shared. All
    audits of 2026-11-29."""
    given = a
    if dtype is not None:
        floating_dtype(dtype)
    if np.iscomplexobj(a):
        raise ValueError(f"{what} must be real: the operators are real linear maps, whose "
                         f"adjoint is their transpose")
    a = np.asarray(a)
    if dtype is not None:
        a = a.astype(dtype, copy=False)
    elif a.dtype == np.float16:
        a = a.astype(np.float32)
    elif a.dtype == bool or np.issubdtype(a.dtype, np.integer):
        a = a.astype(np.float64)
    elif not np.issubdtype(a.dtype, np.floating):
        raise ValueError(f"{what} must hold numbers, got dtype {a.dtype}")
    if a.ndim != 2:
        raise ValueError(f"{what} must be an (M, N) matrix, got shape {a.shape}")
    if a.size == 0:
        # (an empty matrix made an operator whose products were empty arrays and whose
        # solvers failed deep inside: an audit of 2026-11-29)
        raise ValueError(f"{what} must have at least one row and one column, got shape "
                         f"{a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{what} holds a NaN or an infinity: it must hold finite real "
                         f"{values}")
    if copy and isinstance(given, np.ndarray) and np.may_share_memory(a, given):
        a = a.copy()
    return a


def _product(M: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``M @ x``; when large enough, in fixed bands of rows shared out among the threads of an
    active :func:`~spslidar.operators.parallel.parallel` context (one after the other
    without one): the same numbers whatever the threads
    (:func:`~spslidar.operators.parallel.banded_matmul`)."""
    if x.ndim == 2 and M.size * x.shape[1] >= _parallel.SPLIT_MIN_WORK:
        return _parallel.banded_matmul(M, x, _parallel.current())
    return M @ x


class Identity(LinearOperator):
    """The identity on R^n."""

    def __init__(self, n: int, dtype=np.float64):
        super().__init__((n, n), dtype)

    def _matvec(self, x):
        return x.copy()

    def _rmatvec(self, y):
        return y.copy()


def dottest(
    op: LinearOperator,
    n_cols: int = 1,
    rng: np.random.Generator | int | None = 0,
    rtol: float | None = None,
    raise_error: bool = True,
) -> float:
    """Adjoint (dot) test: ``<A x, y>`` must equal ``<x, A^H y>``.

    Parameters
    ----------
    op : LinearOperator
    n_cols : int
        Number of columns in the random test blocks (checks the batched path), >= 1.
    rng : Generator or int or None
        Random source (``np.random.default_rng`` seed).
    rtol : float, optional
        Tolerance; default 1e-4 for float32 operators and 1e-10 for float64.
    raise_error : bool
        Raise ``AssertionError`` when the test fails.

    Returns
    -------
    float
        The relative mismatch ``|<Ax,y> - <x,A^H y>| / max(|<Ax,y>|, |<x,A^H y>|)``.

    Examples
    --------
    >>> import numpy as np
    >>> from spslidar.operators import MatrixOperator, dottest
    >>> A = MatrixOperator(np.random.default_rng(0).standard_normal((6, 4)))
    >>> dottest(A) < 1e-10
    True
    >>> dottest(A.H @ A, n_cols=2) < 1e-10  # the batched path too
    True
    """
    from ..arrays import positive_number

    # (n_cols=0 compared empty blocks and passed: an audit of 2026-12-02)
    n_cols = positive_number(n_cols, "n_cols", integer=True, unit="columns")
    rng = as_generator(rng)
    m, n = op.shape
    shape_x = (n,) if n_cols == 1 else (n, n_cols)
    shape_y = (m,) if n_cols == 1 else (m, n_cols)
    x = rng.standard_normal(shape_x)
    y = rng.standard_normal(shape_y)
    lhs = float(np.vdot(np.asarray(op.matvec(x), dtype=np.float64), y))
    rhs = float(np.vdot(x, np.asarray(op.rmatvec(y), dtype=np.float64)))
    err = abs(lhs - rhs) / max(abs(lhs), abs(rhs), 1e-300)
    if rtol is None:
        rtol = 1e-4 if op.dtype == np.float32 else 1e-10
    if raise_error and not err <= rtol:  # (NaN passed: an operator of NaNs, an audit)
        raise AssertionError(f"dot test failed for {op!r}: <Ax,y>={lhs:.8g}, <x,A'y>={rhs:.8g}")
    return err


def power_norm(
    op: LinearOperator,
    n_iter: int = 50,
    rtol: float = 1e-4,
    rng: np.random.Generator | int | None = 0,
) -> float:
    """Largest singular value ``||op||_2`` by power iteration on ``op^H op``.

    Returns ``1.01 x`` the value the iteration reached, so that ``1 / L`` step sizes derived
    from it stay safe once it has converged. Power iteration approaches the largest singular
    value from below, at the rate of the ratio of the two largest: where they are close and
    ``n_iter`` or ``rtol`` stops it early, the result can still be an under-estimate (0.90 x
    on a contrived spectrum of an audit). On the pipeline's operators (32 x 32 Gaussian
    patterns at 25 %, with QCR or the mean eliminated, whose two largest singular values are
    0.993 apart; Hadamard patterns) it returned 1.0055-1.01 x the norm from a dense SVD.

    ``n_iter`` must be a whole number >= 1 (0 returned 0.0 without an iteration, so that a
    ``1 / L`` step became infinite: an audit of 2026-12-02).
    """
    from ..arrays import positive_number

    n_iter = positive_number(n_iter, "n_iter", integer=True, unit="iterations")
    rng = as_generator(rng)
    x = rng.standard_normal(op.shape[1])
    x /= np.linalg.norm(x)
    s_old = 0.0
    s = 0.0
    for _ in range(n_iter):
        z = op.rmatvec(op.matvec(x)).astype(np.float64)
        s = float(np.linalg.norm(z))
        if s == 0.0:
            return 0.0
        x = z / s
        if abs(s - s_old) <= rtol * s:
            break
        s_old = s
    return 1.01 * float(np.sqrt(s))
