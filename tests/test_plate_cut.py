"""The cut of the plate and the bank's frames (lipsync.videobank.cut, lipsync.videobank.plate):
whole pixels where the map is a translation, one detail-keeping resample where it is not."""

import cv2
import numpy as np
import pytest

from lipsync.composite.plate import compose, pose_inverse
from lipsync.composite.samples import SNAP_PX
from lipsync.videobank.cut import INTERPOLATION, copy_offset, warp_frame
from lipsync.videobank.plate import PLATE_SCALE_BAND, plate_cut, stretch_poses
from lipsync.videobank.stabilise import Framing, Registration

RNG = np.random.default_rng(35)


def _image(h=48, w=64):
    return RNG.integers(0, 256, (h, w, 3), dtype=np.uint8)


def _shift(dx, dy):
    return np.array([[1.0, 0.0, dx], [0.0, 1.0, dy]])


def test_whole_pixel_translation_is_the_source_pixels():
    img = _image()
    out = warp_frame(img, _shift(-7, -5), (30, 20))
    assert out.shape == (20, 30, 3)
    assert np.array_equal(out, img[5:25, 7:37])


def test_window_leaving_the_picture_repeats_the_edge_as_the_warp_does():
    img = _image()
    m = _shift(4, -40)  # 4 columns left of the picture, 8 rows below it
    out = warp_frame(img, m, (30, 16))
    ref = cv2.warpAffine(img, m, (30, 16), flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE)
    assert np.array_equal(out, ref)
    assert np.array_equal(out[0, :4], np.repeat(img[40, :1], 4, axis=0))


@pytest.mark.parametrize("dx, dy, x, y", [(-7.3, -5.2, 7, 5), (-7.6, -4.6, 8, 5), (-7.5, -5.5, 8, 6)])
def test_fractional_translation_within_the_snap_copies_whole_pixels(dx, dy, x, y):
    # the nearest whole-pixel window (half rounds up), not a blend of neighbours
    img = _image()
    out = warp_frame(img, _shift(dx, dy), (30, 20))
    assert np.array_equal(out, img[y:y + 20, x:x + 30])


def test_near_identity_scale_within_the_snap_is_still_a_copy():
    # 0.5 % larger over a 30x20 window moves its corners by 0.09 px: inside SNAP_PX
    img = _image()
    m = np.array([[1.005, 0.0, -7.0], [0.0, 1.005, -5.0]])
    assert copy_offset(m, (30, 20)) is not None
    assert set(map(tuple, warp_frame(img, m, (30, 20)).reshape(-1, 3))) <= set(map(tuple, img.reshape(-1, 3)))
    # 5 % moves them by ~0.9 px over 30x20 but 3 px over a 120x100 window: resampled there
    big = np.array([[1.05, 0.0, 0.0], [0.0, 1.05, 0.0]])
    corner = 0.05 * np.hypot(120, 100) / 2
    assert corner > SNAP_PX and copy_offset(big, (120, 100)) is None


def _ramp(h, w):
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    return x, y, np.stack([40 + 2.0 * x + 1.0 * y, 200 - 1.5 * y, 100 + 0.8 * x], axis=-1)


def test_turned_map_is_resampled_with_the_chosen_kernel_to_the_analytic_value():
    # a linear ramp is reproduced by an interpolating kernel: the output pixel p holds the
    # ramp at m^-1 p (rounded to uint8)
    h, w = 80, 100
    _, _, f = _ramp(h, w)
    img = np.round(f).astype(np.uint8)
    m = cv2.getRotationMatrix2D((50.0, 40.0), 3.0, 0.97)
    m[:, 2] += (-10.25, -8.5)
    assert copy_offset(m, (60, 40)) is None
    out = warp_frame(img, m, (60, 40)).astype(np.float64)
    inv = pose_inverse(m)
    yy, xx = np.mgrid[0:40, 0:60].astype(np.float64)
    sx, sy = inv[0, 0] * xx + inv[0, 1] * yy + inv[0, 2], inv[1, 0] * xx + inv[1, 1] * yy + inv[1, 2]
    want = np.stack([40 + 2.0 * sx + 1.0 * sy, 200 - 1.5 * sy, 100 + 0.8 * sx], axis=-1)
    inner = (slice(4, -4), slice(4, -4))  # the kernel's reach from the edges
    assert np.abs(out[inner] - want[inner]).max() <= 1.0
    # and it is the Lanczos4 resample itself (not bilinear, not a copy)
    assert INTERPOLATION == cv2.INTER_LANCZOS4
    tex = _image(80, 100)
    assert np.array_equal(warp_frame(tex, m, (60, 40)),
                          cv2.warpAffine(tex, m, (60, 40), flags=cv2.INTER_LANCZOS4, borderMode=cv2.BORDER_REPLICATE))


def test_shrinking_map_is_area_averaged_first():
    # half the size: each output pixel is the mean of a 2x2 block (the ramp's value at its centre)
    h, w = 80, 100
    _, _, f = _ramp(h, w)
    img = np.round(f).astype(np.uint8)
    m = np.array([[0.5, 0.0, 0.25 - 0.5], [0.0, 0.5, 0.25 - 0.5]])  # pixel centres: x' = (x + 0.5) / 2 - 0.5
    out = warp_frame(img, m, (50, 40)).astype(np.float64)
    block = img.astype(np.float64).reshape(40, 2, 50, 2, 3).mean(axis=(1, 3))
    assert np.abs(out[2:-2, 2:-2] - block[2:-2, 2:-2]).max() <= 1.0


