"""FISTA + TV on a CUDA device through PyTorch, one iteration captured as a CUDA graph.

On small problems (a 64x64 run: ``(4096, 61)`` blocks) an iteration of
:func:`spslidar.backends.kernels.fista_tv` is ~200 tiny kernels, and the time goes to Python
and kernel-launch overhead, not to the GPU. Here one whole iteration (gradient step, the FGP
prox with its ``max_inner`` dual iterations, the product with ``A``, the extrapolation and the
two norms of the stop test) is captured once per solve into a ``torch.cuda.CUDAGraph`` and
replayed: one launch and one 8-byte read-back per iteration.

The iterates are those of :func:`~spslidar.backends.kernels.fista_tv`: the prox's early stop
(``||p_k - p_{k-1}|| <= inner_tol ||p_k||``) is taken branch-free (every dual iteration runs
and the first one that meets the test is selected), the extrapolation coefficient of each
iteration is written into a device scalar before its replay, and the objective is evaluated
once, at the end.
"""

from __future__ import annotations

import math
from typing import Any

from .kernels import FistaInfo, TVProx, power_norm


def _grad(z: Any) -> tuple[Any, Any]:
    import torch

    g0 = torch.zeros_like(z)
    g1 = torch.zeros_like(z)
    torch.sub(z[1:], z[:-1], out=g0[:-1])
    torch.sub(z[:, 1:], z[:, :-1], out=g1[:, :-1])
    return g0, g1


def _neg_div(p0: Any, p1: Any, v: Any = None) -> Any:
    out = p0 + p1 if v is None else v + p0 + p1
    out[1:] -= p0[:-1]
    out[:, 1:] -= p1[:, :-1]
    return out


def fista_tv_graphed(be: Any, A: Any, y: Any, reg: TVProx, lam: float, max_iter: int,
                     rtol: float, L: float | None = None,
                     graph: bool = True) -> tuple[Any, FistaInfo]:
    """:func:`spslidar.backends.kernels.fista_tv` with each iteration replayed from a CUDA
    graph (PyTorch on CUDA).

    ``graph=False`` runs the same branch-free iteration eagerly (any PyTorch device: the
    tests check it on the CPU against the NumPy solver).
    """
    import torch

    if L is None:
        L = power_norm(be, A) ** 2
    L, lam = float(L), float(lam)
    if not (math.isfinite(L) and L > 0):
        raise ValueError(f"Lipschitz constant must be positive and finite, got {L}")
    info = FistaInfo(L=L)
    mat = A.matrix if hasattr(A, "matrix") else None
    matvec = (lambda v: mat @ v) if mat is not None else A.matvec
    rmatvec = (lambda v: mat.T @ v) if mat is not None else A.rmatvec
    ny, nx = reg.image_shape
    n, k = A.shape[1], y.shape[1]
    dev, dt = y.device, y.dtype
    x = torch.zeros((n, k), dtype=dt, device=dev)
    ax = torch.zeros_like(y)
    yk, ayk = torch.zeros_like(x), torch.zeros_like(y)
    p0 = torch.zeros((ny, nx, k), dtype=dt, device=dev)
    p1 = torch.zeros_like(p0)
    cm = torch.zeros((), dtype=dt, device=dev)
    norms = torch.zeros(2, dtype=torch.float64, device=dev)
    neg_inv_l, t = -1.0 / L, lam / L
    tol2 = reg.inner_tol ** 2
    # the prox's extrapolation coefficients (the same at every call: s restarts at 1)
    coefs, s = [], 1.0
    for _ in range(reg.max_inner):
        s_new = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * s * s))
        coefs.append((s - 1.0) / s_new)
        s = s_new

    def prox(g: Any) -> Any:
        v3 = g.reshape(ny, nx, k)
        vt = v3 * (1.0 / t)
        r0, r1, q_prev = p0, p1, (p0, p1)
        picks = []
        for i, c in enumerate(coefs):
            z = _neg_div(r0, r1, vt)
            if reg.nonneg:
                z.clamp_(min=0.0)
            z *= 0.125
            g0, g1 = _grad(z)
            q0, q1 = g0.add_(r0), g1.add_(r1)
            w = torch.sqrt(torch.clamp(q0 * q0 + q1 * q1, min=1.0))
            q0, q1 = q0 / w, q1 / w
            if i == len(coefs) - 1:
                break
            d0, d1 = q0 - q_prev[0], q1 - q_prev[1]
            dn2 = torch.sum(d0 * d0) + torch.sum(d1 * d1)
            pn2 = torch.sum(q0 * q0) + torch.sum(q1 * q1)
            picks.append((dn2 <= tol2 * torch.clamp(pn2, min=1e-60), q0, q1))
            r0, r1 = (q0 + c * d0, q1 + c * d1) if c > 0.0 else (q0, q1)
            q_prev = (q0, q1)
        for ok, a0, a1 in reversed(picks):  # the first dual iterate that met the test wins
            q0, q1 = torch.where(ok, a0, q0), torch.where(ok, a1, q1)
        p0.copy_(q0)
        p1.copy_(q1)
        out = _neg_div(q0, q1) * t + v3
        if reg.nonneg:
            out.clamp_(min=0.0)
        return out.reshape(n, k)

    def step() -> None:
        g = rmatvec(ayk - y) * neg_inv_l + yk
        z = prox(g)
        az = matvec(z)
        d = z - x
        norms[0] = torch.sum(d * d, dtype=torch.float64)
        norms[1] = torch.sum(z * z, dtype=torch.float64)
        yk.copy_(d * cm + z)
        ayk.copy_(az + cm * (az - ax))
        x.copy_(z)
        ax.copy_(az)

    run_step = step
    if graph:
        side = torch.cuda.Stream(device=dev)
        side.wait_stream(torch.cuda.current_stream(dev))
        with torch.cuda.stream(side):
            step()  # warm-up (allocator, cuBLAS handles) on a side stream, then back to zero
        torch.cuda.current_stream(dev).wait_stream(side)
        for a in (x, ax, yk, ayk, p0, p1):
            a.zero_()
        cuda_graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(cuda_graph):
            step()
        run_step = cuda_graph.replay
    tk = 1.0
    for it in range(1, max_iter + 1):
        t_new = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * tk * tk))
        cm.fill_((tk - 1.0) / t_new)
        tk = t_new
        run_step()
        dn2, xn2 = norms.tolist()
        info.iterations = it
        reason = ""
        if not (math.isfinite(dn2) and math.isfinite(xn2)):
            reason = "diverged"
        elif rtol > 0 and it > 1 and math.sqrt(dn2) <= rtol * max(math.sqrt(xn2), 1e-300):
            reason = "rtol"
        elif it >= max_iter:
            reason = "max_iter"
        if reason:
            info.stop_reason = reason
            break
    result = x.clone()
    r = ax - y
    info.objective.append(float(0.5 * torch.sum(r * r, dtype=torch.float64)
                                + lam * torch.sum(reg.values(result))))
    return result, info
