"""A calibrated instrument against an ideal one, on acquisitions nobody in spslidar wrote.

Issue 20's stand-in for a real instrument: a 32x32 scene at 29.8-30.6 m (a back wall, a
slanted panel, a box and, with ``--scenes pole``, a one-pixel pole of reflectivity 0.3 in front
of the wall), its photons drawn and written as PicoHarp T3 records by the independent writer of
``tests/test_independent_ptu.py`` (PicoQuant's published record layout; its own forward model
and, for the instrument, a system delay of 13.74 ns and a jitter of 1.5 bins FWHM with 30 %
of it in a 4-bin exponential tail, drawn from SciPy's ``norm`` and ``exponnorm``, not from
spslidar). Each seed gives a fresh code, patterns and photons (about 12.9 M of them).

Per scene variant and seed, three reconstructions, none given the truth:

* ``ideal``: the same scene through an instrument without delay or jitter;
* ``calibrated``: the instrument, calibrated on a flat wall at 25 m (its own acquisition,
  seed 1) with ``spslidar calibrate``, reconstructed with ``--calibration``;
* ``by hand``: the instrument, uncalibrated, the range gate moved by the delay's metres and
  the offset subtracted from the depths afterwards (what a user without a calibration step
  would do).

Scored afterwards against the scene: bias (mean signed error), the bias of the pixels within
5 cm (what the calibration's delay leaves, without the outliers that a weak return costs: a
panel pixel given the wall 0.2-0.4 m behind moves the mean, never the inliers), median
absolute error, RMSE and coverage (share of pixels with a depth). Run::

    python benchmarks/instrument.py [--scenes pole no-pole] [--seeds 0 1 2 3 4 5]
        [--wall range|plane] [--lam-scale 0.5] [--out table.md] [--keep DIR]

Each reconstruction is a separate in-process ``spslidar`` call on files in a temporary
folder (about 60 MB of PTU per acquisition; 1.2 GB peak, measured, most of it writing the
acquisitions); ``--keep DIR`` writes the acquisitions into ``DIR`` once and reads them from
there on later runs (measured, one seed: 11.0 s and 1.24 GB the first time, 3.7 s and
0.18 GB after, the same scores).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import _cli
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

import test_independent_ptu as indep  # noqa: E402  (the independent writer and instrument)

from spslidar.cli import main  # noqa: E402

GATE = (29.5, 30.9)
WALL_M = 25.0


def scene(variant: str) -> tuple[np.ndarray, np.ndarray]:
    """The test's scene, with (``pole``) or without (``no-pole``) its one-pixel pole."""
    depth, refl = indep._scene()
    if variant == "no-pole":
        depth[:, 30], refl[:, 30] = 30.6, 0.8  # the wall behind it
    elif variant != "pole":
        raise ValueError(f"unknown scene variant {variant!r}")
    return depth, refl


def _instrument(ideal: bool) -> tuple[float, float, float]:
    """Set the independent instrument's delay, jitter and tail weight; return the old ones."""
    old = (indep.SYSTEM_DELAY_BINS, indep.SIGMA_BINS, indep.TAIL_WEIGHT)
    if ideal:  # no delay, a jitter far below a bin, no tail
        indep.SYSTEM_DELAY_BINS, indep.SIGMA_BINS, indep.TAIL_WEIGHT = 0.0, 1e-6, 0.0
    return old


def _files(folder: Path, name: str) -> list[str]:
    return ["--ptu", str(folder / f"{name}.ptu"), "--patterns",
            str(folder / f"{name}_patterns.npy"), "--code", str(folder / f"{name}_code.npy"),
            "--bit-rate", f"{indep.BIT_RATE:g}"]


