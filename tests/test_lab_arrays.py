"""A lab's own pattern and code files (``spslidar.io.lab_arrays``): a folder of DMD images, a
multi-page TIFF, a MATLAB file, a text file of bits are read to exactly the arrays the
``.npy`` holds, and ``reconstruct`` on them gives the ``.npy``'s depth map bit for bit (the
same numbers in, the same computation); what their conventions cannot settle is refused in
one line with exit 2."""

from __future__ import annotations

import re

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
    """8 x 8 patterns shown as 4 x 4 blocks of mirrors (32 x 32 images) are read as they are,
    the same map as their .npy, with a warning naming --pattern-size; with --pattern-size 8
    they are the 8 x 8 patterns. A block holding two states, or a side that is no multiple
    of the size, is refused."""
    pats = _pats(5)
    big = np.kron(pats, np.ones((4, 4), np.float32))
    _save_folder(tmp_path / "dmd", big)
    with pytest.warns(UserWarning, match=r"4 x 4 blocks of mirrors at one state: "
                                         r"--pattern-size 8 reads them"):
        got = load_patterns(tmp_path / "dmd")
    np.testing.assert_array_equal(got, big.reshape(5, -1))
    np.testing.assert_array_equal(load_patterns(tmp_path / "dmd", size=8), pats.reshape(5, -1))
    np.save(tmp_path / "big.npy", big)  # (any format: the .npy alike)
    np.testing.assert_array_equal(load_patterns(tmp_path / "big.npy", size=8),
                                  pats.reshape(5, -1))
    big[2, 6:8, 10:12] = 1 - big[2, 6, 10]  # a 2 x 2 block changes inside a 4 x 4 one
    _save_folder(tmp_path / "fine", big)
    with pytest.raises(ConfigError, match=r"block at row 1, column 2 \(4 x 4 mirrors\) holds "
                                          r"two states"):
        load_patterns(tmp_path / "fine", size=8)
    with pytest.raises(ConfigError, match="is 32 x 32, not 5 x 5 blocks"):
        load_patterns(tmp_path / "fine", size=5)
    with pytest.raises(ConfigError, match="--pattern-size must be a whole number of 4"):
        load_patterns(tmp_path / "fine", size=2)
    _save_folder(tmp_path / "wide", np.kron(pats, np.ones((4, 6), np.float32)))
    with pytest.raises(ConfigError, match="is 48 x 32, not square: crop it"):
        load_patterns(tmp_path / "wide", size=8)


def test_low_sequency_patterns_keep_their_size(tmp_path):
    """Patterns that are all blocks of 2 x 2 (the lowest Walsh sequencies of a compressive
    sequence, an outside audit) are read at their own 16 x 16, as the .npy is, never reduced
    without being asked."""
    pats = np.kron(_pats(12), np.ones((2, 2), np.float32))
    _save_folder(tmp_path / "w", pats)
    with pytest.warns(UserWarning, match="--pattern-size 8"):
        np.testing.assert_array_equal(load_patterns(tmp_path / "w"), pats.reshape(12, -1))


def test_binary_images_at_any_depth(tmp_path):
    """A sequence of binary images reads 0/1 whatever each image's depth (an outside audit:
    1-bit beside 8-bit images read 1/255, 0/255 in 16 bits read 0.0039); a min-is-white TIFF
    is read as displayed."""
    import tifffile

    pats = _pats(6)
    mix = tmp_path / "mix"
    mix.mkdir()
    for i, p in enumerate(pats):
        img = Image.fromarray((p * 255).astype(np.uint8))
        (img.convert("1") if i % 2 else img).save(mix / f"p{i}.png")
    np.testing.assert_array_equal(load_patterns(mix), pats.reshape(6, -1))
    u16 = tmp_path / "u16"
    u16.mkdir()
    for i, p in enumerate(pats):
        Image.fromarray((p * 4095).astype(np.uint16)).save(u16 / f"p{i}.png")
    np.testing.assert_array_equal(load_patterns(u16), pats.reshape(6, -1))
    tifffile.imwrite(tmp_path / "wiz.tif", (1 - pats).astype(bool), photometric="miniswhite")
    np.testing.assert_array_equal(load_patterns(tmp_path / "wiz.tif"), pats.reshape(6, -1))
    wiz = tmp_path / "wiz"
    wiz.mkdir()
    for i, p in enumerate(pats):
        tifffile.imwrite(wiz / f"p{i}.tif", (255 - p * 255).astype(np.uint8),
                         photometric="miniswhite")
    np.testing.assert_array_equal(load_patterns(wiz), pats.reshape(6, -1))


