"""Inputs a careful user would not expect to be accepted silently (issue 15, item 5): each is
refused in one line with exit 2 and nothing written, or run with a warning that says what was
done."""

import json
import re

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.config import Config
from spslidar.errors import ConfigError, SceneError
from spslidar.scenes import load_scene

FAST = ["--size", "16", "--code-length", "1023"]


def _refused(capsys, argv, out):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert not out.exists()
    return err


@pytest.mark.parametrize("name, array, words", [
    ("complex", np.full((16, 16), 3.0).astype(complex), "complex"),
    ("boolean", np.ones((16, 16), dtype=bool), "boolean"),
    ("far", np.full((16, 16), 1e12), "metres"),
])
def test_scene_arrays_a_user_did_not_mean_are_refused(tmp_path, capsys, name, array, words):
    path = tmp_path / f"{name}.npy"
    np.save(path, array)
    out = tmp_path / "out"
    err = _refused(capsys, ["run", *FAST, "--scene", str(path), "--out", str(out)], out)
    assert words in err and path.name in err


def test_a_complex_npz_reflectivity_is_refused(tmp_path):
    path = tmp_path / "s.npz"
    np.savez(path, depth=np.full((8, 8), 3.0), reflectivity=np.full((8, 8), 0.5 + 0j))
    with pytest.raises(SceneError, match="complex"):
        load_scene(str(path), 8)


def test_boolean_valid_mask_is_still_accepted(tmp_path):
    path = tmp_path / "s.npz"
    valid = np.ones((8, 8), dtype=bool)
    valid[0, 0] = False
    np.savez(path, depth=np.full((8, 8), 3.0), valid=valid)
    assert load_scene(str(path), 8).valid.sum() == 63


def test_non_square_scene_is_cropped_with_a_warning(tmp_path, capsys):
    path = tmp_path / "wide.npy"
    np.save(path, np.full((16, 20), 3.0))
    scene = load_scene(str(path), 16)
    assert scene.notes and "16x20" in scene.notes[0] and "centre 16x16" in scene.notes[0]
    # the crop's field of view is not the file's (an outside audit of 2026-12-01)
    assert "2 atan(tan(F/2) 16/20) in the crop, the --fov of the point cloud" in scene.notes[0]
    # nothing is resized at the crop's own size; at another size, what it is resized to
    assert "resized" not in scene.notes[0]
    assert "(resized to 8x8)" in load_scene(str(path), 8).notes[0]
    assert load_scene("camera", 16).notes == []
    out = tmp_path / "out"
    assert main(["run", *FAST, "--scene", str(path), "--out", str(out), "--no-figure"]) == 0
    assert "16x20" in capsys.readouterr().err


def test_ones_ratio_with_an_msequence_is_refused(tmp_path, capsys):
    out = tmp_path / "out"
    err = _refused(capsys, ["run", *FAST, "--ones-ratio", "0.3", "--out", str(out)], out)
    assert "--code random" in err


def test_toml_scene_path_is_relative_to_the_toml(tmp_path, monkeypatch):
    sub = tmp_path / "project"
    sub.mkdir()
    np.save(sub / "flat.npy", np.full((16, 16), 3.0))
    (sub / "cfg.toml").write_text('scene = "flat.npy"\nsize = 16\ncode_length = 1023\n')
    monkeypatch.chdir(tmp_path)  # the TOML's folder is not the working directory
    cfg = Config.from_toml(sub / "cfg.toml")
    assert cfg.scene == str(sub / "flat.npy")
    out = tmp_path / "out"
    assert main(["run", "--config", str(sub / "cfg.toml"), "--out", str(out),
                 "--no-figure"]) == 0
    # a built-in scene name is not a path
    (sub / "b.toml").write_text('scene = "motorcycle"\n')
    assert Config.from_toml(sub / "b.toml").scene == "motorcycle"


