"""A researcher's own stages, registered from outside the package (an audit of 2026-11-28):
an option a pattern kind, solver or depth estimator declares reaches the stage (only the
detectors' did: the others were validated, written to ``metrics.json`` and never given to
the stage), has its command-line flag, is a processing key where it belongs to the
processing (``reconstruct(m, key=...)``, a sweep's paired seeds), and a code family's output
is checked."""

from __future__ import annotations

import json

import numpy as np
import pytest

import spslidar
from spslidar.cli import build_parser, main
from spslidar.codes import CODES
from spslidar.config import Config
from spslidar.depth import ESTIMATORS
from spslidar.depth.argmax import ArgmaxDepth
from spslidar.errors import ConfigError
from spslidar.patterns import PATTERNS
from spslidar.registry import Option
from spslidar.solvers import SOLVERS
from spslidar.solvers.fista import FISTA

SEEN: dict[str, object] = {}


def _patterns(kind, m, n, rng, dtype, density=0.5, **_):
    """Bernoulli patterns of a given share of mirrors on."""
    from spslidar.patterns.dense import DensePatterns

    SEEN["density"] = density
    return DensePatterns((rng.random((m, n * n)) < density).astype(dtype))


class _Fista(FISTA):
    """FISTA, recording the option it was built with."""

    def __init__(self, stop=None, threads=None, relax=1.0, **options):
        SEEN["relax"] = relax
        super().__init__(stop=stop, threads=threads, **options)


class _Argmax(ArgmaxDepth):
    """Argmax, recording the option it was built with."""

    name = "argmax2"

    def __init__(self, low_confidence=None, half_width=1, **options):
        SEEN["half_width"] = half_width
        super().__init__(low_confidence, **options)


def _short_code(kind, length, ones_ratio, rng=None, index=0, **_):
    return np.ones(length - 1, dtype=np.uint8)


@pytest.fixture
def plugins():
    SEEN.clear()
    PATTERNS.add("sparse", _patterns, "sparse", "Bernoulli of --density",
                 options=(Option("density", 0.5, "share of mirrors on", lo=0, hi=1,
                                 lo_open=True),), dense=True)
    SOLVERS.add("fista2", _Fista, "FISTA 2", "FISTA with --relax", iterations=30,
                lam_scale=0.45, regulariser="tv",
                options=(Option("relax", 1.0, "a relaxation", lo=0, hi=2),))
    ESTIMATORS.add("argmax2", _Argmax, "argmax 2", "argmax with --half-width",
                   options=(Option("half_width", 1, "half width", kind=int, lo=0, hi=5),))
    CODES.add("short", _short_code, "short", "a broken family: one bit short", index=0)
    try:
        yield
    finally:
        for reg, name in ((PATTERNS, "sparse"), (SOLVERS, "fista2"), (ESTIMATORS, "argmax2"),
                          (CODES, "short")):
            reg._entries.pop(name, None)


SMALL = dict(size=8, code_length=127, scene="steps", depth_min=1.0, depth_max=1.6,
             range_gate=(0.8, 1.8))


def test_each_stages_own_option_reaches_it(plugins):
    r = spslidar.run(**SMALL, patterns="sparse", density=0.3, solver="fista2", relax=0.5,
                     depth="argmax2", half_width=3)
    assert SEEN == {"density": 0.3, "relax": 0.5, "half_width": 3}
    cfg = r.metrics["config"]
    assert (cfg["density"], cfg["relax"], cfg["half_width"]) == (0.3, 0.5, 3)


def test_each_stages_option_has_its_flag(plugins, tmp_path):
    run_help = build_parser()._subparsers._group_actions[0].choices["run"].format_help()
    for flag in ("--density", "--relax", "--half-width"):
        assert flag in run_help
    rec_help = build_parser()._subparsers._group_actions[0].choices["reconstruct"].format_help()
    assert "--relax" in rec_help and "--half-width" in rec_help
    assert main(["run", "--size", "8", "--code-length", "127", "--scene", "steps",
                 "--depth-min", "1", "--depth-max", "1.6", "--range-gate", "0.8", "1.8",
                 "--patterns", "sparse", "--density", "0.25", "--depth", "argmax2",
                 "--half-width", "2", "--no-figure", "--out", str(tmp_path / "o")]) == 0
    assert SEEN["density"] == 0.25 and SEEN["half_width"] == 2
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["config"]["density"] == 0.25


