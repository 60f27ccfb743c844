"""Random streams per backend: the patterns and the photon counts of a run.

``numpy`` and ``array-api-strict`` use NumPy's generators split exactly as the NumPy path
splits them (so their runs reproduce its patterns and Poisson streams); ``torch`` and ``cupy``
draw on the device from their own generators, seeded from the same
``numpy.random.SeedSequence`` children. Each backend and device is reproducible with itself;
the numbers differ across backends (see :mod:`spslidar.backends`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: backends whose streams are NumPy's (host) generators
HOST_STREAMS = ("numpy", "array-api-strict")


def device_seed(seq: np.random.SeedSequence) -> int:
    """A 63-bit seed for a device generator from a ``SeedSequence`` child."""
    return int(seq.generate_state(1, np.uint64)[0] >> np.uint64(1))


class Stream:
    """One role's random numbers (patterns or counts) on a backend.

    Parameters
    ----------
    be : Backend
    seq : numpy.random.SeedSequence
        The role's child of the run's seed.
    """

    def __init__(self, be: Any, seq: np.random.SeedSequence):
        self.be = be
        self.host = be.name in HOST_STREAMS
        self.seq = seq
        if self.host:
            self.gen = np.random.default_rng(seq)
        elif be.name == "torch":
            import torch

            self.gen = torch.Generator(device=be.device)
            self.gen.manual_seed(device_seed(seq))
        else:  # cupy
            import cupy

            self.gen = cupy.random.RandomState(seed=device_seed(seq) % (2**32))

    def host_generator(self) -> np.random.Generator:
        """The NumPy generator of this role (host streams: the NumPy path's own)."""
        return self.gen if self.host else np.random.default_rng(self.seq)

    def device_patterns(self, kind: str, m: int, n_side: int, sigma: float, dtype: Any) -> Any:
        """``M`` ``gaussian`` (``clip(0.5 + sigma N(0, 1), 0, 1)``) or ``bernoulli`` (on with
        probability 1/2) patterns drawn on the device, as an ``(M, N^2)`` array (device
        streams only; host streams build them with the registry's factory, see
        :func:`spslidar.backends.patterns.device_patterns`)."""
        xp, be = self.be.xp, self.be
        q = n_side * n_side
        np_dtype = np.float32 if dtype == xp.float32 else np.float64
        if be.name == "torch":
            import torch

            tdt = torch.float32 if np_dtype == np.float32 else torch.float64
            if kind == "gaussian":
                phi = torch.randn((m, q), generator=self.gen, device=be.device, dtype=tdt)
                return phi.mul_(sigma).add_(0.5).clamp_(0.0, 1.0)
            u = torch.rand((m, q), generator=self.gen, device=be.device, dtype=tdt)
            return (u < 0.5).to(tdt)
        if kind == "gaussian":
            phi = self.gen.standard_normal((m, q), dtype=np_dtype)
            return xp.clip(phi * sigma + 0.5, min=0.0, max=1.0)
        return xp.astype(self.gen.random_sample((m, q), dtype=np_dtype) < 0.5, dtype)

    def children(self, n: int) -> list[Any]:
        """``n`` NumPy child generators (host streams: the NumPy path's per-block streams)."""
        return self.gen.spawn(n) if self.host else [None] * n

    def poisson(self, lam: Any, child: Any = None, detector: Any = None,
                n_periods: int = 1) -> tuple[Any, Any]:
        """Poisson counts with means ``lam`` (``(B, L)`` float32) and each row's total.

        Host streams draw with the detector's own kernel from the block's ``child`` (as the
        NumPy path does); device streams with ``torch.poisson`` / CuPy's sampler.

        Returns
        -------
        counts : array, float32, shape (B, L)
        totals : array, float64, shape (B,)
        """
        be, xp = self.be, self.be.xp
        if self.host:
            host = np.array(be.to_numpy(lam), dtype=np.float32)
            from ..detectors.base import checked_detect

            counts, totals = checked_detect(detector, host, child, n_periods, out=host)
            return be.asarray(counts), be.asarray(np.asarray(totals, dtype=np.float64))
        if be.name == "torch":
            import torch

            counts = torch.poisson(lam, generator=self.gen)
        else:
            counts = xp.astype(self.gen.poisson(lam), xp.float32)
        return counts, xp.sum(counts, axis=1, dtype=xp.float64)

    def standard_normal(self, shape: tuple[int, ...]) -> np.ndarray:
        """Host standard normals (for the small probes)."""
        return np.random.default_rng(self.seq).standard_normal(shape)
