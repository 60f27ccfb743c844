"""A pattern sequence shown several times in a row (``--repeats K``): a lab repeats its
sequence to gather photons, and the file then holds K x M marker blocks for M pattern rows.
Before ``--repeats`` such a file was refused as not matching the patterns, and a user's way
round it (the patterns given K times) solved K times the rows. Files written here by the
independent PicoHarp writer of ``test_independent_ptu``.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_independent_ptu import write_picoharp_t3  # (tests/ is on sys.path under pytest)
from test_screen_blocks import BIT_RATE, L, N, _scene

from spslidar.cli import main
from spslidar.pipeline.blocks import check_repeats, fold_repeats
from spslidar.pipeline.real import reconstruct_ptu

C = 299_792_458.0
M, K, DWELL = 96, 3, 800


def _counts(seed, signal=2e-4, background=2e-4, mask=None, move=0.0):
    """Photon counts per repeat, pattern and bin (K, M, L), the patterns, code and truth of
    the 16x16 scene of ``test_screen_blocks`` (random binary patterns, a balanced code;
    ``mask``: 0 where a mirror is never on; ``move``: metres the scene moves away each
    repeat, the truth the first repeat's)."""
    rng = np.random.default_rng(seed)
    depth, refl = _scene()
    code = np.zeros(L)
    code[rng.permutation(L)[: L // 2 + 1]] = 1.0
    pats = (rng.random((M, N, N)) < 0.5).astype(np.float32)
    if mask is not None:  # (mirrors that never turn on: lit by no pattern)
        pats *= mask
    w = pats.reshape(M, -1) * refl.ravel()[None, :]
    lam = []
    for r in range(K):
        delay = np.rint(2 * (depth.ravel() + r * move) / (C / BIT_RATE)).astype(int)
        amp = np.zeros((M, L))
        for d in np.unique(delay):
            amp[:, d % L] += w[:, delay == d].sum(axis=1)
        spectrum = np.fft.ifft(np.fft.fft(amp, axis=1) * np.fft.fft(code)[None, :],
                               axis=1).real
        lam.append(np.clip(DWELL * (signal * spectrum + background), 0, None))
    return rng.poisson(np.array(lam)), pats, code, depth, rng


def _write(path, counts, pats, code, rng, order="repeated"):
    """``repeated``: K x M blocks, block r M + i showing pattern i over DWELL periods;
    ``merged``: M blocks of K x DWELL periods, each holding its pattern's K repeats' photons
    (the same photons, the same histograms); K is ``counts``' first axis."""
    syncs, dtimes, marks = [], [], []
    k = counts.shape[0]
    for r in range(k):
        for i in range(M):
            start = (r * M + i) * DWELL if order == "repeated" else (i * k + r) * DWELL
            t = np.repeat(np.arange(L), counts[r, i])
            s = start + rng.integers(0, DWELL, t.size)
            if order == "repeated" or r == 0:
                syncs.append(np.array([start]))
                dtimes.append(np.zeros(1, int))
                marks.append(np.ones(1, bool))
            syncs.append(s)
            dtimes.append(t)
            marks.append(np.zeros(t.size, bool))
    sync, dtime, mark = (np.concatenate(a) for a in (syncs, dtimes, marks))
    order_ = np.lexsort((~mark, sync))  # time order, a block's marker before its photons
    write_picoharp_t3(path / f"{order}.ptu", sync[order_], dtime[order_], mark[order_],
                      1 / BIT_RATE, BIT_RATE / L)
    np.save(path / "patterns.npy", pats)
    np.save(path / "code.npy", code.astype(np.uint8))


def _passes(path, counts, pats, code, rng):
    """Each repeat of ``counts`` written as a file of its own (``path/passR/once.ptu``, with
    the patterns and code beside it): an acquisition saved one file a pass. Their paths."""
    names = []
    for r in range(counts.shape[0]):
        d = path / f"pass{r}"
        d.mkdir()
        _write(d, counts[r:r + 1], pats, code, rng, "once")
        names.append(str(d / "once.ptu"))
    return names


def _reconstruct(path, name, capsys, *extra, out=None):
    out = path / f"rec_{name}" if out is None else out
    rc = main(["reconstruct", "--ptu", str(path / f"{name}.ptu"), "--patterns",
               str(path / "patterns.npy"), "--code", str(path / "code.npy"), "--bit-rate",
               "10e9", "--range-gate", "2.5", "4", "--out", str(out), "--no-figure", *extra])
    err = capsys.readouterr().err
    if rc:
        return rc, None, None, err
    return rc, json.loads((out / "metrics.json").read_text()), np.load(out / "depth.npy"), err


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    path = tmp_path_factory.mktemp("repeats")
    counts, pats, code, depth, rng = _counts(0)
    _write(path, counts, pats, code, rng, "repeated")
    _write(path, counts, pats, code, rng, "merged")
    _write(path, counts[:1], pats, code, rng, "once")
    return path, depth


def test_a_repeated_sequence_is_refused_without_repeats_and_named(files, capsys):
    """K x M blocks for M rows: refused in one line that names the repeats and the flag."""
    path, _ = files
    rc, _, _, err = _reconstruct(path, "repeated", capsys)
    assert rc == 2
    assert f"has {K * M} marker-delimited blocks but --patterns has {M} rows" in err
    assert f"the sequence shown {K} times in a row? pass --repeats {K}" in err
    assert "Traceback" not in err


def test_repeats_sums_each_patterns_blocks(files, capsys):
    """The repeated file with --repeats K reconstructs exactly as the same photons written as
    one block per pattern of K times the dwell: the summed histograms and dwells are the same
    integers (exact in float64), so the depth maps are equal, not merely close."""
    path, truth = files
    rc, rep, depth_rep, err = _reconstruct(path, "repeated", capsys, "--repeats", str(K))
    assert rc == 0, err
    rc, one, depth_one, _ = _reconstruct(path, "merged", capsys)
    assert rc == 0
    assert rep["ptu"]["repeats"] == K and one["ptu"]["repeats"] == 1
    assert rep["ptu"]["n_patterns_solved"] == M
    assert rep["ptu"]["counts_per_pattern"] == one["ptu"]["counts_per_pattern"]
    assert rep["ptu"]["periods_per_pattern"] == one["ptu"]["periods_per_pattern"]
    assert rep["ptu"]["blocks_left_out"] == []
    np.testing.assert_array_equal(depth_rep, depth_one)
    # and the repeats' photons count: the map beats the first repeat's alone
    rc, _, depth_once, _ = _reconstruct(path, "once", capsys)
    assert rc == 0
    rmse = [float(np.sqrt(np.nanmean((d - truth) ** 2))) for d in (depth_rep, depth_once)]
    assert rmse[0] < 0.8 * rmse[1]


def test_a_dropout_in_one_repeat_leaves_that_block_out_only(tmp_path, capsys):
    """A detector shutdown over 20 blocks of the second repeat: those blocks are left out
    (numbered through the repeats) and their patterns keep their other repeats' photons and
    dwells, so every pattern is still solved."""
    counts, pats, code, truth, rng = _counts(1)
    counts[1, 30:50] = 0
    _write(tmp_path, counts, pats, code, rng, "repeated")
    rc, m, depth, err = _reconstruct(tmp_path, "repeated", capsys, "--repeats", str(K))
    assert rc == 0, err
    assert m["ptu"]["blocks_left_out"] == list(range(M + 30, M + 50))
    assert m["ptu"]["n_patterns_solved"] == M and m["ptu"]["patterns_solved"] == list(range(M))
    periods = np.array(m["ptu"]["periods_per_pattern"])
    assert np.all(periods[30:50] == (K - 1) * DWELL)
    assert np.all(np.delete(periods, np.arange(30, 50)) == K * DWELL)
    assert m["ptu"]["counts_per_pattern"][30:50] == counts[[0, 2], 30:50].sum(axis=(0, 2)).tolist()
    assert float(np.sqrt(np.nanmean((depth - truth) ** 2))) < 0.15


@pytest.mark.parametrize("value", [0, -2, 1.5, True, "3", float("nan")])
def test_check_repeats_refuses_what_is_no_count(value):
    with pytest.raises(Exception, match="--repeats must be a whole number"):
        check_repeats(value)
    assert check_repeats(3) == 3 and check_repeats(np.int64(2)) == 2 and check_repeats(4.0) == 4


def test_bad_repeats_on_the_command_line_is_one_line(files, capsys, tmp_path):
    path, _ = files
    out = tmp_path / "rec"
    rc, _, _, err = _reconstruct(path, "repeated", capsys, "--repeats", "0", out=out)
    assert rc == 2 and "--repeats must be a whole number" in err and "Traceback" not in err
    assert not out.exists()  # (nothing written)
    # more repeats than the file holds: the reader's refusal, one line
    rc, _, _, err = _reconstruct(path, "repeated", capsys, "--repeats", str(K + 1), out=out)
    assert rc == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert f"fewer than the {(K + 1) * M} patterns (--repeats {K + 1}: {M} pattern rows " \
           f"shown {K + 1} times)" in err
    assert not out.exists()


def test_fold_repeats_sums_per_pattern():
    pattern = np.array([0, 1, 2, 0, 2])
    hist = np.arange(10.0).reshape(5, 2)
    shown, h, p, nt, c = fold_repeats(pattern, hist, np.array([5, 5, 5, 4, 5]), None,
                                      np.array([1, 2, 3, 4, 5]))
    assert shown.tolist() == [0, 1, 2] and nt is None
    assert h.tolist() == [[6.0, 8.0], [2.0, 3.0], [12.0, 14.0]]
    assert p.tolist() == [9, 5, 10] and c.tolist() == [5, 2, 8]


def test_calibrate_takes_repeats(files, capsys, tmp_path):
    """calibrate reads every block of a repeated file (its response from all the photons)."""
    path, _ = files
    out = tmp_path / "cal.json"
    args = ["calibrate", "--ptu", str(path / "repeated.ptu"), "--patterns",
            str(path / "patterns.npy"), "--code", str(path / "code.npy"), "--bit-rate", "10e9",
            "--distance", "3.6", "--out", str(out)]
    assert main(args) == 2
    assert f"pass --repeats {K}" in capsys.readouterr().err
    assert main([*args, "--repeats", str(K)]) == 0
    cal = json.loads(out.read_text())
    assert cal["measured_from"]["repeats"] == K
    assert cal["measured_from"]["patterns"] == M  # (each pattern's blocks summed)


def test_reconstruct_ptu_api_takes_repeats(files):
    path, _ = files
    r = reconstruct_ptu(path / "repeated.ptu", np.load(path / "patterns.npy"),
                        np.load(path / "code.npy"), 10e9, (2.5, 4.0), repeats=K)
    assert r.metrics["ptu"]["repeats"] == K
    assert r.metrics["ptu"]["n_patterns_solved"] == M



def test_pixels_no_pattern_lights_have_no_depth(tmp_path, capsys):
    """A DMD region padded to a square (or a round aperture): pixels whose mirror is 0 in
    every pattern were measured by nothing, but the solve's prior filled them in and they got
    confident depths, with "returns in 100% of pixels" (an outside lab audit of 2026-11-30).
    Now they are NaN, with confidence 0 and no reflectivity, and said; the lit ones are as
    good as before."""
    mask = np.ones((N, N), np.float32)
    mask[:, 12:] = 0.0  # four columns never lit
    counts, pats, code, depth, rng = _counts(2, mask=mask)
    _write(tmp_path, counts[:1], pats, code, rng, "once")
    rc, m, est, err = _reconstruct(tmp_path, "once", capsys)
    assert rc == 0, err
    assert "64 of the 256 pixels are lit by no pattern" in err
    assert np.isnan(est[:, 12:]).all() and np.isfinite(est[:, :12]).mean() > 0.9
    conf = np.load(tmp_path / "rec_once" / "confidence.npy")
    refl = np.load(tmp_path / "rec_once" / "reflectivity.npy")
    assert (conf[:, 12:] == 0).all() and np.isnan(refl[:, 12:]).all()
    # (refitted with the depth held, the unlit pixels left out of its TV)
    assert m["reflectivity_method"]["method"] == "refit"
    assert np.isfinite(refl[:, :12][np.isfinite(est[:, :12])]).all()
    assert m["coverage"] <= 0.75
    # the lit pixels keep the map (the rule changes no solve): most within 5 cm
    assert float(np.mean(np.abs(est[:, :12] - depth[:, :12]) < 0.05)) > 0.8


def test_frame_reads_one_repeat_of_a_moving_scene(tmp_path, capsys):
    """A video: the scene 10 cm farther at each of the K repeats. Summed, the map lies
    between them; --frame I reads repeat I alone, the scene where it was then (an outside
    lab audit of 2026-11-30: no way to get a frame but to split the file by hand)."""
    counts, pats, code, depth, rng = _counts(5, signal=6e-4, move=0.1)
    _write(tmp_path, counts, pats, code, rng, "repeated")
    bias = {}
    for frame in (None, 0, 2):
        extra = () if frame is None else ("--frame", str(frame))
        rc, m, est, err = _reconstruct(tmp_path, "repeated", capsys, "--repeats", str(K),
                                       *extra, out=tmp_path / f"f{frame}")
        assert rc == 0, err
        assert m["ptu"]["frame"] == frame
        bias[frame] = float(np.nanmedian(est - depth))
        # (the figure's title says which: a frame's read as the whole acquisition's)
        from types import SimpleNamespace

        from spslidar.config import Config
        from spslidar.figures import _title

        title = _title(SimpleNamespace(config=Config(), metrics=m))
        assert (f"{M} patterns (shown {K} times, summed)" if frame is None else
                f"{M} patterns (repeat {frame} of {K})") in title
        # (summed, the motion reads as a drift, and the warning names the frames; a frame's
        # map is read with its own blocks' drift, none: a review found the repeats' motion
        # said as a blur of the frame's map)
        assert ("a scene that moves between the repeats reads as the drift above; --frame I"
                in err) == (frame is None)
        assert ("a timing drift" in err) == (frame is None)
        if frame is not None:
            assert abs(m["ptu"]["timing_drift_bins"]) < 0.5
        if frame is not None:
            assert m["ptu"]["n_patterns_solved"] == M and m["ptu"]["blocks_left_out"] == []
            assert m["ptu"]["periods_per_pattern"] == [DWELL] * M
    assert abs(bias[0]) < 0.02 and abs(bias[2] - 0.2) < 0.02  # (each frame's own scene)
    assert 0.05 < bias[None] < 0.15  # (summed: in between)


@pytest.mark.parametrize("args,says", [
    (("--frame", "1"), "--frame reads one repeat of a sequence shown several times: give "
                       "--repeats K"),
    (("--repeats", "3", "--frame", "3"), "--frame must be a repeat of the sequence read, 0 to 2"),
    (("--repeats", "3", "--frame", "-1"), "--frame must be a repeat of the sequence read, 0 to 2")])
def test_a_frame_outside_the_repeats_is_one_line(files, capsys, tmp_path, args, says):
    path, _ = files
    out = tmp_path / "rec"
    rc, _, _, err = _reconstruct(path, "repeated", capsys, *args, out=out)
    assert rc == 2 and says in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_the_wrong_repeats_is_named_with_the_rows_given(files, capsys, tmp_path):
    """A file of 3 repeats read with --repeats 2 was told of "192 rows" (the blocks) and to
    pass --repeats 2, what it had passed (a review); and the repeats' word went onto every
    refusal of the reader, a bad --sync-divider's too."""
    path, _ = files
    rc, _, _, err = _reconstruct(path, "repeated", capsys, "--repeats", "2",
                                 out=tmp_path / "a")
    assert rc == 2
    assert (f"has {K * M} marker-delimited blocks but --patterns has {M} rows shown 2 times "
            f"({2 * M} blocks)") in err and f"pass --repeats {K}" in err
    rc, _, _, err = _reconstruct(path, "repeated", capsys, "--repeats", str(K),
                                 "--sync-divider", "0", out=tmp_path / "b")
    assert rc == 2 and "--sync-divider must be a whole number" in err
    assert "pattern rows shown" not in err


def test_a_frame_whose_blocks_were_all_left_out_is_one_line(tmp_path, capsys):
    """A repeat in which the detector was off throughout: --frame of it ended in "Mean of
    empty slice" and "gain must be a positive number, got nan" (a review)."""
    counts, pats, code, _, rng = _counts(6)
    counts[1] = 0
    _write(tmp_path, counts, pats, code, rng, "repeated")
    rc, _, _, err = _reconstruct(tmp_path, "repeated", capsys, "--repeats", str(K), "--frame",
                                 "1", out=tmp_path / "f1")
    assert rc == 2 and "every block of --frame 1 was left out" in err
    assert "Traceback" not in err and "Mean of empty slice" not in err
    assert not (tmp_path / "f1").exists()
    rc, m, _, err = _reconstruct(tmp_path, "repeated", capsys, "--repeats", str(K), "--frame",
                                 "0", out=tmp_path / "f0")
    assert rc == 0 and m["ptu"]["n_patterns_solved"] == M


def test_an_acquisition_saved_one_file_a_pass_is_read_as_one(files, tmp_path, capsys):
    """A lab that saves each pass of the sequence to its own file: ``--ptu A B C`` sums them
    as ``--repeats`` sums the passes of one file (the same integer histograms, so the same
    map), ``--frame`` counts the passes through the files, and a repeated ``--ptu`` adds
    its file (it kept the last alone, without a word: an outside lab audit of 2026-11-30)."""
    path, _ = files
    counts, pats, code, _, rng = _counts(0)  # (the module's repeated file's own counts)
    names = _passes(tmp_path, counts, pats, code, rng)
    rc, one, depth_one, err = _reconstruct(path, "repeated", capsys, "--repeats", str(K),
                                           out=tmp_path / "one")
    assert rc == 0, err
    base = ["reconstruct", "--patterns", str(path / "patterns.npy"), "--code",
            str(path / "code.npy"), "--bit-rate", "10e9", "--range-gate", "2.5", "4",
            "--no-figure"]
    # (with its figure: the title read the file list as a path, a traceback at the end)
    assert main([*(a for a in base if a != "--no-figure"), "--ptu", *names, "--out",
                 str(tmp_path / "many")]) == 0
    assert (tmp_path / "many" / "depth.png").exists()
    capsys.readouterr()
    many = json.loads((tmp_path / "many" / "metrics.json").read_text())
    np.testing.assert_array_equal(np.load(tmp_path / "many" / "depth.npy"), depth_one)
    assert many["ptu"]["file"] == names and many["ptu"]["n_photons"] == one["ptu"]["n_photons"]
    assert many["ptu"]["counts_per_pattern"] == one["ptu"]["counts_per_pattern"]
    # --frame 1 of the files is the second file alone; a repeated --ptu adds its file
    assert main([*base, "--ptu", names[0], "--ptu", names[1], "--ptu", names[2], "--frame",
                 "1", "--out", str(tmp_path / "f1")]) == 0
    assert main([*base, "--ptu", names[1], "--out", str(tmp_path / "b")]) == 0
    capsys.readouterr()
    np.testing.assert_array_equal(np.load(tmp_path / "f1" / "depth.npy"),
                                  np.load(tmp_path / "b" / "depth.npy"))
    # calibrate reads one file: two are one line, nothing written
    out = tmp_path / "cal.json"
    assert main(["calibrate", "--ptu", names[0], "--ptu", names[1], "--patterns",
                 str(path / "patterns.npy"), "--code", str(path / "code.npy"), "--bit-rate",
                 "10e9", "--distance", "3.6", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "calibrate reads one PTU file, got 2" in err[0]
    assert not out.exists()


def test_a_list_of_no_files_is_refused():
    with pytest.raises(Exception, match=r"ptu must be the path of a PTU file \(or a list of "
                                        r"them\), got an empty list"):
        reconstruct_ptu([], np.ones((4, 4, 4)), np.ones(7), 10e9, (1.0, 2.0))


def test_a_file_given_twice_and_files_of_another_tdc_are_refused(files, tmp_path):
    """The same pass twice was summed with itself without a word, and a second file's TDC
    resolution taken for the first's (a review): both one line."""
    path, _ = files
    ptu = path / "repeated.ptu"
    args = (np.load(path / "patterns.npy"), np.load(path / "code.npy"), 10e9, (2.5, 4.0))
    with pytest.raises(Exception, match=r"is given twice \(as .* too\): each pass once"):
        reconstruct_ptu([ptu, str(ptu)], *args, repeats=K)
    with pytest.raises(Exception, match="calibrate reads one PTU file"):
        from spslidar.pipeline.calibration import calibrate_ptu

        calibrate_ptu([ptu], args[0], args[1], 10e9, 3.6)


def test_a_drift_across_the_files_is_said_and_a_frame_is_read_without_it(tmp_path, capsys):
    """A scene 10 cm farther at each pass, one file a pass: the drift across the files went
    unsaid while the next warning pointed at "the drift above", and a frame kept the files'
    own drift warnings (a review). Now the drift is read over the files and said; a frame
    says none."""
    counts, pats, code, _, rng = _counts(5, signal=6e-4, move=0.1)
    names = _passes(tmp_path, counts, pats, code, rng)
    base = ["reconstruct", "--patterns", str(tmp_path / "pass0" / "patterns.npy"), "--code",
            str(tmp_path / "pass0" / "code.npy"), "--bit-rate", "10e9", "--range-gate", "2.5",
            "4", "--no-figure", "--ptu", *names]
    assert main([*base, "--out", str(tmp_path / "all")]) == 0
    err = capsys.readouterr().err
    assert f"over the {K} files: the returns' delay moves by up to" in err
    assert "a scene that moves between the repeats reads as the drift above" in err
    assert main([*base, "--frame", "1", "--out", str(tmp_path / "f1")]) == 0
    err = capsys.readouterr().err
    assert "a timing drift" not in err and "moves between the repeats" not in err
