"""The contracts of solvers and regularisers (eq. 18), against references written here
(:mod:`spslidar.testing`).

A solver is run on every small problem whose regulariser its registry hook accepts:

* ``tv``: a 16 x 16 compressive problem (128 Gaussian measurements, K = 2) with the isotropic
  TV; ``tv-aniso``: the same with the anisotropic TV. Reference: a plain FISTA loop
  (:func:`fista_tv`, only the regulariser's prox, tightly converged) run to a fixed point;
* ``tv-denoise``: ``A = I`` (two noisy images): the optimum is scikit-image's
  ``denoise_tv_chambolle``;
* ``l1`` (sparse spikes) and ``wavelet`` (Haar l1 of the images): a plain FISTA with soft
  thresholding, polished on its support by the optimality conditions (:func:`lasso`).

The project's own tests check these references against scikit-learn's ``Lasso`` and
scikit-image (``tests/test_solver_conformance.py``); they are written here, not imported from
those libraries, so that the kit needs only spslidar's own dependencies.

Besides the optimum (objective within ``REL_TOL`` of the reference's), a solver must stop
at ``max_iter``, call its callbacks once per iteration, give the same iterates twice and when
driven step by step, give a reused regulariser's result as a fresh one's, and start from
``x0`` when given one. A regulariser's
prox must beat random feasible perturbations, ``values`` agree with the call, no input be
changed, the dtype be kept, and ``reset`` restore the fresh state.
"""

from __future__ import annotations

import functools
from types import SimpleNamespace

import numpy as np

from ..errors import ConfigError

__all__ = ["KINDS", "Problem", "check_regulariser", "check_solver", "check_warm_start",
           "fista_tv", "lasso", "problems", "solver_kinds"]

SHAPE = (16, 16)
N = SHAPE[0] * SHAPE[1]
#: relative objective gap to the reference optimum every solver must reach ...
REL_TOL = 1e-4
#: ... within this many iterations (the built-in solvers need at most ~130)
MAX_ITER = 1000
#: the conformance problems, by regulariser (``tv-denoise`` is ``tv`` with ``A = I``)
KINDS = ("tv", "tv-aniso", "tv-denoise", "l1", "wavelet")


def _fail(what: str, why: str) -> AssertionError:
    return AssertionError(f"{what}: {why}")


def fista_tv(a: np.ndarray, y: np.ndarray, lam: float, reg, n_iter: int) -> np.ndarray:
    """Plain FISTA on ``||a x - y||^2 / 2 + lam reg(x)`` with ``reg``'s prox, written without
    the solver classes: the reference their optimum is checked against."""
    lip = np.linalg.norm(a, 2) ** 2
    x = np.zeros((a.shape[1], y.shape[1]))
    v, t = x.copy(), 1.0
    for _ in range(n_iter):
        xn = reg.prox(v - a.T @ (a @ v - y) / lip, lam / lip)
        tn = 0.5 * (1 + np.sqrt(1 + 4 * t * t))
        v, x, t = xn + (t - 1) / tn * (xn - x), xn, tn
    return x


def lasso(b: np.ndarray, y: np.ndarray, lam: float, tol: float = 1e-8,
          max_iter: int = 100_000) -> np.ndarray:
    """``argmin_w ||b w - y||^2 / 2 + lam ||w||_1`` per column of ``y``.

    FISTA with soft thresholding until an iterate moves less than ``tol`` relative to its
    norm, then each column polished on its support: the optimality conditions solved there
    exactly (``b_S^T (b_S w_S - y) = -lam sign(w_S)``), kept where they hold (the signs, and
    ``|b^T r| <= lam`` off the support); a first-order method alone needs seconds for the
    last digits."""
    lip = np.linalg.norm(b, 2) ** 2

    def soft(v, t):
        return np.sign(v) * np.maximum(np.abs(v) - t, 0.0)

    w = np.zeros((b.shape[1], y.shape[1]))
    v, t = w.copy(), 1.0
    for _ in range(max_iter):
        wn = soft(v - b.T @ (b @ v - y) / lip, lam / lip)
        tn = 0.5 * (1 + np.sqrt(1 + 4 * t * t))
        done = np.linalg.norm(wn - w) <= tol * max(np.linalg.norm(wn), 1e-300)
        v, w, t = wn + (t - 1) / tn * (wn - w), wn, tn
        if done:
            break
    for j in range(y.shape[1]):
        on = np.abs(w[:, j]) > 0
        sign = np.sign(w[on, j])
        bs = b[:, on]
        try:
            ws = np.linalg.solve(bs.T @ bs, bs.T @ y[:, j] - lam * sign)
        except np.linalg.LinAlgError:
            continue
        cand = np.zeros(b.shape[1])
        cand[on] = ws
        g = b.T @ (b @ cand - y[:, j])
        if np.all(np.sign(ws) == sign) and np.all(np.abs(g[~on]) <= lam * (1 + 1e-9)):
            w[:, j] = cand
    return w


