"""The chain on a CUDA GPU (PyTorch, CuPy): skipped cleanly on machines without one (CI)."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.backends import get_backend, is_available

GPU_BACKENDS = [b for b in ("torch", "cupy") if is_available(b, "cuda")]
pytestmark = pytest.mark.skipif(not GPU_BACKENDS, reason="no CUDA GPU (torch or cupy) here")
SMALL = {"size": 32, "code_length": 4095}


@pytest.fixture(params=GPU_BACKENDS or ["none"])
def backend(request):
    return request.param


def test_runs_are_reproducible_on_the_gpu(backend):
    from spslidar.pipeline.chain import run

    a = run(**SMALL, backend=backend, device="cuda", seed=3)
    b = run(**SMALL, backend=backend, device="cuda", seed=3)
    np.testing.assert_array_equal(a.depth, b.depth)
    assert a.metrics["config"]["device"] == "cuda"


def test_gpu_rmse_statistics_match_numpy(backend):
    """Own random streams: compare the depth RMSE over seeds, not the maps."""
    from spslidar.pipeline.chain import run

    gpu = [run(**SMALL, backend=backend, device="cuda", seed=s).depth_rmse for s in range(5)]
    cpu = [run(**SMALL, seed=s).depth_rmse for s in range(5)]
    assert abs(np.mean(gpu) - np.mean(cpu)) <= 0.25 * np.mean(cpu) + 0.005


@pytest.mark.parametrize("graphed", [False, True])
def test_gpu_fista_tv_matches_numpy(backend, graphed):
    """Same inputs (no random streams): FISTA + TV on the GPU gives NumPy's solution (torch:
    also with the iteration replayed from a CUDA graph)."""
    from spslidar.backends.kernels import DenseOperator, TVProx, fista_tv
    from spslidar.operators import MatrixOperator
    from spslidar.solvers import StopRule
    from spslidar.solvers.fista import FISTA
    from spslidar.solvers.regularisers import TV

    if graphed and backend != "torch":
        pytest.skip("CUDA graphs are used with torch only")
    if graphed:
        from spslidar.backends.torch_graph import fista_tv_graphed as fista_tv
    be = get_backend(backend, "cuda")
    for seed in (0, 1):  # the second solve of the same shape replays the cached graph
        rng = np.random.default_rng(seed)
        shape, k = (16, 16), 7
        a = (rng.standard_normal((100, 256)) / 10).astype(np.float32)
        x_true = np.zeros((256, k), np.float32)
        x_true[40 + 10 * seed:120] = 1.0
        y = (a @ x_true + 0.01 * rng.standard_normal((100, k))).astype(np.float32)
        ref, info = FISTA(stop=StopRule(max_iter=60, rtol=1e-4)).solve(
            MatrixOperator(a, dtype=np.float32), y, TV(shape, nonneg=True, max_inner=3), 0.05)
        got, ginfo = fista_tv(be, DenseOperator(be.asarray(a)), be.asarray(y),
                              TVProx(be.xp, shape, nonneg=True, max_inner=3, be=be), 0.05, 60,
                              1e-4)
        assert ginfo.iterations == info.iterations
        assert np.linalg.norm(be.to_numpy(got) - ref) <= 1e-4 * np.linalg.norm(ref)


def test_gpu_hadamard_matches_the_host_transform(backend):
    from spslidar.backends.patterns import DeviceHadamard
    from spslidar.patterns import PATTERNS, build_patterns

    if "hadamard" not in PATTERNS.names():
        pytest.skip("no hadamard pattern kind")
    be = get_backend(backend, "cuda")
    host = build_patterns("scrambled-hadamard", 200, 32, np.random.default_rng(1))
    dev = DeviceHadamard(host, be)
    x = np.random.default_rng(2).standard_normal((1024, 3)).astype(np.float32)
    y = np.random.default_rng(3).standard_normal((200, 3)).astype(np.float32)
    np.testing.assert_allclose(be.to_numpy(dev.apply(be.asarray(x))), host.matvec(x),
                               rtol=0, atol=1e-3)
    np.testing.assert_allclose(be.to_numpy(dev.apply_t(be.asarray(y))), host.rmatvec(y),
                               rtol=0, atol=1e-3)
