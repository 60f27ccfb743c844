"""Defects an outside plugin author's audit found in the registries, the stage options and the
conformance kit (``spslidar check``): each test fails without its fix."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.depth import ESTIMATORS
from spslidar.depth.argmax import ArgmaxDepth
from spslidar.errors import ConfigError
from spslidar.registry import Option

WINDOW = Option("window", 1, "median window", kind=int, lo=1, hi=15)


class MedArgmax(ArgmaxDepth):
    """The paper's argmax, with an option of its own (unused: the runs must only reach it)."""

    name = "medargmax"

    def __init__(self, window: int = 1, **kw):
        super().__init__(**kw)
        self.window = window


@pytest.fixture
def medargmax():
    ESTIMATORS.add("medargmax", MedArgmax, "med argmax", "argmax with a window",
                   options=(WINDOW,))
    try:
        yield "medargmax"
    finally:
        ESTIMATORS.remove("medargmax")


# -- 1. reproduce: a plugin estimator's option is processing, as sweep reads it -------------

_ROWS: list = []


def _exp_window(ctx):
    """An experiment plugin's points: one estimator, two of its windows."""
    from spslidar.experiments.reproduce.context import base_params, run_points

    points = [base_params(ctx, code_length=255, compression=0.1, depth="medargmax", window=w)
              for w in (1, 3)]
    _ROWS[:] = run_points(ctx, points)
    return "## Window\n\nTwo windows.\n", []


@pytest.mark.parametrize("max_time", [None, 600])
def test_reproduce_reads_a_plugin_estimators_option_as_processing(medargmax, tmp_path,
                                                                  monkeypatch, max_time):
    """``base_params(ctx, depth="medargmax", window=w)``: the batch's time check dropped
    ``depth`` but kept ``window`` ("--window is an option of --depth medargmax, not of --depth
    mrf", exit 2), and the two windows drew two measurements (an unpaired comparison)."""
    from spslidar.experiments import reproduce
    from spslidar.experiments.reproduce import reproduce_main
    from spslidar.experiments.sweep import ERROR_KEY

    reg = reproduce.EXPERIMENT_REGISTRY
    monkeypatch.setattr(reg, "_entries", dict(reg._entries))
    reg.add("window", _exp_window, "Window", "two windows", in_all=False)
    assert reproduce_main("window", tmp_path, quick=True, progress=False,
                          max_time=max_time) == 0
    assert len(_ROWS) == 2 and not any(ERROR_KEY in row for row in _ROWS)
    assert _ROWS[0]["seed"] == _ROWS[1]["seed"]  # one measurement, two processings


# -- 2. a declared numeric option takes numbers only (the CLI's text is read by argparse) ---


@pytest.mark.parametrize("keys", [
    {"depth": "medargmax", "window": True},
    {"depth": "medargmax", "window": "3"},
    {"detector": "gmapd", "jitter_tail": 1e-10, "jitter_tail_weight": True},
    {"detector": "gmapd", "dead_time": "5e-8"},
])
def test_a_numeric_option_refuses_booleans_and_text(medargmax, keys):
    """``window = true`` in a TOML ran with 1, ``window = "3"`` with 3, and the built-in
    ``jitter_tail_weight=True`` with 1.0, where ``iterations = true`` is refused."""
    from spslidar import Config

    with pytest.raises(ConfigError, match=r"must be a number, got (True|'3'|'5e-8')") as err:
        Config(size=16, **keys)
    assert "\n" not in str(err.value)


def test_a_toml_options_boolean_is_refused_and_the_cli_still_reads_numbers(medargmax,
                                                                         tmp_path):
    import numpy as np

    from spslidar import Config
    from spslidar.cli import main

    toml = tmp_path / "run.toml"
    toml.write_text('depth = "medargmax"\nwindow = true\nsize = 16\n')
    with pytest.raises(ConfigError, match="--window must be a number, got True"):
        Config.from_toml(toml)
    toml.write_text('depth = "medargmax"\nwindow = "3"\nsize = 16\n')
    with pytest.raises(ConfigError, match=r"--window must be a number, got '3' \(in TOML"):
        Config.from_toml(toml)
    # NumPy's numbers are numbers (an int option's np.int64, a float option's np.float32)
    cfg = Config(size=16, depth="medargmax", window=np.int64(3), detector="gmapd",
                 dead_time=np.float32(2e-8))
    assert cfg.window == 3 and type(cfg.window) is int and type(cfg.dead_time) is float
    # the command line's text is a number once argparse has read it
    out = tmp_path / "run"
    assert main(["run", "--size", "16", "--code-length", "255", "--compression", "0.1",
                 "--depth", "medargmax", "--window", "3",
                 "--dead-time", "2e-8", "--out", str(out), "--no-figure"]) == 0
    import json

    metrics = json.loads((out / "metrics.json").read_text())
    assert json.dumps(metrics).count('"window": 3') >= 1


