"""The Blender add-on in real headless Blender: what Blender shows is lipsync's own frame.

One Blender run (``blender -b --factory-startup --python-exit-code 1 -P tests/blender_check.py``)
installs the add-on from the zip ``lipsync blender-addon`` writes, imports a small lipsync
render of samples/hello.phn (a 192 x 160 RGBA bank, 75 frames at 25 fps; its atlas and
frames.json at 30 fps) and keys its cues; this file then compares the renders and keyed
values with lipsync's files, by the rule written here independently of the add-on: Blender
frame ``f`` shows time ``t = (f - start) / scene_fps``, lipsync frame ``floor(t * fps)``, and
the cue that started last at or before ``t``.

Skipped (with the reason) when Debian's ``blender`` is absent; ``make test-blender`` installs
it and runs this file.
"""

import json
import math
import os
import shutil
import subprocess
import wave
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest

import synthetic
from lipsync.cli import main

BLENDER = shutil.which("blender")
pytestmark = pytest.mark.skipif(BLENDER is None, reason="no Blender: `make test-blender` installs Debian's blender")

ROOT = Path(__file__).resolve().parents[1]
HELLO = ROOT / "samples" / "hello.phn"
SPEECH = ROOT / "samples" / "hello.wav"
START = 11            # the scene's first frame: not 1, so an off-by-start shows
SIZE = (192, 160)     # synthetic.SIZE as (width, height)
OPAQUE = 30           # rows from here down are opaque in every frame (_rgba_bank)


def _rgba_bank(folder):
    """The synthetic Rhubarb-shaped bank with transparency: clear top rows, a half-clear band."""
    synthetic.write_bank(folder, synthetic.RHUBARB_SHAPES)
    for png in folder.glob("*.png"):
        im = cv2.imread(str(png))
        alpha = np.full(im.shape[:2], 255, np.uint8)
        alpha[:20], alpha[20:30] = 0, 128
        cv2.imwrite(str(png), np.dstack([im, alpha]))
    return folder


def _read(path):
    return cv2.imread(str(path), cv2.IMREAD_UNCHANGED).astype(int)


def _tsv(path):
    rows = [line.split("\t") for line in Path(path).read_text().splitlines() if line]
    return [(float(a), v) for a, v in rows[:-1]], float(rows[-1][0])


