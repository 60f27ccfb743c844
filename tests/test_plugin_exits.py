"""Defects an outside audit of 2026-12-02 found where a plugin's code leaves by an unusual
door: a stage's ``SystemExit``, a plugin's ``sys.exit()`` at import, a stage registered under
a lazy path that does not import, a stage returning the wrong type, and the SNR experiment and
a uniform grey image, which ``--max-time`` and the depth window did not reach. Each test fails
without its fix."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.depth import ESTIMATORS
from spslidar.errors import SceneError

RUN = ["run", "--size", "16", "--code-length", "1023", "--no-figure"]

#: three estimators in registry order: one raising an error, one exiting, one after it
EXITING = '''
from spslidar.depth import ESTIMATORS
from spslidar.depth.argmax import ArgmaxDepth


class Raises(ArgmaxDepth):
    def estimate(self, slices, ctx):
        raise RuntimeError("boom")


class Exits(ArgmaxDepth):
    def estimate(self, slices, ctx):
        raise SystemExit(CODE)


class Stops(ArgmaxDepth):
    def estimate(self, slices, ctx):
        raise KeyboardInterrupt


ESTIMATORS.add("xraises", Raises, "raises", "raises an error")
ESTIMATORS.add("xexits", Exits, "exits", "raises SystemExit")
ESTIMATORS.add("xafter", Raises, "after", "raises, after the one that exits")
ESTIMATORS.add("xstops", Stops, "stops", "raises KeyboardInterrupt")
'''
NAMES = ("xraises", "xexits", "xafter", "xstops")


@pytest.fixture(autouse=True)
def _plugin_state(plugin_state, monkeypatch):
    """Each test leaves the plugins it loaded behind it (``conftest.plugin_state``), the
    environment's plugins out and the estimators its plugins registered gone."""
    import spslidar.plugins as plugins

    monkeypatch.setenv(plugins.ENV, "")
    yield
    for name in (*NAMES, "strtarget"):
        ESTIMATORS._entries.pop(name, None)


