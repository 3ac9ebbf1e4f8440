"""TTS and recogniser formats: Polly speech marks, Azure viseme events, Whisper-style word
timings, ElevenLabs character alignments, and the word-to-phone split they share.

The real examples (tests/data/timelines/README-tts-examples.md) are read here against
expectations worked out independently: by hand from the engines' published viseme tables,
or from the words' own times and CMUdict pronunciations.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lipsync.cli import main
from lipsync.errors import TimelineError
from lipsync.phonetics.phonemes import load_map
from lipsync.speech.lexicon import normalise_transcript, pronounce
from lipsync.speech.phonetise import phones_of, split_word, words_to_phones
from lipsync.motion.timeline import Segment, Timeline
from lipsync.readers import read_timeline

TIMELINES = Path(__file__).parent / "data" / "timelines"


def _rows(tl, nd=6):
    return [(round(s.start, nd), round(s.end, nd), s.label) for s in tl]


def _write(tmp_path, name, obj):
    p = tmp_path / name
    p.write_text(obj if isinstance(obj, str) else json.dumps(obj, indent=1))
    return p


# --- words to phones ----------------------------------------------------------------------------


def test_split_is_proportional_to_typical_durations():
    # Klatt's inherent durations, written out here: M 70 ms, AA 240 ms (total 380 ms).
    segs = split_word(1.0, 1.38, ("M", "AA", "M"))
    assert [s.label for s in segs] == ["M", "AA", "M"]
    assert [round(s.duration, 9) for s in segs] == [0.07, 0.24, 0.07]
    # A word half as long keeps the proportions.
    segs = split_word(0.0, 0.19, ("M", "AA", "M"))
    assert [round(s.duration, 9) for s in segs] == [0.035, 0.12, 0.035]
    assert segs[-1].end == 0.19


def test_words_to_phones_keeps_every_word_in_its_own_time():
    words = Timeline((Segment(0.1, 0.5, "Hello,"), Segment(0.5, 0.62, "2"), Segment(0.9, 1.4, "well-known")),
                     stated_end=2.0)
    phones = words_to_phones(words)
    assert phones.kind == "phoneme" and phones.duration == 2.0
    want = []
    for w in words:
        for word in normalise_transcript(w.label):
            want += [p.rstrip("012") for p in pronounce(word)]
    assert phones.labels() == want
    # Phone boundaries at the word boundaries; the gap 0.62-0.9 stays a gap.
    starts = [round(s.start, 9) for s in phones]
    ends = [round(s.end, 9) for s in phones]
    for w in words:
        assert round(w.start, 9) in starts and round(w.end, 9) in ends
    assert not any(0.62 < s.start < 0.9 for s in phones)


def test_punctuation_only_words_leave_a_gap():
    phones = words_to_phones(Timeline((Segment(0, 0.3, "hi"), Segment(0.3, 0.5, "--"), Segment(0.5, 0.8, "yo"))))
    assert not any(0.3 <= s.start < 0.5 for s in phones)


# --- Amazon Polly ----------------------------------------------------------------------------------


def test_polly_map_covers_polly_visemes_exactly():
    # Polly's viseme set for English (Polly Developer Guide, viseme tables).
    polly = {"p", "t", "S", "T", "f", "k", "i", "r", "s", "u", "@", "a", "e", "E", "o", "O", "sil"}
    pmap = load_map("polly-to-rhubarb")
    assert set(pmap.map) == polly
    assert pmap.targets("p") == ["A"] and pmap.targets("f") == ["G"] and pmap.targets("sil") == ["X"]
    assert pmap.closures == ["A"]


def test_polly_json_array_reads_like_json_lines(tmp_path):
    lines = (TIMELINES / "polly_mary_lamb.txt").read_text().splitlines()
    arr = _write(tmp_path, "marks.json", "[\n" + ",\n".join(lines) + "\n]\n")
    assert read_timeline(arr) == read_timeline(TIMELINES / "polly_mary_lamb.txt").replace(path=str(arr))


def test_polly_word_marks_skip_ssml_and_stop_at_twice_the_typical_length():
    tl = read_timeline(TIMELINES / "polly_ssml_words.txt")
    # "had" starts at 325 ms; the next spoken word ("a") is at 1291 ms, after a 300 ms break
    # Polly reports as a word. HH+AE+D typical 80+230+75 = 385 ms, so "had" ends at
    # 325 + 2 * 385 = 1095 ms and the rest until 1291 ms is silence.
    had = [s for s in tl if 0.325 <= s.start < 1.1]
    assert [s.label for s in had] == ["HH", "AE", "D"]
    assert had[-1].end == pytest.approx(1.095)
    assert not any(1.095 < s.start < 1.291 for s in tl)
    # The last word ("lamb", L AE M: 80+230+70 ms) lasts its typical length.
    assert tl[-1].end == pytest.approx(1.635 + 0.380)


def test_polly_without_viseme_or_word_marks_is_an_error(tmp_path):
    p = _write(tmp_path, "s.marks", '{"time":0,"type":"sentence","start":0,"end":2,"value":"Hi"}\n')
    with pytest.raises(TimelineError, match="no viseme or word marks"):
        read_timeline(p)


def test_polly_bad_line_names_the_line(tmp_path):
    p = _write(tmp_path, "s.marks", '{"time":0,"type":"viseme","value":"p"}\n{"time":5,"type":"viseme",\n')
    with pytest.raises(TimelineError) as info:
        read_timeline(p)
    assert info.value.line == 2 and "not valid JSON" in str(info.value)


# --- Azure -------------------------------------------------------------------------------------------


def test_azure_map_covers_the_22_ids():
    pmap = load_map("azure-to-rhubarb")
    assert set(pmap.map) == {str(i) for i in range(22)}
    # SAPI viseme 21 is p b m, 18 is f v, 14 is l, 0 silence.
    assert pmap.targets("21") == ["A"] and pmap.targets("18") == ["G"] and pmap.targets("14") == ["H"]
    assert pmap.targets("0") == ["X"]


AZURE_EVENTS = [(500000, 0), (1000000, 19), (2000000, 7), (3125000, 21), (4000000, 0)]
# By hand: 19 d t n -> B, 7 w uw -> F, 21 p b m -> A; points last until the next one.
AZURE_WANT = [(0.0, 0.05, "X"), (0.05, 0.1, "X"), (0.1, 0.2, "B"), (0.2, 0.3125, "F"), (0.3125, 0.4, "A"),
              (0.4, 0.55, "X")]


@pytest.mark.parametrize("spelling", [
    lambda o, v: {"AudioOffset": o, "VisemeId": v},
    lambda o, v: {"audioOffset": o, "visemeId": v},
    lambda o, v: {"audio_offset": o, "viseme_id": v},
    lambda o, v: {"offset": o, "visemeID": v},
    lambda o, v: {"audio_offset_ms": o / 10000, "viseme_id": v},
    lambda o, v: {"offsetMs": o / 10000, "VisemeID": v},
], ids=["csharp", "javascript", "python", "offset", "ms", "offsetMs"])
def test_azure_field_spellings_agree(tmp_path, spelling):
    p = _write(tmp_path, "v.json", [spelling(o, v) for o, v in AZURE_EVENTS])
    tl = read_timeline(p)
    assert tl.kind == "viseme" and _rows(tl) == AZURE_WANT


@pytest.mark.parametrize("wrap", ["visemes", "events", "metadata"])
def test_azure_wrappers(tmp_path, wrap):
    events = [{"audioOffset": o, "visemeId": v} for o, v in AZURE_EVENTS]
    if wrap == "metadata":  # the service's websocket message, word boundaries mixed in
        doc = {"Metadata": [{"Type": "WordBoundary", "Data": {"Offset": 500000, "text": {"Text": "hi"}}}]
               + [{"Type": "Viseme", "Data": {"Offset": o, "VisemeId": v}} for o, v in AZURE_EVENTS]}
    else:
        doc = {wrap: events}
    assert _rows(read_timeline(_write(tmp_path, "v.json", doc))) == AZURE_WANT


# --- Whisper-style word timings ------------------------------------------------------------------------

WORDS = [("Hello", 0.0, 0.42), ("there,", 0.42, 0.8), ("lipsync!", 1.2, 1.9)]


def _whisper_variants():
    w = [{"word": " " + t, "start": s, "end": e, "probability": 0.9} for t, s, e in WORDS]
    yield "openai-whisper", {"text": "x", "segments": [{"id": 0, "start": 0.0, "end": 0.8, "words": w[:2]},
                                                       {"id": 1, "start": 1.2, "end": 1.9, "words": w[2:]}]}
    yield "verbose_json", {"task": "transcribe", "duration": 1.9, "words": [{"word": t, "start": s, "end": e}
                                                                           for t, s, e in WORDS]}
    yield "plain list", [{"word": t, "start": s, "end": e} for t, s, e in WORDS]
    yield "faster-whisper list", [{"start": 0, "end": 1.9, "text": "x", "words": w}]
    yield "whisper-timestamped", {"segments": [{"words": [{"text": t, "start": s, "end": e, "confidence": 0.5}
                                                          for t, s, e in WORDS]}]}
    yield "whisper.cpp", {"transcription": [{"timestamps": {"from": "00:00:00,000", "to": "x"},
                                             "offsets": {"from": round(s * 1000), "to": round(e * 1000)},
                                             "text": " " + t} for t, s, e in WORDS]}
    yield "transformers", {"text": "x", "chunks": [{"text": " " + t, "timestamp": [s, e]} for t, s, e in WORDS]}


@pytest.mark.parametrize("name,doc", list(_whisper_variants()), ids=[n for n, _ in _whisper_variants()])
def test_whisper_variants_give_the_same_phones(tmp_path, name, doc):
    tl = read_timeline(_write(tmp_path, "w.json", doc))
    want = words_to_phones(Timeline(tuple(Segment(s, e, t) for t, s, e in WORDS)))
    assert _rows(tl) == _rows(want)
    assert tl.labels()[:4] == [p.rstrip("012") for p in pronounce("hello")]


def test_whisper_real_example_words_keep_their_times():
    tl = read_timeline(TIMELINES / "whisper_timestamped_apollo11.json")
    doc = json.loads((TIMELINES / "whisper_timestamped_apollo11.json").read_text())
    words = [w for seg in doc["segments"] for w in seg["words"]]
    assert tl.kind == "phoneme" and tl.duration == pytest.approx(6.94)
    i = 0
    for w in words:
        n = len(phones_of(w["text"]))
        assert n > 0, w
        mine = tl[i:i + n]
        assert mine[0].start == pytest.approx(w["start"]) and mine[-1].end == pytest.approx(w["end"])
        i += n
    assert i == len(tl)


def test_whisper_untimed_and_overlapping_words(tmp_path):
    doc = [{"word": "one", "start": 0.0, "end": 0.5}, {"word": "2", "start": None, "end": None},
           {"word": "three", "start": 0.45, "end": 1.0}]
    tl = read_timeline(_write(tmp_path, "w.json", doc))
    three = [s for s in tl if s.start >= 0.5]
    assert three[0].start == 0.5 and three[-1].end == 1.0  # starts where "one" ends
    assert [s.label for s in three] == [p.rstrip("012") for p in pronounce("three")]


def test_whisper_long_transcript_before_segments_is_recognised_by_structure(tmp_path):
    doc = {"text": "word " * 2000, "segments": [{"words": [{"word": "hi", "start": 0, "end": 0.3}]}]}
    tl = read_timeline(_write(tmp_path, "w.json", doc))
    assert tl.labels() == ["HH", "AY"]


# --- ElevenLabs ------------------------------------------------------------------------------------


def test_elevenlabs_real_example_drops_the_audio_tag_and_keeps_word_times():
    doc = json.loads((TIMELINES / "elevenlabs_v3_tags.json").read_text())
    al = doc["alignment"]
    tl = read_timeline(TIMELINES / "elevenlabs_v3_tags.json")
    # "[excited] " is not spoken: the first phone is the T of "This" (index 10), 67 ms.
    assert al["characters"][10] == "T"
    assert tl[0].start == al["character_start_times_seconds"][10] == 0.067
    assert tl[-1].end == al["character_end_times_seconds"][-1] == 5.84
    spoken = "This is the first beat of a real v3 tags test. So here's the second beat, after a real pause."
    assert tl.labels() == list(phones_of(spoken))


def _eleven(chars, starts, ends):
    return {"characters": list(chars), "character_start_times_seconds": starts, "character_end_times_seconds": ends}


def test_elevenlabs_wrappers_and_spellings(tmp_path):
    chars = "hi you"
    starts = [0.0, 0.1, 0.25, 0.3, 0.4, 0.5]
    ends = [0.1, 0.25, 0.3, 0.4, 0.5, 0.62]
    want = _rows(read_timeline(_write(tmp_path, "bare.json", _eleven(chars, starts, ends))))
    assert [r[2] for r in want] == ["HH", "AY", "Y", "UW"]
    assert want[0][0] == 0.0 and want[1][1] == 0.25 and want[2][0] == 0.3 and want[-1][1] == 0.62
    wrapped = {"audio_base64": "", "alignment": _eleven("xx", [0, 1], [1, 2]),
               "normalized_alignment": _eleven(chars, starts, ends)}  # normalized is preferred
    assert _rows(read_timeline(_write(tmp_path, "w.json", wrapped))) == want
    camel = {"normalizedAlignment": {"characters": list(chars), "characterStartTimesSeconds": starts,
                                     "characterEndTimesSeconds": ends}}
    assert _rows(read_timeline(_write(tmp_path, "c.json", camel))) == want
    ws = {"alignment": {"chars": list(chars), "charStartTimesMs": [round(s * 1000) for s in starts],
                        "charDurationsMs": [round((e - s) * 1000) for s, e in zip(starts, ends)]}}
    assert _rows(read_timeline(_write(tmp_path, "ws.json", ws))) == want


# --- detection and the CLI ----------------------------------------------------------------------------


@pytest.mark.parametrize("name,fmt", [("polly_mary_lamb.txt", "polly"), ("azure_docs_visemes.json", "azure"),
                                      ("whisper_timestamped_apollo11.json", "whisper"),
                                      ("elevenlabs_v3_tags.json", "elevenlabs")])
def test_detected_under_any_extension(tmp_path, name, fmt):
    from lipsync.readers import _choose_reader

    data = (TIMELINES / name).read_bytes()
    for ext in (".json", ".txt", ".dat", ""):
        assert _choose_reader(str(tmp_path / f"x{ext}"), data).name == fmt


def test_unknown_json_lists_the_formats_and_exits_2(tmp_path, capsys):
    p = _write(tmp_path, "mystery.json", {"hello": [1, 2]})
    assert main(["cues", str(p), "-o", str(tmp_path / "c.tsv")]) == 2
    err = capsys.readouterr().err
    assert str(p) in err
    for name in ("gentle", "rhubarb-json", "polly", "azure", "elevenlabs", "whisper"):
        assert name in err


def test_cues_from_polly_marks(tmp_path):
    out = tmp_path / "c.tsv"
    assert main(["cues", str(TIMELINES / "polly_mary_lamb.txt"), "-o", str(out), "-q"]) == 0
    cues = read_timeline(out)
    # By hand from the marks: lips closed for M (6-73 ms) and for the M of "lamb" (1082 ms on).
    assert cues.labels()[1] == "A" and cues[1].start == pytest.approx(0.006)
    assert [s for s in cues if s.label == "A"][-1].start == pytest.approx(1.082)


# --- the split against real phone times ----------------------------------------------------------


def _shape_frames(tl, duration, step=0.01):
    from lipsync.phonetics.phonemes import map_timeline

    n = int(duration / step)
    out = ["X"] * n
    for s in map_timeline(tl, load_map("rhubarb")):
        a, b = int(round(s.start / step)), min(n, int(round(s.end / step)))
        out[a:b] = [s.label] * max(0, b - a)
    return out


def test_word_split_against_mfa_phone_times():
    """MFA's own word times in, its phone times as the reference (26.7 s of real speech).

    Measured: 81.6 % of 10 ms frames show the same Rhubarb shape as MFA's phones (80.7 % with
    an equal split of each word), inner phone boundaries 44 ms off on average (47 ms equal).
    """
    grid = Path(__file__).parent / "data" / "conformance" / "mfa" / "acoustic_corpus.TextGrid"
    words, phones = read_timeline(grid, tier="words"), read_timeline(grid, tier="phones")
    mine = words_to_phones(words)
    equal = Timeline(tuple(Segment(w.start + (w.end - w.start) * i / len(ps),
                                   w.start + (w.end - w.start) * (i + 1) / len(ps), p)
                           for w in words for ps in [phones_of(w.label)] for i, p in enumerate(ps)))
    ref = _shape_frames(phones, phones.duration)
    agree = sum(a == b for a, b in zip(_shape_frames(mine, phones.duration), ref)) / len(ref)
    agree_equal = sum(a == b for a, b in zip(_shape_frames(equal, phones.duration), ref)) / len(ref)
    assert agree >= 0.80 and agree >= agree_equal
    spoken = [s for s in phones if s.label not in ("sil", "sp", "spn")]
    errors = []
    for w in words:
        ref_in = [s for s in spoken if w.start - 1e-6 <= s.start and s.end <= w.end + 1e-6]
        mine_in = [s for s in mine if w.start - 1e-6 <= s.start and s.end <= w.end + 1e-6]
        if ref_in and len(ref_in) == len(mine_in):
            errors += [abs(a.end - b.end) for a, b in zip(ref_in[:-1], mine_in[:-1])]
    assert len(errors) > 100 and sum(errors) / len(errors) <= 0.050
