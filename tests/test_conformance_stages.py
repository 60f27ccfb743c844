"""Conformance suites over the stage registries, discovered: every registered code family,
pattern kind, detector model, depth estimator and scene kind is held by the checks of
:mod:`spslidar.testing` (the same ones ``spslidar check`` runs on a plugin's stages), so a new
entry is tested without touching this file (and fails here if it breaks the contract). Solvers
and regularisers have theirs in ``test_solver_conformance.py``. Below them, the checks are
shown to fail on stages that break each contract (a check that cannot fail tests nothing).

* codes: the length asked for, 0/1 bits, reproducible from the generator, a share of ones the
  family promises, and a periodic correlation with a single peak (what the matched filter of
  eq. 5-6 needs);
* pattern operators: the adjoint (dot) test for single and batched columns, the dtype asked
  for, mirror states in [0, 1] as the DMD shows them, no side effect on the input, the same
  patterns from the same seed;
* detectors: the mean of ``detect`` is ``expected`` (Monte Carlo, 5 standard errors), and
  ``correct`` inverts ``expected`` at low flux;
* depth estimators: noiseless recovery of a depth map with a one-pixel pole, a step and a
  slanted plane, confidence in [0, 1], no depth where no pixel has a return.
"""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.codes import CODES
from spslidar.depth import ESTIMATORS
from spslidar.depth.argmax import ArgmaxDepth
from spslidar.detectors import DETECTORS
from spslidar.detectors.linear import LinearDetector
from spslidar.patterns import PATTERNS
from spslidar.registry import Option
from spslidar.scenes import SCENES
from spslidar.testing import check_stage, check_stages, is_plugin


@pytest.mark.parametrize("name", CODES.names())
def test_code_family_contract(name):
    assert "single correlation peak" in check_stage("code", name)


@pytest.mark.parametrize("name", PATTERNS.names())
def test_pattern_operator_contract(name):
    assert "adjoint" in check_stage("patterns", name)


@pytest.mark.parametrize("name", DETECTORS.names())
def test_detector_contract(name):
    assert "mean of detect is expected" in check_stage("detector", name)


@pytest.mark.parametrize("name", ESTIMATORS.names())
def test_depth_estimator_contract(name):
    assert "no depth without returns" in check_stage("depth", name)


@pytest.mark.parametrize("name", SCENES.names())
def test_scene_kind_contract(name):
    assert "rescaled into a window" in check_stage("scene", name)


