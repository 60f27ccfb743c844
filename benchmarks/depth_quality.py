"""Depth quality of every depth estimator, on the built-in scenes or on a family of procedural
scenes, each estimator against the paper's argmax on the same measurement.

Each case (scene, m_n, pattern ratio) is simulated and reconstructed once (the pipeline's
defaults otherwise, the measurement's seed the scene's seed for ``procedural:SEED``); every
estimator then runs on the same reconstructed slices ``result.slices``, so the table compares
the depth stage alone (``--draw K`` measures the procedural scenes again under seed + 1000 K,
to see which losses are the noise draw's). ``--cache DIR`` keeps each case's slices
(``.npz``, inside DIR whatever the scene's path; a scene file's content is in the key), so a
second run with other estimators reconstructs nothing; slices cached by other spslidar code
are used, as the estimators' research wants, and said once (delete DIR to compute them
again).

Per case: RMSE (eq. 19), median absolute error, the share of valid pixels off by more than
5 cm, the low-confidence and missing shares, and the estimator's time. The summary gives, per
estimator and setting (m_n, pattern ratio), the median and the worst ratio of its RMSE to
argmax's on the same measurement, and the mean share of pixels off by more than 5 cm. Run:

    python benchmarks/depth_quality.py --procedural 100-149 --noise 5 10 --compression 0.25 0.5
        [--size 64] [--estimators argmax censor mrf evidence] [--cache DIR] [--jobs 2]
        [--lam-scale K] [--out table.md]
    python benchmarks/depth_quality.py --scenes camera motorcycle --noise 10 --compression 0.25
    python benchmarks/depth_quality.py --scenes room --noise 5 --compression 0.5 --seed 8-15
    python benchmarks/depth_quality.py --procedural 100-149 --draw 1 --estimators argmax mrf
    python benchmarks/depth_quality.py --plugin mine.py --estimators mine mrf --noise 5

(``--seed`` takes a list or ranges as ``--procedural`` does; with several, each case is named
``scene:s<seed>``.)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import _cli
import numpy as np

from spslidar.depth import ESTIMATORS, DepthContext
from spslidar.metrics import depth_errors

#: a pixel is "off" when its error exceeds this (metres)
OFF_M = 0.05
#: the first cached case found from other code (said once)
_OTHER_CODE: list = []


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


def case_data(scene: str, noise: float, ratio: float, size: int, seed: int,
              cache: Path | None, lam_scale: float | None = None) -> dict:
    """The reconstructed slices of one measurement with what the estimators and the scoring
    need (from ``cache`` when there); ``lam_scale``: the solve's weight factor (default the
    solver's)."""
    import hashlib

    import spslidar
    from spslidar.plugins import code_fingerprint

    weight = "" if lam_scale is None else f"_ls{lam_scale:g}"
    # (an absolute scene path was joined onto the folder and replaced it, writing beside the
    # scene; a scene file rewritten gave its old slices: an audit of 2026-11-29)
    label = Path(scene).name if Path(scene).suffix else scene
    label = "".join(ch if ch.isalnum() or ch in "-_." else "-" for ch in label)
    key = scene
    if Path(scene).is_file():
        key = f"{Path(scene).resolve()}:{hashlib.sha256(Path(scene).read_bytes()).hexdigest()}"
    key = hashlib.sha256(key.encode()).hexdigest()[:10]
    name = f"{label}_{key}_mn{noise:g}_c{ratio:g}_n{size}_s{seed}{weight}.npz"
    path = cache / name if cache is not None else None
    if path is not None and path.exists():
        with np.load(path) as f:
            data = {k: f[k] for k in f.files}
        if not _OTHER_CODE and str(data.get("code", "")) != code_fingerprint():
            _OTHER_CODE.append(path)
            # (a depth-only plugin loaded read as "other spslidar code", and deleting the
            # cache as advised wasted every reconstruction: an outside audit)
            print(f"depth_quality.py: note: {path.name} (and maybe more) holds slices from "
                  f"other spslidar code or with other plugins loaded, used as they are (the "
                  f"depth stage is what is compared); delete {cache} to compute them again "
                  f"where the solve or the simulation changed", file=sys.stderr)
        return data

    t0 = time.perf_counter()
    meas = spslidar.measure(scene=scene, size=size, noise=noise, compression=ratio, seed=seed,
                            depth="argmax")
    r = spslidar.reconstruct(meas, lam_scale=lam_scale)  # None: the solver's default
    data = {"slices": np.asarray(r.slices, dtype=np.float32), "lags": np.asarray(r.lags),
            "bin_width": np.float64(meas.acq.bin_width),
            "pulse_width": np.float64(r.config.pulse_width),
            "truth": r.scene.depth, "valid": r.scene.valid,
            "chain_s": np.float64(time.perf_counter() - t0), "code": np.str_(code_fingerprint())}
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, **data)
        tmp.replace(path)
    return data


