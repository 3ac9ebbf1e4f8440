"""Sprite atlases: layout, cells against lipsync's own frames, frames.json against the sequencer.

Independent references: ``lipsync morph`` (the public command) and the Renderer for what a
cell must hold; the Animator's FrameSpecs (the frames ``lipsync render`` draws) and a
nearest-alpha search written here for what frames.json must say; the cue track ``lipsync
cues`` writes for which transitions a timeline uses.
"""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from lipsync import Animator, Bank
from lipsync._data import default_bank_dir
from lipsync.atlas import load_atlas
from lipsync.atlas.build import build_atlas, compose
from lipsync.atlas.layout import fit, grid
from lipsync.cli import main
from lipsync.errors import InputError
from lipsync.morphing.render import Renderer

ROOT = Path(__file__).parent.parent
HELLO = ROOT / "samples" / "hello.phn"
BALLOONS = ROOT / "samples" / "balloons.phn"
N = 3  # in-betweens in the atlases below: cells at alpha 1/4, 1/2, 3/4
N_ALL = 2  # in-betweens of the all-pairs atlas (81 cells: a 24 MB texture in memory, not 38)


def read_rgba(path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert img is not None and img.shape[2] == 4, path
    return cv2.cvtColor(img, cv2.COLOR_BGRA2RGBA)


def read_rgb(path) -> np.ndarray:
    return cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


@pytest.fixture(scope="module")
def toon():
    return Bank.load(default_bank_dir())


@pytest.fixture(scope="module")
def renderer(toon):
    return Renderer(toon)


@pytest.fixture(scope="module")
def all_pairs(tmp_path_factory, toon):
    out = tmp_path_factory.mktemp("all") / "mouth.png"
    assert main(["atlas", str(default_bank_dir()), "-o", str(out), "--pairs", "all", "-n", str(N_ALL), "-q"]) == 0
    atlas = load_atlas(out.with_suffix(".json"))
    return atlas, read_rgba(out), read_rgba(out.with_name("mouth.base.png"))


@pytest.fixture(scope="module")
def hello(tmp_path_factory):
    d = tmp_path_factory.mktemp("hello")
    assert main(["atlas", str(default_bank_dir()), "-o", str(d / "mouth.png"), "-q", "-n", str(N), str(HELLO)]) == 0
    return d


# --- layout ---------------------------------------------------------------------------------

@pytest.mark.parametrize("n", [1, 2, 7, 9, 117, 300])
def test_grid_is_the_smallest_square_ish_grid_and_cells_do_not_overlap(n):
    g = grid(n, (30, 20), padding=2)
    w, h = g.size
    # no grid with fewer columns or rows has a shorter longest side
    for cols in range(1, n + 1):
        rows = -(-n // cols)
        assert max(cols * 34, rows * 24) >= max(w, h)
    occupied = np.zeros((h, w), int)
    for i in range(n):
        x, y, cw, ch = g.rect(i)
        assert (cw, ch) == (30, 20) and x >= 2 and y >= 2 and x + cw + 2 <= w and y + ch + 2 <= h
        occupied[y - 2:y + ch + 2, x - 2:x + cw + 2] += 1
    assert occupied.max() == 1


def test_too_large_names_a_scale_that_fits():
    with pytest.raises(InputError, match=r"--scale 0\.(\d+)") as info:
        fit(117, (306, 251), scale=1.0, max_size=2048)
    s = float(str(info.value).split("--scale ")[1].split()[0])
    assert max(fit(117, (306, 251), scale=s, max_size=2048).size) <= 2048
    with pytest.raises(InputError):
        fit(117, (306, 251), scale=s + 0.01, max_size=2048)


# --- cells against lipsync's own frames ----------------------------------------------------

def test_every_cell_is_the_rendered_frame_of_its_pair_and_alpha(all_pairs, toon, renderer):
    atlas, texture, base = all_pairs
    names = list(toon.names)
    assert atlas.visemes == tuple(names) and atlas.rest == "X" and atlas.inbetweens == N_ALL
    pairs = [(a, b) for i, a in enumerate(names) for b in names[i + 1:]]
    assert len(atlas.cells) == len(names) + N_ALL * len(pairs)
    assert [(c.from_viseme, c.alpha) for c in atlas.cells[:len(names)]] == [(v, 0.0) for v in names]
    assert [(c.from_viseme, c.to_viseme, c.alpha) for c in atlas.cells[len(names):]] == [
        (a, b, k / (N_ALL + 1)) for a, b in pairs for k in range(1, N_ALL + 1)]
    for i, c in enumerate(atlas.cells):
        frame = compose(atlas, texture, base, i)
        want = renderer.render(c.from_viseme, c.to_viseme, c.alpha)
        assert np.array_equal(frame[..., :3], want), (i, c)
        assert (frame[..., 3] == 255).all()  # an opaque bank: opaque cells and base together


@pytest.mark.parametrize("cell", [0, 12, 40, 77])
def test_cell_equals_lipsync_morph(all_pairs, tmp_path, cell):
    atlas, texture, base = all_pairs
    c = atlas.cells[cell]
    out = tmp_path / "morph.png"
    args = ["morph", str(default_bank_dir()), c.from_viseme, c.to_viseme, "--alpha", repr(c.alpha), "-o", str(out)]
    assert main(args) == 0
    assert np.array_equal(compose(atlas, texture, base, cell)[..., :3], read_rgb(out))


def test_region_is_the_tight_box_of_what_changes(all_pairs, renderer):
    atlas, texture, base = all_pairs
    rx, ry, rw, rh = atlas.region
    rest = renderer.render("X", "X", 0.0).copy()
    differs = np.zeros(rest.shape[:2], bool)
    for i in range(len(atlas.cells)):
        differs |= np.any(compose(atlas, texture, base, i)[..., :3] != rest, axis=2)
    ys, xs = np.nonzero(differs)
    assert (xs.min(), ys.min(), xs.max() + 1 - xs.min(), ys.max() + 1 - ys.min()) == (rx, ry, rw, rh)
    # the base holds the rest of the frame and is clear inside the region
    assert (base[ry:ry + rh, rx:rx + rw, 3] == 0).all()
    outside = np.ones(rest.shape[:2], bool)
    outside[ry:ry + rh, rx:rx + rw] = False
    assert np.array_equal(base[..., :3][outside], rest[outside]) and (base[..., 3][outside] == 255).all()
    # the crop is worth it on the toon: under a third of the frame's pixels per cell
    assert rw * rh < 0.3 * 512 * 512


def test_padding_repeats_the_cell_edge_and_the_rest_is_clear(all_pairs):
    atlas, texture, _ = all_pairs
    p = atlas.padding
    used = np.zeros(texture.shape[:2], bool)
    for c in atlas.cells:
        x, y, w, h = c.rect
        cell = texture[y:y + h, x:x + w]
        padded = texture[y - p:y + h + p, x - p:x + w + p]
        assert np.array_equal(padded, cv2.copyMakeBorder(cell, p, p, p, p, cv2.BORDER_REPLICATE))
        used[y - p:y + h + p, x - p:x + w + p] = True
    assert (texture[~used] == 0).all()
    assert max(texture.shape[:2]) <= 4096


def test_scaled_atlas_cells_are_the_area_averaged_frames(tmp_path, all_pairs):
    full, texture, base = all_pairs
    out = tmp_path / "half.png"
    assert main(["atlas", str(default_bank_dir()), "-o", str(out), "--scale", "0.5", "-n", str(N_ALL), "-q"]) == 0
    half = load_atlas(out.with_suffix(".json"))
    small = read_rgba(out)
    assert half.scale == 0.5 and half.region == full.region and half.frame_size == (512, 512)
    rw, rh = full.region[2:]
    # the same (from, to, alpha) at full scale (the same cells: the region is the same too)
    lookup = {(c.from_viseme, c.to_viseme, c.alpha): i for i, c in enumerate(full.cells)}
    for c in half.cells[:14]:
        x, y, w, h = full.cells[lookup[(c.from_viseme, c.to_viseme, c.alpha)]].rect
        want = cv2.resize(texture[y:y + h, x:x + w], (round(rw / 2), round(rh / 2)), interpolation=cv2.INTER_AREA)
        x, y, w, h = c.rect
        assert (w, h) == want.shape[1::-1]
        assert np.abs(small[y:y + h, x:x + w].astype(int) - want).max() <= 1


def test_too_large_exits_2_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "big.png"
    assert main(["atlas", str(default_bank_dir()), "-o", str(out), "-n", "8", "-q"]) == 2
    err = capsys.readouterr().err
    assert "above --max-size 4096: use --scale 0." in err
    assert list(tmp_path.iterdir()) == []


# --- which transitions ----------------------------------------------------------------------

def _cue_pairs(tmp_path, timeline):
    """Transitions of the cue track `lipsync cues` writes (the sequencer's plan), read back."""
    out = tmp_path / "cues.tsv"
    assert main(["cues", str(timeline), "-o", str(out), "-q"]) == 0
    shapes = [line.split("\t")[1] for line in out.read_text().splitlines()]
    order = "ABCDEFGHX"
    return {tuple(sorted((a, b), key=order.index)) for a, b in zip(shapes, shapes[1:]) if a != b}


def test_used_pairs_are_the_timelines_transitions(tmp_path, hello, toon):
    atlas = load_atlas(hello / "mouth.json")
    stored = {(c.from_viseme, c.to_viseme) for c in atlas.cells if c.viseme is None}
    assert stored == _cue_pairs(tmp_path, HELLO)
    # every morph the render of hello makes, at any frame rate, is in the atlas
    for fps in (24, 25, 30, 60):
        anim = Animator(toon, HELLO, fps=fps)
        morphs = {tuple(sorted((s.from_viseme, s.to_viseme), key=toon.names.index)) for s in anim.specs
                  if not s.is_still}
        assert morphs <= stored
    # two timelines: the union
    out = tmp_path / "two.png"
    assert main(["atlas", str(default_bank_dir()), "-o", str(out), "-q", "-n", "1", str(HELLO), str(BALLOONS)]) == 0
    two = {(c.from_viseme, c.to_viseme) for c in load_atlas(out.with_suffix(".json")).cells if c.viseme is None}
    assert two == stored | _cue_pairs(tmp_path, BALLOONS)


# --- frames.json against the sequencer ------------------------------------------------------

def _nearest_cell(atlas, spec):
    """The cell a frame should show, by brute force over every cell of the atlas."""
    if spec.is_still:
        return [i for i, c in enumerate(atlas.cells) if c.viseme == spec.shown]
    best, cells = None, []
    for i, c in enumerate(atlas.cells):
        if c.viseme is not None:
            alpha = {spec.from_viseme: 0.0, spec.to_viseme: 1.0}.get(c.viseme)
        elif (c.from_viseme, c.to_viseme) == (spec.from_viseme, spec.to_viseme):
            alpha = c.alpha
        elif (c.to_viseme, c.from_viseme) == (spec.from_viseme, spec.to_viseme):
            alpha = 1.0 - c.alpha
        else:
            alpha = None
        if alpha is None:
            continue
        d = abs(alpha - spec.alpha)
        if best is None or d < best - 1e-12:
            best, cells = d, [i]
        elif abs(d - best) <= 1e-12:
            cells.append(i)
    return cells


@pytest.mark.parametrize("fps", [24, 25, 30])
def test_frames_are_the_nearest_cells_of_the_sequencers_frames(tmp_path, hello, toon, fps):
    atlas = load_atlas(hello / "mouth.json")
    out = tmp_path / "frames.json"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert main(["cues", str(HELLO), "--format", "atlas", "--atlas", str(hello / "mouth.json"),
                     "--fps", str(fps), "-o", str(out), "-q"]) == 0
    doc = json.loads(out.read_text())
    specs = Animator(toon, HELLO, fps=fps).specs
    assert doc["format"] == "lipsync-atlas-frames" and doc["version"] == 1 and doc["fps"] == fps
    assert doc["count"] == len(doc["frames"]) == len(specs) and doc["missing_pairs"] == []
    assert doc["atlas"] == "../" + hello.name + "/mouth.json"
    assert (out.parent / doc["atlas"]).resolve() == (hello / "mouth.json").resolve()
    morphs = 0
    for n, (spec, cell) in enumerate(zip(specs, doc["frames"])):
        assert cell in _nearest_cell(atlas, spec), (n, spec, atlas.cells[cell])
        if not spec.is_still:
            morphs += 1
            assert atlas.cells[cell].viseme is None or min(spec.alpha, 1 - spec.alpha) <= 1 / (2 * (N + 1))
    assert morphs >= 10


def test_pairs_missing_from_the_atlas_show_the_nearer_viseme_with_a_warning(tmp_path, hello, toon):
    out = tmp_path / "frames.json"
    with pytest.warns(UserWarning, match=r"transition\(s\) are not in the atlas"):
        assert main(["cues", str(BALLOONS), "--format", "atlas", "--atlas", str(hello / "mouth.json"),
                     "--fps", "25", "-o", str(out), "-q"]) == 0
    doc = json.loads(out.read_text())
    atlas = load_atlas(hello / "mouth.json")
    stored = {(c.from_viseme, c.to_viseme) for c in atlas.cells if c.viseme is None}
    specs = Animator(toon, BALLOONS, fps=25).specs
    missing = set()
    for spec, cell in zip(specs, doc["frames"]):
        pair = (spec.from_viseme, spec.to_viseme)
        if spec.is_still or pair in stored or pair[::-1] in stored:
            continue
        missing.add(pair)
        want = spec.from_viseme if spec.alpha < 0.5 else spec.to_viseme
        assert atlas.cells[cell].viseme == want
    assert missing and {tuple(p) for p in doc["missing_pairs"]} == missing


# --- bad input ------------------------------------------------------------------------------

@pytest.mark.parametrize("edit, message", [
    (lambda d: d.update(version=2), "atlas version 2 is newer"),
    (lambda d: d.update(format="other"), "not a lipsync atlas"),
    (lambda d: d["cells"][3].update(rect=[5000, 0, 10, 10]), "cell 3: \"rect\""),
    (lambda d: d["cells"][20].update(alpha=1.5), "cell 20: \"alpha\""),
    (lambda d: d.update(image="../../etc/passwd"), "must be a file beside the atlas"),
    (lambda d: d.update(region=[0, 0, 600, 10]), "\"region\""),
])
def test_bad_atlas_json_exits_2_naming_the_file(tmp_path, hello, capsys, edit, message):
    doc = json.loads((hello / "mouth.json").read_text())
    edit(doc)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    out = tmp_path / "frames.json"
    assert main(["cues", str(HELLO), "--format", "atlas", "--atlas", str(bad), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: " in err and message in err
    assert not out.exists()


@pytest.mark.parametrize("args, message", [
    (["cues", str(HELLO), "--format", "atlas", "-o", "{d}/f.json"], "--format atlas needs --atlas"),
    (["cues", str(HELLO), "--atlas", "{d}/x.json", "-o", "{d}/f.tsv"], "--atlas is for --format atlas only"),
    (["atlas", str(default_bank_dir()), "-o", "{d}/m.png", "--pairs", "used"], "--pairs used needs timelines"),
    (["atlas", str(default_bank_dir()), "-o", "{d}/m.png", "-n", "65"], "--inbetweens must be a whole number 0..64"),
    (["atlas", str(default_bank_dir()), "-o", "{d}/m.jpg"], "must be a .png"),
    (["atlas", str(default_bank_dir()), "-o", "{d}/m.png", "--scale", "0"], "--scale must be in (0, 1]"),
    (["atlas", str(default_bank_dir()), "-o", "{d}/m.png", str(ROOT / "nope.phn")], "nope.phn: no such file"),
])
def test_bad_options_exit_2_and_write_nothing(tmp_path, capsys, args, message):
    d = tmp_path / "out"
    d.mkdir()
    assert main([a.replace("{d}", str(d)) for a in args]) == 2
    assert message in capsys.readouterr().err
    assert list(d.iterdir()) == []


def test_library_api_refuses_unknown_visemes():
    with pytest.raises(InputError, match="viseme 'Q' is not in the bank"):
        build_atlas(default_bank_dir(), pairs=[("A", "Q")])


def test_player_files_are_written_with_player(tmp_path):
    from lipsync.atlas import player_files

    out = tmp_path / "m.png"
    assert main(["atlas", str(default_bank_dir()), "-o", str(out), "-n", "0", "-q", "--player"]) == 0
    for src in player_files():
        assert (tmp_path / src.name).read_bytes() == src.read_bytes()
    text = (tmp_path / "player.html").read_text() + (tmp_path / "player.js").read_text()
    assert "http://" not in text.replace("http://127.0.0.1", "") and "https://" not in text  # nothing from a CDN
    atlas = load_atlas(out.with_suffix(".json"))
    assert len(atlas.cells) == 9 and atlas.inbetweens == 0


def test_no_crop_cells_are_whole_frames(tmp_path, renderer):
    out = tmp_path / "m.png"
    assert main(["atlas", str(default_bank_dir()), "-o", str(out), "-q", "--no-crop", str(HELLO), "-n", "1"]) == 0
    atlas = load_atlas(out.with_suffix(".json"))
    assert atlas.region == (0, 0, 512, 512) and atlas.base is None
    assert not out.with_name("m.base.png").exists()
    tex = read_rgba(out)
    c = atlas.cells[-1]
    assert np.array_equal(compose(atlas, tex, None, len(atlas.cells) - 1)[..., :3],
                          renderer.render(c.from_viseme, c.to_viseme, c.alpha))
    shutil.rmtree(tmp_path)


# --- the dominance timing model ---------------------------------------------------------------

@pytest.fixture(scope="module")
def dominant_bank(tmp_path_factory):
    """The toon with ``timing: dominance`` in its bank.yaml (flows copied along)."""
    d = tmp_path_factory.mktemp("dom") / "toon"
    shutil.copytree(default_bank_dir(), d)
    text = (d / "bank.yaml").read_text()
    (d / "bank.yaml").write_text(text.replace("rest: X\n", "rest: X\ntiming: dominance\n", 1))
    assert Bank.load(d).timing == "dominance"
    return d


def test_dominance_frames_follow_the_banks_timing(tmp_path, dominant_bank):
    bank = Bank.load(dominant_bank)
    out = tmp_path / "mouth.png"
    assert main(["atlas", str(dominant_bank), "-o", str(out), "-q", "-n", str(N), str(BALLOONS)]) == 0
    atlas = load_atlas(out.with_suffix(".json"))
    stored = {(c.from_viseme, c.to_viseme) for c in atlas.cells if c.viseme is None}
    # the model blends the two heaviest sounds, not only neighbours: more pairs than the plan
    assert stored > _cue_pairs(tmp_path, BALLOONS)
    for fps in (24, 30):
        frames = tmp_path / f"frames{fps}.json"
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # every pair the frames use is in the atlas
            assert main(["cues", str(BALLOONS), "--format", "atlas", "--atlas", str(out.with_suffix(".json")),
                         "--bank", str(dominant_bank), "--fps", str(fps), "-o", str(frames), "-q"]) == 0
        doc = json.loads(frames.read_text())
        specs = Animator(bank, BALLOONS, fps=fps).specs  # the bank's timing: dominance
        rule_specs = Animator(bank, BALLOONS, fps=fps, timing="sqrt-fast-middle").specs
        assert specs != rule_specs and len(doc["frames"]) == len(specs)
        for n, (spec, cell) in enumerate(zip(specs, doc["frames"])):
            assert cell in _nearest_cell(atlas, spec), (fps, n, spec)
    # without --bank the bank's bank.yaml is unknown: --timing says it, else the default curve
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    atlas_json = str(out.with_suffix(".json"))
    assert main(["cues", str(BALLOONS), "--format", "atlas", "--atlas", atlas_json, "--fps", "25", "-o", str(a),
                 "-q", "--timing", "dominance"]) == 0
    assert main(["cues", str(BALLOONS), "--format", "atlas", "--atlas", atlas_json, "--fps", "25", "-o", str(b),
                 "-q", "--bank", str(dominant_bank)]) == 0
    assert json.loads(a.read_text())["frames"] == json.loads(b.read_text())["frames"]


def test_frames_without_fps_are_the_frames_render_renders(tmp_path, hello, toon):
    # one default frame rate for every command (issue 20): atlas frames are what a player
    # shows, so without --fps they are render's 25 a second (Moho keys keep Moho's 24)
    from lipsync.motion.frames import DEFAULT_FPS

    out = tmp_path / "frames.json"
    assert main(["cues", str(HELLO), "--format", "atlas", "--atlas", str(hello / "mouth.json"),
                 "-o", str(out), "-q"]) == 0
    doc = json.loads(out.read_text())
    assert doc["fps"] == DEFAULT_FPS == 25 and doc["count"] == len(Animator(toon, HELLO).specs)
    dat, dat24 = tmp_path / "hello.dat", tmp_path / "hello24.dat"
    assert main(["cues", str(HELLO), "-o", str(dat), "-q"]) == 0
    assert main(["cues", str(HELLO), "-o", str(dat24), "--fps", "24", "-q"]) == 0
    assert dat.read_text() == dat24.read_text()
