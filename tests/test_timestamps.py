"""Another vendor's time tags: absolute timestamps on sync, marker and detector channels ->
T3 events and a PTU file that ``reconstruct`` reads as it reads a PicoHarp's."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spslidar.codes.sequences import make_code
from spslidar.constants import SPEED_OF_LIGHT
from spslidar.errors import ConfigError
from spslidar.io import (
    read_ptu_histograms,
    t3_from_timestamps,
    write_ptu_from_timestamps,
    write_ptu_t3,
)
from spslidar.pipeline.real import reconstruct_ptu

N, M, L, PERIODS = 8, 48, 127, 200
SYNC, MARK, DET_A, DET_B = 0, 3, 1, -2  # a Swabian tagger's numbering: -2 a falling edge


def _events(seed=0):
    """T3 events of a two-plane 8x8 scene (4.0 / 4.3 m): 48 binary patterns of 200 periods of
    a 127-bit m-sequence each, Poisson photons split over two detector channels; a marker at
    the first sync of every pattern."""
    rng = np.random.default_rng(seed)
    code = make_code("mseq", L, 0.5).astype(np.float64)
    truth = np.full((N, N), 4.0)
    truth[:, N // 2:] = 4.3
    delay = np.round(truth / (SPEED_OF_LIGHT / 10e9 / 2)).astype(int).ravel()
    pats = (rng.random((M, N, N)) < 0.5).astype(np.float32)
    lam = np.zeros((M, L))
    for j, d in enumerate(delay):
        lam += 0.02 * pats.reshape(M, -1)[:, j : j + 1] * np.roll(code, d)[None]
    counts = rng.poisson((lam + 0.01) * PERIODS)
    nsync, dtime, chan, mark = [], [], [], []
    for k in range(M):
        bins = np.repeat(np.arange(L), counts[k])
        per = rng.integers(0, PERIODS, bins.size) + k * PERIODS
        order = np.argsort(per, kind="stable")
        nsync += [np.array([k * PERIODS]), per[order]]
        dtime += [np.array([0]), bins[order]]
        chan += [np.array([0]), rng.integers(0, 2, bins.size)]
        mark += [np.array([1]), np.zeros(bins.size, int)]
    ev = [np.concatenate(a) for a in (nsync, dtime, chan, mark)]
    return ev, pats, code, truth


def _stream(ev, res_ps, rng):
    """The same events as a time tagger streams them: picosecond timestamps of every sync
    (jittered by a few ps), of each marker just after its sync, and of each photon somewhere
    inside its TDC bin; channels in the tagger's numbering; merged in time order."""
    nsync, dtime, chan, mark = ev
    period_ps = L * res_ps
    t0 = 1_234_567  # the tagger's clock does not start at a sync
    n_periods = int(nsync[-1]) + 1
    sync_t = t0 + np.round(np.arange(n_periods) * period_ps).astype(np.int64) \
        + rng.integers(-3, 4, n_periods)
    photon = mark == 0
    # (never within 9.6 ps of a bin's edge: the syncs' jitter moves the next sync by up to 6)
    inside = rng.uniform(0.1, 0.9, nsync.size)
    t = sync_t[nsync] + np.where(photon, np.floor((dtime + inside) * res_ps), 7).astype(np.int64)
    c = np.where(photon, np.where(chan == 0, DET_A, DET_B), MARK)
    t = np.concatenate([sync_t, t])
    c = np.concatenate([np.full(n_periods, SYNC), c])
    order = np.argsort(t, kind="stable")
    return t[order], c[order]


