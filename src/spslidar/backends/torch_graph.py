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

from .kernels import FistaInfo, TVProx, power_norm, stop_reason


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


#: captured iterations kept for reuse, by problem shape (a sweep solves the same shapes again
#: and again: capturing costs about as much as 20 iterations of a 64x64 run)
_GRAPHS: dict[tuple, Any] = {}
#: only problems whose matrix has fewer entries than this are kept (the cache holds a copy)
GRAPH_CACHE_MAX_SIZE = 1 << 26


class _Iteration:
    """The static tensors of one FISTA + TV iteration and the iteration itself (:meth:`step`),
    written with in-place updates so that it can be captured once and replayed."""

    def __init__(self, A: Any, y: Any, reg: TVProx, own_matrix: bool):
        import torch

        dev, dt = y.device, y.dtype
        self.dense = hasattr(A, "matrix")
        self.A = A
        self.mat = (A.matrix.clone() if own_matrix else A.matrix) if self.dense else None
        self.y = y.clone() if own_matrix else y
        ny, nx = reg.image_shape
        self.shape3 = (ny, nx, y.shape[1])
        n = A.shape[1]
        self.x = torch.zeros((n, y.shape[1]), dtype=dt, device=dev)
        self.ax = torch.zeros_like(self.y)
        self.yk, self.ayk = torch.zeros_like(self.x), torch.zeros_like(self.y)
        self.p0 = torch.zeros(self.shape3, dtype=dt, device=dev)
        self.p1 = torch.zeros_like(self.p0)
        # per-solve and per-iteration scalars, on the device so that a replay reads them
        self.cm, self.neg_inv_l, self.t, self.inv_t = (torch.zeros((), dtype=dt, device=dev)
                                                       for _ in range(4))
        self.norms = torch.zeros(2, dtype=torch.float64, device=dev)
        self.nonneg = reg.nonneg
        self.isotropic = reg.isotropic
        self.tol2 = reg.inner_tol ** 2
        # the prox's extrapolation coefficients (the same at every call: s restarts at 1)
        self.coefs, s = [], 1.0
        for _ in range(reg.max_inner):
            s_new = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * s * s))
            self.coefs.append((s - 1.0) / s_new)
            s = s_new
        self.graph = None

    def bind(self, A: Any, y: Any, L: float, lam: float) -> None:
        """Load a problem into the static tensors and start from zero."""
        if self.mat is not None and self.mat is not A.matrix:
            self.mat.copy_(A.matrix)
        if self.y is not y:
            self.y.copy_(y)
        t = lam / L
        self.neg_inv_l.fill_(-1.0 / L)
        self.t.fill_(t)
        self.inv_t.fill_(1.0 / t if t > 0 else 0.0)
        self.zero()

    def zero(self) -> None:
        for a in (self.x, self.ax, self.yk, self.ayk, self.p0, self.p1):
            a.zero_()

    def matvec(self, v: Any) -> Any:
        return self.mat @ v if self.dense else self.A.matvec(v)

    def rmatvec(self, v: Any) -> Any:
        return self.mat.T @ v if self.dense else self.A.rmatvec(v)

    def prox(self, g: Any) -> Any:
        """The FGP prox of :class:`TVProx`, branch-free, warm-started from ``p0, p1``."""
        import torch

        v3 = g.reshape(self.shape3)
        vt = v3 * self.inv_t
        r0, r1, q_prev = self.p0, self.p1, (self.p0, self.p1)
        picks = []
        for i, c in enumerate(self.coefs):
            z = _neg_div(r0, r1, vt)
            if self.nonneg:
                z.clamp_(min=0.0)
            z *= 0.125
            g0, g1 = _grad(z)
            q0, q1 = g0.add_(r0), g1.add_(r1)
            if self.isotropic:
                w = torch.sqrt(torch.clamp(q0 * q0 + q1 * q1, min=1.0))
                q0, q1 = q0 / w, q1 / w
            else:
                q0, q1 = q0.clamp(-1.0, 1.0), q1.clamp(-1.0, 1.0)
            if i == len(self.coefs) - 1:
                break
            d0, d1 = q0 - q_prev[0], q1 - q_prev[1]
            dn2 = torch.sum(d0 * d0) + torch.sum(d1 * d1)
            pn2 = torch.sum(q0 * q0) + torch.sum(q1 * q1)
            picks.append((dn2 <= self.tol2 * torch.clamp(pn2, min=1e-60), q0, q1))
            r0, r1 = (q0 + c * d0, q1 + c * d1) if c > 0.0 else (q0, q1)
            q_prev = (q0, q1)
        for ok, a0, a1 in reversed(picks):  # the first dual iterate that met the test wins
            q0, q1 = torch.where(ok, a0, q0), torch.where(ok, a1, q1)
        self.p0.copy_(q0)
        self.p1.copy_(q1)
        out = _neg_div(q0, q1) * self.t + v3
        if self.nonneg:
            out.clamp_(min=0.0)
        return out.reshape(self.x.shape)

    def step(self) -> None:
        """One FISTA iteration; leaves ``||x_k - x_{k-1}||^2, ||x_k||^2`` in ``norms``."""
        import torch

        g = self.rmatvec(self.ayk - self.y) * self.neg_inv_l + self.yk
        z = self.prox(g)
        az = self.matvec(z)
        d = z - self.x
        self.norms[0] = torch.sum(d * d, dtype=torch.float64)
        self.norms[1] = torch.sum(z * z, dtype=torch.float64)
        self.yk.copy_(d * self.cm + z)
        self.ayk.copy_(az + self.cm * (az - self.ax))
        self.x.copy_(z)
        self.ax.copy_(az)

    def capture(self) -> None:
        """Warm up on a side stream, then capture :meth:`step` into a CUDA graph."""
        import torch

        dev = self.x.device
        side = torch.cuda.Stream(device=dev)
        side.wait_stream(torch.cuda.current_stream(dev))
        with torch.cuda.stream(side):
            self.step()  # allocator and cuBLAS workspaces, before the capture
        torch.cuda.current_stream(dev).wait_stream(side)
        self.zero()
        self.graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(self.graph):
            self.step()