@pytest.mark.parametrize("out", ["", "."])
def test_degenerate_out_paths(tmp_path, capsys, monkeypatch, out):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.md").write_text("mine")
    assert main(["run", *FAST, "--out", out]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert (tmp_path / "notes.md").read_text() == "mine"


def test_huge_code_length_is_one_line(tmp_path, capsys):
    out = tmp_path / "out"
    for length in ("1073741823", "16777215"):
        try:
            code = main(["run", "--size", "16", "--code-length", length, "--out", str(out)])
        except SystemExit as exc:
            code = exc.code
        err = capsys.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
        assert not out.exists()


def test_scores_can_be_recomputed_from_the_saved_files(tmp_path):
    """RMSE from depth.npy, truth.npy and valid.npy equals metrics.json's, and the coverage
    it is computed over is stated (issue 15, item 6)."""
    import json

    out = tmp_path / "out"
    assert main(["run", "--scene", "motorcycle", "--size", "32", "--code-length", "1023",
                 "--out", str(out), "--no-figure"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    depth, truth = np.load(out / "depth.npy"), np.load(out / "truth.npy")
    valid = np.load(out / "valid.npy")
    have = valid & np.isfinite(depth)
    rmse = float(np.sqrt(np.mean((depth[have] - truth[have]) ** 2)))
    assert rmse == pytest.approx(m["depth_rmse_m"], rel=1e-12)
    assert m["coverage"] == pytest.approx(have.mean())
    assert m["coverage"] < 1.0  # the motorcycle has pixels without ground truth
    for key in ("iterations", "lam_scale", "code_index"):
        assert m["config"][key] is not None


@pytest.mark.parametrize("grid, words", [
    ('code_length = [1023, 1000]', "code length 1000"),
    ('scene = ["camera", "missing.npy"]', "not found"),
    ('size = [16, 2048]\ncompression = [0.5]', "memory"),
])
def test_sweep_checks_every_point_before_the_first_run(tmp_path, capsys, grid, words):
    """A bad point anywhere in the grid stops the sweep before anything runs: one line,
    exit 2, no partial results.csv (issue 15, item 4)."""
    cfg = tmp_path / "sweep.toml"
    base = "".join(f"{k} = {v}\n" for k, v in (("size", 16), ("code_length", 1023))
                   if not grid.startswith(k))  # a key in both is said (a second line)
    cfg.write_text(f"trials = 1\n[base]\n{base}[grid]\n{grid}\n")
    out = tmp_path / "out"
    assert main(["sweep", str(cfg), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err, err
    assert not out.exists()


def test_sweep_scene_paths_are_relative_to_the_toml(tmp_path, monkeypatch):
    from spslidar.experiments.sweep import load_sweep_config

    (tmp_path / "cfgs").mkdir()
    np.save(tmp_path / "cfgs" / "flat.npy", np.full((16, 16), 3.0))
    cfg = tmp_path / "cfgs" / "s.toml"
    cfg.write_text('[base]\nscene = "flat.npy"\n[grid]\nscene = ["flat.npy", "camera"]\n')
    monkeypatch.chdir(tmp_path)
    with pytest.warns(UserWarning, match="scene is in both"):
        spec = load_sweep_config(cfg)
    # named as the TOML names them (a point's seed and cache file follow the TOML alone),
    # read from the TOML's folder
    assert spec.base["scene"] == "flat.npy"
    assert spec.grid["scene"] == ["flat.npy", "camera"]
    opened = [spec.resolve(point)["scene"] for point in spec.points()]
    assert opened == [str(tmp_path / "cfgs" / "flat.npy"), "camera"]


def test_snr_histogram_too_large_is_one_line(capsys, monkeypatch):
    """(The per-pixel arrays peak at 160 bytes a pixel: 10.7 GB at N = 8192, which the
    estimate once put at 3.2 GB, so a 6 GB process limit met an ArrayMemoryError.)"""
    import spslidar.machine

    monkeypatch.setattr(spslidar.machine, "available_memory", lambda: 6e9)
    assert main(["snr", "--size", "8192", "--method", "histogram"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "GB" in err and "--method sum" in err


def _project_with_an_irf(tmp_path, monkeypatch, name: str, toml: str):
    """A project folder holding a one-bin ``irf.npy`` and the TOML ``name``, run from its
    parent (so that a path read from the current folder misses the IRF)."""
    sub = tmp_path / "project"
    sub.mkdir()
    irf = np.zeros(9)
    irf[4] = 1.0
    np.save(sub / "irf.npy", irf)
    (sub / name).write_text(toml)
    monkeypatch.chdir(tmp_path)
    return sub


def test_toml_files_a_user_writes(tmp_path, monkeypatch, capsys):
    """An audit of 2026-11-28: a relative irf = "irf.npy" was read from the current folder
    (the same TOML gave another response elsewhere); a TOML's code-length could not be
    overridden by --code-length ('given twice'); noise = 1 beside [run] noise = 7 took 7; out
    and a BOM and a folder gave messages that did not say what was wrong; --no-noiseless did
    not exist to undo a TOML's noiseless = true."""
    sub = _project_with_an_irf(tmp_path, monkeypatch, "cfg.toml",
                               'irf = "irf.npy"\nsize = 8\ncode-length = 255\nnoiseless = true\n')
    assert Config.from_toml(sub / "cfg.toml").irf == str(sub / "irf.npy")
    (sub / "spec.toml").write_text('irf = "gaussian:2e-10"\n')  # a spec, not a file
    assert Config.from_toml(sub / "spec.toml").irf == "gaussian:2e-10"
    out = tmp_path / "o"
    assert main(["run", "--config", str(sub / "cfg.toml"), "--code-length", "127",
                 "--no-noiseless", "--no-figure", "--out", str(out)]) == 0
    cfg = json.loads((out / "metrics.json").read_text())["config"]
    assert cfg["code_length"] == 127 and cfg["noiseless"] is False
    for text, match in (('noise = 1\n[run]\nnoise = 7\n', "given both at the top and in [run]"),
                        ('out = "x"\nsize = 8\n', "out is a command-line option"),
                        ('\ufeffsize = 8\n', "byte-order mark")):
        (sub / "bad.toml").write_text(text, encoding="utf-8")
        with pytest.raises(ConfigError, match=re.escape(match)):
            Config.from_toml(sub / "bad.toml")
    with pytest.raises(ConfigError, match="is a directory"):
        Config.from_toml(sub)


def test_a_sweep_follows_its_irf_files_content(tmp_path, monkeypatch):
    """An edited IRF file was given the earlier file's cached results (scene files were
    hashed, IRF files not); and a relative one is read from the TOML's folder."""
    from spslidar.experiments.sweep import sweep_main

    sub = _project_with_an_irf(tmp_path, monkeypatch, "s.toml",
                               'seed = 1\n[base]\nsize = 8\ncode_length = 255\n'
                               'irf = "irf.npy"\ndepth = "argmax"\n[grid]\nnoise = [1, 2]\n')
    assert sweep_main(sub / "s.toml", tmp_path / "o", progress=False) == 0
    first = (tmp_path / "o" / "results.csv").read_text()
    np.save(sub / "irf.npy", np.full(41, 1.0 / 41))  # a 40-bin response
    assert sweep_main(sub / "s.toml", tmp_path / "o", progress=False) == 0
    second = (tmp_path / "o" / "results.csv").read_text()
    assert "irf_sha256" in first and first != second


@pytest.mark.parametrize("encoding", ["utf-8-sig", "utf-16"])
@pytest.mark.parametrize("kind", ["config", "sweep"])
def test_a_toml_with_a_byte_order_mark_says_so(tmp_path, capsys, encoding, kind):
    """Windows editors write UTF-8 with a BOM and PowerShell 5's '>' UTF-16: a sweep's TOML
    read "invalid TOML: Invalid statement (at line 1, column 1)" and a UTF-16 config "'utf-8'
    codec can't decode byte 0xff" (a portability audit); both now say what the file is."""
    path = tmp_path / "c.toml"
    if kind == "config":
        path.write_text("size = 8\n", encoding=encoding)
        argv = ["run", "--config", str(path), "--out", str(tmp_path / "o")]
    else:
        path.write_text("seed = 1\n[base]\nsize = 8\n[grid]\nnoise = [1]\n", encoding=encoding)
        argv = ["sweep", str(path), "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert ("byte-order mark" if encoding == "utf-8-sig" else "is UTF-16") in err, err
    assert "save it as UTF-8 without BOM" in err
    assert not (tmp_path / "o").exists()
