"""RGB -> yuv420p (BT.709, tv range): the values themselves, and what a decoder gives back."""

from __future__ import annotations

import subprocess

import imageio_ffmpeg
import numpy as np
import pytest

from lipsync.encode import yuv
from lipsync.encode import open_writer
from lipsync.encode.yuv import rgb_to_yuv420p, yuv420p_size

# Flat colours: primaries, secondaries, the range ends, grey and two mid-tones.
PATCHES = [(255, 0, 0), (0, 255, 0), (0, 0, 255), (0, 255, 255), (255, 0, 255), (255, 255, 0),
           (255, 255, 255), (0, 0, 0), (128, 128, 128), (200, 120, 40), (30, 160, 220), (90, 60, 140)]
SIDE = 32


def bt709_tv(rgb):
    """Y, Cb, Cr of 8-bit RGB by Rec. BT.709 (float, before rounding), computed independently."""
    r, g, b = (np.asarray(rgb, np.float64)[..., k] / 255 for k in range(3))
    y = 0.2126 * r + 0.7152 * g + 0.0722 * b
    return 16 + 219 * y, 128 + 224 * (b - y) / 1.8556, 128 + 224 * (r - y) / 1.5748


def patch_image():
    img = np.zeros((SIDE, SIDE * len(PATCHES), 3), np.uint8)
    for i, c in enumerate(PATCHES):
        img[:, SIDE * i:SIDE * (i + 1)] = c
    return img