def test_a_processing_option_is_a_processing_key(plugins):
    from spslidar.pipeline import measure, reconstruct
    from spslidar.pipeline.measurement import processing_keys

    assert {"relax", "half_width"} <= processing_keys()
    assert "density" not in processing_keys()  # the patterns are the measurement's
    meas = measure(**SMALL)
    reconstruct(meas, depth="argmax2", half_width=4)
    assert SEEN["half_width"] == 4


def test_a_code_family_that_returns_the_wrong_bits_is_refused(plugins):
    with pytest.raises(ConfigError, match=r"the code family 'short' returned an array of "
                                          r"shape \(126,\) for --code-length 127"):
        spslidar.run(**SMALL, code="short")


def test_the_builtin_families_pass_the_check():
    for kind, length in (("mseq", 127), ("gold", 127), ("random", 100)):
        r = spslidar.run(**{**SMALL, "code_length": length}, code=kind)
        assert r.metrics["code_period_bins"] == length


def test_an_option_given_to_another_stage_is_refused(plugins):
    with pytest.raises(ConfigError, match="--relax is an option of --solver fista2"):
        Config(**SMALL, relax=0.5)


PLUGIN = '''
import numpy as np
from spslidar.codes import CODES
from spslidar.depth import ESTIMATORS
from spslidar.depth.argmax import ArgmaxDepth
from spslidar.registry import Option


def legendre(kind, length, ones_ratio, rng=None, index=0, **_):
    """Quadratic residues modulo a prime length."""
    from spslidar.errors import ConfigError

    if index != 0:
        raise ConfigError("a Legendre code of a length is one code: --code-index 0")
    res = set((np.arange(length) ** 2) % length)
    return np.array([1 if (i in res and i) else 0 for i in range(length)], dtype=np.uint8)


class Centroid(ArgmaxDepth):
    name = "centroid"

    def __init__(self, low_confidence=None, half_width=1, **options):
        self.half_width = half_width
        super().__init__(low_confidence, **options)


CODES.add("legendre", legendre, "Legendre", "quadratic residues mod a prime")
ESTIMATORS.add("centroid", Centroid, "centroid", "argmax with --half-width",
               options=(Option("half_width", 1, "half width", kind=int, lo=0, hi=5),))
'''


@pytest.fixture(autouse=True)
def _plugin_state(plugin_state):
    """Every test leaves the plugins it loaded behind it (``conftest.plugin_state``)."""


@pytest.fixture
def plugin_file(tmp_path, monkeypatch):
    import spslidar.plugins as plugins

    path = tmp_path / "mystages.py"
    path.write_text(PLUGIN)
    monkeypatch.setenv(plugins.ENV, "")  # (restored, unset, afterwards: delenv of an unset
    # variable records nothing, and --plugin's export leaked into later subprocesses)
    try:
        yield path
    finally:
        CODES._entries.pop("legendre", None)
        ESTIMATORS._entries.pop("centroid", None)
        plugins._LOADED.clear()


