"""Would compiled kernels pay? The TV prox in NumPy against the same FGP loop fused by numba.

Outside the dense products, a solve spends most of its time in element-wise passes over the
``(Q, K)`` block; the largest single piece is the FGP loop of the TV prox
(:class:`spslidar.solvers.regularisers.TV`), which FISTA and TwIST call every iteration.
This script measures how much a compiled kernel would save there, to decide whether adding
numba as a dependency (and its JIT compile time on a first run) is worth it.

It takes the prox input of the Table I problem (motorcycle 64x64, m_n = 5, QCR: ``Q = 4096``
pixels, ``K`` slices after the range gate) and times, single-threaded and from the same
zero dual:

* ``numpy``: ``TV(..., max_inner=n, inner_tol=0).prox`` (spslidar's implementation);
* ``numba``: the same iteration written as two fused kernels below (one pass per FGP
  iteration, one for the primal output), operation for operation in the same order.

The numba kernels are compiled twice: with strict IEEE semantics, and with the LLVM flags of
:data:`SAFE_FASTMATH`, which let the loops vectorise without changing any element-wise
result. The script checks that every version gives the same prox (float32: equal to a few
ulps) and prints the times per prox call and the speed-ups. Needs numba (``pip install
numba``), which spslidar itself does not use. Run:

    python benchmarks/fused_tv_prox.py [--inner 3] [--repeat 20]

Measured on the 2-core development VM (2026-11-22, the variants taking turns, best of 20):
numpy 24.6 ms, numba strict 23.8 ms (1.03x), numba safe fastmath 13.5 ms (1.8x; 1.9x in a
second run). Fusing alone gains nothing: the loops only speed up once they vectorise. In the
Table I workload (37.4 s in one process that day) about 15 s are dense products (the floor:
1372 products of 1024 x 4096 by 4096 x 183 at 8-12 ms each) and about 18 s element-wise passes
(per solve: FISTA 1.6 s of which 1.0 s TV prox, TwIST 1.9 s, TVAL3 2.8 s, GPSR 2.5 s). Even if
every element-wise pass of the four solvers were rewritten as such a kernel and gained as much,
the workload would land at about 29-30 s: at the issue's 30 s target, not reliably under it,
for a numba dependency and several seconds of JIT compilation on a first run. So spslidar
stays NumPy + BLAS.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import _cli
import numpy as np

from spslidar import pipeline
from spslidar.solvers.regularisers import TV

sys.path.insert(0, str(Path(__file__).parent))
from solvers import build_problem  # noqa: E402  (the benchmarks' shared problem builder)

#: LLVM flags that allow vectorising the loops without changing any element-wise result: no
#: NaN / inf / signed-zero care (max and min become vector instructions) and reassociation
#: (the per-column float64 sums of the stop test may add in another order); no contraction
#: into FMAs, no approximate reciprocals or square roots
SAFE_FASTMATH = {"nnan", "ninf", "nsz", "reassoc"}


def _kernels(fastmath):
    """The fused FGP kernels (compiled on first call), or ``None`` without numba."""
    try:
        from numba import njit
    except ImportError:
        return None
    opts = {"nogil": True, "fastmath": fastmath}

    @njit(**opts)
    def primal_row(vt, rr, i, out, nonneg, eighth, zero):
        nx, k = out.shape
        for j in range(nx):
            for m in range(k):
                out[j, m] = vt[i, j, m] + rr[0, i, j, m] + rr[1, i, j, m]
            if i > 0:
                for m in range(k):
                    out[j, m] -= rr[0, i - 1, j, m]
            if j > 0:
                for m in range(k):
                    out[j, m] -= rr[1, i, j - 1, m]
            for m in range(k):
                out[j, m] = (max(out[j, m], zero) if nonneg else out[j, m]) * eighth

    @njit(**opts)
    def fgp_iteration(vt, rr, P, Q, R, c, nonneg, zbuf):
        """Q = proj(rr + G P_C(vt - G^T rr) / 8), R = Q + c (Q - P); returns the two norms."""
        ny = vt.shape[0]
        nx, k = zbuf.shape[1], zbuf.shape[2]
        one = c * 0 + 1
        zero = c * 0
        zc, zn = zbuf[0], zbuf[1]
        primal_row(vt, rr, 0, zc, nonneg, one / 8, zero)
        acc_d = np.zeros(k)
        acc_p = np.zeros(k)
        for i in range(ny):
            if i + 1 < ny:
                primal_row(vt, rr, i + 1, zn, nonneg, one / 8, zero)
                for j in range(nx):
                    for m in range(k):
                        Q[0, i, j, m] = (zn[j, m] - zc[j, m]) + rr[0, i, j, m]
            else:
                Q[0, i] = zero
            for j in range(nx - 1):
                for m in range(k):
                    Q[1, i, j, m] = (zc[j + 1, m] - zc[j, m]) + rr[1, i, j, m]
            Q[1, i, nx - 1] = zero
            for j in range(nx):
                for m in range(k):
                    q0 = Q[0, i, j, m]
                    q1 = Q[1, i, j, m]
                    w = np.sqrt(max(q0 * q0 + q1 * q1, one))
                    q0 = q0 / w
                    q1 = q1 / w
                    Q[0, i, j, m] = q0
                    Q[1, i, j, m] = q1
                    d0 = q0 - P[0, i, j, m]
                    d1 = q1 - P[1, i, j, m]
                    acc_d[m] += np.float64(d0 * d0) + np.float64(d1 * d1)
                    acc_p[m] += np.float64(q0 * q0) + np.float64(q1 * q1)
                    R[0, i, j, m] = d0 * c + q0
                    R[1, i, j, m] = d1 * c + q1
            zc, zn = zn, zc
        return acc_d.sum(), acc_p.sum()

    @njit(**opts)
    def primal(v, p, t, nonneg, out):
        ny, nx, k = v.shape
        zero = t * 0
        for i in range(ny):
            for j in range(nx):
                for m in range(k):
                    s = p[0, i, j, m] + p[1, i, j, m]
                    if i > 0:
                        s -= p[0, i - 1, j, m]
                    if j > 0:
                        s -= p[1, i, j - 1, m]
                    s = s * t + v[i, j, m]
                    out[i, j, m] = max(s, zero) if nonneg else s

    return fgp_iteration, primal


def fused_prox(kern, v3: np.ndarray, t: float, n_inner: int, nonneg: bool) -> np.ndarray:
    """The non-negative isotropic TV prox by ``n_inner`` FGP iterations from a zero dual."""
    fgp_iteration, primal = kern
    dt = v3.dtype
    ny, nx, k = v3.shape
    vt = v3 * dt.type(1.0 / t)
    P, Q, Ra, Rb = (np.zeros((2, ny, nx, k), dt) for _ in range(4))
    zbuf = np.empty((2, nx, k), dt)
    rr, s = P, 1.0
    for it in range(1, n_inner + 1):
        s_new = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * s * s))
        c = (s - 1.0) / s_new
        fgp_iteration(vt, rr, P, Q, Ra, dt.type(c), nonneg, zbuf)
        P, Q = Q, P
        if it < n_inner:
            rr, Ra, Rb = (Ra, Rb, Ra) if c > 0 else (P, Ra, Rb)
        s = s_new
    out = np.empty_like(v3)
    primal(v3, P, dt.type(t), nonneg, out)
    return out


def _interleaved(fns: dict, repeat: int) -> dict:
    """Best time of each function over ``repeat`` rounds, the functions taking turns in every
    round (so that a drift of the machine's speed affects them alike)."""
    best = {name: math.inf for name in fns}
    for _ in range(repeat):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            best[name] = min(best[name], time.perf_counter() - t0)
    return best


def main(argv=None) -> int:
    ap = _cli.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--inner", type=_cli.positive_int, default=pipeline.TV_INNER,
                    help=f"FGP iterations per prox call (default: the pipeline's, "
                         f"{pipeline.TV_INNER})")
    ap.add_argument("--repeat", type=_cli.positive_int, default=20,
                    help="rounds, the best time of each variant kept (default 20)")
    args = ap.parse_args(argv)

    meas = pipeline.measure(scene="motorcycle", noise=5.0, size=64)
    prob = build_problem(meas, "fista")
    A, y = prob.A, np.asarray(prob.y, dtype=np.float32)
    # a prox input like FISTA's: a gradient step's worth of back-projected data
    v = np.ascontiguousarray(A.rmatvec(y) * np.float32(50.0))
    t = 10 * prob.lam
    ny, nx = prob.image_shape
    v3 = v.reshape(ny, nx, -1)
    print(f"TV prox on {ny}x{nx}x{v3.shape[2]} float32 (Table I, m_n = 5), "
          f"{args.inner} FGP iterations, one thread, best of {args.repeat}")

    def ours():
        tv = TV((ny, nx), nonneg=True, max_inner=args.inner, inner_tol=0.0, warm_start=False,
                threads=1)
        return tv.prox(v, t)

    fns = {"numpy (spslidar TV.prox)": ours}
    ref = ours()
    for label, flags in (("numba, strict IEEE", False), ("numba, safe fastmath", SAFE_FASTMATH)):
        kern = _kernels(flags)
        if kern is None:
            print("  numba is not installed (pip install numba): nothing to compare")
            return 0
        t0 = time.perf_counter()
        z = fused_prox(kern, v3, t, args.inner, True)
        err = float(np.max(np.abs(z.reshape(v.shape) - ref)))
        print(f"  {label}: compiled in {time.perf_counter() - t0:.1f} s, "
              f"max |difference| from numpy {err:.1e} (max |z| {float(np.max(np.abs(z))):.1f})")
        fns[label] = lambda k=kern: fused_prox(k, v3, t, args.inner, True)
    best = _interleaved(fns, args.repeat)
    t_np = best["numpy (spslidar TV.prox)"]
    for label, sec in best.items():
        print(f"  {label:26s} {sec * 1e3:8.2f} ms   {t_np / sec:5.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(_cli.run(main))
