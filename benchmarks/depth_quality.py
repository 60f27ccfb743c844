"""Depth quality of every depth estimator on every built-in scene and noise level.

Each (scene, m_n) is simulated and reconstructed once (the pipeline's defaults otherwise); all
estimators then run on the same reconstructed slices ``r.slices``, so the table compares the
depth stage alone. Columns: RMSE (eq. 19) and median absolute error over the valid pixels
with a depth, the share of those off by more than 5 cm, the share of pixels the estimator
flags as low-confidence, the share without a depth (no return detected), and the
estimator's time. ``--lam-scales`` repeats the reconstruction at several weights (a
diagnostic of the regularisation weight, not of the depth stage). Run:

    python benchmarks/depth_quality.py [--size 64] [--noise 1 5 10] [--scenes ...]
        [--estimators argmax censor mrf] [--subbin] [--lam-scales 0.3 1.0] [--out table.md]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

import spslidar
from spslidar.depth import ESTIMATORS, DepthContext
from spslidar.metrics import depth_errors
from spslidar.scenes import BUILTIN_SCENES

#: a pixel is "off" when its error exceeds this (metres)
OFF_M = 0.05


def score(depth: np.ndarray, truth: np.ndarray, valid: np.ndarray) -> dict[str, float]:
    """RMSE, median absolute error, share off by more than ``OFF_M`` and missing share."""
    err = depth_errors(depth, truth, valid)
    have = valid & np.isfinite(depth)
    abs_err = np.abs(depth[have] - truth[have])
    return {
        "rmse": err["depth_rmse_m"],
        "median": float(np.median(abs_err)) if abs_err.size else float("nan"),
        "off": float(np.mean(abs_err > OFF_M)) if abs_err.size else float("nan"),
        "missing": err["missing_fraction"],
    }


def run_case(scene: str, noise: float, size: int, seed: int, estimators: list[str],
             subbin: bool, lam_scale: float | None) -> list[dict]:
    """One measurement and reconstruction; every estimator on its slices."""
    t0 = time.perf_counter()
    meas = spslidar.measure(scene=scene, size=size, noise=noise, seed=seed)
    r = spslidar.reconstruct(meas, **({} if lam_scale is None else {"lam_scale": lam_scale}))
    t_chain = time.perf_counter() - t0
    cfg = r.config
    ctx = DepthContext(np.asarray(r.lags), meas.acq.bin_width, cfg.pulse_width,
                       (cfg.size, cfg.size), subbin)
    truth, valid = r.scene.depth, r.scene.valid
    rows = []
    for name in estimators:
        est = ESTIMATORS.load(name)()
        t1 = time.perf_counter()
        out = est.estimate(r.slices, ctx)
        t_est = time.perf_counter() - t1
        depth = out.depth.reshape(truth.shape)
        rows.append({
            "scene": scene, "noise": noise, "estimator": name,
            "lam_scale": r.metrics["lam_scale"], **score(depth, truth, valid),
            "low": float(np.mean(out.low_confidence)), "time": t_est,
            "solve": r.timing["solve"], "chain": t_chain,
        })
    return rows


def markdown(rows: list[dict], lam_column: bool) -> str:
    """The results as a Markdown table (one row per scene, m_n, estimator)."""
    head = ["scene", "m_n"] + (["lam_scale"] if lam_column else []) + [
        "estimator", "RMSE [m]", "median abs [m]", f"> {100 * OFF_M:g} cm", "low-conf",
        "missing", "time [s]"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["scene"], f"{r['noise']:g}"] + ([f"{r['lam_scale']:g}"] if lam_column
                                                   else []) + [
            r["estimator"], f"{r['rmse']:.4f}", f"{r['median']:.4f}", f"{100 * r['off']:.1f} %",
            f"{100 * r['low']:.1f} %", f"{100 * r['missing']:.1f} %", f"{r['time']:.3f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def winners(rows: list[dict]) -> str:
    """Per (scene, m_n, lam_scale): the estimators with the lowest RMSE (ties within 0.1 mm
    listed together) and their gain over argmax."""
    out = []
    keys = sorted({(r["scene"], r["noise"], r["lam_scale"]) for r in rows},
                  key=lambda k: (BUILTIN_SCENES.index(k[0]) if k[0] in BUILTIN_SCENES else 99,
                                 k[1], k[2]))
    for key in keys:
        group = [r for r in rows if (r["scene"], r["noise"], r["lam_scale"]) == key]
        rmse = {r["estimator"]: r["rmse"] if np.isfinite(r["rmse"]) else np.inf for r in group}
        best = min(rmse.values())
        tied = " = ".join(n for n, v in rmse.items() if v <= best + 1e-4)
        gain = f" (argmax / best = {rmse['argmax'] / best:.1f})" if "argmax" in rmse \
            and 0 < best < np.inf else ""
        lam = f" lam_scale={key[2]:g}" if len({r["lam_scale"] for r in rows}) > 1 else ""
        out.append(f"- {key[0]} m_n={key[1]:g}{lam}: {tied} {best:.4f} m{gain}")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--scenes", nargs="+", default=list(BUILTIN_SCENES))
    ap.add_argument("--noise", type=float, nargs="+", default=[1.0, 5.0, 10.0])
    ap.add_argument("--estimators", nargs="+", default=list(ESTIMATORS.names()))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--subbin", action="store_true", help="ctx.subbin=True for every estimator")
    ap.add_argument("--lam-scales", type=float, nargs="+", default=None,
                    help="reconstruct at these lam_scale values (default: the solver's)")
    ap.add_argument("--out", default=None, help="also write the Markdown to this file")
    args = ap.parse_args(argv)
    scales = args.lam_scales or [None]
    rows: list[dict] = []
    for scene in args.scenes:
        for noise in args.noise:
            for lam_scale in scales:
                case = run_case(scene, noise, args.size, args.seed, args.estimators,
                                args.subbin, lam_scale)
                rows.extend(case)
                print(f"{scene} m_n={noise:g} lam_scale={case[0]['lam_scale']:g}: "
                      + ", ".join(f"{r['estimator']} {r['rmse']:.4f} m" for r in case)
                      + f" (chain {case[0]['chain']:.1f} s, solve {case[0]['solve']:.1f} s)",
                      file=sys.stderr, flush=True)
    text = (f"{args.size}x{args.size}, seed {args.seed}, subbin {args.subbin}\n\n"
            + markdown(rows, args.lam_scales is not None)
            + "\n\nLowest RMSE per case:\n\n" + winners(rows) + "\n")
    print(text)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
