"""What a run produced (:class:`Result`) and how it is written to disk."""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..config import Config
from ..metrics import mostly_noise, returns_phrase
from ..metrics import percent as _percent
from ..outdir import write_result_dir
from ..patterns import pattern_share as _share
from ..patterns import realisation_note

#: :class:`Result`'s arrays, held as read-only views
_READ_ONLY = frozenset({"depth", "slices", "lags", "corr", "confidence", "low_confidence",
                        "reflectivity", "depth2"})


@dataclass(eq=False)
class Result:
    """Everything one run produced. ``metrics`` is what ``metrics.json`` holds. Equality is
    identity (its fields are arrays); the repr is a summary (the dataclass's ran to 28 000
    characters in a notebook cell). Its arrays are read-only views, so that what
    :meth:`save` writes agrees with ``metrics`` (``r.depth.copy()`` to edit one).

    Examples
    --------
    >>> import os, tempfile
    >>> import spslidar
    >>> r = spslidar.run(scene="camera", size=16, code_length=2047, noise=1)
    >>> r.depth.shape, r.truth.shape, r.confidence.shape
    ((16, 16), (16, 16), (16, 16))
    >>> points, intensity = r.points(fov_deg=10)  # one point per pixel with a return
    >>> points.shape, intensity.shape
    ((256, 3), (256,))
    >>> points, intensity, fields = r.cloud()  # what points.ply holds
    >>> sorted(fields)
    ['col', 'confidence', 'return_number', 'row']
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     out = r.save(os.path.join(tmp, "run"), figure=False)
    ...     print(sorted(f.name for f in out.glob("*.npy")))
    ['confidence.npy', 'depth.npy', 'reflectivity.npy', 'truth.npy', 'valid.npy']
    """

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
    #: per-pixel reflectivity (intensity) read off the reconstruction, refitted with the
    #: depth held (:mod:`spslidar.refit`; ``metrics['reflectivity_method']``, else the sum of
    #: :func:`spslidar.products.reflectivity_image`): for a simulation an estimate of alpha
    #: (which lies in [0, 1]), itself >= 0 but not bounded by 1: noise and the reconstruction
    #: take it above 1 (1.16 on procedural:4 at 16 x 16, noise 5, by the window's sum; the
    #: refit's 5-95 % on the default run 0.93-1.07); detected photons per pulse
    #: for a measured acquisition; NaN without a return
    reflectivity: np.ndarray | None = None
    #: a second surface per pixel (metres; NaN where the pixel shows one surface), where the
    #: depth estimator looks for one (:attr:`spslidar.depth.DepthEstimate.depth2`)
    depth2: np.ndarray | None = None

    def __setattr__(self, name: str, value: Any) -> None:
        # the arrays are read-only views (the caller's own arrays stay writable): a depth map
        # edited in place was saved beside the metrics of the one the run made, depth.npy all
        # zeros under metrics.json's RMSE of 0.05 m (an outside audit of 2026-12-02); an
        # array put in by assignment is the caller's deliberate choice, and frozen as well
        if name in _READ_ONLY and isinstance(value, np.ndarray):
            value = value.view()
            value.flags.writeable = False
        object.__setattr__(self, name, value)

    def __setstate__(self, state: dict) -> None:
        # a copy or an unpickled result holds read-only views too (its state was put back
        # past __setattr__: a review)
        for name, value in state.items():
            setattr(self, name, value)

    @property
    def truth(self) -> np.ndarray:
        """The ground-truth depth, NaN where the scene has none (its ``valid`` mask is False,
        as in ``truth.npy``; all NaN for a measured acquisition without one); read-only: it is
        the measurement's scene, which later reconstructions score against. (The holes held
        the nearest pixel's depth, which the scene carries to simulate them, and a user's own
        RMSE from ``depth - truth`` scored them, an audit.)"""
        if not self.has_truth:
            return np.full(np.shape(self.scene.depth), np.nan)
        valid = np.asarray(self.scene.valid, dtype=bool)
        view = (self.scene.depth.view() if valid.all()
                else np.where(valid, self.scene.depth, np.nan))
        view.flags.writeable = False
        return view

    @property
    def depth_rmse(self) -> float:
        return self.metrics["depth_rmse_m"]

    def __repr__(self) -> str:
        rmse = self.metrics.get("depth_rmse_m")
        score = "no truth" if rmse is None else f"depth RMSE {rmse:.4g} m"
        return (f"Result({self.scene.name!r}, {self.config.size}x{self.config.size}, "
                f"{self.config.solver} + {self.config.depth}, {score}, "
                f"{len(self.warnings)} warning(s))")

    def summary(self) -> str:
        """Two lines: what was run and what came out."""
        c, m = self.config, self.metrics
        note = m.get("scene_note")
        scene = f"{self.scene.name} ({note})" if note else self.scene.name
        what = (f"{c.lidar} {m['code_description']}, scene {scene} {c.size}x{c.size}, "
                f"{m['n_patterns']} {c.patterns} patterns ({_share(m['n_patterns'], c.size)}%"
                f"{realisation_note(c)}), "
                f"{'QCR' if c.qcr else 'no QCR'}, {c.solver}")
        t = self.timing
        rmse = m.get("depth_rmse_m")
        if not m.get("has_truth", True):
            bright = ("" if mostly_noise(m) else  # (noise's mean read 37 for 1: an audit)
                      f"mean reflectivity {m.get('mean_reflectivity') or 0.0:.3g}, ")
            score = f"no ground truth: {returns_phrase(m, m['coverage'])}, {bright}"
        elif rmse is None or not math.isfinite(rmse):  # (was "depth RMSE nan m (nan bins)")
            score = (f"no depth to score: none of the {m['n_valid']} pixels with a truth "
                     f"holds a return, ")
        else:
            chance = m.get("chance_rmse_m")
            # (a map of noise scores about what random depths in the gate score: said beside
            # its RMSE, which otherwise read as an instrument's, an audit)
            noise = (f" (mostly noise: depths drawn at random in the gate score {chance:.4f} "
                     f"m)" if mostly_noise(m) and chance is not None and math.isfinite(chance)
                     else "")
            score = (f"depth RMSE {m['depth_rmse_m']:.4f} m "
                     f"({m['depth_rmse_m'] / m['bin_depth_m']:.2f} bins){noise} over "
                     f"{_percent(m['coverage'])} of pixels, "
                     f"{_percent(m['missing_fraction'])} without return, ")
        out = (score +
               f"{_percent(m.get('low_confidence_fraction', 0.0))} low-confidence; "
               f"{t['total']:.2f} s (simulate {t['simulate']:.2f}, solve {t['solve']:.2f})")
        return f"{what}\n{out}"

    @property
    def has_truth(self) -> bool:
        """Whether the scene has a ground truth (False for a measured acquisition)."""
        return bool(getattr(self.scene, "has_truth", True))

    def points(self, fov_deg: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The depth map as a point cloud with its reflectivity
        (:func:`spslidar.products.point_cloud`; ``fov_deg`` default 10 degrees)."""
        from ..products import DEFAULT_FOV_DEG, point_cloud

        return point_cloud(self.depth, DEFAULT_FOV_DEG if fov_deg is None else fov_deg,
                           self.reflectivity)

    def cloud(self, fov_deg: float | None = None
              ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """The point cloud ``points.ply`` holds: each pixel's first surface with its
        reflectivity and confidence, then each second surface (:attr:`depth2`, where the
        estimator found one) with NaN for both; ``fields`` holds ``confidence`` (float),
        ``return_number`` and each point's pixel, ``row`` (0 at the top) and ``col``.
        ``return_number`` is 1 for the estimator's depth (``depth.npy``) and 2 for its second
        surface (``depth2.npy``), which may lie nearer or farther: not LAS's order of the
        returns in time (an outside audit of 2026-12-01 found 28 of 426 second surfaces of
        the fence nearer than the first)."""
        from ..products import DEFAULT_FOV_DEG, point_cloud

        fov = DEFAULT_FOV_DEG if fov_deg is None else fov_deg
        pts, intensity = self.points(fov)
        # the points are the finite depths in row-major order: their confidence the same way
        # (NaN read as 0: the estimator's own rule, so return 1's is never NaN)
        have = np.isfinite(self.depth)
        conf = (np.nan_to_num(np.asarray(self.confidence, float)[have])
                if self.confidence is not None else np.full(pts.shape[0], np.nan))
        number = np.ones(pts.shape[0], np.uint8)
        row, col = np.nonzero(have)  # (row-major, as the points)
        have2 = np.isfinite(self.depth2) if self.depth2 is not None else None
        if have2 is not None and have2.any():
            pts2, _ = point_cloud(self.depth2, fov)
            nan = np.full(pts2.shape[0], np.nan)
            pts, intensity = np.concatenate([pts, pts2]), np.concatenate([intensity, nan])
            conf = np.concatenate([conf, nan])
            number = np.concatenate([number, np.full(pts2.shape[0], 2, np.uint8)])
            row2, col2 = np.nonzero(have2)
            row, col = np.concatenate([row, row2]), np.concatenate([col, col2])
        return pts, intensity, {"confidence": conf, "return_number": number,
                                "row": row.astype(np.int64), "col": col.astype(np.int64)}

    def save(self, out_dir: str | os.PathLike, figure: bool = True,
             overwrite: bool = False, fov_deg: float | None = None, *,
             option: str = "out_dir", replace: str = "overwrite=True") -> Path:
        """Write ``metrics.json``, ``depth.npy``, ``reflectivity.npy``, ``confidence.npy``,
        ``points.ply``, ``depth.png``, ``depth2.npy`` where the estimator looks for a second
        surface and, where the scene has a ground truth, ``truth.npy`` and ``valid.npy`` into
        ``out_dir``, all or nothing (see :mod:`spslidar.outdir`).
        ``fov_deg`` is the field of view of the point cloud (default 10 degrees).
        ``metrics.json`` is ``metrics`` with the point cloud's summary (``point_cloud``) and
        the time of the writing (``timing_s['write']``) added; the result is not changed.

        ``out_dir`` must not exist, be empty, or (with ``overwrite=True``) hold a previous
        spslidar result; anything else is refused before a file is written, so a user's
        files are never touched. ``option`` and ``replace`` are what a refusal calls the
        folder and the way to replace it (the command line passes ``--out`` and
        ``--overwrite``).
        """

        from ..products import DEFAULT_FOV_DEG, check_fov

        if isinstance(out_dir, bytes) or not isinstance(out_dir, (str, os.PathLike)):
            from ..errors import ConfigError  # (an int raised os.fspath's TypeError)

            raise ConfigError(f"{option} must be a folder path (a str or os.PathLike), got "
                              f"{type(out_dir).__name__}")
        fov = DEFAULT_FOV_DEG if fov_deg is None else check_fov(fov_deg)  # before any file

        def fill(tmp: Path) -> None:
            t0 = time.perf_counter()
            from ..products import write_ply

            np.save(tmp / "depth.npy", self.depth)
            if self.has_truth:  # NaN where the scene has no truth (what --truth reads so)
                valid = np.asarray(self.scene.valid, dtype=bool)
                np.save(tmp / "truth.npy", np.where(valid, self.truth, np.nan))
                np.save(tmp / "valid.npy", valid)
            if self.reflectivity is not None:
                np.save(tmp / "reflectivity.npy", self.reflectivity)
            if self.confidence is not None:
                np.save(tmp / "confidence.npy", self.confidence)
            if self.depth2 is not None:  # the estimator looked for a second surface
                np.save(tmp / "depth2.npy", self.depth2)
            points, intensity, fields = self.cloud(fov)
            rows, cols = np.shape(self.depth)
            # what the file is, in its header (it said only the frame: an outside audit of
            # 2026-12-01 could not tell the field of view, the image or the intensity's
            # meaning from it)
            what = ("detected photons per pulse (a measured acquisition)" if "ptu" in
                    self.metrics else "an estimate of the reflectivity (a simulation)"
                    if self.has_truth else "reflectivity.npy")
            comments = [f"field of view {fov:g} deg across the larger side of a {rows} x "
                        f"{cols} image (rows x cols; row 0 at the top, square pixels)",
                        "depth is the range along each pixel's ray (metres)",
                        f"intensity: {what}; NaN where unknown, and for return 2",
                        "return_number 1: depth.npy, 2: depth2.npy (nearer or farther)"]
            write_ply(tmp / "points.ply", points, intensity, comments=comments, **fields)
            second = int(np.sum(fields["return_number"] == 2))
            # what the folder adds to the metrics goes into the file, not into the result
            # (save() added both to the caller's result: an audit)
            metrics = dict(self.metrics)
            metrics["point_cloud"] = {"file": "points.ply", "fov_deg": fov,
                                      "n_points": int(points.shape[0]),
                                      "n_second_surface": second,
                                      "fields": ["x", "y", "z", "intensity", *fields]}
            if figure:
                from ..figures import depth_figure

                depth_figure(self, tmp / "depth.png")
            metrics["timing_s"] = {**self.timing, "write": time.perf_counter() - t0}
            with open(tmp / "metrics.json", "w", encoding="utf-8") as fh:
                json.dump(_jsonable(metrics), fh, indent=2, allow_nan=False)

        return write_result_dir(out_dir, fill, overwrite=overwrite, option=option,
                                replace=replace)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None  # JSON has no NaN or infinity: null (what a reader without truth sees too)
    if isinstance(obj, (set, frozenset)):  # (a plugin's info or report: see below)
        items = [_jsonable(v) for v in obj]
        try:
            return sorted(items)
        except TypeError:
            return sorted(items, key=repr)
    if obj is not None and not isinstance(obj, (str, int, float, bool)):
        # what JSON cannot hold, from a plugin stage's info or report (a set, an object),
        # is written as its text: it ended the run, its whole computation done, in json's
        # "not JSON serializable" traceback with nothing written (an outside audit of
        # 2026-12-01)
        return str(obj)
    return obj
