"""Alignment accuracy against other tools' real output.

* acoustic_corpus.wav (26.7 s of real speech, Montreal Forced Aligner test corpus) with its
  .lab transcript, against MFA's own ``phones`` tier: boundary error of matched phones,
  share of MFA's phones matched, and the share of 10 ms frames that show the same Rhubarb
  mouth shape (both timelines mapped through configs/maps/english-to-rhubarb.yaml).
* The espeak-ng samples, whose phone times come from the synthesiser itself.

The matching and the metrics below are a plain reference written here (a longest common
subsequence of phone labels by dynamic programming), not the library's code.
"""

import os
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from lipsync import read_timeline
from lipsync.phonetics.phonemes import load_map, map_timeline
from lipsync.speech.align import align

ROOT = Path(__file__).resolve().parents[1]
MFA = ROOT / "tests" / "data" / "conformance" / "mfa"
SAMPLES = ROOT / "samples"
SILENCE = {"", "SIL", "SP", "SPN", "H#", "PAU"}


def plain_phones(timeline):
    """(start, end, ARPAbet without stress) of the non-silent segments."""
    out = []
    for s in timeline:
        label = re.sub(r"[0-2]$", "", s.label).upper()
        if label not in SILENCE:
            out.append((s.start, s.end, label))
    return out


def lcs_pairs(a, b):
    """Index pairs of a longest common subsequence of two label lists (O(len a * len b) DP)."""
    n, m = len(a), len(b)
    L = np.zeros((n + 1, m + 1), np.int32)
    for i in range(n - 1, -1, -1):
        for j in range(m - 1, -1, -1):
            L[i, j] = L[i + 1, j + 1] + 1 if a[i] == b[j] else max(L[i + 1, j], L[i, j + 1])
    pairs, i, j = [], 0, 0
    while i < n and j < m:
        if a[i] == b[j]:
            pairs.append((i, j))
            i, j = i + 1, j + 1
        elif L[i + 1, j] >= L[i, j + 1]:
            i += 1
        else:
            j += 1
    return pairs


def boundary_stats(ours, ref):
    """(share of ref phones matched, mean |boundary error| s, median signed error s)."""
    a, b = plain_phones(ours), plain_phones(ref)
    pairs = lcs_pairs([x[2] for x in a], [x[2] for x in b])
    errors = []
    for i, j in pairs:
        errors += [a[i][0] - b[j][0], a[i][1] - b[j][1]]
    errors = np.array(errors)
    return len(pairs) / len(b), float(np.abs(errors).mean()), float(np.median(errors))


def frame_shapes(timeline, duration, pmap):
    """The mouth shape at the centre of every 10 ms frame (silence and gaps: the rest shape)."""
    centres = (np.arange(int(round(duration * 100))) + 0.5) / 100
    shapes = np.full(len(centres), pmap.silence, dtype=object)
    for s in map_timeline(timeline, pmap):
        shapes[(centres >= s.start) & (centres < s.end)] = s.label
    return shapes


def frame_agreement(ours, ref, duration):
    pmap = load_map("english-to-rhubarb")
    return float(np.mean(frame_shapes(ours, duration, pmap) == frame_shapes(ref, duration, pmap)))


def _align(wav, text):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "yknow" is not in CMUdict
        return align(wav, text, jobs=2)


@pytest.fixture(scope="module")
def mfa_ref():
    return read_timeline(MFA / "acoustic_corpus.TextGrid")


@pytest.fixture(scope="module")
def with_text():
    return _align(MFA / "acoustic_corpus.wav", str(MFA / "acoustic_corpus.lab"))


@pytest.fixture(scope="module")
def without_text():
    return _align(MFA / "acoustic_corpus.wav", None)


def test_reference_metrics_on_a_known_case():
    # the reference itself: one phone shifted by 10 ms, one phone missing
    from lipsync.motion.timeline import Segment, Timeline

    ref = Timeline((Segment(0.0, 0.1, "M"), Segment(0.1, 0.3, "AA1"), Segment(0.3, 0.4, "P")), stated_end=0.5)
    ours = Timeline((Segment(0.0, 0.11, "M"), Segment(0.11, 0.3, "AA")), stated_end=0.5)
    matched, mae, med = boundary_stats(ours, ref)
    assert (matched, mae, med) == pytest.approx((2 / 3, 0.005, 0.005))
    # P (shape A) is rest (X) in ours for 10 of 50 frames; M->AA boundary moved by 1 frame
    assert frame_agreement(ours, ref, 0.5) == pytest.approx(39 / 50)


