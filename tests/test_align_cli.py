"""``lipsync align``, audio as a timeline input, and the awkward inputs.

Silence, a transcript that does not fit, words missing from the dictionary, a stereo 44.1 kHz
mp3, unreadable audio, an empty transcript, and ``lipsync render speech.wav`` end to end.
"""

import json
import subprocess
import sys
import wave
from pathlib import Path

import numpy as np
import pytest

import synthetic
from lipsync import Animator, Bank, read_timeline
from lipsync.errors import InputError
from lipsync.encode import probe
from lipsync.speech.align import AlignmentWarning, MissingWordsWarning, align
from lipsync.readers import READERS

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "samples"
HELLO_WAV, HELLO_TEXT = SAMPLES / "hello.wav", (SAMPLES / "hello.lab").read_text()
HELLO_WORDS = ["hello", "i", "am", "a", "talking", "head", "made", "by", "lipsync"]


def lipsync(*args):
    return subprocess.run([sys.executable, "-m", "lipsync", *map(str, args)], capture_output=True, text=True)


def write_wav(path, samples, rate=16000, channels=1):
    with wave.open(str(path), "wb") as wf:
        wf.setnchannels(channels)
        wf.setsampwidth(2)
        wf.setframerate(rate)
        wf.writeframes(np.asarray(samples, "<i2").tobytes())
    return path


def ffmpeg(*args):
    import imageio_ffmpeg

    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-nostdin", "-v", "error", "-y", *map(str, args)], check=True)


def textgrid_intervals(path, tier):
    from praatio import textgrid

    tg = textgrid.openTextgrid(str(path), includeEmptyIntervals=True)
    return tg, [(e.start, e.end, e.label) for e in tg.getTier(tier).entries]


@pytest.fixture(scope="module")
def hello_alignment():
    with pytest.warns(MissingWordsWarning, match="lipsync"):
        return align(HELLO_WAV, HELLO_TEXT)


def test_align_cli_textgrid_read_back_by_praatio_and_our_reader(tmp_path, hello_alignment):
    out = tmp_path / "hello.TextGrid"
    r = lipsync("align", HELLO_WAV, "--text", SAMPLES / "hello.lab", "-o", out)
    assert r.returncode == 0, r.stderr
    assert "lipsync: warning:" in r.stderr and "lipsync" in r.stderr.split("warning:")[1]
    text = out.read_text()
    assert text.startswith('File type = "ooTextFile"\nObject class = "TextGrid"')
    assert "intervals [1]:" in text  # the long text form
    tg, words = textgrid_intervals(out, "words")
    _, phones = textgrid_intervals(out, "phones")
    assert tg.tierNames == ("words", "phones") or list(tg.tierNames) == ["words", "phones"]
    duration = 47473 / 16000  # samples in hello.wav
    for intervals in (words, phones):
        # the intervals tile the whole audio, silences as empty labels
        assert intervals[0][0] == 0 and intervals[-1][1] == pytest.approx(duration, abs=1e-6)
        assert all(a[1] == pytest.approx(b[0]) for a, b in zip(intervals, intervals[1:]))
        assert intervals[0][2] == "" and intervals[-1][2] == ""
    assert [w for _, _, w in words if w] == HELLO_WORDS
    labels = [p for _, _, p in phones if p]
    # ARPAbet with a stress digit on every vowel
    assert labels[:4] == ["HH", "AH0", "L", "OW1"]
    assert all(p[-1] in "012" for p in labels if p[0] in "AEIOU")
    # our reader reads it back: the same phones (stress digits dropped, as it does for MFA)
    back = read_timeline(out)
    assert back.labels() == [p.rstrip("012") for p in labels]
    assert back.duration == pytest.approx(duration, abs=1e-6)
    assert read_timeline(out, tier="words").labels() == HELLO_WORDS
    # and the same as the library call
    assert [s.label for s in hello_alignment.phones] == labels


def test_align_cli_json(tmp_path):
    out = tmp_path / "hello.json"
    r = lipsync("align", HELLO_WAV, "--text", HELLO_TEXT, "-o", out, "--quiet")
    assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    assert [w["word"] for w in doc["words"]] == HELLO_WORDS
    assert doc["missing_words"] == ["lipsync"] and doc["recognised"] is False and doc["skipped_words"] == []
    assert all(a["end"] <= b["start"] + 1e-9 for a, b in zip(doc["phones"], doc["phones"][1:]))


