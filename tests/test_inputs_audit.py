"""Inputs from a second sweep of every command by someone who did not write them
(2026-11-28): gates too narrow or too wide, files that collide, arrays of the wrong kind,
options the configuration ignores, calibration files edited by hand. Each is one line and
exit 2 with nothing written, or a one-line warning; never a traceback."""

from __future__ import annotations

import re

import numpy as np
import pytest
from _cli_inputs import FAST, small_acquisition
from _cli_inputs import one_line as _one_line
from _warn_filters import ours_as_errors

from spslidar.cli import main
from spslidar.constants import MAX_GATE_BINS
from spslidar.correlate import gate_lags
from spslidar.errors import ConfigError, SpslidarError


@pytest.mark.parametrize("args,match", [
    (["--range-gate", "0", "1e9"], "beyond any lidar range"),
    (["--range-gate", "0", "1e7"], "beyond any lidar range"),
    (["--range-gate", "0", "1e6"], "delay bins"),
    (["--depth-min", "1e7", "--depth-max", "2e7"], "--depth-min must be in"),
    (["--depth-min", "2e6", "--depth-max", "2.0001e6"], "--depth-min must be in"),
])
def test_a_gate_or_window_beyond_any_range_is_refused_before_any_array(tmp_path, capsys,
                                                                       args, match):
    """A gate of 1e9 m asked for a 497 GiB array of lags before the memory check ran; a
    window at 2e6 m ran although a scene file there is refused."""
    out = tmp_path / "o"
    assert main(["run", *FAST, "--out", str(out), *args]) == 2
    assert match in _one_line(capsys)
    assert not out.exists()


def test_gate_lags_counts_before_it_allocates():
    bw = 1e-13  # the fastest bit rate allowed: 1e6 m is 6.7e10 bins
    with pytest.raises(ConfigError, match="delay bins"):
        gate_lags((0.0, 1e6), bw)
    bins = MAX_GATE_BINS * 1.001 * 299_792_458.0 * bw / 2  # just past the cap
    with pytest.raises(ConfigError, match="delay bins"):
        gate_lags((0.0, bins), bw)
    assert gate_lags((1.0, 2.0), 1e-10).size == 69  # bins 66 (floor of 66.7) to 134 (ceil)


@pytest.mark.parametrize("ptu,where", [("same", "the --out folder"), ("same/x.ptu", "inside")])
def test_save_ptu_into_the_result_folder_is_refused_before_the_work(tmp_path, capsys,
                                                                   monkeypatch, ptu, where):
    """``--out same --save-ptu same`` ran the whole simulation, wrote the PTU and its arrays,
    then refused the result folder (exit 2, four files left behind)."""
    monkeypatch.chdir(tmp_path)
    assert main(["run", *FAST, "--out", "same", "--save-ptu", ptu]) == 2
    line = _one_line(capsys)
    assert "--save-ptu" in line and where in line
    assert sorted(p.name for p in tmp_path.iterdir()) == []


@pytest.mark.parametrize("cmd", [
    ["sweep", "SW", "--jobs", "0"],
    ["sweep", "SW", "--jobs", "-7"],
    ["sweep", "SW", "--scheduler", "bogus"],
    ["reproduce", "fig2", "--quick", "--scheduler", "bogus"],
])
@pytest.mark.parametrize("existed", [False, True])
def test_a_refused_sweep_or_reproduce_leaves_no_folder(tmp_path, capsys, cmd, existed):
    """A refused ``--jobs`` or scheduler left the claimed folder with its marker (and, for
    ``reproduce``, an empty cache) behind; a folder the user made empty stays, empty."""
    sw = tmp_path / "sw.toml"
    sw.write_text("seed=1\ntrials=1\n[base]\nsize=8\ncode_length=127\n[grid]\nnoise=[1,10]\n")
    out = tmp_path / "o"
    if existed:
        out.mkdir()
    cmd = [str(sw) if c == "SW" else c for c in cmd]
    assert main([*cmd, "--out", str(out)]) == 2
    line = _one_line(capsys)
    assert "--jobs must be" in line or "scheduler address 'bogus'" in line
    assert out.exists() == existed
    if existed:
        assert list(out.iterdir()) == []


def test_release_folder_keeps_anything_written(tmp_path):
    from spslidar.outdir import MARKER, claim_folder, release_folder

    out = claim_folder(tmp_path / "o", "sweep")
    (out / "runs" / "a").mkdir(parents=True)
    (out / "runs" / "a" / "r.json").write_text("{}")  # a finished run: kept
    assert not release_folder(out, False)
    assert (out / MARKER).exists() and (out / "runs" / "a" / "r.json").exists()
    (out / "runs" / "a" / "r.json").unlink()
    assert release_folder(out, False) and not out.exists()