def test_mfa_corpus_with_transcript(with_text, mfa_ref):
    matched, mae, bias = boundary_stats(with_text.phones, mfa_ref)
    frames = frame_agreement(with_text.phones, mfa_ref, mfa_ref.duration)
    print(f"\nMFA corpus, with transcript: {matched:.1%} of MFA's phones matched, mean |boundary error| "
          f"{mae * 1000:.1f} ms (median signed {bias * 1000:+.1f} ms), {frames:.1%} of frames same shape")
    assert not with_text.recognised and with_text.confidence > 0.8
    assert matched >= 0.90
    assert mae <= 0.020 + 0.001  # goal 20 ms; measured 15.9 ms (17.7 before issue 20)
    assert frames >= 0.85 - 0.005  # goal 85%; measured 88.4%
    # the whole audio is covered and the words are the transcript's
    assert with_text.duration == pytest.approx(mfa_ref.duration, abs=1e-3)
    assert with_text.words.labels()[:5] == ["this", "is", "the", "acoustic", "corpus"]


def test_mfa_corpus_without_transcript(without_text, mfa_ref):
    frames = frame_agreement(without_text.phones, mfa_ref, mfa_ref.duration)
    matched, mae, _ = boundary_stats(without_text.phones, mfa_ref)
    print(f"\nMFA corpus, recognised: {frames:.1%} of frames same shape, {matched:.1%} of phones matched "
          f"(mean |boundary error| {mae * 1000:.1f} ms); words: {' '.join(without_text.words.labels()[:12])} ...")
    assert without_text.recognised and without_text.confidence is None
    assert frames >= 0.75 - 0.01  # goal 75%; measured 82.6%
    assert matched >= 0.5


@pytest.mark.parametrize("name", ["hello", "balloons"])
def test_espeak_samples_phone_times(name):
    ref = read_timeline(SAMPLES / f"{name}.TextGrid")
    al = _align(SAMPLES / f"{name}.wav", str(SAMPLES / f"{name}.lab"))
    matched, mae, bias = boundary_stats(al.phones, ref)
    frames = frame_agreement(al.phones, ref, ref.duration)
    print(f"\n{name}: {matched:.1%} matched, mean |boundary error| {mae * 1000:.1f} ms, "
          f"median signed {bias * 1000:+.1f} ms, {frames:.1%} frames same shape")
    assert matched >= 0.95
    assert mae <= 0.016  # measured 10.4 ms (hello), 13.8 ms (balloons)
    # pocketsphinx places boundaries about one frame early of the synthesiser's events
    # (see BOUNDARY_OFFSET_S in lipsync/speech/align.py); never late
    assert -0.015 <= bias <= 0.0
    assert frames >= 0.80
    # every spoken word found, in order, and the phones of each word inside it
    words = read_timeline(SAMPLES / f"{name}.TextGrid", tier="words")
    assert al.words.labels() == [w.lower() for w in words.labels()]
    for ours, theirs in zip(al.words, words):
        assert abs(ours.start - theirs.start) < 0.05 and abs(ours.end - theirs.end) < 0.06


# --- GRID (issue 20): real sentences of one speaker with GRID's own word alignments ----------

GRID_DIRS = [ROOT / "tests" / "data" / "grid-s1", ROOT / "tests" / "data" / "grid-s1-audio"]
GRID_SILENCE = {"sil", "sp"}


def grid_rows(path):
    """(start s, end s, label) of a GRID .align file: ticks of 1/25000 s, CRLF lines."""
    rows = []
    for line in path.read_bytes().decode("ascii").split("\r\n"):
        if line.strip():
            start, end, label = line.split()
            rows.append((int(start) / 25000, int(end) / 25000, label))
    return rows


def grid_sentences():
    out = []
    for folder in GRID_DIRS:
        for p in sorted(folder.glob("*.align")):
            audio = p.with_suffix(".mpg") if p.with_suffix(".mpg").is_file() else p.with_suffix(".flac")
            rows = grid_rows(p)
            out.append((p.stem, audio, rows, [w for _, _, w in rows if w not in GRID_SILENCE]))
    return out


def align_recording(audio, text):
    from lipsync.speech.align import AlignmentWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        al = align(audio, text)
    return al, [w for w in caught if issubclass(w.category, AlignmentWarning)]


@pytest.fixture(scope="module")
def grid_own():
    return [(name, rows, words, *align_recording(audio, " ".join(words)))
            for name, audio, rows, words in grid_sentences()]


def test_grid_sentences_come_back_as_their_transcripts(grid_own):
    # seven sentences, among them the five that came back as other words before issue 20
    # (lwae8n, bram2n, lgwg3s, lray6p, lwwf8p: "been invited him to now" for "bin red at m
    # two now"); all 40 are in the bench (python -m lipsync.bench --only align-grid)
    names = {name for name, *_ in grid_own}
    assert {"lwae8n", "bram2n", "lgwg3s", "lray6p", "lwwf8p"} <= names and len(names) == 7
    for name, rows, words, al, warned in grid_own:
        assert al.words.labels() == words, name
        assert not al.recognised and not al.skipped and not warned, name
        assert al.confidence >= 0.6, name  # measured 0.87 to 0.99
        # the phones are the words' (letters by their names: "m" = EH M, "y" = W AY)
        if "m" in words:
            i = words.index("m")
            inside = [p.label for p in al.phones if al.words[i].start <= p.start < al.words[i].end]
            assert [re.sub(r"\d", "", p) for p in inside] == ["EH", "M"]


