"""A third-party stage's output as a run takes it (an outside plugin-author audit of
2026-11-30: the conformance kit caught each of these, ``spslidar run`` did not): a detector
model's negative counts, a scene kind that ignores its depth window, a pattern kind's wrong
shape, mirror states or adjoint, each refused in one line naming the stage, nothing written;
and a run's record of the plugins loaded, the code's fingerprint and a replaced built-in."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

import spslidar
from spslidar.cli import main
from spslidar.detectors import DETECTORS
from spslidar.detectors.linear import LinearDetector
from spslidar.errors import ConfigError

SMALL = dict(size=8, code_length=127, scene="steps", depth_min=1.0, depth_max=1.6,
             range_gate=(0.8, 1.8))
SMALL_ARGS = ["--size", "8", "--code-length", "127", "--scene", "steps", "--depth-min", "1",
              "--depth-max", "1.6", "--range-gate", "0.8", "1.8", "--no-figure"]


@pytest.fixture(autouse=True)
def _plugin_state(plugin_state, monkeypatch):
    """Each test leaves the plugins it loaded behind it (``conftest.plugin_state``), and the
    environment's plugins out."""
    import spslidar.plugins as plugins

    monkeypatch.setenv(plugins.ENV, "")


def _one_line_refusal(capsys, args, out, match):
    """``main(args)`` exits 2 with one line on stderr matching ``match``, and writes nothing."""
    import re

    capsys.readouterr()
    assert main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.search(match, err[0]), err
    assert not out.exists()


# -- 1. a detector model's counts, bin by bin ---------------------------------------------

@dataclass
class _Faulty(LinearDetector):
    """The paper's counter, with one fault: ``minus-one`` (``poisson(mean) - 1``), ``short``
    (a bin short), ``nan``, or ``totals`` (one total too few); in a noiseless run's
    ``expected()``: ``expected-negative`` (the mean less one) or ``expected-short``."""

    fault: str = "minus-one"
    name = "faulty"

    def detect(self, lam, rng, n_periods=1, out=None):
        counts, totals = super().detect(lam, rng, n_periods, out=out)
        if self.fault == "minus-one":
            counts -= 1
            return counts, counts.sum(axis=1)
        if self.fault == "short":
            return counts[:, :-1], totals
        if self.fault == "nan":
            return counts * np.nan, totals
        return counts, totals[:-1]

    def expected(self, lam, n_periods=1):
        mean = super().expected(lam, n_periods)
        if self.fault == "expected-negative":
            return mean - 1.0  # (below zero where the flux is low)
        if self.fault == "expected-short":
            return mean[:, :-1]
        return mean


@pytest.fixture
def faulty():
    def add(fault):
        DETECTORS.add("faulty", lambda **kw: _Faulty(fault=fault), "faulty", "a fault")

    try:
        yield add
    finally:
        DETECTORS._entries.pop("faulty", None)


@pytest.mark.parametrize("fault,match", [
    ("minus-one", r"the detector model 'faulty' \(_Faulty\) returned negative counts \(down "
                  r"to -1 in a bin\) from its detect\(\)"),
    ("short", r"'faulty' \(_Faulty\) returned histograms of shape \(16, 126\) from its "
              r"detect\(\) for \(16, 127\)"),
    ("nan", r"'faulty' \(_Faulty\) returned histograms that are not finite"),
    ("totals", r"'faulty' \(_Faulty\) returned totals of shape \(15,\) from its detect\(\) "
               r"for 16 patterns")])
def test_a_linear_detectors_counts_are_checked(faulty, fault, match):
    """A plugin's linear model was not checked at all (only the non-linear ones were): its
    ``poisson(mean) - 1`` at a low flux ended in correlate.py's 33-line traceback "totals
    holds a negative count", and at a high one ran with its bias."""
    faulty(fault)
    with pytest.raises(ConfigError, match=match):
        spslidar.run(**SMALL, detector="faulty", noise=0.001, signal=0.01)


@pytest.mark.parametrize("fault,match", [
    ("expected-negative", r"'faulty' \(_Faulty\) returned negative counts \(down to -0\.99\d* "
                          r"in a bin\) from its expected\(\)"),
    ("expected-short", r"'faulty' \(_Faulty\) returned histograms of shape \(16, 126\) from "
                       r"its expected\(\) for \(16, 127\)")])