def planes(buf, w, h):
    y = buf[:w * h].reshape(h, w)
    u = buf[w * h:w * h + (w // 2) * (h // 2)].reshape(h // 2, w // 2)
    v = buf[w * h + (w // 2) * (h // 2):].reshape(h // 2, w // 2)
    return y, u, v


def test_known_values():
    # The standard's own corner cases: black, white and grey exactly; 75 % colour bars' red.
    out = rgb_to_yuv420p(np.array([[[0, 0, 0], [255, 255, 255]], [[128, 128, 128], [191, 0, 0]]], np.uint8))
    assert out[:4].tolist() == [16, 235, 126, 51]
    # Chroma of that 2x2 block is the mean of its four pixels' values.
    _, cb, cr = bt709_tv(np.array([[0, 0, 0], [255, 255, 255], [128, 128, 128], [191, 0, 0]]))
    assert out[4] == round(cb.mean()) and out[5] == round(cr.mean())
    # Pure colours (BT.709 tables): red 63/102/240, green 173/42/26, blue 32/240/118.
    for rgb, expected in [((255, 0, 0), (63, 102, 240)), ((0, 255, 0), (173, 42, 26)), ((0, 0, 255), (32, 240, 118))]:
        out = rgb_to_yuv420p(np.full((2, 2, 3), rgb, np.uint8))
        assert (out[0], out[4], out[5]) == expected


def test_flat_patches_match_the_formula_exactly():
    img = patch_image()
    h, w = img.shape[:2]
    y, u, v = planes(rgb_to_yuv420p(img), w, h)
    ey, eu, ev = bt709_tv(np.array(PATCHES))
    for i in range(len(PATCHES)):
        assert np.all(y[:, SIDE * i:SIDE * (i + 1)] == round(ey[i]))
        assert np.all(u[:, SIDE // 2 * i:SIDE // 2 * (i + 1)] == round(eu[i]))
        assert np.all(v[:, SIDE // 2 * i:SIDE // 2 * (i + 1)] == round(ev[i]))


def test_random_images_are_within_rounding_of_the_formula():
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, size=(36, 50, 3), dtype=np.uint8)
    y, u, v = planes(rgb_to_yuv420p(img), 50, 36)
    ey, eu, ev = bt709_tv(img)
    assert np.abs(y - ey).max() <= 0.5 + 1e-3
    blocks = lambda p: p.reshape(18, 2, 25, 2).mean(axis=(1, 3))  # noqa: E731
    assert np.abs(u - blocks(eu)).max() <= 0.5 + 1e-3
    assert np.abs(v - blocks(ev)).max() <= 0.5 + 1e-3
    # Grey of any level stays neutral.
    grey = np.repeat(np.arange(256, dtype=np.uint8)[None, :, None], 2, axis=0).repeat(3, axis=2)
    _, u, v = planes(rgb_to_yuv420p(grey), 256, 2)
    assert np.all(u == 128) and np.all(v == 128)


def test_out_buffer_and_bad_input():
    img = patch_image()
    out = np.zeros(yuv420p_size(img.shape[1], img.shape[0]), np.uint8)
    assert rgb_to_yuv420p(img, out) is out
    assert np.array_equal(out, rgb_to_yuv420p(img[:, ::-1][:, ::-1]))  # non-contiguous input too
    with pytest.raises(ValueError, match="even"):
        rgb_to_yuv420p(np.zeros((3, 4, 3), np.uint8))
    with pytest.raises(ValueError, match="uint8"):
        rgb_to_yuv420p(np.zeros((2, 2, 3), np.float32))
    with pytest.raises(ValueError, match="out"):
        rgb_to_yuv420p(img, np.zeros(5, np.uint8))


def _ffmpeg_decode(path, pix_fmt, w, h):
    raw = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-i", str(path), "-frames:v", "1",
                          "-f", "rawvideo", "-pix_fmt", pix_fmt, "-"], capture_output=True, check=True).stdout
    return np.frombuffer(raw, np.uint8)


def test_mp4_decodes_to_the_same_colours_and_is_tagged_bt709_tv(tmp_path):
    img = patch_image()
    h, w = img.shape[:2]
    out = tmp_path / "patches.mp4"
    with open_writer(out, fps=25, size=(w, h), quiet=True) as wr:
        for _ in range(3):
            wr.write(img)
    # ffmpeg's H.264 decoder, then its own conversion back to RGB following the stream's tags.
    rgb = _ffmpeg_decode(out, "rgb24", w, h).reshape(h, w, 3).astype(int)
    yy, uu, vv = planes(_ffmpeg_decode(out, "yuv420p", w, h), w, h)
    ey, eu, ev = bt709_tv(np.array(PATCHES))
    for i, c in enumerate(PATCHES):
        centre = np.s_[SIDE // 2 - 4:SIDE // 2 + 4, SIDE * i + SIDE // 2 - 4:SIDE * i + SIDE // 2 + 4]
        assert np.abs(rgb[centre] - np.array(c)).max() <= 2, c
        assert abs(int(yy[SIDE // 2, SIDE * i + SIDE // 2]) - ey[i]) <= 1.5, c
        assert abs(int(uu[SIDE // 4, SIDE // 2 * i + SIDE // 4]) - eu[i]) <= 1.5, c
        assert abs(int(vv[SIDE // 4, SIDE // 2 * i + SIDE // 4]) - ev[i]) <= 1.5, c
    text = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(out)],
                          capture_output=True, text=True).stderr
    # matrix, primaries and transfer all written (an untagged transfer would read "bt709/unknown/unknown")
    assert "yuv420p(tv, bt709, progressive)" in text


def test_docstring_examples_run():
    import doctest

    result = doctest.testmod(yuv)
    assert result.attempted >= 2 and result.failed == 0


def test_compiled_and_numba_conversions_give_the_same_bytes():
    pytest.importorskip("lipsync.morphing._flowkernel")
    from lipsync.morphing._numba_kernels import rgb_to_yuv420p as numba_convert
    from lipsync.encode.yuv import _NUMBA_CONSTANTS

    rng = np.random.default_rng(7)
    for h, w in ((2, 2), (38, 62), (144, 256)):
        rgb = rng.integers(0, 256, (h, w, 3), np.uint8)
        want = np.empty(yuv420p_size(w, h), np.uint8)
        numba_convert(rgb, want, *_NUMBA_CONSTANTS)
        np.testing.assert_array_equal(rgb_to_yuv420p(rgb), want)
