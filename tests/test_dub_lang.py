"""Translation dubbing and its papercuts (issue 36 item 1, issue 38 items 5 and 6): an English
GRID video (tests/data/grid-s1, CC BY 4.0) dubbed with real Spanish speech (Multilingual
LibriSpeech, tests/data/languages, CC BY 4.0); a bank made from a video whose speech is
French (FLEURS); the exit-2 cases, each checked for its exit code and the file it names.
Measured on decoded frames with the face mesh, against the real speaker's own lips."""

from __future__ import annotations

import json
import subprocess
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from lipsync.cli import main

DATA = Path(__file__).parent / "data"
GRID = DATA / "grid-s1"
VIDEO = GRID / "bbwm5s.mpg"
SPANISH = DATA / "languages" / "mls-es-13697_11991_000000.opus"
FRENCH = DATA / "languages" / "fleurs-fr-004.ogg"


def _ffmpeg(*args):
    import imageio_ffmpeg

    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-y", *map(str, args)], check=True)


def _exit(argv, capsys):
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


def _openings(video):
    from lipsync.face import measure as M
    from lipsync.face.track import track_video

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tr = track_video(video)
    o = M.lip_opening(tr.points)
    o[~tr.found] = np.nan
    return o


def _middles(opening, phones, labels, fps=25.0):
    """The opening at the middle frame of each phone labelled one of ``labels``."""
    return np.array([opening[min(len(opening) - 1, int(round((s.start + s.end) / 2 * fps)))]
                     for s in phones if s.label.rstrip("012") in labels])


def _minima(opening, phones, labels, fps=25.0, pad=0.06):
    """The smallest opening within ``pad`` of each phone labelled one of ``labels``."""
    out = []
    for s in phones:
        if s.label.rstrip("012") in labels:
            a, b = max(0, int(np.floor((s.start - pad) * fps))), int(np.ceil((s.end + pad) * fps)) + 1
            out.append(float(np.nanmin(opening[a:b])))
    return np.array(out)


