"""TVAL3's penalty and continuation parameters: iterations to a given objective.

For each lidar problem (the default run's, built exactly as ``spslidar.pipeline.reconstruct``
builds it, on the camera and motorcycle scenes) this script takes as the optimum the lowest
objective ``F = 1/2 ||A x - y||^2 + lam TV(x)`` reached by 400 FISTA iterations or by any
TVAL3 run, then prints, for TVAL3 with several settings of ``beta_scale`` (final splitting
penalty ``beta = beta_scale * mu * ||A||^2``) and of the continuation start factors
``mu0_factor = beta0_factor``, the iterations each needs to come within 2 %, 1 % and 0.1 % of
it, and ``F`` after 60 and 100 iterations (the pipeline's default cap is 100).

It is the measurement behind TVAL3's defaults (``beta_scale = 1/4``, factors 1/4). Run:

    python benchmarks/tval3_parameters.py [--quick]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import _cli
import numpy as np

import spslidar
from spslidar.solvers import StopRule
from spslidar.solvers.fista import FISTA
from spslidar.solvers.tval3 import TVAL3

sys.path.insert(0, str(Path(__file__).parent))
from solvers import build_problem  # noqa: E402  (the benchmarks' shared problem builder)


def _opts(beta_scale: float, factor: float) -> dict:
    return {"beta_scale": beta_scale, "mu0_factor": factor, "beta0_factor": factor}


SETTINGS = [
    ("beta 1, factors 1/16 (old)", _opts(1.0, 1 / 16)),
    ("beta 1/2, factors 1/16", _opts(0.5, 1 / 16)),
    ("beta 1/4, factors 1/16", _opts(0.25, 1 / 16)),
    ("beta 1/8, factors 1/4", _opts(0.125, 0.25)),
    ("beta 1/4, factors 1/4 (default)", {}),
    ("beta 1/4, factors 1/2", _opts(0.25, 0.5)),
    ("beta 1/4, no continuation", _opts(0.25, 1.0)),
]


def first_within(h: np.ndarray, f_opt: float, rel: float) -> str:
    hit = np.nonzero(h <= f_opt * (1 + rel))[0]
    return str(hit[0] + 1) if hit.size else "-"


def main(argv=None) -> int:
    ap = _cli.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="32 x 32 images, one noise level")
    args = ap.parse_args(argv)
    size = 32 if args.quick else 64
    cases = [("camera", 10.0)] if args.quick else [
        ("camera", 10.0), ("camera", 2.0), ("motorcycle", 5.0), ("motorcycle", 10.0)]
    n_iter = 200
    for scene, noise in cases:
        meas = spslidar.measure(scene=scene, noise=noise, size=size)
        prob = build_problem(meas, "tval3")
        _, ref = FISTA(stop=StopRule(max_iter=400, rtol=0)).solve(
            prob.A, prob.y, prob.fresh_reg(), prob.lam)
        runs = []
        for name, opts in SETTINGS:
            t0 = time.perf_counter()
            _, info = TVAL3(stop=StopRule(max_iter=n_iter, rtol=0), **opts).solve(
                prob.A, prob.y, prob.fresh_reg(), prob.lam)
            runs.append((name, np.asarray(info.objective), time.perf_counter() - t0))
        f_opt = min(min(ref.objective), *(h.min() for _, h, _ in runs))
        fh = np.asarray(ref.objective)
        print(f"\n{scene} {size}x{size}, m_n = {noise:g}, K = {prob.y.shape[1]} slices, "
              f"optimum F = {f_opt:.6g}")
        print(f"  {'setting':34s} {'to 2%':>6s} {'to 1%':>6s} {'to 0.1%':>7s} "
              f"{'F(60)':>9s} {'F(100)':>9s} {'ms/it':>6s}")
        print(f"  {'FISTA (reference)':34s} {first_within(fh, f_opt, 0.02):>6s} "
              f"{first_within(fh, f_opt, 0.01):>6s} {first_within(fh, f_opt, 1e-3):>7s} "
              f"{fh[59] / f_opt - 1:+9.4f} {fh[99] / f_opt - 1:+9.4f}")
        for name, h, t in runs:
            print(f"  {name:34s} {first_within(h, f_opt, 0.02):>6s} "
                  f"{first_within(h, f_opt, 0.01):>6s} {first_within(h, f_opt, 1e-3):>7s} "
                  f"{h[59] / f_opt - 1:+9.4f} {h[99] / f_opt - 1:+9.4f} "
                  f"{1e3 * t / len(h):6.1f}")
    print("\n(F(n): relative excess of the objective after n iterations; '-': not within "
          f"{n_iter} iterations)")
    return 0


if __name__ == "__main__":
    raise SystemExit(_cli.run(main))