@pytest.mark.parametrize("bit_rate", [10e9, 10.3125e9])
def test_timestamps_give_the_same_histograms_and_depth(tmp_path, bit_rate):
    """The converted stream's PTU holds, per pattern, exactly the histograms of the same
    events written as T3 records directly, on an integer (100 ps) and a fractional
    (96.97 ps) bin; and reconstructs to the same depth map, right to one bin."""
    rng = np.random.default_rng(1)
    ev, pats, code, truth = _events()
    res = 1 / bit_rate
    direct = tmp_path / "direct.ptu"
    write_ptu_t3(direct, nsync=ev[0], dtime=ev[1], channel=ev[2], marker=ev[3],
                 resolution_s=res, sync_rate_hz=bit_rate / L)
    times, channels = _stream(ev, res * 1e12, rng)
    conv = tmp_path / "conv.ptu"
    out = write_ptu_from_timestamps(conv, times, channels, time_unit_s=1e-12, sync_channel=SYNC,
                                    marker_channel=MARK, resolution_s=res,
                                    photon_channels=(DET_B, DET_A))
    assert out.photon_channels == (DET_B, DET_A)  # in the order given: -2 is channel 0
    assert out.n_photons == int(np.count_nonzero(ev[3] == 0)) and out.n_markers == M
    assert out.n_before_first_sync == 0 and out.n_missing_syncs == 0
    # (the median of syncs jittered by +-3 ps: the period within 3 ps of 127 bins)
    assert out.sync_period_s == pytest.approx(L * res, abs=3e-12)
    a = read_ptu_histograms(direct, L, bin_width=res, n_patterns=M)
    b = read_ptu_histograms(conv, L, bin_width=res, n_patterns=M)
    np.testing.assert_array_equal(b.histograms, a.histograms)
    np.testing.assert_array_equal(b.periods_per_pattern, a.periods_per_pattern)
    # channel 1 is the tagger's DET_A, the events' channel 0
    one = read_ptu_histograms(conv, L, bin_width=res, n_patterns=M, channel=1)
    assert one.n_photons == int(np.count_nonzero((ev[3] == 0) & (ev[2] == 0)))
    if bit_rate == 10e9:  # (the scene's delays are whole 100 ps bins)
        flat = pats.reshape(M, -1)
        d1 = reconstruct_ptu(direct, flat, code.astype(np.uint8), bit_rate, (3.5, 4.8),
                             depth="argmax").depth
        d2 = reconstruct_ptu(conv, flat, code.astype(np.uint8), bit_rate, (3.5, 4.8),
                             depth="argmax").depth
        np.testing.assert_array_equal(d2, d1)
        assert np.nanmedian(np.abs(d2 - truth)) <= 0.015


def test_events_outside_the_syncs_are_placed_on_their_grid():
    """A photon before the first sync is placed back from it (counted), one after the last
    sync forward from it (the stream ends between syncs); periods count from the first
    event's."""
    t = np.array([5, 10, 12, 110, 150, 210, 215, 400])
    c = np.array([1, 0, 2, 0, 1, 0, 1, 1])
    ev = t3_from_timestamps(t, c, time_unit_s=1e-12, sync_channel=0, marker_channel=2,
                            resolution_s=10e-12)
    assert ev.n_before_first_sync == 1 and ev.n_missing_syncs == 0
    np.testing.assert_array_equal(ev.nsync, [0, 1, 2, 3, 4])  # photon, marker, photons
    np.testing.assert_array_equal(ev.marker, [0, 1, 0, 0, 0])
    # 5 ps is 95 ps into the period before the sync at 10; 150 - 110 = 40 ps: bin 4
    np.testing.assert_array_equal(ev.dtime, [9, 0, 4, 0, 9])


def test_syncs_left_out_by_a_conditional_filter(tmp_path):
    """A tagger's conditional filter passes only the sync after a photon (the periods
    without a photon keep no sync): the events are placed from the nearest sync held, and
    the histograms equal those of the full stream, with and without the period given."""
    rng = np.random.default_rng(2)
    ev, _, _, _ = _events()
    res = 1e-10
    times, channels = _stream(ev, 100.0, rng)
    # one photon in 50 kept (about one a period): many periods hold none
    thin = (channels == SYNC) | (channels == MARK) | (rng.random(times.size) < 0.02)
    times, channels = times[thin], channels[thin]
    kw = dict(time_unit_s=1e-12, sync_channel=SYNC, marker_channel=MARK, resolution_s=res,
              photon_channels=(DET_B, DET_A))
    full = t3_from_timestamps(times, channels, **kw)
    sync = channels == SYNC
    after_photon = np.zeros(times.size, bool)  # the first sync after each photon or marker
    other = np.flatnonzero(~sync)
    nxt = np.searchsorted(np.flatnonzero(sync), other, side="right")
    keep_sync = np.unique(np.flatnonzero(sync)[nxt[nxt < sync.sum()]])
    after_photon[keep_sync] = True  # (never the first period's: its events come back)
    kept = ~sync | after_photon
    assert (sync & ~kept).sum() > 2000  # of 9600 periods
    for period in (None, L * res):
        got = t3_from_timestamps(times[kept], channels[kept], sync_period_s=period, **kw)
        # (periods from the first sync held to the last, less those held)
        first, last = np.searchsorted(np.flatnonzero(sync), np.flatnonzero(kept & sync)[[0, -1]])
        assert got.n_missing_syncs == int(last - first) + 1 - int((kept & sync).sum())
        assert got.n_before_first_sync > 0 and got.n_markers == M
        for name in ("nsync", "dtime", "channel", "marker"):
            np.testing.assert_array_equal(getattr(got, name), getattr(full, name), name)
        assert got.sync_period_s == pytest.approx(full.sync_period_s, rel=1e-6)