def test_level_warnings(tmp_path):
    """Binary images of one type at two levels (0/1 beside a 0/255 frame) are each read as
    off and on, and said; 16-bit grey levels up to 4095 (12 bits stored in 16) are read over
    65535, and said."""
    pats = _pats(4)
    _save_folder(tmp_path / "two", pats[:3], scale=1)
    Image.fromarray((pats[3] * 255).astype(np.uint8)).save(tmp_path / "two" / "pattern_003.png")
    with pytest.warns(UserWarning, match=r"binary at different levels \(1, 255\)"):
        np.testing.assert_array_equal(load_patterns(tmp_path / "two"), pats.reshape(4, -1))
    grey = np.random.default_rng(2).integers(0, 4096, (4, 8, 8)).astype(np.uint16)
    (tmp_path / "g16").mkdir()
    for i, g in enumerate(grey):
        Image.fromarray(g).save(tmp_path / "g16" / f"{i}.png")
    with pytest.warns(UserWarning, match="16-bit grey levels up to 409"):
        got = load_patterns(tmp_path / "g16")
    np.testing.assert_allclose(got, grey.reshape(4, -1) / 65535, rtol=1e-6)


def test_tiff_memory_checked_before_its_pages_are_read(tmp_path, monkeypatch):
    """A multi-page TIFF is refused in one line where its pages would not fit (as a folder
    is), naming --pattern-size, before a page is decoded; PNM and PPM images are read."""
    import tifffile

    import spslidar.machine

    pats = _pats(6)
    tifffile.imwrite(tmp_path / "seq.tif", (pats * 255).astype(np.uint8))
    monkeypatch.setattr(spslidar.machine, "available_memory", lambda: 1000)
    with pytest.raises(ConfigError, match="more than the memory available: pages at the "
                                          "DMD's resolution\\? --pattern-size N"):
        load_patterns(tmp_path / "seq.tif")
    monkeypatch.undo()
    folder = tmp_path / "pnm"
    folder.mkdir()
    for i, p in enumerate(pats):
        suffix = "ppm" if i % 2 else "pnm"
        Image.fromarray((p * 255).astype(np.uint8)).save(folder / f"{i}.{suffix}")
    np.testing.assert_array_equal(load_patterns(folder), pats.reshape(6, -1))


def test_compressed_tiffs_without_imagecodecs(tmp_path):
    """LZW and CCITT group 4, the usual compressions of 1-bit TIFFs, which tifffile decodes
    only with imagecodecs (no dependency): read through Pillow."""
    from PIL import Image as PILImage

    pats = _pats(4)
    frames = [PILImage.fromarray((p * 255).astype(np.uint8)).convert("1") for p in pats]
    frames[0].save(tmp_path / "g4.tif", save_all=True, append_images=frames[1:],
                   compression="group4")
    np.testing.assert_array_equal(load_patterns(tmp_path / "g4.tif"), pats.reshape(4, -1))
    grey = [PILImage.fromarray((p * 255).astype(np.uint8)) for p in pats]
    grey[0].save(tmp_path / "lzw.tif", save_all=True, append_images=grey[1:],
                 compression="tiff_lzw")
    np.testing.assert_array_equal(load_patterns(tmp_path / "lzw.tif"), pats.reshape(4, -1))


