"""RGB-D frames and intrinsics: what is read, and what is refused before decoding (docs/security.md)."""

from __future__ import annotations

import zlib

import cv2
import numpy as np
import pytest

from baseplace.errors import InputError
from baseplace.perception.rgbd import Intrinsics, load_depth, load_frame, load_rgb, parse_intrinsics


def _png_header_only(path, width, height, bit_depth=8, colour=2):
    """A PNG whose IHDR declares ``width`` x ``height`` over a few bytes of pixel data."""
    import struct

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, colour, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(b"\0" * 64))
        + chunk(b"IEND", b"")
    )
    return path


def test_an_rgb_png_and_a_16_bit_depth_png_in_millimetres_are_read(tmp_path):
    rgb = np.zeros((4, 6, 3), np.uint8)
    rgb[..., 0] = 200  # red
    cv2.imwrite(str(tmp_path / "c.png"), rgb[..., ::-1])
    depth = np.full((4, 6), 1500, np.uint16)
    depth[0, 0] = 0
    cv2.imwrite(str(tmp_path / "d.png"), depth)
    frame = load_frame(tmp_path / "c.png", tmp_path / "d.png", "500 500 2.5 1.5")
    assert frame.rgb.shape == (4, 6, 3) and frame.rgb[1, 1, 0] == 200 and frame.rgb[1, 1, 2] == 0
    assert frame.depth[1, 1] == pytest.approx(1.5) and np.isnan(frame.depth[0, 0])
    p = frame.points_camera()
    assert p[1, 2] == pytest.approx([(2 - 2.5) / 500 * 1.5, (1 - 1.5) / 500 * 1.5, 1.5])


def test_a_float32_npy_depth_in_metres_is_read_and_non_positive_is_no_return(tmp_path):
    d = np.array([[1.0, 0.0], [np.inf, -1.0]], np.float32)
    np.save(tmp_path / "d.npy", d)
    out = load_depth(tmp_path / "d.npy")
    assert out[0, 0] == 1.0 and np.isnan(out[0, 1]) and np.isnan(out[1]).all()


@pytest.mark.parametrize(
    "array, fragment",
    [(np.zeros((2, 2), np.int32), "must be float32"), (np.zeros((2, 2, 3), np.float32), "(H, W)"),
     (np.array([[None]], dtype=object), "must be float32")],
)  # fmt: skip
def test_an_npy_depth_of_the_wrong_dtype_or_shape_is_refused_before_loading(tmp_path, array, fragment):
    np.save(tmp_path / "d.npy", array, allow_pickle=True)
    with pytest.raises(InputError, match=fragment.replace("(", r"\(").replace(")", r"\)")):
        load_depth(tmp_path / "d.npy")


def test_a_png_declaring_a_huge_image_is_refused_before_decoding(tmp_path):
    with pytest.raises(InputError, match="declares more pixels than any camera image"):
        load_rgb(_png_header_only(tmp_path / "huge.png", 16000, 16000))  # Pillow's bomb limit
    with pytest.raises(InputError, match="more than its .* bytes can hold"):
        load_rgb(_png_header_only(tmp_path / "big.png", 8000, 8000))
    with pytest.raises(InputError, match="more than its .* bytes can hold"):
        load_depth(_png_header_only(tmp_path / "bigd.png", 8000, 8000, bit_depth=16, colour=0))


def test_an_rgb_depth_image_and_other_bad_files_are_one_line_errors(tmp_path):
    cv2.imwrite(str(tmp_path / "c.png"), np.zeros((4, 6, 3), np.uint8))
    with pytest.raises(InputError, match="16-bit single-channel"):
        load_depth(tmp_path / "c.png")
    (tmp_path / "junk.png").write_bytes(b"not an image")
    with pytest.raises(InputError, match="corrupt"):
        load_rgb(tmp_path / "junk.png")
    with pytest.raises(InputError, match="unknown suffix '.bmp'"):
        load_rgb(tmp_path / "c.bmp")