class Problem(SimpleNamespace):
    """``op``, dense ``a`` (``None``: identity), ``y``, ``lam``, ``make_reg()``, the
    reference solution ``x_ref`` and its objective ``f_ref``."""

    def objective(self, x: np.ndarray) -> float:
        r = (x - self.y) if self.a is None else (self.a @ x - self.y)
        return 0.5 * float(np.sum(r**2)) + self.lam * self.make_reg()(x)


def _tv(**kw):
    """The TV of the solver runs (accurate enough for a 1e-4 objective gap)."""
    from ..solvers.regularisers import TV

    return TV(SHAPE, **{"max_inner": 100, "inner_tol": 1e-6, **kw})


def _tv_reference(a, y, lam, isotropic=True):
    from ..solvers.regularisers import TV

    return fista_tv(a, y, lam, TV(SHAPE, isotropic=isotropic, max_inner=200, inner_tol=1e-8),
                    300)


@functools.lru_cache(maxsize=1)
def problems() -> dict[str, Problem]:
    """The conformance problems (built once per process: about a second)."""
    from skimage.restoration import denoise_tv_chambolle

    from ..operators import Identity, MatrixOperator, Wavelet2D
    from ..solvers.regularisers import L1

    rng = np.random.default_rng(7)
    m, k = 128, 2
    a = rng.standard_normal((m, N)) / np.sqrt(m)
    img = np.zeros(SHAPE + (k,))
    img[3:10, 4:12, 0] = 1.0
    img[8:14, 2:9, 0] += 0.5
    img[5:13, 6:15, 1] = -0.7
    img[:, 12:, 1] += 0.4
    x_img = img.reshape(N, k)
    y_img = a @ x_img + 0.05 * rng.standard_normal((m, k))
    spikes = np.zeros((N, k))
    for j in range(k):
        spikes[rng.choice(N, 10, replace=False), j] = 2.0 * rng.standard_normal(10)
    y_sp = a @ spikes + 0.05 * rng.standard_normal((m, k))
    noisy = x_img + 0.2 * rng.standard_normal((N, k))
    haar = Wavelet2D(SHAPE, "haar")
    out = {
        "tv": Problem(op=MatrixOperator(a), a=a, y=y_img, lam=0.05, make_reg=_tv,
                      x_ref=_tv_reference(a, y_img, 0.05)),
        "tv-aniso": Problem(op=MatrixOperator(a), a=a, y=y_img, lam=0.05,
                            make_reg=lambda: _tv(isotropic=False),
                            x_ref=_tv_reference(a, y_img, 0.05, isotropic=False)),
        "tv-denoise": Problem(
            op=Identity(N), a=None, y=noisy, lam=0.1, make_reg=_tv,
            x_ref=np.stack([denoise_tv_chambolle(noisy[:, j].reshape(SHAPE), weight=0.1,
                                                 eps=1e-10, max_num_iter=10_000).ravel()
                            for j in range(k)], axis=1)),
        "l1": Problem(op=MatrixOperator(a), a=a, y=y_sp, lam=0.05, make_reg=L1,
                      x_ref=lasso(a, y_sp, 0.05)),
        "wavelet": Problem(op=MatrixOperator(a), a=a, y=y_img, lam=0.03,
                           make_reg=lambda: L1(haar),
                           x_ref=haar.rmatvec(lasso(a @ haar.todense().T, y_img, 0.03))),
    }
    for p in out.values():
        p.f_ref = p.objective(p.x_ref)
    return out


