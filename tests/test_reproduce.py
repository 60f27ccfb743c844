"""Tests of ``spslidar reproduce`` (spslidar.experiments.reproduce and .report)."""

from __future__ import annotations

import csv
import functools
import pickle
from pathlib import Path

import pytest

from spslidar.errors import ConfigError
from spslidar.experiments import reproduce
from spslidar.experiments.report import Claim, build_report, markdown_to_html, md_table
from spslidar.experiments.reproduce import EXPERIMENTS, reproduce_main
from spslidar.experiments.reproduce import context as reproduce_context


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _stamps(folder: Path) -> dict[str, int]:
    return {p.name: p.stat().st_mtime_ns for p in sorted(folder.iterdir())}


@pytest.fixture(scope="module")
def quick_dir(tmp_path_factory) -> Path:
    """fig3 then fig2, quick, into one report folder (fig3 first: the report must reorder)."""
    out = tmp_path_factory.mktemp("repro")
    assert reproduce_main("fig3", out, quick=True, progress=False) == 0
    assert reproduce_main("fig2", out, quick=True, progress=False) == 0
    return out


# -- argument checks ----------------------------------------------------------------------------


def test_experiment_names():
    assert EXPERIMENTS[:10] == (
        "fig2", "fig3", "fig4", "fig5", "fig6", "fig7", "fig8", "table1", "snr", "ambiguity"
    )  # fmt: skip
    assert EXPERIMENTS[-1] == "all"
    assert EXPERIMENTS[:-1] == reproduce.EXPERIMENT_REGISTRY.names()  # the CLI's choices


def test_registry_is_light_and_complete():
    """The registry (and the CLI's choices) import no numerics; every entry loads."""
    import subprocess
    import sys

    code = ("import sys; from spslidar.experiments.reproduce import EXPERIMENTS; "
            "from spslidar.experiments.names import EXPERIMENT_NAMES; "
            "print('numpy' in sys.modules, len(EXPERIMENTS))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.split() == ["False", str(len(EXPERIMENTS))]
    for entry in reproduce.EXPERIMENT_REGISTRY:
        assert callable(entry.load()), entry.name
        assert entry.display and entry.help, entry.name


def test_public_names_still_import():
    from spslidar.experiments.reproduce import (  # noqa: F401
        ALL,
        EXPERIMENT_NAMES,
        PAPER,
        Context,
        Stat,
        base_params,
        exp_ambiguity,
        exp_fig2,
        exp_table1,
        reproduce_point,
        snr_point,
    )

    with pytest.raises(AttributeError):
        reproduce.no_such_name  # noqa: B018


def _exp_toy(ctx):
    """A one-line-registered experiment: writes a CSV and a section, no runs."""
    folder = ctx.folder("toy")
    (folder / "toy.csv").write_text("a\n1\n")
    text = f"## Toy experiment\n\n{ctx.mode}\n\nData: `toy/toy.csv`.\n"
    return text, [Claim("toy", "a toy claim", "p", "o", "consistent")]


def test_new_experiment_is_one_registry_line(tmp_path, monkeypatch, capsys):
    reg = reproduce.EXPERIMENT_REGISTRY
    monkeypatch.setattr(reg, "_entries", dict(reg._entries))  # restored after the test
    reg.add("toy", f"{__name__}:_exp_toy", "Toy", "a toy experiment", in_all=False)
    assert reproduce_main("toy", tmp_path, quick=True, progress=False) == 0
    text = (tmp_path / "report.md").read_text()
    assert "## Toy experiment" in text and "| toy |" in text
    assert "toy" not in reproduce.in_all_names()  # in_all=False: not run by 'all'
    with pytest.raises(ConfigError, match="unknown experiment 'toy2'.*ambiguity, .*toy, all"):
        reproduce_main("toy2", tmp_path, quick=True)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"experiment": "fig9"},
        {"experiment": "fig2", "trials": 0},
        {"experiment": "fig2", "trials": 1.5},
        {"experiment": "fig2", "jobs": 0},
    ],
)
def test_bad_arguments_one_line(tmp_path, kwargs):
    with pytest.raises(ConfigError) as err:
        reproduce_main(out=tmp_path / "r", quick=True, progress=False, **kwargs)
    msg = str(err.value)
    assert "\n" not in msg and msg
    assert not (tmp_path / "r").exists()


