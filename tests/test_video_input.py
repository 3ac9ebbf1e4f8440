"""A video's sound as the speech: ``lipsync render clip.mp4 --text ...`` (GRID clips, CC BY 4.0)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lipsync.readers import read_timeline
from lipsync.readers.audio import is_audio_input

GRID = Path(__file__).parent / "data" / "grid-s1"


def test_video_containers_are_read_for_their_speech():
    for name in ("clip.mp4", "clip.MOV", "clip.mkv", "clip.avi", "clip.mpg"):
        assert is_audio_input(name)
    # by content too: an MPEG program stream (GRID's .mpg) renamed without an extension
    assert is_audio_input(GRID / "prap6p.mpg")
    tl = read_timeline(GRID / "prap6p.mpg", text="place red at p six please")
    words = [ln.split() for ln in (GRID / "prap6p.align").read_text().splitlines()]
    start = next(int(w[0]) for w in words if w[2] not in ("sil", "sp")) / 25000
    assert tl[0].label == "P" and abs(tl[0].start - start) < 0.05  # GRID's own time for "place"


def test_render_a_video_clip_with_its_transcript(tmp_path):
    from lipsync.encode import probe

    out = tmp_path / "out.mp4"
    r = subprocess.run([sys.executable, "-m", "lipsync", "render", str(GRID / "prap6p.mpg"), "--text",
                        "place red at p six please", "-o", str(out), "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    info = probe(out)
    assert info["streams"] == [("video", "h264"), ("audio", "aac")]
    assert info["audio_duration"] == pytest.approx(3.0, abs=0.05) and info["n_frames"] == 75