def _shape_at(cues, t):
    shown = cues[0][1]
    for start, shape in cues:
        if start <= t + 1e-9:
            shown = shape
    return shown


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("blender")
    bank = _rgba_bank(tmp / "bank")
    store = ["--store", str(tmp / "store")]
    assert main(["render", str(HELLO), "--bank", str(bank), "-o", str(tmp / "frames") + "/", "--fps", "25", "-q",
                 *store]) == 0
    assert main(["atlas", str(bank), "-o", str(tmp / "atlas" / "mouth.png"), str(HELLO), "-q", *store]) == 0
    # and one at half scale (cells and base half size, drawn back at frame size)
    assert main(["atlas", str(bank), "-o", str(tmp / "half" / "mouth.png"), str(HELLO), "-q", "--scale", "0.5",
                 *store]) == 0
    for folder in ("atlas", "half"):
        assert main(["cues", str(HELLO), "--format", "atlas", "--atlas", str(tmp / folder / "mouth.json"),
                     "--fps", "30", "--bank", str(bank), "-o", str(tmp / folder / "hello.frames.json")]) == 0
    for ext in ("tsv", "json", "xml"):
        assert main(["cues", str(HELLO), "-o", str(tmp / f"cues.{ext}")]) == 0
    (tmp / "gap").mkdir()  # frames 0, 1, 3: frame 2 missing
    for k in (0, 1, 3):
        shutil.copy(tmp / "frames" / f"frame_{k:06d}.png", tmp / "gap" / f"frame_{k:06d}.png")
    assert main(["blender-addon", "-o", str(tmp / "lipsync_blender.zip"), "-q"]) == 0
    shapes = sorted({v for _, v in _tsv(tmp / "cues.tsv")[0]})
    cues_frames = list(range(START, START + 75))
    cfg = {"zip": str(tmp / "lipsync_blender.zip"), "out": str(tmp / "out"), "frame_start": START, "cases": [
        # same rate: Blender's own sequence mapping (Workbench: flat texture colour, no alpha)
        {"kind": "import", "name": "seq25", "scene_fps": 25, "path": str(tmp / "frames" / "frame_000000.png"),
         "fps": 25, "sound": str(SPEECH), "frames": [START, START + 9, START + 40], "size": SIZE},
        # 25 fps frames in a 24 fps scene, by time (Eevee: colour and alpha)
        {"kind": "import", "name": "seq24", "scene_fps": 24, "path": str(tmp / "frames"), "fps": 25,
         "sound": str(SPEECH), "engine": "BLENDER_EEVEE", "frames": [START + 29, START + 59], "size": SIZE},
        # the atlas at 30 fps in a 24 fps scene
        {"kind": "import", "name": "atlas24", "scene_fps": 24, "path": str(tmp / "atlas" / "hello.frames.json"),
         "engine": "BLENDER_EEVEE", "frames": [START + 9, START + 29], "size": SIZE},
        # frames given as 12 fps with their 25 fps speech: imported, with a warning
        {"kind": "import", "name": "wrongfps", "scene_fps": 24, "path": str(tmp / "frames"), "fps": 12,
         "sound": str(SPEECH), "frames": [], "size": SIZE},
        # the user's own object: its material's Image Texture node gets the frames
        {"kind": "import", "name": "mat24", "scene_fps": 24, "path": str(tmp / "frames"), "fps": 25,
         "target": "MATERIAL", "frames": [START + 29], "size": SIZE},
        {"kind": "bad", "name": "gap", "operator": "import_render", "path": str(tmp / "gap" / "frame_000000.png")},
        {"kind": "bad", "name": "nosound", "operator": "import_render", "path": str(tmp / "frames"),
         "options": {"sound": str(tmp / "missing.wav")}},
        {"kind": "bad", "name": "notcues", "operator": "key_cues", "path": str(tmp / "frames" / "frame_000000.png")},
        {"kind": "import", "name": "half24", "scene_fps": 24, "path": str(tmp / "half" / "hello.frames.json"),
         "engine": "BLENDER_EEVEE", "frames": [START + 29], "size": SIZE},
        {"kind": "cues", "name": "prop", "scene_fps": 24, "target": "PROPERTY", "path": str(tmp / "cues.tsv"),
         "frames": cues_frames},
        {"kind": "cues", "name": "keys", "scene_fps": 30, "target": "SHAPE_KEYS", "path": str(tmp / "cues.json"),
         "keys": [s for s in shapes if s != "X"], "frames": cues_frames},
        {"kind": "cues", "name": "pose", "scene_fps": 24, "target": "POSE", "path": str(tmp / "cues.xml"),
         "prefix": "mouth_", "keys": shapes, "frames": cues_frames},
    ]}
    (tmp / "out").mkdir()
    (tmp / "cfg.json").write_text(json.dumps(cfg))
    env = {**os.environ, "BLENDER_USER_SCRIPTS": str(tmp / "scripts"), "BLENDER_USER_CONFIG": str(tmp / "config")}
    proc = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-exit-code", "1",
                           "-P", str(ROOT / "tests" / "blender_check.py"), "--", str(tmp / "cfg.json")],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    results = json.loads((tmp / "out" / "results.json").read_text())
    results["stdout"] = proc.stdout
    return tmp, cfg, results


def _case(cfg, name):
    return next(c for c in cfg["cases"] if c["name"] == name)


