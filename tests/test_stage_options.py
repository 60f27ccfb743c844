"""Stages own their options (issue 22, item 2): a registry entry declares its options, and the
config, the CLI flags, ``--help``, the stage's construction and ``metrics.json`` follow the
declaration; an option given to a stage that does not take it is one line, exit 2.

The test adds a detector with one parameter the way a contributor would (one class, one
registry line) and checks that nothing else had to change."""

from __future__ import annotations

import json
from dataclasses import dataclass

import pytest

from spslidar.cli import build_parser, main
from spslidar.config import Config
from spslidar.detectors import DETECTORS
from spslidar.detectors.linear import LinearDetector
from spslidar.errors import ConfigError
from spslidar.registry import Option


@dataclass
class _DimDetector(LinearDetector):
    """A linear counter that detects a share ``qe`` of the photons (a toy quantum
    efficiency)."""

    qe: float = 1.0
    name = "dim"

    def __post_init__(self):
        self.efficiency = self.qe


@pytest.fixture
def dim_detector():
    DETECTORS.add("dim", _DimDetector, "dim counter", "a linear counter with efficiency --qe",
                  options=(Option("qe", 1.0, "share of the photons detected", lo=0.0, hi=1.0,
                                  lo_open=True),))
    try:
        yield
    finally:
        DETECTORS._entries.pop("dim")


def test_a_new_detector_option_reaches_config_cli_stage_and_metrics(dim_detector, tmp_path,
                                                                     capsys):
    cfg = Config(detector="dim", qe=0.5)
    assert cfg.qe == 0.5 and cfg.to_dict()["qe"] == 0.5
    # text is not a number (TOML's qe = "0.25"; the command line's is read by argparse)
    with pytest.raises(ConfigError, match="--qe must be a number, got '0.25'"):
        Config.from_dict({"detector": "dim", "qe": "0.25"})
    help_text = build_parser()._subparsers._group_actions[0].choices["run"].format_help()
    assert "--qe" in help_text and "share of the photons detected" in help_text
    out = tmp_path / "r"
    assert main(["run", "--size", "8", "--code-length", "127", "--detector", "dim", "--qe",
                 "0.5", "--noiseless", "--no-figure", "--out", str(out)]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["config"]["qe"] == 0.5 and m["detector"]["model"] == "dim"
    full = tmp_path / "full"
    assert main(["run", "--size", "8", "--code-length", "127", "--noiseless", "--no-figure",
                 "--out", str(full)]) == 0
    m1 = json.loads((full / "metrics.json").read_text())
    # the stage received its option: half the photons are counted (noiseless, exact)
    assert m["mean_signal_counts_per_pattern"] == pytest.approx(
        m1["mean_signal_counts_per_pattern"], rel=1e-12)  # expected signal is the incident
    assert m["detector"]["count_rate_hz"] == pytest.approx(
        0.5 * m1["detector"]["count_rate_hz"], rel=1e-6)
    capsys.readouterr()


def test_an_option_of_another_stage_is_refused(dim_detector, capsys, tmp_path):
    never = str(tmp_path / "never")  # (was "never" in the working folder: a regression
    # would have written into the checkout)
    assert main(["run", "--size", "8", "--qe", "0.5", "--out", never]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--qe is an option of --detector dim" in err[0]
    assert main(["run", "--size", "8", "--detector", "dim", "--jitter", "1e-11",
                 "--out", never]) == 2
    assert not (tmp_path / "never").exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--jitter is an option of --detector gmapd" in err[0]
    assert "takes --qe" in err[0]


@pytest.mark.parametrize("kw,match", [
    ({"detector": "gmapd", "jitter": 1e12}, "a microsecond of timing jitter"),
    ({"detector": "gmapd", "dead_time": 1e12}, "unit mistake"),
    ({"detector": "gmapd", "jitter_tail_weight": 2}, "--jitter-tail-weight must be in"),
    ({"detector": "gmapd", "dead_time": "x"}, "must be a number"),
    ({"detector": "gmapd", "pileup_correction": "maybe"}, "on or off"),
])
def test_declared_bounds_are_enforced(kw, match):
    from spslidar.errors import ConfigError

    with pytest.raises(ConfigError, match=match):
        Config(**kw)


def test_declarations_must_agree():
    """An option two entries declare is one config key: the declarations must agree."""
    with pytest.raises(ValueError, match="differs"):
        DETECTORS.add("bad", LinearDetector, options=(Option("dead_time", 1e-9),))
    assert "bad" not in DETECTORS


@dataclass
class _LabelledDetector(LinearDetector):
    """A linear counter with a ``label`` that only its report reads."""

    label: float = 0.0
    name = "labelled"
    report_only = ("label",)


def test_a_plugins_report_only_option_is_said_in_its_own_words(tmp_path):
    """A detector's ``report_only`` may be a sequence of names (then "its report") or a
    mapping to what each sets; the words were the linear counter's pile-up report for any
    detector's option (a review of 2026-12-03)."""
    from spslidar.pipeline.plan import report_only_keys

    DETECTORS.add("labelled", _LabelledDetector, "labelled", "a counter with a label",
                  options=(Option("label", 0.0, "a number its report carries"),))
    try:
        said = report_only_keys(Config(detector="labelled", label=2.0))
        assert said == {"label": "--label 2 of --detector labelled changes only its report, "
                                 "not its counts"}
        assert report_only_keys(Config(detector="labelled")) == {}  # at its default: quiet
    finally:
        DETECTORS._entries.pop("labelled")
    said = report_only_keys(Config(dead_time=2e-7))
    assert said["dead_time"].startswith("--dead-time 2e-07 of --detector linear changes only "
                                        "its pile-up report (--detector gmapd models")
