"""Atlases of a transparent bank: the texture keeps the bank's alpha, cell for cell.

A synthetic bank of nine semi-transparent discs (Rhubarb's shapes A-H and X, so the
default map reads timelines onto it), each with its own place, size and opacity. Every
cell, placed in the frame, must be the renderer's RGBA frame exactly; scaled cells are
area-averaged premultiplied (no dark rim from the clear pixels around a disc); and the
player page draws them with their alpha (headless Chromium; skipped without it).
"""

from __future__ import annotations

import base64
import json
import shutil
import threading
from functools import partial
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import cv2
import numpy as np
import pytest

from lipsync import Animator, Bank
from lipsync.atlas import load_atlas
from lipsync.atlas.build import compose
from lipsync.cli import main
from lipsync.editor.browser import chromium, missing, wait
from lipsync.morphing.render import Renderer

H, W = 72, 120
#: (centre x, centre y, radius, colour, alpha) per viseme: the discs move, grow and fade.
DISCS = {
    "X": (30, 36, 10, (200, 40, 40), 90), "A": (40, 36, 12, (40, 40, 200), 240),
    "B": (50, 34, 9, (40, 180, 40), 160), "C": (60, 38, 13, (200, 200, 40), 200),
    "D": (70, 36, 16, (200, 40, 200), 255), "E": (64, 30, 11, (40, 200, 200), 120),
    "F": (56, 40, 8, (120, 60, 20), 210), "G": (46, 32, 12, (240, 240, 240), 70),
    "H": (36, 38, 14, (20, 20, 20), 180),
}
TIMELINE = "0.00\tX\n0.20\tD\n0.45\tA\n0.60\tF\n0.85\tX\n1.10\tX\n"


def disc(cx, cy, r, colour, a):
    ss = 8
    ys, xs = np.mgrid[0:H * ss, 0:W * ss]
    inside = ((xs + 0.5) / ss - 0.5 - cx) ** 2 + ((ys + 0.5) / ss - 0.5 - cy) ** 2 <= r * r
    cov = inside.reshape(H, ss, W, ss).mean(axis=(1, 3))
    img = np.zeros((H, W, 4), np.uint8)
    img[..., :3] = np.where(cov[..., None] > 0, colour, 0)
    img[..., 3] = np.rint(cov * a)
    return img


@pytest.fixture(scope="module")
def bank_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("discs") / "bank"
    d.mkdir()
    lines = []
    for name, (cx, cy, r, colour, a) in DISCS.items():
        cv2.imwrite(str(d / f"{name}.png"), cv2.cvtColor(disc(cx, cy, r, colour, a), cv2.COLOR_RGBA2BGRA))
        # one vertical line through the centre, as long as the disc is tall: Beier-Neely moves
        # and stretches the disc onto the next one
        lines.append(f"  {name}: {{image: {name}.png, lines: {{axis: [[{cx}, {cy - r}], [{cx}, {cy + r}]]}}}}")
    (d / "bank.yaml").write_text("name: discs\nrest: X\nsymmetry: false\nvisemes:\n" + "\n".join(lines) + "\n")
    return d


@pytest.fixture(scope="module")
def site(tmp_path_factory, bank_dir):
    d = tmp_path_factory.mktemp("rgba-site")
    (d / "line.tsv").write_text(TIMELINE)
    assert main(["atlas", str(bank_dir), "-o", str(d / "mouth.png"), "-n", "3", "--player", "-q", str(d / "line.tsv")]) == 0
    assert main(["cues", str(d / "line.tsv"), "--format", "atlas", "--atlas", str(d / "mouth.json"), "--fps", "25",
                 "-o", str(d / "frames.json"), "-q"]) == 0
    return d


def read_rgba(path):
    return cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_UNCHANGED), cv2.COLOR_BGRA2RGBA)


def premultiplied(rgba):
    a = rgba[..., 3:4].astype(np.float64)
    return np.concatenate([rgba[..., :3] * a / 255.0, a], axis=2)


