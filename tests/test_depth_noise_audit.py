"""The depth estimators on noise nobody here wrote (an outside statistical audit of
2026-12-02): sparse profiles, most of whose entries are exactly 0, as a photon histogram at low
flux gives."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.depth import DepthContext
from spslidar.depth.mrf import MRFDepth, auto_truncation
from spslidar.depth.profile import NO_NOISE_MAXIMUM, noise_maxima, typical_noise_maximum


def _sparse(seed: int, n: int = 64, k: int = 16) -> np.ndarray:
    """Pure noise: exponential spikes in 10 % of the entries, the rest 0."""
    rng = np.random.default_rng(seed)
    return (rng.exponential(1.0, (n * n, k)) * (rng.random((n * n, k)) < 0.1)).astype(
        np.float32)


def test_typical_noise_maximum_is_over_the_profiles_that_hold_noise():
    assert typical_noise_maximum(np.array([0.0, 0.0, 0.0, 1.0, 3.0])) == 2.0
    assert typical_noise_maximum(np.array([1.0, 2.0, 4.0])) == 2.0  # (dense: the median)
    assert typical_noise_maximum(np.zeros(7)) == NO_NOISE_MAXIMUM
    assert typical_noise_maximum(np.zeros(0)) == NO_NOISE_MAXIMUM


@pytest.mark.parametrize("seed", [4000, 4001, 4002])
def test_sparse_pure_noise_keeps_almost_no_dots(seed):
    """Over half of these profiles' noise maxima are 0, which made the typical one 0 and
    every level of it 0: 546 of 4 096 noise pixels were kept as one-pixel objects (seed
    4000). A noise pixel may still stand out by chance, a few in 4 096."""
    x = _sparse(seed)
    ctx = DepthContext(np.arange(1000, 1016), 1e-10, 0.5, (64, 64))
    est = MRFDepth()
    z = est.evidence(x)
    assert np.median(noise_maxima(z)) == 0.0  # (the case: most maxima are 0)
    assert auto_truncation(z) > 0.25
    assert est.estimate(x, ctx).info["dot_pixels"] <= 4
