"""The selection's dynamic programme and frame plan against references written here (issue 35)."""

from __future__ import annotations

import itertools
from types import SimpleNamespace

import numpy as np
import pytest

from lipsync.composite.samples import SampleCompositor
from lipsync.selection import Viterbi, best_path, frame_plan
from lipsync.selection.select import Tree, positions


def _brute(cands, targets, join):
    """The cheapest path by trying every one."""
    best, arg = np.inf, None
    for pick in itertools.product(*[range(len(c)) for c in cands]):
        cost = sum(targets[t][k] for t, k in enumerate(pick))
        cost += sum(join(np.array([cands[t - 1][pick[t - 1]]]), np.array([cands[t][pick[t]]]))[0, 0]
                    for t in range(1, len(pick)))
        if cost < best - 1e-12:
            best, arg = cost, [cands[t][k] for t, k in enumerate(pick)]
    return best, arg


@pytest.mark.parametrize("seed", range(6))
def test_viterbi_equals_brute_force_on_random_lattices(seed):
    rng = np.random.default_rng(seed)
    n_ids = 9
    table = rng.uniform(0, 2, (n_ids, n_ids))
    table[np.arange(n_ids - 1), np.arange(1, n_ids)] = 0.0  # consecutive ids join free, as source runs do

    def join(a, b):
        return table[np.ix_(a, b)]

    cands = [rng.choice(n_ids, size=rng.integers(1, 4), replace=False) for _ in range(6)]
    targets = [rng.uniform(0, 1, len(c)) for c in cands]
    cost, ref = _brute(cands, targets, join)
    got = best_path(cands, targets, join)
    assert got == ref
    v = Viterbi()
    for t, (c, tc) in enumerate(zip(cands, targets)):
        v.step(c, tc, None if t == 0 else join(v.last, c))
    assert v.cost == pytest.approx(cost)


def test_a_free_run_wins_over_cheaper_targets_that_need_joins():
    # ids 0-1-2-3 a source run; 10-13 each a little cheaper per frame but every step a join
    succ = {0: 1, 1: 2, 2: 3}

    def join(a, b):
        return np.array([[0.0 if succ.get(int(x)) == int(y) else 0.5 for y in b] for x in a])

    cands = [np.array([t, 10 + t]) for t in range(4)]
    targets = [np.array([0.2, 0.0]) for _ in range(4)]
    assert best_path(cands, targets, join) == [0, 1, 2, 3]           # 0.8 against 1.5
    targets = [np.array([0.9, 0.0]) for _ in range(4)]
    assert best_path(cands, targets, join) == [10, 11, 12, 13]       # 3.6 against 1.5


def test_frame_plan_morphs_only_across_joins_and_never_exact_frames():
    succ = np.array([1, 2, 3, -1, 5, 6, 7, -1])
    src, dst, alpha = frame_plan(np.array([0, 1, 4, 5, 6, 2, 3]), succ, join_frames=2)
    assert dst.tolist() == [0, 1, 4, 5, 6, 2, 3]
    # frame 2 joins (1 -> 4): morphs from the old run continued (2, then 3) to the new one
    assert src.tolist() == [0, 1, 2, 3, 6, 7, 7]      # 6 -> 2 joins too; 7 ends its run: held
    assert alpha.tolist() == pytest.approx([1, 1, 1 / 3, 2 / 3, 1, 1 / 3, 2 / 3])
    exact = np.zeros(7, bool)
    exact[2] = True
    src, _, alpha = frame_plan(np.array([0, 1, 4, 5, 6, 2, 3]), succ, exact, join_frames=2)
    assert alpha[2] == 1.0 and src[2] == 4       # a closure frame shows its sample as it is


def test_positions_within_each_phone():
    lab = np.array(["a", "a", "a", "b", "b", "a"])
    assert positions(lab).tolist() == pytest.approx([1 / 6, 0.5, 5 / 6, 0.25, 0.75, 0.5])
    assert positions(lab, np.array([0, 0, 1, 0, 0, 0], bool)).tolist() == pytest.approx(
        [0.25, 0.75, 0.5, 0.25, 0.75, 0.5])


def test_tree_finds_the_exact_nearest_neighbours():
    rng = np.random.default_rng(3)
    pts = rng.uniform(0, 1, (500, 2))
    q = np.array([0.3, 0.6])
    _, idx = Tree(pts).query(q, k=7)
    assert idx.tolist() == np.argsort(((pts - q) ** 2).sum(1))[:7].tolist()


def _bar_sample(y: int):
    """A 40x60 grey crop with a dark horizontal bar (the 'lips') at row y, lip points on it."""
    crop = np.full((40, 60, 3), 200, np.uint8)
    crop[y - 1:y + 2, 10:50] = 40
    xs = np.linspace(10, 49, 11)
    contour = np.c_[xs, np.full(11, float(y))]
    return crop, np.concatenate([contour] * 4)


def test_a_join_morphs_between_the_two_samples():
    (ca, la), (cb, lb) = _bar_sample(12), _bar_sample(24)
    samples = SimpleNamespace(crops=np.stack([ca, cb]), affine=np.array([[[1.0, 0, 0], [0, 1.0, 0]]] * 2),
                              lips=np.stack([la, lb]))
    mask = np.zeros((40, 60), np.float32)
    mask[2:38, 2:58] = 1.0
    sc = SampleCompositor(samples, mask)
    out = np.zeros((40, 60, 3), np.uint8)
    rows = {}
    for alpha in (0.0, 0.5, 1.0):
        sc.morph(0, 1, alpha, out)
        dark = np.clip(200.0 - out[2:38, 20:40, 0].astype(float).mean(axis=1), 0, None)  # inside the mask box
        rows[alpha] = 2 + float((dark * np.arange(len(dark))).sum() / dark.sum())       # the bar's centre row
    assert rows[0.0] == pytest.approx(12, abs=0.1) and rows[1.0] == pytest.approx(24, abs=0.1)
    assert rows[0.5] == pytest.approx(18, abs=1.0)   # the bar moved half way, not two half-dark bars
    sc.morph(0, 1, 0.5, out)
    assert out[12, 30, 0] > 150 and out[24, 30, 0] > 150
