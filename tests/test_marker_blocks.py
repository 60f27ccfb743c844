"""A file's marker blocks against the patterns, as labs' hardware writes them (an outside
audit of 2026-11-29 with its own PTU writer): a DMD whose marker ends each pattern, an arming
marker before the first pattern, an end-of-acquisition marker after the last, photons past
the code period. Read wrongly, every pattern was paired with its neighbour's photons (median
error 0.25 m against 2 mm) and nothing was said."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.errors import ConfigError
from spslidar.io import read_ptu_histograms, write_ptu_t3
from spslidar.pipeline.blocks import read_blocks

L, M, DWELL, PER = 31, 6, 200, 400  # bins, patterns, syncs per pattern, photons per pattern
RES = 1e-10


def _events(rng, start_syncs, marker_syncs, extra=()):
    """Pattern k's photons in syncs ``start_syncs[k] .. + DWELL - 1``, all in bin ``k + 3``
    (so a row's pattern is its peak bin), markers at ``marker_syncs``; ``extra``: more
    (sync, dtime) photons. Returns time-ordered (nsync, dtime, marker): a marker sorts before
    the photons of its own sync."""
    ev = []
    for k, s0 in enumerate(start_syncs):
        syncs = np.sort(rng.integers(s0, s0 + DWELL, PER))
        ev += [(int(s), 1, k + 3, 0) for s in syncs]
    ev += [(int(s), 0, 0, 1) for s in marker_syncs]
    ev += [(int(s), 1, int(d), 0) for s, d in extra]
    ev.sort()
    a = np.array(ev)
    return a[:, 0], a[:, 2], a[:, 3]


def _write(path, nsync, dtime, marker, **tags):
    write_ptu_t3(path, nsync=nsync, dtime=dtime, marker=marker, resolution_s=RES,
                 sync_rate_hz=1 / (L * RES), extra_tags=tags or None)
    return path


def _peaks(data):
    return list(np.argmax(data.histograms, axis=1) - 3)


def test_markers_that_start_their_patterns_read_as_before(tmp_path):
    rng = np.random.default_rng(0)
    starts = [DWELL * k for k in range(M)]
    f = _write(tmp_path / "a.ptu", *_events(rng, starts, starts))
    data, notes = read_blocks(f, M, L, bin_width=RES)
    assert _peaks(data) == list(range(M)) and notes == []
    assert data.n_dropped_before_first_marker == 0


def test_a_marker_that_ends_its_pattern_is_said_and_read_with_marker_edge_end(tmp_path):
    """Markers at each pattern's last sync: read as starts, pattern k got pattern k + 1's
    photons (pattern 0's dropped, 1/M of the file, under the 5 % that is said) and the only
    warning was about an empty last block."""
    rng = np.random.default_rng(1)
    starts = [DWELL * k for k in range(M)]
    ends = [s + DWELL - 1 for s in starts]
    nsync, dtime, marker = _events(rng, starts, ends)
    order = np.lexsort((marker, nsync))  # a pattern's last photons before its marker
    f = _write(tmp_path / "e.ptu", nsync[order], dtime[order], marker[order])
    data, notes = read_blocks(f, M, L, bin_width=RES)
    assert _peaks(data)[:M - 1] == list(range(1, M))  # misread, as before: but now said
    assert any("--marker-edge end" in n for n in notes), notes
    data, notes = read_blocks(f, M, L, bin_width=RES, marker_edge="end")
    assert _peaks(data) == list(range(M))
    assert not any("--marker-edge" in n for n in notes), notes
    assert data.counts_per_pattern.sum() == M * PER  # nothing dropped
    assert list(data.periods_per_pattern) == [DWELL] * M
    # and a file whose markers start their patterns, read with "end", is said the other way
    g = _write(tmp_path / "s.ptu", *_events(rng, starts, starts))
    _, notes = read_blocks(g, M, L, bin_width=RES, marker_edge="end")
    assert any("--marker-edge start" in n for n in notes), notes
    # with a settling time too: the checks read the markers' spacing, not the exposure
    # (a --settle of 5 periods hid both words: a review of 2026-11-30)
    _, notes = read_blocks(f, M, L, bin_width=RES, settle=5.5 * L * RES)
    assert any("--marker-edge end" in n for n in notes), notes
    _, notes = read_blocks(g, M, L, bin_width=RES, marker_edge="end", settle=5.5 * L * RES)
    assert any("--marker-edge start" in n for n in notes), notes


def test_an_arming_marker_before_the_first_pattern_is_left_out(tmp_path):
    """A marker at sync 0 and the patterns from sync 5: M + 1 blocks were read as patterns
    0..M-1 (the 5-sync block scaled up as pattern 0) and the warning pointed at the file's
    end ("is a row missing from --patterns?")."""
    rng = np.random.default_rng(2)
    starts = [5 + DWELL * k for k in range(M)]
    f = _write(tmp_path / "arm.ptu", *_events(rng, starts, [0, *starts]))
    data, notes = read_blocks(f, M, L, bin_width=RES)
    assert _peaks(data) == list(range(M)) and data.n_patterns == M
    assert len(notes) == 1 and "first block (5 code periods, 0 photons)" in notes[0], notes
    assert "arming" in notes[0]


def test_one_block_after_the_patterns_is_left_out(tmp_path):
    """An end-of-acquisition marker is left out without a word; a last block as long as a
    pattern is left out and said (a row missing from --patterns?)."""
    rng = np.random.default_rng(3)
    starts = [DWELL * k for k in range(M)]
    f = _write(tmp_path / "end.ptu", *_events(rng, starts, [*starts, DWELL * M]))
    data, notes = read_blocks(f, M, L, bin_width=RES)
    assert _peaks(data) == list(range(M)) and notes == []
    g = _write(tmp_path / "more.ptu", *_events(rng, [*starts, DWELL * M], [*starts, DWELL * M]))
    data, notes = read_blocks(g, M, L, bin_width=RES)
    assert _peaks(data) == list(range(M)) and data.n_dropped_after_last_pattern == PER
    assert len(notes) == 1 and "is a row missing from --patterns?" in notes[0]
    # an end marker that bounced twice (refused before bounces were merged)
    h = _write(tmp_path / "many.ptu",
               *_events(rng, starts, [*starts, DWELL * M, DWELL * M + 1, DWELL * M + 2]))
    data, notes = read_blocks(h, M, L, bin_width=RES)
    assert _peaks(data) == list(range(M)) and any("bounce" in n for n in notes)
    # (said as markers after the last pattern, not as a bounce merged into "the same
    # pattern's" block, which an outside audit of 2026-11-30 found)
    assert len(notes) == 1 and "(block 6, 7) come after the last pattern" in notes[0]
    assert "the same pattern's" not in notes[0]
    far = _write(tmp_path / "far.ptu", *_events(rng, starts, [*starts, DWELL * M,
                                                              DWELL * M + 60, DWELL * M + 90]))
    with pytest.raises(ConfigError, match="9 marker-delimited blocks but --patterns has 6"):
        read_blocks(far, M, L, bin_width=RES)
    # M + 2 blocks: an arming and an end marker are both left out (they were refused); two
    # blocks as long as patterns are a mismatch
    both = [5 + DWELL * k for k in range(M)]
    g2 = _write(tmp_path / "both.ptu", *_events(rng, both, [0, *both, 5 + DWELL * M]))
    data, notes = read_blocks(g2, M, L, bin_width=RES)
    assert _peaks(data) == list(range(M)) and data.n_patterns == M
    assert len(notes) == 1 and "an arming and an end marker? both are left out" in notes[0]
    two = _write(tmp_path / "two.ptu", *_events(rng, [*starts, DWELL * M, DWELL * (M + 1)],
                                                 [*starts, DWELL * M, DWELL * (M + 1)]))
    with pytest.raises(ConfigError, match="8 marker-delimited blocks but --patterns has 6 "
                                          "rows, and its first and last blocks are not both"):
        read_blocks(two, M, L, bin_width=RES)
    with pytest.raises(ConfigError, match="7 marker-delimited blocks .* fewer than the 8"):
        read_blocks(f, M + 2, L, bin_width=RES)


def test_photons_past_the_code_period_are_said(tmp_path):
    """Photons at a TDC time past the code period were dropped without a word (a fifth of a
    file's, or half with a sync divider of 2)."""
    rng = np.random.default_rng(4)
    starts = [DWELL * k for k in range(M)]
    late = [(int(s), L + 2) for s in rng.integers(0, DWELL * M, M * PER // 5)]
    f = _write(tmp_path / "late.ptu", *_events(rng, starts, starts, late))
    data, notes = read_blocks(f, M, L, bin_width=RES)
    assert data.n_out_of_range == len(late)
    assert any("past the code period (31 bins)" in n and "sync period" in n for n in notes)
    g = _write(tmp_path / "div.ptu", *_events(rng, starts, starts, late), HWSync_Divider=2)
    _, notes = read_blocks(g, M, L, bin_width=RES)
    assert any("the header's sync divider is 2" in n and "does not fold" not in n
               for n in notes), notes
    few = late[: M * PER // 50]  # 2 % of the photons: not said
    h = _write(tmp_path / "few.ptu", *_events(rng, starts, starts, few))
    assert read_blocks(h, M, L, bin_width=RES)[1] == []


def test_the_reader_keeps_extra_blocks_only_where_the_file_has_them(tmp_path):
    rng = np.random.default_rng(5)
    starts = [DWELL * k for k in range(M)]
    f = _write(tmp_path / "a.ptu", *_events(rng, starts, starts))
    for extra in (0, 1, 3):
        d = read_ptu_histograms(f, L, n_patterns=M, extra_blocks=extra)
        assert d.n_patterns == M and d.counts_per_pattern.sum() == M * PER
    # read as ending their patterns, the M markers close M blocks: the first (sync 0, before
    # any photon) empty, and the last pattern's photons after the last marker dropped
    e = read_ptu_histograms(f, L, n_patterns=M - 1, extra_blocks=1, marker_edge="end")
    assert e.n_patterns == M and list(e.periods_per_pattern) == [1] + [DWELL] * (M - 1)
    assert e.counts_per_pattern[0] == 0 and e.n_dropped_after_last_pattern == PER
    for bad, words in (({"extra_blocks": -1}, "extra_blocks"),
                       ({"marker_edge": "middle"}, "marker_edge")):
        with pytest.raises(ConfigError, match=words):
            read_ptu_histograms(f, L, n_patterns=M, **bad)


def test_reconstruct_takes_marker_edge(tmp_path, capsys):
    """--marker-edge on the command line, for reconstruct and calibrate, and said in
    metrics.json."""
    import json

    rng = np.random.default_rng(6)
    starts = [DWELL * k for k in range(M)]
    ends = [s + DWELL - 1 for s in starts]
    nsync, dtime, marker = _events(rng, starts, ends)
    f = _write(tmp_path / "e.ptu", nsync, dtime, marker)
    pats = rng.random((M, 4, 4)).astype(np.float32)
    np.save(tmp_path / "p.npy", pats)
    np.save(tmp_path / "c.npy", (rng.random(L) < 0.5).astype(np.uint8))
    args = ["reconstruct", "--ptu", str(f), "--patterns", str(tmp_path / "p.npy"), "--code",
            str(tmp_path / "c.npy"), "--bit-rate", "10e9", "--range-gate", "0", "0.3",
            "--no-figure"]
    assert main([*args, "--out", str(tmp_path / "r1")]) == 0
    assert "pass --marker-edge end" in capsys.readouterr().err
    assert main([*args, "--marker-edge", "end", "--out", str(tmp_path / "r2")]) == 0
    assert "--marker-edge" not in capsys.readouterr().err
    m = json.loads((tmp_path / "r2" / "metrics.json").read_text())
    assert m["ptu"]["marker_edge"] == "end" and m["ptu"]["n_patterns_solved"] == M
    with pytest.raises(SystemExit) as exc:  # (argparse's own refusals exit from the parser)
        main([*args, "--marker-edge", "middle", "--out", str(tmp_path / "r3")])
    assert exc.value.code == 2 and "invalid choice: 'middle'" in capsys.readouterr().err


def test_marker_edge_end_starts_pattern_0_a_patterns_dwell_before_its_marker(tmp_path):
    """Read with "end", pattern 0 ran from sync 0: a recording started 1 000 syncs before
    the DMD gave it a dwell of 1 200 and the background before it, and the reconstruction
    scaled its signal down six-fold (a review). It now lasts as long as pattern 1."""
    rng = np.random.default_rng(7)
    starts = [1000 + DWELL * k for k in range(M)]
    ends = [s + DWELL - 1 for s in starts]
    early = [(int(s), 20) for s in rng.integers(0, 1000, 40)]
    nsync, dtime, marker = _events(rng, starts, ends, early)
    order = np.lexsort((marker, nsync))
    f = _write(tmp_path / "late.ptu", nsync[order], dtime[order], marker[order])
    data, _ = read_blocks(f, M, L, bin_width=RES, marker_edge="end")
    assert list(data.periods_per_pattern) == [DWELL] * M
    assert _peaks(data) == list(range(M))
    assert data.counts_per_pattern[0] == PER and data.n_dropped_before_first_marker == 40


def test_both_short_ends_leave_out_the_one_without_a_patterns_photons(tmp_path):
    """An arming marker and a last pattern cut short: the last block was left out because
    it was short, the arming block kept as pattern 0 and every pattern read with its
    neighbour's photons, nothing said (a review)."""
    rng = np.random.default_rng(8)
    starts = [10 + DWELL * k for k in range(M)]
    nsync, dtime, marker = _events(rng, starts, [0, *starts])
    cut = nsync < starts[-1] + 80  # the acquisition stops 80 syncs into the last pattern
    f = _write(tmp_path / "cut.ptu", nsync[cut], dtime[cut], marker[cut])
    data, notes = read_blocks(f, M, L, bin_width=RES)
    assert _peaks(data) == list(range(M))
    assert len(notes) == 1 and "the first, at 0 of a pattern's photon rate" in notes[0]


def test_a_recording_started_early_is_not_told_to_change_the_edge(tmp_path):
    """Start markers, the recording begun three quarters of a pattern early with background
    at a pattern's rate, the last pattern cut short: told "--marker-edge end", which misread
    every pattern (a review)."""
    rng = np.random.default_rng(9)
    starts = [150 + DWELL * k for k in range(M)]
    early = [(int(s), 25) for s in rng.integers(0, 150, 300)]
    nsync, dtime, marker = _events(rng, starts, starts, early)
    cut = nsync < starts[-1] + 80
    f = _write(tmp_path / "early.ptu", nsync[cut], dtime[cut], marker[cut])
    data, notes = read_blocks(f, M, L, bin_width=RES)
    assert _peaks(data) == list(range(M))
    assert not any("--marker-edge" in n for n in notes), notes


@pytest.mark.parametrize("periods", ["1", "4"])
def test_a_wrong_marker_edge_is_said_at_short_dwells(tmp_path, periods):
    """A one-period dwell (the paper's) read with the wrong --marker-edge end: the photons
    after the last marker span the marker's own sync, counted as 0 periods against a typical
    1 (3 against 4 at four periods), so nothing was said while every pattern took its
    neighbour's photons (an audit of 2026-11-29)."""
    np.save(tmp_path / "wall.npy", np.full((8, 8), 25.0))
    f = tmp_path / "w.ptu"
    assert main(["run", "--scene", str(tmp_path / "wall.npy"), "--size", "8", "--code-length",
                 "255", "--signal", "1", "--noise", "0.02", "--compression", "0.5",
                 "--range-gate", "24", "26", "--periods", periods, "--no-figure",
                 "--save-ptu", str(f), "--out", str(tmp_path / "o")]) == 0
    m = np.load(tmp_path / "w_patterns.npy").shape[0]
    _, notes = read_blocks(f, m, 255, bin_width=RES, marker_edge="end")
    assert any("--marker-edge start" in n for n in notes), notes
    _, notes = read_blocks(f, m, 255, bin_width=RES)
    assert not any("--marker-edge" in n for n in notes), notes


def test_an_empty_short_block_is_left_out_of_the_solve(tmp_path):
    """A start-marker file read with --marker-edge end opens with a block of no photons over
    one code period where the patterns dwell four: it was kept as a row of zeros and 'scaled
    up to the mean dwell' (which leaves it 0); on a real FLIM file leaving it out moved 32 of
    64 depths by up to 0.94 m (an audit of 2026-11-29). It is left out of the solve, said."""
    import json

    np.save(tmp_path / "wall.npy", np.full((8, 8), 25.0))
    f = tmp_path / "w.ptu"
    assert main(["run", "--scene", str(tmp_path / "wall.npy"), "--size", "8", "--code-length",
                 "255", "--signal", "1", "--noise", "0.02", "--compression", "0.5",
                 "--range-gate", "24", "26", "--periods", "4", "--no-figure",
                 "--save-ptu", str(f), "--out", str(tmp_path / "o")]) == 0
    m = np.load(tmp_path / "w_patterns.npy").shape[0]
    out = tmp_path / "rec"
    assert main(["reconstruct", "--ptu", str(f), "--patterns", str(tmp_path / "w_patterns.npy"),
                 "--code", str(tmp_path / "w_code.npy"), "--bit-rate", "10e9", "--range-gate",
                 "24", "26", "--marker-edge", "end", "--no-figure", "--out", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["n_patterns"] == m - 1
    assert any("left out of the solve" in w and "(first: 0)" in w for w in metrics["warnings"])


@pytest.mark.parametrize("dwell, lead, last, per, seed", [(1, 2, 1, 60, 6), (10, 11, 1, 200, 7)])
def test_a_recording_started_early_keeps_its_edge_at_short_and_long_dwells(tmp_path, dwell, lead,
                                                                          last, per, seed):
    """Start markers read with the default edge, photons at a pattern's rate from ``lead``
    periods before the first marker, the last pattern cut to ``last`` periods: a dwell of 1
    begun two periods early (the tolerance for the marker's own sync, a review) and a dwell
    of 10 begun 11 early (a span over the dwell passed the upper bound, a second review) were
    told to pass --marker-edge end, which would misread every pattern. The marker's own sync
    only ever makes the span short, so these files are read as given without a word."""
    rng = np.random.default_rng(seed)
    ev = [(int(s), 1, 5, 0) for s in np.sort(rng.integers(0, lead, per * lead // dwell))]
    for k in range(M):
        s0 = lead + dwell * k
        n = dwell if k < M - 1 else last
        ev += [(int(s), 1, k + 3, 0) for s in np.sort(rng.integers(s0, s0 + n, per * n // dwell))]
        ev.append((s0, 0, 0, 1))
    ev.sort()
    a = np.array(ev)
    f = _write(tmp_path / "early.ptu", a[:, 0], a[:, 2], a[:, 3])
    data, notes = read_blocks(f, M, L, bin_width=RES)
    assert _peaks(data) == list(range(M))
    assert not any("--marker-edge" in n for n in notes), notes


@pytest.mark.parametrize("bounces", [[(3, 0)], [(2, 1)], [(1, 2), (4, 0)]])
def test_a_bouncing_marker_is_merged_into_its_pattern(tmp_path, bounces):
    """A marker repeated 0, 1 or 2 syncs after its pattern's (a DMD trigger's bounce; one or
    two of them): the short block's photons are the pattern's, and every row keeps its own
    pattern. Before, the last block was dropped as "a row missing from --patterns?" and
    every pattern after the bounce was paired with its neighbour's photons, or the bounce
    block was scaled up as a pattern of its own."""
    rng = np.random.default_rng(7)
    starts = [DWELL * k for k in range(M)]
    marks = starts + [DWELL * k + gap for k, gap in bounces]
    f = _write(tmp_path / "b.ptu", *_events(rng, starts, sorted(marks)))
    data, notes = read_blocks(f, M, L, bin_width=RES)
    assert _peaks(data) == list(range(M))
    np.testing.assert_array_equal(data.periods_per_pattern[:-1], DWELL)
    assert data.counts_per_pattern.sum() == M * PER  # none lost
    assert len(notes) == 1 and "a marker repeated (a DMD trigger's bounce?)" in notes[0]
    # (the short block is the one from the pattern's marker to its bounce: block k, after
    # the earlier bounces' blocks)
    said = ", ".join(str(k + i) for i, (k, _) in enumerate(sorted(bounces)))
    assert f"(block {said})" in notes[0]


def test_patterns_of_a_period_each_are_no_bounce(tmp_path):
    """Patterns lasting a sync or two are not told from bounces: an extra block there is the
    end-of-acquisition marker's, as before."""
    rng = np.random.default_rng(8)
    dwell = 2
    starts = [dwell * k for k in range(M)]
    ev = []
    for k, s0 in enumerate(starts):
        ev += [(int(s), 1, k + 3, 0) for s in rng.integers(s0, s0 + dwell, 50)]
    ev += [(int(s), 0, 0, 1) for s in starts + [dwell * M]]
    ev.sort()
    a = np.array(ev)
    f = _write(tmp_path / "p.ptu", a[:, 0], a[:, 2], a[:, 3])
    data, notes = read_blocks(f, M, L, bin_width=RES)
    assert _peaks(data) == list(range(M)) and not any("bounce" in n for n in notes)


@pytest.mark.parametrize("stray,said", [(200, True), (10, False)])
def test_photons_on_a_second_channel_are_said_when_they_matter(tmp_path, stray, said):
    """A second channel (a laser monitor) merged without --channel is said where it holds 1 %
    of the photons or more (200 of 2 600 here), not for a few stray counts (10)."""
    rng = np.random.default_rng(9)
    starts = [DWELL * k for k in range(M)]
    nsync, dtime, marker = _events(rng, starts, starts)
    extra = np.sort(rng.integers(0, DWELL * M, stray))
    ns = np.concatenate([nsync, extra])
    order = np.argsort(ns, kind="stable")
    ch = np.concatenate([np.zeros(nsync.size, int), np.ones(stray, int)])[order]
    dt = np.concatenate([dtime, np.full(stray, 20)])[order]
    mk = np.concatenate([marker, np.zeros(stray, int)])[order]
    f = tmp_path / "c.ptu"
    write_ptu_t3(f, nsync=ns[order], dtime=dt, channel=ch, marker=mk, resolution_s=RES,
                 sync_rate_hz=1 / (L * RES))
    data, notes = read_blocks(f, M, L, bin_width=RES)
    assert data.photons_per_channel == {0: M * PER, 1: stray}
    assert any("merged into one histogram" in n for n in notes) == said
    _, notes = read_blocks(f, M, L, bin_width=RES, channel=0)
    assert not any("merged" in n for n in notes)


def test_a_sync_divider_folds_each_sync_into_code_periods(tmp_path):
    """A sync divider of 2 (the header's HWSync_Divider; PicoQuant's sync period is the
    divided one): each sync spans two code periods, whose photons are folded into one, and
    the dwell counts code periods. It was refused ("a 62-bit code fits it"), and a code given
    twice over read a third of its returns as outside the gate."""
    rng = np.random.default_rng(10)
    starts = [DWELL * k for k in range(M)]
    nsync, dtime, marker = _events(rng, starts, starts)
    second = rng.random(dtime.size) < 0.5  # half the photons in the sync's second period
    dtime = np.where((marker == 0) & second, dtime + L, dtime)
    args = dict(nsync=nsync, dtime=dtime, marker=marker, resolution_s=RES,
                sync_rate_hz=1 / (2 * L * RES))
    f = tmp_path / "div2.ptu"
    write_ptu_t3(f, **args, extra_tags={"HWSync_Divider": 2})
    data, notes = read_blocks(f, M, L, bin_width=RES)
    assert _peaks(data) == list(range(M)) and data.counts_per_pattern.sum() == M * PER
    assert data.periods_per_sync == 2 and data.n_out_of_range == 0
    np.testing.assert_array_equal(data.periods_per_pattern[:-1], 2 * DWELL)
    g = tmp_path / "nodiv.ptu"  # the same period without the header's word: no fold
    write_ptu_t3(g, **args)
    with pytest.raises(ConfigError, match="sync period") as info:
        read_blocks(g, M, L, bin_width=RES)
    # said first as what it is, a sync every 2 periods, and not as a slower code clock,
    # whose advice read depths 1.5 m off (an outside lab audit of 2026-11-30)
    said = str(info.value)
    assert "it is 2 code periods: a sync every 2 of them" in said and "--sync-divider 2" in said
    assert "--allow-binning" not in said
    # --sync-divider 2 reads it as the header's divider would
    given, _ = read_blocks(g, M, L, bin_width=RES, sync_divider=2)
    np.testing.assert_array_equal(given.histograms, data.histograms)
    np.testing.assert_array_equal(given.periods_per_pattern, data.periods_per_pattern)
    for bad in (0, True, 1.5, "2"):
        with pytest.raises(ConfigError, match="--sync-divider must be a whole number"):
            read_blocks(g, M, L, bin_width=RES, sync_divider=bad)
    assert read_blocks(g, M, L, bin_width=RES, sync_divider=2.0)[0].periods_per_sync == 2
    # a divider the file does not have is refused, not dropped (a review found it dropped)
    with pytest.raises(ConfigError, match=r"is 2 code periods of 31 bins, not the 3 "
                                          r"--sync-divider gives"):
        read_blocks(g, M, L, bin_width=RES, sync_divider=3)
    with pytest.raises(ConfigError, match=r"is 2 code periods of 31 bins, not the 1 "):
        read_blocks(g, M, L, bin_width=RES, sync_divider=1)
    with pytest.raises(ConfigError, match=r"is 2 code periods of 31 bins, not the 3 "):
        read_blocks(f, M, L, bin_width=RES, sync_divider=3)  # (over the header's 2 too)


def test_a_missed_marker_is_refused_naming_the_long_block(tmp_path):
    """One marker missed: refused (as before), now naming the block that lasts two
    patterns' dwell."""
    rng = np.random.default_rng(11)
    starts = [DWELL * k for k in range(M)]
    f = _write(tmp_path / "miss.ptu", *_events(rng, starts, starts[:3] + starts[4:]))
    with pytest.raises(ConfigError, match=r"fewer than the 6 patterns \(block 2 lasts about "
                                          r"twice the 200 code periods of the others"):
        read_blocks(f, M, L, bin_width=RES)


def test_many_bounces_and_a_late_one_are_merged(tmp_path):
    """Four bounces (more than the two extra blocks an arming and an end marker take) with an
    arming and an end marker, and a bounce 15 syncs late, under 10 us: all merged, every row
    its own pattern. Three bounces were refused as a file that does not match the patterns,
    and one three periods late took a pattern row."""
    rng = np.random.default_rng(12)
    m = 12
    starts = [DWELL * k + 5 for k in range(m)]
    bounces = [DWELL * k + 5 + g for k, g in ((1, 1), (3, 0), (5, 2), (7, 1), (9, 15))]
    marks = sorted(starts + bounces + [0, DWELL * m + 5])  # arming and end markers
    ev = []
    for k, s0 in enumerate(starts):
        ev += [(int(s), 1, k + 3, 0) for s in np.sort(rng.integers(s0, s0 + DWELL, PER))]
    ev += [(int(s), 0, 0, 1) for s in marks]
    ev.sort()
    a = np.array(ev)
    f = _write(tmp_path / "many.ptu", a[:, 0], a[:, 2], a[:, 3])
    # (15 syncs of 3.1 ns: 47 ns, a bounce in time and within a tenth of the dwell)
    data, notes = read_blocks(f, m, L, bin_width=RES)
    assert _peaks(data) == list(range(m)) and data.counts_per_pattern.sum() == m * PER
    assert any("5 of the file's" in n and "bounce" in n for n in notes)


def test_a_block_twice_as_long_as_the_others_is_said(tmp_path):
    """A marker missed and an extra one elsewhere: the count matches, so nothing is refused,
    but the block that lasts two patterns' dwell is named."""
    rng = np.random.default_rng(13)
    starts = [DWELL * k for k in range(M)]
    marks = [s for k, s in enumerate(starts) if k != 3] + [DWELL * M - 50]  # an extra, late
    f = _write(tmp_path / "dbl.ptu", *_events(rng, starts, sorted(marks)))
    _, notes = read_blocks(f, M, L, bin_width=RES)
    assert any("pattern block 2 lasts about twice the 200 code periods" in n for n in notes)
    g = _write(tmp_path / "ok.ptu", *_events(rng, starts, starts))
    assert not any("twice" in n for n in read_blocks(g, M, L, bin_width=RES)[1])


def test_marker_edge_end_with_a_bounce_on_the_first_marker(tmp_path):
    """Pattern 0 lasts as long as pattern 1, measured from the next marker that is no bounce
    of the first (a bounce 3 syncs after it made pattern 0 three periods long and dropped
    the rest of its photons as before the first marker: a review)."""
    rng = np.random.default_rng(14)
    starts = [1000 + DWELL * k for k in range(M)]
    ends = [s + DWELL - 1 for s in starts]
    nsync, dtime, marker = _events(rng, starts, sorted(ends + [ends[0] + 3]))
    order = np.lexsort((marker, nsync))
    f = _write(tmp_path / "endb.ptu", nsync[order], dtime[order], marker[order])
    data, notes = read_blocks(f, M, L, bin_width=RES, marker_edge="end")
    assert _peaks(data) == list(range(M)) and data.counts_per_pattern[0] == PER


@pytest.mark.parametrize("m", [8, 32])
def test_every_marker_bouncing_is_merged(tmp_path, m):
    """Every marker after the first bouncing 3 syncs later (a consistent trigger ringing):
    all merged. The reader had kept too few blocks, so the last pattern lost all but its
    bounce's photons, and at 32 patterns the file was refused (a review)."""
    rng = np.random.default_rng(15)
    starts = [DWELL * k for k in range(m)]
    marks = sorted(starts + [s + 3 for s in starts[1:]])
    ev = []
    for k, s0 in enumerate(starts):
        ev += [(int(s), 1, k % (L - 4) + 3, 0) for s in np.sort(rng.integers(s0, s0 + DWELL, PER))]
    ev += [(int(s), 0, 0, 1) for s in marks]
    ev.sort()
    a = np.array(ev)
    f = _write(tmp_path / "ring.ptu", a[:, 0], a[:, 2], a[:, 3])
    data, notes = read_blocks(f, m, L, bin_width=RES)
    assert data.n_patterns == m and data.counts_per_pattern.sum() == m * PER
    assert list(np.argmax(data.histograms, axis=1) - 3) == [k % (L - 4) for k in range(m)]
    np.testing.assert_array_equal(data.periods_per_pattern[:-1], DWELL)
    assert any(f"{m - 1} of the file's {2 * m - 1} marker-delimited blocks" in n and
               f"({DWELL - 3} periods typical)" in n for n in notes)


def test_syncs_that_stop_leave_their_blocks_out_and_say_why(tmp_path, capsys):
    """The sync signal lost after pattern 3: the DMD's markers and the photons go on at one
    sync. Those blocks last no code period: they were read as patterns of one period, scaled
    up 200 times without a word (or named an arming marker's); now they are left out, with
    the cause, and a file whose every block is at one sync is refused in one line."""
    from spslidar.pipeline.blocks import drop_frozen

    rng = np.random.default_rng(5)
    starts = [DWELL * k for k in range(M)]
    nsync, dtime, marker = _events(rng, starts, starts)
    f = _write(tmp_path / "frozen.ptu", np.minimum(nsync, 4 * DWELL), dtime, marker)
    data, _ = read_blocks(f, M, L, bin_width=RES)
    kept, n, note = drop_frozen(data, f)
    assert n == 2 and kept.n_patterns == 4 and _peaks(kept) == [0, 1, 2, 3]
    assert kept.n_dropped_after_last_pattern == data.n_dropped_after_last_pattern + 2 * PER
    assert f"the file's syncs stop at sync {4 * DWELL}: its last 2 marker blocks (from " \
           f"block 4 on) start there and hold {2 * PER} photons" in note
    # a file whose syncs go on, or a bounce at one sync mid-file, keeps every block
    g = _write(tmp_path / "ok.ptu", *_events(rng, starts, starts))
    ok, _ = read_blocks(g, M, L, bin_width=RES)
    assert drop_frozen(ok, g)[1] == 0
    # through reconstruct: the rows are left out and said; the map is still made
    pats = (rng.random((M, 4, 4)) < 0.5).astype(np.float32)
    np.save(tmp_path / "p.npy", pats)
    code = np.zeros(L, np.uint8)
    code[rng.permutation(L)[: L // 2 + 1]] = 1
    np.save(tmp_path / "c.npy", code)
    args = ["reconstruct", "--ptu", str(f), "--patterns", str(tmp_path / "p.npy"), "--code",
            str(tmp_path / "c.npy"), "--bit-rate", f"{1 / RES:g}", "--range-gate", "0.1", "1",
            "--no-figure"]
    assert main([*args, "--out", str(tmp_path / "r")]) == 0
    err = capsys.readouterr().err
    assert "the sync signal lost?" in err and "scaled up" not in err
    import json

    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert metrics["ptu"]["blocks_left_out"] == [4, 5]
    assert metrics["ptu"]["n_patterns_solved"] == 4
    # every block at one sync: refused, nothing written
    nsync0, dtime0, marker0 = _events(rng, [0] * M, [0] * M)
    z = _write(tmp_path / "zero.ptu", nsync0 * 0, dtime0, marker0)
    assert main([*args[:2], str(z), *args[3:], "--out", str(tmp_path / "z")]) == 2
    err = capsys.readouterr().err
    assert "where the file's syncs stop (the sync signal missing or lost?)" in err
    assert not (tmp_path / "z").exists()


def test_files_joined_end_to_end_are_refused(tmp_path, capsys):
    """Two PicoHarp files appended record by record, each counting its syncs from 0: the
    block across the join was read as one code period and scaled up 2 100 times, the map
    ruined under a warning of short dwells (an outside lab audit of 2026-11-30). No real
    acquisition's sync count runs backwards: refused in one line, nothing written."""
    import struct

    from test_independent_ptu import write_picoharp_t3

    rng = np.random.default_rng(9)
    starts = [DWELL * k for k in range(M)]
    parts = []
    for half in (slice(0, M // 2), slice(M // 2, M)):
        s = [x - starts[half.start] for x in starts[half]]
        nsync, dtime, marker = _events(rng, s, s)
        path = tmp_path / f"part{half.start}.ptu"
        n = write_picoharp_t3(path, nsync, dtime, marker.astype(bool), RES, 1 / (L * RES))
        raw = path.read_bytes()
        parts.append((raw[: len(raw) - 4 * n], raw[len(raw) - 4 * n:], n))
    header, first, n0 = parts[0]
    _, second, n1 = parts[1]
    at = header.index(b"TTResult_NumberOfRecords") + 40  # (32-byte name, index, type: value)
    header = header[:at] + struct.pack("<q", n0 + n1) + header[at + 8:]
    joined = tmp_path / "joined.ptu"
    joined.write_bytes(header + first + second)
    with pytest.raises(ConfigError, match=r"its sync count runs backwards \(sync \d+ after "
                                          r"\d+\), which no acquisition records: files joined"):
        read_blocks(joined, M, L, bin_width=RES)
    pats = (rng.random((M, 4, 4)) < 0.5).astype(np.float32)
    np.save(tmp_path / "p.npy", pats)
    np.save(tmp_path / "c.npy", (rng.random(L) < 0.5).astype(np.uint8))
    out = tmp_path / "r"
    assert main(["reconstruct", "--ptu", str(joined), "--patterns", str(tmp_path / "p.npy"),
                 "--code", str(tmp_path / "c.npy"), "--bit-rate", f"{1 / RES:g}",
                 "--range-gate", "0.1", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "files joined end to end" in err[0] and not out.exists()


def test_the_wrong_edge_note_of_a_one_period_dwell_reads_as_words():
    """A one-period dwell read with the wrong edge said "44946 photons over 0 code periods
    came after the last marker ... (1 periods, ...) and the first block lasts 1" (an audit
    of the docs of 2026-12-01)."""
    from types import SimpleNamespace

    from spslidar.pipeline.blocks import _edge_note

    n = 8
    data = SimpleNamespace(periods_per_pattern=np.ones(n, np.int64),
                           counts_per_pattern=np.full(n, 5000),
                           n_dropped_after_last_pattern=4900,
                           pattern_start_sync=np.arange(n), last_sync=n - 1)
    note = _edge_note(data, 1, "end")
    assert note.startswith("4900 photons within a code period came after the last marker on "
                           "input 1, about one pattern's (1 code period, 5000 photons), and "
                           "the first block lasts 1 code period: "), note
    assert note.endswith("pass --marker-edge start")


@pytest.mark.parametrize("lead", [2 * DWELL, 5 * DWELL])
def test_an_arming_marker_long_before_the_sequence_is_left_out(tmp_path, lead):
    """An arming marker two or five patterns' dwell before the first pattern, its block
    without a photon: it was not short, so it was kept as pattern 0 and the last pattern
    dropped (every pattern paired with its neighbour's photons; an outside audit of
    2026-12-02). With an end marker too (M + 2 blocks) it was refused."""
    rng = np.random.default_rng(4)
    starts = [lead + DWELL * k for k in range(M)]
    one = _write(tmp_path / "one.ptu", *_events(rng, starts, [0, *starts]))
    data, notes = read_blocks(one, M, L, bin_width=RES)
    assert _peaks(data) == list(range(M)) and data.n_patterns == M
    assert len(notes) == 1 and "its first block" in notes[0] and "is left out" in notes[0]
    both = _write(tmp_path / "both.ptu", *_events(rng, starts, [0, *starts, lead + DWELL * M]))
    data, notes = read_blocks(both, M, L, bin_width=RES)
    assert _peaks(data) == list(range(M)) and data.n_patterns == M
    # a first block holding a pattern's photons, however long, is a pattern: the last of
    # M + 1 patterns' blocks is left out (a row missing from --patterns?)
    slow = _write(tmp_path / "slow.ptu", *_events(rng, [0, *starts], [0, *starts]))
    data, notes = read_blocks(slow, M, L, bin_width=RES)
    assert _peaks(data) == list(range(M)) and "is a row missing" in notes[0]


def test_a_dark_pattern_at_either_end_stays_a_pattern(tmp_path):
    """An all-off frame (no photon) of a pattern's dwell at the start or the end, and an
    end-of-acquisition or arming marker's short block at the other: the dark frame is a
    pattern, the short block is left out (a review of 2026-12-02 found the rule for empty
    arming blocks taking a dark pattern for one, 12 of 20 seeds shifted)."""
    rng = np.random.default_rng(6)
    starts = [DWELL * k for k in range(M)]
    nsync, dtime, marker = _events(rng, starts, [*starts, DWELL * M],
                                   extra=[(DWELL * M + int(s), 5) for s in
                                          rng.integers(0, 10, 30)])
    dark = ~((nsync < DWELL) & (marker == 0))  # pattern 0's photons taken away
    f = _write(tmp_path / "first.ptu", nsync[dark], dtime[dark], marker[dark])
    data, _ = read_blocks(f, M, L, bin_width=RES)
    assert data.n_patterns == M and data.counts_per_pattern[0] == 0
    assert list(np.argmax(data.histograms[1:], axis=1) - 3) == list(range(1, M))
    # (a dark last pattern's dwell shows only in the light after its marker: here a
    # background of a photon every 40 code periods throughout)
    starts = [10 + DWELL * k for k in range(M)]
    nsync, dtime, marker = _events(rng, starts, [0, *starts],
                                   extra=[(int(s), 29) for s in range(3, DWELL * M + 10, 40)])
    dark = ~((nsync >= starts[-1]) & (marker == 0) & (dtime != 29))  # its pattern's photons
    g = _write(tmp_path / "last.ptu", nsync[dark], dtime[dark], marker[dark])
    data, _ = read_blocks(g, M, L, bin_width=RES)
    assert data.n_patterns == M and data.counts_per_pattern[-1] == 5
    assert list(np.argmax(data.histograms[:-1], axis=1) - 3) == list(range(M - 1))