def test_a_folder_nothing_can_be_moved_into_is_refused_before_the_work(tmp_path, capsys,
                                                                      monkeypatch):
    """An empty, read-only ``--out`` failed only after the run, naming a temporary path. The
    check writes a temporary file in it (root may write anywhere, so the refusal is
    simulated for it)."""
    import tempfile

    out = tmp_path / "ro"
    out.mkdir()
    real = tempfile.TemporaryFile

    def refuse(*a, dir=None, **k):
        if dir is not None and str(dir) == str(out):
            raise PermissionError(13, "Permission denied")
        return real(*a, dir=dir, **k)

    monkeypatch.setattr(tempfile, "TemporaryFile", refuse)
    for cmd in (["run", *FAST], ["reproduce", "fig2", "--quick"]):
        assert main([*cmd, "--out", str(out)]) == 2
        assert f"cannot write in {out} (Permission denied)" in _one_line(capsys)
        assert list(out.iterdir()) == []


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    """A small PTU acquisition written by ``run --save-ptu`` (8x8, 127-bit code)."""
    return small_acquisition(tmp_path_factory.mktemp("measured"))


def _reconstruct(d, out, *extra) -> int:
    return main(["reconstruct", "--ptu", str(d / "scan.ptu"), "--patterns",
                 str(d / "scan_patterns.npy"), "--code", str(d / "scan_code.npy"),
                 "--bit-rate", "10e9", "--range-gate", "1", "3", "--out", str(out),
                 "--no-figure", *extra])


@pytest.mark.parametrize("make,match", [
    (lambda t: t.astype(complex), "of real numbers, got dtype complex128"),
    (lambda t: t > 2, "holds booleans"),
    (lambda t: np.where(np.eye(8, dtype=bool), np.inf, t), "8 infinite or negative"),
    (lambda t: t * 1e6, "beyond any lidar range"),
])
def test_reconstruct_refuses_a_truth_that_is_no_depth_map(measured, tmp_path, capsys, make,
                                                         match):
    """A complex truth was cast to its real part with a library warning, a boolean mask
    scored as depths of 0 and 1 m (RMSE 24.6 m), infinite depths were dropped and a truth in
    micrometres scored an RMSE of 2.5e7 m; negative depths were already refused."""
    truth = np.load(measured / "run" / "truth.npy")
    np.save(tmp_path / "t.npy", make(truth))
    out = tmp_path / "o"
    assert _reconstruct(measured, out, "--truth", str(tmp_path / "t.npy")) == 2
    assert match in _one_line(capsys)
    assert not out.exists()
    np.save(tmp_path / "t.npy", np.where(np.eye(8, dtype=bool), np.nan, truth))
    assert _reconstruct(measured, out, "--truth", str(tmp_path / "t.npy")) == 0  # NaN: unknown


@pytest.mark.parametrize("irf", [np.array([1 + 1j, 0.5]), np.array([True, False])])
def test_run_refuses_an_irf_file_of_no_real_numbers(tmp_path, capsys, irf):
    np.save(tmp_path / "irf.npy", irf)
    out = tmp_path / "o"
    assert main(["run", *FAST, "--out", str(out), "--irf", str(tmp_path / "irf.npy")]) == 2
    assert "real, non-negative numbers" in _one_line(capsys)
    assert not out.exists()


@pytest.mark.parametrize("extra", [["--solver", "gpsr"], ["--regulariser", "wavelet"]])
def test_the_config_says_nonneg_is_off_where_the_regulariser_cannot_take_it(tmp_path, extra):
    """With the wavelet regulariser ``--nonneg`` has no effect (the depth maps are the same
    to the bit), yet ``metrics.json``'s resolved config said ``nonneg: true``."""
    import json

    for flag, name in (("--nonneg", "a"), ("--no-nonneg", "b")):
        assert main(["run", *FAST, *extra, flag, "--out", str(tmp_path / name)]) == 0
    a, b = (json.loads((tmp_path / n / "metrics.json").read_text()) for n in "ab")
    assert a["config"]["nonneg"] is False and b["config"]["nonneg"] is False
    assert np.array_equal(np.load(tmp_path / "a" / "depth.npy"),
                          np.load(tmp_path / "b" / "depth.npy"), equal_nan=True)
    assert main(["run", *FAST, "--regulariser", "l1", "--out", str(tmp_path / "c")]) == 0
    assert json.loads((tmp_path / "c" / "metrics.json").read_text())["config"]["nonneg"]


def test_a_corrupt_tag_is_one_line_naming_it(measured, tmp_path, capsys):
    """ptufile logs a tag type it cannot read (and stops reading the header there) instead of
    raising: its line reached stderr before spslidar's, which named a missing record-type tag
    as the cause."""
    d = bytearray((measured / "scan.ptu").read_bytes())
    d[52:56] = (0x12345678).to_bytes(4, "little")  # the first tag's type code
    (tmp_path / "bad.ptu").write_bytes(bytes(d))
    out = tmp_path / "o"
    assert main(["reconstruct", "--ptu", str(tmp_path / "bad.ptu"), "--patterns",
                 str(measured / "scan_patterns.npy"), "--code", str(measured / "scan_code.npy"),
                 "--bit-rate", "10e9", "--range-gate", "1", "3", "--out", str(out)]) == 2
    line = _one_line(capsys)
    assert "corrupt PTU tag header" in line and "invalid tag type at tag 'File_GUID'" in line
    assert not out.exists()