def fista_tv_graphed(be: Any, A: Any, y: Any, reg: TVProx, lam: float, max_iter: int,
                     rtol: float, L: float | None = None,
                     graph: bool = True) -> tuple[Any, FistaInfo]:
    """:func:`spslidar.backends.kernels.fista_tv` with each iteration replayed from a CUDA
    graph (PyTorch on CUDA).

    Dense problems of fewer than :data:`GRAPH_CACHE_MAX_SIZE` matrix entries reuse the graph
    of an earlier solve of the same shape (the matrix and data are copied into its tensors).
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
    cacheable = (graph and hasattr(A, "matrix")
                 and A.shape[0] * A.shape[1] < GRAPH_CACHE_MAX_SIZE)
    key = (str(y.device), str(y.dtype), tuple(A.shape), y.shape[1], reg.image_shape,
           reg.nonneg, reg.max_inner, reg.inner_tol)
    it_state = _GRAPHS.get(key) if cacheable else None
    if it_state is None:
        it_state = _Iteration(A, y, reg, own_matrix=cacheable)
        it_state.bind(A, y, L, lam)
        if graph:
            it_state.capture()
        if cacheable:
            if len(_GRAPHS) >= 4:
                _GRAPHS.clear()
            _GRAPHS[key] = it_state
    it_state.bind(A, y, L, lam)
    run_step = it_state.graph.replay if graph else it_state.step
    tk = 1.0
    for it in range(1, max_iter + 1):
        t_new = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * tk * tk))
        it_state.cm.fill_((tk - 1.0) / t_new)
        tk = t_new
        run_step()
        dn2, xn2 = it_state.norms.tolist()
        info.iterations = it
        reason = stop_reason(math.isfinite(dn2) and math.isfinite(xn2), dn2, xn2, it, rtol,
                             max_iter)
        if reason:
            info.stop_reason = reason
            break
    result = it_state.x.clone()
    r = it_state.ax - it_state.y
    info.objective.append(float(0.5 * torch.sum(r * r, dtype=torch.float64)
                                + lam * torch.sum(reg.values(result))))
    if not cacheable:
        it_state.graph = None
    return result, info