def test_every_other_sync_needs_the_period():
    """With every other sync left out the stream cannot tell the period from twice it: given
    ``sync_period_s`` the events are placed as from the full stream; without it the period
    read is twice the code's (which ``reconstruct``'s sync-period check then refuses)."""
    t = np.array([0, 30, 250, 400, 530, 800, 820])  # syncs every 200 ps, held at 0, 400, 800
    c = np.array([0, 2, 1, 0, 1, 0, 1])
    kw = dict(time_unit_s=1e-12, sync_channel=0, marker_channel=2, resolution_s=10e-12)
    ev = t3_from_timestamps(t, c, sync_period_s=200e-12, **kw)
    assert ev.sync_period_s == pytest.approx(200e-12) and ev.n_missing_syncs == 2
    np.testing.assert_array_equal(ev.nsync, [0, 1, 2, 4])
    np.testing.assert_array_equal(ev.dtime, [0, 5, 13, 2])
    assert t3_from_timestamps(t, c, **kw).sync_period_s == pytest.approx(400e-12)


@pytest.mark.parametrize("change, match", [
    (dict(sync_period_s=300e-12), "not on one period's grid"),
    (dict(times=np.array([0, 10, 100, 100, 200]), channels=np.array([0, 1, 0, 0, 2])),
     "same time"),
    (dict(times=np.array([0, 10, 5, 20])), "non-decreasing"),
    (dict(times=np.array([0.0, 1.0, 2.0, 3.0])), "integers"),
    (dict(channels=np.array([0, 1, 2])), "same length"),
    (dict(channels=np.array([1, 0, 2, 1])), "1 event.*sync_channel"),
    (dict(times=np.array([0, 100, 150, 230]), channels=np.array([0, 0, 1, 0])),
     "not on one period's grid"),
    (dict(channels=np.array([0, 1, 0, 0])), "no event on marker_channel"),
    (dict(channels=np.array([0, 2, 0, 2])), "no photon events"),
    (dict(marker_channel=0), "both 0"),
    (dict(photon_channels=[1, 2]), "distinct channels"),
    (dict(time_unit_s=0.0), "time_unit_s"),
    (dict(marker_input=5), "marker"),
])
def test_bad_streams_are_one_line(change, match):
    kw = dict(times=np.array([0, 10, 100, 200]), channels=np.array([0, 1, 0, 2]),
              time_unit_s=1e-12, sync_channel=0, marker_channel=2, resolution_s=10e-12)
    kw.update(change)
    with pytest.raises(ConfigError, match=match):
        t3_from_timestamps(kw.pop("times"), kw.pop("channels"), **kw)


def test_inputs_are_not_changed():
    t = np.array([0, 10, 100, 150, 200], np.int64)
    c = np.array([0, 2, 0, 1, 0])
    t0, c0 = t.copy(), c.copy()
    t3_from_timestamps(t, c, time_unit_s=1e-12, sync_channel=0, marker_channel=2,
                       resolution_s=10e-12)
    np.testing.assert_array_equal(t, t0)
    np.testing.assert_array_equal(c, c0)


def test_a_delay_on_a_bin_edge_reads_that_bin():
    """Timestamps in ns and 2.7 ns bins: 81 ns after the sync is bin 30 (81 / (2.7e-9 /
    1e-9) is 29.999999999999996 in floating point; the half-ulp guard reads it right)."""
    with pytest.warns(UserWarning, match="2 or 3 of them.*50 %"):  # (unequal bins: said)
        ev = t3_from_timestamps(np.array([0, 1, 81, 200]), np.array([0, 2, 1, 0]),
                                time_unit_s=1e-9, sync_channel=0, marker_channel=2,
                                resolution_s=2.7e-9)
    np.testing.assert_array_equal(ev.dtime, [0, 30])


