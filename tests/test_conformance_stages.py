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

    return DensePatterns(2.0 * rng.random((m, n * n)).astype(dtype))  # mirrors at 2


@pytest.fixture
def broken():
    added = [(CODES, "run"), (CODES, "sparse10"), (DETECTORS, "leaky"),
             (ESTIMATORS, "shifted"), (ESTIMATORS, "dirty"), (PATTERNS, "bright")]
    CODES.add("run", _bad_code, "run", "one long run", index=0)
    CODES.add("sparse10", _unbalanced, "sparse", "a tenth of ones", index=0)
    DETECTORS.add("leaky", _Leaky, "leaky", "loses photons")
    ESTIMATORS.add("shifted", _Shifted, "shifted", "one bin late")
    ESTIMATORS.add("dirty", _Dirty, "dirty", "zeroes its input")
    PATTERNS.add("bright", _scaled_patterns, "bright", "mirror states up to 2", dense=True)
    try:
        yield
    finally:
        for reg, name in added:
            reg._entries.pop(name, None)


@pytest.mark.parametrize("kind,name,why", [
    ("code", "run", "sidelobe"), ("code", "sparse10", "not about half"),
    ("detector", "leaky", "detections' totals"),
    ("depth", "shifted", "noiseless recovery: 144 of 144 pixels wrong"),
    ("depth", "dirty", "changed the slices"), ("patterns", "bright", "mirror states in")])
def test_checks_fail_on_broken_stages(broken, kind, name, why):
    with pytest.raises(AssertionError, match=why):
        check_stage(kind, name)


def test_check_stages_keeps_failures_and_selects_plugins(broken):
    seen = []
    res = check_stages(["code", "depth"], plugins_only=True, on_result=seen.append)
    assert [(r.kind, r.name, r.ok) for r in res] == [
        ("code", "run", False), ("code", "sparse10", False), ("depth", "shifted", False),
        ("depth", "dirty", False)]
    assert seen == res and all(r.error and not r.passed for r in res)
    assert not is_plugin(CODES.get("mseq")) and is_plugin(CODES.get("run"))
    with pytest.raises(ValueError, match="unknown stage kind 'codes'"):
        check_stage("codes", "mseq")
    with pytest.raises(ValueError, match="unknown code family 'nope'; choose one of mseq"):
        check_stage("code", "nope")


def test_check_command(broken, capsys):
    assert main(["check", "depth:argmax", "code:mseq"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("ok    depth argmax (4 contracts, ")
    assert out[-1] == "2 of 2 stages pass their contracts"
    assert main(["check", "--plugins-only", "depth"]) == 1
    cap = capsys.readouterr()
    assert cap.out.splitlines()[0].startswith(
        "FAIL  depth shifted: depth estimator 'shifted': noiseless recovery")
    assert cap.err.strip() == "0 of 2 stages pass their contracts"
    for argv, why in ((["check", "nope"], "unknown stage kind 'nope'"),
                      (["check", "depth:nope"], "unknown depth estimator 'nope'"),
                      (["check", "--plugins-only", "solver"], "no stage to check")):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("spslidar check: error: ") and why in err
        assert len(err.strip().splitlines()) == 1