def test_names_in_order_and_refused_when_not(tmp_path):
    """Zero-padded hexadecimal names in plain order (natural order read f_0a before f_1);
    two files of one stem, two names of one number, and a broken link among the images are
    refused (each shifted every pattern after it)."""
    pats = _pats(20)
    _save_folder(tmp_path / "hex", pats, names=[f"f_{i:02x}.png" for i in range(20)])
    np.testing.assert_array_equal(load_patterns(tmp_path / "hex"), pats.reshape(20, -1))
    _save_folder(tmp_path / "dup", pats[:4])
    Image.fromarray((pats[5] * 255).astype(np.uint8)).save(tmp_path / "dup" /
                                                          "pattern_002.bmp")
    with pytest.raises(ConfigError, match="pattern_002.bmp and pattern_002.png are one pattern"
                                          "|pattern_002.png and pattern_002.bmp are one"):
        load_patterns(tmp_path / "dup")
    _save_folder(tmp_path / "tie", pats[:3], names=["p5.png", "p05.png", "p6.png"])
    with pytest.raises(ConfigError, match="have the same number"):
        load_patterns(tmp_path / "tie")
    _save_folder(tmp_path / "link", pats[:3])
    (tmp_path / "link" / "pattern_010.png").symlink_to(tmp_path / "nowhere.png")
    with pytest.raises(ConfigError, match="pattern_010.png is named as an image but is no "
                                          "readable file"):
        load_patterns(tmp_path / "link")


def test_matlab_square_matrix_is_refused(tmp_path):
    """A full basis as a square N^2 x N^2 matrix: rows or columns cannot be told (an outside
    audit: columns read as rows gave 0.22 m for 0.006 m, exit 0); said with the reshape."""
    pats = _pats(64)
    sio.savemat(tmp_path / "full.mat", {"A": np.stack([p.ravel(order="F") for p in pats])})
    with pytest.raises(ConfigError, match=r"square 64 x 64 matrix: its patterns may be its "
                                          r"rows or its columns .*reshape\(A', 8, 8, \[\]\)"):
        load_patterns(tmp_path / "full.mat")


def test_matlab_struct_is_named(tmp_path):
    sio.savemat(tmp_path / "s.mat", {"S": {"P": np.zeros((8, 8, 4))}})
    with pytest.raises(ConfigError, match=r"S \(struct 1x1\).*save the array itself"):
        load_patterns(tmp_path / "s.mat")


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
    """16 patterns of 8 x 8 as a 16 x 64 matrix or its 64 x 16 transpose, and 64 patterns of
    4 x 4 (more patterns than pixels: a review found them read as 16 of 8 x 8): both sides
    squares, so which holds the pixels is refused in one line without --pattern-size, and
    read right with it, either way round."""
    for m, n in ((16, 8), (64, 4)):
        pats = _pats(m, n)
        sensing = np.stack([p.ravel(order="F") for p in pats])
        sio.savemat(tmp_path / "rows.mat", {"A": sensing})
        sio.savemat(tmp_path / "cols.mat", {"A": sensing.T.copy()})
        for name in ("rows", "cols"):
            with pytest.raises(ConfigError, match="both sides squares: its patterns may be"):
                load_patterns(tmp_path / f"{name}.mat")
            np.testing.assert_array_equal(load_patterns(tmp_path / f"{name}.mat", size=n),
                                          pats.reshape(m, -1), err_msg=f"{name} {m}")


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


@pytest.mark.parametrize("text,encoding", [
    ("0110100 % an m-sequence\n", "utf-8"), ("% made in MATLAB\n0 1 1 0 1 0 0\n", "utf-8"),
    ("0110100\r\n", "utf-16"), ("0110 # first four\n100\n", "utf-8")])
