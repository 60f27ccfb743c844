"""Where the depth error of a scene sits, and how low any per-pixel choice could take it.

A diagnostic of issue 11's remaining target (the motorcycle at m_n = 10), reading the truth
on purpose: nothing here is an estimator. For each (scene, m_n, seed) it simulates and
reconstructs once with the pipeline's defaults and reports:

* ``rmse``: the default (``mrf``) depth RMSE (eq. 19), and ``rmse_surface``: the same sum of
  squared errors over the same pixels, leaving out the *isolated-truth* pixels (below);
* ``isolated``: the share of valid pixels whose true depth differs by more than 5 cm from
  every valid 4-neighbour's, and ``isolated_sq``: their share of the squared error;
* ``consensus``: the RMSE of the truth itself with each isolated pixel replaced by the median
  of its neighbours' truths: the error of a perfect estimator that follows the neighbours
  wherever the truth is isolated;
* ``oracle_mrf_argmax``: each pixel takes the better (by the truth) of the ``mrf`` depth and
  the argmax of its evidence profile;
* ``oracle_top5``: each pixel takes the best (by the truth) of the five highest maxima of its
  evidence profile;
* ``oracle_data``: as ``oracle_mrf_argmax`` with the argmax of the data's own profile, the
  back-projection of the residual ``p + A^T (y - A p) / ||a_q||^2`` of the reconstruction
  restricted to each pixel's chosen slice +- 1 (a leave-one-pixel-out estimate that no
  spatial prior has touched).

The oracles bound every estimator that picks each pixel's depth among those candidates. For
the motorcycle it also reports ``mixture``: the share of valid pixels whose true depth lies
more than 5 cm from every full-resolution depth in the pixel's footprint (a depth the
anti-aliased resize made by mixing a near and a far surface, which the simulation then
renders as one return). Run:

    python benchmarks/depth_bounds.py [--scenes motorcycle] [--noise 5 10] [--seeds 0 1 2]
"""

from __future__ import annotations

import sys
import warnings

import _cli
import numpy as np

import spslidar
from spslidar.depth.mrf import MRFDepth
from spslidar.depth.profile import index_to_depth, shift2d
from spslidar.qcr import qcr_problem

#: a pixel is off, or a neighbour different, beyond this (metres)
OFF_M = 0.05