def word_boundary_errors(words, rows):
    """(ours - GRID's, beside a pause?) for the start and end of each of GRID's words."""
    out = []
    ref = [(i, r) for i, r in enumerate(rows) if r[2] not in GRID_SILENCE]
    for seg, (i, (start, end, label)) in zip(words, ref):
        assert seg.label == label
        pause_before = i == 0 or rows[i - 1][2] in GRID_SILENCE
        pause_after = i == len(rows) - 1 or rows[i + 1][2] in GRID_SILENCE
        out += [(seg.start - start, pause_before), (seg.end - end, pause_after)]
    return out


def test_grid_word_boundaries(grid_own):
    # Compared: the start and end of every word. Where GRID has a word on both sides the two
    # aligners face the same change of sound; where it has sil/sp beside the word each one's
    # silence model decides (GRID starts "lay" and "set" 70-360 ms before any voicing or
    # frication, over breaths), so those are looser.
    errors = [e for _, rows, _, al, _ in grid_own for e in word_boundary_errors(al.words, rows)]
    between = np.abs([e for e, pause in errors if not pause])
    at_pause = np.abs([e for e, pause in errors if pause])
    print(f"\nGRID, {len(grid_own)} sentences: between words mean {between.mean() * 1000:.1f} ms, 90th percentile "
          f"{np.percentile(between, 90) * 1000:.1f} ms (n={len(between)}); at pauses mean "
          f"{at_pause.mean() * 1000:.1f} ms (n={len(at_pause)})")
    # Measured on these seven: 20.6 and 50 ms (on all 40 in the bench: 18.5 and 40 ms, the
    # issue's goal of 20 and 40); at pauses 42.5 ms. Before issue 20 five of these seven
    # did not align at all.
    assert between.mean() <= 0.022
    assert np.percentile(between, 90) <= 0.050 + 1e-9
    assert at_pause.mean() <= 0.050


def test_grid_another_sentences_transcript_is_reported_with_a_low_confidence(grid_own):
    from lipsync.speech.align import LOW_CONFIDENCE

    sentences = grid_sentences()
    for i, (name, audio, _, words) in enumerate(sentences):
        other = sentences[(i + 1) % len(sentences)][3]  # the next sentence's transcript
        al, warned = align_recording(audio, " ".join(other))
        assert warned and al.confidence < LOW_CONFIDENCE, (name, other, al.confidence)
        assert f"confidence {al.confidence:.2f}" in str(warned[-1].message)


def test_grid_words_stay_when_the_phone_pass_fails(monkeypatch):
    # the words a transcript's grammar found are never given up: had the phone pass failed
    # (it did on five GRID sentences before issue 20), the words keep the grammar's times
    # and share them among their phones
    import lipsync.speech.align as A

    real = A._aligner()

    class NoPhonePass:
        def __getattr__(self, name):
            return getattr(real, name)

        def set_alignment(self, *args):
            raise RuntimeError("Failed to set up sub-word alignment")

    monkeypatch.setattr(A, "_aligner", lambda: NoPhonePass())
    name, audio, rows, words = next(s for s in grid_sentences() if s[0] == "bram2n")
    al, warned = align_recording(audio, " ".join(words))
    assert al.words.labels() == words and not al.recognised and not warned
    ref = [r for r in rows if r[2] not in GRID_SILENCE]
    assert max(abs(s.start - r[0]) for s, r in zip(al.words, ref)) < 0.08
    # "bin" = B IH N within the word's time, in order
    first = [p for p in al.phones if al.words[0].start <= p.start < al.words[0].end]
    assert [re.sub(r"\d", "", p.label) for p in first] == ["B", "IH", "N"]
    assert first[0].start == al.words[0].start and first[-1].end == al.words[0].end


def _bram2n():
    from lipsync.speech.audio import load_audio

    name, audio, rows, words = next(s for s in grid_sentences() if s[0] == "bram2n")
    return load_audio(audio), " ".join(words)


def _same_alignment(a, b):
    assert a.words == b.words and a.phones == b.phones
    assert a.confidence == b.confidence and a.skipped == b.skipped