def test_cells_keep_the_banks_alpha_exactly(site, bank_dir):
    bank = Bank.load(bank_dir)
    assert bank.channels == 4
    renderer = Renderer(bank)
    atlas = load_atlas(site / "mouth.json")
    texture = read_rgba(site / "mouth.png")
    # outside the discs' region the frame is clear: nothing to draw there, no base image
    assert atlas.base is None and not (site / "mouth.base.png").exists()
    rx, ry, rw, rh = atlas.region
    assert rw < W and rh < H
    partial_alpha = 0
    for i, c in enumerate(atlas.cells):
        want = renderer.render(c.from_viseme, c.to_viseme, c.alpha)
        assert want.shape == (H, W, 4)
        got = compose(atlas, texture, None, i)
        assert np.array_equal(got, want), (i, c)
        partial_alpha += int(((got[..., 3] > 0) & (got[..., 3] < 255)).sum())
        outside = np.ones((H, W), bool)
        outside[ry:ry + rh, rx:rx + rw] = False
        assert (want[..., 3][outside] == 0).all()
    assert partial_alpha > 1000  # faint discs and soft edges: the texture is not just 0 and 255
    # a viseme cell is the bank's image (normalised only by a resampling of the same picture)
    d = atlas.viseme_cells()["D"]
    assert compose(atlas, texture, None, d)[..., 3].max() == 255
    assert compose(atlas, texture, None, atlas.viseme_cells()["G"])[..., 3].max() == 70


def test_scaled_cells_are_averaged_premultiplied(tmp_path, site, bank_dir):
    out = tmp_path / "half.png"
    assert main(["atlas", str(bank_dir), "-o", str(out), "-n", "3", "--scale", "0.5", "-q",
                 str(site / "line.tsv")]) == 0
    half, full = load_atlas(out.with_suffix(".json")), load_atlas(site / "mouth.json")
    small, big = read_rgba(out), read_rgba(site / "mouth.png")
    assert half.region == full.region and len(half.cells) == len(full.cells)
    for hc, fc in zip(half.cells, full.cells):
        x, y, w, h = fc.rect
        x2, y2, w2, h2 = hc.rect
        ref = cv2.resize(premultiplied(big[y:y + h, x:x + w]).astype(np.float32), (w2, h2),
                         interpolation=cv2.INTER_AREA)
        got = premultiplied(small[y2:y2 + h2, x2:x2 + w2])
        # 8-bit straight alpha stored: premultiplied colour within a grey level or two
        assert np.abs(got - ref).max() <= 2.0, (hc, np.abs(got - ref).max())
    # a straight-alpha average mixes in the black of the clear pixels: the soft rim of the red
    # disc would come out darker; the atlas keeps it red
    x, y, w, h = full.cells[full.viseme_cells()["X"]].rect
    naive = cv2.resize(big[y:y + h, x:x + w], (half.cells[0].rect[2], half.cells[0].rect[3]),
                       interpolation=cv2.INTER_AREA)
    x2, y2, w2, h2 = half.cells[half.viseme_cells()["X"]].rect
    rim = (small[y2:y2 + h2, x2:x2 + w2, 3] > 0) & (small[y2:y2 + h2, x2:x2 + w2, 3] < 60)
    assert rim.any()
    assert small[y2:y2 + h2, x2:x2 + w2, 0][rim].mean() > naive[..., 0][rim].mean() + 20  # red, not darkened


class _Quiet(SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


@pytest.mark.skipif(missing() is not None, reason=f"no headless Chromium: {missing()}")
def test_player_draws_the_transparent_frames(site, bank_dir):
    frames = json.loads((site / "frames.json").read_text())
    atlas = load_atlas(site / "mouth.json")
    anim = Animator(Bank.load(bank_dir), site / "line.tsv", fps=25)
    assert len(anim) == frames["count"]
    server = ThreadingHTTPServer(("127.0.0.1", 0), partial(_Quiet, directory=str(site)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        with chromium(600, 500) as driver:
            driver.get(f"http://127.0.0.1:{server.server_address[1]}/player.html?atlas=mouth.json&frames=frames.json")
            wait(driver, "window.lipsyncAtlasPlayer.ready || window.lipsyncAtlasPlayer.errors > 0")
            assert driver.execute_script("return window.lipsyncAtlasPlayer.errors") == 0
            for n, spec in enumerate(anim.specs):
                url = driver.execute_script("window.lipsyncAtlasPlayer.drawAt(arguments[0]);"
                                            "return document.getElementById('view').toDataURL('image/png');",
                                            (n + 0.5) / 25)
                png = base64.b64decode(url.split(",", 1)[1])
                drawn = cv2.cvtColor(cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED),
                                     cv2.COLOR_BGRA2RGBA)
                cell = atlas.cells[frames["frames"][n]]
                want = anim.renderer.render(cell.from_viseme, cell.to_viseme, cell.alpha)
                # the canvas keeps premultiplied 8-bit colour: compare there
                diff = np.abs(premultiplied(drawn) - premultiplied(want))
                assert diff[..., 3].max() == 0 and diff.max() <= 1.0 + 1e-9, (n, spec, diff.max())
                if spec.is_still:
                    assert np.array_equal(want, anim.frame(n))
    finally:
        server.shutdown()
        server.server_close()
