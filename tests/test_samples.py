"""The committed samples/: audio and timelines that agree with each other and with the sound.

Each format is read here with a small parser of its own, independent of the
project's readers, so these tests check the files themselves.  They need only the
standard library and numpy (not espeak-ng, which made the files).
"""

from __future__ import annotations

import json
import re
import wave
from pathlib import Path

import numpy as np
import pytest

SAMPLES = Path(__file__).resolve().parent.parent / "samples"
NAMES = sorted(p.stem for p in SAMPLES.glob("*.lab"))
RATE = 16000

# times are written exactly (phn, TextGrid) or to six decimals (Audacity) or as sums
# of float durations (Gentle): all agree far better than one sample (62.5 us)
TIME_TOL = 1e-5
# the brief's tolerance between the audio's length and the timelines' end
DURATION_TOL = 0.020
# how far the first/last audible sound may be from the first phone's start and the
# last phone's end -- one 25 fps video frame is 40 ms, so 30 ms is below what shows
EDGE_TOL = 0.030

ARPABET_VOWELS = set("AA AE AH AO AW AY EH ER EY IH IY OW OY UH UW".split())
ARPABET_CONSONANTS = set("B CH D DH F G HH JH K L M N NG P R S SH T TH V W Y Z ZH".split())
# the 61 labels of the TIMIT transcriptions (TIMIT doc/phoncode.doc)
TIMIT_LABELS = set(
    "b d g p t k dx q jh ch s sh z zh f th v dh m n ng em en eng nx l r w y hh hv el "
    "iy ih eh ey ae aa aw ay ah ao oy ow uh uw ux er ax ix axr ax-h "
    "bcl dcl gcl pcl tcl kcl pau epi h#".split()
)
UNVOICED_OBSTRUENTS = {"P", "T", "K", "F", "S", "SH", "TH", "CH", "HH"}


# ---------------------------------------------------------------- plain parsers


def read_wav(path):
    with wave.open(str(path), "rb") as w:
        params = (w.getframerate(), w.getnchannels(), w.getsampwidth(), w.getcomptype())
        audio = np.frombuffer(w.readframes(w.getnframes()), dtype="<i2").astype(np.float64)
    return params, audio


def read_phn(path):
    out = []
    for line in path.read_text().splitlines():
        a, b, lab = line.split()
        out.append((int(a), int(b), lab))
    return out


def read_textgrid(path):
    """Praat long text form -> {tier name: [(xmin, xmax, text)]}, plus the file's xmax."""
    tiers, cur, iv, xmax = {}, None, None, None
    for raw in path.read_text().splitlines():
        line = raw.strip()
        m = re.fullmatch(r'(\w+) = (.*?)', line)
        if line.startswith("item [") and line != "item []:":
            cur = None
        elif line.startswith("intervals ["):
            iv = {}
        elif m:
            key, val = m.group(1), m.group(2).strip()
            if key == "name":
                cur = tiers.setdefault(val.strip('"'), [])
            elif cur is None and key == "xmax":
                xmax = float(val)
            elif iv is not None and key in ("xmin", "xmax"):
                iv[key] = float(val)
            elif iv is not None and key == "text":
                cur.append((iv["xmin"], iv["xmax"], val.strip('"')))
                iv = None
    return tiers, xmax


def read_gentle(path):
    data = json.loads(path.read_text())
    phones = []
    for w in data["words"]:
        t = w["start"]
        for p in w["phones"]:
            phones.append((t, t + p["duration"], p["phone"]))
            t += p["duration"]
    return data, phones


def read_audacity(path):
    out = []
    for line in path.read_text().splitlines():
        a, b, lab = line.split("\t")
        out.append((float(a), float(b), lab))
    return out


def rms(x):
    return float(np.sqrt(np.mean(x ** 2))) if len(x) else 0.0


def strip_stress(label):
    return label.rstrip("012")


@pytest.fixture(scope="module", params=NAMES)
def sample(request):
    name = request.param
    return {
        "name": name,
        "wav": read_wav(SAMPLES / f"{name}.wav"),
        "phn": read_phn(SAMPLES / f"{name}.phn"),
        "tg": read_textgrid(SAMPLES / f"{name}.TextGrid"),
        "gentle": read_gentle(SAMPLES / f"{name}.json"),
        "txt": read_audacity(SAMPLES / f"{name}.txt"),
        "lab": (SAMPLES / f"{name}.lab").read_text().strip(),
    }


