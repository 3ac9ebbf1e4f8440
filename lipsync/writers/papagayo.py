"""Papagayo-NG projects (``.pgo``) from a word tier and a phone tier.

The file layout is the one :mod:`lipsync.readers.papagayo` reads (and Papagayo-NG writes):
one voice, one phrase holding every word, each word with its phonemes at frames. Times
become frames at ``fps`` (``round(t * fps)``), so a tier on that frame grid reads back
exactly. Phonemes are named in Papagayo-NG's ``CMU_39`` set (ARPAbet without stress digits,
``rest`` for silence): a time inside a word that no phone covers is written as ``rest`` so
the phone before it does not stretch over it. Phones outside every word are put in a word
of their own named :data:`ORPHAN_WORD` (Papagayo keeps phonemes only inside words).

Examples
--------
>>> from lipsync.motion.timeline import Segment, Timeline
>>> words = Timeline((Segment(0.2, 0.6, "hi"),))
>>> phones = Timeline((Segment(0.2, 0.32, "HH"), Segment(0.32, 0.6, "AY")))
>>> print(to_pgo(words, phones, duration=1.0, fps=25, sound_file="hi.wav"), end="")  # doctest: +NORMALIZE_WHITESPACE
lipsync version 1
hi.wav
25
25
1
	Voice 1
	hi
	1
		hi
		5
		14
		1
			hi 5 14 2
				5 HH
				8 AY
"""

from __future__ import annotations

import math
import os
from typing import List, Tuple, Union

from .._files import atomic_write_bytes
from ..errors import InputError
from ..motion.timeline import Timeline
from ..readers.papagayo import CMU_39, FPS_RANGE, REST

PathLike = Union[str, "os.PathLike[str]"]

#: The word that holds phones lying outside every word (a phone tier without words).
ORPHAN_WORD = "~"


def _frames(t: float, fps: float) -> int:
    return int(math.floor(t * fps + 0.5))


def _word_rows(words: Timeline, phones: Timeline, fps: float) -> List[Tuple[str, int, int, List[Tuple[int, str]]]]:
    """(text, first frame, last frame inclusive, [(frame, phoneme)]) per word, in order."""
    spans = [(_frames(w.start, fps), _frames(w.end, fps), w.label) for w in words]
    ph = [(_frames(p.start, fps), _frames(p.end, fps), p.label) for p in phones]
    # phones outside every word: one orphan word per run of them
    inside = [any(a <= s and e <= b for a, b, _ in spans) for s, e, _ in ph]
    run: List[Tuple[int, int, str]] = []
    for (s, e, label), ok in zip(ph + [(0, 0, "")], inside + [True]):
        if not ok and (not run or run[-1][1] == s):
            run.append((s, e, label))
            continue
        if run:
            spans.append((run[0][0], run[-1][1], ORPHAN_WORD))
            run = []
        if not ok:
            run.append((s, e, label))
    spans.sort()
    rows = []
    for a, b, text in spans:
        if b <= a:
            continue
        keys: List[Tuple[int, str]] = []
        t = a
        for s, e, label in ph:
            if s < a or e > b or e <= s:
                continue
            if s > t:
                keys.append((t, REST))  # a silent stretch inside the word
            keys.append((s, label))
            t = e
        if keys and t < b:
            keys.append((t, REST))
        rows.append((text, a, b - 1, keys))
    return rows


def to_pgo(words: Timeline, phones: Timeline, *, duration: float, fps: float, sound_file: str,
           voice: str = "Voice 1") -> str:
    """The text of a one-voice Papagayo project (see the module docstring); ``sound_file`` is
    written as given (Papagayo reads it relative to the project's folder).

    Raises
    ------
    InputError
        ``fps`` outside Papagayo's range, a word without letters, or a phone Papagayo's
        CMU_39 set cannot name (IPA phones: save a TextGrid instead).
    """
    if not FPS_RANGE[0] <= fps <= FPS_RANGE[1]:
        raise InputError(f"a Papagayo project's frame rate must be within {FPS_RANGE[0]:g}..{FPS_RANGE[1]:g}, got {fps:g}")
    foreign = sorted({p.label for p in phones} - CMU_39)
    if foreign:
        raise InputError("Papagayo's CMU_39 phoneme set cannot name these phones: " + ", ".join(foreign[:8])
                         + " (save a TextGrid for IPA phones)")
    rows = _word_rows(words, phones, fps)
    for text, *_ in rows:
        if not text.strip() or len(text.split()) != 1:
            raise InputError(f"a Papagayo word is one token without spaces, not {text!r}: retype it")
    text = " ".join(r[0] for r in rows)
    out = ["lipsync version 1", sound_file, f"{fps:g}", str(max(1, _frames(duration, fps))), "1",
           f"\t{voice}", f"\t{text}", "\t1" if rows else "\t0"]
    if rows:
        out += [f"\t\t{text}", f"\t\t{rows[0][1]}", f"\t\t{rows[-1][2]}", f"\t\t{len(rows)}"]
        for word, a, b, keys in rows:
            out.append(f"\t\t\t{word} {a} {b} {len(keys)}")
            out += [f"\t\t\t\t{f} {name}" for f, name in keys]
    return "\n".join(out) + "\n"


def write_pgo(words: Timeline, phones: Timeline, path: PathLike, *, duration: float, fps: float,
              sound_file: str) -> None:
    """Write :func:`to_pgo`'s text to ``path`` atomically (temporary file, then rename).

    Examples
    --------
    >>> import os, tempfile
    >>> from lipsync import read_timeline
    >>> from lipsync.motion.timeline import Segment, Timeline
    >>> p = os.path.join(tempfile.mkdtemp(), "hi.pgo")
    >>> write_pgo(Timeline((Segment(0.2, 0.6, "hi"),)),
    ...           Timeline((Segment(0.2, 0.32, "HH"), Segment(0.32, 0.6, "AY"))), p,
    ...           duration=1.0, fps=25, sound_file="hi.wav")
    >>> [(s.label, s.start, s.end) for s in read_timeline(p)]
    [('HH', 0.2, 0.32), ('AY', 0.32, 0.6)]
    """
    text = to_pgo(words, phones, duration=duration, fps=fps, sound_file=sound_file)
    atomic_write_bytes(path, lambda fh: fh.write(text.encode("utf-8")))


__all__ = ["to_pgo", "write_pgo", "ORPHAN_WORD"]