REAL = Path(__file__).resolve().parents[1].parent / "shared" / "realdata"


@pytest.mark.skipif(not REAL.is_dir(), reason="../shared/realdata is absent")
@pytest.mark.parametrize("name, n_bins, marker", [
    ("tttrlib_MT200_HH400_beads.ptu", 1563, 3),  # HydraHarp, 16 ps, 25.000025 ns sync
    ("hazelnut_z1.ptu", 132, 1),  # PicoHarp, 96.97 ps, 132.18 bins a sync
])
def test_real_files_as_a_filtered_tagger_stream(tmp_path, name, n_bins, marker):
    """A real acquisition's events as a tagger with a conditional filter streams them (a
    sync only in the periods that hold an event: 0.02-0.1 % of them), in integer
    picoseconds: converted back, the histograms per pattern equal the file's. (Two things
    differ by construction, not by the conversion: a PicoHarp records a few photons up to a
    bin past its sync period, which in absolute time lie after the next sync and are placed
    in its first bin, which gains them; and the last
    pattern's dwell ends at the file's last event, a marker on another input that the stream
    leaves out.)"""
    import ptufile

    with ptufile.PtuFile(REAL / name) as f:
        dec = f.decode_records(f.read_records())
        period, res = f.global_resolution, f.tags["MeasDesc_Resolution"]
    sync = dec["time"].astype(np.int64)
    chan, mark = dec["channel"].astype(np.int64), dec["marker"].astype(np.int64)
    photon = chan >= 0
    keep = photon | ((mark & (1 << (marker - 1))) != 0)
    sync, chan, dtime, photon = sync[keep], chan[keep], dec["dtime"][keep], photon[keep]
    at = np.round(sync * period * 1e12 + np.where(photon, (dtime + 0.5) * res * 1e12, 0.0))
    held = np.unique(sync)
    times = np.concatenate([np.round(held * period * 1e12), at]).astype(np.int64)
    channels = np.concatenate([np.full(held.size, 5), np.where(photon, chan + 10, 9)])
    order = np.argsort(times, kind="stable")  # (a sync before the events of its period)
    ev = write_ptu_from_timestamps(tmp_path / "conv.ptu", times[order], channels[order],
                                   time_unit_s=1e-12, sync_channel=5, marker_channel=9,
                                   resolution_s=res, sync_period_s=period,
                                   marker_input=marker,
                                   photon_channels=np.unique(chan[photon]) + 10)
    assert ev.n_missing_syncs > 1000 * held.size
    a = read_ptu_histograms(REAL / name, n_bins, marker=marker, check_sync_period=False)
    b = read_ptu_histograms(tmp_path / "conv.ptu", n_bins, marker=marker,
                            check_sync_period=False)
    inside = int(np.floor(period / res))  # the bins wholly within a sync period
    np.testing.assert_array_equal(b.histograms[:, 1:inside], a.histograms[:, 1:inside])
    # (past the period: hazelnut_z1's 1 photon at dtime 132, beyond its 132 bins; beads none)
    past = int(a.histograms[:, inside:].sum()) + a.n_out_of_range
    assert past <= 2 and b.histograms[:, inside:].sum() == 0 and b.n_out_of_range == 0
    assert b.histograms[:, 0].sum() == a.histograms[:, 0].sum() + past
    np.testing.assert_array_equal(b.periods_per_pattern[:-1], a.periods_per_pattern[:-1])


@pytest.mark.parametrize("given", [False, True])
@pytest.mark.parametrize("clock", [0.0, 2e-5, -5e-5])
def test_sparse_syncs_on_a_fractional_period_and_a_clock_off_by_ppm(given, clock):
    """Syncs held once in 1000-3000 periods (one adjacent pair), a period of 12817.3 ps (not
    whole picoseconds), a tagger's clock 0-50 ppm off the generator's: the grid is read (it
    was refused beyond 250 periods, and at 20 ppm off a given period; a review of
    2026-11-29), each photon in its own period and bin."""
    period = 12817.3 * (1 + clock)  # the generator's period on the tagger's clock
    ks = np.array([0, 1, 1001, 3001, 4001, 7001])
    syncs = np.round(ks * period).astype(np.int64)
    bins = np.array([3, 50, 100, 131, 7])
    photons = np.round((ks[:-1] + 1 + (bins + 0.5) / 132.18) * period).astype(np.int64)
    t = np.concatenate([syncs, photons, [syncs[0] + 5]])
    c = np.concatenate([np.zeros(ks.size, int), np.ones(bins.size, int), [2]])
    o = np.argsort(t, kind="stable")
    ev = t3_from_timestamps(t[o], c[o], time_unit_s=1e-12, sync_channel=0, marker_channel=2,
                            resolution_s=12817.3e-12 / 132.18,
                            sync_period_s=12817.3e-12 if given else None)
    photon = ev.marker == 0
    np.testing.assert_array_equal(ev.nsync[photon], ks[:-1] + 1)
    # (the bins are of the generator's period as the tagger reads it: refined from the syncs)
    np.testing.assert_array_equal(ev.dtime[photon], np.round(bins * (1 + clock)).astype(int))
    assert ev.sync_period_s == pytest.approx(period * 1e-12, rel=1e-8)
    assert ev.n_missing_syncs == 7001 + 1 - ks.size


