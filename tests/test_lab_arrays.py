"""A lab's own pattern and code files (``spslidar.io.lab_arrays``): a folder of DMD images, a
multi-page TIFF, a MATLAB file, a text file of bits are read to exactly the arrays the
``.npy`` holds, and ``reconstruct`` on them gives the ``.npy``'s depth map bit for bit (the
same numbers in, the same computation); what their conventions cannot settle is refused in
one line with exit 2."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image
from scipy import io as sio
from test_reconstruct import _acquisition

from spslidar.cli import main
from spslidar.errors import ConfigError
from spslidar.io.lab_arrays import read_code_file, read_patterns_file
from spslidar.pipeline.real import load_code, load_patterns

RNG_SEED = 3


def _pats(m=6, n=8, seed=RNG_SEED):
    """Binary patterns that tell every axis apart (no symmetry a transpose would hide)."""
    return (np.random.default_rng(seed).random((m, n, n)) < 0.5).astype(np.float32)


def _save_folder(folder, pats, names=None, mode="L", scale=255):
    folder.mkdir()
    for i, p in enumerate(pats):
        name = names[i] if names else f"pattern_{i:03d}.png"
        img = Image.fromarray((p * scale).astype(np.uint8), mode="L")
        (img.convert("1") if mode == "1" else img).save(folder / name)
    return folder


def test_folder_of_images_in_natural_order(tmp_path):
    """One PNG per pattern named p1 ... p12: read in the order 1, 2, ..., 12 (a plain sort
    puts p10 after p1), 8-bit 0/255 read as 0/1, row 0 at the top."""
    pats = _pats(12)
    folder = tmp_path / "dmd"
    folder.mkdir()
    for i in (4, 11, 0, 9, 1, 2, 3, 5, 6, 7, 8, 10):  # written out of order on purpose
        Image.fromarray((pats[i] * 255).astype(np.uint8)).save(folder / f"p{i + 1}.png")
    (folder / "README.txt").write_text("patterns for the DMD")  # (a note beside them: ignored)
    np.testing.assert_array_equal(load_patterns(folder), pats.reshape(12, -1))


@pytest.mark.parametrize("mode,scale", [("1", 255), ("L", 1)])
def test_folder_of_one_bit_and_zero_one_images(tmp_path, mode, scale):
    """1-bit BMPs, and 8-bit PNGs holding 0/1 (an array of bits saved as 8-bit), are the same
    mirror states as 0/255."""
    pats = _pats()
    folder = tmp_path / "d"
    folder.mkdir()
    for i, p in enumerate(pats):
        img = Image.fromarray((p * 255 if mode == "1" else p * scale).astype(np.uint8))
        if mode == "1":
            img.convert("1").save(folder / f"{i}.bmp")
        else:
            img.save(folder / f"{i}.png")
    np.testing.assert_array_equal(load_patterns(folder), pats.reshape(len(pats), -1))


@pytest.mark.parametrize("mode", ["RGB", "LA", "RGBA", "P"])
def test_grey_levels_and_rgb_grey(tmp_path, mode):
    """8-bit grey levels are divided by 255; an RGB image whose channels are equal is grey,
    and so is one with an alpha channel that is the same everywhere (grey + alpha, RGBA), or
    a palette image."""
    levels = np.random.default_rng(1).integers(0, 256, (4, 8, 8)).astype(np.uint8)
    folder = tmp_path / "g"
    folder.mkdir()
    for i, p in enumerate(levels):
        Image.fromarray(p).convert(mode).save(folder / f"{i}.png")
    np.testing.assert_allclose(load_patterns(folder), levels.reshape(4, -1) / 255,
                               rtol=0, atol=1e-7)  # (float32 of k/255)


def test_images_at_the_dmds_resolution(tmp_path):
    """8 x 8 patterns shown as 4 x 4 blocks of mirrors (32 x 32 images) are read as the 8 x 8
    patterns, with a warning; a pattern whose blocks are 2 x 2 in one place (a finer
    pattern among them) keeps every image's 2 x 2 blocks."""
    pats = _pats(5)
    big = np.kron(pats, np.ones((4, 4), np.float32))
    _save_folder(tmp_path / "dmd", big)
    with pytest.warns(UserWarning, match=r"4 x 4 blocks of mirrors at one state, so the "
                                         r"patterns are 8 x 8 .*images are 32 x 32"):
        got = load_patterns(tmp_path / "dmd")
    np.testing.assert_array_equal(got, pats.reshape(5, -1))
    big[2, 6:8, 10:12] = 1 - big[2, 6, 10]  # a 2 x 2 block changes inside a 4 x 4 one
    _save_folder(tmp_path / "fine", big)
    with pytest.warns(UserWarning, match="2 x 2 blocks"):
        assert load_patterns(tmp_path / "fine").shape == (5, 16 * 16)


def test_multipage_tiff(tmp_path):
    import tifffile

    pats = _pats()
    tifffile.imwrite(tmp_path / "seq.tif", (pats * 255).astype(np.uint8))
    np.testing.assert_array_equal(load_patterns(tmp_path / "seq.tif"), pats.reshape(6, -1))


