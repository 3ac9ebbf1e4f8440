"""Hostile and careless inputs, round five (issue 38): each test failed on round four's code.

Items: a job stuck in any stage is stopped at ``--job-timeout`` (2); transcripts have a size
limit (1); an output that is one of the inputs is refused (4); IPA timelines (12); and the
smaller ones (13).
"""

from __future__ import annotations

import time
from pathlib import Path

import httpx
import pytest

import lipsync.motion.sequencer as sequencer
from lipsync.server import LiveServer, ServeConfig, WS_MAX_MESSAGE
from lipsync.web import Session, start_in_thread

ROOT = Path(__file__).resolve().parents[1]
HELLO = ROOT / "samples" / "hello.phn"


# --- item 2: the job timeout stops a job in any stage ----------------------------------------

def _stuck_in_planning(real):
    def plan_segments(visemes, **kw):
        if visemes.duration > 10:   # the long upload: a planning step that never ends, never checks
            while True:
                pass
        return real(visemes, **kw)
    return plan_segments


def _timit(seconds: float, step: float = 0.2) -> bytes:
    rows, t, k = [], 0.0, 0
    while t < seconds:
        rows.append(f"{int(t * 16000)} {int(min(t + step, seconds) * 16000)} {('aa', 'm')[k % 2]}")
        t, k = t + step, k + 1
    return ("\n".join(rows) + "\n").encode()


def test_a_job_stuck_in_planning_is_stopped_at_its_timeout_and_the_next_one_runs(monkeypatch):
    monkeypatch.setattr(sequencer, "plan_segments", _stuck_in_planning(sequencer.plan_segments))
    session = Session.open("127.0.0.1", 0)
    server = LiveServer(ServeConfig(method="dissolve", job_timeout=5.0), session=session)
    handle = start_in_thread(server.app, session, ws_max_size=WS_MAX_MESSAGE)
    try:
        def submit(name, body):
            r = httpx.post(session.url("/api/render") + f"&name={name}", content=body)
            assert r.status_code == 202, r.text
            return r.json()["job"]

        def wait(job, timeout):
            deadline = time.monotonic() + timeout
            while True:
                s = httpx.get(session.url(f"/api/jobs/{job}")).json()
                if s["state"] in ("done", "error"):
                    return s, time.monotonic()
                assert time.monotonic() < deadline, f"job still {s['state']} after {timeout} s"
                time.sleep(0.05)

        t0 = time.monotonic()
        stuck = submit("long.phn", _timit(20))
        small = submit("hello.phn", HELLO.read_bytes())
        state, t_stopped = wait(stuck, 30)
        assert state["state"] == "error" and "stopped after 5 s (--job-timeout)" in state["error"]
        assert state["frames"] == 0                   # it never got past planning
        assert 5.0 <= t_stopped - t0 < 15.0
        done, _ = wait(small, 60)
        assert done["state"] == "done" and done["frames"] == 75
        assert not list(server.tmp.glob(f"{stuck}/*out*"))   # nothing of the stopped job left
    finally:
        handle.stop()
        server.close()
        session.close()


# --- item 4: an output that is one of the inputs is refused, in every command that writes ---

import hashlib
import os
import shutil
import subprocess

import imageio_ffmpeg

from lipsync.cli import main as cli_main

TOON = ROOT / "visemes" / "toon"


def _digest(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _run(argv, capsys):
    code = cli_main([str(a) for a in argv])
    return code, capsys.readouterr().err


def _linked(tmp_path, src, how):
    """``src`` and the name the output is given: the same name, a hard link or a symbolic link to it."""
    if how == "same":
        return src
    link = tmp_path / f"link-{how}{src.suffix}"
    (os.link if how == "hard" else os.symlink)(src, link)
    return link


@pytest.fixture
def audio_mp4(tmp_path):
    out = tmp_path / "speech.mp4"
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-i", str(ROOT / "samples" / "hello.wav"),
                    "-c:a", "aac", str(out)], check=True)
    return out


@pytest.mark.parametrize("how", ["same", "hard", "symlink"])
def test_render_output_over_its_audio_is_refused(tmp_path, audio_mp4, how, capsys):
    before = _digest(audio_mp4)
    out = _linked(tmp_path, audio_mp4, how)
    code, err = _run(["render", ROOT / "samples" / "hello.phn", "--audio", audio_mp4, "-o", out,
                      "--method", "dissolve", "-q"], capsys)
    assert code == 2 and "is the input" in err and str(audio_mp4) in err
    assert _digest(audio_mp4) == before


def test_render_audio_input_as_its_own_output_is_refused(audio_mp4, capsys):
    before = _digest(audio_mp4)
    code, err = _run(["render", audio_mp4, "-o", audio_mp4, "-q"], capsys)
    assert code == 2 and "is the input" in err and _digest(audio_mp4) == before