#: the regulariser (``--regulariser``) of each conformance problem
REGULARISER_OF = {"tv": "tv", "tv-aniso": "tv-aniso", "tv-denoise": "tv", "l1": "l1",
                  "wavelet": "wavelet"}


def accepts(name: str, kind: str) -> bool:
    """Whether solver ``name`` takes the regulariser of problem ``kind``: a whole
    :class:`~spslidar.config.Config` choosing both passes its registry hook (a hook that reads
    another key, ``cfg.lam``, found a bare namespace without it: an audit)."""
    from . import config_for

    try:
        config_for("solver", name, regulariser=REGULARISER_OF.get(kind, kind))
    except ConfigError:
        return False
    return True


def solver_kinds(name: str) -> list[str]:
    """The conformance problems solver ``name`` accepts (:data:`KINDS` in order)."""
    return [k for k in KINDS if accepts(name, k)]


def _solver(name: str, stop):
    """The solver as the pipeline builds it: its declared options at their defaults."""
    from ..config import chosen_stage_options
    from ..solvers import get_solver
    from . import config_for

    cfg = config_for("solver", name,
                     regulariser=REGULARISER_OF[next(iter(solver_kinds(name)), "tv")])
    return get_solver(name)(stop=stop, **chosen_stage_options(cfg, "solver"))


def check_optimum(name: str, kind: str) -> list[str]:
    """Solver ``name`` reaches the reference optimum of problem ``kind``: its objective within
    ``REL_TOL`` of the reference's in ``MAX_ITER`` iterations, its recorded objective
    that of the iterate it returns, never above the start's."""
    from ..solvers import StopRule

    what = f"solver {name!r} on the {kind} problem"
    p = problems()[kind]
    y = p.y.copy()  # (the problems are shared: a solver that zeroed its y in place was then
    # scored on the zeroed y, and "the reference did not converge" was blamed, an audit)
    x, info = _solver(name, StopRule(MAX_ITER, rtol=1e-10)).solve(p.op, y, p.make_reg(),
                                                                  p.lam)
    if not np.array_equal(y, p.y):
        raise _fail(what, "the solve changed the data y it was given (copy it before "
                          "changing it)")
    if x.shape != p.x_ref.shape:
        raise _fail(what, f"result of shape {x.shape}, not {p.x_ref.shape}")
    f = p.objective(x)
    if not f <= p.f_ref * (1 + REL_TOL):
        raise _fail(what, f"objective {f:.8g} against the reference's {p.f_ref:.8g} "
                          f"(more than {REL_TOL:g} above)")
    if not f >= p.f_ref * (1 - REL_TOL):  # the reference is (near) optimal too
        raise _fail(what, f"objective {f:.8g} below the reference's {p.f_ref:.8g}: the "
                          f"reference did not converge")
    h = np.asarray(info.objective, dtype=np.float64)
    if h.size == 0 or not np.isclose(h[-1], f, rtol=1e-9, atol=0):
        raise _fail(what, "the recorded objective is not that of the returned iterate")
    f0 = p.objective(np.zeros_like(x))
    if not (np.all(np.isfinite(h)) and h[-1] < h[0] and h.max() <= f0):
        raise _fail(what, "the recorded objective is not finite, or rises above the start's")
    return [f"{kind}: reaches the reference optimum"]


