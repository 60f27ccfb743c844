"""A free-running DMD (``--first-pattern I``): the DMD loops its sequence while the time tagger
records from some moment on, so the file's first whole marker block shows pattern ``I``, and
the recording stops mid-sequence (``B`` blocks, no multiple of the ``M`` patterns). Block ``b``
shows pattern ``(I + b) mod M`` and each pattern's blocks are summed. Files written with the
project's own writer (``spslidar.io.write_ptu_t3``).
"""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
from test_screen_blocks import random_scan  # (tests/ is on sys.path under pytest)

from spslidar.cli import main
from spslidar.errors import ConfigError
from spslidar.io import write_ptu_t3
from spslidar.pipeline.free_run import (
    AUTO_MARGIN,
    block_numbers,
    check_first_pattern,
    find_first_pattern,
)

C = 299_792_458.0
BIT_RATE = 10e9
N, M, L, DWELL = 8, 64, 127, 400
_RUNS = itertools.count()  # (each run's own output, in a folder the module's tests share)


def _model(seed):
    """The patterns (M distinct random binary 8x8), a balanced random code, the truth and
    each pattern's photon rate per bin and code period (M, L)."""
    rng = np.random.default_rng(seed)
    depth = np.full((N, N), 1.5)
    depth[:, :3] = 1.0
    depth[2:6, 4:7] = 1.2
    refl = np.full((N, N), 0.8)
    code, pats, spectrum = random_scan(rng, M, depth, refl, L)
    return pats, code, depth, np.clip(5e-4 * spectrum + 1e-3, 0, None), rng