@pytest.mark.parametrize("how", ["same", "symlink"])
def test_dub_output_over_its_video_is_refused(tmp_path, audio_mp4, how, capsys):
    video = tmp_path / "same.mp4"
    shutil.copy(audio_mp4, video)   # refused before it is opened: any file shows the rule
    before = _digest(video)
    code, err = _run(["dub", video, "--audio", ROOT / "samples" / "hello.wav", "-o", _linked(tmp_path, video, how)],
                     capsys)
    assert code == 2 and "is the input" in err and _digest(video) == before


def test_dub_api_refuses_too(tmp_path, audio_mp4):
    import lipsync
    from lipsync.errors import InputError

    with pytest.raises(InputError, match="is the input"):
        lipsync.dub(audio_mp4, ROOT / "samples" / "hello.wav", audio_mp4)


def test_cues_output_over_its_timeline_is_refused(tmp_path, capsys):
    src = tmp_path / "cues.json"
    shutil.copy(ROOT / "samples" / "hello.json", src)
    before = _digest(src)
    for how in ("same", "hard"):
        code, err = _run(["cues", src, "--format", "rhubarb-json", "-o", _linked(tmp_path, src, how)], capsys)
        assert code == 2 and "is the input" in err and _digest(src) == before


def test_align_output_over_its_transcript_is_refused(tmp_path, capsys):
    script = tmp_path / "script.TextGrid"
    script.write_text("hello world\n")
    code, err = _run(["align", ROOT / "samples" / "hello.wav", "--text", script, "-o", script, "-q"], capsys)
    assert code == 2 and "is the input" in err and script.read_text() == "hello world\n"


def test_atlas_json_beside_the_output_over_its_timeline_is_refused(tmp_path, capsys):
    src = tmp_path / "atlas.json"
    shutil.copy(ROOT / "samples" / "hello.json", src)
    before = _digest(src)
    code, err = _run(["atlas", "--bank", "toon", src, "-o", tmp_path / "atlas.png"], capsys)
    assert code == 2 and "is the input" in err and _digest(src) == before


@pytest.mark.parametrize("command", [["morph", "BANK", "A", "D", "--alpha", "0.5"], ["preview", "BANK"],
                                     ["atlas", "BANK"]])
def test_an_output_over_a_bank_picture_is_refused(tmp_path, command, capsys):
    bank = tmp_path / "bank"
    shutil.copytree(TOON, bank)
    before = _digest(bank / "A.png")
    argv = [bank if a == "BANK" else a for a in command]
    code, err = _run(argv + ["-o", bank / "A.png"], capsys)
    assert code == 2 and "is a file of the bank" in err and _digest(bank / "A.png") == before


def test_batch_row_whose_output_is_its_input_is_refused(tmp_path, audio_mp4, capsys):
    outdir = tmp_path / "out"
    outdir.mkdir()
    shutil.copy(audio_mp4, outdir / "speech.mp4")
    before = _digest(outdir / "speech.mp4")
    manifest = tmp_path / "clips.csv"
    manifest.write_text(f"input,output\n{outdir / 'speech.mp4'},speech.mp4\n")
    code, err = _run(["batch", manifest, "-o", outdir], capsys)
    assert code == 2 and "is the input" in err and "clips.csv:2:" in err
    assert _digest(outdir / "speech.mp4") == before


# --- item 1: transcripts have a size limit; warnings never echo a huge word ------------------

import warnings

from lipsync.speech.text import MAX_TRANSCRIPT_CHARS, shown_words