def check_behaviour(name: str, kind: str) -> list[str]:
    """Stop rule, callbacks, 1-D data, determinism, step-by-step driving and a reused
    regulariser, on problem ``kind``."""
    from ..solvers import StopRule

    what = f"solver {name!r}"
    p = problems()[kind]
    seen = []

    def callback(solver):
        seen.append((solver.it, len(solver.info.objective), solver.x.shape, solver.done()))

    x, info = _solver(name, StopRule(max_iter=7, rtol=0)).solve(
        p.op, p.y, p.make_reg(), p.lam, callback=[callback])
    if info.iterations != 7 or info.stop_reason != "max_iter" or len(info.objective) != 7:
        raise _fail(what, f"max_iter 7 gave {info.iterations} iterations "
                          f"({info.stop_reason}), {len(info.objective)} objectives")
    if info.solver != name:
        raise _fail(what, f"info.solver is {info.solver!r}")
    if ([s[0] for s in seen] != list(range(1, 8)) or [s[1] for s in seen] != list(range(1, 8))
            or any(s[2] != x.shape for s in seen) or [s[3] for s in seen] != [False] * 6 + [True]):
        raise _fail(what, "callbacks not called once per iteration, after its objective, "
                          "with done() true only at the last")
    shapes = []
    x1, _ = _solver(name, StopRule(3, rtol=0)).solve(
        p.op, p.y[:, 0], p.make_reg(), p.lam, callback=lambda s: shapes.append(s.x.shape))
    if x1.shape != (N,) or shapes != [(N,)] * 3:
        raise _fail(what, "1-D data did not give a 1-D result (also in the callback)")
    stop = StopRule(max_iter=25, rtol=0)
    x1, i1 = _solver(name, stop).solve(p.op, p.y, p.make_reg(), p.lam)
    solver = _solver(name, stop)
    runs = [solver.solve(p.op, p.y, p.make_reg(), p.lam),
            solver.solve(p.op, p.y, p.make_reg(), p.lam)]  # the same instance again
    s = _solver(name, stop)
    s.setup(p.op, p.y, p.make_reg(), p.lam)
    while not s.done():
        s.step()
    runs.append(s.finish())
    for x2, i2 in runs:
        if not np.array_equal(x2, x1) or i2.objective != i1.objective:
            raise _fail(what, "not the same iterates twice, on the same instance, or driven "
                              "step by step")
    s = _solver(name, StopRule(max_iter=100, rtol=0))
    s.setup(p.op, p.y, p.make_reg(), p.lam)
    for _ in range(4):
        s.step()
    x5, i5 = s.finish()
    if i5.iterations != 4 or i5.stop_reason != "stopped" or i5.objective != i1.objective[:4]:
        raise _fail(what, "finish() after 4 steps is not those 4 iterations, 'stopped'")
    try:
        _solver(name, stop).step()
    except RuntimeError:
        pass
    else:
        raise _fail(what, "step() before setup() did not raise RuntimeError")
    reg = p.make_reg()
    _solver(name, stop).solve(p.op, p.y * 0.5, reg, p.lam)
    x_reused, i_reused = _solver(name, stop).solve(p.op, p.y, reg, p.lam)
    x_fresh, i_fresh = _solver(name, stop).solve(p.op, p.y, p.make_reg(), p.lam)
    if not np.array_equal(x_reused, x_fresh) or i_reused.objective != i_fresh.objective:
        raise _fail(what, "a regulariser reused from an earlier solve changes the result "
                          "(setup must reset it)")
    return ["stops at max_iter", "callbacks once per iteration", "1-D data", "deterministic",
            "step by step equals solve", "a reused regulariser"]


