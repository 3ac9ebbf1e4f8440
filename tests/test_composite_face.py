"""lipsync.composite.face: the lower-face mask, pose, colour match and paste, on synthetic
faces whose answers are known in closed form."""

from __future__ import annotations

import doctest

import numpy as np
import pytest

from lipsync.composite import face as F
from lipsync.face import topology as T


def _toy_mesh(dx: float = 0.0, dy: float = 0.0) -> np.ndarray:
    """A face whose lower face is a trapezoid: jaw straight down from (20, 40)/(80, 40) to
    (20, 70)/(80, 70), then straight in to the chin at (50, 90); the nose's lower edge a
    horizontal bar at y = 40 from x 40 to 60; eyes 40 px apart at y = 20."""
    p = np.zeros((468, 2))
    jl = np.vstack([np.c_[np.full(6, 20.0), np.linspace(30, 70, 6)], np.c_[np.linspace(26, 50, 5), np.linspace(74, 90, 5)]])
    jr = jl * [-1, 1] + [100, 0]
    p[list(T.JAW_L)] = jl
    p[list(T.JAW_R)] = jr
    p[list(T.NOSE_BASE_L)] = [[40, 40], [45, 40], [50, 40]]
    p[list(T.NOSE_BASE_R)] = [[60, 40], [55, 40], [50, 40]]
    p[list(T.EYE_UPPER_L + T.EYE_LOWER_L)] = [30, 20]
    p[list(T.EYE_UPPER_R + T.EYE_LOWER_R)] = [70, 20]
    p[list(T.FACE_UPPER_L)] = np.c_[np.linspace(20, 50, 9), np.linspace(30, 2, 9)]
    p[list(T.FACE_UPPER_R)] = np.c_[np.linspace(80, 50, 9), np.linspace(30, 2, 9)]
    return p + [dx, dy]


def test_docstring_examples():
    assert doctest.testmod(F).failed == 0


def test_outline_of_a_known_face():
    poly = F.polygon_from_mesh(_toy_mesh())
    # the jaw from the wings' level (y = 40) down to the chin and back up, then the nose bar
    # the jaw crosses the wings' level between mesh points (y 38 and 46): cut there
    assert poly[0].tolist() == [20.0, 40.0] and poly[1].tolist() == [20.0, 46.0]
    assert [50.0, 90.0] in poly.tolist() and [80.0, 40.0] in poly.tolist()
    assert len(poly) == 2 * (1 + 9) - 1 + 5   # a side: the crossing and 9 points below it; the chin shared; the bar
    assert poly[:, 1].min() == 40.0            # nothing above the nose base
    np.testing.assert_allclose(poly[-5:], [[60, 40], [55, 40], [50, 40], [45, 40], [40, 40]])


def test_mask_values_follow_the_distance_to_the_outline():
    feather = 6.0
    m = F.lower_face_mask([F.polygon_from_mesh(_toy_mesh())], (100, 100), feather=feather)
    assert m.dtype == np.float32 and m.shape == (100, 100)
    assert not m[:41].any()                    # above and on the nose base: the plate
    assert m[:, :20].max() == 0 and m[:, 81:].max() == 0
    assert m[60, 50] == 1.0                    # deep inside
    # below the straight top edge, column 50: the smoothstep of the distance in from y = 40
    for y in range(41, 48):
        t = min(max((y - 40) / feather, 0.0), 1.0)
        assert m[y, 50] == pytest.approx(t * t * (3 - 2 * t), abs=1e-6), y
    # the same inside the straight left jaw (x = 20), row 55
    for x in range(21, 28):
        t = min(max((x - 20) / feather, 0.0), 1.0)
        assert m[55, x] == pytest.approx(t * t * (3 - 2 * t), abs=1e-6), x


def test_growth_is_full_at_the_chin_and_none_at_the_nose_level():
    grow = 5.0
    plain = F.polygon_from_mesh(_toy_mesh())
    grown = F.polygon_from_mesh(_toy_mesh(), grow=grow)
    chin = int(np.argmax(plain[:, 1]))
    # the chin (the deepest point) moves straight down by grow (its normal is vertical)
    np.testing.assert_allclose(grown[chin], plain[chin] + [0, grow], atol=1e-9)
    # the jaw's ends at the wings' level, and the nose bar, do not move
    np.testing.assert_allclose(grown[[0, chin * 2]], plain[[0, chin * 2]])
    np.testing.assert_allclose(grown[-5:], plain[-5:])
    # down the straight jaw (y = 54: 14 px of the 50 from the wings' level to the chin):
    # that share of the growth, outwards (-x)
    k = int(np.nonzero(np.isclose(plain[:, 1], 54.0) & (plain[:, 0] < 50))[0][0])
    np.testing.assert_allclose(grown[k], plain[k] + [-grow * 14 / 50, 0], atol=1e-9)


def test_union_of_two_faces_and_lines_give_the_same_mask():
    from lipsync.face.lines import face_features

    a, b = _toy_mesh(), _toy_mesh(dy=6.0)     # a dropped jaw: the second face 6 px lower
    m = F.mask_from_mesh([a, b], (110, 100))
    # each chin grown 0.15 eye distances (6 px): a's to 96, b's to 102
    assert m[99, 50] > 0 and F.mask_from_mesh([a], (110, 100))[99, 50] == 0
    feats = face_features({"X": a, "D": b}, (110, 100))
    np.testing.assert_array_equal(F.mask_from_lines([feats["X"], feats["D"]], (110, 100)), m)


def test_pose_colour_and_paste():
    rng = np.random.default_rng(3)
    p = _toy_mesh() + rng.normal(0, 0.01, (468, 2))
    angle, scale, shift = np.radians(4.0), 1.07, np.array([3.0, -2.0])
    rot = scale * np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    q = p @ rot.T + shift
    m = F.pose_onto(p, q)
    np.testing.assert_allclose(m[:, :2], rot, atol=1e-3)
    np.testing.assert_allclose(m[:, 2], shift, atol=0.05)
    # colour: a camera gain per channel is undone exactly (to rounding) by the ratio of means
    src = rng.integers(60, 180, (50, 50, 3)).astype(np.uint8)
    gain = np.array([0.8, 0.9, 1.1])
    dst = np.round(src * gain).astype(np.uint8)
    g, o = F.colour_match(src, dst, np.ones((50, 50), bool))
    np.testing.assert_allclose(g, gain, atol=0.004)
    assert not o.any()
    assert np.abs(F.apply_colour(src, g, o).astype(int) - dst).max() <= 1
    # paste: plate where the mask is 0, the face where it is 1, the blend between
    plate = np.full((10, 10, 3), 40, np.uint8)
    face = np.full((10, 10, 3), 240, np.uint8)
    mask = np.zeros((10, 10), np.float32)
    mask[5:, :] = 1.0
    mask[4, :] = 0.25
    out = F.paste(plate, face, mask)
    assert (out[:4] == 40).all() and (out[5:] == 240).all() and (out[4] == 90).all()
    # Poisson keeps the face's gradients, not its values: a flat face takes the plate's
    # value from the mask's edge (why the alpha blend with a colour match is the default)
    out = F.paste(plate, face, mask, method="poisson")
    assert (out[:4] == 40).all() and np.abs(out[5:].astype(int) - 40).max() <= 1
    with pytest.raises(ValueError):
        F.paste(plate, face, mask, method="clone")