def test_matlab_stack_and_sensing_matrix(tmp_path):
    """MATLAB's P(:,:,k) (N x N x M), an M x N x N array, and a sensing matrix whose row m is
    P(:)' (column-major), as rows or as columns: all the same patterns."""
    pats = _pats(6)
    stack = np.moveaxis(pats, 0, -1)  # N x N x M: P(:,:,k) is pats[k]
    sensing = np.stack([p.ravel(order="F") for p in pats])  # row m = P_m(:)'
    sio.savemat(tmp_path / "stack.mat", {"P": stack})
    sio.savemat(tmp_path / "mnn.mat", {"P": pats})
    sio.savemat(tmp_path / "rows.mat", {"A": sensing, "note": "made in MATLAB"})
    sio.savemat(tmp_path / "cols.mat", {"A": sensing.T.copy()})
    want = pats.reshape(6, -1)
    for name in ("stack", "mnn", "rows", "cols"):
        np.testing.assert_array_equal(load_patterns(tmp_path / f"{name}.mat"), want,
                                      err_msg=name)


def test_matlab_sensing_matrix_both_axes_square(tmp_path):
    """16 patterns of 8 x 8: a 16 x 64 matrix and its 64 x 16 transpose both have square
    axes; the pixels are the longer axis (fewer patterns than pixels), either way round."""
    pats = _pats(16)
    sensing = np.stack([p.ravel(order="F") for p in pats])
    sio.savemat(tmp_path / "rows.mat", {"A": sensing})
    sio.savemat(tmp_path / "cols.mat", {"A": sensing.T.copy()})
    for name in ("rows", "cols"):
        np.testing.assert_array_equal(load_patterns(tmp_path / f"{name}.mat"),
                                      pats.reshape(16, -1), err_msg=name)


def test_matlab_and_npz_name_one_of_several(tmp_path):
    pats = _pats(5)
    sio.savemat(tmp_path / "two.mat", {"P": np.moveaxis(pats, 0, -1),
                                        "Q": np.moveaxis(1 - pats, 0, -1)})
    with pytest.raises(ConfigError, match=r"2 arrays that could be --patterns \(P, Q\): "
                                          r"name one as .*two\.mat:P"):
        load_patterns(tmp_path / "two.mat")
    np.testing.assert_array_equal(load_patterns(f"{tmp_path / 'two.mat'}:Q"),
                                  (1 - pats).reshape(5, -1))
    np.savez(tmp_path / "two.npz", a=pats, b=1 - pats)
    np.testing.assert_array_equal(load_patterns(f"{tmp_path / 'two.npz'}:a"), pats.reshape(5, -1))
    with pytest.raises(ConfigError, match="no array named 'c'"):
        load_patterns(f"{tmp_path / 'two.npz'}:c")


@pytest.mark.parametrize("text", ["0110100\n", "0 1 1 0 1 0 0", "0,1,1,0,1,0,0\n",
                                  "# made by the pattern generator\n0110\n100\n",
                                  "-1 1 1 -1 1 -1 -1", "-1;+1;+1;-1;1;-1;-1",
                                  "0.0\n1.0\n1\n0\n1\n0\n0"])
def test_code_as_text(tmp_path, text):
    """A code's bits as characters, numbers, with separators or without, 0/1 or -1/+1."""
    f = tmp_path / "code.txt"
    f.write_text(text)
    np.testing.assert_array_equal(load_code(f), [0, 1, 1, 0, 1, 0, 0])


def test_code_as_mat_and_bipolar_npy(tmp_path):
    bits = np.array([1, 0, 0, 1, 1, 1, 0], dtype=np.uint8)
    sio.savemat(tmp_path / "c.mat", {"code": bits[None, :].astype(np.float64)})  # 1 x L
    np.testing.assert_array_equal(load_code(tmp_path / "c.mat"), bits)
    np.save(tmp_path / "pm.npy", 2.0 * bits - 1)
    np.testing.assert_array_equal(load_code(tmp_path / "pm.npy"), bits)


def test_reconstruct_from_lab_files_equals_npy(tmp_path):
    """The same acquisition through a folder of PNGs and a text code, and through a MATLAB
    N x N x M stack and a +-1 code, gives the .npy's depth map exactly."""
    ptu, pats, code, _, _ = _acquisition(tmp_path)
    _save_folder(tmp_path / "dmd", pats)
    (tmp_path / "code.txt").write_text("".join(str(int(b)) for b in code) + "\n")
    sio.savemat(tmp_path / "seq.mat", {"P": np.moveaxis(pats, 0, -1),
                                        "code": 2 * code[None, :] - 1})
    common = ["--bit-rate", "10e9", "--range-gate", "3.5", "4.8", "--no-figure"]
    runs = {"npy": ("patterns.npy", "code.npy"), "png": ("dmd", "code.txt"),
            "mat": ("seq.mat:P", "seq.mat:code")}
    depth = {}
    for key, (p, c) in runs.items():
        assert main(["reconstruct", "--ptu", str(ptu), "--patterns", str(tmp_path / p),
                     "--code", str(tmp_path / c), "--out", str(tmp_path / key), *common]) == 0
        depth[key] = np.load(tmp_path / key / "depth.npy")
    np.testing.assert_array_equal(depth["png"], depth["npy"])
    np.testing.assert_array_equal(depth["mat"], depth["npy"])