def _swabian(seed=3):
    """The test scene's stream as a Swabian tagger gives it (int64 ps, int32 channels), its
    event types all time tags."""
    ev, _, _, _ = _events()
    times, channels = _stream(ev, 100.0, np.random.default_rng(seed))
    return times, channels.astype(np.int32), np.zeros(times.size, np.uint8)


KW = dict(time_unit_s=1e-12, sync_channel=SYNC, marker_channel=MARK, resolution_s=1e-10,
          photon_channels=(DET_B, DET_A))


def test_a_tagger_overflow_is_refused_not_read_as_photons():
    """A Swabian tagger's overflow marks (OverflowBegin / OverflowEnd on its unused channel)
    and missed-events tags, given their event types, are refused in one line: without the
    check an audit's overflow tags became photons on channel 0 and its missed-events tag one
    photon more, the lost periods taken for filtered syncs. All time tags: the same events
    as without the types."""
    times, channels, types = _swabian()
    plain = t3_from_timestamps(times, channels, **KW)
    same = t3_from_timestamps(times, channels, event_types=types, **KW)
    np.testing.assert_array_equal(same.nsync, plain.nsync)
    np.testing.assert_array_equal(same.dtime, plain.dtime)
    # an overflow over the 1200th-1450th syncs: the tags there lost, its begin and end kept
    sync_t = times[channels == SYNC]
    lost = (times >= sync_t[1200]) & (times < sync_t[1450])
    unused = np.int32(-134217728)
    t = np.concatenate([times[~lost], [sync_t[1200], sync_t[1450] - 1]])
    c = np.concatenate([channels[~lost], [unused, unused]])
    k = np.concatenate([types[~lost], [2, 3]]).astype(np.uint8)
    o = np.argsort(t, kind="stable")
    with pytest.raises(ConfigError, match=r"2 event\(s\) are not time tags \(overflow begin, "
                                          r"overflow end; the first is event"):
        t3_from_timestamps(t[o], c[o], event_types=k[o], **KW)
    k[o[5]] = 4  # a missed-events tag too
    with pytest.raises(ConfigError, match="missed events, overflow begin"):
        t3_from_timestamps(t[o], c[o], event_types=k[o], **KW)
    with pytest.raises(ConfigError, match="one entry per event"):
        t3_from_timestamps(times, channels, event_types=types[:-1], **KW)


def test_a_gap_in_a_complete_sync_stream_is_refused():
    """A stream that holds every sync (no conditional filter), given ``syncs_complete``,
    refuses a stretch without syncs (a buffer overrun: the pattern there kept its full dwell
    with half its photons, an audit's) and converts the complete stream as before."""
    times, channels, _ = _swabian()
    whole = t3_from_timestamps(times, channels, syncs_complete=True, **KW)
    assert whole.n_missing_syncs == 0
    sync_t = times[channels == SYNC]
    lost = (times >= sync_t[1200]) & (times < sync_t[1450])
    gap = t3_from_timestamps(times[~lost], channels[~lost], **KW)  # (a filter, as far as
    assert gap.n_missing_syncs == 250  # the stream can tell)
    with pytest.raises(ConfigError, match=r"250 period\(s\) without a sync on channel 0, the "
                                          r"first after sync 1199.*syncs_complete"):
        t3_from_timestamps(times[~lost], channels[~lost], syncs_complete=True, **KW)