def test_a_transcript_file_over_the_limit_is_refused_with_exit_2(tmp_path, capsys):
    big = tmp_path / "script.txt"
    big.write_text(("hello world " * (MAX_TRANSCRIPT_CHARS // 12 + 2)))
    assert len(big.read_text()) > MAX_TRANSCRIPT_CHARS
    code, err = _run(["align", ROOT / "samples" / "hello.wav", "--text", big, "-o", tmp_path / "o.TextGrid", "-q"],
                     capsys)
    assert code == 2 and "script.txt: transcript is over 100,000 characters" in err
    assert not (tmp_path / "o.TextGrid").exists()


def test_a_literal_transcript_over_the_limit_is_refused_by_the_api_too():
    import numpy as np
    from lipsync.errors import InputError
    from lipsync.speech.align import align_samples

    with pytest.raises(InputError, match="over 100,000 characters"):
        align_samples(np.zeros(1600, np.int16), "a" * (MAX_TRANSCRIPT_CHARS + 1))


def test_a_huge_unknown_word_is_cut_in_the_warning():
    import numpy as np
    from lipsync.speech.align import align_samples

    word = "zq" * 20_000                      # 40,000 characters: one "word" of letters
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        align_samples(np.zeros(1600, np.int16), f"hello {word}")
    texts = [str(w.message) for w in caught if "dictionary" in str(w.message)]
    assert texts and all(len(t) < 400 for t in texts), [len(t) for t in texts]
    assert "zqzq" in texts[0] and "\u2026" in texts[0]


def test_shown_words_cuts_and_counts():
    assert shown_words(["x" * 100] + ["y"] * 10, limit=2, width=10) == "x" * 9 + "\u2026, y and 9 more"


# --- item 13: --text naming a device, mixed scripts, emoji-only --------------------------------

@pytest.mark.parametrize("device", ["/dev/zero", "/dev/null", "/dev/stdin"])
def test_text_naming_a_device_is_exit_2(tmp_path, device, capsys):
    code, err = _run(["align", ROOT / "samples" / "hello.wav", "--text", device, "-o", tmp_path / "o.TextGrid",
                      "-q"], capsys)
    assert code == 2 and f"{device}: is a device, pipe or stream, not a file" in err
    from lipsync.errors import InputError
    from lipsync.speech.align import read_transcript

    with pytest.raises(InputError, match="is not a regular file"):   # the API's reading of --text too
        read_transcript(device)


def test_mixed_scripts_are_named_each():
    from lipsync.speech.scripts import UnreadWordsWarning, check_english_script

    with pytest.warns(UnreadWordsWarning) as record:
        check_english_script("hello 你好 world مرحبا", ["hello", "world"])
    message = str(record[0].message)
    assert "Chinese (Han) and Arabic letters" in message and "Cyrillic" not in message
    assert "--lang zh or --lang ar" in message


def test_an_emoji_only_transcript_is_exit_2(tmp_path, capsys):
    script = tmp_path / "emoji.txt"
    script.write_text("\U0001F600 \U0001F44D \U0001F389\n")
    code, err = _run(["align", ROOT / "samples" / "hello.wav", "--text", script, "-o", tmp_path / "o.TextGrid",
                      "-q"], capsys)
    assert code == 2 and "the transcript has no words to say" in err


# --- item 12: IPA timelines: a mark never turns an IPA letter into ARPAbet ---------------------

from lipsync.phonetics import detect
from lipsync.phonetics.features import FEATURES
from lipsync.phonetics.phonemes import load_map
from lipsync.phonetics.segments import parse
from lipsync.phonetics.visemes import label_visemes

MARKS = ["", "ː", "ˑ", "\u0303", "\u0325", "\u0329", "\u032f", "\u0308", "ʲ", "ʷ", "ʰ", "ːʲ"]


@pytest.mark.parametrize("map_name", ["rhubarb", "english-to-oculus"])
def test_every_ipa_letter_with_and_without_marks_follows_the_rules(map_name):
    pmap = load_map(map_name)
    rules = pmap._compiled_rules
    aliases = pmap._phoneset.aliases if pmap._phoneset is not None else {}
    checked, wrong = 0, []
    for letter in FEATURES:
        bare = pmap.targets(letter, notation="ipa")
        # the English phone set reads a few IPA letters its own way (MFA English's ɜ is NURSE,
        # ER): then the marked letter must read as the bare one does
        english_reading = bare != label_visemes(letter, rules)
        for mark in MARKS:
            label = letter + mark
            if parse(label) is None or (mark and label in aliases):
                continue
            want = bare if english_reading else label_visemes(label, rules)
            got = pmap.targets(label, notation="ipa")
            checked += 1
            if got != want:
                wrong.append((label, got, want))
    assert checked > 1000 and wrong == []


@pytest.mark.parametrize("label,visemes", [("y", ["F"]), ("yː", ["F"]), ("yˑ", ["F"]), ("ỹː", ["F"]),
                                           ("ɑːɹ", ["D", "E"]), ("ʲ", ["B"]), ("ʷ", ["F"])])
def test_the_issues_labels(label, visemes):
    pmap = load_map("rhubarb")
    assert detect(["sil", label, "a"]) == "ipa"
    assert pmap.targets(label, notation=detect(["sil", label, "a"])) == visemes
    assert pmap.targets(label, notation="ipa") != [pmap.fallback] or visemes == [pmap.fallback]


def test_a_german_textgrid_with_long_y_shows_rounded_lips(tmp_path):
    # MFA's German "über": y: is the rounded vowel (F), not ARPAbet Y (B) for its whole length
    from lipsync.phonetics.phonemes import map_timeline
    from lipsync.motion.timeline import Segment, Timeline

    tl = Timeline((Segment(0, 0.1, "ʔ"), Segment(0.1, 0.3, "yː"), Segment(0.3, 0.4, "b"), Segment(0.4, 0.5, "ɐ")),
                  kind="phoneme")
    out = map_timeline(tl, load_map("rhubarb"), rest="X")
    assert [s.label for s in out if 0.1 <= s.start < 0.3] == ["F"]


# --- item 13: an output folder that cannot take the file is exit 2 naming it -----------------

LONG_NAME = "n" * 250 + ".mp4"


@pytest.mark.parametrize("argv", [["render", ROOT / "samples" / "hello.phn", "-q"],
                                  ["dub", ROOT / "samples" / "hello.wav", "--audio", ROOT / "samples" / "hello.wav"],
                                  ["blender-addon"]])
def test_an_output_name_too_long_is_exit_2_naming_it(tmp_path, argv, capsys):
    out = tmp_path / (LONG_NAME if argv[0] != "blender-addon" else LONG_NAME.replace(".mp4", ".zip"))
    code, err = _run(argv + ["-o", out], capsys)
    assert code == 2 and "the file name is too long" in err and "nnnn" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv", [["render", ROOT / "samples" / "hello.phn", "-q"],
                                  ["dub", ROOT / "samples" / "hello.wav", "--audio", ROOT / "samples" / "hello.wav"],
                                  ["blender-addon"]])
def test_a_read_only_output_folder_is_exit_2_naming_it(tmp_path, argv, capsys, monkeypatch):
    # as tests/test_cli_failures.py does: creating a file there fails as a read-only folder
    # makes it (root may write into a mode-555 folder, so chmod shows nothing here)
    folder = tmp_path / "ro"
    folder.mkdir()
    real_open = os.open

    def refusing_open(path, flags, *args, **kwargs):
        if os.path.dirname(os.fspath(path)) == str(folder) and flags & os.O_CREAT:
            raise OSError(30, "Read-only file system", os.fspath(path))
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", refusing_open)
    out = folder / ("out.zip" if argv[0] == "blender-addon" else "out.mp4")
    code, err = _run(argv + ["-o", out], capsys)
    monkeypatch.undo()
    assert code == 2 and "cannot write here" in err and f"{folder} is not writable" in err
    assert list(folder.iterdir()) == []


@pytest.mark.parametrize("argv", [["render", ROOT / "samples" / "hello.phn", "--audio", "/dev/stdin"],
                                  ["dub", ROOT / "samples" / "hello.wav", "--audio", "/dev/stdin"],
                                  ["align", "/dev/stdin"]])
def test_dev_stdin_as_an_input_is_exit_2(tmp_path, argv, capsys, monkeypatch):
    code, err = _run(argv + ["-o", tmp_path / "out.mp4"], capsys)
    assert code == 2 and "/dev/stdin: is a device, pipe or stream, not a file" in err


# --- item 13: an unknown --lang names the closest few; `lipsync languages` lists all ----------

def test_unknown_language_names_the_closest_codes_and_lipsync_languages_lists_all(tmp_path, capsys):
    from lipsync.phonetics.g2p import espeak_available, languages

    if not espeak_available():
        pytest.skip("the espeak-ng extra is not installed")
    with pytest.raises(SystemExit) as exit_:
        cli_main(["align", str(ROOT / "samples" / "hello.wav"), "--lang", "german", "-o", str(tmp_path / "x.TextGrid")])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "did you mean de (German)" in err and "`lipsync languages`" in err
    assert len(err) < 600 and "zh" not in err.split("did you mean")[1]
    assert cli_main(["languages"]) == 0
    listed = [line.split("\t") for line in capsys.readouterr().out.splitlines()]
    assert dict(listed) == languages() and len(listed) > 100


# --- item 13: a transcript that does not fit stops without saying it went on --------------------

def test_a_mismatched_transcript_says_it_stopped_not_that_it_went_on(tmp_path, capsys):
    from lipsync.phonetics.g2p import espeak_available

    if not espeak_available():
        pytest.skip("the espeak-ng extra is not installed")
    code, err = _run(["align", ROOT / "samples" / "hello.wav", "--text", "こんにちは、元気ですか", "--lang", "es",
                      "-o", tmp_path / "x.TextGrid", "-q"], capsys)
    assert code == 2 and "does not fit the audio" in err
    assert "were used instead" not in err and "were left out" not in err
    assert "stopped, nothing written" in err and "--allow-mismatch goes on" in err
    assert not (tmp_path / "x.TextGrid").exists()


# --- item 13: no text names a folder only this workspace has ------------------------------------

def test_no_source_or_data_readme_names_an_absolute_workspace_folder():
    files = [*(ROOT / "lipsync").rglob("*.py"), *(ROOT / "tests" / "data").rglob("README*"), *(ROOT / "docs").glob("*.md"),
             ROOT / "README.md"]
    named = [str(f.relative_to(ROOT)) for f in files if "/work/" in f.read_text(encoding="utf-8", errors="replace")]
    assert named == []