def check_solver(name: str) -> list[str]:
    """The contract of a solver: the optimum of every conformance problem it accepts and its
    behaviour (see the module docstring).

    Returns
    -------
    list of str
        The contracts checked.
    """
    from ..solvers import SOLVERS, Solver, get_solver

    what = f"solver {name!r}"
    entry = SOLVERS.get(name)
    cls = get_solver(name)
    if not (isinstance(cls, type) and issubclass(cls, Solver)):
        raise _fail(what, f"its entry loads {cls!r}, not a Solver subclass")
    if cls.name != name:
        raise _fail(what, f"its class {cls.__name__} is named {cls.name!r}: give a subclass "
                          f"name = {name!r} (each solve records it, info.solver, in "
                          f"metrics.json)")
    for key in ("iterations", "lam_scale", "regulariser"):
        if key not in entry.defaults:
            raise _fail(what, f"its entry declares no default {key!r}")
    kinds = solver_kinds(name)
    if not kinds:
        raise _fail(what, f"accepts none of the conformance problems {KINDS}")
    # (the problems are shared by every solver checked in this process: one that changes
    # its data only on a warm start or with a callback left them changed for the next,
    # which was then blamed; a review) the data are kept, restored, and their change said
    kept = {k: problems()[k].y.copy() for k in kinds}
    failed: BaseException | None = None
    done = ["entry"]
    try:
        for kind in kinds:
            done += check_optimum(name, kind)
        done += check_behaviour(name, kinds[0]) + check_warm_start(name, kinds)
    except BaseException as exc:  # (a solver's ValueError too: the data restored first)
        failed = exc
    changed = [k for k, y in kept.items() if not np.array_equal(problems()[k].y, y)]
    for k in changed:
        problems()[k].y[...] = kept[k]
    if changed:  # (the cause of any other failure it made: said first)
        raise _fail(what, f"a solve changed the data y it was given (on the {changed[0]} "
                          f"problem; copy it before changing it)") from None
    if failed is not None:
        raise failed
    return done


def check_warm_start(name: str, kinds: list[str]) -> list[str]:
    """A solve started at ``x0`` starts there: three iterations from the reference optimum end
    closer to it than three from zero, by more than half of the latter's gap (on the first
    problem where three iterations from zero leave a gap of a tenth of the optimum; the
    denoising problem's ``A = I`` closes it at once). TVAL3's multipliers start at zero, so
    its iterates leave a warm start a little (a gap of 0.7 against 8.8 on the ``tv``
    problem); a solver that ignores ``x0`` ends where the cold start does."""
    from ..solvers import StopRule

    for kind in kinds:
        p = problems()[kind]
        cold, _ = _solver(name, StopRule(3, rtol=0)).solve(p.op, p.y, p.make_reg(), p.lam)
        gap_cold = p.objective(cold) - p.f_ref
        if gap_cold <= 0.1 * abs(p.f_ref):
            continue
        warm, _ = _solver(name, StopRule(3, rtol=0)).solve(p.op, p.y, p.make_reg(), p.lam,
                                                           x0=p.x_ref.copy())
        gap_warm = p.objective(warm) - p.f_ref
        if not gap_warm < 0.5 * gap_cold:
            raise _fail(f"solver {name!r} on the {kind} problem",
                        f"started at the optimum (x0), three iterations leave a gap of "
                        f"{gap_warm:.4g}, against {gap_cold:.4g} from zero: is x0 ignored?")
        return [f"{kind}: starts at x0"]
    return []


def _block(seed: int, k: int = 3, dtype=np.float64) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = np.zeros((8, 8, k))
    img[2:6, 1:5] = 1.0
    img[:, 6:] -= 0.6
    return (img.reshape(64, k) + 0.3 * rng.standard_normal((64, k))).astype(dtype)


def _prox_objective(reg, z: np.ndarray, v: np.ndarray, t: float) -> float:
    return 0.5 * float(np.sum((z - v) ** 2)) + t * reg(z)


