"""lipsync.encode.preview: lines drawn where they are, grid geometry, atomic PNG writing."""

from __future__ import annotations

import os

import cv2
import numpy as np
import pytest

from lipsync.encode import preview
from lipsync.encode.preview import GAP, draw_lines, preview_sheet, save_png, strip


def _blank(h=64, w=64):
    return np.zeros((h, w, 3), np.uint8)


def _solid(colour, h, w):
    img = np.empty((h, w, 3), np.uint8)
    img[:] = colour
    return img


def test_horizontal_line_colours_its_row_and_nothing_far_away():
    img = _blank()
    out = draw_lines(img, {"lip": [[10, 32], [53, 32]]}, labels=False)
    assert out.shape == img.shape and out.dtype == np.uint8
    assert not img.any(), "the input must not be modified"
    colour = np.array(preview.PALETTE[0])
    # Along the middle of the line the pixels carry the line's colour (red dominant).
    row = out[32, 16:46].astype(int)
    assert np.all(row.max(axis=1) > 100)
    assert np.all(np.argmax(row, axis=1) == np.argmax(colour))
    # Rows well above and below, and columns beyond the ends, are untouched.
    assert not out[:24].any() and not out[41:].any()
    assert not out[:, :5].any() and not out[:, 59:].any()


def test_p_and_q_ends_are_marked_differently():
    fwd = draw_lines(_blank(), {"a": [[10, 32], [53, 32]]}, labels=False)
    back = draw_lines(_blank(), {"a": [[53, 32], [10, 32]]}, labels=False)
    assert not np.array_equal(fwd, back)
    # Reversing the line is its mirror image (x -> 63 - x maps 10 <-> 53): same marks at the
    # swapped ends, up to anti-aliasing.
    diff = np.abs(fwd[:, ::-1].astype(int) - back.astype(int))
    assert diff.mean() < 2.0
    # The P dot extends behind P (left of x = 10); nothing is drawn behind Q (right of 53).
    assert fwd[32, 8].any()
    assert not fwd[30:35, 56:].any()


def test_mirror_partners_share_a_colour_and_other_lines_do_not():
    lines = {"lip_l": [[5, 10], [25, 10]], "lip_r": [[58, 10], [38, 10]],
             "nose": [[31.5, 30], [31.5, 55]]}
    out = draw_lines(_blank(), lines, labels=False)
    left, right, nose = out[10, 15], out[10, 48], out[42, 31:33].max(axis=0)
    assert np.array_equal(left, right)
    assert not np.array_equal(left, nose)


def test_labels_write_the_names_beside_the_lines():
    img = _blank(200, 200)
    lines = {"upper_lip": [[40, 100], [160, 100]]}
    plain = draw_lines(img, lines, labels=False)
    named = draw_lines(img, lines)
    extra = np.any(named != plain, axis=2)
    ys, xs = np.nonzero(extra)
    assert extra.sum() > 50
    # The text sits next to the line, not somewhere else in the image.
    assert abs(ys.mean() - 100) < 20 and 40 < xs.mean() < 160


@pytest.mark.parametrize("bad", [[[0, 0], [1, 1], [2, 2]], [[0, 0], [np.nan, 1]], [1, 2, 3, 4]])
def test_bad_lines_are_refused(bad):
    with pytest.raises(ValueError, match="lip"):
        draw_lines(_blank(), {"lip": bad})


def test_bad_images_are_refused():
    with pytest.raises(ValueError, match="RGB"):
        draw_lines(np.zeros((8, 8, 5), np.uint8), {})
    with pytest.raises(ValueError):
        strip([[np.zeros((8, 8, 2), np.uint8)]])


def _find(sheet, colour):
    ys, xs = np.nonzero(np.all(sheet == colour, axis=2))
    return ys.min(), ys.max() + 1, xs.min(), xs.max() + 1


def test_preview_sheet_grid_captions_and_lines():
    colours = {"A": (200, 30, 30), "B": (30, 200, 30), "C": (30, 30, 200)}
    images = {n: _solid(c, 40, 60) for n, c in colours.items()}
    sheet = preview_sheet(images, {"A": {"x": [[5, 20], [55, 20]]}}, columns=2)
    assert sheet.dtype == np.uint8 and sheet.ndim == 3
    assert sheet.shape[1] == 3 * GAP + 2 * 60
    cell_h = (sheet.shape[0] - 3 * GAP) // 2
    assert sheet.shape[0] == 3 * GAP + 2 * cell_h and cell_h > 40
    caption = cell_h - 40
    expected = {"A": (0, 0), "B": (0, 1), "C": (1, 0)}
    for name, (r, c) in expected.items():
        y0, y1, x0, x1 = _find(sheet, colours[name])
        assert (x0, x1) == (GAP + c * (60 + GAP), GAP + c * (60 + GAP) + 60), name
        assert y1 == GAP + r * (cell_h + GAP) + cell_h, name
        # The caption band above each image holds dark text.
        band = sheet[y1 - 40 - caption:y1 - 40, x0:x1]
        assert (band.max(axis=2) < 100).sum() > 5, name
    # A's line is drawn in A's cell (across its row 20), B and C are untouched.
    a_top = GAP + caption
    assert np.any(sheet[a_top + 20, GAP + 10:GAP + 50] != colours["A"])
    b = sheet[GAP + caption:GAP + caption + 40, 2 * GAP + 60:2 * GAP + 120]
    assert np.all(b == colours["B"])
    # The empty fourth cell is background.
    assert np.all(sheet[-GAP - 10, -GAP - 10] == preview.BACKGROUND)