def test_silence_gives_a_silence_timeline(tmp_path):
    rng = np.random.default_rng(1)
    quiet = write_wav(tmp_path / "hiss.wav", rng.normal(0, 10, 32000).round())  # -70 dBFS noise, 2 s
    zeros = write_wav(tmp_path / "zeros.wav", np.zeros(24000))
    for path, seconds in ((quiet, 2.0), (zeros, 1.5)):
        out = tmp_path / (path.stem + ".TextGrid")
        r = lipsync("align", path, "--text", "hello there", "-o", out, "-q")
        assert r.returncode == 0, r.stderr
        for tier in ("words", "phones"):
            _, intervals = textgrid_intervals(out, tier)
            assert intervals == [(0, seconds, "")]
        r = lipsync("timeline", path)
        assert r.returncode == 0, r.stderr
        rows = [line.split("\t") for line in r.stdout.splitlines() if not line.startswith("#")]
        assert rows == [["0.000", f"{seconds:.3f}", "X"]]


def test_mismatched_transcript_warns_with_a_confidence():
    with pytest.warns(AlignmentWarning, match=r"confidence 0\.\d\d") as record:
        al = align(SAMPLES / "balloons.wav", "hello")
    message = str(record[-1].message)
    confidence = float(message.split("confidence ")[1][:4])
    assert confidence == pytest.approx(al.confidence, abs=0.005) and al.confidence < 0.2
    # best effort: still a timeline over the whole audio
    assert al.duration == pytest.approx(4.96, abs=0.01)
    with pytest.warns(AlignmentWarning) as record:
        al = align(SAMPLES / "balloons.wav", "the quick brown fox jumps over the lazy dog near the bank")
    assert al.recognised and al.confidence < 0.5 and len(al.words) > 3


def test_a_mostly_right_transcript_keeps_its_words():
    # one wrong word of fourteen: the words that fit are aligned, the wrong one left out (with
    # a neighbour or two it blurs into: measured 3), and a warning says how many
    text = (SAMPLES / "balloons.lab").read_text().replace("mother", "telephone")
    with pytest.warns(AlignmentWarning, match=r"[123] of its 14 words were not found") as record:
        al = align(SAMPLES / "balloons.wav", text)
    assert not al.recognised
    words = al.words.labels()
    assert words[:8] == ["five", "blue", "balloons", "floated", "over", "the", "warm", "pool"]
    assert "telephone" not in words and len(words) >= 11
    assert 0.5 < al.confidence < 1.0 and f"confidence {al.confidence:.2f}" in str(record[-1].message)
    # the words left out are named, in the warning and in the alignment
    assert "telephone" in al.skipped and len(al.skipped) == 14 - len(words)
    assert f"({', '.join(al.skipped)})" in str(record[-1].message)


def test_out_of_dictionary_words_are_listed_once_and_pronounced(hello_alignment):
    text = HELLO_TEXT.replace("talking", "tawking")  # a spelling CMUdict lacks
    with pytest.warns(MissingWordsWarning) as record:
        al = align(HELLO_WAV, text)
    missing = [str(w.message) for w in record if issubclass(w.category, MissingWordsWarning)]
    assert len(missing) == 1 and missing[0].endswith("2 word(s) not in the dictionary, pronounced by "
                                                     "letter-to-sound rules: tawking, lipsync")
    assert al.missing == ("tawking", "lipsync")
    words = {s.label: s for s in al.words}
    assert list(words) == [w if w != "talking" else "tawking" for w in HELLO_WORDS]
    # the word has phones from the letter-to-sound rules, and they lie inside it
    inside = [p.label.rstrip("012") for p in al.phones if words["tawking"].start <= p.start < words["tawking"].end]
    assert inside == ["T", "AO", "K", "IH", "NG"]
    lip = [p.label.rstrip("012") for p in hello_alignment.phones
           if hello_alignment.words[-1].start <= p.start < hello_alignment.words[-1].end]
    assert lip == ["L", "IH", "P", "S", "IH", "NG", "K"]