def test_unknown_experiment_lists_choices(tmp_path):
    with pytest.raises(ConfigError, match="unknown experiment 'fig9'.*fig2.*ambiguity.*all"):
        reproduce_main("fig9", tmp_path, quick=True)


def test_out_is_a_file(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(ConfigError, match="folder"):
        reproduce_main("fig2", f, quick=True)


def test_run_function_pickles(tmp_path):
    func = functools.partial(reproduce.reproduce_point, maps_dir=str(tmp_path))
    assert pickle.loads(pickle.dumps(func)).keywords == {"maps_dir": str(tmp_path)}
    assert pickle.loads(pickle.dumps(reproduce.snr_point)) is reproduce.snr_point


def test_base_params_canonical():
    ctx = reproduce.Context(Path("."), quick=True)
    a = reproduce.base_params(ctx, noise=10, compression=0.25)
    b = reproduce.base_params(ctx, code_length=16383, qcr=True)
    assert a == b  # same configuration -> same cache key, whichever experiment asks
    assert isinstance(a["noise"], float) and a["size"] == 32


# -- experiments ----------------------------------------------------------------------------------


def test_fig3_outputs(quick_dir):
    d = quick_dir / "fig3"
    assert (d / "fig3.png").stat().st_size > 10_000
    rows = _rows(d / "fig3.csv")
    assert len(rows) == 4  # random 0.1, random 0.3, gold, mseq; one trial each
    for col in ("experiment", "scene", "size", "code", "code_length", "ones_ratio", "noise",
                "qcr", "solver", "trial", "seed", "depth_rmse_m", "missing_fraction",
                "time_total_s", "map_key"):  # fmt: skip
        assert col in rows[0], col
    assert {(r["code"], r["code_length"]) for r in rows} == {
        ("random", "2048"),
        ("gold", "2047"),
        ("mseq", "2047"),
    }
    assert {r["ones_ratio"] for r in rows if r["code"] == "random"} == {"0.1", "0.3"}
    assert all(r["noise"] == "1.0" and r["size"] == "32" for r in rows)
    for r in rows:
        assert 0 <= float(r["depth_rmse_m"]) < 1.0
        assert (quick_dir / "cache" / "maps" / f"{r['map_key']}.npy").is_file()


def test_fig2_outputs_and_paper_numbers(quick_dir):
    rows = _rows(quick_dir / "fig2" / "fig2.csv")
    assert sorted(float(r["compression"]) for r in rows) == [0.05, 0.25, 0.85]
    assert (quick_dir / "fig2" / "fig2.png").is_file()
    section = (quick_dir / "fig2" / "section.md").read_text()
    assert "## Fig. 2" in section
    assert "8-78 s" in section  # the paper's reconstruction times, next to ours
    assert "consistent" in section


def test_report_sections_in_order(quick_dir):
    text = (quick_dir / "report.md").read_text()
    assert text.count("## Fig. 2:") == 1 and text.count("## Fig. 3:") == 1
    assert text.index("## Fig. 2:") < text.index("## Fig. 3:")  # report order, not run order
    assert "R_a = 0.3 better than 0.1" in text
    assert "## Summary" in text and "| fig3 |" in text
    html = (quick_dir / "report.html").read_text()
    assert '<img src="fig3/fig3.png"' in html and '<img src="fig2/fig2.png"' in html
    assert "<table>" in html and "<h2>" in html


def test_rerun_replaces_section_and_reuses_cache(quick_dir, capsys):
    runs = quick_dir / "cache" / "runs"
    maps = quick_dir / "cache" / "maps"
    before_runs, before_maps = _stamps(runs), _stamps(maps)
    capsys.readouterr()
    assert reproduce_main("fig3", quick_dir, quick=True, progress=False) == 0
    assert "(0 new runs)" in capsys.readouterr().out
    assert _stamps(runs) == before_runs  # nothing recomputed or rewritten
    assert _stamps(maps) == before_maps
    text = (quick_dir / "report.md").read_text()
    assert text.count("## Fig. 3:") == 1 and text.count("## Fig. 2:") == 1
    assert len(_rows(quick_dir / "fig3" / "fig3.csv")) == 4


def test_missing_map_is_recomputed(quick_dir):
    rows = _rows(quick_dir / "fig3" / "fig3.csv")
    maps = quick_dir / "cache" / "maps"
    victim = maps / f"{rows[0]['map_key']}.npy"
    others = {k: v for k, v in _stamps(maps).items() if k != victim.name}
    victim.unlink()
    assert reproduce_main("fig3", quick_dir, quick=True, progress=False) == 0
    assert victim.is_file()
    after = _stamps(maps)
    assert {k: after[k] for k in others} == others  # only the lost one was run again


# -- report helpers -------------------------------------------------------------------------------


def test_markdown_to_html_subset():
    md = (
        "## Title\n\nSome `code` and **bold** a < b.\n\n- one\n- two\n\n"
        + md_table(("a", "b|c"), [(1, "x|y")])
        + "\n![cap](fig/x.png)\n"
    )
    html = markdown_to_html(md, "t")
    assert "<h2>Title</h2>" in html
    assert "<code>code</code>" in html and "<strong>bold</strong>" in html
    assert "a &lt; b" in html
    assert "<ul><li>one</li><li>two</li></ul>" in html
    assert "<th>b|c</th>" in html and "<td>x|y</td>" in html
    assert '<img src="fig/x.png" alt="cap">' in html


def test_build_report_from_sections(tmp_path):
    from spslidar.experiments.report import write_section

    write_section(tmp_path, "b", "## B\n\ntext b\n", [Claim("b", "c", "p", "o", "consistent")])
    write_section(tmp_path, "a", "## A\n\ntext a\n")
    write_section(tmp_path, "b", "## B\n\nnew b\n")  # replaces b
    md, html = build_report(tmp_path, ["a", "b", "missing"])
    text = md.read_text()
    assert text.index("## A") < text.index("## B")
    assert "new b" in text and "text b" not in text
    assert html.read_text().count("<h2>B</h2>") == 1


# -- full mode, with the runs faked (full mode itself is too slow for the test suite) -------------


@functools.lru_cache(maxsize=8)
def _scene(name: str, size: int):
    from spslidar.scenes import load_scene

    return load_scene(name, size)


def _fake_sweep(
    func, points, out_dir, *, seed=0, jobs=1, scheduler=None, progress=True, seed_ignore=(),
    code=None,
):
    """Stand-in for run_sweep: truth plus noise of a plausible size, no simulation."""
    import numpy as np

    from spslidar.experiments.sweep import derive_seed, point_key

    rows = []
    for point in points:
        params = dict(point)
        params.setdefault(
            "seed", derive_seed(seed, {k: v for k, v in params.items() if k not in seed_ignore})
        )
        if "scene" not in params:  # an SNR point: the real one, with few periods
            rows.append({**params, **reproduce.snr_point({**params, "periods": 20})})
            continue
        scene = _scene(params["scene"], params["size"])
        rng = np.random.default_rng(params["seed"])
        err = 0.02 if params["qcr"] else 0.1
        if params["lidar"] == "conventional":
            err = 0.3
        depth = scene.depth + rng.normal(0.0, err, scene.depth.shape)
        if params["lidar"] == "conventional" and params.get("rep_rate"):
            depth -= 14.99  # the 10 MHz alias
        key = point_key(params)
        np.save(Path(func.keywords["maps_dir"]) / f"{key}.npy", depth.astype(np.float32))
        d = depth[scene.valid] - scene.depth[scene.valid]
        rows.append(
            {
                **params,
                "depth_rmse_m": float(np.sqrt(np.mean(d**2))),
                "depth_mae_m": float(np.mean(np.abs(d))),
                "depth_bias_m": float(np.mean(d)),
                "missing_fraction": 0.0,
                "edge_correlation": 0.5,
                "depth_median_m": float(np.median(depth[scene.valid])),
                "truth_median_m": float(np.median(scene.depth[scene.valid])),
                "n_patterns": int(params["compression"] * params["size"] ** 2),
                "n_slices": 60,
                "n_slices_solved": 60,
                "unambiguous_range_m": 15.0 if params.get("rep_rate") else 245.6,
                "code_description": "fake",
                "replica": "bipolar",
                "lam": 0.1,
                "iterations": 100,
                "time_total_s": 1.0 + params["compression"],
                "time_simulate_s": 0.5,
                "time_solve_s": 0.5,
                "n_warnings": 0,
                "map_key": key,
            }
        )
    return rows


def test_full_mode_layouts_with_fake_runs(tmp_path, monkeypatch):
    """Full-mode settings and figure layouts (quick mode covers the other experiments)."""
    monkeypatch.setattr(reproduce_context, "run_sweep", _fake_sweep)
    for name in ("fig2", "fig4", "fig6", "table1"):
        assert reproduce_main(name, tmp_path, quick=False, trials=2, progress=False) == 0
        assert list((tmp_path / name).glob("*.csv")), name
    rows = _rows(tmp_path / "fig4" / "fig4.csv")
    lengths = {int(r["code_length"]) for r in rows if r["lidar"] == "psst"}
    assert lengths == {1023, 2047, 4095, 8191, 16383, 32767}
    # trials x (lengths x QCR + conventional x QCR), plus no-QCR solved to convergence at the
    # shortest and the 16383-bit code on trial 0's measurements (same seed), plus the
    # conventional lidar at equal average power (each trial)
    assert len(rows) == 2 * (6 * 2 + 2) + 2 + 2
    assert sum(r.get("fairness") == "power" for r in rows) == 2
    from collections import Counter

    twins = Counter((r["code_length"], r["seed"]) for r in rows
                    if r["lidar"] == "psst" and r["qcr"] == "False" and r["trial"] == "0")
    assert sorted(int(L) for (L, _), n in twins.items() if n == 2) == [1023, 16383]
    assert {r["size"] for r in rows} == {"64"}
    assert len(_rows(tmp_path / "fig2" / "fig2.csv")) == 2 * 6
    assert {r["noise"] for r in _rows(tmp_path / "fig6" / "fig6.csv")} == {"5.0", "8.0", "10.0"}
    summary = _rows(tmp_path / "table1" / "table1_summary.csv")
    assert len(summary) == 8
    tval3 = [r for r in summary if r["solver"] == "tval3" and r["noise"] == "10.0"][0]
    assert tval3["paper_mse_printed_cm"] == "0.011" and tval3["paper_time_s"] == "57.0"
    text = (tmp_path / "report.md").read_text()
    assert "Full mode" in text and "Quick mode" not in text
    assert "± " in text  # two trials: mean ± std
    assert "0.201" in text and "0.176" in text and "0.033" in text
    for name in ("fig2", "fig4", "fig6"):
        assert (tmp_path / name / f"{name}.png").stat().st_size > 10_000


def test_a_file_of_the_users_where_reproduce_writes_is_kept(quick_dir, tmp_path):
    """A user's fig2/fig2.png and section.md in a report folder were replaced without a word
    (an audit of 2026-11-28); other files of theirs stayed. The marker now lists what
    reproduce wrote, and a standard output name it did not write stops the run first."""
    import shutil

    from spslidar.errors import SpslidarError

    out = tmp_path / "r"
    shutil.copytree(quick_dir, out)
    (out / "fig2" / "fig2.png").unlink()
    (out / "fig2" / "fig2.png").write_text("mine")
    (out / "fig2" / "notes.txt").write_text("mine too")
    with pytest.raises(SpslidarError, match=r"fig2/fig2.png was not written by spslidar"):
        reproduce_main("fig2", out, quick=True, progress=False)
    (out / "report.md").write_text("my edit")  # changed since: refused as well
    with pytest.raises(SpslidarError, match=r"report.md were not written|report.md was not"):
        reproduce_main("fig2", out, quick=True, progress=False)
    assert (out / "fig2" / "fig2.png").read_text() == "mine"
    (out / "fig2" / "fig2.png").unlink()  # moved away: the experiment runs again
    (out / "report.md").unlink()
    assert reproduce_main("fig2", out, quick=True, progress=False) == 0
    assert (out / "fig2" / "notes.txt").read_text() == "mine too"


def test_verdicts_that_trials_cannot_resolve_are_inconclusive():
    """Fig. 3's two verdicts, each from one trial, both reversed at five trials, and Fig. 8's
    'TVAL3 best' rested on a 1.5 % lead in one trial (an audit of 2026-11-28)."""
    from spslidar.experiments.reproduce.stats import Stat, best_verdict, compare, within_scatter

    one_a, one_b = Stat(0.0094, 0.0, 1), Stat(0.0102, 0.0, 1)
    assert within_scatter(one_a, one_b)  # one trial: no scatter to judge by
    assert compare(0.0102, 0.0094, 0.0, 0.0, stats=(one_b, one_a))[0] == "inconclusive"
    assert compare(0.0102, 0.0094, 0.0, 0.0)[0] == "not consistent"  # as before, without stats
    close_a, close_b = Stat(0.0077, 0.0017, 5), Stat(0.0081, 0.0012, 5)
    assert compare(0.0077, 0.0081, 0.0, 0.0, stats=(close_a, close_b))[0] == "inconclusive"
    far_a, far_b = Stat(0.0077, 0.0017, 5), Stat(0.0119, 0.0015, 5)  # 2 SE = 0.0020
    assert compare(0.0077, 0.0119, 0.0, 0.0, stats=(far_a, far_b))[0] == "consistent"
    solvers = {"tval3": Stat(0.0794, 0.0, 1), "twist": Stat(0.0806, 0.0, 1),
               "fista": Stat(0.0875, 0.0, 1)}
    verdict, why = best_verdict(solvers, "tval3")
    assert verdict == "inconclusive" and "one trial each" in why
    spread = {"tval3": Stat(0.050, 0.002, 5), "twist": Stat(0.080, 0.002, 5),
              "fista": Stat(0.081, 0.002, 5)}
    assert best_verdict(spread, "tval3") == ("consistent", "")
    assert best_verdict(spread, "fista") == ("not consistent", "")
    assert best_verdict({"a": Stat(0.05, 0.01, 5), "b": Stat(0.051, 0.01, 5)}, "b")[0] == \
        "inconclusive"


def test_a_resumed_reproduction_prices_only_what_it_has_not_cached(quick_dir, capsys):
    """After an interruption, --max-time was refused for the runs already cached; and the
    refusal advised --size and --compression, which reproduce does not take."""
    from spslidar.errors import SpslidarError

    assert reproduce_main("fig3", quick_dir, quick=True, progress=False, max_time=1e-3) == 0
    with pytest.raises(SpslidarError, match="--quick or fewer --trials"):
        reproduce_main("fig3", quick_dir, quick=True, trials=2, progress=False, max_time=1e-3)


def test_a_report_folder_of_an_earlier_version_is_taken_as_reproduces(quick_dir, tmp_path):
    """A marker without the list (the committed docs/reproduction) must not refuse its own
    outputs: the first experiment run there adopts every standard output as reproduce's."""
    import json
    import shutil

    from spslidar.outdir import MARKER

    out = tmp_path / "old"
    shutil.copytree(quick_dir, out)
    meta = json.loads((out / MARKER).read_text())
    meta.pop("written")
    (out / MARKER).write_text(json.dumps(meta))
    assert reproduce_main("fig2", out, quick=True, progress=False) == 0
    assert reproduce_main("fig3", out, quick=True, progress=False) == 0
