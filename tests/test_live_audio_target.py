"""A live session fed audio gives its sample windows the bank's audio lip target (issue 35 items 2 and 4).

* the features kept as the audio arrives (:class:`lipsync.speech.features.RunningFeatures`)
  are the offline features of the same audio, frame for frame, and their running
  statistics over the frames heard are the offline per-utterance normalisation of exactly
  those frames (so once the whole utterance is heard, the offline normalisation);
* a frame is fixed only once its ±3 frames of context are final (200 ms look-ahead);
* a session fed a sentence's audio predicts, frame by frame from what it has heard, the
  openings the offline prediction of the whole sentence gives, and selects samples that
  follow it closer than the phones' target alone; without the lip model it selects as with
  the phones' target alone (pushed events: tests/test_live_samples.py, unchanged).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lipsync import Bank
from lipsync._data import default_bank_dir
from lipsync.live import LiveAnimator
from lipsync.live import samples as LS
from lipsync.live.audio import BLOCK, RATE
from lipsync.speech.audio import load_audio
from lipsync.speech.features import RunningFeatures, frame_features, normalised

AUDIO = Path(__file__).resolve().parent / "data" / "grid-s1-audio"
GRID_BANK = default_bank_dir().parent / "grid-s1"


@pytest.fixture(scope="module")
def pcm():
    return load_audio(AUDIO / "bram2n.flac")


@pytest.fixture(scope="module")
def bank():
    return Bank.load(GRID_BANK)


def test_running_features_are_the_offline_features_and_statistics_of_what_was_heard(pcm):
    x = pcm[:int(2.0 * RATE)]
    offline = frame_features(x, RATE, 25.0)
    run = RunningFeatures(RATE, 25.0)
    cuts = np.cumsum(np.random.default_rng(1).integers(1, 900, 200))   # uneven chunks
    at = 0
    for c in cuts[cuts < len(x)].tolist() + [len(x)]:
        run.add(x[at:c])
        at = c
        k = len(run)
        # a frame is final once its last window (centred 10 ms before its end: 40 ms frames,
        # 10 ms hops) is whole: 2.5 ms past the frame's end (or one frame later, where the
        # offline rule's float rounding gives a window on a frame's edge to the frame before)
        ideal = max(0, (at - 40) // 640)
        assert min(50, ideal - 1) <= k <= min(50, ideal)
        if k:
            assert np.allclose(run.rows(0, k), offline[:k], atol=1e-9)
            assert np.allclose(run.normalised(0, k), normalised(offline[:k]), atol=1e-9)
    run.finish(50)
    assert len(run) == 50
    assert np.allclose(run.normalised(0, 50), normalised(offline), atol=1e-9)


def _feed(bank, pcm, spy=None):
    live = LiveAnimator(bank, fps=25, prepare=False, samples="on")
    if spy is not None:
        spy(live)
    for i in range(0, len(pcm), BLOCK):
        due = live.feed_audio(pcm[i:i + BLOCK], RATE)
        if due and live.samples.features is not None:   # the context of the frame fixed is heard
            assert len(live.samples.features) >= due[-1] + 1 + live.samples.model.context
    live.finish_audio()
    return live


def test_a_live_session_fed_a_sentence_selects_for_the_speechs_prediction(bank, pcm):
    from lipsync.pipeline.samplepath import speech_prediction

    seen = {}

    def spy(live):
        fix = live.samples.selection.fix

        def record(specs, timeline, base, key, audio=None, share=0.0):
            c = len(live.samples.selection)
            if audio is not None:
                seen[c] = (float(audio[c - base, 0]), share)
            return fix(specs, timeline, base, key, audio, share)
        live.samples.selection.fix = record

    live = _feed(bank, pcm, spy)
    n = len(live.samples)
    samples = live.samples.shared.samples
    offline = speech_prediction(samples, pcm, 25.0, n)[:, 0]
    # heard whole, the running prediction is the offline one
    assert np.allclose(live.samples.prediction(0, n)[:, 0], offline, atol=1e-9)
    # frame by frame, from the audio heard by then (running statistics): close to it
    frames = sorted(seen)
    assert len(frames) >= n - 2 and {s for _, s in seen.values()} == {LS.LIVE_AUDIO_SHARE}
    streamed = np.array([seen[f][0] for f in frames])
    # (bram2n: r 0.89; early frames are normalised by the leading silence's statistics alone)
    assert np.corrcoef(streamed, offline[frames])[0, 1] > 0.8
    # the chosen samples follow the prediction closer than with the phones' target alone
    keep = LS.LIVE_AUDIO_SHARE
    try:
        LS.LIVE_AUDIO_SHARE = 0.0
        plain = _feed(bank, pcm)
    finally:
        LS.LIVE_AUDIO_SHARE = keep
    assert plain.samples.features is None
    op = samples.opening

    def r(live):
        return np.corrcoef(op[np.array(live.samples.selection.path)], offline)[0, 1]
    assert r(live) > r(plain) + 0.05
    # a bank without the lip model: the phones' target alone, sample for sample
    bare = []

    def no_model(live):
        live.samples.model = None
        bare.append(live)
    _feed(bank, pcm, no_model)
    assert bare[0].samples.features is None
    assert bare[0].samples.selection.path == plain.samples.selection.path
