"""Round four's papercuts (issue 31 part 4, issue 32 item 8), each against today's behaviour.

* ``--text`` given a file that is not a transcript (a label track, a TextGrid, JSON, audio)
  or a path that does not exist: exit 2 naming the file and what it looks like (the
  samples' Audacity label track used to be read as 539 "words").
* A transcript that does not fit the speech at all: exit 2 unless ``--allow-mismatch``.
* Rhubarb JSON's ``soundFile`` is the recording, not the timeline.
* ``--shapes basic``: Rhubarb's A-F and X, G shown as B and H as C (Rhubarb's getBasicShape).
* Shipped subjects by name; ``lipsync.write_video``; the MOV's pixel format in the docs.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from lipsync.cli import main

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "samples"


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


# --- --text that is not a transcript -------------------------------------------------------

@pytest.mark.parametrize("name, looks", [
    ("hello.txt", "Audacity label track"),     # the case: start, end, label lines
    ("hello.phn", "timed lines"),              # TIMIT: sample numbers before each label
    ("hello.TextGrid", "Praat TextGrid"),
    ("hello.json", "JSON"),
    ("hello.wav", "binary"),
])
def test_a_file_that_is_not_a_transcript_is_refused_naming_it(capsys, tmp_path, name, looks):
    out = tmp_path / "a.TextGrid"
    code, err = run(capsys, "align", SAMPLES / "hello.wav", "--text", SAMPLES / name, "-o", out)
    assert code == 2, err
    assert f"{SAMPLES / name}:" in err and looks in err
    assert not out.exists()


def test_render_with_a_label_track_as_text_stops_before_any_work(capsys, tmp_path):
    # the command: render hello.wav --text hello.txt read 539 "words" and exited 0
    out = tmp_path / "hello.mp4"
    code, err = run(capsys, "render", SAMPLES / "hello.wav", "--text", SAMPLES / "hello.txt", "-o", out)
    assert code == 2 and f"{SAMPLES / 'hello.txt'}: given as a transcript" in err
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_a_transcript_file_with_markup_or_nul_bytes_is_refused(tmp_path):
    from lipsync.errors import InputError
    from lipsync.speech.align import read_transcript

    for body, looks in [('<?xml version="1.0"?><rhubarbResult/>', "XML"), ("MohoSwitch1\n1 rest\n", "Moho"),
                        ("lipsync version 1\n", "Papagayo"), ("hello\0world", "binary"),
                        ("WEBVTT\n\n00:00.000 --> 00:01.000\nhello\n", "WebVTT")]:
        f = tmp_path / "t.txt"
        f.write_text(body)
        with pytest.raises(InputError, match=looks):
            read_transcript(str(f))
    # real transcripts still read: the samples' .lab and a line starting with a number
    assert read_transcript(str(SAMPLES / "hello.lab")).startswith("Hello")
    f.write_text("2 birds sang in 1999.\nThen they left.\n")
    assert read_transcript(str(f)) == "2 birds sang in 1999.\nThen they left.\n"


def test_a_missing_transcript_path_is_an_error_not_words(capsys, tmp_path):
    # issue 32 item 8: "media/missing.txt" was aligned as the words "media missing txt"
    os.chdir(tmp_path)
    code, err = run(capsys, "align", SAMPLES / "hello.wav", "--text", "media/missing.txt", "-o", "a.TextGrid")
    assert code == 2 and "media/missing.txt: no such transcript file" in err
    assert not (tmp_path / "a.TextGrid").exists()
    from lipsync.speech.align import read_transcript

    assert read_transcript("Hello there.") == "Hello there."   # words are still words
    assert read_transcript("and/or") == "and/or"


# --- a transcript that does not fit ---------------------------------------------------------

def test_a_transcript_that_does_not_fit_at_all_is_an_error_unless_allowed(capsys, tmp_path):
    # balloons' sentence over hello's speech: none of its words is there (confidence 0.00)
    out = tmp_path / "a.TextGrid"
    code, err = run(capsys, "align", SAMPLES / "hello.wav", "--text", SAMPLES / "balloons.lab", "-o", out)
    assert code == 2 and "does not fit" in err and "--allow-mismatch" in err, err
    assert not out.exists()
    code, err = run(capsys, "align", SAMPLES / "hello.wav", "--text", SAMPLES / "balloons.lab", "-o", out,
                    "--allow-mismatch")
    assert code == 0 and "confidence 0.00" in err and out.exists()
    # a partial transcript (all its words there, little of the speech covered) is no error
    code, err = run(capsys, "align", SAMPLES / "hello.wav", "--text", "Hello, I am", "-o", out, "-q")
    assert code == 0, err
    # the right transcript is no error
    code, err = run(capsys, "align", SAMPLES / "hello.wav", "--text", SAMPLES / "hello.lab", "-o", out, "-q")
    assert code == 0, err
    import warnings

    from lipsync.errors import TranscriptMismatch
    assert not [f for f in warnings.filters if f[2] is TranscriptMismatch]  # main() left no filter behind


# --- soundFile --------------------------------------------------------------------------------

def _sound_file(path):
    return json.loads(Path(path).read_text())["metadata"]["soundFile"]


def test_rhubarb_json_names_the_recording_not_the_timeline(capsys, tmp_path):
    out = tmp_path / "c.json"
    assert run(capsys, "cues", SAMPLES / "hello.phn", "-o", out, "--audio", SAMPLES / "hello.wav", "-q")[0] == 0
    assert _sound_file(out) == str(SAMPLES / "hello.wav")
    assert run(capsys, "cues", SAMPLES / "hello.phn", "-o", out, "-q")[0] == 0
    assert _sound_file(out) == ""                      # a timeline is not a sound file
    assert run(capsys, "cues", SAMPLES / "hello.wav", "--text", SAMPLES / "hello.lab", "-o", out, "-q")[0] == 0
    assert _sound_file(out) == str(SAMPLES / "hello.wav")
    code, err = run(capsys, "cues", SAMPLES / "hello.phn", "-o", tmp_path / "d.json", "--audio", tmp_path / "no.wav")
    assert code == 2 and "no.wav" in err and not (tmp_path / "d.json").exists()


# --- --shapes basic ---------------------------------------------------------------------------

def _cue_at(track, t):
    times = [float(line.split("\t")[0]) for line in track]
    labels = [line.split("\t")[1] for line in track]
    i = max(k for k, s in enumerate(times) if s <= t)
    return labels[i]


def test_cues_with_basic_shapes_use_rhubarbs_fallbacks(capsys, tmp_path):
    full, basic = tmp_path / "full.tsv", tmp_path / "basic.tsv"
    for src in ("hello.phn", "balloons.phn"):
        assert run(capsys, "cues", SAMPLES / src, "-o", full, "-q")[0] == 0
        assert run(capsys, "cues", SAMPLES / src, "-o", basic, "--shapes", "basic", "-q")[0] == 0
        a = full.read_text().splitlines()
        b = basic.read_text().splitlines()
        assert {line.split("\t")[1] for line in a} & {"G", "H"}, "the sample should use an extended shape"
        assert {line.split("\t")[1] for line in b} <= set("ABCDEFX")
        end = float(a[-1].split("\t")[0])
        fallback = {"G": "B", "H": "C"}   # Rhubarb's getBasicShape (animationRules.cpp)
        # Away from the full track's cue changes (the sequencer merges a G turned B with a B
        # beside it, which moves boundaries by up to a short segment), the shape is the fallback.
        bounds = np.array([float(line.split("\t")[0]) for line in a])
        checked = 0
        for t in np.arange(0.0, end, 0.005):
            if np.abs(bounds - t).min() >= 0.03:
                assert _cue_at(b, t) == fallback.get(_cue_at(a, t), _cue_at(a, t)), (src, t)
                checked += 1
        assert checked > 0.4 * end / 0.005   # most of the speech (hello 60 %, balloons 47 %)


def test_render_with_basic_shapes_shows_b_where_g_is_held(capsys, tmp_path):
    # A Rhubarb track holding G and H for 0.6 s each: the middle of each hold is the
    # viseme's own picture, exactly (alpha 0), so basic shapes show the toon's B and C there.
    tsv = tmp_path / "gh.tsv"
    tsv.write_text("0.00\tX\n0.20\tG\n0.80\tH\n1.40\tX\n1.80\tX\n")
    from lipsync import Bank

    toon = Bank.load("toon")
    for shapes, g_shows, h_shows in (("all", "G", "H"), ("basic", "B", "C")):
        out = tmp_path / shapes
        assert run(capsys, "render", tsv, "-o", f"{out}/", "--shapes", shapes, "-q")[0] == 0
        for t, viseme in ((0.5, g_shows), (1.1, h_shows)):
            frame = cv2.cvtColor(cv2.imread(str(out / f"frame_{round(t * 25):06d}.png")), cv2.COLOR_BGR2RGB)
            assert np.abs(frame.astype(int) - toon.images[viseme][..., :3].astype(int)).max() <= 1, (shapes, t)


def test_basic_shapes_need_rhubarbs_shape_set(capsys, tmp_path):
    code, err = run(capsys, "cues", SAMPLES / "hello.phn", "-o", tmp_path / "c.tsv", "--shapes", "basic",
                    "--map", "oculus")
    assert code == 2 and "english-to-oculus" in err


# --- shipped subjects by name --------------------------------------------------------------------

def test_shipped_subjects_load_by_name_from_any_folder(tmp_path, monkeypatch):
    from lipsync import Bank
    from lipsync.errors import BankError

    monkeypatch.chdir(tmp_path)                     # nothing called toon or grid-s1 here
    assert Bank.load("toon").shape == (512, 512)
    grid = Bank.load("grid-s1")
    assert grid.path.name == "grid-s1" and set("ABCDEFGHX") <= set(grid.names)
    with pytest.raises(BankError, match=r"nosuch: .*shipped: grid-s1, toon"):
        Bank.load("nosuch")
    (tmp_path / "toon").mkdir()                     # a folder of that name wins: it is what was meant
    with pytest.raises(BankError, match="no bank.yaml here"):
        Bank.load("toon")


def test_bank_names_on_the_command_line(capsys, tmp_path):
    assert run(capsys, "check", "grid-s1")[0] == 0
    code, err = run(capsys, "cues", SAMPLES / "hello.phn", "--bank", "grid-s1", "-o", tmp_path / "c.tsv", "-q")
    assert code == 0, err
    code, err = run(capsys, "check", "no-such-subject")
    assert code == 2 and "shipped: grid-s1, toon" in err


def test_atlas_defaults_to_the_toon(capsys, tmp_path):
    # `lipsync atlas -o A.png TIMELINE`: no bank given, the first positional is a timeline
    out = tmp_path / "mouth.png"
    code, err = run(capsys, "atlas", "-o", out, SAMPLES / "hello.phn", "-q", "--inbetweens", "1")
    assert code == 0, err
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta["bank"] == "toon", meta["bank"]
    code, err = run(capsys, "atlas", "toon", "-o", out, "--bank", "grid-s1")
    assert code == 2 and "two banks" in err


# --- write_video --------------------------------------------------------------------------------

def _decode(path):
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, f = cap.read()
        if not ok:
            return frames
        frames.append(cv2.cvtColor(f, cv2.COLOR_BGR2RGB))


def test_write_video_writes_the_frames_it_is_given(tmp_path):
    from lipsync import write_video

    colours = [(200, 40, 40), (40, 200, 40), (40, 40, 200)] * 4
    frames = [np.full((48, 64, 3), c, np.uint8) for c in colours]
    out = write_video(frames, tmp_path / "c.mp4", fps=12)
    got = _decode(out)
    assert len(got) == 12 and got[0].shape == (48, 64, 3)
    for f, c in zip(got, colours):
        assert np.abs(f.reshape(-1, 3).mean(axis=0) - c).max() < 6
    # RGBA to mp4: flattened onto white; fully transparent is white
    rgba = np.zeros((2, 32, 32, 4), np.uint8)
    rgba[1, ..., :3], rgba[1, ..., 3] = (0, 0, 255), 255
    got = _decode(write_video(iter(rgba), tmp_path / "a.mp4", fps=5))
    assert np.abs(got[0].astype(int) - 255).max() < 6 and np.abs(got[1].mean(axis=(0, 1)) - (0, 0, 255)).max() < 6
    with pytest.raises(ValueError, match="no frames"):
        write_video([], tmp_path / "e.mp4")
    assert not (tmp_path / "e.mp4").exists()


# --- the MOV's pixel format in the docs -------------------------------------------------------

def test_docs_name_the_mov_pixel_format_the_file_has(tmp_path):
    import subprocess

    from lipsync import write_video
    from lipsync.encode.ffmpeg import ffmpeg_exe

    frames = np.zeros((2, 16, 16, 4), np.uint8)
    out = write_video(list(frames), tmp_path / "a.mov", fps=10)
    info = subprocess.run([ffmpeg_exe(), "-hide_banner", "-i", out], capture_output=True, text=True).stderr
    fmt = re.search(r"prores \(4444\).*?, (yuva\w+)\(", info).group(1)
    assert fmt == "yuva444p12le"
    texts = [p.read_text(encoding="utf-8") for p in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]]
    texts.append((ROOT / "lipsync/encode/__init__.py").read_text())
    named = {m for t in texts for m in re.findall(r"yuva444p1\dle", t)}
    assert named == {fmt}, named


def test_toolchains_says_how_frame_numbers_meet_blenders():
    text = (ROOT / "docs" / "toolchains.md").read_text(encoding="utf-8")
    assert re.search(r"`frame_000000\.png` shows time 0 s.*?Blender frame NNNNNN \+ 1", text, re.S)


def test_a_batch_manifest_names_a_shipped_subject(tmp_path):
    from lipsync._data import shipped_banks
    from lipsync.batch.manifest import ManifestError, read_manifest

    (tmp_path / "a.tsv").write_text("0.00\tX\n0.40\tD\n0.80\tX\n")
    (tmp_path / "m.csv").write_text("input,output,bank\na.tsv,a.mp4,grid-s1\na.tsv,b.mp4,\n")
    jobs = read_manifest(tmp_path / "m.csv")
    assert jobs[0].bank == shipped_banks()["grid-s1"].resolve() and jobs[1].bank.name == "toon"
    (tmp_path / "n.csv").write_text("input,output,bank\na.tsv,a.mp4,no-such-subject\n")
    with pytest.raises(ManifestError, match="no-such-subject"):
        read_manifest(tmp_path / "n.csv")