# -- 3. and 4. an option's declaration is checked where it is registered --------------------


@pytest.mark.parametrize("option,says", [
    (Option("noise", 1.0, "a clash"), "'noise'.*spslidar's own config keys or flags"),
    (Option("out", 1.0, "a clash with run --out"), "'out'.*spslidar's own"),
    (Option("win_b", 20, kind=int, lo=1, hi=15), r"default 20 .*--win-b must be in \[1, 15\]"),
    (Option("win_c", 3.5, kind=int), "default 3.5 .*must be an integer"),
    (Option("win_f", True, kind=float), "default True .*must be a number"),
    (Option("win_s", "fast", kind=str, choices=("slow",)), "default 'fast' .*one of slow"),
    (Option("win-d", 3, kind=int), "'win-d'.*snake_case"),
    (Option("halfWidth", 3, kind=int), "'halfWidth'.*snake_case"),
    (Option("win_k", 3, kind=complex), "kind.*float, int, bool or str"),
])
def test_an_options_declaration_is_checked_where_it_is_registered(option, says):
    """``Option("win_b", 20, lo=1, hi=15)`` was accepted, then every run failed, those of
    other estimators too; ``win-d`` was "unknown config key 'win_d' (did you mean win-d)";
    an option named as a config key (``noise``) crashed ``spslidar --plugin collide run``
    with argparse's "conflicting option string" traceback. Refused at registration."""
    from spslidar import Config

    with pytest.raises(ValueError, match=f"{says}") as err:
        ESTIMATORS.add("bad-window", MedArgmax, options=(option,))
    assert "bad-window" not in ESTIMATORS and "\n" not in str(err.value)
    assert Config(size=16).depth == "mrf"  # the other runs are untouched


def test_a_scene_kind_refuses_options_and_keeps_its_defaults():
    """``SCENES.add(..., options=(Option("tilt", 0.0),))`` was accepted, and ``--tilt`` was
    unknown: a scene is built from its spec (``kind:ARG``), not from options."""
    from spslidar.scenes import SCENES
    from spslidar.scenes.builtin import _ramp

    with pytest.raises(ValueError, match="a scene declares no options.*tilt of 'tilted'"):
        SCENES.add("tilted", _ramp, options=(Option("tilt", 0.0),))
    assert "tilted" not in SCENES
    SCENES.add("tilted", _ramp, "tilted", "a ramp", argument="DEG", example="5")
    try:
        assert SCENES.get("tilted").defaults == {"argument": "DEG", "example": "5"}
    finally:
        SCENES.remove("tilted")


def test_a_plugin_whose_option_clashes_is_one_line_at_the_command_line(tmp_path, capsys,
                                                                      monkeypatch):
    """``spslidar --plugin collide run ...`` ended in argparse's traceback (exit 1)."""
    from spslidar.cli import main
    from spslidar.detectors import DETECTORS

    plugin = tmp_path / "collide.py"
    plugin.write_text("from spslidar.detectors import DETECTORS\n"
                      "from spslidar.detectors.linear import LinearDetector\n"
                      "from spslidar.registry import Option\n"
                      "DETECTORS.add('collide', LinearDetector, 'collide', 'a clash',\n"
                      "              options=(Option('noise', 1.0, 'a clash'),))\n")
    monkeypatch.delenv("SPSLIDAR_PLUGINS", raising=False)
    try:
        assert main(["--plugin", str(plugin), "run", "--size", "16", "--out",
                     str(tmp_path / "r")]) == 2
    finally:
        DETECTORS._entries.pop("collide", None)
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "collide.py:4" in err and "'noise'" in err


