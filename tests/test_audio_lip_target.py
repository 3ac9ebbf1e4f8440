"""The audio-driven lip target (issue 35): per-frame audio features, the bank's ridge lip
model, its place in samples.npz and the selection's target.

Features are checked on synthetic sound whose answer is known (a tone burst's frames, a
tone's mel band by the mel formula written here, a pulse train's voicing against noise),
the regression on data made from a known linear map, the stored model against
``lipsync check``, and the shipped GRID s1 bank's model on a sentence it never saw against
dlib's landmarks (tests/data/grid-s1/dlib68.json, an independent tracker).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from lipsync.samples import lipmodel as L
from lipsync.speech import features as F

SR = 16000
GRID = Path(__file__).parent / "data" / "grid-s1"


def _tone(seconds: float, hz: float, start: float, end: float, amp: float = 0.5) -> np.ndarray:
    t = np.arange(int(seconds * SR)) / SR
    return np.where((t >= start) & (t < end), amp * np.sin(2 * np.pi * hz * t), 0.0)


def test_a_tone_bursts_frames_carry_its_energy():
    # 25 fps: frame i spans [i/25, (i+1)/25); the burst fills frames 10-14 (0.40-0.60 s)
    f = F.frame_features(_tone(1.0, 440.0, 0.40, 0.60), SR, fps=25)
    assert f.shape == (25, F.MELS + 2)
    e = f[:, F.ENERGY]
    loud = e[11:14]
    assert loud.min() > e[:9].max() + 10 and loud.min() > e[16:].max() + 10  # > 40 dB (log power) above silence
    # a steady tone's frames agree with each other
    assert np.ptp(loud) < 0.1
    # halving the amplitude lowers log power by log(4)
    g = F.frame_features(_tone(1.0, 440.0, 0.40, 0.60, amp=0.25), SR, fps=25)
    assert g[12, F.ENERGY] == pytest.approx(e[12] - np.log(4.0), abs=0.01)


def test_a_tone_lands_in_the_mel_band_whose_centre_is_nearest():
    mel = lambda hz: 2595.0 * np.log10(1.0 + hz / 700.0)  # HTK's formula, written out here
    centres = 700.0 * (10 ** (np.linspace(mel(F.FMIN), mel(F.FMAX), F.MELS + 2)[1:-1] / 2595.0) - 1.0)
    for hz in (300.0, 1000.0, 3000.0):
        f = F.frame_features(_tone(0.4, hz, 0.0, 0.4), SR, fps=25)
        assert int(np.argmax(f[5, :F.MELS])) == int(np.argmin(np.abs(centres - hz))), hz


def test_voicing_tells_a_pulse_train_from_noise():
    pulses = np.zeros(SR // 2)
    pulses[:: SR // 120] = 1.0  # 120 Hz glottal-like pulses
    noise = np.random.default_rng(0).normal(scale=0.1, size=SR // 2)
    v_pulse = F.frame_features(pulses, SR, fps=25)[2:-2, F.VOICING]
    v_noise = F.frame_features(noise, SR, fps=25)[2:-2, F.VOICING]
    assert v_pulse.min() > 0.9 and v_noise.max() < 0.4


def test_int16_and_float_samples_give_the_same_features():
    x = _tone(0.5, 700.0, 0.1, 0.3)
    a = F.frame_features(x, SR, fps=30)
    b = F.frame_features(np.round(x * 32768).astype(np.int16), SR, fps=30)
    assert np.allclose(a[:, F.MELS:], b[:, F.MELS:], atol=1e-3)
    # the tone's own bands in its frames (far from 700 Hz there is only int16's rounding noise)
    strong = a[6, :F.MELS] > a[6, :F.MELS].max() - 5.0
    assert strong.sum() >= 3 and np.allclose(a[4:9, :F.MELS][:, strong], b[4:9, :F.MELS][:, strong], atol=1e-2)


def _synthetic(seed: int, clips: int = 3, frames: int = 200):
    """Clips of random feature rows and a table whose opening and width are a known linear map
    of the per-clip normalised features, with the previous frame's energy (context) in it."""
    rng = np.random.default_rng(seed)
    feats = [rng.normal(size=(frames, L.FEATURES)) * rng.uniform(0.5, 3.0, L.FEATURES) + rng.normal(
        size=L.FEATURES) for _ in range(clips)]
    opening, width = [], []
    for f in feats:
        z = F.normalised(f)
        prev = np.r_[z[:1], z[:-1]]
        opening.append(0.12 + 0.03 * z[:, F.ENERGY] + 0.02 * prev[:, F.ENERGY] - 0.01 * z[:, 3])
        width.append(0.9 - 0.02 * z[:, F.VOICING])
    table = {"clip": np.repeat(np.arange(clips), frames), "frame": np.tile(np.arange(frames), clips),
             "opening": np.concatenate(opening), "width": np.concatenate(width)}
    return feats, table


