"""The sequencer's frames as atlas cells: each (from, to, alpha) to the nearest cell that exists.

The rule, per frame:

* a still frame (from = to, alpha 0 or 1) is its viseme's cell, exactly;
* a morph of a pair the atlas holds is the cell of that pair whose alpha is nearest (the two
  viseme cells count as alpha 0 and 1, so alpha 0.05 with 3 in-betweens shows ``from``);
  the pair may be stored the other way round: B -> A at alpha is A -> B at ``1 - alpha``;
* a morph of a pair the atlas lacks shows the nearer viseme (alpha < 0.5: ``from``): what a
  cue-file player would show. Such pairs are listed in ``missing_pairs`` and warned about,
  since the atlas was built for other timelines (``--pairs used``).

With ``N`` in-betweens a frame's alpha is off by at most ``1 / (2 (N + 1))``.
"""

from __future__ import annotations

import bisect
from typing import Dict, List, Sequence, Tuple

from .schema import Atlas


class CellIndex:
    """Fast lookups of an atlas' cells by viseme and by pair (either direction).

    Examples
    --------
    >>> from lipsync.atlas.schema import Cell
    >>> cells = (Cell((0, 0, 1, 1), "A", "A", 0.0), Cell((1, 0, 1, 1), "B", "B", 0.0),
    ...          Cell((2, 0, 1, 1), "A", "B", 0.25), Cell((3, 0, 1, 1), "A", "B", 0.5),
    ...          Cell((4, 0, 1, 1), "A", "B", 0.75))
    >>> atlas = Atlas(image="m.png", image_size=(5, 1), base=None, frame_size=(1, 1), region=(0, 0, 1, 1),
    ...               scale=1.0, padding=0, bank="b", rest="A", visemes=("A", "B"), method="flow",
    ...               inbetweens=3, cells=cells)
    >>> idx = CellIndex(atlas)
    >>> [idx.cell(a, b, t)[0] for a, b, t in [("A", "A", 0), ("A", "B", 0.3), ("B", "A", 0.3), ("A", "B", 0.1)]]
    [0, 2, 4, 0]
    """

    def __init__(self, atlas: Atlas):
        self.atlas = atlas
        self.visemes = atlas.viseme_cells()
        self.pairs = atlas.pair_cells()
        self._alphas: Dict[Tuple[str, str], List[float]] = {k: [a for a, _ in v] for k, v in self.pairs.items()}

    def cell(self, from_viseme: str, to_viseme: str, alpha: float) -> Tuple[int, bool]:
        """(cell index, whether the pair is in the atlas) for one frame."""
        if from_viseme == to_viseme or alpha <= 0.0:
            return self.visemes[from_viseme], True
        if alpha >= 1.0:
            return self.visemes[to_viseme], True
        key, t = (from_viseme, to_viseme), float(alpha)
        if key not in self.pairs:
            key, t = (to_viseme, from_viseme), 1.0 - t
        if key not in self.pairs:
            return self.visemes[from_viseme if alpha < 0.5 else to_viseme], False
        alphas = self._alphas[key]
        j = bisect.bisect_left(alphas, t)
        # the nearer of the two neighbours; a tie goes to the lower alpha (deterministic)
        if j == len(alphas) or (j > 0 and t - alphas[j - 1] <= alphas[j] - t):
            j -= 1
        return self.pairs[key][j][1], True


def quantise(atlas: Atlas, specs: Sequence) -> Tuple[List[int], List[Tuple[str, str]]]:
    """The cell of each FrameSpec, and the pairs (in first-seen order) the atlas lacks.

    Examples
    --------
    >>> from lipsync.motion.sequencer import FrameSpec
    >>> from lipsync.atlas.schema import Cell
    >>> atlas = Atlas(image="m.png", image_size=(2, 1), base=None, frame_size=(1, 1), region=(0, 0, 1, 1),
    ...               scale=1.0, padding=0, bank="b", rest="A", visemes=("A", "B"), method="flow",
    ...               inbetweens=0, cells=(Cell((0, 0, 1, 1), "A", "A", 0.0), Cell((1, 0, 1, 1), "B", "B", 0.0)))
    >>> quantise(atlas, [FrameSpec("A", "A", 0.0), FrameSpec("A", "B", 0.7)])
    ([0, 1], [('A', 'B')])
    """
    index = CellIndex(atlas)
    cells: List[int] = []
    missing: Dict[Tuple[str, str], None] = {}
    for spec in specs:
        i, found = index.cell(spec.from_viseme, spec.to_viseme, spec.alpha)
        if not found:
            missing.setdefault((spec.from_viseme, spec.to_viseme), None)
        cells.append(i)
    return cells, list(missing)