def test_other_channels_are_not_taken_for_photons_unasked():
    """With photon_channels left out, one channel besides the sync's and the marker's is the
    detector's; with more (a falling edge of the sync, a quTAG's 1 ms tick on 104, a second
    detector) they are to be named: an audit's sync falling edges were read as 2 000 photons
    at one delay, a strong return in every pixel."""
    times, channels, _ = _swabian()
    one = np.where(channels == DET_B, DET_A, channels)
    ev = t3_from_timestamps(times, one, **{**KW, "photon_channels": None})
    assert ev.photon_channels == (DET_A,) and ev.n_photons == int((one == DET_A).sum())
    falling = np.concatenate([times, times[channels == SYNC] + 3000])
    c = np.concatenate([one, np.full(int((channels == SYNC).sum()), -1 - SYNC - 1)])
    o = np.argsort(falling, kind="stable")
    with pytest.raises(ConfigError, match=r"2 channels besides the sync's and the marker's "
                                          r"\(-2, 1\): give photon_channels"):
        t3_from_timestamps(falling[o], c[o], **{**KW, "photon_channels": None})


def test_timestamps_coarser_than_the_bins():
    """A timestamp unit coarser than the delay bin is refused (bins between its ticks stay
    empty: an audit's 1 ns counter in 100 ps bins left 920 of 1 023 empty); one that is not a
    whole fraction of the bin is said (81 ps units in 100 ps bins: 1 or 2 units a bin)."""
    kw = dict(sync_channel=0, marker_channel=2, photon_channels=[1])
    t, c = np.array([0, 1, 5, 20, 40]), np.array([0, 2, 1, 0, 0])
    with pytest.raises(ConfigError, match="coarser than resolution_s"):
        t3_from_timestamps(t, c, time_unit_s=1e-9, resolution_s=1e-10, **kw)
    with pytest.warns(UserWarning, match=r"1\.235 of the timestamps' units.*1 or 2 of them"):
        t3_from_timestamps(t, c, time_unit_s=81e-12, resolution_s=1e-10, **kw)


def test_a_long_stream_converted_in_pieces_is_one_file(tmp_path):
    """The pieces of a stream converted one by one, each given the one before as ``after``,
    and written through ``write_ptu_t3_stream`` give the file of the whole stream: the same
    histograms and dwells (numbered from each piece's first event, an audit's split lost 44
    empty periods of the pattern it cut). Pieces out of order or overlapping are refused."""
    from spslidar.io import write_ptu_t3_stream

    times, channels, _ = _swabian()
    whole = t3_from_timestamps(times, channels, **KW)
    cut = np.flatnonzero(channels == MARK)[5] - 3  # (just before the 6th marker)
    one = t3_from_timestamps(times[:cut], channels[:cut], **KW)
    two = t3_from_timestamps(times[cut:], channels[cut:], after=one, **KW)
    np.testing.assert_array_equal(np.concatenate([one.nsync, two.nsync]), whole.nsync)
    assert two.last_sync_period == whole.last_sync_period
    files = {}
    for name, parts in (("whole", [whole]), ("pieces", [one, two])):
        files[name] = tmp_path / f"{name}.ptu"
        write_ptu_t3_stream(files[name], ((e.nsync, e.dtime, e.channel, e.marker) for e in parts),
                            resolution_s=1e-10, sync_rate_hz=1 / whole.sync_period_s,
                            record_type="GenericT3")
    a, b = (read_ptu_histograms(files[k], L, bin_width=1e-10, n_patterns=M)
            for k in ("whole", "pieces"))
    np.testing.assert_array_equal(b.histograms, a.histograms)
    np.testing.assert_array_equal(b.periods_per_pattern, a.periods_per_pattern)
    with pytest.raises(ConfigError, match="the pieces of one stream, in order"):
        t3_from_timestamps(times, channels, after=one, **KW)  # (again from its start)
    late = np.r_[np.flatnonzero(channels[cut - 40:cut] != SYNC) + cut - 40,
                 np.arange(cut, times.size)]  # (photons of one's last periods, no sync)
    with pytest.raises(ConfigError, match="before the previous piece's last"):
        t3_from_timestamps(times[late], channels[late], after=one, **KW)
    with pytest.raises(ConfigError, match="not a whole number of periods after it"):
        t3_from_timestamps(times[cut:] + 6350, channels[cut:], after=one, **KW)  # (half)
    with pytest.raises(ConfigError, match="after must be the previous piece's T3Events"):
        t3_from_timestamps(times, channels, after=10, **KW)


