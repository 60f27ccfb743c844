"""The paper's linear photon counter: Poisson counts per TDC bin, no dead time."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .base import DetectorModel, check_periods, means_block
from .counting import PhotonCountingDetector, poisson_rows

__all__ = ["LinearDetector"]


@dataclass
class LinearDetector(PhotonCountingDetector, DetectorModel):
    """Counts ~ Poisson(efficiency * lambda) per bin (the paper's model, eq. 4).

    The fused fast path of the simulation: with ``out`` the means' own array
    (``detect(lam, rng, out=lam)``, as the simulation calls it) the counts overwrite them in
    place, and each row's exact total comes with them
    (:func:`spslidar.detectors.counting.poisson_rows`).
    ``dead_time`` only feeds :meth:`report`'s pile-up flag.

    Examples
    --------
    >>> import numpy as np
    >>> from spslidar.detectors.linear import LinearDetector
    >>> det = LinearDetector(efficiency=1.0)
    >>> lam = np.full((4, 1000), 2.0)  # 4 patterns x 1000 TDC bins, 2 photons per bin
    >>> counts, totals = det.detect(lam, np.random.default_rng(0))
    >>> counts.shape, totals.shape
    ((4, 1000), (4,))
    >>> bool(abs(counts.mean() - det.expected(lam).mean()) < 0.15)  # Poisson around 2
    True
    >>> bool(np.array_equal(totals, counts.sum(axis=1)))
    True
    """

    name = "linear"
    linear = True
    #: options that change only :meth:`report`, not the counts, each with what it sets (a
    #: sweep over them shares its seeds and says so in these words:
    #: :func:`spslidar.pipeline.plan.report_only_keys`)
    report_only = {"dead_time": "its pile-up report (--detector gmapd models a dead time)"}

    def detect(self, lam: np.ndarray, rng: np.random.Generator | int | None,
               n_periods: int = 1, out: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
        """Poisson counts of the detected means, with each row's total
        (:meth:`~spslidar.detectors.base.DetectorModel.detect`; ``n_periods`` does not
        change the counts, but is refused, as the GMAPD refuses it, where it is not a
        positive number of code periods: 0 and -1 were taken without a word, an outside
        audit)."""
        from ..randomness import as_generator

        rng = as_generator(rng)
        check_periods(n_periods)
        lam = self.detected_means(means_block(lam))  # (an AxisError deep inside, an audit)
        if out is None:  # (the counts were written over the caller's means, an audit)
            out = np.empty(np.shape(lam), dtype=np.result_type(np.asarray(lam).dtype,
                                                              np.float32))
        totals = poisson_rows(lam, rng, out)
        return out, totals

    def expected(self, lam: np.ndarray, n_periods: int = 1) -> np.ndarray:
        """The detected means, ``efficiency * lam``, as a new array
        (:meth:`~spslidar.detectors.base.DetectorModel.expected`).

        At an efficiency of 1 this was ``lam`` itself, so a caller editing the result edited
        its own means (an outside audit); ``n_periods`` is checked as :meth:`detect` checks
        it."""
        check_periods(n_periods)
        means = self.detected_means(lam)
        return np.array(means, copy=True) if means is lam else means

    def report(self, counts_per_period: float, period_s: float,
               pulsed: bool = False, incident_per_period: float | None = None
               ) -> dict[str, Any]:
        return {"model": self.name, **self.pileup_report(counts_per_period, period_s)}