def _write(path, blocks, pre=None, rng=None, edge="start", end_marker=False):
    """Blocks of (photon counts per bin (L,), dwell in periods), each opened by a marker
    (``edge="end"``: closed by one, at its last sync after its photons), in the order given;
    ``pre``: the counts of a block cut by the recording (over DWELL // 2 periods), before
    the first marker (after the last under ``end``). The last block's last photon is at its
    last sync, so its dwell is the one given; ``end_marker``: a marker after it (an end of
    acquisition's)."""
    rng = np.random.default_rng(0) if rng is None else rng
    syncs, dtimes, marks = [], [], []
    start = 0

    def cut_block(begin):
        t = np.repeat(np.arange(L), pre)
        syncs.append(begin + rng.integers(0, DWELL // 2, t.size))
        dtimes.append(t)
        marks.append(np.zeros(t.size, int))
        return begin + DWELL // 2

    if pre is not None and edge == "start":
        start = cut_block(0)
    for k, (counts, dwell) in enumerate(blocks):
        t = np.repeat(np.arange(L), counts)
        s = start + rng.integers(0, dwell, t.size)
        if k == len(blocks) - 1 and s.size:
            s[0] = start + dwell - 1
        syncs += [np.array([start if edge == "start" else start + dwell - 1]), s]
        dtimes += [np.zeros(1, int), t]
        marks += [np.ones(1, int), np.zeros(t.size, int)]
        start += dwell
    if pre is not None and edge == "end":
        cut_block(start)
    if end_marker:
        syncs.append(np.array([start]))
        dtimes.append(np.zeros(1, int))
        marks.append(np.ones(1, int))
    sync, dtime, mark = (np.concatenate(a) for a in (syncs, dtimes, marks))
    # time order: a block's opening marker before its photons, a closing one after them
    order = np.lexsort((-mark if edge == "start" else mark, sync))
    write_ptu_t3(path, nsync=sync[order], dtime=dtime[order], marker=mark[order],
                 resolution_s=1 / BIT_RATE, sync_rate_hz=BIT_RATE / L)


def _free_run(path, seed, first, n_blocks, cut=0.3, **how):
    """A free-running acquisition (``path/free.ptu``): ``n_blocks`` blocks from pattern
    ``first`` on, the last lasting ``cut`` of a dwell, a cut block before the first marker;
    and the same photons written aligned (``path/aligned.ptu``): one block per pattern
    holding its blocks' photons over their summed dwells. The truth."""
    pats, code, depth, lam, rng = _model(seed)
    dwells = np.full(n_blocks, DWELL)
    dwells[-1] = int(cut * DWELL)
    shown = block_numbers(first, n_blocks, M)
    counts = rng.poisson(lam[shown] * dwells[:, None])
    if how.get("edge") == "end":  # (the first block is cut by the start, the last whole)
        dwells = dwells[::-1].copy()
        counts = rng.poisson(lam[shown] * dwells[:, None])
    _write(path / "free.ptu", list(zip(counts, dwells, strict=True)),
           pre=rng.poisson(lam[(first - 1) % M] * (DWELL // 2)), rng=rng, **how)
    _aligned(path, shown, counts, dwells, pats, code, rng)
    return depth


def _aligned(path, shown, counts, dwells, pats, code, rng) -> None:
    """The free-running blocks' photons written aligned (``path/aligned.ptu``): one block per
    pattern holding its blocks' photons over their summed dwells; the patterns and code."""
    summed = np.zeros((M, L), np.int64)
    total = np.zeros(M, np.int64)
    np.add.at(summed, shown, counts)
    np.add.at(total, shown, dwells)
    _write(path / "aligned.ptu", list(zip(summed, total, strict=True)), rng=rng)
    np.save(path / "patterns.npy", pats)
    np.save(path / "code.npy", code.astype(np.uint8))


def _cli(path, name, capsys, *extra, command="reconstruct"):
    tag = "_".join(a.strip("-") for a in extra).replace("/", "")[-40:] + f"_{next(_RUNS)}"
    out = path / f"out_{name}_{tag}"
    args = ["--ptu", str(path / f"{name}.ptu"), "--patterns", str(path / "patterns.npy"),
            "--code", str(path / "code.npy"), "--bit-rate", "10e9"]
    if command == "reconstruct":
        args = ["reconstruct", *args, "--range-gate", "0.7", "1.8", "--out", str(out),
                "--no-figure", *extra]
    else:
        out = path / f"cal_{name}_{tag}.json"
        args = ["calibrate", *args, "--distance", "1.5", "--out", str(out), *extra]
    try:
        rc = main(args)
    except SystemExit as exc:  # (argparse's own refusal: one line, exit 2)
        rc = exc.code
    err = capsys.readouterr().err
    if rc or command != "reconstruct":
        return rc, out, err
    return rc, (json.loads((out / "metrics.json").read_text()), np.load(out / "depth.npy")), err


@pytest.fixture(scope="module")
def cut(tmp_path_factory):
    """B = 2.3 M blocks from pattern 37, and the same photons aligned."""
    path = tmp_path_factory.mktemp("first_pattern")
    return path, _free_run(path, seed=1, first=37, n_blocks=int(2.3 * M))


def test_a_rotated_cut_acquisition_reads_as_its_aligned_photons(cut, capsys):
    """Rotated by I = 37 and cut at 2.3 passes (the last block 0.3 of a dwell, a block cut
    by the recording's start before the first marker): with --first-pattern 37 the depth map
    is the aligned file's, bit for bit (each pattern's photons and dwell are the same
    integers, summed), and it is a depth map (the truth within a few cm)."""
    path, truth = cut
    rc, (free, depth), err = _cli(path, "free", capsys, "--first-pattern", "37")
    assert rc == 0, err
    rc, (aligned, depth_aligned), err_aligned = _cli(path, "aligned", capsys)
    assert rc == 0, err_aligned
    np.testing.assert_array_equal(depth, depth_aligned)
    assert np.nanmedian(np.abs(depth - truth)) < 0.03
    ptu = free["ptu"]
    assert ptu["first_pattern"] == 37 and aligned["ptu"]["first_pattern"] is None
    assert ptu["patterns_solved"] == list(range(M))
    assert ptu["counts_per_pattern"] == aligned["ptu"]["counts_per_pattern"]
    assert ptu["periods_per_pattern"] == aligned["ptu"]["periods_per_pattern"]
    b = int(2.3 * M)  # blocks 0..B-1 show 37, 38, ... : pattern p has 2 or 3 blocks
    assert ptu["blocks_per_pattern"] == np.bincount(block_numbers(37, b, M)).tolist()
    assert aligned["ptu"]["blocks_per_pattern"] is None
    assert ptu["blocks_left_out"] == []
    assert ptu["n_dropped_before_first_marker"] > 0  # (the block cut by the start)
    # (without the flag the free-running file is refused, as before: its blocks match nothing)
    rc, _, err = _cli(path, "free", capsys)
    assert rc == 2 and f"has {b} marker-delimited blocks but --patterns has {M} rows" in err


def test_calibrate_reads_a_free_running_file_as_its_aligned_photons(cut, capsys):
    """calibrate --first-pattern: the same delay and response as the aligned file's."""
    path, _ = cut
    rc, out, err = _cli(path, "free", capsys, "--first-pattern", "37", command="calibrate")
    assert rc == 0, err
    rc, out_aligned, err = _cli(path, "aligned", capsys, command="calibrate")
    assert rc == 0, err
    cal, ref = (json.loads(p.read_text()) for p in (out, out_aligned))
    assert cal["measured_from"]["first_pattern"] == 37
    assert ref["measured_from"]["first_pattern"] is None
    assert cal["delay_s"] == ref["delay_s"] and cal["irf_values"] == ref["irf_values"]
    assert cal["target"] == ref["target"] and cal["measured_from"]["patterns"] == M


def test_warnings_and_patterns_solved_are_in_patterns_numbering(tmp_path, capsys):
    """One pass from pattern 5 (B = M), block 10 a dropout (no photon over a whole dwell)
    and the last block cut to 0.3 of a dwell: the dropout is said as pattern 15 (block 10 in
    blocks_left_out), the short dwell as pattern 4, and pattern 15 is the one not solved."""
    pats, code, _, lam, rng = _model(2)
    dwells = np.full(M, DWELL)
    dwells[-1] = int(0.3 * DWELL)
    shown = block_numbers(5, M, M)
    counts = rng.poisson(lam[shown] * dwells[:, None])
    counts[10] = 0
    _write(tmp_path / "free.ptu", list(zip(counts, dwells, strict=True)), rng=rng)
    np.save(tmp_path / "patterns.npy", pats)
    np.save(tmp_path / "code.npy", code.astype(np.uint8))
    rc, (metrics, _), err = _cli(tmp_path, "free", capsys, "--first-pattern", "5")
    assert rc == 0, err
    ptu = metrics["ptu"]
    assert ptu["patterns_solved"] == [p for p in range(M) if p != 15]
    assert ptu["blocks_left_out"] == [10]
    assert ptu["blocks_per_pattern"] == [0 if p == 15 else 1 for p in range(M)]
    said = " ".join(metrics["warnings"])
    assert "pattern 15" in said and "pattern 10" not in said
    assert "1 pattern(s) (first: 4) have less than half the median dwell" in said


@pytest.mark.parametrize("how", [{"edge": "end"}, {"end_marker": True}])
def test_marker_edge_end_and_an_end_marker(tmp_path, capsys, how):
    """Markers that end their patterns (--marker-edge end): block 0 is the one the first
    marker ends, cut by the recording's start, and it shows I; the photons after the last
    marker are left out. An end-of-acquisition marker after a cut last block: its empty
    block is left out. Either reads as the same photons aligned, bit for bit."""
    _free_run(tmp_path, seed=4, first=9, n_blocks=int(1.6 * M), **how)
    extra = ("--marker-edge", "end") if how.get("edge") else ()
    rc, (free, depth), err = _cli(tmp_path, "free", capsys, "--first-pattern", "9", *extra)
    assert rc == 0, err
    rc, (aligned, depth_aligned), err = _cli(tmp_path, "aligned", capsys)
    assert rc == 0, err
    np.testing.assert_array_equal(depth, depth_aligned)
    assert free["ptu"]["periods_per_pattern"] == aligned["ptu"]["periods_per_pattern"]
    assert free["ptu"]["patterns_solved"] == list(range(M))
    if how.get("end_marker"):
        assert free["ptu"]["blocks_left_out"] == [int(1.6 * M)]
        said = f"the last of the {int(1.6 * M) + 1} marker blocks holds no photons"
        assert any(w.startswith(said) and w.endswith("it is left out")
                   for w in free["warnings"])
    else:
        assert free["ptu"]["n_dropped_after_last_pattern"] > 0


def _refused(capsys, path, *argv, command="reconstruct"):
    rc, out, err = _cli(path, "free", capsys, *argv, command=command)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1, err
    assert not out.exists()
    return lines[0]


_BAD = [
    (["--first-pattern", "-1"], "--first-pattern must be a row of --patterns, 0 to 63"),
    (["--first-pattern", "64"], "--first-pattern must be a row of --patterns, 0 to 63"),
    (["--first-pattern", "2.5"], "a whole number (a --patterns row) or auto, got '2.5'"),
    (["--first-pattern", "3", "--repeats", "2"], "leave --repeats out"),
]


@pytest.mark.parametrize("command, argv, said", [
    *[("reconstruct", a, s) for a, s in _BAD], *[("calibrate", a, s) for a, s in _BAD],
    ("reconstruct", ["--first-pattern", "3", "--frame", "0"], "is summed over every pass"),
])
def test_bad_first_patterns_are_refused_in_one_line(cut, capsys, command, argv, said):
    """Exit 2, one line on stderr, nothing written."""
    path, _ = cut
    assert said in _refused(capsys, path, *argv, command=command)


def _free_file(folder, seed: int, counts_of) -> None:
    """``free.ptu`` of the blocks ``counts_of(lam, rng)`` gives (one a row, each DWELL
    periods long), with the patterns and code of ``_model(seed)`` beside it."""
    pats, code, _, lam, rng = _model(seed)
    _write(folder / "free.ptu", [(c, DWELL) for c in counts_of(lam, rng)], rng=rng)
    np.save(folder / "patterns.npy", pats)
    np.save(folder / "code.npy", code.astype(np.uint8))


def test_several_files_and_too_few_blocks_are_refused(cut, tmp_path, capsys):
    """Several --ptu files with it: one line; fewer blocks than patterns: one line saying
    how many were found."""
    path, _ = cut
    line = _refused(capsys, path, "--first-pattern", "3", "--ptu", str(path / "aligned.ptu"))
    assert "--first-pattern reads one PTU file" in line
    _free_file(tmp_path, 3, lambda lam, rng: rng.poisson(lam[:40] * DWELL))
    for command in ("reconstruct", "calibrate"):
        line = _refused(capsys, tmp_path, "--first-pattern", "0", command=command)
        assert "has 40 marker-delimited blocks on input 1, fewer than the 64 rows" in line


def test_check_first_pattern_refuses_what_is_no_row():
    """The API's check: not a bool or text, a whole number, a row; None stays None."""
    assert check_first_pattern(None, 4) is None
    assert check_first_pattern(np.int64(3), 4) == 3 and check_first_pattern(2.0, 4) == 2
    assert check_first_pattern("auto", 4) == "auto"
    for bad in (True, "1", "Auto", 1.5, float("nan"), -1, 4, np.array([1, 2])):
        with pytest.raises(Exception, match="--first-pattern must be"):
            check_first_pattern(bad, 4)


def test_auto_finds_the_first_pattern_and_says_its_margin(cut, capsys):
    """--first-pattern auto on the rotated, cut file: pattern 37, said with its margin over
    the runner-up, and the map the explicit --first-pattern 37 gives."""
    path, _ = cut
    rc, (found, depth), err = _cli(path, "free", capsys, "--first-pattern", "auto")
    assert rc == 0, err
    rc, (given, depth_given), err = _cli(path, "free", capsys, "--first-pattern", "37")
    assert rc == 0, err
    np.testing.assert_array_equal(depth, depth_given)
    assert found["ptu"]["first_pattern"] == 37 and found["ptu"]["first_pattern_found"]
    assert given["ptu"]["first_pattern_found"] is False
    said = [w for w in found["warnings"] if w.startswith("--first-pattern auto: the file's "
                                                         "first block shows pattern 37")]
    assert len(said) == 1 and f"{AUTO_MARGIN:g} needed" in said[0]
    rc, out, err = _cli(path, "free", capsys, "--first-pattern", "auto", command="calibrate")
    assert rc == 0, err
    assert json.loads(out.read_text())["measured_from"]["first_pattern"] == 37


def test_auto_refuses_where_it_cannot_tell(tmp_path, capsys):
    """A file of background alone (no return to place the patterns by): every offset fits
    as well, and auto is refused in one line that asks for the number; as with --repeats."""
    _free_file(tmp_path, 5, lambda lam, rng: rng.poisson(np.full((M + 20, L), 0.4)))
    for command in ("reconstruct", "calibrate"):
        line = _refused(capsys, tmp_path, "--first-pattern", "auto", command=command)
        assert "--first-pattern auto cannot tell which of the 64 patterns" in line
        assert "give the number, --first-pattern I" in line
    line = _refused(capsys, tmp_path, "--first-pattern", "auto", "--repeats", "2")
    assert "leave --repeats out" in line
    line = _refused(capsys, tmp_path, "--first-pattern", "first")
    assert "a whole number (a --patterns row) or auto, got 'first'" in line


def test_auto_refuses_patterns_too_large_for_its_fit():
    """Over AUTO_MAX pixels: refused before any fit (a dense (Q, Q) solve)."""
    with pytest.raises(ConfigError, match="auto reads at most 4096 patterns"):
        find_first_pattern(np.ones((3, 7)), np.ones(3), np.ones((2, 65 * 65)), np.ones(7))


@pytest.mark.parametrize("lead", ["arming", "bounce"])
def test_a_short_first_block_takes_no_pattern_number(tmp_path, capsys, lead):
    """An arming marker 5 periods before the sequence (no photon), or the first marker's
    bounce 2 periods after it (8 of its pattern's photons), made a short block 0 that took
    pattern I, every block after it reading its neighbour's pattern, with exit 0 (an outside
    audit of stop 67: median error 0.15 m against 0.037): it is left out and said, and the
    map is the aligned photons' (exactly where the block held none); auto finds 37 too."""
    pats, code, depth, lam, rng = _model(1)
    n = int(2.3 * M)
    dwells = np.full(n, DWELL)
    shown = block_numbers(37, n, M)
    counts = rng.poisson(lam[shown] * dwells[:, None])
    short = np.zeros(L, np.int64)
    if lead == "bounce":
        short[rng.integers(0, L, 8)] += 1
    _write(tmp_path / "free.ptu", [(short, 5 if lead == "arming" else 2)]
           + list(zip(counts, dwells, strict=True)), rng=rng)
    _aligned(tmp_path, shown, counts, dwells, pats, code, rng)
    rc, (free, got), err = _cli(tmp_path, "free", capsys, "--first-pattern", "37")
    assert rc == 0, err
    assert "the first 1 marker block(s) on input 1 last under half a pattern's dwell" in err
    rc, (_, want), err = _cli(tmp_path, "aligned", capsys)
    assert rc == 0, err
    if lead == "arming":
        np.testing.assert_array_equal(got, want)
    else:  # (the bounce's 8 photons left out of pattern 37's thousands)
        assert np.nanmedian(np.abs(got - want)) < 1e-3
    assert np.nanmedian(np.abs(got - depth)) < 0.03
    rc, (found, _), err = _cli(tmp_path, "free", capsys, "--first-pattern", "auto")
    assert rc == 0, err
    assert found["ptu"]["first_pattern"] == 37


def test_a_wrong_first_pattern_given_is_said(cut, capsys):
    """--first-pattern 36 / 38 / 0 on the file that starts at 37 were read with exit 0 and
    no word (median errors 0.15-0.94 m: an audit of stop 67): where another offset fits the
    data better by the auto threshold, a warning names it; the right one says nothing."""
    path, _ = cut
    for wrong in (36, 38, 0):
        rc, (metrics, _), err = _cli(path, "free", capsys, "--first-pattern", str(wrong))
        assert rc == 0, err
        said = [w for w in metrics["warnings"] if w.startswith(f"--first-pattern {wrong}: the "
                                                               f"data fit pattern 37")]
        assert len(said) == 1, metrics["warnings"]
    rc, (metrics, _), err = _cli(path, "free", capsys, "--first-pattern", "37")
    assert rc == 0 and not any("the data fit pattern" in w for w in metrics["warnings"])
