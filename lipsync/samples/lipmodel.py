"""The audio lip model: the lip opening and width a frame's sound predicts, learnt from the bank's footage.

A bank made from video has its speaker's sound and, per sample, the tracked lips. A ridge
regression (numpy's least squares; no new dependency) maps each frame's audio features
(:mod:`lipsync.speech.features`: log mel energies, energy, voicing, normalised per
utterance, with :data:`CONTEXT` frames either side) to the sample's opening and width; it
is fitted when the samples are written (:func:`fit_clips`) and stored in ``samples.npz``
(``lip_weights``, ``lip_bias``, ``lip_context``: :data:`ARRAYS`). At render time
:meth:`LipModel.predict` runs it on the new speech and :func:`lipsync.selection.select.make_target`
blends the prediction into the selection's target: the phones say *which* shape, the sound
says *when* and *how far* the lips open (Wang, Qian, Soong et al. 2010: a lip trajectory
predicted from the speech guides the sample selection). A bank without the arrays selects
as before.

Examples
--------
>>> rng = np.random.default_rng(0)
>>> x = rng.normal(size=(400, FEATURES)); y = np.c_[x[:, 0] * 0.1 + 0.2, x[:, 1] * -0.05 + 1.0]
>>> w, b, lam = ridge_fit([x[:200], x[200:]], [y[:200], y[200:]], lambdas=(1e-6,))
>>> bool(np.allclose(w[:2], [[0.1, 0.0], [0.0, -0.05]], atol=1e-6)), np.round(b, 3).tolist()
(True, [0.2, 1.0])
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..speech.features import MELS, frame_features, normalised, stacked

#: Feature columns per frame (mel bands, energy, voicing).
FEATURES = MELS + 2
#: Frames of context either side: the lips open ahead of the sound and close after it.
#: Prediction r on GRID s1's tuning sentences (held_out()[18:30], bank of the ten bank
#: sentences): 2 / 3 / 4 frames gave 0.760 / 0.758 / 0.756 (more context, more weights than
#: 30 s of footage pins down); adding deltas (0.759 / 0.756 / 0.753) or 13 cepstra in place
#: of the mel bands (0.751 / 0.747 / 0.740) did no better. 3 keeps 120 ms either side.
#: Round 5 (issue 35), prediction r on the same sentences: a linear model of these features
#: is at its ceiling. Smoothing the prediction (Gaussian, sigma 1 / 1.5 / 2 frames: 0.762 /
#: 0.750 / 0.730; real openings peak for 1-3 frames, and a shift of one frame costs 0.06);
#: trajectory generation (static, delta and delta-delta predicted, the smooth path solved
#: for, Tokuda's MLPG: 0.763); spectral centroids, an F1 peak, zero crossings (0.741-0.748);
#: k nearest bank frames in whitened feature space (0.62-0.69); context 5 / 7 with more
#: footage (leave-one-sentence-out over the 22 sentences outside the judged ones: 0.755 /
#: 0.758 against 3's 0.756). Footage helps a little, then levels: 5 / 10 / 15 / 21
#: training sentences gave 0.704 / 0.735 / 0.753 / 0.751 (random splits of those 22).
#: Nonlinear models of the same features (scikit-learn, scratch only), trained on the ten
#: bank sentences: extra trees 0.782, an RBF kernel ridge 0.778, a 64-unit MLP (5 seeds
#: averaged) 0.776, their average 0.792, against the ridge's 0.757; but as the target's
#: share the chosen samples' r moved only 0.783 -> 0.784-0.791: not worth a dependency or a
#: hand-written network.
CONTEXT = 3
#: The most context a stored model may have (a bound on the arrays ``lipsync check`` reads).
MAX_CONTEXT = 12
#: Ridge strengths tried; the one with the best leave-one-clip-out r of the opening is kept
#: (GRID s1's bank: 30).
LAMBDAS = (10.0, 30.0, 100.0, 300.0, 1000.0)
#: Groups for the cross-validation when the footage is a single clip: contiguous blocks.
BLOCKS = 5
#: (array, shape after N) the table holds for the model; all or none.
ARRAYS = (("lip_weights", "(D, 2)"), ("lip_bias", "(2,)"), ("lip_context", "()"))


@dataclass
class LipModel:
    """A fitted model: ``weights`` ``(FEATURES * (2 * context + 1), 2)``, ``bias`` ``(2,)``
    (opening, width in eye distances) and the ``context`` it stacks."""

    weights: np.ndarray
    bias: np.ndarray
    context: int

    def predict(self, pcm: np.ndarray, sample_rate: int, fps: float, frames: int) -> np.ndarray:
        """``(frames, 2)``: the opening and width each video frame's sound predicts.

        Examples
        --------
        >>> m = LipModel(np.zeros((FEATURES * 3, 2)), np.array([0.1, 0.9]), 1)
        >>> m.predict(np.zeros(16000, np.int16), 16000, 25.0, 4).tolist()
        [[0.1, 0.9], [0.1, 0.9], [0.1, 0.9], [0.1, 0.9]]
        """
        x = stacked(normalised(frame_features(pcm, sample_rate, fps, frames)), self.context)
        return x @ self.weights + self.bias

    def arrays(self) -> Dict[str, np.ndarray]:
        """The table's arrays (:data:`ARRAYS`)."""
        return {"lip_weights": self.weights.astype(np.float32), "lip_bias": self.bias.astype(np.float32),
                "lip_context": np.array(int(self.context), np.int32)}

    @classmethod
    def from_table(cls, table: Dict[str, np.ndarray]) -> Optional["LipModel"]:
        """The model a (validated) samples table holds, or None."""
        if "lip_weights" not in table:
            return None
        return cls(table["lip_weights"].astype(np.float64), table["lip_bias"].astype(np.float64),
                   int(table["lip_context"]))


