"""The wheel carries the licences of what it ships (issue 19, item 9).

The files the wheel would hold are listed by setuptools itself (``setup.py build_py`` on a
copy of the tracked sources: the package data rules of pyproject.toml, exactly as a wheel
build applies them, without compiling anything), and every folder of shipped data must be
either third-party -- with its licence and provenance beside it, as its licence asks -- or
our own, with the reason written here. A new data folder fails until it is classified.

Not shipped, so not checked here: tests/data (MFA and Gentle conformance files with their
LICENSE, the GRID clips and faces with their SOURCE.md); tests are not part of the wheel.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Third-party files the wheel ships: folder -> the files that must lie beside them.
THIRD_PARTY = {
    # MediaPipe's models, Apache 2.0: its text (LICENSE) and where the files came from.
    "lipsync/face/models": ("LICENSE", "SOURCE.md"),
    # Frames of the GRID corpus (CC BY 4.0): the attribution travels with the pictures.
    "lipsync/_visemes/grid-s1": ("SOURCE.md",),
}
#: Data folders that are ours (the project's MIT licence covers them), with the reason.
OWN = {
    "lipsync/morphing": "the package's own files (the C kernel's source)",
    "lipsync/_visemes": "visemes/README.md, written for this project",
    "lipsync/_visemes/toon": "drawn by tools/make_toon.py from code (visemes/README.md)",
    "lipsync/_configs/maps": "phoneme-to-viseme maps written for lipsync (sources cited in each file)",
    "lipsync/_configs/phonesets": "the phone set written for lipsync",
    "lipsync/editor/static": "the editor page: our own HTML, JS and CSS, no library vendored",
    "lipsync/server/static": "the live player page: our own HTML, JS and CSS, no library vendored",
    "lipsync/atlas/static": "the atlas player: our own HTML and JS, no library vendored",
    "lipsync/timing_editor/static": "the timing editor page: our own HTML, JS and CSS (the waveform on a plain canvas), no library vendored",
}


@pytest.fixture(scope="module")
def shipped(tmp_path_factory):
    """Paths (relative, '/'-separated) of every file a wheel built from this tree would install."""
    src = tmp_path_factory.mktemp("src")
    try:  # the tracked files: what a build from a clean checkout sees
        listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
        names = [n for n in listed.decode().split("\0") if n]
    except (OSError, subprocess.CalledProcessError):  # not a git checkout (an unpacked sdist)
        skip = {".lipsync", "__pycache__", "build", ".venv", ".git"}
        names = [p.relative_to(ROOT).as_posix() for p in ROOT.rglob("*")
                 if p.is_file() and not skip & set(p.relative_to(ROOT).parts) and p.suffix != ".so"]
    for name in names:
        if name.split("/")[0] in ("tests", "docs", "samples", "tools", ".ci") or not (ROOT / name).is_file():
            continue
        (src / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, src / name)
    out = tmp_path_factory.mktemp("build")
    run = subprocess.run([sys.executable, "setup.py", "-q", "build_py", "-d", str(out / "lib"),
                          "egg_info", "-e", str(out)], cwd=src, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-2000:]
    lib = out / "lib"
    return {p.relative_to(lib).as_posix() for p in lib.rglob("*") if p.is_file()}, out


def test_every_shipped_data_folder_is_classified_and_third_party_files_carry_their_licence(shipped):
    files, _ = shipped
    data = defaultdict(set)
    for f in files:
        if not f.endswith(".py"):
            data[os.path.dirname(f)].add(os.path.basename(f))
    assert "lipsync/face/models" in data and "lipsync/_visemes/grid-s1" in data  # the rules still ship them
    for folder, names in sorted(data.items()):
        assert folder in THIRD_PARTY or folder in OWN, (
            f"{folder} ships {sorted(names)[:5]}: third-party (add it to THIRD_PARTY with its LICENSE/SOURCE.md "
            f"beside it, and a package-data rule for them) or our own (OWN, with the reason)?")
        for required in THIRD_PARTY.get(folder, ()):
            assert required in names, f"{folder} ships third-party files without {required} beside them"
    # the models themselves and every GRID picture are there
    assert {"face_detection_short_range.tflite", "face_landmark.tflite"} <= data["lipsync/face/models"]
    assert {f"{v}.png" for v in "ABCDEFGHX"} <= data["lipsync/_visemes/grid-s1"]


def test_the_wheel_carries_the_project_licence_and_no_tests(shipped):
    files, out = shipped
    info = (out / "lipsync.egg-info" / "PKG-INFO").read_text()
    assert "License-File: LICENSE" in info  # setuptools puts it in the wheel's .dist-info
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")
    assert not [f for f in files if f.startswith("tests/") or "/tests/" in f]


def test_the_licences_named_are_the_licences_there():
    assert "Apache License" in (ROOT / "lipsync/face/models/LICENSE").read_text()
    assert "CC BY 4.0" in (ROOT / "visemes/grid-s1/SOURCE.md").read_text()