def test_the_regression_recovers_a_known_linear_map():
    feats, table = _synthetic(1)
    model = L.fit(feats, table, context=1)
    w = model.weights.reshape(3, L.FEATURES, 2)  # rows: frame t-1, t, t+1
    assert w[1, F.ENERGY, 0] == pytest.approx(0.03, abs=2e-3)
    assert w[0, F.ENERGY, 0] == pytest.approx(0.02, abs=2e-3)
    assert w[1, 3, 0] == pytest.approx(-0.01, abs=2e-3)
    assert w[1, F.VOICING, 1] == pytest.approx(-0.02, abs=2e-3)
    assert model.bias == pytest.approx([0.12, 0.9], abs=5e-3)
    # and on a clip it never saw, through the same normalisation
    new, truth = _synthetic(2, clips=1)
    x = F.stacked(F.normalised(new[0]), 1)
    r = np.corrcoef(x @ model.weights[:, 0] + model.bias[0], truth["opening"])[0, 1]
    assert r > 0.99


def test_the_ridge_strength_is_chosen_by_leaving_clips_out():
    rng = np.random.default_rng(3)
    xs = [rng.normal(size=(60, 40)) for _ in range(4)]
    ys = [np.c_[x[:, 0] + rng.normal(scale=3.0, size=60), x[:, 1]] for x in xs]  # noisy: shrinking helps
    _, _, lam = L.ridge_fit(xs, ys, lambdas=(1e-6, 100.0))
    assert lam == 100.0


def test_a_stored_model_round_trips_and_bad_ones_are_named():
    m = L.LipModel(np.arange(L.FEATURES * 5 * 2, dtype=float).reshape(-1, 2), np.array([0.1, 0.8]), 2)
    arrays = m.arrays()
    assert L.problem(arrays) is None
    back = L.LipModel.from_table(arrays)
    assert back.context == 2 and np.array_equal(back.weights, m.weights) and np.allclose(back.bias, [0.1, 0.8])
    assert L.LipModel.from_table({}) is None and L.problem({}) is None
    bad = dict(arrays, lip_context=np.array(3, np.int32))
    assert "context of 3" in L.problem(bad)
    assert "come together" in L.problem({"lip_weights": arrays["lip_weights"]})


@pytest.fixture(scope="module")
def grid_samples():
    from lipsync.banks.bank import Bank
    from lipsync._data import default_bank_dir
    from lipsync.pipeline.samplepath import bank_samples

    bank = Bank.load(Path(default_bank_dir()).parent / "grid-s1")
    return bank, bank_samples(bank, "on")


def test_the_shipped_grid_bank_predicts_an_unseen_sentences_lips_from_its_sound(grid_samples):
    """prap6p is not one of the bank's sentences; dlib's landmarks (every third frame) are the reference."""
    from lipsync.pipeline.samplepath import speech_prediction

    bank, samples = grid_samples
    assert "prap6p.mpg" not in samples.clips.tolist()
    ref = json.loads((GRID / "dlib68.json").read_text())
    video = ref["videos"]["prap6p.mpg"]
    idx = np.array(video["frames"], int)
    pts = np.array(video["points"], dtype=float)
    opening = np.linalg.norm(pts[:, 66] - pts[:, 62], axis=1) / np.linalg.norm(
        pts[:, 36:42].mean(1) - pts[:, 42:48].mean(1), axis=1)  # dlib's inner lips over the eye centres' distance
    pred = speech_prediction(samples, GRID / "prap6p.mpg", 25.0, int(idx.max()) + 1)
    ok = np.isfinite(opening)
    assert np.corrcoef(pred[idx[ok], 0], opening[ok])[0, 1] > 0.6


