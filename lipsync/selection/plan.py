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

#: Frames a join is morphed over. Runs are ~3 frames on GRID s1, so every morphed frame
#: is a blend of two moments: on the 6 tuning sentences the rendered lip opening's r with
#: the real one was 0.72 with joins cut, 0.68 with one morphed frame, 0.66 with two. One
#: frame (40 ms at 25 fps) softens the step of a cut; the figure shows both.
JOIN_FRAMES = 1


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