def test_code_text_comments_and_encodings(tmp_path, text, encoding):
    """MATLAB's % comments, comments after the bits, and Notepad's UTF-16 "Unicode"."""
    f = tmp_path / "code.txt"
    f.write_bytes(text.encode(encoding))
    np.testing.assert_array_equal(load_code(f), [0, 1, 1, 0, 1, 0, 0])


@pytest.mark.parametrize("text,said", [
    ("code\n0110100\n", "a header line? start it with #"),
    ("01101002\n", "a run of bits holds '2' at character 8 of 8"),
    ("".join(f"{b},{1 - b}\n" for b in [0, 1, 1, 0, 1, 0, 0, 1]), "2 columns on each of its 8"),
    ("".join(f"{b} {1 - b}\n" for b in [0, 1, 1, 0, 1, 0, 0, 1]), "2 columns on each of its 8"),
    ("".join(f"   {b:.7e}   {1 - b:.7e}\n" for b in [0, 1, 1, 0, 1, 0, 0, 1]),
     "2 columns on each of its 8"),  # (MATLAB's save -ascii)
])
def test_code_text_refused_with_the_cause(tmp_path, text, said):
    f = tmp_path / "code.txt"
    f.write_text(text)
    with pytest.raises(ConfigError, match=re.escape(said)):
        load_code(f)


def test_a_wrapped_code_is_no_table(tmp_path):
    """Runs of bits, two to a line, are a code wrapped, not a table of columns."""
    f = tmp_path / "code.txt"
    f.write_text("0110 1001\n" * 8)
    assert load_code(f).size == 64


def test_code_as_mat_and_bipolar_npy(tmp_path):
    bits = np.array([1, 0, 0, 1, 1, 1, 0], dtype=np.uint8)
    sio.savemat(tmp_path / "c.mat", {"code": bits[None, :].astype(np.float64)})  # 1 x L
    np.testing.assert_array_equal(load_code(tmp_path / "c.mat"), bits)
    np.save(tmp_path / "pm.npy", 2.0 * bits - 1)
    np.testing.assert_array_equal(load_code(tmp_path / "pm.npy"), bits)
    np.save(tmp_path / "row.npy", bits[None, :])  # (1, L), as the .mat and .npz are read
    np.testing.assert_array_equal(load_code(tmp_path / "row.npy"), bits)


def test_reconstruct_from_lab_files_equals_npy(tmp_path):
    """The same acquisition through a folder of PNGs and a text code, and through a MATLAB
    N x N x M stack and a +-1 code, gives the .npy's depth map exactly."""
    ptu, pats, code, _, _ = _acquisition(tmp_path)
    _save_folder(tmp_path / "dmd", pats)
    (tmp_path / "code.txt").write_text("".join(str(int(b)) for b in code) + "\n")
    sio.savemat(tmp_path / "seq.mat", {"P": np.moveaxis(pats, 0, -1),
                                        "code": 2 * code[None, :] - 1})
    common = ["--bit-rate", "10e9", "--range-gate", "3.5", "4.8", "--no-figure"]
    _save_folder(tmp_path / "mirrors", np.kron(pats, np.ones((3, 3), np.float32)))
    runs = {"npy": ("patterns.npy", "code.npy", []), "png": ("dmd", "code.txt", []),
            "mat": ("seq.mat:P", "seq.mat:code", []),
            "mirrors": ("mirrors", "code.npy", ["--pattern-size", "8"])}
    depth = {}
    for key, (p, c, extra) in runs.items():
        assert main(["reconstruct", "--ptu", str(ptu), "--patterns", str(tmp_path / p),
                     "--code", str(tmp_path / c), "--out", str(tmp_path / f"out_{key}"), *common,
                     *extra]) == 0
        depth[key] = np.load(tmp_path / f"out_{key}" / "depth.npy")
    for key in ("png", "mat", "mirrors"):
        np.testing.assert_array_equal(depth[key], depth["npy"], err_msg=key)
    # metrics.json names each file as given and hashes what was read: alike over the formats
    import json

    inputs = {k: json.loads((tmp_path / f"out_{k}" / "metrics.json").read_text())["inputs"]
              for k in runs}
    for key, (p, c, extra) in runs.items():
        assert inputs[key]["patterns"]["file"] == str(tmp_path / p)
        assert inputs[key]["code"]["file"] == str(tmp_path / c)
        assert inputs[key]["code"]["family"] is None
        assert inputs[key]["patterns"]["pattern_size"] == (8 if extra else None)
        assert (inputs[key]["patterns"]["n_patterns"], inputs[key]["patterns"]["side"]) == (
            len(pats), 8)
        for what in ("patterns", "code"):
            assert inputs[key][what]["sha256"] == inputs["npy"][what]["sha256"], (key, what)
    assert inputs["npy"]["code"]["bits"] == code.size
    # the API alike: an array given finer, pattern_size reading it as the patterns
    from spslidar.pipeline.inputs import patterns_in

    np.testing.assert_array_equal(
        patterns_in(np.kron(pats, np.ones((2, 2), np.float32)), 8), pats.reshape(len(pats), -1))


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
        ("frame", "frame", ok_code, "the images are 12 x 8, not square: crop them"),
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