def _hdf5_mat(path):
    path.write_bytes(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Nov 30 2026"
                     .ljust(128, b" ") + b"\x89HDF\r\n\x1a\n" + bytes(64))


def _refusals(tmp_path):
    """(what, patterns, code, expected message) for each file the conventions refuse."""
    pats = _pats(4)
    _hdf5_mat(tmp_path / "v73.mat")
    sio.savemat(tmp_path / "cube.mat", {"P": np.zeros((8, 8, 8))})
    sio.savemat(tmp_path / "none.mat", {"x": np.zeros(3)})
    (tmp_path / "empty").mkdir()
    _save_folder(tmp_path / "sizes", pats)
    Image.fromarray(np.zeros((10, 8), np.uint8)).save(tmp_path / "sizes" / "pattern_009.png")
    _save_folder(tmp_path / "jpg", pats)
    Image.fromarray(np.zeros((8, 8), np.uint8)).save(tmp_path / "jpg" / "x.jpg")
    colour = np.zeros((8, 8, 3), np.uint8)
    colour[..., 0] = 255
    _save_folder(tmp_path / "rgb", pats)
    Image.fromarray(colour).save(tmp_path / "rgb" / "pattern_010.png")
    Image.fromarray(np.zeros((8, 8), np.uint8)).save(tmp_path / "one.png")
    (tmp_path / "frame").mkdir()
    for i, pat in enumerate(pats):  # the DMD's whole 12 x 8 frame around an 8 x 8 region
        img = np.zeros((8, 12), np.uint8)
        img[:, 2:10] = pat * 255
        Image.fromarray(img).save(tmp_path / "frame" / f"{i}.png")
    import tifffile
    tifffile.imwrite(tmp_path / "page.tif", np.zeros((8, 8), np.uint8))
    (tmp_path / "words.txt").write_text("bits: 0 1 1 0\n")
    (tmp_path / "p.bin").write_bytes(bytes(range(64)))
    (tmp_path / "blank.txt").write_text("# nothing\n\n")
    ok_code = tmp_path / "ok.txt"
    ok_code.write_text("0110100")
    _save_folder(tmp_path / "good", pats)
    return [
        ("v7.3", "v73.mat", ok_code, "MATLAB 7.3 file (HDF5): save it with save(..., '-v7')"),
        ("N x N x N", "cube.mat", ok_code, "which axis counts the patterns is not known"),
        ("no candidate", "none.mat", ok_code, "holds no array that can be --patterns"),
        ("empty folder", "empty", ok_code, "a folder with no image in it"),
        ("sizes", "sizes", ok_code, "every pattern image must have the same size"),
        ("jpeg", "jpg", ok_code, "lossy images (x.jpg)"),
        ("colour", "rgb", ok_code, "is in colour"),
        ("one image", "one.png", ok_code, "is one image: give the folder"),
        ("frame", "frame", ok_code, "the images are 12 x 8 patterns, not square: crop them"),
        ("one page", "page.tif", ok_code, "a TIFF of one page"),
        ("unknown", "p.bin", ok_code, "spslidar reads patterns from .npy, .npz, .mat, a "
                                      "multi-page .tif or a folder of images"),
        ("words", "good", tmp_path / "words.txt", "'bits:' is not a bit"),
        ("blank", "good", tmp_path / "blank.txt", "holds no bits"),
    ]


def test_refusals_one_line_exit_2(tmp_path, capsys):
    """Each file the conventions cannot settle: exit 2, one line naming the cause, no output
    folder."""
    ptu, *_ = _acquisition(tmp_path)
    for what, pats, code, message in _refusals(tmp_path):
        out = tmp_path / f"out_{what.replace(' ', '_')}"
        code_arg = str(code)
        rc = main(["reconstruct", "--ptu", str(ptu), "--patterns", str(tmp_path / pats),
                   "--code", code_arg, "--bit-rate", "10e9", "--range-gate", "3.5", "4.8",
                   "--out", str(out)])
        err = capsys.readouterr().err.strip()
        assert rc == 2, what
        assert len(err.splitlines()) == 1, (what, err)
        assert message in err, (what, err)
        assert not out.exists(), what


def test_readers_return_arrays_unchecked(tmp_path):
    """The readers give arrays as stored (levels scaled, axes ordered); the checks are
    check_patterns' and check_code's, so a .npy and a folder are refused alike."""
    pats = _pats(3)
    _save_folder(tmp_path / "f", pats * 0)  # every mirror off
    assert read_patterns_file(tmp_path / "f").shape == (3, 8, 8)
    with pytest.raises(ConfigError, match="every mirror of every pattern is off"):
        load_patterns(tmp_path / "f")
    (tmp_path / "c.txt").write_text("1 2 1")
    assert list(read_code_file(tmp_path / "c.txt")) == [1, 2, 1]
    with pytest.raises(ConfigError, match="must hold 0/1 bits"):
        load_code(tmp_path / "c.txt")
