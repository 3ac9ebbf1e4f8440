"""Motion-blurred samples lose to crisp ones (issue 35): :mod:`lipsync.samples.quality`
against a Gaussian blur made here, and the selection on ``visemes/grid-s1`` with half its
footage blurred by the test."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from lipsync import Animator, Bank
from lipsync._data import default_bank_dir
from lipsync.samples import Samples, load_samples
from lipsync.samples.quality import lip_sharpness, softness
from lipsync.selection import select as S

ROOT = Path(__file__).resolve().parents[1]
GRID_BANK = default_bank_dir().parent / "grid-s1"
SENTENCE = ROOT / "tests" / "data" / "grid-s1" / "lwae8n.align"   # not one of the bank's sentences


def _texture(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return cv2.resize(rng.integers(0, 255, (12, 16, 3)).astype(np.uint8), (64, 48), interpolation=cv2.INTER_CUBIC)


def _lap_var(img: np.ndarray) -> float:
    return float(cv2.Laplacian(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), cv2.CV_64F).var())


def test_softness_is_the_log_sharpness_lost_to_a_blur():
    crisp = [_texture(s) for s in range(3)]
    soft = cv2.GaussianBlur(crisp[0], (0, 0), 1.5)
    # the lips' box covers the whole 64x48 crop once its margin is added (crop = bank pixels)
    lips = np.tile(np.array([[2.0, 2.0], [61.0, 45.0]]), (4, 22, 1))
    s = SimpleNamespace(crops=np.stack(crisp + [soft]), lips=lips, opening=np.full(4, 0.05),
                        affine=np.tile([[1.0, 0, 0], [0, 1.0, 0]], (4, 1, 1)))
    logs = np.log(np.array([_lap_var(c) for c in crisp + [soft]]) + 1.0)
    assert lip_sharpness(s) == pytest.approx(np.exp(logs) - 1.0, rel=1e-9)
    got = softness(s)
    # one opening for all: the fit is the mean log sharpness, and only what falls below it counts
    assert got == pytest.approx(np.maximum(0.0, logs.mean() - logs), abs=1e-9)
    assert got[3] > 0.5 and got[3] == got.max() and got[:3].max() < 0.2   # the blur took most edges


def test_softness_follows_the_opening():
    """Parted lips have more edges: a sample as sharp as its opening's usual is not soft,
    however it compares with samples of another opening."""
    s = SimpleNamespace(opening=np.array([0.0, 0.0, 0.2, 0.2, 0.2]))
    sharp = np.exp([4.0, 4.2, 5.0, 5.2, 4.4]) - 1.0
    got = softness(s, sharp)
    assert got[0] == pytest.approx(0.1) and got[1] == 0.0
    assert got[4] == pytest.approx((5.0 + 5.2 + 4.4) / 3 - 4.4)


#: The selection's weight as shipped (the tests below set it).
BLUR = S.WEIGHTS["blur"]


def _chosen(bank, samples, anim, weight, monkeypatch):
    monkeypatch.setitem(S.WEIGHTS, "blur", weight)
    sel = S.Selector(samples, anim.pmap, bank.rest, closures=anim.pmap.closures)
    return sel.select(anim.specs, anim.phones, anim.fps)


def test_the_selection_takes_the_crisp_footage(monkeypatch):
    bank = Bank.load(GRID_BANK)
    s = load_samples(bank)
    anim = Animator(bank, SENTENCE, fps=25, samples="off")
    # blind to blur, the selection's choice does not depend on the crops: blur the five
    # sentences it took most from, and it now stands on blurred footage
    blind = _chosen(bank, s, anim, 0.0, monkeypatch)
    used = np.bincount(s.table["clip"][blind.samples], minlength=len(s.table["clips"]))
    blurred = np.isin(s.table["clip"], np.argsort(-used)[:5])
    crops = s.crops.copy()
    for k in np.nonzero(blurred)[0]:
        crops[k] = cv2.GaussianBlur(crops[k], (0, 0), 1.0)
    half = Samples(table=s.table, crops=crops, path=s.path)
    off = _chosen(bank, half, anim, 0.0, monkeypatch)
    on = _chosen(bank, half, anim, BLUR, monkeypatch)
    assert off.samples.tolist() == blind.samples.tolist()
    share_off, share_on = blurred[off.samples].mean(), blurred[on.samples].mean()
    assert share_off > 0.6
    assert share_on < 0.5 * share_off        # seeing the blur, the crisp half is preferred
    # and the chosen lips still follow the target as closely
    r_off = np.corrcoef(s.opening[off.samples], off.target.opening)[0, 1]
    r_on = np.corrcoef(s.opening[on.samples], on.target.opening)[0, 1]
    assert r_on > r_off - 0.05, (r_on, r_off)


def test_a_closure_pays_no_blur(monkeypatch):
    """Lips pressing for P/B/M move fast, so the footage's pressed frames are its soft ones: a
    closure frame's costs are the same whatever the blur weight; any other frame's grow by
    the weight times each candidate's softness."""
    bank = Bank.load(GRID_BANK)
    s = load_samples(bank)
    anim = Animator(bank, SENTENCE.with_name("bbwm5s.align"), fps=25, samples="off")   # "bin blue with m ..."
    sel = S.Selector(s, anim.pmap, bank.rest, closures=anim.pmap.closures)
    tg = sel.select(anim.specs, anim.phones, anim.fps).target
    shut, open_ = np.nonzero(tg.closed)[0], np.nonzero(~tg.closed & ~tg.rest)[0]
    assert len(shut) and len(open_)
    ids = np.arange(len(s))
    for t, exempt in ((shut[0], True), (open_[len(open_) // 2], False)):
        monkeypatch.setitem(S.WEIGHTS, "blur", 0.0)
        without = sel.target_cost(ids, tg, int(t))
        monkeypatch.setitem(S.WEIGHTS, "blur", 7.0)
        with_ = sel.target_cost(ids, tg, int(t))
        expected = np.zeros(len(s)) if exempt else 7.0 * softness(s)
        assert with_ - without == pytest.approx(expected, abs=1e-9)
    assert softness(s).max() > 0.2                        # the bank has soft samples to charge
