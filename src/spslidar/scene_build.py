"""Regenerating the shipped built-in scenes (``data/builtin_scenes.npz``) of
:mod:`spslidar.scene_cache` from scikit-image's sample data: ``python -m spslidar.scene_build``.

Kept apart from :mod:`spslidar.scene_cache`, which only reads the file and is imported by
:mod:`spslidar.scenes`; computing the arrays needs the scenes themselves.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .scene_cache import CACHE_FILE, CACHED_SIZES, FIELDS, _archive
from .scenes.base import _center_crop, _resize
from .scenes.builtin import _motorcycle_computed

__all__ = ["build", "compute"]


def compute(name: str, size: int) -> dict[str, np.ndarray]:
    """The arrays of ``name`` at ``size``, computed from scikit-image's sample data."""
    from skimage import data

    if name == "camera":
        return {"grey": _resize(_center_crop(data.camera()), size)}
    if name == "motorcycle":
        scene = _motorcycle_computed(size)
        return {"depth": scene.depth, "reflectivity": scene.reflectivity,
                "valid": scene.valid,
                "source_shape": np.asarray(data.stereo_motorcycle()[2].shape, dtype=np.int64)}
    raise ValueError(f"no cached arrays for scene {name!r}")


def build(path: str | Path = CACHE_FILE) -> Path:
    """Write the cache file: every scene of :data:`~spslidar.scene_cache.FIELDS` at every
    :data:`~spslidar.scene_cache.CACHED_SIZES`."""
    arrays = {}
    for name in FIELDS:
        for size in CACHED_SIZES:
            for field, arr in compute(name, size).items():
                arrays[f"{name}_{size}_{field}"] = arr
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **arrays)
    _archive.cache_clear()
    return path


if __name__ == "__main__":  # pragma: no cover
    print(build())