def test_an_option_two_stages_of_two_kinds_declare_is_refused_where_it_is_registered(
        medargmax, capsys):
    """A detector's ``window`` beside the estimator's ``window``, declared alike, made
    ``spslidar run`` (every command, ``check`` too) argparse's traceback: a flag each; then a
    one-line refusal of every later ``Config()``, runs using neither stage too (an audit of
    2026-12-01). Refused at registration now, in one line naming the other stage, and
    nothing of it kept."""
    from spslidar.cli import main
    from spslidar.config import Config
    from spslidar.detectors import DETECTORS
    from spslidar.detectors.linear import LinearDetector

    with pytest.raises(ValueError, match=r"option 'window' of detector model 'windowed': "
                                         r"--depth medargmax declares it"):
        DETECTORS.add("windowed", LinearDetector, options=(WINDOW,))
    assert "windowed" not in DETECTORS.names()
    with pytest.raises(SystemExit) as done:  # every command still builds
        main(["run", "--help"])
    assert done.value.code == 0
    capsys.readouterr()
    assert Config(depth="medargmax", window=3).window == 3  # the estimator's key


@pytest.mark.parametrize("name", ["truth", "settle"])
def test_an_option_named_as_a_commands_own_flag_is_refused_where_it_is_registered(name):
    """``reconstruct --truth`` is its own flag: an estimator's ``truth`` took argparse's
    traceback, then (one line) refused every command, ``run`` too, since the parser builds
    them all; ``settle``, a flag new in stop 64, would have done the same to a plugin that
    had it (a review of 2026-11-30): refused at registration."""
    with pytest.raises(ValueError, match="one of spslidar's own config keys or flags"):
        ESTIMATORS.add("flagged", MedArgmax, options=(Option(name, 1.0),))
    assert "flagged" not in ESTIMATORS.names()


def test_the_reserved_names_are_the_configs_keys_and_the_commands_flags():
    """The registry cannot import the config (which imports it): its list of the names an
    option cannot take is written out, and must follow ``Config`` and the flags of ``run``,
    ``reconstruct`` and ``calibrate``."""
    from spslidar.cli import build_parser
    from spslidar.config import CLI_ONLY_KEYS, _config_fields, stage_options
    from spslidar.registry import RESERVED_NAMES

    commands = build_parser()._subparsers._group_actions[0].choices
    flags = {s[2:].replace("-", "_") for c in ("run", "reconstruct", "calibrate")
             for a in commands[c]._actions for s in a.option_strings
             if s.startswith("--")} - set(stage_options())
    assert _config_fields() | CLI_ONLY_KEYS | {"extra"} <= RESERVED_NAMES
    assert flags <= RESERVED_NAMES


# -- 5. the conformance kit (spslidar check) -----------------------------------------------

HASHED_CODES = '''
import numpy as np
from spslidar.codes import CODES


def hashed(name, length, ratio, rng=None, index=0, **_):
    from spslidar.codes import make_code

    return np.roll(make_code("mseq", length, index=index), hash("x") % length)


CODES.add("hashpkg-hashed", hashed, "hashed", "an m-sequence shifted by hash()")
'''


@pytest.fixture
def hashpkg(tmp_path, monkeypatch):
    """A plugin package whose stage is registered in a submodule it imports."""
    import sys

    import spslidar.plugins as plugins
    from spslidar.codes import CODES

    (tmp_path / "hashpkg").mkdir()
    (tmp_path / "hashpkg" / "__init__.py").write_text("from . import codes  # noqa: F401\n")
    (tmp_path / "hashpkg" / "codes.py").write_text(HASHED_CODES)
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv(plugins.ENV, "")
    try:
        yield "hashpkg"
    finally:
        CODES._entries.pop("hashpkg-hashed", None)
        plugins._LOADED.pop("hashpkg", None)
        for name in ("hashpkg", "hashpkg.codes"):
            sys.modules.pop(name, None)


def test_a_stage_a_plugin_packages_submodule_registers_is_checked_afresh(hashpkg, capsys):
    """``hashpkg/__init__.py`` importing ``codes.py``, which registers a code seeded from
    ``hash("x")``: ``spslidar --plugin hashpkg check`` said ok (the fresh-process check needs
    the stage's module to be a plugin's own name), ``--plugin hashpkg.codes`` FAILed."""
    from spslidar.cli import main

    assert main(["--plugin", hashpkg, "check", "--plugins-only"]) == 1
    out = capsys.readouterr().out
    assert "FAIL  code hashpkg-hashed" in out and "another output in a fresh process" in out


