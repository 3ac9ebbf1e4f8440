"""Sample selection: which real mouth sample each rendered frame shows.

For an utterance's frames, a dynamic programme (:mod:`.viterbi`) over per-frame candidate
samples (:mod:`.select`: nearest to the predicted lip shape, pruned with a k-d tree (OpenCV FLANN), and the
continuations of the best runs so far) chooses one sample per frame, preferring runs of
consecutive source frames; :mod:`.plan` says where a join between two samples is morphed;
:mod:`.incremental` fixes the choice frame by frame for a live stream (the same programme
over the look-ahead).

Examples
--------
>>> from lipsync.selection import best_path
>>> import numpy as np
>>> best_path([np.array([0]), np.array([1])], [np.zeros(1), np.zeros(1)], lambda a, b: np.zeros((1, 1)))
[0, 1]
"""

from __future__ import annotations

from .incremental import Incremental
from .plan import JOIN_FRAMES, frame_plan
from .select import Selection, Selector, Target
from .viterbi import Viterbi, best_path

__all__ = ["Incremental", "Selector", "Selection", "Target", "Viterbi", "best_path", "frame_plan", "JOIN_FRAMES"]
