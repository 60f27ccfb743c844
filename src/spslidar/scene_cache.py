"""The built-in image scenes at the sizes runs use most, shipped precomputed.

``camera`` and ``motorcycle`` come from scikit-image's sample data, resized with
``skimage.transform.resize``; importing ``skimage.io`` and ``skimage.transform`` (with SciPy's
``ndimage``) costs about 0.5 s, a fifth of a default run. ``data/builtin_scenes.npz`` holds
what :mod:`spslidar.scenes` computes from them at :data:`CACHED_SIZES` (the camera's resized
grey levels before they are mapped onto the depth window; the motorcycle's depth,
reflectivity and validity in its native window, before an optional remap), so those sizes
load without scikit-image. ``tests/test_scenes.py`` checks the file against a fresh
computation; :func:`spslidar.scene_build.build` regenerates it
(``python -m spslidar.scene_build``). This module only reads the file, so the scenes can use
it without a circular import.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

__all__ = ["CACHED_SIZES", "CACHE_FILE", "FIELDS", "lookup"]

#: image sides shipped precomputed (the default run's and the quick reproduction's)
CACHED_SIZES: tuple[int, ...] = (32, 64)
#: the shipped file
CACHE_FILE = Path(__file__).with_name("data") / "builtin_scenes.npz"
#: the scenes it holds and their arrays
FIELDS: dict[str, tuple[str, ...]] = {
    "camera": ("grey",),
    "motorcycle": ("depth", "reflectivity", "valid", "source_shape"),
}


@lru_cache(maxsize=1)
def _archive() -> dict[str, np.ndarray]:
    if not CACHE_FILE.is_file():  # pragma: no cover - a broken installation
        return {}
    with np.load(CACHE_FILE, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def lookup(name: str, size: int) -> dict[str, np.ndarray] | None:
    """The shipped arrays of built-in ``name`` at ``size`` (copies), or None."""
    if name not in FIELDS or size not in CACHED_SIZES:
        return None
    arc = _archive()
    keys = [f"{name}_{size}_{f}" for f in FIELDS[name]]
    if not all(k in arc for k in keys):
        return None
    return {f: arc[k].copy() for f, k in zip(FIELDS[name], keys, strict=True)}
