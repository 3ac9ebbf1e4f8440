"""Step 2: when each mouth shape is shown — the speech aligned, its phones mapped to visemes.

Each video's sound is aligned with its transcript by the project's aligner
(:func:`lipsync.speech.align.align`, pocketsphinx; audio decoded from the container by the
bundled ffmpeg) and the phones mapped to the bank's visemes by the phoneme map, exactly as
``lipsync render`` maps them, so that the frame picked for a viseme shows what the renderer
will show for the same sounds. Silence (gaps between words, before and after) becomes the
map's silence viseme: the rest shape.

Examples
--------
>>> from lipsync.motion.timeline import Segment, Timeline
>>> from lipsync.phonetics.phonemes import load_map
>>> tl = Timeline((Segment(0.5, 0.6, "S"), Segment(0.6, 0.7, "T"), Segment(0.7, 0.9, "AA1")),
...               stated_end=1.5)
>>> [(s.label, s.start, s.end) for s in viseme_spans(tl, load_map("english-to-rhubarb"))]
[('X', 0.0, 0.5), ('B', 0.5, 0.7), ('D', 0.7, 0.9), ('X', 0.9, 1.5)]
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import List, Optional, Tuple

from ..errors import InputError
from ..phonetics.phonemes import PhonemeMap, map_timeline
from ..motion.timeline import Segment, Timeline
from .sources import Source


@dataclass(frozen=True)
class Speech:
    """What was said in one video, and when.

    Attributes
    ----------
    source : Source
    words : tuple of str
        The words aligned.
    phones : Timeline
        ARPAbet phones (silence is gaps).
    visemes : tuple of Segment
        Viseme spans covering the whole video (same-viseme neighbours merged).
    recognised : bool
        Whether the words were recognised (no transcript, or one that did not fit); phones
        recognised without words (other languages) leave ``words`` empty.
    confidence : float or None
        How well the transcript fits (the aligner's figure).
    """

    source: Source
    words: Tuple[str, ...]
    phones: Timeline
    visemes: Tuple[Segment, ...]
    recognised: bool
    confidence: Optional[float]
    #: Nothing in the sound could be named (not even phones): the frames are labelled by lip
    #: shape (:func:`from_face`) once the face is tracked.
    from_face: bool = False


def viseme_spans(phones: Timeline, pmap: PhonemeMap) -> Tuple[Segment, ...]:
    """The viseme timeline of ``phones`` with neighbours of one viseme merged into one span.

    Two sounds of one shape in a row (S then T: both B) are one held mouth shape: its
    steady middle is the middle of both.
    """
    with warnings.catch_warnings():
        # an unknown phone is shown as the map's fallback by render too; nothing to add here
        warnings.simplefilter("ignore")
        mapped = map_timeline(phones, pmap)
    out: List[Segment] = []
    for s in mapped:
        if s.end <= s.start:
            continue
        if out and out[-1].label == s.label and abs(out[-1].end - s.start) < 1e-9:
            out[-1] = Segment(out[-1].start, s.end, s.label)
        else:
            out.append(s)
    return tuple(out)


def transcribe(source: Source, pmap: PhonemeMap, *, quiet: bool = True, jobs: Optional[int] = None,
               lang: Optional[str] = None) -> Speech:
    """Align one video's speech (with its transcript when it has one) and map it to visemes.

    What the sound gives, best first: words (a transcript, or English recognition); phones
    without words (recognition in other languages hears phones, not words: the bank is made
    from them); nothing that can be named in a sound track that is not silent -- the speech
    is then :attr:`Speech.from_face`, and :func:`from_face` labels the frames by lip shape
    once the face is tracked.

    Raises
    ------
    lipsync.errors.InputError
        The sound track is silent (its loudest 10 ms, in dBFS, is named).

    Warns
    -----
    lipsync.speech.align.AlignmentWarning
        The transcript does not fit the speech (passed on from the aligner).
    """
    from ..speech.align import SILENCE_DBFS, align

    al = align(source.path, source.text, quiet=quiet, jobs=jobs, lang=lang)
    phones = Timeline(tuple(al.phones), kind=al.phones.kind, path=str(source.path), stated_end=al.duration)
    if len(al.phones) == 0:
        loudest = _loudest_dbfs(source.path)
        if loudest < SILENCE_DBFS:
            dropped = f"; the transcript ({source.text_from}) could not be used" if source.text else ""
            raise InputError(f"its sound track is silent (loudest {loudest:.0f} dBFS, speech is above "
                             f"{SILENCE_DBFS:g}){dropped}: the speech is what tells which mouth shape each frame "
                             f"shows (record with sound)", path=source.path)
        return Speech(source=source, words=(), phones=phones, visemes=(), recognised=True, confidence=None,
                      from_face=True)
    return Speech(source=source, words=tuple(al.words.labels()), phones=phones,
                  visemes=viseme_spans(phones, pmap), recognised=al.recognised, confidence=al.confidence)


def _loudest_dbfs(path) -> float:
    """The loudest 10 ms of a file's sound, dBFS (-inf for none)."""
    import numpy as np

    from ..speech.audio import load_audio

    pcm = load_audio(path)
    n = len(pcm) // 160
    if n == 0:
        return float("-inf")
    x = pcm[:n * 160].astype(np.float32).reshape(n, 160) / 32768.0
    return float(20 * np.log10(np.sqrt((x * x).mean(axis=1)).max() + 1e-12))


#: Face-alone labels (:func:`from_face`): a speech frame's lip opening, as a share of its
#: range over the speech's frames (5th to 95th percentile), picks a sound standing for its
#: shape; the map turns it into the bank's viseme as it does for aligned speech. A frame
#: where the lips are nearest (a local minimum of the opening) in the lower CLOSING_SHARE
#: of the range is a closure: lips meet between syllables only for a moment, and the face
#: mesh never puts them quite together. Narrow lips (the mouth's width more than NARROW
#: below its median, in eye distances) stand for a rounded vowel.
FACE_RULES = (
    # (opening at most, sound, why)
    (0.12, "P", "lips together: the closure every map has"),
    (0.40, "S", "lips just apart, teeth together"),
    (0.75, "EH", "open, the jaw half down"),
    (9.99, "AA", "wide open"),
)
CLOSING_SHARE = 0.3
#: Narrower than this (mouth width below its median, eye distances) and not closed: rounded.
NARROW = 0.04
#: Frames of sound this far below the loudest (dB) are pauses: the rest shape's candidates
#: (the aligner's own split of speech from breath and room noise,
#: lipsync.speech.align.SPEECH_BELOW_PEAK_DB).
PAUSE_BELOW_PEAK_DB = 25.0


def from_face(speech: Speech, points, found, fps: float, pmap: PhonemeMap) -> Speech:
    """``speech`` (:attr:`Speech.from_face`) with phones and visemes read off the face: each
    frame's lip opening and width (:mod:`lipsync.face.measure`) through :data:`FACE_RULES`
    where the sound is loud, the rest shape where it is quiet -- the bank's pictures then
    are chosen by lip shape alone. Runs of one label become one phone.
    """
    import numpy as np

    from dataclasses import replace

    from ..face.measure import lip_opening, mouth_width
    from ..speech.audio import load_audio

    n = len(points)
    pcm = load_audio(speech.source.path)
    per = max(1, int(round(16000 / fps)))
    db = np.full(n, -np.inf)
    for i in range(n):
        x = pcm[i * per:(i + 1) * per].astype(np.float32) / 32768.0
        if x.size:
            db[i] = 20 * np.log10(np.sqrt(float((x * x).mean())) + 1e-12)
    loud = db >= np.max(db) - PAUSE_BELOW_PEAK_DB
    ok = np.asarray(found, bool)
    opening, width = lip_opening(points), mouth_width(points)
    talk = ok & loud
    lo, hi = np.nanpercentile(opening[talk], [5, 95]) if talk.any() else (0.0, 1.0)
    share = (opening - lo) / max(hi - lo, 1e-6)
    nearest = np.zeros(n, bool)  # the lips' local minima
    nearest[1:-1] = (opening[1:-1] <= opening[:-2]) & (opening[1:-1] <= opening[2:])
    narrow = width < np.nanmedian(width[ok]) - NARROW if ok.any() else np.zeros(n, bool)
    labels = []
    for i in range(n):
        if not loud[i] or not ok[i]:
            labels.append("")
            continue
        sound = "P" if nearest[i] and share[i] <= CLOSING_SHARE else \
            next(p for top, p, _ in FACE_RULES if share[i] <= top)
        labels.append("UW" if narrow[i] and sound != "P" else sound)
    segs, i = [], 0
    while i < n:
        j = i
        while j < n and labels[j] == labels[i]:
            j += 1
        if labels[i]:
            segs.append(Segment(i / fps, j / fps, labels[i]))
        i = j
    phones = Timeline(tuple(segs), kind=speech.phones.kind, path=speech.phones.path, stated_end=n / fps)
    return replace(speech, phones=phones, visemes=viseme_spans(phones, pmap))