def _laplacian_var(img):
    g = img.astype(np.float64)
    lap = g[:-2, 1:-1] + g[2:, 1:-1] + g[1:-1, :-2] + g[1:-1, 2:] - 4 * g[1:-1, 1:-1]
    return float(lap[8:-8, 8:-8].var())


def _texture(h=120, w=160):
    # fine detail like skin and lip texture: noise smoothed by a 3-tap [1, 2, 1] / 4 each way
    # (most of its energy below half the sampling rate, as a camera's optics leave it)
    n = RNG.normal(128, 40, (h + 2, w + 2))
    n = (n[:-2] + 2 * n[1:-1] + n[2:]) / 4
    n = (n[:, :-2] + 2 * n[:, 1:-1] + n[:, 2:]) / 4
    return np.clip(n, 0, 255).astype(np.uint8)


def test_half_pixel_cut_keeps_more_detail_than_bilinear_would():
    tex = _texture()
    grey = np.stack([tex] * 3, axis=-1)
    base = _laplacian_var(tex)
    # what bilinear keeps at a half-pixel shift each way, derived: it averages each 2x2
    # block of neighbours (weights 1/4), computed here without cv2
    t = tex.astype(np.float64)
    bilinear = (t[:-1, :-1] + t[1:, :-1] + t[:-1, 1:] + t[1:, 1:]) / 4
    kept_bilinear = _laplacian_var(bilinear) / base
    assert kept_bilinear < 0.5  # the loss the plate suffered (GRID mouths: 0.52)
    # a pure half-pixel translation is copied: every bit of detail kept
    copied = warp_frame(grey, _shift(-10.5, -10.5), (140, 100))[..., 0]
    assert _laplacian_var(copied) / _laplacian_var(tex[11:111, 11:151]) == pytest.approx(1.0)
    # a map that must be resampled (turned 2 degrees, half a pixel off) keeps more than
    # bilinear does at the half pixel alone
    m = cv2.getRotationMatrix2D((80.0, 60.0), 2.0, 1.0)
    m[:, 2] += (-10.5, -10.5)
    assert copy_offset(m, (140, 100)) is None
    turned = warp_frame(grey, m, (140, 100))[..., 0]
    lin = cv2.warpAffine(grey, m, (140, 100), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)[..., 0]
    kept = _laplacian_var(turned) / base
    assert kept > kept_bilinear + 0.2
    assert kept > _laplacian_var(lin) / base + 0.2


# ------------------------------------------------------------------ the plate's cut and poses

def _framing(scale=50.0, size=(100, 80)):
    return Framing(origin=complex(-1.0, -0.8), scale=scale, size=size)


def _reg(n, c0=1 / 50 * np.exp(0.03j), drift=0.3):
    # a head turned 1.7 degrees, drifting a few tenths of a pixel and turning a little per frame
    k = np.arange(n)
    c = c0 * np.exp(0.002j * np.sin(k)) * (1 + 0.003 * np.cos(k))
    t = (-(180 + 140j) + drift * (k + 0.5j * k)) * abs(c0)
    return Registration(c=c, t=t, residual=np.zeros(n))


def test_plate_cut_is_a_whole_pixel_window_inside_the_picture():
    fr, reg = _framing(), _reg(6)
    cut, poses = stretch_poses(fr, reg, 0, 6, (360, 288))
    assert np.array_equal(cut[:, :2], np.eye(2)) and np.all(cut[:, 2] == np.round(cut[:, 2]))
    ox, oy = -cut[:, 2]
    assert 0 <= ox <= 360 - 100 and 0 <= oy <= 288 - 80
    # the window's centre is where the mean pose puts the plate's centre (within half a pixel)
    mean = Registration(c=np.array([reg.c.mean()]), t=np.array([reg.t.mean()]), residual=np.zeros(1))
    want = pose_inverse(fr.matrix(mean, 0)) @ np.array([49.5, 39.5, 1.0])
    assert np.abs(np.array([ox + 49.5, oy + 39.5]) - want).max() <= 0.5
    # every frame's pose takes bank pixels to where that frame's face is in the plate
    for f in range(6):
        assert np.allclose(compose(poses[f], fr.matrix(reg, f)), cut, atol=1e-9)


def test_plate_cut_stays_inside_the_picture_and_resamples_beyond_the_band():
    m = np.array([[1.0, 0.0, 5.0], [0.0, 1.0, 3.0]])  # the plate's centre near the picture's corner
    got = plate_cut(m, (100, 80), (360, 288))
    assert got[:, 2].tolist() == [0.0, 0.0]
    far = np.array([[1.0 - 1.5 * PLATE_SCALE_BAND, 0.0, -30.0], [0.0, 1.0 - 1.5 * PLATE_SCALE_BAND, -20.0]])
    assert np.array_equal(plate_cut(far, (100, 80), (360, 288)), far)
    # a picture smaller than the plate cannot give a window
    near = np.array([[1.0, 0.0, -3.0], [0.0, 1.0, -2.0]])
    assert np.array_equal(plate_cut(near, (100, 80), (90, 288)), near)
