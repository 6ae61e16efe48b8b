"""Image I/O: EXR round trips, sRGB decoding of 8-bit inputs, uint16 masks."""

import cv2
import numpy as np
import OpenEXR
import pytest

from invrender.scene import SceneError
from invrender.scene.images import (
    linear_to_srgb,
    read_image,
    read_mask,
    srgb_to_linear,
    write_exr,
    write_mask,
    write_png_preview,
)


@pytest.fixture
def rng():
    return np.random.default_rng(0)


def test_exr_rgb_roundtrip(tmp_path, rng):
    a = rng.random((7, 5, 3), dtype=np.float32) * 100
    write_exr(tmp_path / "a.exr", a)
    b = read_image(tmp_path / "a.exr")
    assert b.dtype == np.float32 and b.shape == (7, 5, 3)
    np.testing.assert_array_equal(a, b)
    with OpenEXR.File(str(tmp_path / "a.exr"), separate_channels=True) as f:
        assert sorted(f.channels()) == ["B", "G", "R"]
        np.testing.assert_array_equal(f.channels()["R"].pixels, a[:, :, 0])


def test_exr_one_channel_roundtrip(tmp_path, rng):
    a = rng.random((4, 6), dtype=np.float32)
    write_exr(tmp_path / "y.exr", a)
    with OpenEXR.File(str(tmp_path / "y.exr"), separate_channels=True) as f:
        assert list(f.channels()) == ["Y"]
    b = read_image(tmp_path / "y.exr")
    assert b.shape == (4, 6, 1)
    np.testing.assert_array_equal(a, b[:, :, 0])


def test_exr_half(tmp_path, rng):
    a = rng.random((3, 4, 3), dtype=np.float32)
    write_exr(tmp_path / "h.exr", a, half=True)
    with OpenEXR.File(str(tmp_path / "h.exr"), separate_channels=True) as f:
        assert f.channels()["G"].pixels.dtype == np.float16
    b = read_image(tmp_path / "h.exr")
    assert b.dtype == np.float32
    np.testing.assert_array_equal(b, a.astype(np.float16).astype(np.float32))


def test_png_srgb_decode_value_and_rgb_order(tmp_path):
    rgb = np.zeros((2, 3, 3), np.uint8)
    rgb[..., 0], rgb[..., 1], rgb[..., 2] = 188, 0, 255
    assert cv2.imwrite(str(tmp_path / "c.png"), rgb[:, :, ::-1])  # OpenCV writes BGR
    img = read_image(tmp_path / "c.png")
    assert img.dtype == np.float32 and img.shape == (2, 3, 3)
    assert img[0, 0, 0] == pytest.approx(0.5029, abs=1e-4)
    assert img[0, 0, 1] == 0.0 and img[0, 0, 2] == pytest.approx(1.0)


def test_jpeg_is_decoded_to_linear(tmp_path):
    grey = np.full((8, 8, 3), 188, np.uint8)
    assert cv2.imwrite(str(tmp_path / "g.jpg"), grey)
    assert read_image(tmp_path / "g.jpg")[4, 4, 1] == pytest.approx(0.5029, abs=0.01)


def test_srgb_transfer_inverse():
    x = np.linspace(0, 1, 101)
    np.testing.assert_allclose(linear_to_srgb(srgb_to_linear(x)), x, atol=1e-12)


def test_mask_uint16_roundtrip(tmp_path, rng):
    m = rng.integers(0, 65536, (9, 11)).astype(np.uint16)
    m[0, 0] = 65535
    write_mask(tmp_path / "m.png", m)
    back = read_mask(tmp_path / "m.png")
    assert back.dtype == np.uint16
    np.testing.assert_array_equal(back, m)


def test_mask_8bit_and_rgb_refused(tmp_path):
    cv2.imwrite(str(tmp_path / "m8.png"), np.array([[0, 3], [7, 255]], np.uint8))
    np.testing.assert_array_equal(read_mask(tmp_path / "m8.png"), [[0, 3], [7, 255]])
    cv2.imwrite(str(tmp_path / "rgb.png"), np.zeros((2, 2, 3), np.uint8))
    with pytest.raises(SceneError, match=r"rgb\.png: channels"):
        read_mask(tmp_path / "rgb.png")


def test_png_preview(tmp_path):
    lin = np.full((4, 4, 3), 2.0, np.float32)
    lin[0, 0] = [0.5, 1.0, 2.0]
    exposure = write_png_preview(tmp_path / "p.png", lin)
    assert exposure == pytest.approx(0.5)
    back = cv2.imread(str(tmp_path / "p.png"))[:, :, ::-1]
    assert back.dtype == np.uint8 and tuple(back[1, 1]) == (255, 255, 255)
    assert tuple(back[0, 0]) == (137, 188, 255)  # 0.25, 0.5, 1 linear -> sRGB
    write_png_preview(tmp_path / "q.png", lin, exposure=0.25)
    assert tuple(cv2.imread(str(tmp_path / "q.png"))[1, 1]) == (188, 188, 188)


def test_missing_or_bad_image_is_scene_error(tmp_path):
    with pytest.raises(SceneError, match="nope.exr"):
        read_image(tmp_path / "nope.exr")
    (tmp_path / "junk.exr").write_bytes(b"not an exr")
    with pytest.raises(SceneError, match="junk.exr"):
        read_image(tmp_path / "junk.exr")


def test_failed_write_leaves_nothing(tmp_path, monkeypatch):
    with pytest.raises(ValueError):
        write_exr(tmp_path / "bad.exr", np.zeros((2, 2, 2)))
    assert list(tmp_path.iterdir()) == []

    import invrender.scene.images as images

    class Crashing:  # writes half a file, then fails, like a full disk
        def __init__(self, *args):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *args):
            pass

        def write(self, path):
            open(path, "wb").write(b"\x76\x2f\x31\x01 partial")
            raise OSError("No space left on device")

    fake = type("FakeOpenEXR", (), {"File": Crashing, "ZIP_COMPRESSION": 0, "scanlineimage": 0})
    monkeypatch.setattr(images, "OpenEXR", fake)
    with pytest.raises(OSError):
        write_exr(tmp_path / "out.exr", np.zeros((2, 2, 3)))
    assert list(tmp_path.iterdir()) == []