@pytest.fixture(scope="module")
def spanish_dub(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("es")
    out = tmp / "es.mp4"
    code = main(["dub", str(VIDEO), "--audio", str(SPANISH), "--text", str(SPANISH.with_suffix(".txt")),
                 "--lang", "es", "-o", str(out), "--cache", str(tmp / "cache"), "-q"])
    return code, out, tmp / "cache"


def test_an_english_video_dubbed_in_spanish_closes_the_mouth_at_spanish_p_b_m(spanish_dub):
    from lipsync.speech.align import align

    code, out, cache = spanish_dub
    assert code == 0 and out.is_file()
    # the bank was made from the video's own speech in English (the key of no --video-lang),
    # never with the new speech's language
    from lipsync.phonetics.phonemes import DEFAULT_MAP
    from lipsync.pipeline.dubbing import bank_key

    banks = [p.name for p in cache.glob("*/bank-*")]
    assert banks == [f"bank-{bank_key(DEFAULT_MAP)}"] and bank_key(DEFAULT_MAP, lang="es") not in banks[0], banks
    report = json.loads(next(cache.glob("*/bank-*/init-report.json")).read_text())
    assert report["videos"][0]["lang"] == "en" and report["videos"][0]["shapes_from"] == "words"
    # "closed": as closed as the real speaker's lips at his own P, B, M in this video
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        own = align(VIDEO, "bin blue with m five soon").phones
        spanish = align(SPANISH, SPANISH.with_suffix(".txt").read_text(encoding="utf-8"), lang="es").phones
    real = _minima(_openings(VIDEO), own, ("P", "B", "M"))
    closed_below = float(real.max())
    dubbed = _openings(out)
    closures = _minima(dubbed, spanish, ("p", "b", "m"))
    vowels = _middles(dubbed, spanish, ("a", "e", "o"))
    assert len(real) == 3 and len(closures) == 13
    assert np.mean(closures <= closed_below) >= 0.7, (closures, closed_below)
    # and the measure tells: in the middle of open vowels the mouth is mostly not "closed"
    assert np.mean(vowels <= closed_below) < 0.5 * np.mean(closures <= closed_below), (vowels, closed_below)


def test_a_transcript_that_does_not_fit_exits_2_unless_allow_mismatch(spanish_dub, capsys):
    _, _, cache = spanish_dub
    out = cache.parent / "mismatch.mp4"
    wrong = "the quick brown fox jumps over the lazy dog"
    code, err = _exit(["dub", VIDEO, "--audio", GRID / "prap6p.mpg", "--text", wrong, "-o", out,
                       "--cache", cache, "-q"], capsys)
    assert code == 2 and f"{GRID / 'prap6p.mpg'}: the transcript does not fit" in err and "--allow-mismatch" in err
    assert not out.exists() and "Traceback" not in err
    from lipsync.speech.align import TranscriptMismatchWarning

    with pytest.warns(TranscriptMismatchWarning, match="prap6p.mpg: the transcript does not fit"):  # said, and gone on
        code, err = _exit(["dub", VIDEO, "--audio", GRID / "prap6p.mpg", "--text", wrong, "--allow-mismatch",
                           "-o", out, "--cache", cache, "-q"], capsys)
    assert code == 0 and out.is_file()


def test_silent_speech_exits_2_naming_it(tmp_path, capsys):
    silent = tmp_path / "silent.wav"
    _ffmpeg("-f", "lavfi", "-i", "anullsrc=r=16000:cl=mono", "-t", "2", silent)
    code, err = _exit(["dub", VIDEO, "--audio", silent, "-o", tmp_path / "o.mp4", "--cache", tmp_path / "c", "-q"],
                      capsys)
    assert code == 2 and f"{silent}: is silent" in err and "Traceback" not in err
    assert not (tmp_path / "o.mp4").exists() and not (tmp_path / "c").exists()  # refused before any work


def test_a_sideways_video_is_turned_upright_as_init_does(spanish_dub, tmp_path, capsys):
    _, _, cache = spanish_dub
    bank = next(cache.glob("*/bank-*"))
    sideways = tmp_path / "sideways.mp4"
    _ffmpeg("-i", VIDEO, "-vf", "transpose=1", "-c:v", "libx264", "-crf", "14", "-preset", "ultrafast",
            "-c:a", "aac", sideways)  # pixels turned a quarter clockwise, no rotation tag
    out = tmp_path / "o.mp4"
    with pytest.warns(UserWarning, match="turned 90 degrees clockwise"):
        code, err = _exit(["dub", sideways, "--audio", GRID / "prap6p.mpg", "--bank", bank, "-o", out,
                           "--cache", tmp_path / "c", "-q"], capsys)
    from lipsync.face.video import probe_video

    assert code == 0 and probe_video(out).size == (360, 288)  # upright again
    assert np.isfinite(_openings(out)).mean() > 0.95  # the face is found in the dub's frames


def test_video_lang_reaches_the_bank_and_its_key():
    from lipsync.pipeline.dubbing import bank_key

    from lipsync.phonetics.phonemes import DEFAULT_MAP

    assert bank_key(lang="fr") != bank_key() == bank_key(lang="en-US") == bank_key(DEFAULT_MAP)
    assert bank_key(text="a", lang="fr") != bank_key(text="b", lang="fr")


@pytest.fixture(scope="module")
def french_video(tmp_path_factory):
    """The GRID speaker's face (looped) with real French speech as its sound, no transcript; a
    second of silence before and after it (a pause for the rest shape, as a recording has)."""
    out = tmp_path_factory.mktemp("fr") / "parle.mp4"
    _ffmpeg("-stream_loop", "3", "-i", VIDEO, "-i", FRENCH, "-filter_complex",
            "[1:a]adelay=1000:all=1,apad=pad_dur=1[a]", "-map", "0:v", "-map", "[a]", "-t", "10.3",
            "-c:v", "libx264", "-crf", "14", "-preset", "ultrafast", "-c:a", "aac", out)
    return out


def test_init_from_a_french_video_without_a_transcript_is_made_from_its_phones(french_video, tmp_path, capsys):
    out = tmp_path / "b"
    code, err = _exit(["init", out, "--video", french_video, "--lang", "fr", "--quiet"], capsys)
    assert code == 0, err
    assert "no speech" not in err
    report = json.loads((out / "init-report.json").read_text())
    v = report["videos"][0]
    assert v["words"] == [] and v["shapes_from"] == "phones" and v["lang"] == "fr"
    assert (out / "bank.yaml").is_file() and len(report["visemes"]) == 9


def test_a_bank_from_a_sound_nothing_can_name_chooses_its_pictures_by_lip_shape(tmp_path, monkeypatch):
    # the aligner hears no words and no phones (what a language it cannot follow at all
    # would give) in a sound track that is not silent: the bank is made from the lips alone,
    # with a warning saying so, and its pictures are ordered by their real lip opening
    from lipsync.banks.bank import Bank
    from lipsync.face import measure as M
    from lipsync.face.landmarks import FaceMesh
    from lipsync.speech import align as A
    from lipsync.videobank import make_bank

    real = A.align

    def hears_nothing(audio, text=None, **kw):
        al = real(audio, text, **kw)
        return A.Alignment(A._timeline((), al.duration, None), A._timeline((), al.duration, None), al.duration,
                           transcript=(), recognised=True)

    monkeypatch.setattr(A, "align", hears_nothing)
    with pytest.warns(UserWarning, match="bbwm5s.mpg: nothing in its sound could be recognised as speech"):
        made = make_bank(tmp_path / "b", [VIDEO], quiet=True, flows=False)
    assert made.report["videos"][0]["shapes_from"] == "lip shape"
    bank = Bank.load(made.path)
    mesh = FaceMesh()
    opening = {v: float(M.lip_opening(mesh.find(bank.images[v][..., :3])[None])[0]) for v in ("A", "B", "C", "D")}
    assert opening["A"] < opening["B"] < opening["D"] and opening["A"] < opening["C"] < opening["D"], opening


def test_no_stretch_with_the_face_throughout_exits_2_naming_the_video():
    from lipsync.errors import InputError
    from lipsync.videobank.plate import choose_stretch

    n = 75
    pts = np.zeros((n, 468, 3))
    pts[:, :, 0] = np.arange(468) % 30
    pts[:, :, 1] = np.arange(468) // 30
    found = np.ones(n, bool)
    found[::10] = False  # the face lost every 0.4 s: no 0.5 s with it in every frame
    tracks = [type("T", (), {"points": pts, "found": found, "fps": 25.0, "__len__": lambda self: n})()]
    regs = [SimpleNamespace(residual=np.zeros(n))]
    footage = SimpleNamespace(tracks=tracks, regs=regs, names="gone.mp4")
    with pytest.raises(InputError, match="gone.mp4: no 0.5 s of video with the face in every frame"):
        choose_stretch(footage)
    found[::10] = True
    found[::20] = False  # every 0.8 s: a short plate is made
    s = choose_stretch(footage)
    assert round(0.5 * 25) <= len(s) < 1.5 * 25 and found[s.start:s.stop].all()


def test_a_face_that_leaves_the_picture_every_second_still_dubs(spanish_dub, tmp_path, capsys):
    from lipsync.face.video import read_video
    from test_videobank import _write_video

    frames = [f.copy() for f in read_video(VIDEO)]
    for i in range(len(frames)):
        if i % 30 in (0, 1, 2):  # covered for 3 frames every 1.2 s: no 1.5 s with the face throughout
            frames[i][40:260, 90:270] = 128
    covered = _write_video(tmp_path / "covered.mp4", frames, audio=VIDEO)
    out = tmp_path / "o.mp4"
    from lipsync.pipeline.dubbing import DubWarning

    with pytest.warns(DubWarning, match=r"no face in the video at output frame\(s\) 0-2 "):
        code, err = _exit(["dub", covered, "--audio", GRID / "prap6p.mpg", "--text", "place red at p six please",
                           "-o", out, "--cache", tmp_path / "c", "-q"], capsys)
    assert code == 0 and out.is_file() and "Traceback" not in err, err
    plate = json.loads(next((tmp_path / "c").glob("*/bank-*/plate.json")).read_text())
    assert 12 <= plate["frames"] < 37  # a plate shorter than 1.5 s, between two covered moments