def test_a_noiseless_runs_expected_counts_are_checked(faulty, fault, match):
    """A noiseless run takes the model's ``expected()`` instead of its draws: the same check
    holds there (a review of stop 64 found that guard without a test of its own)."""
    faulty(fault)
    with pytest.raises(ConfigError, match=match):
        spslidar.run(**SMALL, detector="faulty", noiseless=True, noise=1e-6, signal=1e-5)


def test_a_detectors_negative_counts_are_one_line(faulty, capsys, tmp_path):
    faulty("minus-one")
    _one_line_refusal(capsys, ["run", *SMALL_ARGS, "--detector", "faulty", "--noise", "0.001",
                               "--signal", "0.01"], tmp_path / "o",
                      r"^spslidar run: error: the detector model 'faulty' .* negative counts")


def test_the_builtin_detectors_pass_the_check():
    """The built-in models, where most bins hold no count and (the linear counter) at the
    default flux, noiseless too (``expected()`` is checked there; a noiseless GMAPD run takes
    half a minute: the GMAPD suites run it)."""
    low = dict(noise=0.001, signal=0.01)
    for detector, flux in (("linear", low), ("linear", {}), ("linear", {"noiseless": True}),
                           ("gmapd", low)):
        assert spslidar.run(**SMALL, detector=detector, **flux).depth.shape == (8, 8)


# -- 2. a scene kind's depth window -------------------------------------------------------

def _fixed(size, depth_min=None, depth_max=None):
    """A plugin's slanted wall at 5-6 m, whatever the window."""
    from spslidar.scenes import Scene

    depth = np.linspace(5.0, 6.0, size * size).reshape(size, size)
    return Scene("fixed", depth, np.full((size, size), 0.7), np.ones((size, size), bool))


def _float32_wall(size, depth_min=None, depth_max=None):
    """A wall that fills its window by a remap computed in float32 (its round-off, 6e-8 of
    the depth, is no fault)."""
    from spslidar.scenes import Scene

    lo, hi = (5.0 if depth_min is None else depth_min), (6.0 if depth_max is None else depth_max)
    t = np.linspace(0, 1, size * size, dtype=np.float32).reshape(size, size)
    depth = (np.float32(lo) + t * np.float32(hi - lo)).astype(np.float32) * np.float32(1.0000001)
    return Scene("f32", depth, np.full((size, size), 0.7), np.ones((size, size), bool))


@pytest.fixture
def scenes():
    from spslidar.scenes import SCENES

    SCENES.add("fixed", _fixed, "fixed", "5-6 m, whatever the window")
    SCENES.add("f32", _float32_wall, "f32", "a float32 remap")
    try:
        yield
    finally:
        SCENES._entries.pop("fixed", None)
        SCENES._entries.pop("f32", None)


def test_a_scene_kind_that_ignores_the_window_is_refused(scenes, capsys, tmp_path):
    """``--depth-min 3 --depth-max 4`` ran a plugin's 5-6 m scene without a word, and
    metrics.json recorded the window."""
    from spslidar.errors import SceneError
    from spslidar.scenes import load_scene

    with pytest.raises(SceneError, match=r"scene kind 'fixed' ignores the depth window: asked "
                                         r"for \[3, 4\] m, its depths span \[5, 6\] m"):
        spslidar.run(**{**SMALL, "scene": "fixed", "depth_min": 3.0, "depth_max": 4.0,
                        "range_gate": None})
    with pytest.raises(SceneError, match=r"asked for depths from 5.5 m"):
        load_scene("fixed", 8, 5.5)  # one end given: that end is held
    with pytest.raises(SceneError, match=r"asked for depths to 5.5 m"):
        load_scene("fixed", 8, None, 5.5)
    _one_line_refusal(capsys, ["run", "--size", "8", "--code-length", "127", "--scene", "fixed",
                               "--depth-min", "3", "--depth-max", "4", "--no-figure"],
                      tmp_path / "o", r"^spslidar run: error: scene kind 'fixed' ignores")
    assert load_scene("fixed", 8).depth.max() == 6.0  # no window asked for: its own
    assert load_scene("fixed", 8, 4.0, 7.0).depth.min() == 5.0  # inside the window
    load_scene("f32", 8, 3.0, 4.0)  # float32 round-off of the window's ends



