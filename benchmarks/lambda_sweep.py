"""Depth RMSE against the regularisation weight, on the built-in scenes, default marked.

The default weight is ``lam = lam_scale * sigma_eff`` with ``sigma_eff`` the noise level
estimated from the measurements (see docs/model.md). This script simulates each scene once,
reconstructs it with a range of ``lam_scale`` values, and prints (and plots, with --plot) the
RMSE, so the default can be seen against the optimum. Run:

    python benchmarks/lambda_sweep.py [--size 64] [--solver fista] [--plot out.png]
"""

from __future__ import annotations

import time

import _cli
import numpy as np

import spslidar
from spslidar.pipeline import solver_default
from spslidar.solvers import SOLVERS


def main(argv=None):
    scales = list(np.round(np.logspace(-1.5, 1.0, 11), 4))
    ap = _cli.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=_cli.positive_int, default=64,
                    help="image side N (default 64)")
    ap.add_argument("--solver", default="fista", choices=SOLVERS.names(),
                    help="the solver (default fista)")
    ap.add_argument("--scenes", nargs="+", default=["camera", "motorcycle"],
                    help="built-in scenes or files (default: camera motorcycle)")
    ap.add_argument("--noise", type=_cli.nonneg_float, nargs="+", default=[10.0],
                    help="background levels m_n (default: 10)")
    ap.add_argument("--scales", type=_cli.positive_float, nargs="+", default=scales,
                    metavar="K", help="lam_scale values, the solver's default added (default: "
                    f"11 from {scales[0]:g} to {scales[-1]:g}, log-spaced)")
    ap.add_argument("--no-qcr", action="store_true",
                    help="solve without QCR (default: QCR on)")
    ap.add_argument("--plot", type=_cli.out_file, default=None, metavar="PNG",
                    help="write a PNG of RMSE vs lam_scale (default: none)")
    args = ap.parse_args(argv)
    _cli.check_runs(args.scenes, args.size, ({"noise": n, "qcr": not args.no_qcr,
                                              "solver": args.solver} for n in args.noise))
    default = solver_default(args.solver, "lam_scale")
    scales = sorted(set(args.scales) | {default})
    rows = []
    for scene in args.scenes:
        for noise in args.noise:
            t0 = time.perf_counter()
            meas = spslidar.measure(scene=scene, size=args.size, noise=noise,
                                    qcr=not args.no_qcr, solver=args.solver)
            t_sim = time.perf_counter() - t0
            print(f"\n{scene} {args.size}x{args.size} m_n={noise:g} {args.solver} "
                  f"(simulated in {t_sim:.2f} s)")
            print(f"{'lam_scale':>10} {'lam':>10} {'RMSE [m]':>10} {'missing':>8} {'time [s]':>9}")
            for s in scales:
                r = spslidar.reconstruct(meas, lam_scale=float(s))
                mark = "  <- default" if s == default else ""
                if r.metrics.get("lam_floored"):  # (its lam_scale was not what applied)
                    mark += "  (at the weight's floor)"
                print(f"{s:10.4g} {r.metrics['lam']:10.4g} {r.depth_rmse:10.5f} "
                      f"{r.metrics['missing_fraction']:8.3f} {r.timing['solve']:9.2f}{mark}")
                rows.append((scene, noise, s, r.depth_rmse))
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
        for scene in args.scenes:
            for noise in args.noise:
                pts = [(s, e) for sc, n, s, e in rows if sc == scene and n == noise]
                ax.loglog(*zip(*pts, strict=True), "o-", label=f"{scene}, m_n={noise:g}")
        ax.axvline(default, color="k", ls="--", label=f"default lam_scale={default:g}")
        ax.set_xlabel("lam_scale (weight / estimated noise level)")
        ax.set_ylabel("depth RMSE [m]")
        qcr = "off" if args.no_qcr else "on"
        ax.set_title(f"{args.solver}, {args.size}x{args.size}, QCR {qcr}")
        ax.legend(fontsize=8)
        fig.savefig(args.plot, dpi=110)
        print(f"wrote {args.plot}")


if __name__ == "__main__":
    raise SystemExit(_cli.run(main))