def test_many_pieces_of_a_jittered_filtered_stream_keep_their_periods():
    """400 000 periods of 12.7 ns, syncs jittered by +-10 ps and held only after a photon (a
    conditional filter), in 20 pieces each numbered on from the one before (the period given,
    as a piece seldom holds syncs of adjacent periods): every event in the period the whole
    stream gives it. (A first design, each piece given the first
    piece's time origin, extrapolated each piece's period back over the whole stream and
    refused the 9th-32nd piece: a review.)"""
    rng = np.random.default_rng(4)
    n, period = 400_000, 12_700.0
    sync = np.round(np.arange(n) * period + rng.uniform(-10, 10, n)).astype(np.int64)
    hot = np.sort(rng.choice(n - 1, 4000, replace=False))
    photon = sync[hot] + rng.integers(0, 12_600, hot.size)
    marker = sync[::20_000] + 5
    keep = np.unique(np.r_[hot + 1, np.arange(0, n, 20_000), [0, 1]])  # (after a photon)
    t = np.concatenate([sync[keep], photon, marker])
    c = np.concatenate([np.zeros(keep.size, int), np.ones(photon.size, int),
                        np.full(marker.size, 2)])
    o = np.argsort(t, kind="stable")
    t, c = t[o], c[o]
    kw = dict(time_unit_s=1e-12, sync_channel=0, marker_channel=2, resolution_s=1e-10,
              sync_period_s=12.7e-9)  # (a piece's syncs are rarely of adjacent periods)
    whole = t3_from_timestamps(t, c, **kw)
    pieces, prev = [], None
    for part in np.array_split(np.arange(t.size), 20):
        prev = t3_from_timestamps(t[part], c[part], after=prev, **kw)
        pieces.append(prev.nsync)
    np.testing.assert_array_equal(np.concatenate(pieces), whole.nsync)


def test_a_period_too_long_for_the_records_names_the_resolution(tmp_path):
    """A 10 us code period in 100 ps bins is 100 000 delays, beyond a GenericT3 record's
    32 768: refused naming the resolution (it was the writer's bare "dtime out of range")."""
    t = np.array([0, 5, 15_000_000, 10_000_000, 20_000_000])
    c = np.array([0, 2, 1, 0, 0])
    o = np.argsort(t)
    with pytest.raises(ConfigError, match="100000 delay units of resolution_s 1e-10 s, more "
                                          "than GenericT3 records hold"):
        write_ptu_from_timestamps(tmp_path / "x.ptu", t[o], c[o], time_unit_s=1e-12,
                                  sync_channel=0, marker_channel=2, resolution_s=1e-10)
    assert not (tmp_path / "x.ptu").exists()


def test_review_edges_of_the_new_parameters(tmp_path):
    """A review's cases: the records' delay range is checked on the period, not on where the
    photons fell (a 500 ns period in 100 ps bins went into PicoHarp records when the photons
    were early); the message names the record type as registered; ``syncs_complete`` must be
    a bool, and refuses events more than a period beyond the syncs held; a time unit equal
    to the bin but for rounding is not "coarser"."""
    t = np.array([0, 5, 100, 500_000, 1_000_000])  # (a photon 100 ps after the first sync)
    c = np.array([0, 2, 1, 0, 0])
    kw = dict(time_unit_s=1e-12, sync_channel=0, marker_channel=2, resolution_s=1e-10)
    with pytest.raises(ConfigError, match="5000 delay units .* more than PicoHarpT3 records"):
        write_ptu_from_timestamps(tmp_path / "x.ptu", t, c, record_type="picoharpt3", **kw)
    assert not (tmp_path / "x.ptu").exists()
    with pytest.raises(ConfigError, match="syncs_complete must be True or False"):
        t3_from_timestamps(t, c, syncs_complete="no", **kw)
    far = np.array([0, 5, 100, 500_000, 1_000_000, 2_600_000])
    with pytest.raises(ConfigError, match="1 event.* more than a period .* syncs_complete"):
        t3_from_timestamps(far, np.r_[c, 1], syncs_complete=True, **kw)
    assert t3_from_timestamps(far, np.r_[c, 1], **kw).n_photons == 2
    same = t3_from_timestamps(t, c, time_unit_s=1e-9, sync_channel=0, marker_channel=2,
                              resolution_s=1e-9 * (1 - 1e-12))
    assert same.n_photons == 1