@pytest.mark.parametrize("past,refused", [(5e-6, False), (1e-5, True), (1e-3, True)])
def test_the_windows_tolerance_is_round_off_only(past, refused):
    """1e-6 of the window's far end (6 um at 6 m): a scene 5 um past a [5, 6] m window's ends
    is round-off, 10 um (a thousandth of a 1.5 cm bin) is refused, and so is 1 mm (a review
    of stop 64 found the tolerance without a test of its bound)."""
    from spslidar.errors import SceneError
    from spslidar.scenes import SCENES, Scene, load_scene

    def nudged(size, depth_min=None, depth_max=None):
        depth = np.linspace(5.0, 6.0, size * size).reshape(size, size) + past
        return Scene("nudged", depth, np.full((size, size), 0.7), np.ones((size, size), bool))

    SCENES.add("nudged", nudged, "nudged", "5-6 m, nudged far")
    try:
        if refused:
            with pytest.raises(SceneError, match=r"scene kind 'nudged' ignores the depth "
                                                 r"window: asked for \[5, 6\] m"):
                load_scene("nudged", 8, 5.0, 6.0)
        else:
            assert load_scene("nudged", 8, 5.0, 6.0).depth.max() == pytest.approx(6.0 + past)
    finally:
        SCENES._entries.pop("nudged", None)


def test_the_builtin_scenes_fill_their_window():
    """What the check holds a plugin to, every built-in kind holds, valid pixel or not (a
    linear remap in float64), in windows of either end or both."""
    from spslidar.scenes import SCENES, load_scene

    for entry in SCENES:
        name = entry.name + (":3" if entry.defaults.get("argument") else "")
        for window in ((3.0, 4.0), (20.0, 20.0000001), (0.5, None), (None, 300.0)):
            depth = load_scene(name, 16, *window).depth
            lo, hi = window
            assert lo is None or depth.min() >= lo, (name, window)
            assert hi is None or depth.max() <= hi, (name, window)


# -- 3. a pattern kind's shape, mirror states and adjoint ---------------------------------

def _pattern_operator(matrix, adjoint_scale=1.0):
    """A plugin's own operator (not a :class:`DensePatterns`, whose constructor reads its
    matrix) with a given matrix, its adjoint scaled by ``adjoint_scale``."""
    from spslidar.patterns.base import PatternOperator

    class Mine(PatternOperator):
        def __init__(self):
            super().__init__(matrix.shape, matrix.dtype)

        def _matvec(self, x):
            return matrix @ x.astype(self.dtype)

        def _rmatvec(self, y):
            return (adjoint_scale * (matrix.T @ y.astype(self.dtype))).astype(self.dtype)

    return Mine()


