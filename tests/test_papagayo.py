"""Papagayo-NG projects (.pgo): the real sample project, voices, phoneme sets, bad files.

The golden and error cases of the reader are in tests/data/timelines (papagayo_*.pgo,
error_pgo_*.pgo); here the real file of Papagayo-NG's repository is checked against an
independent reading written in the test: Papagayo's own rule for what the mouth shows at a
frame (``LipsyncVoice::GetPhonemeAtFrame``), applied frame by frame.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from lipsync.cli import main
from lipsync.errors import TimelineError
from lipsync.readers import read_timeline

DATA = Path(__file__).parent / "data"
EXAMPLE = DATA / "conformance" / "papagayo" / "example1.pgo"


def _papagayo_by_hand(path: Path):
    """fps, frame count and, per voice, GetPhonemeAtFrame for every frame (None for rest)."""
    lines = [ln.strip() for ln in path.read_text(encoding="utf-8").splitlines()]
    assert lines[0] == "lipsync version 1"
    fps, length, n_voices = int(lines[2]), int(lines[3]), int(lines[4])
    i = 5
    voices = []
    for _ in range(n_voices):
        name, n_phrases = lines[i], int(lines[i + 2])
        i += 3
        phrases = []
        for _ in range(n_phrases):
            p0, p1, n_words = int(lines[i + 1]), int(lines[i + 2]), int(lines[i + 3])
            i += 4
            words = []
            for _ in range(n_words):
                _, w0, w1, n_ph = lines[i].split()
                i += 1
                phonemes = [(int(lines[i + k].split()[0]), lines[i + k].split()[1]) for k in range(int(n_ph))]
                i += int(n_ph)
                words.append((int(w0), int(w1), phonemes))
            phrases.append((p0, p1, words))

        def at(frame, phrases=phrases):
            for p0, p1, words in phrases:
                if p0 <= frame <= p1:
                    for w0, w1, phonemes in words:
                        if w0 <= frame <= w1:
                            for f, label in reversed(phonemes):
                                if frame >= f:
                                    return label
            return None

        voices.append((name, [at(f) for f in range(length)]))
    return fps, length, voices


def _label_at(tl, t):
    for s in tl:
        if s.start <= t < s.end:
            return s.label
    return None


def test_real_project_matches_papagayos_own_rule_frame_by_frame():
    fps, length, voices = _papagayo_by_hand(EXAMPLE)
    tl = read_timeline(EXAMPLE)
    assert (fps, length, len(voices)) == (24, 71, 1)
    assert tl.kind == "viseme" and tl.duration == pytest.approx(71 / 24)
    by_frame = voices[0][1]
    got = [_label_at(tl, (f + 0.5) / fps) for f in range(length)]
    assert got == by_frame
    # and every boundary sits on a frame edge
    for s in tl:
        assert s.start * fps == pytest.approx(round(s.start * fps)) and s.end * fps == pytest.approx(round(s.end * fps))


def test_real_project_facts_read_off_the_file():
    tl = read_timeline(EXAMPLE)
    assert len(tl) == 26  # 4 + 3 + 6 + 4 + 3 + 6 phonemes in the six words
    # "Short" starts at frame 1 with etc; frame 0 and frame 8 (between "Short" and "term") are rest
    assert (tl[0].start, tl[0].label) == (pytest.approx(1 / 24), "etc")
    assert _label_at(tl, 0.5 / 24) is None and _label_at(tl, 8.5 / 24) is None
    # "bills 34 43": MBP at 34 until AI at 37; the last phoneme E (frame 67) lasts to the word's end 69
    mbp = [s for s in tl if s.label == "MBP"]
    assert [(round(s.start * 24), round(s.end * 24)) for s in mbp] == [(16, 19), (34, 37)]
    assert (round(tl[-1].start * 24), round(tl[-1].end * 24), tl[-1].label) == (67, 70, "E")
    assert set(tl.labels()) == {"etc", "O", "E", "MBP", "AI", "L", "FV"}


def test_real_project_maps_to_the_toons_shapes_and_renders_morphs():
    from lipsync import Animator, Bank
    from lipsync._data import default_bank_dir

    bank = Bank.load(default_bank_dir())
    anim = Animator(bank, EXAMPLE, fps=24)
    # Preston Blair names through the map's aliases, as Moho files are read
    shapes = {s.label for s in anim.visemes}
    assert shapes == {"B", "E", "C", "A", "D", "H", "G"}
    assert [s.label for s in anim.visemes if abs(s.start - 16 / 24) < 1e-9] == ["A"]  # MBP -> A
    assert len(anim) == 71
    morphs = [f for f in anim.specs if not f.is_still]
    assert len(morphs) >= 20, "the breakdown should render with in-between frames"
    # the closure (MBP, frames 16-18) is shown exactly on one of its frames, as the sequencer
    # promises closures; the frames around it are morphs into and out of it
    exact = [n for n in range(16, 19) if anim.specs[n].shown == "A"]
    assert exact and np.array_equal(anim.frame(exact[0]), anim.renderer.render("A", "A", 0.0))
    assert anim.specs[16].to_viseme == "A" and 0 < anim.specs[16].alpha < 1


def test_first_voice_by_default_with_a_warning_and_tier_picks_another():
    src = DATA / "timelines" / "papagayo_two_voices.pgo"
    with pytest.warns(UserWarning, match=r"2 voices \('Alice', 'Bob'\); reading the first, 'Alice'"):
        alice = read_timeline(src)
    assert alice.labels() == ["etc", "AI"]
    assert [(round(s.start * 24), round(s.end * 24)) for s in alice] == [(2, 5), (5, 9)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        bob = read_timeline(src, tier="Bob")
    assert bob.labels() == ["L", "O", "WQ", "E", "E"]
    with pytest.raises(TimelineError, match=r"no voice named 'Carol'; voices: 'Alice', 'Bob'"):
        read_timeline(src, tier="Carol")


def test_cmu39_set_reads_as_phonemes_and_rest_is_silence(tmp_path):
    p = tmp_path / "cmu.pgo"
    p.write_text("lipsync version 1\ns.wav\n10\n10\n1\n\tV\n\tt\n\t1\n\t\tt\n\t\t0\n\t\t9\n\t\t1\n"
                 "\t\t\thello 1 8 5\n\t\t\t\t1 HH\n\t\t\t\t2 AH\n\t\t\t\t4 L\n\t\t\t\t5 rest\n\t\t\t\t7 OW\n")
    tl = read_timeline(p)
    assert tl.kind == "phoneme"
    assert [(s.label, round(s.start * 10), round(s.end * 10)) for s in tl] == [
        ("HH", 1, 2), ("AH", 2, 4), ("L", 4, 5), ("OW", 7, 9)]


def test_latin1_project_of_the_original_papagayo_is_read(tmp_path):
    p = tmp_path / "espanol.pgo"
    text = ("lipsync version 1\nespanol.wav\n24\n24\n1\n\tVoice 1\n\tsí Español\n\t1\n\t\tsí Español\n\t\t0\n"
            "\t\t20\n\t\t1\n\t\t\tEspañol 2 12 2\n\t\t\t\t2 E\n\t\t\t\t6 MBP\n")
    p.write_bytes(text.encode("latin-1"))
    tl = read_timeline(p)
    assert tl.labels() == ["E", "MBP"] and tl[1].end == pytest.approx(13 / 24)


@pytest.mark.parametrize("bad, line, message", [
    ("1e308", 3, "frame rate 1e308 is outside 1..1000"),
    ("0", 3, "frame rate 0 is outside"),
    ("nan", 3, "frame rate 'nan' is not a number"),
])
def test_cli_refuses_bad_numbers_naming_file_and_line(tmp_path, capsys, bad, line, message):
    good = (DATA / "timelines" / "papagayo_fleming_dobbs.pgo").read_text().split("\n")
    p = tmp_path / "bad.pgo"
    p.write_text("\n".join(good[:2] + [bad] + good[3:]))
    out = tmp_path / "cues.tsv"
    assert main(["cues", str(p), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{p}:{line}: " in err and message in err
    assert not out.exists()


def test_cues_of_the_real_project(tmp_path):
    out = tmp_path / "cues.tsv"
    assert main(["cues", str(EXAMPLE), "-o", str(out), "--quiet"]) == 0
    rows = [ln.split("\t") for ln in out.read_text().splitlines()]
    # starts at rest, MBP (A) at frame 16 of 24 fps, ends at rest at the sound's end
    assert rows[0] == ["0.000", "X"] and ["0.667", "A"] in rows and rows[-1] == [f"{71 / 24:.3f}", "X"]