def _score(est: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    err = est - truth
    have = np.isfinite(err)
    e = err[have]
    near = np.abs(e) <= 0.05
    return {"bias": float(e.mean()),
            "inlier_bias": float(e[near].mean()) if near.any() else float("nan"),
            "median": float(np.median(np.abs(e))),
            "rmse": float(np.sqrt(np.mean(e ** 2))), "coverage": float(have.mean())}


def _write_once(folder: Path, name: str, depth: np.ndarray, refl: np.ndarray, seed: int,
                ideal: bool = False) -> None:
    """Write one acquisition (``name.ptu`` and its patterns and code) into ``folder`` unless a
    complete one is there (a ``name.done`` marker is written last, so a cut write is redone)."""
    if (folder / f"{name}.done").exists():
        return
    old = _instrument(ideal)
    try:
        indep._acquire_instrument(folder, name, depth, refl, seed)
    finally:
        indep.SYSTEM_DELAY_BINS, indep.SIGMA_BINS, indep.TAIL_WEIGHT = old
    (folder / f"{name}.done").write_text("")


def wall(kind: str) -> np.ndarray:
    """The calibration wall's ranges: ``range``, 25 m on every pixel (the issue's wall, as
    the independent writer takes a depth map); ``plane``, a flat wall 25 m ahead through a
    10 degree field of view (written here with the pinhole of ``points.ply``: 25.000-25.168
    m), which ``calibrate`` must find and remove (``--target auto``)."""
    if kind == "range":
        return np.full((indep.N, indep.N), WALL_M)
    if kind != "plane":
        raise ValueError(f"unknown wall {kind!r}")
    u = (np.arange(indep.N) + 0.5 - indep.N / 2) * 2 * np.tan(np.radians(5.0)) / indep.N
    return WALL_M * np.sqrt(1 + u[:, None] ** 2 + u[None, :] ** 2)


def run_case(variant: str, seed: int, extra: list[str],
             keep: str | None = None, wall_kind: str = "range") -> dict[str, dict[str, float]]:
    """The three reconstructions of one scene variant and seed.

    With ``keep``, the acquisitions are written once into ``keep/<variant>-<seed>/`` (the
    wall's into ``keep/``) and read from there on every later run: writing them is most of a
    case's time (about 8 s a seed against 1.5 s a reconstruction), so trying a change of the
    processing on many seeds needs them written only once. About 105 MB a seed.
    """
    depth, refl = scene(variant)
    out: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory(prefix="spslidar_instrument_") as tmp:
        d = Path(tmp)
        acq = d if keep is None else Path(keep) / f"{variant}-{seed}"
        name = "wall" if wall_kind == "range" else f"wall_{wall_kind}"
        wall_dir = d if keep is None else Path(keep)
        acq.mkdir(parents=True, exist_ok=True)
        _write_once(acq, "ideal", depth, refl, seed, ideal=True)
        _write_once(acq, "scan", depth, refl, seed)
        _write_once(wall_dir, name, wall(wall_kind), np.full_like(refl, 0.8), 1)
        quiet = ["--no-figure"]
        assert _main(["reconstruct", *_files(acq, "ideal"), "--range-gate", *map(str, GATE),
                     "--out", str(d / "r_ideal"), *quiet, *extra]) == 0
        out["ideal"] = _score(np.load(d / "r_ideal" / "depth.npy"), depth)
        assert _main(["calibrate", *_files(wall_dir, name), "--distance", str(WALL_M),
                     "--out", str(d / "cal.json")]) == 0
        assert _main(["reconstruct", *_files(acq, "scan"), "--range-gate", *map(str, GATE),
                     "--calibration", str(d / "cal.json"), "--out", str(d / "r_cal"),
                     *quiet, *extra]) == 0
        out["calibrated"] = _score(np.load(d / "r_cal" / "depth.npy"), depth)
        off = indep.SYSTEM_DELAY_BINS / indep.BIT_RATE * indep.C / 2
        gate = [str(g + off) for g in GATE]
        assert _main(["reconstruct", *_files(acq, "scan"), "--range-gate", *gate, "--out",
                     str(d / "r_hand"), *quiet, *extra]) == 0
        out["by hand"] = _score(np.load(d / "r_hand" / "depth.npy") - off, depth)
    return out


def _main(argv: list[str]) -> int:
    """``spslidar``'s ``main`` with its stdout kept out of the benchmark's (its "wrote
    /tmp/spslidar_instrument_.../" named folders deleted when the case ends, an outside
    audit); its warnings stay on stderr."""
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):
        return main(argv)