def _fewrows(kind, m, n, rng, dtype, **_):
    from spslidar.patterns.dense import DensePatterns

    return DensePatterns((rng.random((m // 2, n * n)) < 0.5).astype(dtype), kind)


def _negative(kind, m, n, rng, dtype, **_):
    return _pattern_operator(-np.clip(0.5 + 0.25 * rng.standard_normal((m, n * n)), 0, 1)
                             .astype(dtype))


def _wrong_adjoint(kind, m, n, rng, dtype, **_):
    return _pattern_operator((rng.random((m, n * n)) < 0.5).astype(dtype), 1.1)


def _own(kind, m, n, rng, dtype, **_):
    return _pattern_operator((rng.random((m, n * n)) < 0.5).astype(dtype))


@pytest.fixture
def pattern_kinds():
    from spslidar.patterns import PATTERNS

    kinds = {"fewrows": _fewrows, "negative": _negative, "wrong-adjoint": _wrong_adjoint,
             "own": _own}
    for name, factory in kinds.items():
        PATTERNS.add(name, factory, name, "a plugin's", dense=True)
    try:
        yield
    finally:
        for name in kinds:
            PATTERNS._entries.pop(name, None)


@pytest.mark.parametrize("kind,match", [
    ("fewrows", r"the pattern kind 'fewrows' made patterns of shape \(8, 64\) for 16 patterns "
                r"over 8 x 8 mirrors"),
    ("negative", r"the pattern kind 'negative' made mirror states in \[-1, 0\] .* not \[0, 1\]"),
    ("wrong-adjoint", r"the pattern kind 'wrong-adjoint': its adjoint is not its transpose")])
def test_a_pattern_kinds_output_is_checked(pattern_kinds, kind, match):
    """A factory of M // 2 rows ran ("32 fewrows patterns"), mirror states in [-1, 0] ran
    with mean_signal_counts_per_pattern -1029, an adjoint 1.1 times the transpose ran."""
    with pytest.raises(ConfigError, match=match):
        spslidar.run(**SMALL, patterns=kind)


@pytest.mark.parametrize("kind", ["fewrows", "negative"])
def test_a_pattern_kinds_output_is_checked_on_another_backend(pattern_kinds, kind):
    """The device path builds a plugin's set on the host and copies it: it ran under
    ``array-api-strict`` with half its rows or negative mirror states (a review)."""
    with pytest.raises(ConfigError, match=f"the pattern kind '{kind}' made"):
        spslidar.run(**SMALL, patterns=kind, backend="array-api-strict")


def test_a_pattern_kinds_fault_is_one_line(pattern_kinds, capsys, tmp_path):
    _one_line_refusal(capsys, ["run", *SMALL_ARGS, "--patterns", "negative"], tmp_path / "o",
                      r"^spslidar run: error: the pattern kind 'negative' made mirror states")
    assert spslidar.run(**SMALL, patterns="own").depth.shape == (8, 8)  # a sound one runs


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_builtin_pattern_kinds_pass_the_check(dtype):
    """Every built-in kind, each Hadamard realisation (differential: a +-1 operator, whose
    two DMD frames are what is read), at a few sizes and compressions."""
    from spslidar.patterns import HADAMARD_REALISATIONS, PATTERNS, build_patterns
    from spslidar.patterns.dense import check_pattern_set

    for kind in PATTERNS.names():
        for n, m in ((4, 2), (8, 16), (32, 256), (64, 1024)):
            for realisation in HADAMARD_REALISATIONS:
                op = build_patterns(kind, m, n, np.random.default_rng(n), dtype=dtype,
                                    realisation=realisation)
                check_pattern_set(op, kind, m, n)


# -- 4. what ran: plugins, the code's fingerprint, a replaced built-in --------------------

REPLACING = '''
from spslidar.depth import ESTIMATORS
from spslidar.depth.censor import CensorDepth


class Other(CensorDepth):
    name = "argmax"


ESTIMATORS.add("argmax", Other, "argmax", "censor under argmax's name")
'''


def test_a_replaced_builtin_and_the_plugins_are_recorded(tmp_path, capsys):
    """``--plugin`` re-registering ``argmax`` as another estimator warned at load, but
    metrics.json said ``depth: "argmax"`` with no warning, and named neither the plugins
    nor the code's fingerprint."""
    import json

    from spslidar.depth import ESTIMATORS
    from spslidar.plugins import code_fingerprint

    plugin = tmp_path / "replacing.py"
    plugin.write_text(REPLACING)
    out = tmp_path / "o"
    try:
        assert main(["--plugin", str(plugin), "run", *SMALL_ARGS, "--depth", "argmax",
                     "--out", str(out)]) == 0
        err = capsys.readouterr().err
        m = json.loads((out / "metrics.json").read_text())
        fingerprint = code_fingerprint()  # (the plugin's file is in it)
    finally:
        ESTIMATORS.remove("argmax")  # the built-in comes back
    said = ("the depth estimator 'argmax' ('spslidar.depth.argmax:ArgmaxDepth') is replaced "
            "by <class 'spslidar_plugin_replacing.Other'>")
    assert said in m["warnings"]
    # (the last loaded: the plugins other tests loaded in this process stay loaded, as they
    # would in a notebook; a fresh command's list is its own --plugin's)
    assert m["plugins"][-1] == str(plugin.resolve())
    assert m["code_fingerprint"] == fingerprint and len(fingerprint) == 16
    assert err.count(said) == 1, err  # said at the load, not again by the run


def test_a_run_without_a_replaced_stage_says_none():
    from spslidar.plugins import code_fingerprint, load_plugins

    r = spslidar.run(**SMALL, depth="argmax")
    assert r.metrics["plugins"] == load_plugins([])  # (none, unless the session loaded some)
    assert r.metrics["code_fingerprint"] == code_fingerprint()
    assert not any("is replaced by" in w for w in r.metrics["warnings"])