def test_inputs_record_tells_patterns_and_codes_apart(tmp_path):
    """The record's hashes differ where the patterns or the code do (one mirror, one bit),
    and a code family given by name is recorded as such, its bits hashed as a file's."""
    from argparse import Namespace

    from spslidar.cli_measured import _code
    from spslidar.codes import CODES
    from spslidar.pipeline.inputs import input_record

    pats = _pats().reshape(6, -1)
    code = np.array([0, 1, 1, 0, 1, 0, 0], np.uint8)
    base = input_record(tmp_path / "p.npy", pats, None, code, code)
    assert base["patterns"]["file"] == str(tmp_path / "p.npy")
    assert base["code"]["file"] is None  # (an array)
    other = pats.copy()
    other[2, 5] = 1 - other[2, 5]
    assert input_record(None, other, None, code, code)["patterns"]["sha256"] != \
        base["patterns"]["sha256"]
    assert input_record(None, pats, None, code, code ^ 1)["code"]["sha256"] != \
        base["code"]["sha256"]
    assert input_record(None, pats, None, code, code)["patterns"]["sha256"] == \
        base["patterns"]["sha256"]
    bits, source = _code(Namespace(code="mseq", code_length=31, code_index=None))
    assert source == {"file": None, "family": {
        "name": "mseq", "length": 31, "index": CODES.get("mseq").defaults.get("index", 0)}}
    assert bits.size == 31
    np.save(tmp_path / "c.npy", code)
    bits, source = _code(Namespace(code=str(tmp_path / "c.npy"), code_length=None,
                                   code_index=None))
    np.testing.assert_array_equal(bits, code)
    assert source == {"file": str(tmp_path / "c.npy"), "family": None}
    np.savez(tmp_path / "c.npz", bits=code)
    given = f"{tmp_path / 'c.npz'}:bits"
    assert _code(Namespace(code=given, code_length=None, code_index=None))[1] == {
        "file": given, "family": None}


@pytest.mark.parametrize("levels", ["binary", "grey", "sixteen"])
def test_integer_arrays_read_alike_in_every_file(tmp_path, levels):
    """An integer array is stored levels, read as an image's in a .npy, an .npz, a .mat and
    in Python alike (a .mat of uint8 0/255 was read as 0/1 while the same .npy was refused
    with "divide by 255": the audit of stop 66)."""
    from spslidar.pipeline.inputs import check_patterns

    pats = _pats()
    if levels == "binary":
        arr, want = (pats * 255).astype(np.uint8), pats
    elif levels == "grey":
        arr = np.random.default_rng(5).integers(0, 256, pats.shape).astype(np.uint8)
        want = arr / 255.0
    else:
        arr = np.random.default_rng(6).integers(0, 65536, pats.shape).astype(np.uint16)
        want = arr / 65535.0
    np.save(tmp_path / "p.npy", arr)
    np.savez(tmp_path / "p.npz", P=arr)
    sio.savemat(tmp_path / "p.mat", {"P": np.moveaxis(arr, 0, -1)})
    got = {f: load_patterns(tmp_path / f) for f in ("p.npy", "p.npz", "p.mat")}
    got["python"] = check_patterns(arr)
    for key, value in got.items():
        # (float32 states: levels over 65535 kept to float32's 6e-8 relative step)
        np.testing.assert_allclose(value, want.reshape(len(pats), -1), rtol=1e-6, atol=0,
                                   err_msg=key)