def test_preview_sheet_tile_scales_images_and_lines():
    img = _solid((90, 90, 90), 40, 80)
    sheet = preview_sheet({"A": img}, {"A": {"x": [[0, 20], [79, 20]]}}, tile=40)
    assert sheet.shape[1] == 2 * GAP + 40
    # Scaled by 1/2: pixel-centre convention maps y = 20 to (20 + 0.5) / 2 - 0.5 = 9.75.
    body = sheet[-GAP - 20:-GAP, GAP + 10:GAP + 30]     # the middle, away from the end marks
    per_row = np.any(body != 90, axis=2).sum(axis=1)
    # The (anti-aliased) line fills rows within a pixel and a half of 9.75 all across; the
    # small label below it only partly fills its rows; nothing is drawn well above it.
    full = set(np.nonzero(per_row == 20)[0])
    assert 10 in full and full <= {9, 10, 11}
    assert per_row[:8].sum() == 0


def test_strip_without_labels_places_cells_on_the_grid():
    h, w = 10, 20
    rows = [[_solid((r * 100 + 10, c * 80 + 10, 50), h, w) for c in range(3)] for r in range(2)]
    out = strip(rows)
    assert out.shape == (3 * GAP + 2 * h, 4 * GAP + 3 * w, 3)
    for r in range(2):
        for c in range(3):
            y, x = GAP + r * (h + GAP), GAP + c * (w + GAP)
            assert np.array_equal(out[y:y + h, x:x + w], rows[r][c])
    # Gaps are background.
    assert np.all(out[:GAP] == preview.BACKGROUND)
    assert np.all(out[:, GAP + w:2 * GAP + w] == preview.BACKGROUND)


def test_strip_labels_go_in_margins_left_and_top():
    h, w = 30, 40
    rows = [[_solid((r * 100 + 10, c * 80 + 10, 50), h, w) for c in range(2)] for r in range(3)]
    out = strip(rows, row_labels=["forward", "blend", "backward"],
                column_labels=["a=0", "a=1"])
    left = out.shape[1] - (3 * GAP + 2 * w)
    top = out.shape[0] - (4 * GAP + 3 * h)
    assert left > 0 and top > 0
    for r in range(3):
        for c in range(2):
            y, x = top + GAP + r * (h + GAP), left + GAP + c * (w + GAP)
            assert np.array_equal(out[y:y + h, x:x + w], rows[r][c])
        row_margin = out[top + GAP + r * (h + GAP):top + GAP + r * (h + GAP) + h, :left]
        assert (row_margin.max(axis=2) < 100).sum() > 5, r
    for c in range(2):
        x = left + GAP + c * (w + GAP)
        assert (out[:top, x:x + w].max(axis=2) < 100).sum() > 5, c


def test_strip_ragged_rows_tile_and_label_counts():
    a = _solid((10, 20, 30), 10, 20)
    out = strip([[a, a], [a]], tile=10)
    assert out.shape == (3 * GAP + 2 * 5, 3 * GAP + 2 * 10, 3)
    assert np.all(out[2 * GAP + 5:2 * GAP + 10, 2 * GAP + 10:2 * GAP + 20] == preview.BACKGROUND)
    with pytest.raises(ValueError, match="row labels"):
        strip([[a], [a]], row_labels=["one"])
    with pytest.raises(ValueError, match="column labels"):
        strip([[a, a]], column_labels=["one"])
    with pytest.raises(ValueError):
        strip([])


def test_save_png_round_trip_and_no_leftovers(tmp_path):
    rng = np.random.default_rng(7)
    img = rng.integers(0, 256, (17, 23, 3), dtype=np.uint8)
    path = tmp_path / "out.png"
    save_png(path, img)
    back = cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_UNCHANGED), cv2.COLOR_BGR2RGB)
    assert np.array_equal(back, img)
    assert os.listdir(tmp_path) == ["out.png"]
    # Overwriting replaces the content.
    save_png(str(path), img[::-1])
    back = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)
    assert np.array_equal(back, img[::-1])


def test_save_png_failure_leaves_the_old_file_and_no_temp(tmp_path, monkeypatch):
    path = tmp_path / "keep.png"
    old = _solid((1, 2, 3), 4, 4)
    save_png(path, old)
    before = path.read_bytes()

    def boom(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(preview.os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        save_png(path, _solid((9, 9, 9), 4, 4))
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["keep.png"]
    with pytest.raises(ValueError):
        save_png(tmp_path / "bad.png", np.zeros((4, 4, 5), np.uint8))
    assert not (tmp_path / "bad.png").exists()