@pytest.mark.parametrize("args,said", [
    (["--patterns", "bernoulli", "--hadamard-realisation", "differential"],
     "--hadamard-realisation differential is ignored"),
    (["--patterns", "hadamard", "--pattern-sigma", "0.5"], "--pattern-sigma 0.5 is ignored"),
    (["--fairness", "power"], "--fairness power is ignored"),
    (["--lidar", "conventional", "--code-length", "2047", "--code", "gold", "--code-index", "7",
      "--ones-ratio", "0.3"],
     "--code gold, --code-index 7, --ones-ratio 0.3 are ignored"),
    (["--lam", "0.1", "--lam-scale", "5"], "--lam-scale 5 is ignored"),
])
def test_options_the_configuration_ignores_are_said_in_one_line(tmp_path, capsys, args, said):
    """Each ran with the option silently without effect (the depth map the same to the
    bit) while metrics.json recorded it as used."""
    import json

    assert main(["run", *FAST, "--out", str(tmp_path / "o"), *args]) == 0  # (the last wins)
    err = [e for e in capsys.readouterr().err.splitlines() if "ignored" in e]
    assert len(err) == 1 and said in err[0], err
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert any(said in w for w in m["warnings"])


def test_a_fixed_ratio_code_names_its_family():
    from spslidar.config import Config
    from spslidar.errors import ConfigError

    with pytest.raises(ConfigError, match="a Gold code has"):
        Config.from_dict({"code": "gold", "code_length": 127, "ones_ratio": 0.3})
    with pytest.raises(ConfigError, match="an m-sequence has"):
        Config.from_dict({"code_length": 127, "ones_ratio": 0.3})


def test_an_empty_save_ptu_is_refused(tmp_path, capsys):
    """``--save-ptu ""`` ran and wrote no PTU, saying nothing (``--out ""`` was refused)."""
    out = tmp_path / "o"
    assert main(["run", *FAST, "--out", str(out), "--save-ptu", ""]) == 2
    assert "--save-ptu must name a file" in _one_line(capsys)
    assert not out.exists()


@pytest.mark.parametrize("where,match", [
    ("afile/c.json", "afile is a file, not a folder"),
    ("", "--out must name the calibration file"),
    ("adir", "adir is a folder"),
])
def test_calibrate_says_what_is_wrong_with_out(tmp_path, capsys, monkeypatch, where, match):
    """It said "the folder afile does not exist" of a file, and "--out  exists; use
    --overwrite" of an empty name."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("mine")
    (tmp_path / "adir").mkdir()
    assert main(["calibrate", "--ptu", "x.ptu", "--patterns", "p.npy", "--code", "c.npy",
                 "--bit-rate", "10e9", "--distance", "25", "--out", where]) == 2
    assert match in _one_line(capsys)
    assert (tmp_path / "afile").read_text() == "mine"


def test_reproduce_says_trials_are_ignored_where_none_are_run(tmp_path, capsys):
    """``reproduce snr --trials 3`` wrote the same snr.csv as without it, saying nothing."""
    assert main(["reproduce", "snr", "--quick", "--trials", "3", "--out",
                 str(tmp_path / "r"), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "--trials 3 is ignored by snr" in err


def _profiles(seed: int = 0) -> tuple[np.ndarray, object]:
    from spslidar.depth import DepthContext

    rng = np.random.default_rng(seed)
    s = rng.random((64, 40)) * 0.1
    s[np.arange(64), rng.integers(0, 40, 64)] += 1.0
    return s, DepthContext(np.arange(1000, 1040), 1e-10, 0.5, (8, 8))


@pytest.mark.parametrize("name", ["argmax", "censor", "evidence", "guarded", "mrf"])
def test_a_value_that_is_not_finite_is_no_evidence_and_leaves_the_others(name):
    """One NaN moved 62 of 64 MRF depths to the first lag and made every confidence NaN;
    all-NaN slices gave 64 finite depths. A value that is not finite reads as 0 (it voided
    its whole pixel until an audit of 2026-11-29 found one NaN delay voiding every pixel);
    a pixel with no finite value has no return."""
    from spslidar.depth import ESTIMATORS

    s, ctx = _profiles()
    bad = s.copy()
    bad[3, 5] = np.nan
    bad[7, 0] = np.inf
    bad[9] = np.nan
    zeroed = np.where(np.isfinite(bad), bad, 0.0)
    a = ESTIMATORS.load(name)().estimate(zeroed, ctx)
    b = ESTIMATORS.load(name)().estimate(bad, ctx)
    rest = np.arange(64) != 9
    assert np.array_equal(a.depth[rest], b.depth[rest], equal_nan=True)
    assert np.isfinite(b.depth[[3, 7]]).all()
    assert np.isnan(b.depth[9]) and b.confidence[9] == 0
    assert np.all((b.confidence >= 0) & (b.confidence <= 1))
    allnan = ESTIMATORS.load(name)().estimate(np.full((64, 40), np.nan), ctx)
    assert np.isnan(allnan.depth).all() and not allnan.confidence.any()


@pytest.mark.parametrize("slices,match", [
    (np.zeros(64), "non-empty (Q, K) array"),
    (np.zeros((64, 0)), "non-empty (Q, K) array"),
    (np.zeros((0, 40)), "non-empty (Q, K) array"),
    (np.zeros((64, 30)), "ctx.lags has 40 delays but the slices 30"),
    (np.zeros((64, 40), complex), "real numbers"),
    (np.zeros((49, 40)), "does not hold the 49 pixels"),
])
@pytest.mark.parametrize("name", ["argmax", "censor", "evidence", "guarded", "mrf"])
def test_an_estimator_refuses_slices_that_do_not_fit_its_context(name, slices, match):
    """These ended in IndexError, AxisError or numpy's pad errors, or gave depths from lags
    that were not the slices' (every estimator but argmax took 30 lags for 40 slices)."""
    from spslidar.depth import ESTIMATORS

    _, ctx = _profiles()
    if name in ("argmax", "censor") and slices.shape == (49, 40):
        return  # per-pixel estimators need no image shape
    with pytest.raises(ConfigError, match=re.escape(match)):
        ESTIMATORS.load(name)().estimate(slices, ctx)


