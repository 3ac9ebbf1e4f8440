"""The default subject (visemes/toon): complete, symmetric, static outside the mouth, reproducible."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
BANK = ROOT / "visemes" / "toon"
GENERATOR = ROOT / "tools" / "make_toon.py"
RHUBARB = set("ABCDEFGHX")
SIZE = 512
# The mirror axis stated in bank.yaml and visemes/README.md: column i mirrors column 511 - i.
MIRROR = SIZE - 1
# The documented mouth/jaw region (visemes/README.md): rows 322..511, columns 96..415.
REGION_ROWS, REGION_COLS = slice(322, 512), slice(96, 416)
# Where the lips are at rest: rows 330..420, columns 190..321 (every shape has its mouth here).
MOUTH_ROWS, MOUTH_COLS = slice(330, 420), slice(190, 322)


def _read(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert img is not None, path
    return img


@pytest.fixture(scope="module")
def bank():
    return yaml.safe_load((BANK / "bank.yaml").read_text())


@pytest.fixture(scope="module")
def images(bank):
    return {n: _read(BANK / v["image"]) for n, v in bank["visemes"].items()}


def _mirror(line) -> np.ndarray:
    a = np.array(line, dtype=np.float64)
    a[:, 0] = MIRROR - a[:, 0]
    return a


def test_nine_rhubarb_visemes_with_the_same_lines(bank):
    assert set(bank["visemes"]) == RHUBARB
    assert bank["rest"] == "X"
    assert bank["symmetry"] is True
    names = [list(v["lines"]) for v in bank["visemes"].values()]
    assert all(n == names[0] for n in names)
    assert 20 <= len(names[0]) <= 48  # lips, teeth, jaw, and the static anchors that hold the face
    for v in bank["visemes"].values():
        for name, line in v["lines"].items():
            a = np.array(line, dtype=np.float64)
            assert a.shape == (2, 2), name
            assert np.hypot(*(a[1] - a[0])) >= 1.0, name
            assert np.all((a >= 0) & (a <= SIZE - 1)), name


def test_images_are_512_rgb_uint8(images):
    for name, img in images.items():
        assert img.shape == (SIZE, SIZE, 3), name
        assert img.dtype == np.uint8, name


def test_images_are_mirror_symmetric(images):
    for name, img in images.items():
        assert np.array_equal(img, img[:, ::-1]), name


def test_lines_are_mirror_symmetric(bank):
    for viseme, v in bank["visemes"].items():
        lines = v["lines"]
        for name, line in lines.items():
            m = _mirror(line)
            if name.endswith("_l"):
                np.testing.assert_allclose(m, lines[name[:-2] + "_r"], atol=1e-6,
                                           err_msg=f"{viseme} {name}")
            elif name.endswith("_r"):
                assert name[:-2] + "_l" in lines
            else:
                own = np.array(line, dtype=np.float64)
                same = np.allclose(m, own, atol=1e-6)
                reversed_ = np.allclose(m, own[::-1], atol=1e-6)
                assert same or reversed_, f"{viseme} {name} is not its own mirror image"


def test_pixels_outside_the_mouth_and_jaw_are_identical(images):
    rest = images["X"]
    outside = np.ones(rest.shape[:2], bool)
    outside[REGION_ROWS, REGION_COLS] = False
    for name, img in images.items():
        assert np.array_equal(img[outside], rest[outside]), name


def test_static_anchor_lines_are_identical_in_every_viseme(bank):
    static = ["nose", "nostrils", "collar", "eye_l", "eye_r", "brow_l", "brow_r", "cheek_l",
              "cheek_r"]
    rest = bank["visemes"]["X"]["lines"]
    for v in bank["visemes"].values():
        for name in static:
            assert v["lines"][name] == rest[name], name


def test_mouth_lines_stay_in_the_region_that_changes(bank):
    moving = [n for n in bank["visemes"]["X"]["lines"]
              if n.split("_")[0] in {"upper", "lower", "corner", "teeth", "jaw", "chin"}]
    assert len(moving) >= 20
    for v in bank["visemes"].values():
        for name in moving:
            a = np.array(v["lines"][name])
            assert np.all(a[:, 1] >= REGION_ROWS.start), name
            assert np.all((a[:, 0] >= REGION_COLS.start) & (a[:, 0] < REGION_COLS.stop)), name


def test_the_shapes_differ_in_the_mouth(images):
    names = sorted(images)
    crops = {n: images[n][MOUTH_ROWS, MOUTH_COLS].astype(np.int16) for n in names}
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            changed = np.abs(crops[a] - crops[b]).max(axis=2) > 40
            # At least 300 clearly different pixels: a visible change of shape, not noise.
            assert changed.sum() > 300, (a, b)


def test_open_shapes_are_dark_inside_and_closed_ones_are_not(images):
    def darkest_share(name):
        crop = images[name][MOUTH_ROWS, MOUTH_COLS]
        return float((crop.max(axis=2) < 90).mean())

    # Wide open (D) shows the most dark interior; closed lips (A, X) show none.
    assert darkest_share("D") > darkest_share("C") > darkest_share("B")
    assert darkest_share("A") == 0.0 and darkest_share("X") == 0.0


def test_inner_lip_lines_meet_when_the_lips_are_closed(bank):
    for closed in ("A", "X"):
        lines = bank["visemes"][closed]["lines"]
        for side in ("l", "r"):
            for part in ("", "_mid"):
                up = np.array(lines[f"upper_inner{part}_{side}"])
                lo = np.array(lines[f"lower_inner{part}_{side}"])
                np.testing.assert_allclose(up, lo, atol=1e-9)
    d = bank["visemes"]["D"]["lines"]
    gap = np.array(d["lower_inner_mid_l"])[1, 1] - np.array(d["upper_inner_mid_l"])[1, 1]
    assert gap > 40


def test_generator_reproduces_the_committed_bank(tmp_path):
    subprocess.run([sys.executable, str(GENERATOR), str(tmp_path)], check=True,
                   capture_output=True, timeout=300)
    assert (tmp_path / "bank.yaml").read_text() == (BANK / "bank.yaml").read_text()
    for name in sorted(RHUBARB):
        assert np.array_equal(_read(tmp_path / f"{name}.png"), _read(BANK / f"{name}.png")), name