def test_stereo_44k_mp3_aligns_like_the_wav(tmp_path, hello_alignment):
    mp3 = tmp_path / "hello.mp3"
    ffmpeg("-i", HELLO_WAV, "-ac", "2", "-ar", "44100", "-b:a", "128k", mp3)
    info = probe(mp3)
    assert info["audio_codec"] == "mp3"
    with pytest.warns(MissingWordsWarning):
        al = align(mp3, HELLO_TEXT)
    assert al.words.labels() == HELLO_WORDS
    assert al.duration == pytest.approx(hello_alignment.duration, abs=0.03)
    a = [s.start for s in al.phones]
    b = [s.start for s in hello_alignment.phones]
    assert len(a) == len(b) and np.mean(np.abs(np.subtract(a, b))) < 0.015


def test_unreadable_audio_exit_2_naming_the_file(tmp_path):
    bad = tmp_path / "notes.wav"
    bad.write_text("this is not audio\n" * 20)
    out = tmp_path / "out.TextGrid"
    for path in (bad, tmp_path / "missing.mp3"):
        r = lipsync("align", path, "-o", out)
        assert r.returncode == 2 and str(path) in r.stderr, r.stderr
        assert not out.exists() and not list(tmp_path.glob(".lipsync-*"))
    r = lipsync("render", bad, "-o", tmp_path / "x.mp4", "--method", "dissolve")
    assert r.returncode == 2 and str(bad) in r.stderr
    silent_video = tmp_path / "silent.mp4"
    ffmpeg("-f", "lavfi", "-i", "testsrc=size=32x32:rate=5", "-t", "0.4", silent_video)
    r = lipsync("align", silent_video, "-o", out)
    assert r.returncode == 2 and f"{silent_video}: cannot read as audio (no audio stream)" in r.stderr
    r = lipsync("align", HELLO_WAV, "-o", tmp_path / "no" / "such" / "out.TextGrid")
    assert r.returncode == 2 and "out.TextGrid" in r.stderr and "folder" in r.stderr


def test_empty_transcript_means_none(tmp_path):
    empty = tmp_path / "empty.txt"
    empty.write_text("  \n")
    recognised = align(HELLO_WAV, None)
    assert recognised.recognised and recognised.confidence is None and len(recognised.words) >= 3
    for text in ("", "   ", str(empty)):
        al = align(HELLO_WAV, text)
        assert al.recognised and al.words == recognised.words and al.phones == recognised.phones
    # only symbols is not "no transcript" but a wrong one (issue 38 item 13): refused, named
    with pytest.raises(InputError, match="no words to say, only symbols or punctuation"):
        align(HELLO_WAV, "...!")


def test_audio_is_a_timeline_format(tmp_path):
    assert "audio" in READERS.names()
    for ext in (".wav", ".flac", ".mp3", ".m4a", ".ogg", ".opus"):
        assert READERS.name_for_extension(ext) == "audio"
    flac = tmp_path / "speech.bin"  # unknown extension: found by its content
    ffmpeg("-i", HELLO_WAV, "-f", "flac", flac)
    with pytest.warns(MissingWordsWarning, match="lipsync"):
        tl = read_timeline(flac, text=HELLO_TEXT)
    assert tl.kind == "phoneme" and tl.labels()[:4] == ["HH", "AH", "L", "OW"]
    with pytest.warns(MissingWordsWarning):
        assert read_timeline(flac, tier="words", text=HELLO_TEXT).labels() == HELLO_WORDS


@pytest.fixture(scope="module")
def rhubarb_bank(tmp_path_factory):
    return synthetic.write_bank(tmp_path_factory.mktemp("align-e2e") / "bank", synthetic.RHUBARB_SHAPES)


def test_render_speech_wav_end_to_end(tmp_path, rhubarb_bank):
    out = tmp_path / "out.mp4"
    r = lipsync("render", HELLO_WAV, "--text", SAMPLES / "hello.lab", "--bank", rhubarb_bank,
                "--method", "dissolve", "-o", out, "--quiet")
    assert r.returncode == 0, r.stderr
    info = probe(out)
    duration = 47473 / 16000
    assert info["streams"] == [("video", "h264"), ("audio", "aac")]  # the input muxed, no --audio
    assert info["n_frames"] == int(np.ceil(duration * 25))
    assert abs(info["audio_duration"] - duration) <= 1 / 25
    # frames in the middle of long vowels show the shape the synthesiser's own phones give
    from lipsync.phonetics.phonemes import load_map, map_timeline

    import imageio_ffmpeg

    gen = imageio_ffmpeg.read_frames(str(out))
    w, h = next(gen)["size"]
    frames = [np.frombuffer(f, np.uint8).reshape(h, w, 3).astype(np.float32) for f in gen]
    bank = Bank.load(rhubarb_bank)
    truth = map_timeline(read_timeline(SAMPLES / "hello.TextGrid"), load_map("english-to-rhubarb"))
    hits = total = 0
    for seg in truth:
        if seg.end - seg.start < 0.09 or seg.label == "X":
            continue
        frame = frames[int((seg.start + seg.end) / 2 * 25)]
        dist = {v: float(np.mean((frame - bank.images[v]) ** 2)) for v in bank.names}
        hits += min(dist, key=dist.get) == seg.label
        total += 1
    print(f"\n{hits} of {total} held shapes shown at their midpoints")
    assert total == 7 and hits >= 5, (hits, total)


