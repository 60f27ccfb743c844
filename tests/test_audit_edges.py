"""Extreme but plausible values, as a researcher exploring a design space gives them (an audit
of 2026-11-28): each ended in a traceback, a wrong message or a run far beyond its estimate."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _warn_filters import ours_as_errors

from spslidar.cli import main

TINY = ["--size", "8", "--no-figure", "--scene", "steps", "--depth-min", "1", "--depth-max",
        "1.6", "--range-gate", "0.8", "1.8", "--code-length", "255"]


def test_tval3_refuses_a_zero_weight_in_one_line(tmp_path, capsys):
    """TVAL3 weighs the data by 1/(2 lam): ``--lam 0`` ended in a traceback (exit 1)."""
    assert main(["run", *TINY, "--solver", "tval3", "--lam", "0",
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--lam > 0" in err[0]
    assert not (tmp_path / "o").exists()


def test_tval3_without_photons_gives_an_empty_map(tmp_path, capsys):
    """Without photons max|A^H y| = 0 and the default weight is 0: TVAL3 raised; its
    solution is 0 at every weight, so the run ends as the other solvers' do (no depth)."""
    assert main(["run", *TINY, "--solver", "tval3", "--signal", "1e-12", "--noise", "0",
                 "--out", str(tmp_path / "o")]) == 0
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["coverage"] == 0.0
    assert not np.isfinite(np.load(tmp_path / "o" / "depth.npy")).any()