# ---------------------------------------------------------------- tests


def test_demo_sample_present():
    # `make demo` renders samples/hello.phn with samples/hello.wav
    assert "hello" in NAMES
    assert len(NAMES) >= 2
    for name in NAMES:
        for ext in ("wav", "phn", "TextGrid", "json", "txt"):
            assert (SAMPLES / f"{name}.{ext}").is_file(), f"{name}.{ext}"


def test_wav_format_and_duration(sample):
    (rate, channels, width, comp), audio = sample["wav"]
    assert (rate, channels, width, comp) == (RATE, 1, 2, "NONE")
    duration = len(audio) / RATE
    assert sample["phn"][-1][1] == len(audio)  # TIMIT covers the file to the sample
    tiers, xmax = sample["tg"]
    assert abs(xmax - duration) < DURATION_TOL
    for ivs in tiers.values():
        assert abs(ivs[-1][1] - duration) < DURATION_TOL
    assert abs(sample["txt"][-1][1] - duration) < DURATION_TOL
    # Gentle has no silence entries: its last word ends inside the audio, before the trailing silence
    last_word_end = sample["gentle"][0]["words"][-1]["end"]
    assert 0 < duration - last_word_end < 1.0


def _segments(sample):
    """Each format's intervals as (start s, end s, label), silence labels kept."""
    phn = [(a / RATE, b / RATE, lab) for a, b, lab in sample["phn"]]
    return {
        "phn": phn,
        "TextGrid": sample["tg"][0]["phones"],
        "txt": sample["txt"],
    }


def test_intervals_sorted_contiguous_and_cover_the_audio(sample):
    duration = len(sample["wav"][1]) / RATE
    for fmt, segs in list(_segments(sample).items()) + [("words", sample["tg"][0]["words"])]:
        starts = np.array([s[0] for s in segs])
        ends = np.array([s[1] for s in segs])
        assert starts[0] == 0, fmt
        assert np.all(ends > starts), fmt
        # contiguous: each interval starts where the one before ends (so no overlap)
        np.testing.assert_allclose(starts[1:], ends[:-1], atol=TIME_TOL, err_msg=fmt)
        assert abs(ends[-1] - duration) < TIME_TOL, fmt
    words = sample["gentle"][0]["words"]
    for w0, w1 in zip(words, words[1:]):
        assert w0["start"] < w0["end"] <= w1["start"] + TIME_TOL


def test_all_formats_describe_the_same_phones(sample):
    segs = _segments(sample)
    silence = {"phn": {"h#", "pau"}, "TextGrid": {""}, "txt": {"sil"}}
    spoken = {
        fmt: [(a, b, strip_stress(lab).upper()) for a, b, lab in s if lab not in silence[fmt]]
        for fmt, s in segs.items()
    }
    spoken["json"] = [(a, b, lab.rsplit("_", 1)[0].upper()) for a, b, lab in sample["gentle"][1]]
    ref = spoken["TextGrid"]
    assert len(ref) > 10
    for fmt, seq in spoken.items():
        assert [s[2] for s in seq] == [s[2] for s in ref], fmt
        np.testing.assert_allclose([s[:2] for s in seq], [s[:2] for s in ref], atol=TIME_TOL, err_msg=fmt)
    # the silences are the same stretches too
    sil = {fmt: [(a, b) for a, b, lab in s if lab in silence[fmt]] for fmt, s in segs.items()}
    for fmt in sil:
        np.testing.assert_allclose(sil[fmt], sil["TextGrid"], atol=TIME_TOL, err_msg=fmt)
    # and the TextGrid and Audacity labels agree with stress digits included
    assert [s[2] for s in segs["TextGrid"]] == [lab if lab != "sil" else "" for _, _, lab in segs["txt"]]