def test_the_target_blends_the_speechs_prediction_and_a_bank_without_the_model_selects_as_before(grid_samples):
    from dataclasses import replace as dc_replace

    from lipsync.motion.timeline import Segment, Timeline
    from lipsync.pipeline.animator import Animator
    from lipsync.pipeline.samplepath import speech_prediction, _selector
    from lipsync.samples import Samples
    from lipsync.selection import select as S

    bank, samples = grid_samples
    tl = Timeline((Segment(0.0, 0.3, "sil"), Segment(0.3, 0.5, "AA"), Segment(0.5, 0.7, "M"),
                   Segment(0.7, 0.9, "IY"), Segment(0.9, 1.2, "sil")), kind="phoneme")
    anim = Animator(bank, tl, fps=25, samples="off")
    speech = (_tone(1.2, 200.0, 0.3, 0.5) + _tone(1.2, 300.0, 0.7, 0.9)) * 0.5
    sel = _selector(samples, anim.pmap, bank.rest)
    plain = sel.select(anim.specs, tl, 25.0)
    pred = speech_prediction(samples, speech, 25.0, len(anim.specs))
    assert pred.shape == (len(anim.specs), 2)
    heard = sel.select(anim.specs, tl, 25.0, audio=pred)
    a = pred.mean(0) + S.AUDIO_GAIN * (pred - pred.mean(0))
    s_open, s_width = S.AUDIO_SHARE
    assert np.allclose(heard.target.opening, (1 - s_open) * plain.target.opening + s_open * a[:, 0])
    assert np.allclose(heard.target.width, (1 - s_width) * plain.target.width + s_width * a[:, 1])
    # closures and rest stay exact whatever the sound says
    assert np.array_equal(heard.target.closed, plain.target.closed) and np.array_equal(heard.target.rest,
                                                                                        plain.target.rest)
    assert (samples.opening[heard.samples[plain.target.closed]] <= S.CLOSED).all()
    # a table without the model's arrays: no prediction, the same selection as today's
    bare = Samples(table={k: v for k, v in samples.table.items() if not k.startswith("lip_")}, crops=samples.crops,
                   path=samples.path)
    assert speech_prediction(bare, speech, 25.0, len(anim.specs)) is None
    again = _selector(bare, anim.pmap, bank.rest).select(anim.specs, tl, 25.0, audio=None)
    assert np.array_equal(again.samples, plain.samples)


def test_check_names_a_table_whose_model_is_not_finite(tmp_path, capsys):
    from lipsync._data import default_bank_dir
    from lipsync.cli import main as lipsync
    from lipsync.samples import read_table

    src = Path(default_bank_dir()).parent / "grid-s1"
    b = tmp_path / "bank"
    shutil.copytree(src, b, ignore=shutil.ignore_patterns(".lipsync"))
    t = read_table(b / "samples.npz")
    assert "lip_weights" in t
    t["lip_weights"][5, 0] = np.inf
    with open(b / "samples.npz", "wb") as fh:
        np.savez(fh, **t)
    assert lipsync(["check", str(b)]) == 2
    err = capsys.readouterr().err
    assert "samples.npz" in err and "'lip_weights'" in err and "finite" in err and "Traceback" not in err


def test_an_animator_given_the_speech_selects_for_it(grid_samples):
    """``Animator(..., audio=)`` (what render_clip, from_audio and dub hand on): the sample path
    predicts from that sound; without it, today's target."""
    from lipsync.pipeline.animator import Animator
    from lipsync.readers.grid import read_words
    from lipsync.speech.phonetise import words_to_phones

    bank, samples = grid_samples
    p = GRID / "prap6p.align"  # GRID's own word times, split into phones (no aligner run)
    phones = words_to_phones(read_words(str(p), p.read_bytes()))
    heard = Animator(bank, phones, fps=25, samples="on", audio=GRID / "prap6p.mpg")
    plain = Animator(bank, phones, fps=25, samples="on")
    assert plain.sample_path.audio_prediction is None
    pred = heard.sample_path.audio_prediction
    assert pred.shape == (len(heard), 2)
    assert not np.allclose(heard.sample_path.selection.target.opening, plain.sample_path.selection.target.opening)
    assert [s.alpha for s in heard.specs] == [s.alpha for s in plain.specs]  # the schedule is the phones'
