"""The Python API as a notebook uses it (an outside audit of 2026-11-29): runs in a thread
pool keep their own warnings and leave BLAS as they found it; results and measurements sent
through pickle or deepcopy keep their arrays read-only; stages pickle."""

from __future__ import annotations

import copy
import pickle
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from threadpoolctl import threadpool_info

import spslidar

SMALL = dict(scene="camera", size=16, code_length=255, iterations=30)


def _blas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_runs_in_threads_keep_their_own_warnings_and_blas():
    """A GPSR run on an odd side (the wavelet warns) beside a TV run, both in a thread pool,
    five times: the warning is the GPSR run's only; BLAS's threads are as before."""
    before = _blas_threads()
    odd = spslidar.measure(**dict(SMALL, size=15, solver="gpsr"))
    for _ in range(5):
        with ThreadPoolExecutor(2) as pool:
            a = pool.submit(spslidar.reconstruct, odd)
            b = pool.submit(spslidar.run, **SMALL)
            a, b = a.result(), b.result()
        assert any("wavelet" in w for w in a.warnings)
        assert not any("wavelet" in w for w in b.warnings)
    # (a BLAS library loaded meanwhile, SciPy's, starts at the same default)
    assert set(_blas_threads()) == set(before)


def test_runs_in_threads_equal_runs_in_turn():
    with ThreadPoolExecutor(2) as pool:
        threaded = list(pool.map(lambda s: spslidar.run(**SMALL, seed=s).depth, (1, 2, 3, 4)))
    for seed, depth in zip((1, 2, 3, 4), threaded, strict=True):
        np.testing.assert_array_equal(depth, spslidar.run(**SMALL, seed=seed).depth)