def table(rows: list[tuple[str, int, dict]]) -> str:
    """Markdown: one line per scene variant, seed and instrument."""
    lines = ["| scene | seed | instrument | bias [cm] | bias within 5 cm [mm] | median [mm] | "
             "RMSE [m] | coverage |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for variant, seed, res in rows:
        for inst, s in res.items():
            lines.append(f"| {variant} | {seed} | {inst} | {100 * s['bias']:.2f} | "
                         f"{1000 * s['inlier_bias']:.2f} | {1000 * s['median']:.1f} | "
                         f"{s['rmse']:.3f} | {s['coverage']:.3f} |")
    return "\n".join(lines)


def summary(rows: list[tuple[str, int, dict]]) -> str:
    """Markdown: per variant and instrument, the worst |bias|, median and RMSE over the seeds,
    and how many seeds meet issue 20's targets (|bias| <= 1 cm, median <= 1.2 cm,
    RMSE <= 0.10 m)."""
    lines = ["| scene | instrument | seeds | worst abs bias [cm] | worst median [mm] | "
             "RMSE over seeds [m] | seeds meeting all three targets |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for variant in dict.fromkeys(r[0] for r in rows):
        group = [r[2] for r in rows if r[0] == variant]
        for inst in group[0]:
            s = [g[inst] for g in group]
            ok = sum(abs(x["bias"]) <= 0.01 and x["median"] <= 0.012 and x["rmse"] <= 0.10
                     for x in s)
            rm = [x["rmse"] for x in s]
            lines.append(f"| {variant} | {inst} | {len(s)} | "
                         f"{100 * max(abs(x['bias']) for x in s):.2f} | "
                         f"{1000 * max(x['median'] for x in s):.1f} | "
                         f"{min(rm):.3f}-{max(rm):.3f} | {ok} of {len(s)} |")
    return "\n".join(lines)


def main_(argv=None) -> int:
    ap = _cli.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["pole", "no-pole"],
                    choices=["pole", "no-pole"],
                    help="scene variants, with or without the one-pixel pole (default: both)")
    ap.add_argument("--seeds", nargs="+", type=_cli.nonneg_int, default=[0, 1, 2],
                    help="seeds of the acquisitions (default: 0 1 2)")
    ap.add_argument("--wall", choices=["range", "plane"], default="range",
                    help="the calibration wall: 25 m on every pixel (default), or a flat wall "
                         "through a 10 degree field of view")
    ap.add_argument("--lam-scale", type=_cli.positive_float, default=None,
                    help="passed to every reconstruction (default: the pipeline's)")
    ap.add_argument("--out", type=_cli.out_file, default=None, metavar="FILE",
                    help="also write the Markdown to this file (default: print only)")
    ap.add_argument("--keep", type=_cli.out_dir, default=None, metavar="DIR",
                    help="write the acquisitions into DIR once and reuse them on later runs "
                         "(about 105 MB a seed; default: a temporary folder per case)")
    args = ap.parse_args(argv)
    extra = [] if args.lam_scale is None else ["--lam-scale", f"{args.lam_scale:g}"]
    rows = []
    t0 = time.perf_counter()
    for variant in args.scenes:
        for seed in args.seeds:
            res = run_case(variant, seed, extra, args.keep, args.wall)
            rows.append((variant, seed, res))
            print(f"{variant} seed {seed}: " + ", ".join(
                f"{k} {v['rmse']:.3f} m" for k, v in res.items())
                + f" ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
    text = summary(rows) + "\n\n" + table(rows) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(_cli.run(main_))