def test_the_addon_is_installed_from_lipsyncs_zip(run):
    tmp, _, results = run
    assert Path(results["module_file"]).parent == tmp / "scripts" / "addons" / "lipsync_blender"
    assert results["lipsync_importable"] is False  # it ran on Blender's Python alone
    assert results["unregistered"]  # disabling it removes its operators
    names = zipfile.ZipFile(tmp / "lipsync_blender.zip").namelist()
    assert {Path(n).name for n in names} == {p.name for p in (tmp / "scripts/addons/lipsync_blender").glob("*.py")}


@pytest.mark.parametrize("name", ["seq25", "seq24", "mat24"])
def test_png_sequence_shows_lipsyncs_frame_for_each_frames_time(run, name):
    tmp, cfg, results = run
    case = _case(cfg, name)
    frames = [_read(p) for p in sorted((tmp / "frames").glob("frame_*.png"))]
    assert len(frames) == 75 and frames[0].shape == (160, 192, 4)
    for f in case["frames"]:
        t = (f - START) / case["scene_fps"]
        k = math.floor(t * 25 + 1e-9)
        index = f - START  # what showing the files one per Blender frame would give
        shown = _read(results["renders"][name][str(f)])[1:-1, 1:-1]  # the plane's rim pixel is anti-aliased
        # colour where the frames are opaque (Workbench shows no alpha; a clear pixel's colour is moot)
        diffs = [np.abs(shown[OPAQUE:, :, :3] - fr[1 + OPAQUE:-1, 1:-1, :3]).mean() for fr in frames]
        assert int(np.argmin(diffs)) == k, (f, k, np.argsort(diffs)[:3])
        assert diffs[k] < 1.5
        if name != "seq25":  # by time, not by index: the files a frame apart differ visibly here
            assert index != k and diffs[index] > diffs[k] + 0.3, (f, diffs[index], diffs[k])
        if name == "seq24":  # Eevee renders the alpha too: clear top rows, the half-clear band, opaque below
            alpha = shown[..., 3]
            assert abs(alpha[:17].mean()) < 2 and abs(alpha[21:27].mean() - 128) < 3 and alpha[33:].min() > 250
        if name != "seq24":  # Workbench samples the texture exactly
            assert np.abs(shown[OPAQUE:, :, :3] - frames[k][1 + OPAQUE:-1, 1:-1, :3]).max() <= 2


@pytest.mark.parametrize("name", ["atlas24", "half24"])
def test_atlas_shows_the_cell_frames_json_names_at_each_frames_time(run, name):
    tmp, cfg, results = run
    case = _case(cfg, name)
    folder = tmp / {"atlas24": "atlas", "half24": "half"}[name]
    atlas = json.loads((folder / "mouth.json").read_text())
    doc = json.loads((folder / "hello.frames.json").read_text())
    texture, base = _read(folder / "mouth.png"), _read(folder / "mouth.base.png")
    rx, ry, rw, rh = atlas["region"]
    scale = atlas["scale"]
    assert scale == {"atlas24": 1.0, "half24": 0.5}[name]
    # the schema's drawing rule at frame size: base, then the cell's rect into the region, each
    # texel drawn 1 / scale frame pixels wide (a frame pixel's centre picks its texel)
    ys, xs = np.mgrid[0:SIZE[1], 0:SIZE[0]]
    base_px = base[((ys + 0.5) * scale).astype(int), ((xs + 0.5) * scale).astype(int)]
    inside = (xs >= rx) & (xs < rx + rw) & (ys >= ry) & (ys < ry + rh)

    def frame_of(cell):
        x, y = atlas["cells"][cell]["rect"][:2]
        cy = np.clip(y + ((ys - ry + 0.5) * scale).astype(int), 0, texture.shape[0] - 1)
        cx = np.clip(x + ((xs - rx + 0.5) * scale).astype(int), 0, texture.shape[1] - 1)
        return np.where(inside[..., None], texture[cy, cx], base_px)[1:-1, 1:-1]

    by_index_differs = 0
    for f in case["frames"]:
        k = math.floor((f - START) / 24 * doc["fps"] + 1e-9)
        cell = doc["frames"][k]
        shown = _read(results["renders"][name][str(f)])[1:-1, 1:-1]
        diffs = {c: np.abs(shown[OPAQUE:, :, :3] - frame_of(c)[OPAQUE:, :, :3]).mean() for c in set(doc["frames"])}
        assert min(diffs, key=diffs.get) == cell, (f, k, cell, sorted(diffs.items(), key=lambda x: x[1])[:3])
        # Closest sampling and a region mask: the render is the schema's frame, pixel for pixel
        # (compared premultiplied: a clear pixel's colour is moot)
        want = frame_of(cell)
        worst = np.abs(shown[..., :3] * shown[..., 3:] - want[..., :3] * want[..., 3:]).max() / 255
        assert worst <= 2 and np.abs(shown[..., 3] - want[..., 3]).max() <= 2, (f, worst)
        index_cell = doc["frames"][f - START]  # one cell per Blender frame would show this one
        if index_cell != cell:
            by_index_differs += 1
            assert diffs[index_cell] > diffs[cell] + 0.3
    assert by_index_differs  # a frame where matching by index would have shown another cell


