"""What a run produced (:class:`Result`) and how it is written to disk."""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..config import Config
from ..outdir import write_result_dir


@dataclass
class Result:
    """Everything one run produced. ``metrics`` is what ``metrics.json`` holds."""

    config: Config
    scene: Any
    depth: np.ndarray
    slices: np.ndarray
    lags: np.ndarray
    corr: np.ndarray
    metrics: dict[str, Any]
    timing: dict[str, float]
    warnings: list[str] = field(default_factory=list)
    #: per-pixel confidence of the depth estimate in [0, 1], and the low-confidence mask
    confidence: np.ndarray | None = None
    low_confidence: np.ndarray | None = None

    @property
    def truth(self) -> np.ndarray:
        return self.scene.depth

    @property
    def depth_rmse(self) -> float:
        return self.metrics["depth_rmse_m"]

    def summary(self) -> str:
        """Two lines: what was run and what came out."""
        c, m = self.config, self.metrics
        what = (f"{c.lidar} {m['code_description']}, scene {self.scene.name} {c.size}x{c.size}, "
                f"{m['n_patterns']} {c.patterns} patterns ({100 * c.compression:g}%), "
                f"{'QCR' if c.qcr else 'no QCR'}, {c.solver}")
        t = self.timing
        out = (f"depth RMSE {m['depth_rmse_m']:.4f} m ({m['depth_rmse_m'] / m['bin_depth_m']:.2f} "
               f"bins) over {100 * m['coverage']:.0f}% of pixels, "
               f"{100 * m['missing_fraction']:.1f}% without return, "
               f"{100 * m.get('low_confidence_fraction', 0.0):.0f}% low-confidence; "
               f"{t['total']:.2f} s (simulate {t['simulate']:.2f}, solve {t['solve']:.2f})")
        return f"{what}\n{out}"

    def save(self, out_dir: str | os.PathLike, figure: bool = True,
             overwrite: bool = False) -> Path:
        """Write ``metrics.json``, ``depth.npy``, ``truth.npy``, ``valid.npy`` and
        ``depth.png`` into ``out_dir``, all or nothing (see :mod:`spslidar.outdir`).

        ``out_dir`` must not exist, be empty, or (with ``overwrite=True``) hold a previous
        spslidar result; anything else is refused before a file is written, so a user's
        files are never touched.
        """

        def fill(tmp: Path) -> None:
            t0 = time.perf_counter()
            np.save(tmp / "depth.npy", self.depth)
            np.save(tmp / "truth.npy", self.truth)
            np.save(tmp / "valid.npy", np.asarray(self.scene.valid, dtype=bool))
            if figure:
                from ..figures import depth_figure

                depth_figure(self, tmp / "depth.png")
            self.timing["write"] = time.perf_counter() - t0
            self.metrics["timing_s"] = dict(self.timing)
            with open(tmp / "metrics.json", "w") as fh:
                json.dump(_jsonable(self.metrics), fh, indent=2, allow_nan=True)

        return write_result_dir(out_dir, fill, overwrite=overwrite)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    return obj