def test_images_of_different_sizes_are_refused(tmp_path):
    cv2.imwrite(str(tmp_path / "c.png"), np.zeros((4, 6, 3), np.uint8))
    cv2.imwrite(str(tmp_path / "d.png"), np.ones((5, 6), np.uint16))
    with pytest.raises(InputError, match="6x4 and the depth image 6x5"):
        load_frame(tmp_path / "c.png", tmp_path / "d.png", "500 500 2.5 1.5")


@pytest.mark.parametrize(
    "spec, fragment",
    [("500 500 3", "neither 4 numbers"), ("0 500 3 2", "positive"), ("nan 500 3 2", "finite"),
     ("x y z w", "neither 4 numbers")],
)  # fmt: skip
def test_bad_intrinsics_are_refused(spec, fragment):
    with pytest.raises(InputError, match=fragment):
        parse_intrinsics(spec)


def test_a_principal_point_outside_the_image_is_refused():
    with pytest.raises(InputError, match="outside the 6x4 image"):
        Intrinsics(500, 500, 10, 1).check_image(6, 4)


def test_a_ros_camera_info_yaml_is_read_both_ways(tmp_path):
    calib = tmp_path / "calib.yaml"
    calib.write_text("image_width: 640\nimage_height: 480\ncamera_matrix:\n  rows: 3\n  cols: 3\n"
                     "  data: [525.0, 0, 319.5, 0, 526.0, 239.5, 0, 0, 1]\n")  # fmt: skip
    K = parse_intrinsics(str(calib))
    assert (K.fx, K.fy, K.cx, K.cy, K.width, K.height) == (525.0, 526.0, 319.5, 239.5, 640, 480)
    echo = tmp_path / "info.yaml"
    echo.write_text("height: 480\nwidth: 640\nk: [600.0, 0.0, 320.0, 0.0, 601.0, 240.0, 0.0, 0.0, 1.0]\n")
    assert parse_intrinsics(str(echo)).fy == 601.0
    bad = tmp_path / "bad.yaml"
    bad.write_text("!!python/object/apply:os.system ['true']\n")
    with pytest.raises(InputError, match="cannot parse CameraInfo YAML .*bad.yaml at line 1"):
        parse_intrinsics(str(bad))
    with pytest.raises(InputError, match="the CameraInfo is for 640x480 images"):
        K.check_image(320, 240)


@pytest.mark.parametrize("which", ["rgb", "depth", "npy"])
def test_a_small_file_declaring_a_huge_frame_is_refused_by_the_cli_within_a_small_peak(tmp_path, which):
    """A 100-byte PNG declaring 15000 x 15000 pixels, or a .npy header declaring 15000 x 15000 floats."""
    from peak_memory import CAP_MB, cli_peak

    cv2.imwrite(str(tmp_path / "c.png"), np.zeros((4, 6, 3), np.uint8))
    cv2.imwrite(str(tmp_path / "d.png"), np.ones((4, 6), np.uint16))
    files = {"rgb": tmp_path / "c.png", "depth": tmp_path / "d.png"}
    if which == "npy":
        header = {"descr": "<f4", "fortran_order": False, "shape": (15000, 15000)}
        with open(tmp_path / "big.npy", "wb") as f:
            np.lib.format.write_array_header_1_0(f, header)
            f.write(b"\0" * 64)
        files["depth"] = tmp_path / "big.npy"
    else:
        files[which] = _png_header_only(
            tmp_path / "big.png", 15000, 15000, *((16, 0) if which == "depth" else ())
        )
    (tmp_path / "hand.json").write_text("[]")
    code, err, seconds, peak_mb = cli_peak(
        "point", "--rgb", str(files["rgb"]), "--depth", str(files["depth"]), "--intrinsics", "500 500 2 1",
        "--transform", "0 -1 0", "--landmarks", str(tmp_path / "hand.json"), cwd=tmp_path,
    )  # fmt: skip
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "declares" in err or "more than" in err, err
    print(f"{which}: peak {peak_mb:.0f} MB under a {CAP_MB} MB cap, {seconds:.2f} s")
    assert peak_mb < 250 and seconds < 30, (peak_mb, CAP_MB)
