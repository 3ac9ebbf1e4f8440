"""The Blender add-on's files without Blender: the zip, the frame rule, the readers of lipsync's files.

The add-on's ``files.py`` imports no bpy, so it is loaded here on its own; its readers are
checked against lipsync's own timeline readers on every cue format ``lipsync cues`` writes,
and its frame rule against keys evaluated the way Blender evaluates constant fcurves. What
Blender shows is tests/test_blender.py's part (it needs Blender).
"""

import importlib.util
import json
import math
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import lipsync
from lipsync.blender import ADDON_MODULE, addon_files, write_addon_zip
from lipsync.cli import main

ROOT = Path(__file__).resolve().parents[1]
HELLO = ROOT / "samples" / "hello.phn"


@pytest.fixture(scope="module")
def files():
    path = next(p for p in addon_files() if p.name == "files.py")
    spec = importlib.util.spec_from_file_location("lipsync_blender_files", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_zip_holds_the_addon_package_and_is_the_same_every_time(tmp_path):
    a = write_addon_zip(tmp_path / "a.zip")
    assert main(["blender-addon", "-o", str(tmp_path / "b.zip"), "-q"]) == 0
    assert a.read_bytes() == (tmp_path / "b.zip").read_bytes()
    with zipfile.ZipFile(a) as zf:
        assert sorted(zf.namelist()) == [f"{ADDON_MODULE}/{p.name}" for p in addon_files()]
        init = zf.read(f"{ADDON_MODULE}/__init__.py").decode()
    assert "bl_info" in init and "def register" in init and "def unregister" in init
    assert "import lipsync" not in init.replace("import lipsync_blender", "")


def test_a_bad_output_name_exits_2_and_writes_nothing(tmp_path, capsys):
    assert main(["blender-addon", "-o", str(tmp_path / "addon.txt")]) == 2
    assert "addon.txt" in capsys.readouterr().err and not list(tmp_path.iterdir())
    (tmp_path / "folder.zip").mkdir()
    assert main(["blender-addon", "-o", str(tmp_path / "folder.zip")]) == 2


def test_the_wheel_ships_the_addon_source(tmp_path):
    src = tmp_path / "src"
    listed = subprocess.run(["git", "ls-files", "-z", "lipsync", "setup.py", "pyproject.toml", "README.md",
                             "LICENSE", "visemes", "configs"], cwd=ROOT, capture_output=True, check=True).stdout
    for name in (n for n in listed.decode().split("\0") if n):
        if (ROOT / name).is_file():
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, src / name)
    for p in addon_files():  # also when run before the add-on is committed
        dest = src / p.relative_to(ROOT)
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(p, dest)
    run = subprocess.run([sys.executable, "setup.py", "-q", "build_py", "-d", str(tmp_path / "lib")], cwd=src,
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-2000:]
    shipped = tmp_path / "lib" / "lipsync" / "blender" / "addon" / ADDON_MODULE
    assert sorted(p.name for p in shipped.glob("*.py")) == [p.name for p in addon_files()]


@pytest.mark.parametrize("ext", ["tsv", "json", "xml", "TextGrid", "txt", "dat"])
def test_cue_readers_agree_with_lipsyncs_own_readers(tmp_path, files, ext):
    out = tmp_path / f"cues.{ext}"
    assert main(["cues", str(HELLO), "-o", str(out), "--fps", "24"]) == 0
    cues = files.read_cues(str(out), moho_fps=24)
    own = [s for s in lipsync.read_timeline(out)]
    if ext == "tsv":  # lipsync's reader keeps Rhubarb's closing X as a cue of no length
        own = [s for s in own if s.end > s.start] or own
    assert [shape for _, shape in cues.starts] == [s.label for s in own]
    assert [start for start, _ in cues.starts] == pytest.approx([s.start for s in own], abs=1e-6)
    assert len(cues.starts) > 15


def test_frame_rule_by_time_and_the_keys_that_give_it(files):
    # same rate: frame_000000.png is Blender frame 1 when the scene starts at 1
    assert [files.lipsync_frame(f, frame_start=1, scene_fps=24, fps=24, count=100) for f in (1, 2, 25)] == [0, 1, 24]
    # 25 fps frames in a 24 fps scene: one second (24 Blender frames) shows 25 frames' worth, skipping one
    shown = [files.lipsync_frame(f, frame_start=1, scene_fps=24, fps=25, count=100) for f in range(1, 26)]
    assert shown[-1] == 25 and len(set(shown)) == 25 and sorted(set(range(26)) - set(shown)) == [24]
    # constant keys at key_frame(k / fps), evaluated at whole frames, give the same rule,
    # including frames that fall exactly on a lipsync frame's start
    for sfps, fps, start in ((24, 25, 1), (30, 24, 11), (25, 30, 0), (24, 24, 101), (29.97, 30, 1), (60, 7.5, 3)):
        keys = [files.key_frame(k / fps, frame_start=start, scene_fps=sfps) for k in range(200)]
        for f in range(start, start + 150):
            # fcurves store frames as float32: a key at 23.999999 must still be reached at 24
            last = max(k for k, x in enumerate(keys) if _f32(x) <= f) if _f32(keys[0]) <= f else 0
            assert last == files.lipsync_frame(f, frame_start=start, scene_fps=sfps, fps=fps, count=200), (sfps, fps, f)
            t = (f - start) / sfps
            assert last == math.floor(t * fps + 1e-9) or abs(t * fps - round(t * fps)) < 1e-6


def _f32(x):
    import numpy as np

    return float(np.float32(x))


def test_png_sequence_and_atlas_errors_name_the_file(tmp_path, files):
    with pytest.raises(files.LipsyncFileError, match="no lipsync frames here"):
        files.png_sequence(str(tmp_path))
    for k in (0, 1, 3):
        (tmp_path / f"frame_{k:06d}.png").write_bytes(b"")
    with pytest.raises(files.LipsyncFileError, match=f"{tmp_path}: frame 2 is missing"):
        files.png_sequence(str(tmp_path / "frame_000000.png"))
    (tmp_path / "frame_000003.png").unlink()
    (tmp_path / "frame_000002.png").write_bytes(b"")
    assert files.png_sequence(str(tmp_path)).numbers == (0, 1, 2)
    atlas = {"format": "lipsync-atlas", "version": 1, "cells": [{"rect": [0, 0, 1, 1]}]}
    (tmp_path / "m.json").write_text(json.dumps(atlas))
    doc = {"format": "lipsync-atlas-frames", "version": 1, "atlas": "m.json", "fps": 30, "frames": [0, 1]}
    (tmp_path / "f.json").write_text(json.dumps(doc))
    with pytest.raises(files.LipsyncFileError, match="f.json: frame 1 names cell 1, the atlas has 1"):
        files.atlas_clip(str(tmp_path / "f.json"))
    (tmp_path / "f.json").write_text(json.dumps({**doc, "version": 2}))
    with pytest.raises(files.LipsyncFileError, match="version 2 is newer"):
        files.atlas_clip(str(tmp_path / "f.json"))
    (tmp_path / "f.json").write_text("{\n oops")
    with pytest.raises(files.LipsyncFileError, match="f.json: line 2: not JSON"):
        files.atlas_clip(str(tmp_path / "f.json"))
    (tmp_path / "c.tsv").write_text("0.000\tX\nzero\tA\n")
    with pytest.raises(files.LipsyncFileError, match="c.tsv: line 2: 'zero' is not a time"):
        files.read_cues(str(tmp_path / "c.tsv"))
