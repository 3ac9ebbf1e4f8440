"""The real footage every real-face figure measures on: GRID speaker s1 (40 sentences).

The data: the 40 sentences (video, audio, GRID's word alignments) of speaker s1 of the GRID
audio-visual corpus (Cooke et al. 2006, CC BY 4.0), in a folder named by ``$LIPSYNC_GRID``,
or else a ``shared/grid-s1`` folder beside the checkout or one level above it; the three
clips in ``tests/data/grid-s1`` when none is there. The sentences are split once, here, so every
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


# --- what the real-footage figures measure (shared: coarticulation, real-face renders) -----

#: The lip measures a figure compares, by name (functions of a face track's points).
MEASURES = ("opening", "width", "protrusion")


def lip_measures(points) -> dict:
    """Lip opening, mouth width and the protrusion proxy of every frame of a track's points.

    ``{"opening": (N,), "width": (N,), "protrusion": (N,)}`` in eye distances
    (:mod:`lipsync.face.measure`); NaN where no face was found.
    """
    from ..face import measure as M

    return {"opening": M.lip_opening(points), "width": M.mouth_width(points),
            "protrusion": M.lip_protrusion(points)}


@functools.lru_cache(maxsize=None)
def real_measures(name: str) -> dict:
    """:func:`lip_measures` of a clip's own frames (its cached :func:`track`)."""
    return lip_measures(track(name).points)


@functools.lru_cache(maxsize=None)
def alignment_of(name: str):
    """lipsync's aligner on the clip's audio with its transcript (cached; warnings silenced:
    a clip the aligner gets wrong is part of what a figure measures)."""
    import warnings

    from ..speech.align import align

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return align(str(video(name)), transcript(name))


def phones(name: str, source: str = "align"):
    """The clip's phones as a timeline spanning its video: ``source="align"`` from lipsync's
    aligner with the transcript, ``"grid"`` from GRID's own word alignment (words split into
    phones by typical durations, as the ``grid`` reader does)."""
    n = len(track(name))
    end = n / track(name).fps
    if source == "align":
        tl = alignment_of(name).phones
    elif source == "grid":
        from ..readers.grid import read_words
        from ..speech.phonetise import words_to_phones

        p = alignment(name)
        tl = words_to_phones(read_words(str(p), p.read_bytes()))
    else:
        raise ValueError(f"unknown phone source {source!r}; valid: align, grid")
    return tl.replace(stated_end=max(end, tl.duration))


def correlation(a, b) -> float:
    """Pearson's r of two per-frame series over the frames where both are finite (0 if either is flat)."""
    import numpy as np

    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3 or a[ok].std() == 0 or b[ok].std() == 0:
        return 0.0
    return float(np.corrcoef(a[ok], b[ok])[0, 1])


# --- pops: how much the picture above the nose jumps between frames (issue 28) ----------------

#: The percentile of frame-to-frame changes a "pops" figure reports: a render that swaps
#: whole pictures jumps at every viseme change (a few frames in a hundred), which a median
#: would not see; the 99th percentile does and ignores a single cut.
POPS_PERCENTILE = 99


def above_nose_rows(landmarks) -> int:
    """The rows above the nose: those above the highest point of the nose's lower edge
    (:data:`lipsync.face.topology.NOSE_BASE_L`/``_R``) of a face mesh ``(468, 2|3)``, or the
    median over a track's meshes ``(N, 468, 2|3)`` (NaN frames left out)."""
    import numpy as np

    from ..face import topology as T

    p = np.asarray(landmarks, np.float64)
    base = p[..., list(T.NOSE_BASE_L + T.NOSE_BASE_R), 1].min(axis=-1)
    return int(np.floor(np.nanmedian(base)))


def above_nose_changes(frames, landmarks_or_rows):
    """Mean absolute grey change (0-255) above the nose between each frame and the next.

    Parameters
    ----------
    frames : iterable of numpy.ndarray
        RGB ``uint8`` frames of one size.
    landmarks_or_rows : int or numpy.ndarray
        The number of rows from the top that are above the nose, or face meshes to take it
        from (:func:`above_nose_rows`: one mesh, or a track's).

    Returns
    -------
    numpy.ndarray
        ``(N - 1,)`` changes.

    Examples
    --------
    >>> import numpy as np
    >>> a = np.zeros((10, 4, 3), np.uint8); b = a.copy(); b[:5] = 30; b[8:] = 200
    >>> above_nose_changes([a, b, b], 5).tolist()    # rows 0-4 only
    [30.0, 0.0]
    """
    import cv2
    import numpy as np

    rows = landmarks_or_rows if isinstance(landmarks_or_rows, (int, np.integer)) else above_nose_rows(landmarks_or_rows)
    out, prev = [], None
    for f in frames:
        g = cv2.cvtColor(np.ascontiguousarray(f[:rows, :, :3]), cv2.COLOR_RGB2GRAY).astype(np.int16)
        if prev is not None:
            out.append(float(np.abs(g - prev).mean()))
        prev = g
    return np.array(out)


def above_nose_pops(frames, landmarks_or_rows, q: float = POPS_PERCENTILE) -> float:
    """The pops figure: the ``q``-th percentile over frames of :func:`above_nose_changes`
    (issue 28: a render's at most twice the real clips').

    Examples
    --------
    >>> import numpy as np
    >>> frames = [np.full((8, 8, 3), 100 + 10 * (i % 2), np.uint8) for i in range(5)]
    >>> above_nose_pops(frames, 4)
    10.0
    """
    import numpy as np

    ch = above_nose_changes(frames, landmarks_or_rows)
    return float(np.percentile(ch, q)) if len(ch) else 0.0