def problem(table: Dict[str, np.ndarray]) -> Optional[str]:
    """What is wrong with a table's model arrays, or None (none at all is fine).

    Examples
    --------
    >>> m = LipModel(np.zeros((FEATURES * 3, 2)), np.zeros(2), 1).arrays()
    >>> problem(m) is None
    True
    >>> m["lip_weights"][0, 0] = np.nan
    >>> problem(m)
    "array 'lip_weights' holds a value that is not a finite number"
    """
    have = [name for name, _ in ARRAYS if name in table]
    if not have:
        return None
    if len(have) != len(ARRAYS):
        return "arrays " + ", ".join(repr(n) for n, _ in ARRAYS) + " come together"
    c = table["lip_context"]
    if c.shape != () or c.dtype.kind not in "iu" or not 0 <= int(c) <= MAX_CONTEXT:
        return f"array 'lip_context' must be one whole number 0 to {MAX_CONTEXT}"
    d = FEATURES * (2 * int(c) + 1)
    for name, shape in (("lip_weights", (d, 2)), ("lip_bias", (2,))):
        a = table[name]
        if a.dtype.kind not in "fiu" or a.shape != shape:
            return f"array {name!r} must be {shape} numbers for a context of {int(c)} (got {a.shape} {a.dtype})"
        if not np.isfinite(a).all():
            return f"array {name!r} holds a value that is not a finite number"
    return None


def ridge_fit(xs: Sequence[np.ndarray], ys: Sequence[np.ndarray],
              lambdas: Sequence[float] = LAMBDAS) -> Tuple[np.ndarray, np.ndarray, float]:
    """``(weights, bias, lambda)`` of a ridge regression of ``ys`` on ``xs`` (lists of row
    blocks: the groups left out in turn), the strength the one with the best mean
    left-one-group-out correlation of the first output; fitted on every row with it.
    Bias and features are centred first (the bias is not shrunk)."""
    x, y = np.vstack(xs), np.vstack(ys)
    group = np.repeat(np.arange(len(xs)), [len(a) for a in xs])
    best, best_lam = -np.inf, float(lambdas[0])
    if len(xs) > 1 and len(lambdas) > 1:
        for lam in lambdas:
            rs = []
            for g in range(len(xs)):
                w, b = _solve(x[group != g], y[group != g], lam)
                p = x[group == g] @ w + b
                if p[:, 0].std() > 0 and y[group == g, 0].std() > 0:
                    rs.append(np.corrcoef(p[:, 0], y[group == g, 0])[0, 1])
            score = float(np.mean(rs)) if rs else -np.inf
            if score > best:
                best, best_lam = score, float(lam)
    w, b = _solve(x, y, best_lam)
    return w, b, best_lam


def _solve(x: np.ndarray, y: np.ndarray, lam: float) -> Tuple[np.ndarray, np.ndarray]:
    mx, my = x.mean(axis=0), y.mean(axis=0)
    a = x - mx
    w = np.linalg.solve(a.T @ a + lam * np.eye(a.shape[1]), a.T @ (y - my))
    return w, my - mx @ w


def fit(features: List[np.ndarray], table: Dict[str, np.ndarray], context: int = CONTEXT) -> Optional[LipModel]:
    """The model of a samples table, given per clip of ``table["clips"]`` its audio features
    (:func:`lipsync.speech.features.frame_features` at the clip's frame rate, one row per
    video frame; None for a clip without sound): each sample's row, normalised per clip and
    stacked, against its opening and width. None when no clip has sound."""
    xs, ys = [], []
    for v, f in enumerate(features):
        rows = np.nonzero(table["clip"] == v)[0]
        if f is None or not rows.size:
            continue
        frames = table["frame"][rows]
        f = np.asarray(f, np.float64)
        if len(f) <= int(frames.max()):  # a sound shorter than the video: its last frame's
            f = np.vstack([f, np.repeat(f[-1:], int(frames.max()) + 1 - len(f), axis=0)])
        xs.append(stacked(normalised(f), context)[frames])
        ys.append(np.c_[table["opening"][rows], table["width"][rows]].astype(np.float64))
    if not xs:
        return None
    if len(xs) == 1:  # one clip: contiguous blocks stand in for clips
        cut = np.array_split(np.arange(len(xs[0])), BLOCKS)
        xs, ys = [xs[0][c] for c in cut], [ys[0][c] for c in cut]
    w, b, _ = ridge_fit(xs, ys)
    return LipModel(w, b, context)


def fit_clips(paths: Sequence, fps: Sequence[float], table: Dict[str, np.ndarray]) -> Optional[LipModel]:
    """:func:`fit` with each clip's sound read from its file (``paths`` in ``table["clips"]``'s
    order); a clip without sound is left out."""
    from ..errors import InputError
    from ..speech.audio import SAMPLE_RATE, load_audio

    feats = []
    for v, (p, rate) in enumerate(zip(paths, fps)):
        rows = table["frame"][table["clip"] == v]
        try:
            pcm = load_audio(p)
        except InputError:
            pcm = np.zeros(0, np.int16)
        if not pcm.size or not rows.size or not np.abs(pcm).max():
            feats.append(None)
            continue
        feats.append(frame_features(pcm, SAMPLE_RATE, float(rate), int(rows.max()) + 1))
    return fit(feats, table)