def run_case(scene: str, noise: float, ratio: float, size: int, seed: int,
             estimators: list[str], cache: Path | None, label: str | None = None,
             lam_scale: float | None = None) -> list[dict]:
    """One measurement and reconstruction; every estimator on its slices (``label``: how the
    tables name the case, default the scene)."""
    d = case_data(scene, noise, ratio, size, seed, cache, lam_scale)
    truth, valid = d["truth"], d["valid"]
    ctx = DepthContext(d["lags"], float(d["bin_width"]), float(d["pulse_width"]), truth.shape,
                       False)
    rows = []
    for name in estimators:
        est = ESTIMATORS.load(name)()
        t1 = time.perf_counter()
        out = est.estimate(d["slices"], ctx)
        t_est = time.perf_counter() - t1
        two = getattr(out, "depth2", None)
        rows.append({
            "scene": label or scene, "noise": noise, "ratio": ratio, "estimator": name,
            **score(out.depth.reshape(truth.shape), truth, valid),
            "low": float(np.mean(out.low_confidence)), "time": t_est,
            "two": float(np.mean(np.isfinite(two))) if two is not None else 0.0,
            "chain": float(d["chain_s"]),
        })
    return rows


def markdown(rows: list[dict]) -> str:
    """The results as a Markdown table (one row per case and estimator)."""
    head = ["scene", "m_n", "patterns", "estimator", "RMSE [m]", "median abs [m]",
            f"> {100 * OFF_M:g} cm", "low-conf", "missing", "time [s]"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["scene"], f"{r['noise']:g}", f"{100 * r['ratio']:g} %", r["estimator"],
                 f"{r['rmse']:.4f}", f"{r['median']:.4f}", f"{100 * r['off']:.1f} %",
                 f"{100 * r['low']:.1f} %", f"{100 * r['missing']:.1f} %", f"{r['time']:.3f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def ratios(rows: list[dict]) -> str:
    """Per estimator and setting: median and worst RMSE / argmax RMSE on the same measurement
    (and which scene is the worst), mean share off by more than 5 cm, mean RMSE."""
    ref = {(r["scene"], r["noise"], r["ratio"]): r["rmse"] for r in rows
           if r["estimator"] == "argmax"}
    if not ref:
        return ""
    names = list(dict.fromkeys(r["estimator"] for r in rows))
    settings = sorted({(r["noise"], r["ratio"]) for r in rows})
    head = ["m_n", "patterns", "estimator", "scenes", "median ratio", "worst ratio (scene)",
            "share of scenes > 1.05", f"off > {100 * OFF_M:g} cm", "mean RMSE [m]"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for noise, ratio in settings:
        for name in names:
            group = [r for r in rows if r["estimator"] == name and r["noise"] == noise
                     and r["ratio"] == ratio]
            rr = np.array([r["rmse"] / ref[(r["scene"], noise, ratio)] for r in group])
            worst = int(np.argmax(rr))
            lines.append("| " + " | ".join([
                f"{noise:g}", f"{100 * ratio:g} %", name, str(len(group)),
                f"{np.median(rr):.3f}", f"{rr[worst]:.3f} ({group[worst]['scene']})",
                f"{np.mean(rr > 1.05):.0%}",
                f"{100 * np.mean([r['off'] for r in group]):.1f} %",
                f"{np.mean([r['rmse'] for r in group]):.4f}"]) + " |")
    return "\n".join(lines)


def check_cases(cases: list[tuple[str, int]], noises: list[float], ratios_: list[float],
                size: int, estimators: list[str]) -> None:
    """Refuse, before the first reconstruction, an unknown estimator, a scene that cannot be
    loaded at ``size`` and a setting spslidar's ``Config`` refuses (raises ``ValueError``;
    ``--estimators foo`` was found only after a reconstruction, ``--scenes nosuch`` after the
    cases before it)."""
    bad = [name for name in estimators if name not in ESTIMATORS.names()]
    if bad:
        raise ValueError(f"--estimators: unknown estimator {bad[0]!r}; choose from "
                         f"{', '.join(ESTIMATORS.names())}")
    _cli.check_runs((s for s, _ in cases if not s.startswith("procedural:")), size,
                    ({"noise": n, "compression": r, "seed": seed}
                     for n in noises for r in ratios_ for _, seed in cases))


def _load_plugins(argv: list[str]) -> None:
    """Import the ``--plugin`` modules first, so their estimators are choices (and the
    workers of ``--jobs`` import them too): a user's estimator had no way in but the
    ``SPSLIDAR_PLUGINS`` variable, which nothing here said (an outside audit)."""
    pre = _cli.ArgumentParser(add_help=False)
    pre.add_argument("--plugin", action="append", default=[])
    specs = pre.parse_known_args(argv)[0].plugin
    if specs:
        from spslidar.plugins import load_plugins

        try:
            load_plugins(specs, export=True)
        except ValueError as exc:
            pre.prog = "depth_quality.py"
            pre.error(str(exc))


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    _load_plugins(argv)
    ap = _cli.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--plugin", action="append", default=[], metavar="MODULE",
                    help="import MODULE (a module name or a .py file) first: its depth "
                         "estimators are choices of --estimators, beside the built-ins "
                         "(repeatable; also SPSLIDAR_PLUGINS, commas)")
    ap.add_argument("--size", type=_cli.positive_int, default=64,
                    help="image side N (default 64)")
    ap.add_argument("--scenes", nargs="+", default=None,
                    help="built-in scenes or files (default: camera, unless --procedural)")
    ap.add_argument("--procedural", type=_cli.int_list, default=None,
                    help="procedural seeds, e.g. 100-149 or 0-19,40 (the measurement's seed too; "
                         "default: none)")
    ap.add_argument("--noise", type=_cli.nonneg_float, nargs="+", default=[5.0, 10.0],
                    help="background levels m_n (default: 5 10)")
    ap.add_argument("--compression", type=_cli.fraction, nargs="+", default=[0.25, 0.5],
                    help="pattern ratios M / Q in (0, 1] (default: 0.25 0.5)")
    ap.add_argument("--estimators", nargs="+", default=list(ESTIMATORS.names()),
                    help=f"depth estimators (default: all, {' '.join(ESTIMATORS.names())}); "
                         "argmax is always added")
    ap.add_argument("--seed", type=_cli.int_list, default=None,
                    help="measurement seed(s) of --scenes, e.g. 0 or 8-15 (as --procedural; "
                         "default 0)")
    ap.add_argument("--draw", type=_cli.nonneg_int, default=0,
                    help="another noise draw of --procedural: measurement seed = scene seed + "
                         "1000 * DRAW (new code, patterns and photons; 0, the default: the "
                         "scene's seed)")
    ap.add_argument("--cache", type=_cli.out_dir, default=None, metavar="DIR",
                    help="keep the slices here (default: none)")
    ap.add_argument("--lam-scale", type=_cli.positive_float, default=None, metavar="K",
                    help="the solve's weight factor (default the solver's); every estimator, "
                         "argmax included, reads the slices of that weight")
    ap.add_argument("--out", type=_cli.out_file, default=None, metavar="FILE",
                    help="also write the Markdown to this file (default: print only)")
    ap.add_argument("--per-case", action="store_true", help="also print the per-case table")
    ap.add_argument("--jobs", type=_cli.positive_int, default=1,
                    help="reconstruct the measurements missing from --cache in this many "
                         "processes first (each about 150 MB at 64x64; 2 on a 2-core machine; "
                         "default 1)")
    args = ap.parse_args(argv)
    # (each was ignored without a word, an audit of 2026-11-29)
    if args.draw and not args.procedural:
        ap.error("--draw draws --procedural scenes again: give --procedural")
    if args.seed is not None and args.procedural and not args.scenes:
        ap.error("--seed is the measurement seed of --scenes; a --procedural scene's is its "
                 "own seed (--draw K measures it again under seed + 1000 K)")
    if args.cache is not None:
        args.cache = Path(args.cache)
    seeds = args.seed if args.seed is not None else [0]
    cases = [(s, seed) for s in (args.scenes or []) for seed in seeds]
    if not cases and not args.procedural:
        cases = [("camera", seed) for seed in seeds]
    # several seeds of one built-in scene: the tables name each case scene:s<seed>
    label = {c: f"{c[0]}:s{c[1]}" for c in cases} if len(seeds) > 1 else {}
    if args.procedural:
        cases += [(f"procedural:{s}", s + 1000 * args.draw) for s in args.procedural]
    if "argmax" not in args.estimators:
        args.estimators.insert(0, "argmax")
    check_cases(cases, args.noise, args.compression, args.size, args.estimators)
    if args.jobs > 1:
        if args.cache is None:
            ap.error("--jobs needs --cache (the workers hand the slices over through it)")
        from joblib import Parallel, delayed

        todo = [(scene, noise, ratio, seed) for scene, seed in cases for noise in args.noise
                for ratio in args.compression]
        Parallel(n_jobs=args.jobs)(delayed(case_data)(scene, noise, ratio, args.size, seed,
                                                      args.cache, args.lam_scale)
                                   for scene, noise, ratio, seed in todo)
    rows: list[dict] = []
    t0 = time.perf_counter()
    for scene, seed in cases:
        for noise in args.noise:
            for ratio in args.compression:
                case = run_case(scene, noise, ratio, args.size, seed, args.estimators,
                                args.cache, label.get((scene, seed)), args.lam_scale)
                rows.extend(case)
                print(f"{label.get((scene, seed), scene)} m_n={noise:g} {100 * ratio:g}%: "
                      + ", ".join(f"{r['estimator']} {r['rmse']:.4f}" for r in case)
                      + f" (chain {case[0]['chain']:.1f} s; {time.perf_counter() - t0:.0f} s)",
                      file=sys.stderr, flush=True)
    text = (f"{args.size}x{args.size}, {len(cases)} scenes\n\n"
            + "RMSE / argmax RMSE on the same measurement:\n\n" + ratios(rows) + "\n")
    if args.per_case:
        text += "\n" + markdown(rows) + "\n"
    print(text)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(_cli.run(main))