def test_a_plugin_is_reached_from_the_command_line(plugin_file, tmp_path, capsys):
    """``spslidar --plugin FILE run ...``: the plugin's code family and estimator are choices,
    the estimator's option a flag, and the run records them (there was no way in from the
    command line, an audit)."""
    out = tmp_path / "o"
    assert main(["--plugin", str(plugin_file), "run", "--size", "8", "--code", "legendre",
                 "--code-length", "131", "--depth", "centroid", "--half-width", "2",
                 "--no-figure", "--out", str(out)]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["code_description"].startswith("Legendre of 131 bits")
    assert m["config"]["half_width"] == 2 and m["depth_estimator"] == "centroid"


def test_a_sweeps_workers_import_the_plugin(plugin_file, tmp_path, capsys):
    """``sweep --jobs 2`` ran its points in workers that knew nothing of the plugin (every
    point "unknown config key"); ``--plugin`` sets ``SPSLIDAR_PLUGINS`` for them, and the
    estimator's option is a processing key (one seed for the points it alone tells apart)."""
    toml = tmp_path / "s.toml"
    toml.write_text('seed = 1\n[base]\nsize = 8\ncode = "legendre"\ncode_length = 131\n'
                    'depth = "centroid"\n[grid]\nhalf_width = [1, 2]\nnoise = [1, 10]\n')
    assert main(["--plugin", str(plugin_file), "sweep", str(toml), "--out",
                 str(tmp_path / "s"), "--jobs", "2", "--no-progress"]) == 0
    import csv

    rows = list(csv.DictReader((tmp_path / "s" / "results.csv").open()))
    assert len(rows) == 4 and all(r["depth_rmse_m"] for r in rows)
    seeds = {(r["noise"], r["half_width"]): r["seed"] for r in rows}
    assert seeds[("1", "1")] == seeds[("1", "2")] != seeds[("10", "1")]


def test_a_plugin_that_fails_is_one_line(tmp_path, capsys, monkeypatch):
    import spslidar.plugins as plugins

    monkeypatch.setenv(plugins.ENV, "")  # (restored, unset, afterwards: delenv of an unset
    # variable records nothing, and --plugin's export leaked into later subprocesses)
    bad = tmp_path / "bad.py"
    bad.write_text("raise RuntimeError('no licence server')\n")
    assert main(["--plugin", str(bad), "run", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    # (where in the plugin, too: an audit of the check command had only the message)
    assert err == [f"spslidar: error: plugin {bad} failed to import: RuntimeError: no "
                   f"licence server (bad.py:1)"]
    helper = tmp_path / "helper_mod.py"  # a sibling module, as `python mystages.py` finds it
    helper.write_text("VALUE = 3\n")
    good = tmp_path / "uses_helper.py"
    good.write_text("import helper_mod\nassert helper_mod.VALUE == 3\n")
    assert main(["--plugin", str(good), "check", "code:mseq"]) == 0
    capsys.readouterr()
    assert main(["--plugin", "no_such_module_here", "run", "--out", str(tmp_path / "o")]) == 2
    assert "No module named 'no_such_module_here'" in capsys.readouterr().err


def test_a_plugins_outputs_are_checked(plugins):
    """A plugin estimator's short depth array ended in a reshape traceback and a confidence
    in [-2, 4] was written as it was; a scene kind's 15x15 map at size 16 ended in a matmul
    traceback; a scene kind registered as "MyPlane" was unknown as "MyPlane" (an audit)."""
    from spslidar.errors import SceneError
    from spslidar.scenes import SCENES, Scene

    class Short(ArgmaxDepth):
        name = "short"

        def estimate(self, slices, ctx):
            out = super().estimate(slices, ctx)
            out.depth = out.depth[:-3]
            return out

    class Wild(ArgmaxDepth):
        name = "wild"

        def estimate(self, slices, ctx):
            out = super().estimate(slices, ctx)
            out.confidence = out.confidence * 6 - 2
            return out

    def plane(size, lo, hi):
        n = size - 1
        return Scene("MyPlane", np.full((n, n), 1.2), np.ones((n, n)), np.ones((n, n), bool))

    ESTIMATORS.add("short", Short, "short", "returns too few depths")
    ESTIMATORS.add("wild", Wild, "wild", "returns confidences outside [0, 1]")
    SCENES.add("MyPlane", plane, "my plane", "a scene one pixel short")
    try:
        with pytest.raises(ConfigError, match="the depth estimator Short returned depth of "
                                              "61 entries for 64 pixels"):
            spslidar.run(**SMALL, depth="short")
        with pytest.raises(ConfigError, match=r"confidences outside \[0, 1\]"):
            spslidar.run(**SMALL, depth="wild")
        with pytest.raises(SceneError, match=r"scene kind 'MyPlane' made a depth map of shape "
                                             r"\(7, 7\) for size 8"):
            spslidar.run(**{**SMALL, "scene": "MyPlane"})
    finally:
        ESTIMATORS._entries.pop("short", None)
        ESTIMATORS._entries.pop("wild", None)
        SCENES._entries.pop("MyPlane", None)


def test_an_option_named_as_a_config_key_is_refused(plugins):
    """A plugin detector's option ``signal`` took the config key over: ``Config(signal=7)``
    was refused as "an option of --detector noisy" (an audit); it is refused where it is
    registered (an audit of plugins: ``--noise`` crashed the command line)."""
    from spslidar.detectors import DETECTORS
    from spslidar.detectors.linear import LinearDetector

    with pytest.raises(ValueError, match="option 'signal' of detector model 'noisy': the "
                                         "name is one of spslidar's own config keys"):
        DETECTORS.add("noisy", LinearDetector, "noisy", "declares signal",
                      options=(Option("signal", 1.0, "a clash", lo=0, hi=100),))
    assert "noisy" not in DETECTORS
    assert Config(size=16, signal=7).signal == 7.0


def test_a_detector_models_histograms_are_checked():
    """A plugin detector's NaN counts were refused as a weight "beyond what float32 can
    hold ... lower --lam", its histograms one bin short ended in a matched-filter traceback
    (an audit): one line naming the model."""
    from dataclasses import dataclass

    from spslidar.detectors import DETECTORS
    from spslidar.detectors.linear import LinearDetector

    @dataclass
    class Broken(LinearDetector):
        fault: str = "nan"
        name = "broken"
        linear = False

        def detect(self, lam, rng, n_periods=1, out=None):
            counts, totals = super().detect(lam, rng, n_periods, out=out)
            if self.fault == "nan":
                return counts * np.nan, totals
            return counts[:, :-1], totals

        def correct(self, counts, n_periods=1, expected=False):
            return counts

        def noise_totals(self, counts, totals, n_periods=1, corrected=None):
            return totals

    for fault, match in (("nan", "histograms that are not finite from its detect()"),
                         ("short", r"histograms of shape \(16, 126\) from its detect\(\) for "
                                   r"\(16, 127\)")):
        DETECTORS.add("broken", lambda fault=fault, **kw: Broken(fault=fault), "broken", "faulty")
        try:
            with pytest.raises(ConfigError, match=match):
                spslidar.run(**SMALL, detector="broken")
        finally:
            DETECTORS._entries.pop("broken", None)


def test_replacing_a_registered_stage_is_said():
    """A plugin's "fista" replaced the built-in without a word (an audit): said, and done."""
    entry = SOLVERS.get("fista")
    try:
        with pytest.warns(RuntimeWarning, match="the solver 'fista' .* is replaced by"):
            SOLVERS.add("fista", _Fista, "FISTA 2", "replaced", iterations=60,
                        lam_scale=0.45, regulariser="tv")
        assert SOLVERS.get("fista").target is _Fista
    finally:
        SOLVERS._entries["fista"] = entry


def test_a_plugin_experiment_is_a_reproduce_choice():
    """``reproduce`` took its choices from names frozen at import: a plugin's experiment was
    an "invalid choice" (an audit); they are read when the parser is built."""
    from spslidar.experiments.reproduce import EXPERIMENT_REGISTRY

    EXPERIMENT_REGISTRY.add("mine", lambda ctx: ("", []), "Mine", "a plugin's experiment",
                            in_all=False)
    try:
        choices = build_parser()._subparsers._group_actions[0].choices["reproduce"]
        action = next(a for a in choices._actions if a.dest == "experiment")
        assert "mine" in action.choices and "all" in action.choices
    finally:
        EXPERIMENT_REGISTRY._entries.pop("mine", None)


def test_a_plugin_stage_that_raises_is_one_line(tmp_path, capsys, monkeypatch):
    """``--scene disc:abc`` of a plugin scene kind ended in the plugin's ValueError
    traceback (an audit of 2026-11-29); a plugin stage's own error is one line with where it
    is, exit 2, nothing written."""
    import spslidar.plugins as plugins
    from spslidar.scenes import SCENES

    monkeypatch.setenv(plugins.ENV, "")
    mod = tmp_path / "discs.py"
    mod.write_text(
        "import numpy as np\n"
        "from spslidar.scenes import SCENES, Scene\n"
        "def disc(size, depth_min=None, depth_max=None, arg='3'):\n"
        "    r = float(arg)\n"
        "    d = np.full((size, size), 5.0 if depth_min is None else depth_min)\n"
        "    return Scene('disc', d, np.ones((size, size)), np.ones((size, size), bool))\n"
        "SCENES.add('disc', disc, 'disc', 'a disc', argument='R', example='3')\n")
    try:
        assert main(["--plugin", str(mod), "run", "--scene", "disc:abc", "--size", "8",
                     "--code-length", "127", "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == ["spslidar run: error: a plugin's stage raised ValueError: could not "
                       "convert string to float: 'abc' (discs.py:4)"], err
        assert not (tmp_path / "o").exists()
    finally:
        SCENES._entries.pop("disc", None)


def _strict_patterns(kind, m, n, rng, dtype, density=0.5):
    """The docs' factory ``make(kind, M, N, rng, dtype, **options)`` with its own option
    only, no ``**kwargs``."""
    from spslidar.patterns.dense import DensePatterns

    SEEN["strict"] = density
    return DensePatterns((rng.random((m, n * n)) < density).astype(dtype))


def test_a_pattern_factory_without_kwargs_gets_its_own_options_only():
    """A factory written to the docs, its own option and no ``**kwargs``, raised TypeError
    ("unexpected keyword argument 'sigma'"): every factory was given the built-in kinds'
    keywords (an outside audit). It gets the keywords it names; ``check`` passes it."""
    from spslidar.testing import check_stage

    PATTERNS.add("strict", _strict_patterns, "strict", "Bernoulli of --density",
                 options=(Option("density", 0.5, "share of mirrors on", lo=0, hi=1,
                                 lo_open=True),), dense=True)
    try:
        SEEN.clear()
        spslidar.run(**SMALL, patterns="strict", density=0.3)
        assert SEEN == {"strict": 0.3}
        assert "adjoint" in check_stage("patterns", "strict")  # (raises where one fails)
    finally:
        PATTERNS._entries.pop("strict", None)


def _held_bits(kind, length, ones_ratio, rng=None, index=0, run_len=1):
    """Random bits, each held for ``run_len`` bits."""
    SEEN["run_len"] = run_len
    rng = np.random.default_rng(rng)
    bits = (rng.random(-(-length // run_len)) < 0.5).astype(np.uint8)
    return np.repeat(bits, run_len)[:length]


def test_snr_takes_a_plugin_code_familys_option(capsys):
    """``snr --help`` listed a plugin family, but its option was "unrecognized arguments" and
    the family ran at its default without a word (an outside audit of a plugin developer):
    the option reaches the family; another family's refuses it in one line."""
    from spslidar.codes import CODES

    CODES.add("held", _held_bits, "held", "bits held --run-len",
              options=(Option("run_len", 1, "bits each draw is held", kind=int, lo=1, hi=64),))
    try:
        args = ["snr", "--code", "held", "--code-length", "127", "--trials", "20", "--size",
                "8", "--json"]
        capsys.readouterr()
        assert main([*args, "--run-len", "4"]) == 0 and SEEN["run_len"] == 4
        assert json.loads(capsys.readouterr().out)["params"]["code_options"] == {"run_len": 4}
        assert main(args) == 0 and SEEN["run_len"] == 1
        assert json.loads(capsys.readouterr().out)["params"]["code_options"] == {"run_len": 1}
        assert main(["snr", "--code", "mseq", "--code-length", "127", "--run-len", "4"]) == 2
        err = capsys.readouterr().err
        assert "--run-len is not an option of --code mseq" in err and err.count("\n") == 1
        assert main([*args, "--run-len", "0"]) == 2
    finally:
        CODES._entries.pop("held", None)


def _burst(kind, length, ones_ratio, rng=None, index=0, method="block"):
    SEEN["method"] = method
    return _held_bits(kind, length, ones_ratio, rng, index, 2)


def test_a_code_familys_option_named_as_an_snr_flag_leaves_every_command_working(capsys):
    """A plugin family's option ``method`` (snr's own --method) made every command a
    traceback, ``run --help`` too, once snr took the families' options (a review): snr keeps
    its own flag and runs the family at its default; ``run`` takes the family's."""
    from spslidar.codes import CODES

    CODES.add("burst", _burst, "burst", "bits in pairs",
              options=(Option("method", "block", "how", kind=str, choices=("block", "spread")),))
    try:
        with pytest.raises(SystemExit) as done:
            main(["run", "--help"])
        assert done.value.code == 0 and "--method" in capsys.readouterr().out
        SEEN.clear()
        assert main(["snr", "--code", "burst", "--code-length", "127", "--trials", "20",
                     "--size", "8", "--method", "histogram", "--json"]) == 0
        assert SEEN["method"] == "block"  # (snr's --method is its own)
        SEEN.clear()
        spslidar.run(**{**SMALL, "code": "burst"}, method="spread")
        assert SEEN["method"] == "spread"
    finally:
        CODES._entries.pop("burst", None)