def test_the_fit_check_decoded_in_a_worker_is_the_one_decoded_here(monkeypatch):
    # With two or more jobs the phone loop of the fit check runs in a forked worker beside
    # the phone pass (a second core: issue 20's speed); it must give exactly what it gives
    # decoded in this process, and leave no process behind.
    import multiprocessing

    import lipsync.speech.align as A

    monkeypatch.setattr(A, "FIT_WITHOUT_LOOP", float("inf"))  # always ask the loop
    pcm, text = _bram2n()
    here = A.align_samples(pcm, text, jobs=1)
    beside = A.align_samples(pcm, text, jobs=2)
    _same_alignment(here, beside)
    assert 0.6 <= here.confidence <= 1.0
    assert multiprocessing.active_children() == []
    # a wrong transcript takes the relaxed path, which asks the loop again
    other = "lay green with g three soon"
    with pytest.warns(A.AlignmentWarning):
        wrong = [A.align_samples(pcm, other, jobs=jobs) for jobs in (1, 2)]
    _same_alignment(*wrong)
    assert wrong[0].confidence < 0.5


def test_the_loop_is_asked_only_when_the_words_own_scores_leave_doubt(monkeypatch):
    # The transcript's grammar search scores its words against the senones it keeps active
    # (silence and noise among them): words forced onto other sounds score far below
    # FIT_WITHOUT_LOOP, words that were said mostly above it, and then the free phone loop
    # (as much CPU as the alignment) is not decoded at all.
    import lipsync.speech.align as A
    from lipsync.speech.audio import load_audio

    asked = []
    real = A._phone_loop_scores
    monkeypatch.setattr(A, "_phone_loop_scores", lambda pcm: asked.append(1) or real(pcm))
    sentences = grid_sentences()
    own, others = [], []
    for i, (name, audio, rows, words) in enumerate(sentences):
        pcm = A._dither(load_audio(audio))
        speech = A._speech_frames(A._frame_energy(load_audio(audio)))
        for kind, text in (("own", words), ("other", sentences[(i + 1) % len(sentences)][3])):
            scores = []
            A._force_align(pcm, tuple(text), searched=lambda f, w: scores.append(A._own_score(f, w, speech)))
            (own if kind == "own" else others).extend(scores)
    # measured on these 7: own -21.3 to -11.3 (6 at -20 or above), others' -47.5 to -30.8
    # (2 find no path at all)
    assert min(own) > max(others) + 4.0
    assert max(others) < A.FIT_WITHOUT_LOOP
    assert sum(s >= A.FIT_WITHOUT_LOOP for s in own) >= 5
    # a clear one aligns without the loop: its confidence is the words' and speech shares
    name, audio, rows, words = next(s for s in sentences if s[0] == "bram2n")
    asked.clear()
    al = A.align_samples(load_audio(audio), " ".join(words), jobs=1)
    assert not asked and al.words.labels() == words and al.confidence >= 0.9
    # another sentence's transcript is judged by the loop, and reported
    with pytest.warns(A.AlignmentWarning):
        al = A.align_samples(load_audio(audio), " ".join(sentences[0][3]), jobs=1)
    assert asked and al.confidence < 0.5


def test_a_fit_check_worker_that_dies_is_replaced_by_decoding_here(monkeypatch):
    import os as _os

    import lipsync.speech.align as A

    pcm, text = _bram2n()
    here = A.align_samples(pcm, text, jobs=1)
    # the worker is forked, so it runs this module's (patched) function
    monkeypatch.setattr(A, "_loop_worker", lambda *args: _os._exit(3))
    _same_alignment(here, A.align_samples(pcm, text, jobs=2))


def test_sound_onset_finds_where_a_band_starts():
    # the bench's independent reference at pauses (sentence-initial "lay": voicing under
    # 400 Hz; "set": frication at 4-8 kHz): a 200 Hz tone from 0.5 s, and 4-8 kHz noise
    # from 0.7 s after a low hum that must not count
    from lipsync.bench.align import sound_onset

    sr, rng = 16000, np.random.default_rng(0)
    t = np.arange(sr) / sr
    tone = np.where(t >= 0.5, 8000 * np.sin(2 * np.pi * 200 * t), 0.0) + rng.normal(0, 3, sr)
    assert abs(sound_onset(tone.astype(np.int16), 80, 400) - 0.5) <= 0.025
    hiss = rng.normal(0, 3000, sr)
    spectrum = np.fft.rfft(hiss)
    spectrum[np.fft.rfftfreq(sr, 1 / sr) < 4000] = 0
    hiss = np.fft.irfft(spectrum, sr) * (t >= 0.7)
    hum = 3000 * np.sin(2 * np.pi * 150 * t) * (t >= 0.3)
    x = (hiss + hum + rng.normal(0, 3, sr)).astype(np.int16)
    assert abs(sound_onset(x, 4000, 8000) - 0.7) <= 0.025
    assert sound_onset(np.zeros(sr, np.int16) + 1, 80, 400) is None