def check_regulariser_instance(make, what: str = "regulariser",
                               slack: float = 1e-10) -> list[str]:
    """The contract of the regulariser ``make()`` builds, on 8 x 8 images (64 rows).

    Parameters
    ----------
    make : callable
        Returns a fresh :class:`~spslidar.solvers.regularisers.Regulariser`.
    what : str
        Its name, for messages.
    slack : float
        Relative tolerance of the prox's optimality (an iterative prox's own accuracy).
    """
    for t in (0.05, 0.4):  # the prox: better than the input and than random perturbations
        reg = make()
        v = _block(1)
        z = reg.prox(v.copy(), t)  # (a prox that writes into its input fails further down)

        def feasible(w, nonneg=reg.nonneg):
            return np.maximum(w, 0) if nonneg else w

        if reg.nonneg and z.min() < 0:
            raise _fail(what, "a non-negative prox gave negative values")
        best = _prox_objective(reg, z, v, t)
        tol = slack * max(1.0, abs(best))
        if best > _prox_objective(reg, feasible(v), v, t) + tol:
            raise _fail(what, f"prox at t = {t}: worse than its input")
        rng = np.random.default_rng(2)
        # random perturbations, and steps along the two directions a wrong prox errs in:
        # towards its input (too much shrinkage) and a rescaling of the result
        steps = [scale * rng.standard_normal(z.shape) for scale in (1e-1, 1e-3, 1e-5)
                 for _ in range(5)]
        steps += [s * d for s in (1e-1, 1e-2, 1e-3, -1e-3, -1e-2) for d in (v - z, z)]
        for step in steps:
            w = feasible(z + step)
            if _prox_objective(reg, w, v, t) < best - tol:
                raise _fail(what, f"prox at t = {t}: a step of norm {np.linalg.norm(step):.2g}"
                                  f" from it does better")
        if not np.allclose(reg.prox(v.copy(), 0.0), feasible(v), rtol=0, atol=1e-12):
            raise _fail(what, "prox at t = 0 is not the (feasible) input")
    reg = make()
    x = _block(3, k=4)
    vals = reg.values(x)
    if vals.shape != (4,) or not np.all(np.isfinite(vals)) or not np.all(vals >= 0):
        raise _fail(what, "values() is not one finite, non-negative value per column")
    if not np.isclose(reg(x), float(np.sum(vals)), rtol=1e-12, atol=0):
        raise _fail(what, "its value is not the sum of values()")
    for j in range(4):
        if not np.isclose(reg(x[:, j]), vals[j], rtol=1e-12, atol=1e-12):
            raise _fail(what, "a column's value differs from its values() entry")
        if reg.values(x[:, j]).shape != (1,):
            raise _fail(what, "values() of a 1-D input is not of shape (1,)")
    if reg(np.zeros(64)) != 0.0:
        raise _fail(what, "its value at 0 is not 0")
    for dtype in (np.float64, np.float32):
        for v in (_block(4, dtype=dtype), _block(5, k=1, dtype=dtype)[:, 0]):
            keep = v.copy()
            z = reg.prox(v, 0.2)
            reg.values(v)
            reg(v)
            if not np.array_equal(v, keep):
                raise _fail(what, "prox, values or the call changed the input")
            z0 = reg.prox(v, 0.0)
            for out in (z, z0):
                if out.dtype != dtype or out.shape != v.shape or np.shares_memory(out, v):
                    raise _fail(what, f"prox of {np.dtype(dtype).name} {v.shape} gave "
                                      f"{out.dtype} {out.shape}, or a view of its input")
    v1, v2 = _block(6), _block(7)
    reg = make()
    reg.prox(v1, 0.3)
    reg.prox(v1 * 1.1, 0.2)
    reg.reset()
    if not np.array_equal(reg.prox(v2, 0.3), make().prox(v2, 0.3)):
        raise _fail(what, "reset() does not restore the fresh state")
    return ["prox optimal", "values agree with the call", "no side effect", "dtype kept",
            "reset"]


def check_regulariser(name: str) -> list[str]:
    """The contract of a registered regulariser, built by its factory on 8 x 8 images with
    and without non-negativity; an iterative prox (one with an ``inner_tol``, as
    :class:`~spslidar.solvers.regularisers.TV`) is run to 1e-10 in up to 3 000 inner
    iterations, so that its optimality is checked to 1e-9 of the objective, not to the
    pipeline's working tolerance.

    Returns
    -------
    list of str
        The contracts checked.
    """
    from ..solvers import REGULARISERS

    factory = REGULARISERS.load(name)

    def make(nonneg: bool):
        reg = factory((8, 8), nonneg=nonneg, max_inner=3000)
        if hasattr(reg, "inner_tol"):
            reg.inner_tol = 1e-10
        return reg

    done: list[str] = []
    for nonneg in (False, True):
        label = f"regulariser {name!r}" + (" (non-negative)" if nonneg else "")
        try:
            make(nonneg)
        except ConfigError:
            if not nonneg:
                raise
            done.append("refuses non-negativity (ConfigError)")
            continue
        done = check_regulariser_instance(lambda nonneg=nonneg: make(nonneg), label,
                                          slack=1e-9) + done
    return done
