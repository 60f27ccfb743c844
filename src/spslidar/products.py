"""What a user looks at besides the depth map: a reflectivity (intensity) image and a point
cloud.

Both are read off a finished reconstruction and need no ground truth, so ``spslidar run`` and
``spslidar reconstruct`` (a measured acquisition) write them alike (``reflectivity.npy``,
``points.ply``).

* **Reflectivity.** The solution of eq. (18) holds, per pixel and gated delay, the return
  strength ``p_j(tau)``: the matched filter divides by the gain ``G n m_s`` (eq. 5-6, with
  ``m_s`` the photons per pulse of a reflectivity-1 pixel), so for a simulation ``p_j`` reads
  ``alpha_j`` of eq. (8) spread over the bins the pulse overlaps, and for a measured
  acquisition (no ``m_s`` known) detected photons per pulse. :func:`reflectivity_image` sums
  a pixel's profile over the estimated return's bins (the bin of the depth and one on each
  side, which hold a half-bin RZ pulse wherever it falls), negative values clipped. The
  pipeline's ``reflectivity.npy`` is that sum refitted with the depth held
  (:mod:`spslidar.refit`), because the solve's per-slice TV spreads a slanted surface's
  return into its neighbours and the sum then shows the depth's gradients (the camera's
  uniform 1 read 0.58-1.20 over 5-95 % of its pixels at 64x64, m_n = 10; refitted 0.93-1.07,
  seeds 0-1);
  the sum is kept where the refit's model does not hold (``metrics.json``'s
  ``reflectivity_method``). Either is a relative image, not a calibrated albedo.
* **Point cloud.** A pinhole camera whose full field of view ``fov_deg`` spans the ``N``
  pixels: pixel ``(r, c)`` looks along ``(u, v, 1)`` with
  ``u = (c + 0.5 - N / 2) * 2 tan(fov / 2) / N`` (``v`` likewise, rows downwards). The lidar
  measures the range along that ray, so the point is ``range * (u, v, 1) / |(u, v, 1)|``
  (x right, y down, z forward, metres; the convention of OpenCV and of most point-cloud
  tools). The paper gives no optics; the default 10 degrees puts a 64-pixel image of a scene
  at 20 m on a 3.5 m wide field, 5.5 cm per pixel.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .arrays import pair_shape, positive_number, real_array
from .errors import ConfigError

__all__ = ["DEFAULT_FOV_DEG", "pixel_rays", "point_cloud", "read_ply", "reflectivity_image",
           "write_ply"]

#: full field of view across the image (degrees) when none is given
DEFAULT_FOV_DEG = 10.0


def reflectivity_image(slices: np.ndarray, depth: np.ndarray, lags: np.ndarray,
                       bin_width: float, half_window: int = 1) -> np.ndarray:
    """Reflectivity (intensity) of each pixel from its reconstructed profile.

    Parameters
    ----------
    slices : ndarray, shape (Q, K)
        Reconstructed return strength per pixel and gated delay (eq. 18's solution).
    depth : ndarray, shape (N, N) or (Q,)
        Estimated depth in metres, NaN where no return was detected.
    lags : ndarray of int, shape (K,)
        Absolute delay (TDC bins) of each slice, increasing.
    bin_width : float
        TDC bin width in seconds.
    half_window : int
        Bins on each side of the depth's bin that are summed.

    Returns
    -------
    ndarray, shape of ``depth``
        ``sum_{|t - t_j| <= half_window} max(p_j(t), 0)``; NaN where ``depth`` is NaN or
        its window holds none of the slices (a depth outside the gate).
    """
    from .forward import depth_to_delay

    slices = real_array(slices, "slices", ndim=2).astype(np.float64)
    shape = np.shape(depth)
    d = real_array(depth, "depth").astype(np.float64).ravel()
    if slices.shape[0] != d.size:
        raise ValueError(f"slices have {slices.shape[0]} pixels, depth has {d.size}")
    # (lags shorter than the slices summed the wrong slices, longer ones an IndexError,
    # decreasing ones other numbers, all without a word: an audit of 2026-11-29)
    # (a calibrated acquisition's lags hold the system delay's part of a bin)
    lags = real_array(lags, "lags", ndim=1, finite=True)
    if lags.size != slices.shape[1]:
        raise ValueError(f"{lags.size} lags for slices of {slices.shape[1]} delays: one each")
    if lags.size > 1 and not np.allclose(np.diff(lags.astype(np.float64)), 1.0):
        raise ValueError("lags must be consecutive delay bins, increasing (as a gate's)")
    if isinstance(half_window, (bool, np.bool_)) or not float(half_window).is_integer() \
            or half_window < 0:
        raise ValueError(f"half_window must be a whole number of bins >= 0, got "
                         f"{half_window!r}")
    half_window = int(half_window)
    positive_number(bin_width, "bin_width", unit="seconds")
    out = np.full(d.size, np.nan)
    have = np.isfinite(d)
    if lags.size == 0 or not have.any():
        return out.reshape(shape)
    # index of the slice nearest to each depth's delay (lags are consecutive bins); a depth
    # whose window holds no slice has no reflectivity here (it read the edge slice's value,
    # an audit of 2026-12-01)
    centre = np.rint(depth_to_delay(d, bin_width) - lags[0])
    have &= (centre >= -half_window) & (centre <= lags.size - 1 + half_window)
    if not have.any():
        return out.reshape(shape)
    centre = centre[have]
    pos = np.clip(slices[have], 0.0, None)
    # each slice within the window of each depth, in at most min(2 half_window + 1, K)
    # passes (a loop over the window's offsets took 10**12 turns for half_window=10**12: an
    # outside audit of 2026-12-02), each pixel's slices added in increasing order either way
    total = np.zeros(centre.size)
    if 2 * half_window + 1 <= lags.size:  # the window's offsets (the default: 3)
        rows, c = np.arange(centre.size), centre.astype(np.int64)
        for off in range(-half_window, half_window + 1):
            idx = c + off
            ok = (idx >= 0) & (idx < lags.size)
            total[ok] += pos[rows[ok], idx[ok]]
    else:  # a window wider than the gate: slice by slice
        for j in range(lags.size):
            near = np.abs(j - centre) <= half_window
            total[near] += pos[near, j]
    out[have] = total
    return out.reshape(shape)


def check_fov(fov_deg: Any) -> float:
    """A field of view in degrees, in (0, 180), as a float; one line otherwise."""
    if isinstance(fov_deg, (str, bytes, bool)) or not isinstance(fov_deg,
                                                                 (int, float, np.number)):
        raise ConfigError(f"the field of view must be a number of degrees, got {fov_deg!r}")
    if not 0.0 < float(fov_deg) < 180.0:
        raise ConfigError(f"the field of view must lie in (0, 180) degrees, got {fov_deg}")
    return float(fov_deg)


def pixel_rays(shape: tuple[int, int], fov_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """The pinhole's ray of each pixel: pixel ``(r, c)`` looks along ``(u, v, 1)``, ``u`` to
    the right and ``v`` down (module docstring), the full field of view ``fov_deg`` across
    the larger side.

    Returns
    -------
    u, v : ndarray, shape ``shape``
    """
    check_fov(fov_deg)
    # (a negative side gave empty rays, 2.7 was read as 2: an audit and a review)
    rows, cols = pair_shape(shape, "shape (rows, cols)", 0)
    scale = 2.0 * np.tan(np.radians(float(fov_deg)) / 2.0) / max(rows, cols, 1)  # (0 x 0)
    v, u = np.meshgrid((np.arange(rows) + 0.5 - rows / 2.0) * scale,
                       (np.arange(cols) + 0.5 - cols / 2.0) * scale, indexing="ij")
    return u, v


def point_cloud(depth: np.ndarray, fov_deg: float = DEFAULT_FOV_DEG,
                intensity: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """3-D points of a depth (range) image seen through a pinhole of field of view ``fov_deg``.

    Parameters
    ----------
    depth : ndarray, shape (rows, cols)
        Range along each pixel's ray, metres; NaN pixels give no point.
    fov_deg : float
        Full field of view across the image's larger side, degrees, in (0, 180) (square
        pixels: the other side spans less).
    intensity : ndarray, shape (rows, cols), optional
        Per-pixel value carried with each point (NaN where unknown, as given: it was read as
        0, which a reader takes for dark; an outside audit of 2026-12-01).

    Returns
    -------
    points : ndarray, shape (P, 3)
        ``x`` right, ``y`` down, ``z`` forward, metres, in row-major pixel order (a
        negative range, which no reconstruction gives, is a point behind the pinhole).
    values : ndarray, shape (P,)
        The intensity of each point (zeros if none given).
    """
    d = real_array(depth, "depth").astype(np.float64)
    if d.ndim != 2:
        raise ValueError(f"depth must be a 2-D image, got shape {d.shape}")
    if np.isinf(d).any():  # (dropped as if no return, where rmse refuses them: an audit)
        raise ValueError("depth holds infinite values; NaN marks a pixel without a return")
    u, v = pixel_rays(d.shape, fov_deg)
    norm = np.sqrt(u * u + v * v + 1.0)
    have = np.isfinite(d)
    r = d[have] / norm[have]
    points = np.stack([r * u[have], r * v[have], r], axis=1)
    if intensity is None:
        values = np.zeros(points.shape[0])
    else:
        inten = real_array(intensity, "intensity").astype(np.float64)
        if inten.size != d.size or inten.ndim not in (1, 2) or (inten.ndim == 2
                                                               and inten.shape != d.shape):
            raise ValueError(f"intensity of shape {inten.shape} for a depth of shape "
                             f"{d.shape}: one value per pixel")
        values = inten.reshape(d.shape)[have]
    return points, values


_PLY_TYPES = {"double": "<f8", "float": "<f4", "uchar": "u1", "ushort": "<u2"}


def write_ply(path: str | os.PathLike, points: np.ndarray, values: np.ndarray,
              comments: Sequence[str] = (), **fields: np.ndarray) -> Path:
    """Write points, their intensity and any further per-point scalars as a binary
    little-endian PLY file.

    The vertex element has ``double x, y, z`` (float64: as float32 a point at 1 000 km sat
    3.1 cm, two bins, off its depth; an audit of 2026-11-30) and ``float intensity``
    (float32), then one property per keyword in the order given: ``float`` for a float
    array (NaN where unknown), ``uchar`` for an integer one within 0-255 and ``ushort`` for
    one within 0-65535 (a pixel's ``row`` and ``col`` at 512 x 512). ``comments`` are
    header lines after the frame's (``comment ...``: the field of view, the image's size,
    what the intensity is), ASCII without line breaks; a single string is one line.
    Readable by CloudCompare, MeshLab, Open3D, PDAL and ``plyfile`` (each extra property a
    scalar field). Written by hand: the format is a short header and a packed array, and no
    dependency the project has writes it.
    """
    pts = real_array(points, "points").astype(np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        # (reshape(-1, 3) wrote a (3, N) array as scrambled points: an audit of 2026-11-29)
        raise ValueError(f"points must be (P, 3), one x y z row per point, got shape "
                         f"{pts.shape}")
    vals = real_array(values, "values").astype(np.float64).ravel()
    n = pts.shape[0]
    if vals.size != n:
        raise ValueError(f"{n} points but {vals.size} intensity values")
    columns = {"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2], "intensity": vals}
    kinds = {"x": "double", "y": "double", "z": "double", "intensity": "float"}
    for name, arr in fields.items():
        a = real_array(arr, name).ravel()
        if not name.isidentifier() or name in columns:
            raise ValueError(f"bad PLY property name {name!r}")
        if a.size != n:
            raise ValueError(f"{n} points but {a.size} values of {name!r}")
        if np.issubdtype(a.dtype, np.integer) or a.dtype == bool:
            if a.size and (a.min() < 0 or a.max() > 65535):
                raise ValueError(f"{name!r} must lie in 0..65535 (a PLY uchar or ushort)")
            kinds[name] = "uchar" if not a.size or a.max() <= 255 else "ushort"
        else:
            kinds[name] = "float"
        columns[name] = a
    # one string is one comment (it was written one header line per character: an audit)
    lines = [comments] if isinstance(comments, str) else [str(c) for c in comments]
    for c in lines:
        if not c.isascii() or "\n" in c or "\r" in c:
            raise ValueError(f"a PLY comment is one line of ASCII, got {c!r}")
    rec = np.empty(n, dtype=[(k, _PLY_TYPES[t]) for k, t in kinds.items()])
    for k, col in columns.items():
        rec[k] = col
    header = ("ply\nformat binary_little_endian 1.0\ncomment spslidar point cloud: x right, "
              "y down, z forward (m)\n"
              + "".join(f"comment {c}\n" for c in lines)
              + f"element vertex {n}\n"
              + "".join(f"property {t} {k}\n" for k, t in kinds.items()) + "end_header\n")
    path = Path(path)
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(rec.tobytes())
    return path


def read_ply(path: str | os.PathLike, fields: bool = False):
    """Read back a file of :func:`write_ply`: ``(points (P, 3), intensity (P,))``, and with
    ``fields=True`` also a dict of its further properties (float64 or uint8 arrays).

    Raises
    ------
    ValueError
        Naming the file, where it is not such a file (any other file was ``bytes.index``'s
        bare "subsection not found": an outside audit of 2026-12-02).
    """
    data = Path(path).read_bytes()

    def refuse(why: str) -> ValueError:
        return ValueError(f"{path} is not a point cloud of spslidar's write_ply ({why})")

    if not data.startswith(b"ply\n"):
        raise refuse("it does not start with 'ply'")
    end = data.find(b"end_header\n")
    if end < 0:
        raise refuse("no end_header")
    end += len(b"end_header\n")
    try:
        header = data[:end].decode("ascii").splitlines()
        if "format binary_little_endian 1.0" not in header:
            raise ValueError("not binary little-endian")
        n = next(int(line.split()[2]) for line in header if line.startswith("element vertex"))
        props = [line.split()[1:3] for line in header if line.startswith("property ")]
        dtype = np.dtype([(name, _PLY_TYPES[t]) for t, name in props])
        if not {"x", "y", "z", "intensity"} <= set(dtype.names or ()):
            raise ValueError("no x, y, z and intensity")
        rec = np.frombuffer(data[end:], dtype=dtype, count=n)
    except (UnicodeDecodeError, StopIteration, IndexError, KeyError, ValueError) as exc:
        why = {UnicodeDecodeError: "its header is not text", StopIteration: "no vertices",
               KeyError: f"a property of type {exc}"}.get(type(exc), str(exc) or "its header")
        raise refuse(why) from None
    out = (np.stack([rec["x"], rec["y"], rec["z"]], axis=1).astype(np.float64),
           rec["intensity"].astype(np.float64))
    if not fields:
        return out
    extra = {name: (rec[name].astype(np.float64) if t == "float" else rec[name].copy())
             for t, name in props if name not in ("x", "y", "z", "intensity")}
    return (*out, extra)
