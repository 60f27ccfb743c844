"""An audit of ``metrics.json`` as a user recomputes it from the files a run writes: the edge
score read edges across the truth's holes (0.970 where the files give 0.48), a noiseless run
that said no pixel holds a return reported full coverage, a sweep's ``results.csv`` had no
coverage or warnings, and a low-confidence share came without its threshold."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spslidar import pipeline
from spslidar.cli import main
from spslidar.depth import ESTIMATORS
from spslidar.metrics import edge_agreement, sobel_edges, truth_edge_mask


def _metrics(out) -> dict:
    return json.loads((out / "metrics.json").read_text())


def test_truth_edge_mask_keeps_the_pixels_whose_sobel_window_is_known():
    valid = np.ones((6, 7), bool)
    assert truth_edge_mask(valid) is None  # every pixel known: nothing to leave out
    valid[2, 3] = False
    keep = truth_edge_mask(valid)
    expect = np.ones((6, 7), bool)
    expect[1:4, 2:5] = False  # the hole and its 8 neighbours
    np.testing.assert_array_equal(keep, expect)
    valid = np.ones((5, 5), bool)
    valid[0, 0] = False  # a corner: the mirrored border adds no other pixel
    expect = np.ones((5, 5), bool)
    expect[:2, :2] = False
    np.testing.assert_array_equal(truth_edge_mask(valid), expect)


def test_the_edge_score_does_not_read_what_fills_the_truths_holes():
    """Two fillings of the same holes (run fills them from the scene, reconstruct --truth
    with 0 m) give one score over the known pixels; over every pixel they did not."""
    rng = np.random.default_rng(0)
    truth = np.where(np.arange(16)[None, :] < 8, 2.0, 3.0) * np.ones((16, 16))
    valid = np.ones((16, 16), bool)
    valid[4:9, 10:14] = False
    estimate = truth + rng.normal(0.0, 0.01, truth.shape)
    est_edges = sobel_edges(estimate)
    keep = truth_edge_mask(valid)
    scores = [edge_agreement(est_edges, sobel_edges(np.where(valid, truth, fill)), keep)
              for fill in (0.0, 2.5, 7.0)]
    assert scores[0] == pytest.approx(scores[1], abs=1e-12)
    assert scores[0] == pytest.approx(scores[2], abs=1e-12)
    unmasked = [edge_agreement(est_edges, sobel_edges(np.where(valid, truth, fill)))
                for fill in (0.0, 7.0)]
    assert abs(unmasked[0] - unmasked[1]) > 0.05  # the score the mask replaces moved (0.08)
    assert edge_agreement(est_edges, est_edges, np.zeros((16, 16), bool)) != \
        edge_agreement(est_edges, est_edges, np.zeros((16, 16), bool))  # none scored: NaN


def test_run_scores_edges_over_the_known_pixels_as_its_files_recompute(tmp_path):
    """A scene file whose ``valid`` blanks part of it: metrics.json's edge score equals the
    one recomputed from depth.npy, truth.npy and valid.npy (1.0 against 0.54 before)."""
    depth = np.full((16, 16), 4.0)
    depth[:, 6:10] = 3.0
    depth[3:7, 2:5] = 2.5
    valid = np.ones((16, 16), bool)
    valid[:, 11:] = False
    scene = tmp_path / "half.npz"
    np.savez(scene, depth=depth, valid=valid)
    out = tmp_path / "o"
    assert main(["run", "--scene", str(scene), "--size", "16", "--code-length", "1023",
                 "--no-figure", "--out", str(out)]) == 0
    m = _metrics(out)
    d, t, v = (np.load(out / f"{k}.npy") for k in ("depth", "truth", "valid"))
    again = edge_agreement(sobel_edges(d), sobel_edges(t), truth_edge_mask(v))
    assert m["edge_correlation"] == pytest.approx(again, abs=1e-12)


def test_a_noiseless_gate_without_the_scene_leaves_the_map_empty(tmp_path, capsys):
    """It said "no pixel holds a return" and reported coverage 1.0 and an RMSE of 2.29 m."""
    out = tmp_path / "o"
    assert main(["run", "--scene", "steps", "--size", "8", "--noiseless", "--range-gate",
                 "12", "13", "--no-figure", "--out", str(out)]) == 0
    m = _metrics(out)
    assert m["coverage"] == 0.0 and m["missing_fraction"] == 1.0
    assert m["depth_rmse_m"] is None
    assert np.isnan(np.load(out / "depth.npy")).all()
    assert not np.any(np.load(out / "confidence.npy"))
    assert any("no pixel holds a return" in w for w in m["warnings"])
    assert "no depth to score: none of the 64 pixels" in capsys.readouterr().out


def test_a_sweep_row_says_its_coverage_and_warnings():
    """A pure-noise point looked like an ordinary result in results.csv."""
    base = {"scene": "steps", "size": 16, "code_length": 1023, "seed": 0}
    good = pipeline.run_metrics(base)
    noise = pipeline.run_metrics({**base, "signal": 1e-6})
    for row in (good, noise):
        assert 0.0 <= row["coverage"] <= 1.0
        assert row["n_warnings"] == len([w for w in row["warnings"].split(" | ") if w])
    assert good["n_warnings"] == 0 and good["warnings"] == ""
    assert "mostly noise" in noise["warnings"]
    assert noise["peak_to_noise_p90"] < noise["peak_to_noise_floor"]


@pytest.mark.parametrize("depth", ["argmax", "censor", "mrf"])
def test_the_low_confidence_share_comes_with_its_threshold(depth):
    r = pipeline.run(scene="steps", size=8, code_length=1023, depth=depth, seed=1)
    m = r.metrics
    assert m["low_confidence_threshold"] == ESTIMATORS.load(depth)().low_confidence
    flagged = np.isfinite(r.depth) & (r.confidence < m["low_confidence_threshold"])
    assert m["low_confidence_fraction"] == pytest.approx(flagged.mean(), abs=1e-12)


# -- sweeps as a user runs them (an audit of TOML sweeps, 2026-11-28) --------------------------


def _rows(out) -> list[dict]:
    import csv

    with open(out / "results.csv", encoding="utf-8") as fh:
        return [{k: v for k, v in row.items() if not k.startswith("time_")}
                for row in csv.DictReader(fh)]


def test_a_sweep_gives_the_same_seeds_and_results_from_any_folder(tmp_path, monkeypatch):
    """A scene file was named relative to the current folder in the seed and the cache key:
    three folders gave three seeds (RMSE 0.081 / 0.048 / 0.056 m), and a resume from another
    folder ran everything again."""
    sc = tmp_path / "sc"
    sc.mkdir()
    depth = np.full((8, 8), 4.0)
    depth[:, 3:5] = 3.0
    np.save(sc / "a.npy", depth)
    (sc / "s.toml").write_text('seed = 5\n[base]\nsize = 8\ncode_length = 255\n'
                               '[grid]\nscene = ["./a.npy", "procedural:1"]\nnoise = [1, 5]\n')
    monkeypatch.chdir(tmp_path)
    assert main(["sweep", "sc/s.toml", "--out", "A", "--no-progress"]) == 0
    monkeypatch.chdir(sc)
    assert main(["sweep", "s.toml", "--out", str(tmp_path / "B"), "--no-progress"]) == 0
    a, b = _rows(tmp_path / "A"), _rows(tmp_path / "B")
    assert a == b
    assert a[0]["scene"] == "a.npy"  # as the TOML names it, in one spelling
    cached = sorted(p.name for p in (tmp_path / "A" / "runs").iterdir())
    assert cached == sorted(p.name for p in (tmp_path / "B" / "runs").iterdir())


def test_the_pipeline_runs_blas_on_one_thread():
    """Its results then do not depend on how many threads BLAS may use (a sweep in-process and
    in --jobs 2 workers differed on 12 of 40 points)."""
    from threadpoolctl import threadpool_info

    from spslidar.operators.parallel import one_blas_thread
    from spslidar.pipeline import chain

    @one_blas_thread
    def seen():
        return [pool["num_threads"] for pool in threadpool_info()
                if pool["user_api"] == "blas"]

    assert seen() and set(seen()) == {1}
    assert chain.measure.__wrapped__ and chain.reconstruct.__wrapped__


def test_a_sweep_says_what_its_runs_warned(tmp_path, capsys):
    """Each kind of warning is said once with the runs that gave it (a map of noise is said
    with its own numbers in each run: the first two texts named 2 of an audit's 12 warned
    runs), and results.csv holds the settings the points left at their defaults (the m_n of
    10 a curve over the signal was run at, the solver's weight factor: an audit)."""
    cfg = tmp_path / "s.toml"
    cfg.write_text('[base]\nscene = "steps"\nsize = 8\ncode_length = 1023\n'
                   '[grid]\nsignal = [5.0, 1e-6, 2e-6, 3e-6]\n')
    assert main(["sweep", str(cfg), "--out", str(tmp_path / "o"), "--no-progress"]) == 0
    err = capsys.readouterr().err
    rows = _rows(tmp_path / "o")
    noisy = [r for r in rows if float(r["signal"]) < 1e-3]
    assert all("mostly noise" in r["warnings"] for r in noisy)
    said = [line for line in err.splitlines() if "mostly noise" in line]
    assert len(said) == 1 and "warning in 3 runs (signal=1e-06, trial=0; signal=2e-06, trial=0; " \
        in said[0], said
    assert "3 of 4 runs warned (the warnings column" in err
    assert {r["noise"] for r in rows} == {"10.0"} and {r["lam_scale"] for r in rows} == {"0.45"}
    assert {r["solver"] for r in rows} == {"fista"} and "signal" in rows[0]


@pytest.mark.parametrize("key,value,said", [
    ("out", '"x"', "belongs to spslidar run's command line"),
    ("fov", "20", "belongs to spslidar run's command line"),
    ("config", '"r.toml"', "--config names a run's TOML file")])
def test_a_sweep_names_an_output_option_as_such(tmp_path, capsys, key, value, said):
    """``out = "x"`` in [base] was "unknown config key 'out'" where run --config says what
    it is."""
    cfg = tmp_path / "s.toml"
    cfg.write_text(f'[base]\nsize = 8\n{key} = {value}\n[grid]\nnoise = [1, 2]\n')
    assert main(["sweep", str(cfg), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert f"base.{key} is not a sweep key: {said}" in err
    assert not (tmp_path / "o").exists()


def test_run_into_a_sweeps_folder_says_whose_it_is(tmp_path, capsys):
    """It said the sweep's folder "holds files spslidar did not write"."""
    cfg = tmp_path / "s.toml"
    cfg.write_text('[base]\nscene = "steps"\nsize = 8\ncode_length = 255\n[grid]\nnoise = [1, 2]\n')
    assert main(["sweep", str(cfg), "--out", str(tmp_path / "w"), "--no-progress"]) == 0
    capsys.readouterr()
    before = sorted(p.name for p in (tmp_path / "w").iterdir())
    assert main(["run", "--size", "8", "--out", str(tmp_path / "w"), "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert "it is the folder of a 'spslidar sweep', not of a run" in err
    assert sorted(p.name for p in (tmp_path / "w").iterdir()) == before


def test_an_empty_noiseless_gate_says_no_second_surface_consistently(tmp_path):
    """An estimator that looks for second surfaces and finds none in an empty gate writes an
    all-NaN depth2.npy and a share of 0, where its own depth_info said 0.0039 beside a null
    share and no depth2.npy (an audit of 2026-11-29)."""
    out = tmp_path / "o"
    assert main(["run", "--scene", "steps", "--size", "16", "--noiseless", "--range-gate",
                 "12", "13", "--depth", "guarded", "--no-figure", "--out", str(out)]) == 0
    m = _metrics(out)
    assert m["two_surface_fraction"] == 0.0
    assert m["depth_info"]["two_surface_fraction"] == 0.0
    assert np.isnan(np.load(out / "depth2.npy")).all()


def test_the_rmse_of_random_depths_in_the_gate_is_said_beside_a_map_of_noise(tmp_path, capsys):
    """``chance_rmse_m``: the RMSE of depths drawn uniformly over the gate, against the
    truth, checked against draws (a million per pixel, so within 0.2 %), NaN without a valid
    pixel. A map of noise (a wall at 50 m, m_s = 0.001) scores about it, and the summary says
    so (an audit's curve of RMSE against the signal flattened at the gate's 0.17 m, read as
    the instrument's); a map with returns is not given it."""
    from spslidar.metrics import chance_rmse

    rng = np.random.default_rng(0)
    truth = np.array([[10.0, 10.4], [np.nan, 11.0]])
    draws = rng.uniform(9.8, 11.2, (1_000_000, 1))
    want = np.sqrt(np.mean((draws - truth.ravel()[[0, 1, 3]]) ** 2))
    assert chance_rmse(truth, (9.8, 11.2)) == pytest.approx(want, rel=2e-3)
    assert chance_rmse(truth, (9.8, 11.2), valid=np.array([[1, 0], [0, 0]])) == \
        pytest.approx(np.sqrt(1.4 ** 2 / 12 + 0.5 ** 2))
    assert np.isnan(chance_rmse(np.full((2, 2), np.nan), (0, 1)))
    np.save(tmp_path / "wall.npy", np.full((16, 16), 50.0))
    for signal, said in (("0.001", True), ("5", False)):
        out = tmp_path / signal
        assert main(["run", "--scene", str(tmp_path / "wall.npy"), "--size", "16",
                     "--code-length", "1023", "--signal", signal, "--noise", "10",
                     "--no-figure", "--out", str(out)]) == 0
        m = json.loads((out / "metrics.json").read_text())
        lo, hi = m["range_gate_m"]
        assert m["chance_rmse_m"] == pytest.approx(np.sqrt((hi - lo) ** 2 / 12
                                                           + ((lo + hi) / 2 - 50.0) ** 2))
        text = capsys.readouterr().out
        assert ("depths drawn at random in the gate score" in text) is said, text
        if said:
            assert 0.7 < m["depth_rmse_m"] / m["chance_rmse_m"] < 1.3


def test_review_mends_of_the_sweep_columns_and_the_chance_score(tmp_path, capsys):
    """A review's cases: a run that gives one kind of warning twice is one run; a point's
    hyphenated key (``code-length``) is not written again as ``code_length``, and no
    ``lam_scale`` is claimed where the weight itself was given; the chance score of a gate
    longer than the code's unambiguous range is over its first range (where a map can put
    its depths: a correct map read worse than "chance" through a 30-70 m gate)."""
    from spslidar.experiments.sweep.store import say_outcome
    from spslidar.pipeline.shared import run_metrics

    rows = [{"signal": 1, "n_warnings": 2, "warnings": "odd 1.5 here | odd 2.5 here"}]
    say_outcome(rows, ["signal"], tmp_path / "r.csv")
    err = capsys.readouterr().err
    assert "warning in 1 run (signal=1), the first: odd 1.5 here" in err
    out = run_metrics({"size": 8, "code-length": 127, "lam": 0.01, "noiseless": True})
    assert "code_length" not in out and out["lam_scale"] is None and out["noise"] == 10.0
    np.save(tmp_path / "wall.npy", np.full((8, 8), 50.0))
    run = tmp_path / "far"
    assert main(["run", "--scene", str(tmp_path / "wall.npy"), "--size", "8", "--code-length",
                 "1023", "--bit-rate", "5e9", "--range-gate", "30", "70", "--no-figure",
                 "--out", str(run)]) == 0
    m = json.loads((run / "metrics.json").read_text())
    ru = 1023 * 299792458.0 / 5e9 / 2
    assert m["chance_rmse_m"] == pytest.approx(np.sqrt(ru ** 2 / 12 + (30 + ru / 2 - 50) ** 2))