def test_animator_from_audio(rhubarb_bank):
    anim = Animator.from_audio(rhubarb_bank, HELLO_WAV, HELLO_TEXT, fps=30, method="dissolve")
    assert len(anim) == int(np.ceil(47473 / 16000 * 30))
    assert anim.alignment.words.labels() == HELLO_WORDS
    assert anim.frame(0).shape[2] == 3
    # samples instead of a file (floats in -1..1, as sound libraries give them): same result
    from lipsync.speech.audio import load_audio

    samples = load_audio(HELLO_WAV).astype(np.float32) / 32768
    same = Animator.from_audio(rhubarb_bank, samples, HELLO_TEXT, fps=30, method="dissolve")
    assert same.alignment.phones.labels() == anim.alignment.phones.labels()
    assert same.specs == anim.specs


def test_workers_are_forked_only_from_a_single_threaded_main():
    import threading

    from lipsync.speech.align import _can_fork

    seen = []
    worker = threading.Thread(target=lambda: seen.append(_can_fork()))
    worker.start()
    worker.join()
    assert seen == [False]  # from a thread (a server's request handler): decode in-process
    idle = threading.Event()
    other = threading.Thread(target=idle.wait)
    other.start()
    try:
        assert not _can_fork()  # another thread alive: a fork could copy its held locks
    finally:
        idle.set()
        other.join()


def test_cues_from_audio_equal_cues_from_its_alignment(tmp_path):
    # audio goes through the same stage as any timeline: cues made straight from the wav are
    # the cues made from the TextGrid `lipsync align` wrote for it
    grid = tmp_path / "hello.TextGrid"
    assert lipsync("align", HELLO_WAV, "--text", SAMPLES / "hello.lab", "-o", grid, "-q").returncode == 0
    a, b = tmp_path / "from_audio.tsv", tmp_path / "from_grid.tsv"
    r = lipsync("cues", HELLO_WAV, "--text", SAMPLES / "hello.lab", "-o", a, "--format", "rhubarb-tsv")
    assert r.returncode == 0, r.stderr
    assert lipsync("cues", grid, "-o", b, "--format", "rhubarb-tsv").returncode == 0
    assert a.read_text() == b.read_text() and len(a.read_text().splitlines()) > 10


def test_long_transcribed_audio_is_aligned_chunk_by_chunk():
    # 12 copies of hello.wav (35.6 s, over MAX_CHUNK_S): cut into chunks, each taking the
    # next words of the transcript; every copy's words land at that copy's times
    from lipsync.speech.align import MAX_CHUNK_S, align_samples
    from lipsync.speech.audio import load_audio

    pcm = load_audio(HELLO_WAV)
    copies, period = 12, len(pcm) / 16000
    assert copies * period > MAX_CHUNK_S
    with pytest.warns(MissingWordsWarning):
        long = align_samples(np.tile(pcm, copies), " ".join([HELLO_TEXT] * copies))
    with pytest.warns(MissingWordsWarning):
        one = align_samples(pcm, HELLO_TEXT)
    assert not long.recognised and long.confidence > 0.9
    words = long.words.labels()
    assert len(words) >= 0.95 * copies * len(HELLO_WORDS)
    # each word within 40 ms of the same word in the single copy, shifted by its copy's start
    ref = [(s.label, s.start) for s in one.words]
    errors = []
    for seg in long.words:
        k = int(seg.start // period)
        cands = [t for w, t in ref if w == seg.label]
        errors.append(min(abs(seg.start - k * period - t) for t in cands))
    assert np.median(errors) < 0.02 and np.mean(np.array(errors) < 0.04) > 0.95