def _plugin(tmp_path, text: str, name: str = "exits.py"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def _err_line(capsys) -> str:
    """The one line a refusal wrote on stderr."""
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


# -- 1. a stage's SystemExit ------------------------------------------------------------------


@pytest.mark.parametrize("code", [0, 3])
def test_check_reports_a_stage_that_raises_systemexit_and_goes_on(tmp_path, capsys, code):
    """``check --plugins-only`` stopped at the stage with the stage's exit status (0 or 3),
    no summary and the later stages unreported."""
    plugin = _plugin(tmp_path, EXITING.replace("CODE", str(code)).replace(
        'ESTIMATORS.add("xstops"', '# ESTIMATORS.add("xstops"'))
    assert main(["--plugin", plugin, "check", "--plugins-only"]) == 1
    out = capsys.readouterr().out
    assert f"FAIL  depth xexits: depth 'xexits' raised SystemExit({code}) (exits.py:" in out
    assert "FAIL  depth xraises: depth 'xraises' raised RuntimeError: boom" in out
    assert "FAIL  depth xafter:" in out  # (the stage after it is checked too)
    assert out.strip().splitlines()[-1].startswith("0 of 3 stages pass their contracts")


def test_run_refuses_a_stages_systemexit_in_one_line(tmp_path, capsys):
    """``run --depth xexits`` exited 0, silently, writing nothing."""
    plugin = _plugin(tmp_path, EXITING.replace("CODE", "0"))
    out = tmp_path / "o" / "x"
    assert main(["--plugin", plugin, *RUN, "--depth", "xexits", "--out", str(out)]) == 2
    line = _err_line(capsys)
    assert line.startswith("spslidar run: error: a plugin's stage raised SystemExit(0) "
                           "(exits.py:"), line
    assert not out.exists()


def test_the_command_lines_own_exits_and_ctrl_c_are_kept(tmp_path, capsys):
    """The fix catches a stage's SystemExit, not argparse's (``--help``, a bad option), nor a
    KeyboardInterrupt, which is still Ctrl-C's exit status 130 in ``run`` and ``check``."""
    from spslidar.interrupts import EXIT_INTERRUPTED

    plugin = _plugin(tmp_path, EXITING.replace("CODE", "0"))
    with pytest.raises(SystemExit) as help_exit:
        main(["--plugin", plugin, "run", "--help"])
    assert help_exit.value.code == 0
    with pytest.raises(SystemExit) as bad_exit:
        main(["--plugin", plugin, "run", "--size", "sixteen"])
    assert bad_exit.value.code == 2
    capsys.readouterr()
    assert main(["--plugin", plugin, *RUN, "--depth", "xstops",
                 "--out", str(tmp_path / "s")]) == EXIT_INTERRUPTED
    assert main(["--plugin", plugin, "check", "depth:xstops"]) == EXIT_INTERRUPTED
    assert "interrupted" in capsys.readouterr().err


# -- 2. a plugin's sys.exit() at import -------------------------------------------------------


def test_a_plugin_that_exits_at_import_is_refused_in_one_line(tmp_path, capsys):
    """``import sys; sys.exit(0)`` in a plugin made every command a silent exit 0."""
    plugin = _plugin(tmp_path, "import sys\nsys.exit(0)\n", "sysexit.py")
    for args in ([*RUN, "--out", str(tmp_path / "o")], ["check"]):
        assert main(["--plugin", plugin, *args]) == 2
        assert _err_line(capsys) == ("spslidar: error: plugin " + plugin + " failed to import: "
                                     "SystemExit(0) (sysexit.py:2)")
    assert not (tmp_path / "o").exists()


def test_an_environment_plugin_that_exits_at_import_leaves_import_spslidar_alive(tmp_path):
    """Under ``SPSLIDAR_PLUGINS`` the plugin's exit ended ``import spslidar`` itself."""
    plugin = _plugin(tmp_path, "import sys\nsys.exit(5)\n", "sysexit.py")
    proc = subprocess.run([sys.executable, "-c", "import spslidar.plugins as p; "
                           "print('alive', p.FAILED)"],
                          env={**os.environ, "SPSLIDAR_PLUGINS": plugin},
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("alive") and "failed to import: SystemExit(5)" in proc.stdout


# -- 3. a stage registered under a lazy path that does not import -----------------------------

LAZY = 'from spslidar.depth import ESTIMATORS\n' \
       'ESTIMATORS.add("strtarget", "nonexistent.module:Thing", "X", "bad")\n'
SAID = ("depth estimator 'strtarget', registered as 'nonexistent.module:Thing', does not "
        "load: ModuleNotFoundError: No module named 'nonexistent'")


def test_a_stage_whose_lazy_path_does_not_import_is_one_line(tmp_path, capsys):
    """``run --depth strtarget`` was a 42-line ModuleNotFoundError traceback, exit 1; ``check``
    says it in the same words, without wrapping them in "raised ConfigError"."""
    plugin = _plugin(tmp_path, LAZY, "strt.py")
    out = tmp_path / "o"
    assert main(["--plugin", plugin, *RUN, "--depth", "strtarget", "--out", str(out)]) == 2
    assert _err_line(capsys) == f"spslidar run: error: {SAID}"
    assert not out.exists()
    assert main(["--plugin", plugin, "check", "--plugins-only"]) == 1
    assert f"FAIL  depth strtarget: {SAID}\n" in capsys.readouterr().out


def test_a_built_in_stage_that_does_not_import_is_still_a_traceback():
    """spslidar's own entry failing to import is spslidar's bug: its error, not a refusal."""
    from spslidar.registry import Entry

    entry = Entry("x", "nonexistent.module:Thing", origin="spslidar.depth", kind="depth")
    with pytest.raises(ModuleNotFoundError):
        entry.load()


# -- 4. reproduce snr is priced against --max-time --------------------------------------------


def test_reproduce_snr_is_priced_against_max_time(tmp_path, capsys):
    """``reproduce snr --max-time 1s`` ran its 11.5 s (its points were priced at nothing);
    ``--quick`` (1.5 s estimated) is refused at 1 s too, and runs within 10 s. Cached runs cost
    nothing: the quick run resumed under 1 s is not refused."""
    from spslidar.experiments.reproduce.context import snr_point_seconds

    full = [dict(code_length=2**n - 1, periods=1000, method="histogram")
            for n in range(10, 16) for _ in range(4)]
    assert 12 < sum(map(snr_point_seconds, full)) < 20  # (measured 9.9 s, 11.7 s the command)
    for quick in ([], ["--quick"]):
        out = tmp_path / f"r{len(quick)}"
        assert main(["reproduce", "snr", *quick, "--max-time", "1s", "--no-progress",
                     "--out", str(out)]) == 2
        assert "more than --max-time 1 s" in _err_line(capsys)
        assert not out.exists()
    out = tmp_path / "q"
    args = ["reproduce", "snr", "--quick", "--no-progress", "--out", str(out)]
    assert main([*args, "--max-time", "10s"]) == 0
    assert main([*args, "--max-time", "1s"]) == 0


# -- 5. a stage returning the wrong type ------------------------------------------------------


def test_an_estimator_returning_none_is_told_so():
    """An ``estimate`` returning None was told it "returned depth of 1 entries for 256
    pixels"."""
    import spslidar
    from spslidar.depth.argmax import ArgmaxDepth
    from spslidar.errors import ConfigError

    class Nothing(ArgmaxDepth):
        def estimate(self, slices, ctx):
            return None

    ESTIMATORS.add("xraises", Nothing, "nothing", "returns None")
    with pytest.raises(ConfigError, match="the depth estimator Nothing returned None, not a "
                                          "DepthEstimate"):
        spslidar.run(size=16, code_length=1023, depth="xraises")


@pytest.mark.parametrize("made,said", [
    (lambda size: np.full((size, size), 5.0), "returned a float64 array of shape (16, 16)"),
    (lambda size: None, "returned None"),
])
def test_a_scene_kind_returning_no_scene_is_told_what_it_returned(made, said):
    """A scene kind returning a plain depth array was told it "made a depth map of shape
    ()"."""
    from spslidar.scenes import SCENES, load_scene

    SCENES.add("xnoscene", lambda size, lo, hi: made(size), "no scene", "returns no Scene")
    try:
        with pytest.raises(SceneError) as err:
            load_scene("xnoscene", size=16)
    finally:
        SCENES._entries.pop("xnoscene", None)
    assert str(err.value) == (f"scene kind 'xnoscene' {said}, not a Scene: a scene kind "
                              f"returns spslidar.scenes.Scene(name, depth, reflectivity, "
                              f"valid) of (size, size) arrays")


# -- 6. a uniform grey image ------------------------------------------------------------------


@pytest.mark.parametrize("level", [0, 1, 128, 255])
def test_a_uniform_grey_image_is_a_flat_wall_at_the_windows_middle(tmp_path, level):
    """Its grey level was taken as metres and clipped: level 0 or 1 a wall at the window's
    near end, 128-255 one at its far end, unsaid."""
    from PIL import Image

    from spslidar.scenes import load_scene

    path = tmp_path / "c.png"
    Image.fromarray(np.full((16, 16), level, np.uint8)).save(path)
    scene = load_scene(path, size=16)
    assert np.all(scene.depth == 20.4)
    assert [n for n in scene.notes if "uniform" in n] == [
        f"scene image c.png is uniform (grey level {level} everywhere at 16x16): no range of "
        f"grey levels to map onto the depth window 20-20.8 m, so its depth is a flat wall at "
        f"20.4 m, the window's middle (--depth-min/--depth-max move it; an .npy depth map "
        f"gives any depth)"]
    moved = load_scene(path, size=16, depth_min=5, depth_max=6)
    assert np.all(moved.depth == 5.5)


def test_a_uniform_grey_image_is_said_once_and_a_textured_one_keeps_its_mapping(tmp_path,
                                                                               capsys):
    from PIL import Image

    from spslidar.scenes import load_scene

    flat, half = tmp_path / "c.png", tmp_path / "half.png"
    Image.fromarray(np.full((16, 16), 7, np.uint8)).save(flat)
    grey = np.zeros((16, 16), np.uint8)
    grey[:, 8:] = 200
    Image.fromarray(grey).save(half)
    scene = load_scene(half, size=16)
    assert scene.depth[0, 0] == 20.0 and scene.depth[0, -1] == 20.8  # darkest near, as before
    assert not any("uniform" in n for n in scene.notes)
    assert main(["run", "--scene", str(flat), "--size", "16", "--code-length", "16383",
                 "--no-figure", "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert err.count("scene image c.png is uniform (grey level 7") == 1, err