def test_a_weight_the_solve_cannot_hold_is_refused():
    """``lam_scale=1e40`` in float32 solved to NaN slices, scored as a depth map of one
    value with every confidence NaN and no warning."""
    import spslidar

    m = spslidar.measure(size=8, code_length=127, compression=0.5)
    with pytest.raises(ConfigError, match="beyond what float32 can hold"):
        spslidar.reconstruct(m, lam_scale=1e40)
    assert np.isfinite(spslidar.reconstruct(m, lam_scale=1e30).depth_rmse)


def _sweep_toml(tmp_path, text: str):
    path = tmp_path / "s.toml"
    path.write_text(text)
    return str(path)


def test_a_sweep_reads_an_edited_scene_file_again(tmp_path, monkeypatch, capsys):
    """The cache key held the scene's name only: a sweep resumed after the file was edited
    gave the earlier file's results (0.081 m for a scene whose own is 1.19 m)."""
    import csv

    monkeypatch.chdir(tmp_path)
    np.save("plane.npy", np.full((8, 8), 20.0) + np.linspace(0, 0.5, 8))
    toml = _sweep_toml(tmp_path, 'seed=1\n[base]\nsize=8\ncode_length=127\ncompression=0.5\n'
                                 'scene="plane.npy"\ndepth="argmax"\n[grid]\nnoise=[1]\n')

    def rows():
        with open(tmp_path / "o" / "results.csv") as fh:
            return list(csv.DictReader(fh))

    assert main(["sweep", toml, "--out", "o", "--no-progress"]) == 0
    first = rows()[0]
    np.save("plane.npy", np.full((8, 8), 40.0) + np.linspace(0, 3, 8))
    assert main(["sweep", toml, "--out", "o", "--no-progress"]) == 0
    second = rows()[0]
    assert first["scene_sha256"] != second["scene_sha256"]
    assert first["seed"] == second["seed"]  # the same noise: a paired comparison
    assert float(second["depth_rmse_m"]) != float(first["depth_rmse_m"])


def test_a_seed_in_the_grid_with_trials_is_refused(tmp_path, capsys):
    """Every trial of each seed was the same to the bit (base.seed was already refused)."""
    toml = _sweep_toml(tmp_path, "trials=3\n[base]\nsize=8\ncode_length=127\n"
                                 "[grid]\nseed=[1, 2]\n")
    assert main(["sweep", toml, "--out", str(tmp_path / "o")]) == 2
    assert "grid.seed with trials = 3" in _one_line(capsys)
    assert not (tmp_path / "o").exists()


