"""The selection's exact rules on ``visemes/grid-s1`` (issue 35): a frame the sequencer shows
closed (P/B/M) shows a closed sample of that viseme, even where a run of another viseme's
closed frames could continue into it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lipsync import Animator, Bank
from lipsync._data import default_bank_dir
from lipsync.selection.select import CLOSED

DATA = Path(__file__).resolve().parent / "data" / "grid-s1"


@pytest.mark.parametrize("clip", ["bbwm5s", "prap6p"])   # both once showed a resting X on an A closure
@pytest.mark.parametrize("sound", [False, True])
def test_a_closure_shows_its_own_visemes_closed_lips(clip, sound):
    bank = Bank.load(default_bank_dir().parent / "grid-s1")
    anim = Animator(bank, DATA / f"{clip}.align", fps=25, samples="on", audio=DATA / f"{clip}.mpg" if sound else None)
    sp = anim.sample_path
    sel, vis, s = sp.selection, sp.selector.vis, sp.samples
    shut = np.nonzero(sel.target.closed)[0]
    assert len(shut) >= 5
    for t in shut:
        k = sel.samples[t]
        assert vis[k] == sel.target.viseme[t], (t, sel.target.viseme[t], vis[k], s.labels[k])
        assert s.opening[k] <= CLOSED
