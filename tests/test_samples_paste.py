"""lipsync.composite.samples: a paste whose map is a translation copies the crop at a whole-pixel
offset (issue 35: a fractional-offset resample lost a sixth to a third of the mouth's sharpness)."""

import cv2
import numpy as np
from types import SimpleNamespace

from lipsync.composite.samples import SNAP_PX, SampleCompositor, whole_shift


def _compositor(crop, affine):
    s = SimpleNamespace(crops=crop[None], affine=np.asarray(affine, np.float64)[None], lips=np.zeros((1, 44, 2)))
    mask = np.zeros((80, 80), np.float32)
    mask[10:70, 10:70] = 1.0  # the box the paste covers, hard-edged: every pixel is the sample's or the plate's
    return SampleCompositor(s, mask)


def _texture(h=40, w=48, seed=0):
    rng = np.random.default_rng(seed)
    return np.ascontiguousarray(np.repeat(rng.integers(0, 256, (h, w, 1)), 3, axis=2).astype(np.uint8))


def _lapvar(img):
    return float(cv2.Laplacian(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), cv2.CV_64F).var())


def test_a_fractional_translation_pastes_the_crop_pixels_unchanged():
    crop = _texture()
    sc = _compositor(crop, [[1.0, 0, 12.0], [0, 1.0, 15.0]])       # crop -> bank: at (12, 15)
    plate = np.zeros((80, 80, 3), np.uint8)
    pose = np.array([[1.0, 0, 3.4], [0, 1.0, -2.3]])                 # bank -> plate: 0.4 / 0.3 px off the grid
    out = sc.paste(0, plate, pose)
    # the crop's pixel (x, y) lands at round(12 + 3.4) + x = 15 + x, round(15 - 2.3) + y = 13 + y
    assert np.array_equal(out[13:13 + 40, 15:15 + 48], crop[:, :48 - 0][:40])
    assert _lapvar(out[20:50, 20:55]) == _lapvar(crop[7:37, 5:40])


def test_a_half_pixel_resample_would_have_lost_sharpness():
    crop = _texture(seed=1)
    m = np.array([[1.0, 0, 0.5], [0, 1.0, 0.5]])
    resampled = cv2.warpAffine(crop, m, (48, 40), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
    # what the copy avoids: bicubic at half a pixel keeps well under 0.9 of the variance
    assert _lapvar(resampled[4:-4, 4:-4]) < 0.8 * _lapvar(crop[4:-4, 4:-4])
    assert whole_shift(m, crop.shape) == (1, 1)                      # round half up: a copy one pixel on


def test_a_scaled_or_turned_map_is_resampled():
    h, w = 64, 82                                                    # GRID s1's crop size
    assert whole_shift(np.array([[0.96, 0, 0], [0, 0.96, 0]]), (h, w)) is None
    turn = np.deg2rad(2.0)
    rot = np.array([[np.cos(turn), -np.sin(turn), 0], [np.sin(turn), np.cos(turn), 0]])
    assert whole_shift(rot, (h, w)) is None                          # 2 degrees: 1.8 px at the corners
    # just inside the tolerance: SNAP_PX at the farthest corner
    k = 1.0 + 0.99 * SNAP_PX / (w / 2.0)
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0                            # scaled about the crop's centre, moved 3, -2
    assert whole_shift(np.array([[k, 0, (1 - k) * cx + 3], [0, k, (1 - k) * cy - 2]]), (h, w)) == (3, -2)
    crop = _texture(h, w, seed=2)
    sc = _compositor(crop, [[0.96, 0, 2.0], [0, 0.96, 3.0]])
    out = sc.paste(0, np.zeros((80, 80, 3), np.uint8), np.array([[1.0, 0, 0], [0, 1.0, 0]]))
    expect = cv2.warpAffine(crop, np.array([[0.96, 0, 2.0], [0, 0.96, 3.0]]), (80, 80), flags=cv2.INTER_LANCZOS4,
                            borderMode=cv2.BORDER_REPLICATE)
    assert np.abs(out[20:45, 20:50].astype(int) - expect[20:45, 20:50]).max() <= 1