def test_a_huge_iteration_count_is_priced_and_refused(tmp_path, capsys):
    """Each iteration costs some 0.1-0.2 ms whatever the size: ``--iterations 100000`` at
    8x8 was priced from its products alone (under 3 s) and ran 16 s past ``--max-time 3``."""
    assert main(["run", *TINY, "--noise", "0.5", "--depth", "argmax", "--iterations",
                 "100000", "--max-time", "3", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "more than --max-time 3 s" in err[0]
    # the example raises the limit above the estimate, in a form --max-time reads
    assert "(e.g. --max-time 2h)" not in err[0] and "s)" in err[0]
    assert not (tmp_path / "o").exists()


def test_a_gate_of_many_periods_gives_no_verdict_without_the_memory(tmp_path):
    """A 0-1000 m gate on the default code (66 714 slices, four periods) drew a white-noise
    reference of 2 048 x 66 714 slices and ended in a MemoryError (1.02 GiB; the run's
    estimate 0.3 GB). An aliased profile's noise beside its peak is its own repeat: no
    verdict, said."""
    assert main(["run", "--size", "8", "--no-figure", "--scene", "steps", "--depth-min", "1",
                 "--depth-max", "1.6", "--noise", "0.5", "--depth", "argmax",
                 "--range-gate", "0", "1000", "--out", str(tmp_path / "o")]) == 0
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["peak_to_noise_p90"] is None
    assert any(w.startswith("no noise verdict: the range gate spans more than one code")
               for w in m["warnings"])


def test_the_noise_reference_is_bounded_at_long_gates():
    """The white-noise reference is drawn a block at a time and with fewer profiles past
    4 096 slices: at 66 714 slices its peak allocation is 142 MB (over 2 GB before); up to
    2 048 slices it is the same draw as before (the same numbers)."""
    import tracemalloc

    from spslidar.depth import profile

    tracemalloc.start()
    try:
        profile._reference_stats.cache_clear()
        p90, tau = profile._reference_stats(66714)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
        profile._reference_stats.cache_clear()
    assert peak < 300e6, peak
    # more slices, a taller noise maximum beside the peak: below 1023 slices' 1.23
    assert 1.0 < p90 < 1.2 and tau > 1.0
    rng = np.random.default_rng(0)
    one = np.maximum(rng.standard_normal((2048, 300)), 0.0)
    assert profile._reference_stats(300)[0] == pytest.approx(
        float(np.percentile(profile._noise_stats(one)[0], 90)), rel=1e-12)


@pytest.mark.parametrize("scale", [1e-11, 1e-9])
def test_the_dead_time_model_settles_at_a_vanishing_flux(scale):
    """At 1e-11 photons a bin the histogram is 1e-11 and alpha (of order 1) rounds at
    1e-16: their ratio never met the tolerance, and a GMAPD run swept 15 687 times (13.6 s)
    to say "not converged" (an audit; at 1e-9, 2 000 sweeps left a change of 1e-7). Each
    part's change is now read on its own scale: a few sweeps, and the histogram is the flux
    (a dead time is all but never hit)."""

    from spslidar.detectors.pileup import renewal_detection

    # codes' returns spread over a few bins (a Gaussian of 2 bins), 16 patterns, under a
    # dead time of two 255-bin periods: the audit's 8x8 run's flux
    rng = np.random.default_rng(0)
    code = (rng.random((16, 255)) < 0.5).astype(float)
    kern = np.exp(-0.5 * ((np.arange(255) + 127) % 255 - 127) ** 2 / 4.0)
    spread = np.fft.irfft(np.fft.rfft(code, axis=1) * np.fft.rfft(kern), 255, axis=1)
    mu = scale * spread / spread.max() + 3e-13
    with ours_as_errors():
        h, info = renewal_detection(mu, 500.0, return_info=True)
    assert info["sweeps"] < 50, info
    # h = mu (1 - the flux summed over a dead time: 5e-7 at 1e-9)
    np.testing.assert_allclose(h, mu, rtol=1e-6, atol=0)


def test_a_stages_python_warning_is_kept_in_metrics(tmp_path, capsys):
    """The wavelet prior at an odd image side warns through ``warnings.warn``: it was shown
    on stderr, in another format, and missing from ``metrics.json`` (and so from a sweep's
    row). It is now one of the run's warnings: in ``metrics.json``, said once."""
    assert main(["run", *TINY, "--size", "5", "--solver", "gpsr",
                 "--out", str(tmp_path / "o")]) == 0
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    said = [w for w in m["warnings"] if "wavelet regulariser needs an even image side" in w]
    assert len(said) == 1
    err = capsys.readouterr().err
    assert err.count("wavelet regulariser needs an even image side") == 1
    assert "(UserWarning in" not in err


def test_a_failing_run_gives_its_python_warnings_back(monkeypatch):
    """Where the run raises, what it warned is not swallowed with it."""
    import warnings

    from spslidar.pipeline.chain import keeping_warnings

    @keeping_warnings
    def broken():
        warnings.warn("half way", RuntimeWarning, stacklevel=1)
        raise ValueError("broke")

    with pytest.warns(RuntimeWarning, match="half way"), pytest.raises(ValueError):
        broken()


def test_a_result_folder_with_a_users_file_names_the_file(tmp_path, capsys):
    """A previous result with a user's file added was refused as "the folder of a 'spslidar
    result', not of a run", a contradiction (an audit): the refusal names the user's file,
    which stays."""
    out = tmp_path / "e"
    assert main(["run", *TINY, "--out", str(out)]) == 0
    (out / "user.txt").write_text("mine")
    capsys.readouterr()
    assert main(["run", *TINY, "--out", str(out), "--overwrite"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "files spslidar did not write: user.txt" in err[0]
    assert "not of a run" not in err[0]
    # (nor "is not a spslidar result (it holds a spslidar result ...)", an outside audit)
    assert "holds files besides a spslidar result" in err[0]
    assert "not a spslidar result" not in err[0]
    assert (out / "user.txt").read_text() == "mine"


def test_a_gate_beyond_the_unambiguous_range_is_said(tmp_path):
    """A gate at 100-101 m through a code of 3.75 m unambiguous range read depths there
    without a word (an audit, on a real file): right only where the target is known to be in
    the gate. The steps (1.0-1.6 m) through a 255-bit code (3.82 m) read 3.82 m farther
    through a gate one range out, and say so; through their own gate they do not. (At 8x8
    and 16 patterns this flat wall is also called "mostly noise", its depths right to 1 cm:
    not what is tested here.)"""
    np.save(tmp_path / "wall.npy", np.full((8, 8), 1.3))
    assert main(["run", "--scene", str(tmp_path / "wall.npy"), "--size", "8", "--no-figure",
                 "--code-length", "255", "--range-gate", "0.8", "1.8", "--save-ptu",
                 str(tmp_path / "a.ptu"), "--out", str(tmp_path / "r")]) == 0
    files = ["--ptu", str(tmp_path / "a.ptu"), "--patterns", str(tmp_path / "a_patterns.npy"),
             "--code", str(tmp_path / "a_code.npy"), "--bit-rate", "10e9", "--no-figure"]
    for gate, out in ((("4.6", "5.6"), "far"), (("0.8", "1.8"), "near")):
        assert main(["reconstruct", *files, "--range-gate", *gate,
                     "--out", str(tmp_path / out)]) == 0
    far = json.loads((tmp_path / "far" / "metrics.json").read_text())
    said = [w for w in far["warnings"] if "beyond the 3.822 m unambiguous range of the "
            "255-bit code" in w]
    assert len(said) == 1 and "reads what lies at 0.7776-1.778 m, 3.822 m farther" in said[0]
    assert np.nanmedian(np.load(tmp_path / "far" / "depth.npy")) == pytest.approx(
        1.3 + 3.822, abs=0.02)
    near = json.loads((tmp_path / "near" / "metrics.json").read_text())
    assert not any("unambiguous" in w for w in near["warnings"])
    # run says it too, of a gate it is given there (a new researcher's audit: a wall at 50 m
    # read through a 40-60 m gate and a 30.67 m code without a word); not of its own
    assert main(["run", "--scene", str(tmp_path / "wall.npy"), "--size", "8", "--no-figure",
                 "--code-length", "255", "--range-gate", "4.6", "5.6",
                 "--out", str(tmp_path / "run_far")]) == 0
    run_far = json.loads((tmp_path / "run_far" / "metrics.json").read_text())["warnings"]
    said = [w for w in run_far if "beyond the 3.822 m unambiguous range of the m-seq" in w]
    assert len(said) == 1 and "reads what lies at 0.7776-1.778 m, 3.822 m farther" in said[0]
    assert not any("beyond" in w for w in json.loads(
        (tmp_path / "r" / "metrics.json").read_text())["warnings"])


def test_reconstruct_prices_its_depth_stage_before_the_file():
    """Without the automatic gate ``reconstruct`` priced only its solve before reading the
    file: a 128x128 acquisition priced at 16 s took 35 s, 23 s of it the MRF (an audit).
    A solve of one iteration over 1 000 slices fits a second; its MRF over them does not."""
    from spslidar.config import Config
    from spslidar.errors import SpslidarError
    from spslidar.pipeline.real import _check_solve_time

    cfg = Config(iterations=1, max_time=1.0, auto_gate=False, depth="mrf")
    with pytest.raises(SpslidarError, match="would take"):
        _check_solve_time(cfg, 50, 128 * 128, 1000, 1563)
    _check_solve_time(Config(iterations=1, max_time=1.0, auto_gate=False, depth="argmax"),
                      50, 128 * 128, 100, 1563)  # 0.2 s of argmax and verdict: taken


def test_a_map_of_noise_is_not_summed_up_as_returns(tmp_path, capsys):
    """The summary said "returns in 100% of pixels" right after the warning that the map is
    mostly noise (an audit): where the verdict says noise it reads "a depth in ... mostly
    noise"; where it does not, "returns in"."""
    np.save(tmp_path / "wall.npy", np.full((16, 16), 1.3))
    assert main(["run", "--scene", str(tmp_path / "wall.npy"), "--size", "16", "--no-figure",
                 "--code-length", "255", "--range-gate", "0.8", "1.8", "--signal", "4", "--noise",
                 "0.02", "--save-ptu",
                 str(tmp_path / "a.ptu"), "--out", str(tmp_path / "r")]) == 0
    files = ["reconstruct", "--ptu", str(tmp_path / "a.ptu"), "--patterns",
             str(tmp_path / "a_patterns.npy"), "--code", str(tmp_path / "a_code.npy"),
             "--bit-rate", "10e9", "--no-figure"]
    capsys.readouterr()
    assert main([*files, "--range-gate", "2.2", "3.2", "--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    # (and why: the gate holds none of the wall's returns, said beside the verdict since an
    # outside audit of 2026-12-03)
    assert "a depth in" in out and ("mostly noise, 100% of the returns outside the range "
                                    "gate (see the warnings)") in out
    assert "returns in" not in out
    assert main([*files, "--range-gate", "0.8", "1.8", "--out", str(tmp_path / "b")]) == 0
    out = capsys.readouterr().out
    assert "returns in 100% of pixels" in out and "mostly noise" not in out
    # and depth.png's title, as the line says it
    from spslidar.figures import _title
    from spslidar.pipeline.real import load_code, load_patterns, reconstruct_ptu

    pats, code = load_patterns(tmp_path / "a_patterns.npy"), load_code(tmp_path / "a_code.npy")
    noise = _title(reconstruct_ptu(tmp_path / "a.ptu", pats, code, 10e9, (2.2, 3.2)))
    lit = _title(reconstruct_ptu(tmp_path / "a.ptu", pats, code, 10e9, (0.8, 1.8)))
    assert "a depth in" in noise and "MOSTLY NOISE" in noise and "returns in" not in noise
    assert "100% of the returns outside the range gate; MOSTLY NOISE" in noise
    assert "returns in 100% of pixels" in lit and "MOSTLY NOISE" not in lit


def test_reconstruct_refuses_a_truth_without_depths_and_a_text_bit_rate(tmp_path):
    """An all-NaN --truth was refused after the file was read as "scene '<the PTU>': no pixel
    has a valid ground-truth depth"; a bit rate given as text was taken in Python where a
    text distance is refused (audits). Both are one line before the file is read (the file
    here does not exist, so reading it would be refused otherwise)."""
    from spslidar.errors import ConfigError
    from spslidar.pipeline.real import reconstruct_ptu

    pat = (np.random.default_rng(0).random((8, 4, 4)) < 0.5).astype(np.float32)
    code = (np.random.default_rng(1).random(63) < 0.5).astype(np.uint8)
    with pytest.raises(ConfigError, match=r"--truth holds no depth \(every pixel is NaN\)"):
        reconstruct_ptu(tmp_path / "none.ptu", pat.reshape(8, -1), code, 10e9, (1, 2),
                        truth=np.full((4, 4), np.nan))
    with pytest.raises(ConfigError, match="--bit-rate must be a number"):
        reconstruct_ptu(tmp_path / "none.ptu", pat.reshape(8, -1), code, "10e9", (1, 2))


def test_a_far_gate_is_said_with_the_digits_that_tell_its_ends_apart(tmp_path):
    """A scene at 900 km: "the range gate 900000-900000 m" (an audit)."""
    from spslidar.pipeline.gate import gate_text

    assert gate_text((19.955, 20.845)) == "19.955-20.845"
    assert gate_text((899999.9, 900000.1)) == "899999.9-900000.1"
    assert gate_text((5.0, 5.0)) == "5-5"
    np.save(tmp_path / "far.npy", np.full((8, 8), 9e5))
    assert main(["run", "--scene", str(tmp_path / "far.npy"), "--size", "8", "--no-figure",
                 "--code-length", "255", "--out", str(tmp_path / "o")]) == 0
    warns = json.loads((tmp_path / "o" / "metrics.json").read_text())["warnings"]
    assert any("the default range gate 899999.9-900000.1 m" in w for w in warns), warns


def test_a_diverged_solve_in_float64_is_not_told_to_use_float64(tmp_path, capsys):
    """A noiseless float64 run at 1e-300 photons was told "or use --dtype float64" (an
    audit): the cure it gets is the one that applies."""
    assert main(["run", *TINY, "--signal", "1e-300", "--noise", "0", "--noiseless",
                 "--dtype", "float64", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--dtype float64" not in err[0]
    # (its measurements are not finite: said before the solve, which refuses them since
    # 2026-11-29; before, the solve diverged and said so)
    assert "not finite" in err[0] and "raise --signal" in err[0]


def test_a_memory_limit_no_run_fits_says_so(tmp_path, capsys):
    """``--max-memory 1e-6`` read "largest part: patterns, 0 MB ... more than the 0 MB
    --max-memory: reduce --size" (an audit): no run fits under the interpreter's own."""
    assert main(["run", *TINY, "--max-memory", "1e-6", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no run fits in the 0.001 MB --max-memory" in err[0]
    assert "reduce --size" not in err[0] and not (tmp_path / "o").exists()


@pytest.mark.parametrize("value", ["-1e-9", "-2E+3", "-.5e1"])
def test_a_negative_number_in_scientific_notation_is_a_value(tmp_path, capsys, value):
    """``--system-delay -1e-9`` was "expected one argument" (argparse takes only -1 and -1.5
    for numbers), so the value's own refusal was never reached (an audit)."""
    assert main(["run", *TINY, "--system-delay", value, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--system-delay must be in [0, 0.001]" in err[0], err


def test_a_random_codes_description_says_the_ones_it_holds(tmp_path):
    """A Bernoulli code of 3 bits at ones ratio 0.01 holds 1 one: it was described as "ones
    ratio 0.01" (an audit)."""
    assert main(["run", *TINY, "--code", "random", "--code-length", "3", "--ones-ratio",
                 "0.01", "--out", str(tmp_path / "o")]) == 0
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["code_description"].endswith("(ones ratio 0.01: 1 of its 3 bits)")
    assert m["code_ones"] == 1


REAL = __import__("pathlib").Path(__file__).resolve().parents[2] / "shared" / "realdata"


@pytest.mark.skipif(not (REAL / "hazelnut_z1.ptu").exists(), reason="../shared/realdata absent")
def test_photons_before_the_first_marker_are_said_when_many(tmp_path):
    """hazelnut_z1.ptu read on marker input 3 leaves out 30 479 of its 150 363 photons
    (20 %, before the first marker, no pattern known): said only in metrics.json before
    (an audit); now a warning, with the count there as before."""
    rng = np.random.default_rng(5)
    np.save(tmp_path / "p.npy", (rng.random((5, 8, 8)) < 0.5).astype(np.uint8))
    np.save(tmp_path / "c.npy", (np.random.default_rng(0).random(132) < 0.5).astype(np.uint8))
    assert main(["reconstruct", "--ptu", str(REAL / "hazelnut_z1.ptu"), "--patterns",
                 str(tmp_path / "p.npy"), "--code", str(tmp_path / "c.npy"), "--bit-rate",
                 "10.3125e9", "--marker", "3", "--range-gate", "0.1", "1.8", "--no-figure",
                 "--out", str(tmp_path / "o")]) == 0
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    said = [w for w in m["warnings"] if "of the file's 150363 photons" in w]
    assert len(said) == 1 and "30479 of the file's 150363 photons" in said[0]
    assert "came before the first marker on input 3" in said[0]
    assert m["ptu"]["n_dropped_before_first_marker"] == 30479
    # a frame's photons (30479 over 32374784 periods, against 29934 over as many) before the
    # first of its 5 frame markers and a last block of 1 period: markers that end their
    # frames, as the audit of 2026-11-29's block rules reads it, said with the flag to use
    edge = [w for w in m["warnings"] if "--marker-edge end" in w]
    assert len(edge) == 1 and "30479 photons over 32374784 code periods" in edge[0]


def test_a_gmapd_sweep_says_its_estimate_leaves_the_detector_model_out(tmp_path, capsys):
    """A sweep prices its runs before any runs, but not the GMAPD's dead-time model, whose
    time depends on the flux (a 3-point GMAPD sweep ran 70 s with nothing said, an audit):
    it now says so; a sweep of linear runs does not."""
    for name, det in (("g", 'detector = "gmapd"\nnoise = 1e-5\n'), ("l", "")):
        (tmp_path / f"{name}.toml").write_text(
            f'seed = 1\n[base]\nsize = 8\ncode_length = 255\ndepth = "argmax"\n{det}'
            f"[grid]\nsignal = [1e-5, 3e-5]\n")
        assert main(["sweep", str(tmp_path / f"{name}.toml"), "--out", str(tmp_path / name),
                     "--no-progress"]) == 0
        err = capsys.readouterr().err
        said = "the estimate leaves out the detector model of the 2 points through --detector"
        assert (said in err) is (name == "g"), err


def test_float32_solves_do_not_depend_on_the_threads():
    """Large products were split into one band of rows per thread, and a float32 product
    rounds differently in other bands: a run's numbers depended on the CPUs it was given
    (``taskset -c 0``: a GPSR run 0.0329 -> 0.0309 m; every solver's iterates; an audit of
    reproducibility). The bands are fixed now: the same bits on 1 to 4 threads."""
    from spslidar.operators import MatrixOperator
    from spslidar.operators.parallel import parallel
    from spslidar.solvers import StopRule, get_solver
    from spslidar.solvers.regularisers import make_tv

    rng = np.random.default_rng(0)
    a = MatrixOperator(rng.random((256, 1024)), dtype=np.float32)
    y = rng.standard_normal((256, 40)).astype(np.float32)
    x = rng.standard_normal((1024, 40)).astype(np.float32)
    products = []
    for threads in (1, 2, 3, 4):
        with parallel(threads):
            products.append(a.matvec(x))
    for p in products[1:]:
        np.testing.assert_array_equal(p, products[0])  # bit for bit: the same BLAS calls
    out = [get_solver("fista")(stop=StopRule(max_iter=15), threads=t).solve(
        a, y, make_tv((32, 32)), 0.5)[0] for t in (1, 2, 4)]
    for o in out[1:]:
        np.testing.assert_array_equal(o, out[0])