def test_a_sweeps_time_is_shared_by_the_cores_not_by_jobs(tmp_path, capsys, monkeypatch):
    """``--jobs 1000`` divided the estimate by 1000 before the pool was clamped to the cores,
    and a 9 h sweep started."""
    import re as _re

    from spslidar.experiments.sweep import engine

    monkeypatch.setattr(engine, "_cores", lambda: 2)
    toml = _sweep_toml(tmp_path, "seed=1\n[base]\nsize=16\ncode_length=1023\n"
                                 "[grid]\nnoise=[1,2,3,4,5,6,7,8,9,10]\n")
    said = []
    for jobs in ("2", "1000"):
        assert main(["sweep", toml, "--out", str(tmp_path / "o"), "--jobs", jobs,
                     "--max-time", "0.001"]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        if jobs == "1000":  # the clamp is said first (it was silent here: an audit)
            assert lines[0] == ("spslidar sweep: warning: --jobs 1000 clamped to 2 (10 runs to "
                                "do, 2 cores)")
            lines = lines[1:]
        assert len(lines) == 1, lines
        said.append(float(_re.search(r"take ~([0-9.]+) s", lines[0]).group(1)))
    assert said[0] == said[1]


def test_a_measurement_keeps_its_own_config_and_truth():
    """``measure(cfg)`` kept the caller's Config: editing it afterwards changed what a later
    ``reconstruct`` reported (scene 'motorcycle' for camera data) or broke it (a raw
    ValueError from the TV at another size); ``r.truth[:] = 0`` changed what a later
    reconstruction was scored against."""
    import spslidar

    cfg = spslidar.Config(size=8, code_length=127, compression=0.5, noise=10, depth="argmax")
    m = spslidar.measure(cfg)
    cfg.noise, cfg.scene, cfg.size = 0.0, "motorcycle", 16
    r = spslidar.reconstruct(m)
    assert r.metrics["config"]["noise"] == 10 and r.metrics["config"]["scene"] == "camera"
    with pytest.raises(ValueError, match="read-only"):
        r.truth[:] = 0
    assert spslidar.reconstruct(m).depth_rmse == r.depth_rmse


@pytest.mark.parametrize("kw,match", [
    ({"size": float("nan")}, "--size must be finite, got nan"),
    ({"seed": float("inf")}, "--seed must be finite"),
    ({"iterations": float("inf")}, "--iterations must be finite"),
    ({"code_length": 10**400}, "--code-length must be finite, got an integer of 401 digits"),
    ({"signal": 10**400}, "--signal must be finite"),
    ({"signal": 1e38}, "expected photons per TDC bin per pixel"),
    ({"noise": 1e38}, "expected photons per TDC bin per pixel"),
    ({"background_rate": 1e300}, "expected photons per TDC bin per pixel"),
    ({"dark_count_rate": 1e300}, "expected photons per TDC bin per pixel"),
])
def test_numbers_no_run_can_hold_are_one_line(kw, match):
    """NaN, infinite or huge integers gave ValueError / OverflowError from int() and
    float(); a signal of 1e38 overflowed to an infinite Poisson mean deep in the detector."""
    from spslidar.config import Config

    with pytest.raises(ConfigError) as info:
        Config.from_dict(kw)
    assert match in str(info.value) and "\n" not in str(info.value)


def test_a_seed_beyond_a_float_is_an_integer():
    from spslidar.config import Config

    assert Config.from_dict({"seed": 10**30}).seed == 10**30  # (it was "must be an integer")


def test_a_toml_with_nan_is_one_line(tmp_path, capsys):
    toml = _sweep_toml(tmp_path, "[base]\ncode_length=127\n[grid]\nsize=[nan, 8]\n")
    assert main(["sweep", toml, "--out", str(tmp_path / "o")]) == 2
    assert "must be finite" in _one_line(capsys)
    (tmp_path / "r.toml").write_text("size = nan\n")
    assert main(["run", "--config", str(tmp_path / "r.toml"), "--out", str(tmp_path / "p")]) == 2
    assert "--size must be finite" in _one_line(capsys)


@pytest.mark.parametrize("fov", ["abc", np.array([10]), True, 200])
def test_result_save_checks_the_field_of_view_before_any_file(tmp_path, fov):
    """``save(fov_deg='abc')`` raised a raw ValueError from float(), an array a TypeError."""
    import spslidar

    r = spslidar.run(size=8, code_length=127, compression=0.5)
    with pytest.raises(ConfigError, match="field of view"):
        r.save(tmp_path / "o", fov_deg=fov, figure=False)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("args,match", [
    (["--code", "random", "--code-length", "1000000000"], "more than the 16777216 bits"),
    (["--trials", "2", "--interval", "bootstrap"], "at least 10 trials"),
    (["--trials", "1000000", "--interval", "bootstrap", "--max-time", "5"], "--max-time 5 s"),
])
def test_snr_refuses_what_it_cannot_simulate_or_resample(capsys, args, match):
    """A 10^9-bit random code asked for 7.45 GiB (a traceback); a bootstrap of 2 trials said
    '+- 0'; the bootstrap's resampling was not in the time estimate (16 s past --max-time 5)."""
    assert main(["snr", "--size", "8", "--code-length", "127", *args]) == 2
    assert match in _one_line(capsys)


def test_a_bootstrap_without_variance_in_its_resamples_has_no_interval():
    from spslidar.snr.simulate import _bootstrap

    se, lo, hi = _bootstrap(np.full(10, 5.0), 0.0, 1000, np.random.default_rng(0))
    assert np.isnan(se) and np.isnan(lo) and np.isnan(hi)  # no resample has a variance
    c = np.array([5.0] * 9 + [9.0])  # 35 % of the resamples miss the 9: the rest give one
    se, lo, hi = _bootstrap(c, 0.0, 1000, np.random.default_rng(0))
    assert se > 0 and lo < hi
    se, lo, hi = _bootstrap(np.random.default_rng(1).poisson(50, 40).astype(float), 0.0, 1000,
                            np.random.default_rng(0))
    assert se > 0 and lo < hi


@pytest.mark.parametrize("kw,match", [
    ({"resolution_s": None}, "resolution_s must be a number"),
    ({"resolution_s": "1e-10"}, "resolution_s must be a number"),
    ({"resolution_s": float("inf")}, "resolution_s must be in"),
    ({"sync_rate_hz": float("inf")}, "sync_rate_hz must be in"),
    ({"sync_rate_hz": np.array([1e6, 2e6])}, "sync_rate_hz must be a number"),
    ({"sync_rate_hz": 1e-300}, "at least 1 Hz"),
    ({"extra_tags": {"X": [1]}}, "cannot encode PTU tag X"),
    ({"extra_tags": {"X": 2**70}}, "does not fit a 64-bit integer"),
    ({"extra_tags": {"Ä": 1}}, "1-31 ASCII characters"),
    ({"extra_tags": {5: 1}}, "1-31 ASCII characters"),
    ({"extra_tags": {"A" * 40: 1}}, "1-31 ASCII characters"),
    ({"nsync": [0, 2**52], "dtime": [1, 2]}, "overflow records"),
])
def test_write_ptu_t3_checks_its_arguments(tmp_path, kw, match):
    """Each raised TypeError, OverflowError, struct.error, UnicodeEncodeError, AttributeError
    or MemoryError (16 GiB of overflow records), or was written (an infinite resolution, a
    40-character tag name cut to 32)."""
    from spslidar.io.ptu_write import write_ptu_t3

    args = {"nsync": [0, 1, 2], "dtime": [1, 2, 3], "resolution_s": 1e-10,
            "sync_rate_hz": 1e6, **kw}
    with pytest.raises(ConfigError, match=re.escape(match)):
        write_ptu_t3(tmp_path / "x.ptu", **args)
    assert not list(tmp_path.iterdir())


def test_write_ptu_t3_takes_an_aware_time_and_refuses_a_folder(tmp_path):
    from datetime import datetime, timezone

    from spslidar.io.ptu_write import write_ptu_t3

    args = {"nsync": [0, 1, 2], "dtime": [1, 2, 3], "resolution_s": 1e-10, "sync_rate_hz": 1e6}
    assert write_ptu_t3(tmp_path / "x.ptu", created=datetime.now(timezone.utc), **args) == 3
    for where, match in ((tmp_path, "it is a folder"), (tmp_path / "no" / "x.ptu", "not exist")):
        with pytest.raises(ConfigError, match=match):
            write_ptu_t3(where, **args)


def test_reproduces_time_limit_bounds_the_whole_command(tmp_path):
    """``reproduce all --quick --max-time 10`` checked each batch against 10 s and ran 30 s:
    the batches' estimates now add up against the limit."""
    from spslidar.experiments.reproduce.context import Context, _check_batch_time

    points = [{"size": 16, "code_length": 1023, "seed": s} for s in range(4)]
    ctx = Context(tmp_path, quick=True)
    _check_batch_time(ctx, points)
    one = ctx.estimated_s
    assert one > 0
    ctx = Context(tmp_path, quick=True, max_time=1.5 * one)
    _check_batch_time(ctx, points)  # the first batch fits
    with pytest.raises(SpslidarError, match="its earlier batches and this one"):
        _check_batch_time(ctx, points)  # the second would pass the limit in all


@pytest.mark.parametrize("kw,match", [
    ({"range_gate": [19.9, "20.9"]}, "--range-gate must be two numbers"),
    ({"noise_split": [0.5, "0.5", 0]}, "noise-split must be three numbers"),
    ({"auto_gate": "true"}, "without quotes"),
    ({"qcr": "false"}, "without quotes"),
])
def test_text_is_not_a_number_or_a_flag(kw, match):
    """A gate of [19.9, "20.9"] was read as numbers while size = "16" was refused, and
    auto_gate = "true" did not say TOML's booleans are bare words."""
    from spslidar.config import Config

    with pytest.raises(ConfigError, match=match):
        Config.from_dict(kw)


WALL_RUN = ["--size", "8", "--code-length", "1023", "--signal", "1", "--noise", "0.02",
            "--compression", "0.5", "--range-gate", "24", "30", "--no-figure"]


@pytest.fixture(scope="module")
def wall(tmp_path_factory):
    d = tmp_path_factory.mktemp("wall")
    np.save(d / "w.npy", np.full((8, 8), 25.0))
    np.save(d / "big.npy", np.ones(2) * 1e308)
    np.save(d / "flat.npy", np.ones(1023))
    return d


@pytest.mark.parametrize("args,match", [
    (["--irf", "gaussian:150e-12,weight:0.3"], "a weight without a tail does nothing"),
    (["--irf", "gaussian:150e-12,tail:400e-12,weight:0"], "a tail of weight 0 does nothing"),
    (["--irf", "gaussian:2e-10,tail:4e-10,weight:0.3,weight:0.9"], "weight is given twice"),
    (["--irf", "gaussian:1e-6"], "wider than half the code period"),
    (["--irf", "FLAT"], "more than half the code period"),
    (["--detector", "gmapd", "--jitter-tail", "4e-10"], "--jitter-tail does nothing without"),
    (["--detector", "gmapd", "--jitter-tail-weight", "0.5"], "does nothing without --jitter-tail"),
    (["--detector", "gmapd", "--afterpulse-delay", "1e-9"], "--afterpulse-prob"),
    (["--detector", "gmapd", "--jitter", "1e-6"], "wider than half the code period"),
])
def test_instrument_options_that_do_nothing_or_resolve_nothing_are_refused(wall, capsys, args,
                                                                          match):
    """Each ran with the option doing nothing (the same depth map to the bit), the last of
    two weights silently winning, or a response wider than the code giving a map of noise
    (RMSE 1.4-1.9 m), saying nothing."""
    args = [str(wall / "flat.npy") if a == "FLAT" else a for a in args]
    out = wall / "o"
    assert main(["run", "--scene", str(wall / "w.npy"), *WALL_RUN, *args, "--out",
                 str(out)]) == 2
    assert match in _one_line(capsys)
    assert not out.exists()


@pytest.mark.parametrize("args", [["--irf", "BIG"], ["--irf", "gaussian:1e-300"]])
def test_extreme_but_valid_responses_run_quietly(wall, capsys, args):
    """An IRF file summing past 1e308 was normalised to zeros (RMSE 0.22 m) with a library
    overflow warning; a width of 1e-300 s leaked NumPy's overflow warning."""
    args = [str(wall / "big.npy") if a == "BIG" else a for a in args]
    out = wall / f"q{len(list(wall.iterdir()))}"
    assert main(["run", "--scene", str(wall / "w.npy"), *WALL_RUN, *args, "--out",
                 str(out)]) == 0
    assert "RuntimeWarning" not in capsys.readouterr().err
    import json

    assert json.loads((out / "metrics.json").read_text())["depth_rmse_m"] < 0.02


def test_a_delay_of_whole_code_periods_is_said_as_it_reads(wall, capsys):
    """A delay of one code period read the true depths while the warning said 15.3 m too far
    and every pixel outside the gate; 120 ns read 2.65 m too far, not 18 m."""
    for delay, said in (("102.3e-9", "(0 m too far, modulo the code's 15.3 m"),
                        ("120e-9", "(2.65 m too far, modulo")):
        out = wall / f"d{delay}"
        assert main(["run", "--scene", str(wall / "w.npy"), *WALL_RUN, "--system-delay",
                     delay, "--out", str(out)]) == 0
        err = capsys.readouterr().err
        assert said in err and "outside the range gate" not in err


def test_save_ptu_of_a_gmapd_is_no_longer_said_to_be_linear(wall, capsys):
    """The file was drawn by linear counting, and said so; it now holds the GMAPD's own
    detections (tests/test_deadtime.py checks them)."""
    out = wall / "g"
    assert main(["run", "--scene", str(wall / "w.npy"), *WALL_RUN, "--detector", "gmapd",
                 "--periods", "2", "--signal", "1e-3", "--noise", "1e-4", "--pileup-correction",
                 "off", "--save-ptu", str(wall / "g.ptu"), "--out", str(out)]) == 0
    assert "linear Poisson counting" not in capsys.readouterr().err


def test_save_ptu_says_noiseless_is_not_in_the_file(wall, capsys):
    """run --noiseless --save-ptu reported a noiseless map while the file held drawn photons,
    whose reconstruct read 0.044 m for run's 0.0015 m, without a word (an outside audit,
    options paired)."""
    assert main(["run", "--scene", str(wall / "w.npy"), *WALL_RUN, "--noiseless",
                 "--save-ptu", str(wall / "n.ptu"), "--out", str(wall / "n")]) == 0
    assert "--noiseless is in run's own depth map, not in" in capsys.readouterr().err


def test_calibrating_on_a_target_that_is_not_flat_is_said():
    """The steps scene (24.5-25.5 m) calibrated to a delay 0.5 m off, read from its farthest
    plane, without a word. A flat target's response (a peak and a tail that only falls) says
    nothing; two surfaces 1 m apart warn once."""

    from spslidar.codes import make_code
    from spslidar.pipeline.calibration import measure_response

    code = make_code("mseq", 1023).astype(float)
    tail = np.exp(-np.arange(40) / 4.0)
    tail /= tail.sum()

    def hist(delays_weights):
        h = np.zeros(1023)
        for d, w in delays_weights:
            for o, t in enumerate(tail):
                h += w * t * np.roll(code, d + o)
        return 1000 * h + 50.0

    with ours_as_errors():
        one = measure_response(hist([(300, 1.0)]), code, 1e-10, 25.0, 0.5)
    with pytest.warns(UserWarning, match=r"second return \+1 m from the strongest \(50 %"):
        two = measure_response(hist([(300, 1.0), (367, 0.5)]), code, 1e-10, 25.0, 0.5)
    assert one["lag_shift"] == two["lag_shift"]  # read from the strongest either way


def test_a_chunk_larger_than_the_file_reads_the_file(measured):
    """``chunk_records=10**12`` was refused as '64000 GB of histograms'; the result does not
    depend on the chunk, so a chunk past the file's end is the file."""
    from spslidar.io.ptu import read_ptu_histograms

    a = read_ptu_histograms(measured / "scan.ptu", 127, bin_width=1e-10, marker=1)
    b = read_ptu_histograms(measured / "scan.ptu", 127, bin_width=1e-10, marker=1,
                            chunk_records=10**12)
    assert np.array_equal(a.histograms, b.histograms)


def test_natural_hadamard_order_below_full_sampling_is_said_to_alias(tmp_path, capsys):
    """``--hadamard-order natural`` at 25 % took the first rows of Sylvester's order, whose
    patterns repeat down the image: the steps (32x32) came out as bands at 0.25 m against
    cake-cutting's 0.0015 m, with a high peak-to-noise ratio and no word (a sweep of unusual
    regimes). It is said; at full sampling, where it is exact, it is not."""
    assert main(["run", *FAST, "--out", str(tmp_path / "a"), "--patterns", "hadamard",
                 "--hadamard-order", "natural"]) == 0
    err = [e for e in capsys.readouterr().err.splitlines() if "natural" in e]
    assert len(err) == 1 and "copied into bands" in err[0]
    assert main(["run", *FAST, "--out", str(tmp_path / "b"), "--patterns", "hadamard",
                 "--hadamard-order", "natural", "--compression", "1"]) == 0
    assert "natural" not in capsys.readouterr().err


def test_a_random_code_drawn_all_ones_keeps_a_zero(tmp_path, capsys):
    """A 7-bit random code drawn all ones (``--ones-ratio 0.99``) ended in two NumPy warnings
    and 'the weight nan is beyond what float32 can hold' (a sweep of unusual regimes): its
    zero-mean replica is zero. As a draw without a '1' gets one, a draw without a '0' gets
    one, and the run goes through."""
    from spslidar.codes.sequences import make_code

    for seed in range(20):
        code = make_code("random", 7, 0.99, np.random.default_rng(seed))
        assert 0 < code.sum() < 7
        code = make_code("random", 7, 0.01, np.random.default_rng(seed))
        assert 0 < code.sum() < 7
    assert main(["run", "--size", "8", "--code", "random", "--code-length", "7",
                 "--ones-ratio", "0.99", "--no-figure", "--out", str(tmp_path / "o")]) == 0
    assert "RuntimeWarning" not in capsys.readouterr().err


@pytest.mark.parametrize("kernel,second", [
    ([1, 1, 1, 1, 1], False),  # a box response: a plateau, one return
    # a peak and a tail of 20 bins holding 90 % of it
    ([1.0] + list(9.0 * np.exp(-np.arange(1, 60) / 20.0) / 20.0), False),
    ([0.3, 1, 0.4, 0.1, 0.05, 0.05, 0.3, 0.2, 0.05], True),  # a bump after a valley
])
def test_a_second_return_needs_a_valley_before_it(kernel, second):
    """A flat wall through a box IRF was said to hold 'a second return +0.06 m (100 % of
    it)', through a 90 % tail of 20 bins '+0.285 m (19 %)' (an audit of calibrations): a
    plateau, a shoulder or a tail's noise is the same return. A maximum after the response
    fell below half of it still warns (an afterpulse bump looks like a second surface)."""
    import warnings

    from spslidar.codes import make_code
    from spslidar.pipeline.calibration import measure_response

    code = make_code("mseq", 1023).astype(float)
    k = np.asarray(kernel, float) / np.sum(kernel)
    h = sum(w * np.roll(code, 300 + o) for o, w in enumerate(k))
    counts = np.random.default_rng(0).poisson(20000 * h + 50.0).astype(float)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        measure_response(counts, code, 1e-10, 25.0, 0.5)
    said = [w for w in caught if "second return" in str(w.message)]
    assert len(said) == (1 if second else 0), [str(w.message) for w in caught]
