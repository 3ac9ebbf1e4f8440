"""What each frame shows once the samples are chosen: a sample as it is, or a morph across a join.

Where the sample of frame t is the source's next frame after frame t-1's, it is shown as
it is (pasted with one warp). Where it is not (a *join*), the next :data:`JOIN_FRAMES`
frames are morphs (the paper's flows between two samples' lines) from the old run,
continued in its source, to the new one, at alpha ``(m + 1) / (JOIN_FRAMES + 1)``: the
cut becomes a short transition. Frames that must be exact (closed lips, rest) are never
morphed.

Examples
--------
>>> import numpy as np
>>> succ = np.array([1, 2, -1, 4, 5, -1])          # two runs: samples 0-2 and 3-5
>>> src, dst, alpha = frame_plan(np.array([0, 1, 3, 4, 5]), succ, join_frames=2)
>>> src.tolist(), dst.tolist(), alpha.round(2).tolist()
([0, 1, 2, 2, 5], [0, 1, 3, 4, 5], [1.0, 1.0, 0.33, 0.67, 1.0])
"""

from __future__ import annotations

from typing import Optional, Tuple

import numpy as np

#: Frames a join is morphed over: 0, joins are cut (the new sample shown at once). Measured
#: both ways from one bank (``python -m lipsync.bench --only samples``, GRID s1, 18 held-out
#: sentences; ``tools/other_face.py`` on two other speakers), cut against one morphed frame:
#: lip r 0.804 / 0.780 (dub 0.807 / 0.762), range 0.81 / 0.69 (dub 0.79 / 0.66), the lips'
#: sharpness over the real frames' 0.90 / 0.81 (dub 0.93 / 0.82; the other faces' dubs 0.93
#: and 0.96 / 0.50 and 0.81), detector AUC 0.991 / 0.991 (dub 0.862 / 0.896). The morph
#: only trims the largest steps: the mouth box's p99 change at a join over the real clips'
#: p99 frame-to-frame change is 1.62 / 1.45 (dub 1.67 / 1.44; other faces 0.85-1.04 /
#: 0.57-1.12), while the morphed frame itself is a double exposure of two mouths (teeth
#: fade to a blur: full-size crops of the largest joins, ``tools/other_face.py --sheets``).
#: Runs are short (2.7 frames on GRID s1), so a morphed frame is a third of all frames. The
#: paper's flow morph across a join stays available: ``lipsync.selection.plan.JOIN_FRAMES
#: = 1`` before the render (or ``frame_plan(..., join_frames=1)``).
JOIN_FRAMES = 0


def frame_plan(path: np.ndarray, succ: np.ndarray, exact: Optional[np.ndarray] = None,
               join_frames: Optional[int] = None) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(src, dst, alpha)`` per frame: show ``dst`` (alpha 1, ``src == dst``), or the morph
    from ``src`` to ``dst`` at ``alpha``. ``succ`` is each sample's next source frame (-1:
    none); ``exact`` frames (bool) are never morphed."""
    path = np.asarray(path, np.int64)
    join_frames = JOIN_FRAMES if join_frames is None else join_frames
    n = len(path)
    src, alpha = path.copy(), np.ones(n)
    exact = np.zeros(n, bool) if exact is None else np.asarray(exact, bool)
    joins = np.zeros(n, bool)
    joins[1:] = succ[path[:-1]] != path[1:]
    for t in np.nonzero(joins)[0]:
        old = int(path[t - 1])
        for m in range(join_frames):
            k = t + m
            if k >= n or (m > 0 and joins[k]) or exact[k]:
                break
            old = int(succ[old]) if succ[old] >= 0 else old  # the old run continued (held at its end)
            src[k], alpha[k] = old, (m + 1) / (join_frames + 1)
    return src, path.copy(), alpha