def test_sound_strip_starts_with_the_frames_and_lasts_the_speech(run):
    _, cfg, results = run
    with wave.open(str(SPEECH)) as w:
        seconds = w.getnframes() / w.getframerate()
    for name, fps in (("seq25", 25), ("seq24", 24)):
        strips = results["values"][name]["sounds"]
        strip = strips[-1]
        assert strip["filepath"] == str(SPEECH)
        assert strip["frame_final_start"] == START
        assert abs(strip["frame_final_duration"] - seconds * fps) < 1.0, (strip, seconds * fps)


def test_frames_at_another_rate_than_their_speech_are_warned_about(run):
    _, _, results = run
    warnings = [line for line in results["stdout"].splitlines() if "is Render fps the --fps" in line]
    assert len(warnings) == 1 and "75 frames at 12 fps last 6.25 s but the speech lasts 2.96 s" in warnings[0]


def test_cues_keyed_on_a_property_shape_keys_and_poses(run):
    tmp, cfg, results = run
    cues, end = _tsv(tmp / "cues.tsv")  # the same track as cues.json and cues.xml
    order = list("ABCDEFGHX")
    shapes = sorted({v for _, v in cues})
    changes = 0
    for name in ("prop", "keys", "pose"):
        case = _case(cfg, name)
        values = results["values"][name]
        for f in case["frames"]:
            t = (f - START) / case["scene_fps"]
            want = _shape_at(cues, t)
            got = values[str(f)]
            if name == "prop":
                assert got == order.index(want), (f, t, got, want)
            elif name == "keys":
                assert got == {s: float(s == want) for s in case["keys"]}, (f, t, got, want)
            else:  # pose action i moves the jaw to z = i
                assert got == pytest.approx(shapes.index(want)), (f, t, got, want)
        changes += len({_shape_at(cues, (f - START) / case["scene_fps"]) for f in case["frames"]})
    assert changes > 3 * 6  # the frames checked cross many cues


def test_bad_files_are_refused_with_a_message_naming_them_and_nothing_is_made(run):
    tmp, _, results = run
    gap = results["values"]["gap"]
    assert gap["result"] == ["CANCELLED"] and gap["unchanged"]
    assert str(tmp / "gap") in gap["message"] and "frame 2 is missing" in gap["message"]
    nosound = results["values"]["nosound"]  # checked before the plane is made
    assert nosound["result"] == ["CANCELLED"] and nosound["unchanged"] and "missing.wav: no such sound" in nosound["message"]
    bad = results["values"]["notcues"]
    assert bad["result"] == ["CANCELLED"] and bad["unchanged"]
    assert "frame_000000.png" in bad["message"] and "unknown cue file type .png" in bad["message"]
