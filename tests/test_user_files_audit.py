"""A user's own files, from an outside audit of 2026-12-03: a multi-page TIFF scene, a grey +
alpha PNG, a valid mask resized, a square crop without valid pixels, a sweep's TOML given to
`run`, `~` in a TOML path, whose file is said before `--overwrite` is suggested, and a full
disk under `--save-ptu` named as such."""

from __future__ import annotations

import errno
from pathlib import Path

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.errors import SceneError
from spslidar.outfiles import write_files
from spslidar.scenes import load_scene

RUN = ["--size", "16", "--code-length", "1023", "--no-figure"]


def _tiff(path: Path, pages: int) -> None:
    from PIL import Image

    x = np.tile(np.arange(16, dtype=np.uint8) * 16, (16, 1))
    ims = [Image.fromarray(np.roll(x, k, axis=1)) for k in range(pages)]
    ims[0].save(path, save_all=True, append_images=ims[1:])


@pytest.mark.parametrize("pages", [2, 3, 4])
def test_a_multi_page_tiff_scene_is_refused_in_one_line(tmp_path, capsys, pages):
    """3 and 4 pages were read as an RGB(A) image, the pages mixed into one grey map."""
    f = tmp_path / "stack.tif"
    _tiff(f, pages)
    with pytest.raises(SceneError, match=f"TIFF of {pages} pages"):
        load_scene(str(f), size=16)
    assert main(["run", "--scene", str(f), *RUN, "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"TIFF of {pages} pages" in err[0]
    assert not (tmp_path / "r").exists()


def test_a_one_page_tiff_is_its_grey_levels(tmp_path):
    f = tmp_path / "one.tif"
    _tiff(f, 1)
    s = load_scene(str(f), size=16, depth_min=10.0, depth_max=11.0)
    assert np.all(np.diff(s.depth, axis=1) > 0) and np.all(np.diff(s.depth, axis=0) == 0)


def test_grey_and_alpha_is_read_as_its_grey_levels_like_rgba(tmp_path):
    from PIL import Image

    g = (np.arange(256).reshape(16, 16) % 251).astype(np.uint8)
    Image.fromarray(g, "L").save(tmp_path / "l.png")
    Image.fromarray(np.stack([g, np.full_like(g, 128)], -1), "LA").save(tmp_path / "la.png")
    grey = load_scene(str(tmp_path / "l.png"), size=16)
    la = load_scene(str(tmp_path / "la.png"), size=16)
    np.testing.assert_array_equal(la.depth, grey.depth)


def test_a_files_valid_mask_keeps_the_pixels_half_of_whose_footprint_is_valid(tmp_path):
    """A file 95 % valid (isolated holes) at 128 -> 32 kept 43 % of its pixels scored; one
    75 % valid up-sampled 40 -> 64, 44 %: a pixel is now scored where half its footprint is."""
    rng = np.random.default_rng(0)
    d = np.linspace(10, 11, 128 * 128).reshape(128, 128)
    v = rng.random((128, 128)) > 0.05
    np.savez(tmp_path / "holes.npz", depth=np.where(v, d, np.nan), valid=v)
    s = load_scene(str(tmp_path / "holes.npz"), size=32)
    assert s.valid.mean() > 0.99  # (each 4x4 footprint holds 0.8 holes on average)
    d = np.linspace(10, 11, 1600).reshape(40, 40)
    v = np.ones((40, 40), bool)
    v[::2, ::2] = False
    np.savez(tmp_path / "v40.npz", depth=np.where(v, d, np.nan), valid=v)
    up = load_scene(str(tmp_path / "v40.npz"), size=64)
    assert up.valid.mean() >= 0.75  # (at least the file's share)
    # a pixel that lies in one invalid file pixel alone is not scored
    assert not up.valid.all()
    native = load_scene(str(tmp_path / "v40.npz"), size=40)
    np.testing.assert_array_equal(native.valid, v)


def test_a_crop_without_valid_pixels_says_so(tmp_path, capsys):
    d = np.full((16, 40), 10.0)
    v = np.zeros((16, 40), bool)
    v[:, :10] = True
    np.savez(tmp_path / "edge.npz", depth=d, valid=v)
    assert main(["run", "--scene", str(tmp_path / "edge.npz"), *RUN, "--out",
                 str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "centre 16x16 of its 16x40" in err and "larger size" not in err


def test_a_sweeps_toml_given_to_run_is_named(tmp_path, capsys):
    f = tmp_path / "sweep.toml"
    f.write_text("seed = 1\n[base]\nsize = 16\n[grid]\nnoise = [1, 10]\n")
    assert main(["run", "--config", str(f), "--out", str(tmp_path / "r")]) == 2
    assert "is a sweep's file" in capsys.readouterr().err


def test_a_tilde_in_a_toml_path_is_the_home_folder(tmp_path, monkeypatch, capsys):
    home = tmp_path / "home"
    home.mkdir()
    np.save(home / "wall.npy", np.full((16, 16), 20.0))
    monkeypatch.setenv("HOME", str(home))
    cfg = tmp_path / "cfgdir" / "run.toml"
    cfg.parent.mkdir()
    cfg.write_text('scene = "~/wall.npy"\nsize = 16\ncode_length = 1023\n')
    assert main(["run", "--config", str(cfg), "--no-figure", "--out", str(tmp_path / "r")]) == 0
    assert (tmp_path / "r" / "depth.npy").exists()


def test_output_only_keys_in_a_toml_are_said_as_them(tmp_path, capsys):
    f = tmp_path / "t.toml"
    f.write_text('out = "x"\nfov = 3\n')
    assert main(["run", "--config", str(f), "--out", str(tmp_path / "r")]) == 2
    assert "give them on the command line" in capsys.readouterr().err


def test_a_users_file_is_said_to_be_theirs_before_overwrite_is_offered(tmp_path, capsys):
    """`--save-ptu` onto a user's pattern file said "use --overwrite", which then refused."""
    (tmp_path / "acq_patterns.npy").write_text("mine")
    args = ["run", "--scene", "steps", *RUN, "--save-ptu", str(tmp_path / "acq.ptu"),
            "--out", str(tmp_path / "r")]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "is not a file spslidar wrote" in err and "use --overwrite" not in err
    assert (tmp_path / "acq_patterns.npy").read_text() == "mine"


def test_a_full_disk_under_save_ptu_is_named_as_that_file(tmp_path):
    def full(tmps):
        for t in tmps:
            t.write_bytes(b"partial")
        raise OSError(errno.ENOSPC, "No space left on device")

    target = tmp_path / "a.ptu"
    with pytest.raises(OSError) as info:
        write_files([target], full)
    assert info.value.errno == errno.ENOSPC
    assert f"--save-ptu {target}" in info.value.filename
    assert list(tmp_path.iterdir()) == []  # nothing left, not even the temporary file


def test_npy_patterns_at_the_dmds_resolution_get_the_pattern_size_hint(tmp_path):
    """As a folder of images did: 16 x 16 patterns saved as 64 x 64 blocks of 4 x 4."""
    from spslidar.io.lab_arrays import read_patterns_file

    rng = np.random.default_rng(0)
    p = (rng.random((40, 16, 16)) > 0.5).astype(np.float32)
    np.save(tmp_path / "dmd.npy", np.kron(p, np.ones((1, 4, 4), np.float32)))
    np.save(tmp_path / "p16.npy", p)
    with pytest.warns(UserWarning, match="4 x 4 blocks.*--pattern-size 16"):
        read_patterns_file(tmp_path / "dmd.npy")
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_patterns_file(tmp_path / "p16.npy")  # (its own resolution: no hint)
    np.testing.assert_array_equal(read_patterns_file(tmp_path / "dmd.npy", 16), p)


def test_messages_read_as_written():
    """A ratio under its floor is not said equal to it; a TOML's true is said as true."""
    from spslidar.config import Config
    from spslidar.errors import ConfigError
    from spslidar.pipeline.score import _apart

    a, b = _apart(2.066, 2.07)
    assert a != b and float(a) < float(b)
    assert _apart(1.5, 2.07) == ("1.50", "2.07")
    with pytest.raises(ConfigError, match=r"--size must be a number, got true \("):
        Config(size=True)


# -- a second audit of the commands' bad inputs (2026-12-03) ----------------------------------

def test_empty_files_are_said_to_be_empty(tmp_path, capsys):
    """A 0-byte PTU file and a 0-byte scene image: one line each saying the file is empty
    (they read "is not a PtuFile magic=b''" and imageio's plugin list cut mid-word), status
    2, nothing written; a longer reason is cut at a word."""
    (tmp_path / "e.ptu").write_bytes(b"")
    assert main(["inspect", str(tmp_path / "e.ptu")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is empty (0 bytes): not a PicoQuant PTU file" in err
    (tmp_path / "e.png").write_bytes(b"")
    assert main(["run", "--scene", str(tmp_path / "e.png"), "--size", "16", "--out",
                 str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "cannot read scene image e.png: the file is empty (0 bytes)" in err
    assert not (tmp_path / "o").exists()
    (tmp_path / "b.png").write_bytes(b"not a png at all, but long enough to be read " * 4)
    assert main(["run", "--scene", str(tmp_path / "b.png"), "--size", "16", "--out",
                 str(tmp_path / "o")]) == 2
    reason = capsys.readouterr().err.split("(", 1)[1].split("): use a grey", 1)[0]
    assert len(reason) <= 120 and (not reason.endswith("...") or reason.endswith(" ..."))


def test_inspect_checks_as_reconstruct_does(tmp_path, capsys):
    """``inspect``'s --bit-rate in reconstruct's range, said as reconstruct says it, and
    --pattern-size checked without --patterns too (0 passed silently: an audit of
    2026-12-03)."""
    from spslidar.io import write_acquisition_ptu

    events = [np.array([[0, 3], [1, 5]])]
    write_acquisition_ptu(tmp_path / "a.ptu", events, 31, 1e-10, periods_per_pattern=4)
    np.save(tmp_path / "c.npy", (np.arange(31) % 2).astype(np.uint8))
    for rate in ("0", "1e3", "1e14"):
        assert main(["inspect", str(tmp_path / "a.ptu"), "--code", str(tmp_path / "c.npy"),
                     "--bit-rate", rate]) == 2
        assert "--bit-rate must be in [1e6, 1e13] bits (TDC bins) per second" in (
            capsys.readouterr().err)
    assert main(["inspect", str(tmp_path / "a.ptu"), "--pattern-size", "0"]) == 2
    assert "--pattern-size" in capsys.readouterr().err


def test_numpys_short_write_is_said_as_a_full_disk(tmp_path, monkeypatch, capsys):
    """NumPy's own message for a short write ("1024 requested and 496 written", no errno) is
    said as the full disk it is, in one line, nothing left in --out (an audit of 2026-12-03)."""
    def short(*args, **kwargs):
        raise OSError("1024 requested and 496 written")

    monkeypatch.setattr(np, "save", short)
    assert main(["run", "--scene", "steps", "--size", "8", "--code-length", "127",
                 "--no-figure", "--out", str(tmp_path / "o")]) == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if "error:" in line]
    assert len(errors) == 1  # (the run's warnings come before it)
    assert ("error: the disk is full (1024 requested and 496 written): while writing --out"
            in errors[0])
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())