def test_a_stage_no_new_interpreter_can_import_is_skipped_not_passed(capsys):
    """A stage registered in this process only (a notebook's cell, a test): that contract
    cannot run, and ``check`` says so rather than counting it passed."""
    from spslidar.cli import main
    from spslidar.codes import CODES, make_code
    from spslidar.testing import check_stage, check_stages

    CODES.add("cell-code", lambda kind, length, ratio, rng=None, index=0, **_: make_code(
        "mseq", length, index=index), "cell", "an m-sequence, registered in a cell")
    try:
        got = check_stage("code", "cell-code")
        assert "the same in a fresh process" not in got
        assert any(c.startswith("skipped: the same in a fresh process") for c in got), got
        (res,) = check_stages(["code"], ["cell-code"])
        assert res.ok and res.skipped and not any("fresh" in c for c in res.passed)
        assert main(["check", "code:cell-code"]) == 0
    finally:
        CODES.remove("cell-code")
    out = capsys.readouterr().out
    assert "skipped: the same in a fresh process" in out, out


def test_a_code_one_bit_short_fails_the_length_contract():
    """The length contract compared ``code.size`` with itself: a family returning ``length
    - 1`` bits passed."""
    from spslidar.codes import CODES, make_code
    from spslidar.testing import check_stage

    CODES.add("short-code", lambda kind, length, ratio, rng=None, index=0, **_: make_code(
        "mseq", length, index=index)[:-1], "short", "one bit short")
    try:
        with pytest.raises(AssertionError, match=r"126 bits, not the 127 asked for"):
            check_stage("code", "short-code")
    finally:
        CODES.remove("short-code")


def test_a_detector_with_negative_counts_fails():
    """A detector returning ``poisson(mean) - 1`` (its ``expected`` alike) passed the three
    detector contracts."""
    import numpy as np

    from spslidar.detectors import DETECTORS
    from spslidar.detectors.linear import LinearDetector
    from spslidar.testing import check_stage

    class MinusOne(LinearDetector):
        name = "minus-one"

        def detect(self, lam, rng, n_periods=1, out=None):
            counts, _ = super().detect(lam, rng, n_periods)
            counts = np.asarray(counts, np.float64) - 1.0
            return counts, counts.sum(axis=-1)

        def expected(self, lam, n_periods=1):
            return np.asarray(super().expected(lam, n_periods), np.float64) - 1.0

    DETECTORS.add("minus-one", MinusOne, "minus one", "poisson(mean) - 1")
    try:
        with pytest.raises(AssertionError, match="negative or non-finite counts"):
            check_stage("detector", "minus-one")
    finally:
        DETECTORS.remove("minus-one")


def test_a_numpy_bool_is_no_number_and_a_declaration_is_an_option():
    """``np.bool_`` (``window=np.True_``) falls through to ``float()`` unless read as the
    Python bool it is; a registration whose options are not ``Option`` declarations is one
    line (a review found neither guard tested)."""
    opt = Option("window", 3, kind=int, lo=1)
    with pytest.raises(ConfigError, match="must be a number"):
        opt.check(np.True_)
    assert opt.check(np.int64(5)) == 5
    with pytest.raises(ValueError, match="is not an Option"):
        ESTIMATORS.add("undeclared", MedArgmax, options=("window",))
    assert "undeclared" not in ESTIMATORS.names()


@pytest.mark.parametrize("name, says", [
    ("my est", "letters, digits"), ("--mrf", "not starting with a sign"),
    ("MRF", "differs from the registered 'mrf' only in case")])
def test_a_stage_name_that_no_flag_can_give_is_refused(name, says):
    """"my est", "--mrf" (``--depth --mrf`` is argparse's "expected one argument") and "MRF"
    beside the built-in "mrf" were registered and passed ``check`` (an outside audit of a
    plugin developer): refused at registration, in one line."""
    with pytest.raises(ValueError, match=says) as err:
        ESTIMATORS.add(name, MedArgmax)
    assert name not in ESTIMATORS and "\n" not in str(err.value)
    ESTIMATORS.add("my-est.2+", MedArgmax)  # (what the built-in names use, and more)
    ESTIMATORS.remove("my-est.2+")