def test_the_code_is_read_once_and_a_family_is_not_shadowed(tmp_path, monkeypatch, capsys):
    """--code given as a FIFO was read by the command line and again by the library, and
    hung (an audit of stop 67): read once, it gives the file's map; a file (or folder) named
    like a code family in the working folder is refused, not read for the family; the API
    refuses a family's name, naming load_code."""
    import json
    import os
    import threading

    from spslidar.pipeline.inputs import code_in

    ptu, pats, code, _, _ = _acquisition(tmp_path)
    fifo = tmp_path / "code.txt"
    os.mkfifo(fifo)
    text = "".join(str(int(b)) for b in code) + "\n"
    writer = threading.Thread(target=lambda: fifo.write_text(text), daemon=True)
    writer.start()
    assert main(["reconstruct", "--ptu", str(ptu), "--patterns", str(tmp_path / "patterns.npy"),
                 "--code", str(fifo), "--bit-rate", "10e9", "--range-gate", "3.5", "4.8",
                 "--no-figure", "--out", str(tmp_path / "fifo_out")]) == 0
    writer.join(timeout=5)
    assert not writer.is_alive()
    metrics = json.loads((tmp_path / "fifo_out" / "metrics.json").read_text())
    assert metrics["inputs"]["code"]["file"] == str(fifo)
    monkeypatch.chdir(tmp_path)
    np.save(tmp_path / "stale.npy", np.roll(code, 40))
    os.replace(tmp_path / "stale.npy", tmp_path / "mseq")
    (tmp_path / "gold").mkdir()
    capsys.readouterr()
    for name, kind in (("mseq", "file"), ("gold", "folder")):
        assert main(["reconstruct", "--ptu", str(ptu), "--patterns", "patterns.npy",
                     "--code", name, "--code-length", "127", "--bit-rate", "10e9",
                     "--range-gate", "3.5", "4.8", "--out", f"o_{name}"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"names both the code family and a {kind}" in err[0], err
        assert not (tmp_path / f"o_{name}").exists()
    np.testing.assert_array_equal(load_code("./mseq"), np.roll(code, 40))  # (the file)
    with pytest.raises(ConfigError, match=r"names a code family: give its bits, "
                                          r"spslidar.pipeline.real.load_code\('Gold', L\)"):
        code_in("Gold")  # (no file of that name here, unlike gold/)


def test_integer_levels_that_cannot_be_read_alike_are_refused(tmp_path):
    """0/1 patterns of an 8-bit type beside grey ones were read as 0 and 1/255 with exit 0
    (a set with one 0..255 pattern: 0.44 m for 0.03 m; a stray 2 in 0/1 patterns: the
    reflectivity 255 times high); a signed int16's 0..255 was read over 32767: each refused
    in one line, in an array and in a folder of images (an audit of stop 67). A set of
    binary patterns at two levels is still read as off and on, and said."""
    from spslidar.pipeline.inputs import check_patterns

    pats = (_pats() * 1).astype(np.uint8)
    mixed = pats.copy()
    mixed[-1] = np.random.default_rng(8).integers(0, 256, mixed[-1].shape)
    stray = pats.copy()
    stray[0, 0, 0] = 2
    for arr in (mixed, stray):
        with pytest.raises(ConfigError, match="hold only 0 and 1 as uint8, beside grey levels"):
            check_patterns(arr)
    with pytest.raises(ConfigError, match=r"values from 0 to \d+: 8-bit levels 0-255"):
        check_patterns(mixed.astype(np.int16))
    two = pats.copy()
    two[1] *= 255
    with pytest.warns(UserWarning, match=r"binary at different levels \(1, 255\)"):
        np.testing.assert_array_equal(check_patterns(two), pats.reshape(len(pats), -1))
    folder = _save_folder(tmp_path / "mixed", pats, scale=1)  # (0/1 PNGs of 8 bits)
    Image.fromarray(mixed[-1]).save(folder / "pattern_009.png")
    with pytest.raises(ConfigError, match="image 0 and others hold only 0 and 1 as uint8"):
        load_patterns(folder)


# -- layouts NumPy's order settles: said, not refused (an outside audit of 2026-12-01) --------


def _layout_warnings(path, recwarn):
    read_patterns_file(path)
    return [str(w.message) for w in recwarn if "--patterns" in str(w.message)]


def test_npy_layouts_numpy_settles_are_said(tmp_path, recwarn):
    rng = np.random.default_rng(RNG_SEED)
    basis = (rng.random((16, 16)) > 0.5).astype(np.float32)  # 16 patterns of 4 x 4, rows
    np.save(tmp_path / "basis.npy", basis)
    said = _layout_warnings(tmp_path / "basis.npy", recwarn)
    assert len(said) == 1 and "one pattern per row" in said[0] and "(A.T)" in said[0]
    recwarn.clear()
    # a symmetric basis (Sylvester's Hadamard) reads the same either way: nothing to say
    from scipy.linalg import hadamard

    np.save(tmp_path / "sylvester.npy", ((hadamard(16) + 1) / 2).astype(np.float32))
    assert _layout_warnings(tmp_path / "sylvester.npy", recwarn) == []
    # an N x N x N stack: which axis counts the patterns is NumPy's order
    np.save(tmp_path / "cube.npy", (rng.random((8, 8, 8)) > 0.5).astype(np.float32))
    said = _layout_warnings(tmp_path / "cube.npy", recwarn)
    assert len(said) == 1 and "np.moveaxis(P, -1, 0)" in said[0]
    recwarn.clear()
    # both sides squares, more rows than pixels: the columns may be the patterns
    np.savez(tmp_path / "tall.npz", A=(rng.random((64, 16)) > 0.5).astype(np.float32))
    said = _layout_warnings(tmp_path / "tall.npz", recwarn)
    assert len(said) == 1 and "tall.npz:A" in said[0] and "its 16 columns of 8 x 8" in said[0]
    recwarn.clear()
    # what NumPy's order reads without doubt is not warned: (M, N, N), (M, N^2) with M < N^2
    np.save(tmp_path / "stack.npy", (rng.random((6, 8, 8)) > 0.5).astype(np.float32))
    np.save(tmp_path / "rows.npy", (rng.random((16, 64)) > 0.5).astype(np.float32))
    assert _layout_warnings(tmp_path / "stack.npy", recwarn) == []
    assert _layout_warnings(tmp_path / "rows.npy", recwarn) == []


def test_patterns_in_columns_are_refused_with_the_transpose_named(tmp_path):
    from spslidar.pipeline.inputs import check_patterns

    rng = np.random.default_rng(RNG_SEED)
    cols = (rng.random((64, 10)) > 0.5).astype(np.float32)  # 10 patterns of 8 x 8, columns
    with pytest.raises(ConfigError, match=r"one pattern of 8 x 8 per column\? save its "
                                          r"transpose \(A\.T\)"):
        check_patterns(cols)
    assert check_patterns(cols.T).shape == (10, 64)
    with pytest.raises(ConfigError) as err:  # no square side: no transpose to name
        check_patterns(np.ones((10, 7), np.float32))
    assert "transpose" not in str(err.value)