def test_labels_are_valid(sample):
    phn = sample["phn"]
    assert phn[0][2] == "h#" and phn[-1][2] == "h#"
    assert all(lab != "h#" for _, _, lab in phn[1:-1])  # inner pauses are pau
    assert all(lab in TIMIT_LABELS for _, _, lab in phn)
    for fmt, segs in (("TextGrid", sample["tg"][0]["phones"]), ("txt", sample["txt"])):
        for _, _, lab in segs:
            if lab in ("", "sil"):
                continue
            base = strip_stress(lab)
            if base in ARPABET_VOWELS:
                # MFA writes every vowel with its stress digit
                assert re.fullmatch(r"[A-Z]+[012]", lab), (fmt, lab)
            else:
                assert base in ARPABET_CONSONANTS and base == lab, (fmt, lab)
    for w in sample["gentle"][0]["words"]:
        labels = [p["phone"] for p in w["phones"]]
        want = ["S"] if len(labels) == 1 else ["B"] + ["I"] * (len(labels) - 2) + ["E"]
        assert [lab.rsplit("_", 1)[1] for lab in labels] == want, w["word"]
        for lab in labels:
            base = lab.rsplit("_", 1)[0]
            assert base == base.lower() and base.upper() in ARPABET_VOWELS | ARPABET_CONSONANTS, lab


def test_words_match_the_text(sample):
    text = sample["lab"]
    tokens = re.findall(r"[A-Za-z]+(?:'[A-Za-z]+)?", text)
    tg_words = sample["tg"][0]["words"]
    assert [w for _, _, w in tg_words if w] == [t.lower() for t in tokens]
    data, _ = sample["gentle"]
    assert data["transcript"] == text
    assert [w["word"] for w in data["words"]] == tokens
    for w in data["words"]:
        assert w["case"] == "success"
        assert text[w["startOffset"]:w["endOffset"]] == w["word"]
        assert w["alignedWord"] == w["word"].lower()
        assert abs(w["start"] + sum(p["duration"] for p in w["phones"]) - w["end"]) < TIME_TOL
    # each TextGrid word spans exactly the phones inside it, as in the Gentle file
    spoken_words = [(a, b) for a, b, w in tg_words if w]
    np.testing.assert_allclose(spoken_words, [(w["start"], w["end"]) for w in data["words"]], atol=TIME_TOL)
    phone_edges = {round(a * RATE) for a, _, _ in sample["tg"][0]["phones"]} | {
        round(b * RATE) for _, b, _ in sample["tg"][0]["phones"]}
    for a, b in spoken_words:
        assert round(a * RATE) in phone_edges and round(b * RATE) in phone_edges


def test_audio_has_speech_where_the_phones_are(sample):
    audio = sample["wav"][1]
    phn = sample["phn"]
    speech = np.concatenate([audio[a:b] for a, b, lab in phn if lab not in ("h#", "pau")])
    speech_rms = rms(speech)
    assert speech_rms > 500  # clearly audible, about -36 dBFS or louder
    for a, b, lab in phn:
        if lab in ("h#", "pau"):
            assert rms(audio[a:b]) < 0.01 * speech_rms, (a, b, lab)
    # every word is sounded
    for w in sample["gentle"][0]["words"]:
        seg = audio[round(w["start"] * RATE):round(w["end"] * RATE)]
        assert rms(seg) > 0.2 * speech_rms, w["word"]
    # vowels are the loud parts: a timeline shifted off its audio would lose this
    tg = sample["tg"][0]["phones"]
    vowel = [rms(audio[round(a * RATE):round(b * RATE)]) for a, b, lab in tg if strip_stress(lab) in ARPABET_VOWELS]
    obstruent = [rms(audio[round(a * RATE):round(b * RATE)]) for a, b, lab in tg if lab in UNVOICED_OBSTRUENTS]
    assert np.median(vowel) > 4 * np.median(obstruent)


def test_speech_starts_and_ends_with_the_timeline(sample):
    audio = sample["wav"][1]
    frame = RATE // 100  # 10 ms
    n = len(audio) // frame
    frames = np.sqrt(np.mean(audio[: n * frame].reshape(n, frame) ** 2, axis=1))
    loud = np.flatnonzero(frames > 0.02 * frames.max())
    onset, offset = loud[0] * frame / RATE, (loud[-1] + 1) * frame / RATE
    spoken = [(a, b) for a, b, lab in sample["tg"][0]["phones"] if lab]
    assert abs(onset - spoken[0][0]) < EDGE_TOL
    assert abs(offset - spoken[-1][1]) < EDGE_TOL