def isolated_truth(truth: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Valid pixels whose truth differs by more than ``OFF_M`` from every valid 4-neighbour,
    and the median of each pixel's valid neighbours' truths."""
    masked = np.where(valid, truth, np.nan)
    nbs = np.stack([shift2d(masked, dy, dx) for dy, dx in ((1, 0), (-1, 0), (0, 1), (0, -1))])
    have = np.isfinite(nbs)
    far = have & (np.abs(np.nan_to_num(nbs) - truth[None]) > OFF_M)
    iso = valid & have.any(axis=0) & (far.sum(axis=0) == have.sum(axis=0))
    with warnings.catch_warnings():  # all-NaN neighbourhoods (isolated invalid pixels)
        warnings.simplefilter("ignore", RuntimeWarning)
        med = np.nanmedian(nbs, axis=0)
    return iso, med


def mixture_share(size: int, truth: np.ndarray, valid: np.ndarray) -> float:
    """Share of valid pixels of the motorcycle whose truth is more than ``OFF_M`` from every
    source depth in the pixel's footprint (the box of source pixels it covers)."""
    from spslidar import scenes

    depth, _lum, src_valid = scenes.motorcycle_source()
    from spslidar.scenes.base import _center_crop, _fill_invalid

    src = _center_crop(_fill_invalid(depth, src_valid))
    start, stop = scenes.footprints(src.shape[0], size)
    mixed = np.zeros(truth.shape, dtype=bool)
    for i in range(size):
        for j in range(size):
            if valid[i, j]:
                box = src[start[i]:stop[i], start[j]:stop[j]]
                mixed[i, j] = np.min(np.abs(box - truth[i, j])) > OFF_M
    return float(mixed[valid].mean())


def column_norms(A) -> np.ndarray:
    """``||A e_q||^2`` for every pixel, in blocks of 512 columns (no Q x Q identity)."""
    q = A.shape[1]
    out = np.empty(q)
    for a in range(0, q, 512):
        e = np.zeros((q, min(512, q - a)), dtype=np.float32)
        e[np.arange(a, a + e.shape[1]), np.arange(e.shape[1])] = 1.0
        out[a:a + e.shape[1]] = np.sum(np.asarray(A.matvec(e), dtype=np.float64) ** 2, axis=0)
    return out


def bounds(scene: str, noise: float, seed: int, size: int) -> dict[str, float]:
    """One simulation and reconstruction; the numbers of the module docstring."""
    meas = spslidar.measure(scene=scene, size=size, noise=noise, seed=seed)
    r = spslidar.reconstruct(meas)
    cfg = r.config
    truth, valid = r.scene.depth, r.scene.valid
    x = np.asarray(r.slices, dtype=np.float32)
    q, k = x.shape
    dk = index_to_depth(np.arange(k), _ctx(r, meas))
    depth = r.depth
    lab = np.argmin(np.abs(np.nan_to_num(depth, nan=1e9).reshape(-1, 1) - dk[None, :]), axis=1)
    err = (depth - truth)[valid]
    n_valid = int(valid.sum())
    sq = float(np.nansum(err**2))
    iso, med = isolated_truth(truth, valid)
    out = {"rmse": r.metrics["depth_rmse_m"],
           "isolated": float(iso[valid].mean()),
           "isolated_sq": float(np.nansum(((depth - truth)[iso]) ** 2) / sq) if sq else 0.0,
           "rmse_surface": float(np.sqrt(np.nansum(((depth - truth)[valid & ~iso]) ** 2)
                                         / n_valid)),
           "consensus": float(np.sqrt(np.mean((np.where(iso, med, truth) - truth)[valid]
                                              ** 2)))}
    flat_truth = truth.ravel()
    e_mrf = dk[lab] - flat_truth

    def best_of(*errs):
        stack = np.abs(np.stack(errs))
        return float(np.sqrt(np.mean(np.min(stack, axis=0)[valid.ravel()] ** 2)))

    z = MRFDepth().evidence(x)
    out["oracle_mrf_argmax"] = best_of(e_mrf, dk[np.argmax(z, axis=1)] - flat_truth)
    top = np.argsort(-z, axis=1)[:, :5]
    out["oracle_top5"] = best_of(*(dk[top[:, i]] - flat_truth for i in range(5)))
    # the data's own profile around the reconstruction restricted to the chosen slices
    # the profile needs every slice solved and no aliased (repeated) lag
    if (r.metrics["n_slices_solved"] == r.metrics["n_slices"] == k
            and np.array_equal(meas.inverse, np.arange(k))):
        A, y = qcr_problem(meas.patterns, meas.sim["corr"], cfg.qcr_form, dtype=np.float32)
        support = np.zeros((q, k), dtype=bool)
        for d in (-1, 0, 1):
            support[np.arange(q), np.clip(lab + d, 0, k - 1)] = True
        xs = np.where(support, x, 0.0).astype(np.float32)
        resid = y - np.asarray(A.matvec(xs))
        prof = xs + np.asarray(A.rmatvec(resid)) / column_norms(A)[:, None].astype(np.float32)
        zd = MRFDepth().evidence(prof)
        out["oracle_data"] = best_of(e_mrf, dk[np.argmax(zd, axis=1)] - flat_truth)
    else:
        out["oracle_data"] = float("nan")
    if scene == "motorcycle":
        out["mixture"] = mixture_share(size, truth, valid)
    return out


def _ctx(r, meas):
    from spslidar.depth import DepthContext

    cfg = r.config
    return DepthContext(np.asarray(r.lags), meas.acq.bin_width, cfg.pulse_width,
                        (cfg.size, cfg.size), cfg.subbin)


COLUMNS = ["rmse", "rmse_surface", "isolated", "isolated_sq", "consensus",
           "oracle_mrf_argmax", "oracle_top5", "oracle_data", "mixture"]


def main(argv=None) -> int:
    ap = _cli.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=_cli.positive_int, default=64,
                    help="image side N (default 64)")
    ap.add_argument("--scenes", nargs="+", default=["motorcycle"],
                    help="built-in scenes or files (default: motorcycle)")
    ap.add_argument("--noise", type=_cli.nonneg_float, nargs="+", default=[5.0, 10.0],
                    help="background levels m_n (default: 5 10)")
    ap.add_argument("--seeds", type=_cli.nonneg_int, nargs="+", default=[0, 1, 2],
                    help="measurement seeds (default: 0 1 2)")
    args = ap.parse_args(argv)
    _cli.check_runs(args.scenes, args.size,
                    ({"noise": n, "seed": s} for n in args.noise for s in args.seeds))
    lines = ["| scene | m_n | seed | " + " | ".join(COLUMNS) + " |",
             "|" + "---|" * (3 + len(COLUMNS))]
    for scene in args.scenes:
        for noise in args.noise:
            for seed in args.seeds:
                b = bounds(scene, noise, seed, args.size)
                cells = [f"{100 * b[c]:.1f} %" if c in ("isolated", "isolated_sq", "mixture")
                         else f"{b[c]:.4f}" for c in COLUMNS if c in b]
                cells += ["-"] * (len(COLUMNS) - len(cells))
                lines.append(f"| {scene} | {noise:g} | {seed} | " + " | ".join(cells) + " |")
                print(lines[-1], file=sys.stderr, flush=True)
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(_cli.run(main))