# -- the checks fail where a stage breaks its contract ------------------------------------------
def _bad_code(kind, length, ones_ratio, rng=None, index=0, **_):
    code = np.zeros(length, np.uint8)
    code[: (length + 1) // 2] = 1  # balanced, but one long run: sidelobes near the peak
    return code


def _unbalanced(kind, length, ones_ratio, rng=None, index=0, **_):
    return (rng.random(length) < 0.1).astype(np.uint8)


def _deaf(kind, length, ones_ratio, rng=None, index=0, **_):
    """A good m-sequence for every index asked for (a known limit of stop 51: passed)."""
    from spslidar.codes import make_code

    return make_code("mseq", length, index=0)


class _Leaky(LinearDetector):
    """Loses a fifth of the photons ``expected`` promises."""

    name = "leaky"

    def detect(self, lam, rng, n_periods=1, out=None):
        counts, _ = super().detect(0.8 * lam, rng, n_periods, out)
        return counts, counts.sum(axis=1)


class _Shifted(ArgmaxDepth):
    """Argmax, one bin late."""

    name = "shifted"

    def estimate(self, slices, ctx):
        est = super().estimate(slices, ctx)
        est.depth = est.depth + 0.015
        return est


class _Dirty(ArgmaxDepth):
    """Argmax that zeroes the slices it is given."""

    name = "dirty"

    def estimate(self, slices, ctx):
        est = super().estimate(slices.copy(), ctx)
        slices[...] = 0
        return est


def _scaled_patterns(kind, m, n, rng, dtype, **_):
    from spslidar.patterns.dense import DensePatterns

    pats = DensePatterns(rng.random((m, n * n)).astype(dtype))
    pats.matrix = 2.0 * pats.matrix  # mirrors at 2, past the constructor's own check
    return pats


def _bad_mean(kind, m, n, rng, dtype, **_):
    """Patterns whose mean pattern forgets to divide by M (QCR then centres wrongly: RMSE
    0.0048 -> 0.051 m and 55 % of the pixels lost, an audit)."""
    from spslidar.patterns.dense import DensePatterns

    class Bad(DensePatterns):
        def mean_pattern(self):
            return super().mean_pattern() * self.shape[0]

    return Bad((rng.random((m, n * n)) < 0.5).astype(dtype))


def _big_patterns(kind, m, n, rng, dtype, **_):
    """A pattern kind that needs sides that are multiples of 16 (superpixels)."""
    from spslidar.errors import ConfigError
    from spslidar.patterns.dense import DensePatterns

    if n % 16:
        raise ConfigError(f"superpixel patterns need a multiple of 16, not {n}")
    return DensePatterns((rng.random((m, n * n)) < 0.5).astype(dtype))


class _Optimist(LinearDetector):
    """Promises 2 % more counts than it detects."""

    name = "optimist"

    def expected(self, lam, n_periods=1):
        return 1.02 * super().expected(lam, n_periods)


class _Late(ArgmaxDepth):
    """Argmax, a whole bin late when asked for sub-bin depths."""

    name = "late"

    def estimate(self, slices, ctx):
        est = super().estimate(slices, ctx)
        if ctx.subbin:
            est.depth = est.depth + 0.015
        return est


class _Filler(ArgmaxDepth):
    """Argmax that gives a pixel without a return the first lag's depth."""

    name = "filler"

    def estimate(self, slices, ctx):
        from spslidar.constants import SPEED_OF_LIGHT

        est = super().estimate(slices, ctx)
        est.depth = np.where(np.isnan(est.depth) & np.isfinite(est.depth).any(),
                             ctx.lags[0] * SPEED_OF_LIGHT * ctx.bin_width / 2, est.depth)
        return est


def _flat(size, depth_min=None, depth_max=None):
    from spslidar.scenes.base import Scene

    # flat: its own 5 m where the window holds it, else the window's nearer end
    lo = 0.0 if depth_min is None else depth_min
    hi = np.inf if depth_max is None else depth_max
    depth = min(max(5.0, lo), hi)
    return Scene("wall", np.full((size, size), depth), np.full((size, size), 0.7),
                 np.ones((size, size), bool))


def _near_only(size, depth_min=None, depth_max=None):
    """A slanted wall that reads its window's near end and keeps its own 1 m span (a known
    limit of stop 51: the one [7, 8] m probe window passed it)."""
    from spslidar.scenes.base import Scene

    near = 5.0 if depth_min is None else depth_min
    depth = near + np.tile(np.linspace(0.0, 1.0, size), (size, 1))
    return Scene("ramp", depth, np.full((size, size), 0.7), np.ones((size, size), bool))


@pytest.fixture
def broken():
    added = [(CODES, "run"), (CODES, "sparse10"), (CODES, "deaf"), (DETECTORS, "leaky"),
             (ESTIMATORS, "shifted"), (ESTIMATORS, "dirty"), (PATTERNS, "bright"),
             (PATTERNS, "bad-mean"), (DETECTORS, "optimist"), (ESTIMATORS, "late"),
             (ESTIMATORS, "filler"), (SCENES, "near-only")]
    CODES.add("run", _bad_code, "run", "one long run", index=0)
    CODES.add("sparse10", _unbalanced, "sparse", "a tenth of ones", index=0)
    CODES.add("deaf", _deaf, "deaf", "ignores its index", index=0)
    DETECTORS.add("leaky", _Leaky, "leaky", "loses photons")
    DETECTORS.add("optimist", _Optimist, "optimist", "expects 2 % too many")
    ESTIMATORS.add("shifted", _Shifted, "shifted", "one bin late")
    ESTIMATORS.add("dirty", _Dirty, "dirty", "zeroes its input")
    ESTIMATORS.add("late", _Late, "late", "a bin late with --subbin")
    ESTIMATORS.add("filler", _Filler, "filler", "fills pixels without returns")
    SCENES.add("near-only", _near_only, "near only", "ignores the window's far end")
    PATTERNS.add("bright", _scaled_patterns, "bright", "mirror states up to 2", dense=True)
    PATTERNS.add("bad-mean", _bad_mean, "bad mean", "mean pattern x M", dense=True)
    try:
        yield
    finally:
        for reg, name in added:
            reg._entries.pop(name, None)


@pytest.mark.parametrize("kind,name,why", [
    ("code", "run", "sidelobe"), ("code", "sparse10", "not about half"),
    ("code", "deaf", "index 1 gives the same code as index 0"),
    ("detector", "leaky", "detections' totals"),
    ("detector", "optimist", r"detections' totals .* \(-1.9 %"),
    ("depth", "shifted", "noiseless recovery: 144 of 144 pixels wrong"),
    ("depth", "dirty", "changed the slices"), ("patterns", "bright", "mirror states in"),
    ("patterns", "bad-mean", r"mean_pattern\(\) is not the patterns' mean"),
    ("depth", "late", "more than half a bin from"),
    ("depth", "filler", r"hold no return, among pixels that do"),
    ("scene", "near-only", r"rescaled into \[3, 5.5\] m it spans \[3, 4\]")])
def test_checks_fail_on_broken_stages(broken, kind, name, why):
    with pytest.raises(AssertionError, match=why):
        check_stage(kind, name)


@pytest.fixture
def legitimate():
    """Stages an audit's plugin wrote that the checks refused: a detector of efficiency 0.5
    (its correct() leaves the efficiency, as the built-in linear counter's does), patterns
    that need sides of 16, a flat wall, a built-in class registered under a new name."""
    from spslidar.patterns.dense import DensePatterns  # noqa: F401  (the factory's import)

    added = [(DETECTORS, "half"), (PATTERNS, "superpixel"), (SCENES, "wall"),
             (ESTIMATORS, "argmax-strict")]
    DETECTORS.add("half", LinearDetector, "half", "efficiency 0.5",
                  options=(Option("efficiency", 1.0, "detection efficiency", lo=0, hi=1,
                                  lo_open=True),))
    PATTERNS.add("superpixel", _big_patterns, "superpixel", "sides of 16", dense=True,
                 check={"size": 16})
    SCENES.add("wall", _flat, "wall", "a flat wall")
    ESTIMATORS.add("argmax-strict", ArgmaxDepth, "strict argmax", "argmax, another name")
    try:
        yield
    finally:
        for reg, name in added:
            reg._entries.pop(name, None)


def test_checks_pass_legitimate_stages(legitimate, monkeypatch):
    from spslidar.config import Config

    original = Config.from_dict.__func__

    def half_efficiency(cls, data=None, **kw):  # the plugin's option set to 0.5
        data = dict(data or {})
        if data.get("detector") == "half":
            data["efficiency"] = 0.5
        return original(cls, data, **kw)

    monkeypatch.setattr(Config, "from_dict", classmethod(half_efficiency))
    assert "correct undoes the non-linearity" in check_stage("detector", "half")
    assert "adjoint" in check_stage("patterns", "superpixel")
    assert "rescaled into a window" in check_stage("scene", "wall")
    plugins = [(r.kind, r.name) for r in check_stages(plugins_only=True)]
    assert plugins == [("patterns", "superpixel"), ("detector", "half"),
                       ("depth", "argmax-strict"), ("scene", "wall")], plugins


def test_check_stages_keeps_failures_and_selects_plugins(broken):
    seen = []
    res = check_stages(["code", "depth"], plugins_only=True, on_result=seen.append)
    assert [(r.kind, r.name, r.ok) for r in res] == [
        ("code", "run", False), ("code", "sparse10", False), ("code", "deaf", False),
        ("depth", "shifted", False),
        ("depth", "dirty", False), ("depth", "late", False), ("depth", "filler", False)]
    assert seen == res and all(r.error and not r.passed for r in res)
    assert not is_plugin(CODES.get("mseq")) and is_plugin(CODES.get("run"))
    with pytest.raises(ValueError, match="unknown stage kind 'codes'"):
        check_stage("codes", "mseq")
    with pytest.raises(ValueError, match="unknown code family 'nope'; choose one of mseq"):
        check_stage("code", "nope")


def test_check_command(broken, capsys):
    # (names in any case, as the registries read them; each stage once: an outside audit)
    assert main(["check", "depth:argmax", "CODE:MSeq", "depth:argmax"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("ok    depth argmax (5 contracts, ")
    assert out[1].startswith("ok    code mseq (")
    assert out[-1] == ("2 of 2 stages pass their contracts (each built with its options at "
                       "their defaults)")
    assert main(["check", "--plugins-only", "depth"]) == 1
    cap = capsys.readouterr()
    assert cap.out.splitlines()[0].startswith(
        "FAIL  depth shifted: depth estimator 'shifted': noiseless recovery")
    assert cap.out.splitlines()[-1].startswith("0 of 4 stages pass their contracts")
    assert not cap.err
    for argv, why in ((["check", "nope"], "unknown stage kind 'nope'"),
                      (["check", "depth:nope"], "unknown depth estimator 'nope'"),
                      (["check", "--plugins-only", "solver"], "no stage to check")):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("spslidar check: error: ") and why in err
        assert len(err.strip().splitlines()) == 1


HASHED = '''
import numpy as np
from spslidar.codes import CODES
from spslidar.scenes import SCENES
from spslidar.scenes.base import Scene


def hashed(kind, length, ones_ratio, rng=None, index=0, **_):
    """An m-sequence's balance, cyclically shifted by Python's hash of a string."""
    from spslidar.codes import make_code

    return np.roll(make_code("mseq", length, index=index), hash(kind + "x") % length)


def fixed(kind, length, ones_ratio, rng=None, index=0, **_):
    from spslidar.codes import make_code

    return make_code("mseq", length, index=index)


def hashed_scene(size, depth_min=None, depth_max=None):
    lo = 5.0 if depth_min is None else depth_min
    hi = lo + 1.0 if depth_max is None else depth_max
    rng = np.random.default_rng(abs(hash("wall")))
    depth = lo + (hi - lo) * rng.random((size, size))
    depth.flat[0], depth.flat[1] = lo, hi
    return Scene("noisy", depth, np.full((size, size), 0.7), np.ones((size, size), bool))


CODES.add("hashed", hashed, "hashed", "shifted by hash()", index=0)
CODES.add("fixed", fixed, "fixed", "an m-sequence", index=0)
SCENES.add("hashed-wall", hashed_scene, "hashed wall", "random depths from hash()")
'''


@pytest.fixture
def hashed_plugin(tmp_path, monkeypatch):
    import spslidar.plugins as plugins

    path = tmp_path / "hashed_stages.py"
    path.write_text(HASHED)
    monkeypatch.setenv(plugins.ENV, "")
    plugins.load_plugins([str(path)])
    try:
        yield
    finally:
        for reg, name in ((CODES, "hashed"), (CODES, "fixed"), (SCENES, "hashed-wall")):
            reg._entries.pop(name, None)
        plugins._LOADED.clear()


def test_a_stage_seeded_from_hash_fails_in_a_fresh_process(hashed_plugin):
    """A code or scene drawn from Python's ``hash`` passed every check made in one process (a
    known limit of stop 51); a new interpreter under another PYTHONHASHSEED builds another."""
    with pytest.raises(AssertionError, match="another output in a fresh process"):
        check_stage("code", "hashed")
    with pytest.raises(AssertionError, match="another output in a fresh process"):
        check_stage("scene", "hashed-wall")
    assert "the same in a fresh process" in check_stage("code", "fixed")
    assert "the same in a fresh process" in check_stage("code", "mseq")


def test_a_stage_registered_in_this_process_only_is_not_checked_afresh(broken):
    """A stage a test registered has no module a new interpreter can import: that contract is
    left out, not failed."""
    from spslidar.testing.process import fresh_digest

    assert fresh_digest("scene", "near-only") is None


def test_check_says_a_plugin_that_replaces_a_built_in(capsys):
    """A plugin's own ``argmax`` was checked as "ok    depth argmax", the replacement unsaid
    where ``run`` warns of it (an outside audit of a plugin developer); taken back, the
    built-in is checked as before."""
    from spslidar.depth import ESTIMATORS
    from spslidar.depth.argmax import ArgmaxDepth

    class Mine(ArgmaxDepth):
        name = "argmax"

    with pytest.warns(RuntimeWarning, match="is replaced by"):
        ESTIMATORS.add("argmax", Mine, "argmax", "a plugin's")
    try:
        assert main(["check", "depth:argmax"]) == 0
        line = capsys.readouterr().out.splitlines()[0]
        assert line.startswith("ok    depth argmax (") and \
            ", a plugin's, replacing the built-in spslidar.depth.argmax:ArgmaxDepth)" in line
    finally:
        ESTIMATORS.remove("argmax")
    assert main(["check", "depth:argmax"]) == 0
    assert "replacing" not in capsys.readouterr().out
