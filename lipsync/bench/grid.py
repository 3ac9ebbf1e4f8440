"""The real footage every real-face figure measures on: GRID speaker s1 (40 sentences).

``/work/shared/grid-s1`` in this project's workspace (``$LIPSYNC_GRID`` elsewhere, or the
``shared/grid-s1`` folder beside or above the checkout; the three clips in
``tests/data/grid-s1`` when none is there). The sentences are split once, here, so every
figure makes banks from the same clips and judges on the same held-out ones:

* :data:`BANK_CLIPS`: every fourth sentence in name order, 10 sentences (30 s of video),
  which between them show every viseme of both shipped maps (``english-to-rhubarb``: A-H, X;
  ``english-to-oculus``: all 15);
* :func:`held_out`: the other 30.

Tracks are cached per process (a track of a clip costs ~0.2 s).

Examples
--------
>>> d = grid_dir()
>>> sorted(p.suffix for p in d.iterdir())[:1]
['.align']
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import List

#: The sentences banks are made from (see the module docstring).
BANK_CLIPS = ("bbaf3s", "bginzn", "bwbg9s", "lbwy7s", "lrik5a", "pbav3s", "pgwe7s", "pwbk2p", "sbwo2p", "srbu8p")


def grid_dir() -> Path:
    """The folder of GRID clips (``NAME.mpg`` + ``NAME.align``)."""
    root = Path(__file__).resolve().parents[2]
    candidates = [Path(os.environ["LIPSYNC_GRID"])] if os.environ.get("LIPSYNC_GRID") else []
    candidates += [up / "shared" / "grid-s1" for up in (root.parent, root.parent.parent)]
    for c in candidates:
        if (c / f"{BANK_CLIPS[0]}.mpg").is_file():
            return c
    return root / "tests" / "data" / "grid-s1"


def clips() -> List[str]:
    """Every clip name in the folder, sorted."""
    return sorted(p.stem for p in grid_dir().glob("*.mpg"))


def held_out() -> List[str]:
    """The clips that are not :data:`BANK_CLIPS`."""
    return [c for c in clips() if c not in BANK_CLIPS]


def video(name: str) -> Path:
    return grid_dir() / f"{name}.mpg"


def alignment(name: str) -> Path:
    return grid_dir() / f"{name}.align"


def transcript(name: str) -> str:
    """The sentence's words (GRID's alignment without ``sil``/``sp``)."""
    from ..readers.grid import read_words

    p = alignment(name)
    return " ".join(s.label for s in read_words(str(p), p.read_bytes()))


@functools.lru_cache(maxsize=None)
def track(name: str):
    """The face track of a clip (:func:`lipsync.face.track.track_video`), cached."""
    from ..face.track import track_video

    return track_video(video(name))
