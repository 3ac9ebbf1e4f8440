"""Speech in languages other than English: IPA phones aligned with pocketsphinx's en-us models.

pocketsphinx ships acoustic models for US English only. For any language espeak-ng speaks
(:mod:`lipsync.phonetics.g2p`):

* with a transcript, each word's IPA segments (espeak-ng's letters to sounds) are given the
  closest en-us acoustic unit by articulatory features
  (:func:`lipsync.phonetics.closest_english`), and the words are aligned as English words
  are (:func:`lipsync.speech.align.align_samples`: a grammar of exactly the transcript's
  words, the fit check against a free phone loop, the tolerant search that may leave words
  out). The phones tier then holds each word's IPA segments, each spanning the units it was
  given.
* without one, pocketsphinx's free phone loop (context-independent en-us phones, any after
  any: Rhubarb Lip Sync's "phonetic" recogniser) listens, and its phones, written in IPA,
  go straight to the mouth shapes. There are no words.

The decoder knows each word by a name of its own (``ipa_`` and a digest of the word and
its units), so words in any script reach a dictionary that expects ASCII.

Examples
--------
>>> import numpy as np
>>> from lipsync.phonetics.g2p import espeak_available
>>> if espeak_available():
...     al = align_language(np.zeros(8000, np.int16), "bonjour", "fr")
...     print(al.duration, al.words.labels())
... else:
...     print(0.5, [])
0.5 []
"""

from __future__ import annotations

import hashlib
import warnings
from dataclasses import replace
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..errors import InputError
from ..motion.timeline import Segment, Timeline
from .scripts import OTHER_LANGUAGES, UnreadWordsWarning, check_english_script, script_of

__all__ = ["align_language", "check_english_script", "UnreadWordsWarning", "script_of"]


def check_transcript(text: str, lang: Optional[str] = None, *, path: Optional[str] = None) -> None:
    """Refuse a transcript none of whose words ``lang`` can read, before any long work.

    English: :func:`check_english_script`; other languages: the words espeak-ng reads in
    the language (:func:`lipsync.phonetics.g2p.transcribe`).

    Raises
    ------
    lipsync.errors.InputError
        No word can be read (the message names the script or the words, and ``--lang``).

    Examples
    --------
    >>> check_transcript("Hello there")
    >>> check_transcript("经广州日报报道", None, path="clip.txt")
    Traceback (most recent call last):
    ...
    lipsync.errors.InputError: clip.txt: the transcript is written in Chinese (Han) letters, which the English aligner cannot read: pass the language, for example --lang zh
    """
    from ..phonetics.g2p import is_english

    if is_english(lang):
        from .text import normalise_transcript

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UnreadWordsWarning)  # warned when aligned
            check_english_script(text, normalise_transcript(text), path=path)
        return
    from ..phonetics.g2p import languages, resolve, transcribe

    words = transcribe(text, lang)
    if words and not any(w.read and w.phones for w in words):
        raise InputError(f"none of the transcript's words can be read as {languages()[resolve(lang)]} (--lang {lang}): "
                         f"{', '.join(w.text for w in words[:8])}", path=path)


# --- IPA segments to en-us acoustic units and back -------------------------------------------

#: Per language (espeak-ng's code, :func:`lipsync.phonetics.g2p.resolve`): IPA segments
#: given other en-us acoustic units than their closest by features, with the reason. "SIL"
#: is the en-us model's silence: the segment keeps its own time in the phones tier, the gap
#: the silence leaves between the phones around it within its word (:func:`_in_ipa`).
#:
#: Arabic (``ar``), both rows measured together on ``python -m lipsync.bench --only
#: languages`` (4 sentences, 24 lip closures), Arabic with the transcript: frame agreement
#: with the truth's mouth shapes, bilabials shown closed:
#:
#: ================================= ===== ======
#: ʔ, short a aligned as             frames closed
#: ================================= ===== ======
#: K, AA (the features' and round 4) 0.755 20/24
#: SIL, AA                           0.760 19/24
#: K, AE                             0.736 20/24
#: SIL, AE                           0.767 19/24
#: K, AH                             0.779 23/24
#: SIL, AH (used)                    0.825 22/24
#: SIL, AH and long aː as AH too     0.733 18/24
#: ================================= ===== ======
#:
#: - short a as AH: Arabic's short a is a centralised vowel (near ɐ), unlike its long aː
#:   (AA, as for every language): aligned as AA, the article's a after the glottal stop was
#:   not heard as a vowel, and the aligner stretched the glottal stop over it and put the
#:   article's l and the b or m after it (البحر, البارد, المباراة) up to 0.3 s late.
#: - ʔ as silence: the glottal stop is a closure of the glottis, a short silence (espeak-ng
#:   speaks 50 ms of it) with no burst; en-us K, its nearest by features, expects one.
#:   Kept to Arabic: Japanese has the bench's only other ʔ (one), and as silence it cost
#:   Japanese 0.789 -> 0.785.
LANGUAGE_UNITS: Dict[str, Dict[str, Tuple[str, ...]]] = {
    "ar": {"a": ("AH",), "ʔ": ("SIL",)},
}


#: Per espeak-ng voice: the probability of a pause between the words
#: (:data:`lipsync.speech.align.PAUSE_PROB`, pocketsphinx's 0.005 for the others). In the
#: tone languages the search put silence over speech the en-us units fit loosely and
#: squeezed the words around it into what was left: on the tuning half (``--only
#: languages``, 130 sentences) the pauses it put inside speech exceeded espeak-ng's own by
#: 3.3 s in 25.8 s of Vietnamese and 2.2 s in 16.7 s of Mandarin (13 % of the speech), by
#: at most 0.8 s (5 %, Dutch) in any other language (0.49 s of silence over "một ngôi",
#: whose words then came 0.3 s late). A real pause costs one step (``log`` of this) whatever
#: its length, far less than speech units forced over it. Frame agreement with the
#: transcript, tuning half, Vietnamese / Mandarin: 0.005 0.764 / 0.804; 1e-3 0.777 /
#: 0.821; 1e-5 0.844 / 0.833; 1e-10 0.873 / 0.871; 1e-20 the same. For every other
#: language too (tried, not used), 1e-10 raised the tuning half's mean from 0.841 to 0.854
#: but lowered seven languages' held-out figures by 0.003 to 0.008 (docs/languages.md).
PAUSE_PROB: Dict[str, float] = {"vi": 1e-10, "cmn": 1e-10}


def _units(phone: str, lang: str = "") -> Tuple[str, ...]:
    """The en-us ARPAbet acoustic units standing for one IPA segment: the closest by
    features (open a as AA, by sound: the phonetics room's overrides), an affricate or
    diphthong English lacks as two or three; ``lang``'s own rows first
    (:data:`LANGUAGE_UNITS`)."""
    from ..phonetics import english_phones

    own = LANGUAGE_UNITS.get(lang, {})
    if phone in own:
        return own[phone]
    return tuple(english_phones(phone)) or ("AH",)


def _speech_units(units: Sequence[str]) -> int:
    """How many of ``units`` the phone pass reports (it leaves out the silence within a word)."""
    from .align import _NON_SPEECH_PHONES

    return sum(u not in _NON_SPEECH_PHONES for u in units)


def _ipa_of_unit(unit: str) -> str:
    """An ARPAbet phone (stress digit allowed) written in IPA."""
    from ..phonetics import to_ipa

    return to_ipa(unit.rstrip("012"), "arpabet") or unit


def _name(text: str, units: Sequence[str]) -> str:
    digest = hashlib.sha1(f"{text}|{' '.join(units)}".encode("utf-8")).hexdigest()[:12]
    return f"ipa_{digest}"


@OTHER_LANGUAGES.decorator("espeak-ipa")
def align_language(pcm, text: Optional[str], lang: str, *, quiet: bool = True, path: Optional[str] = None,
                   jobs: Optional[int] = None):
    """Words and IPA phones of speech in ``lang`` (any language espeak-ng speaks but English).

    Parameters
    ----------
    pcm : numpy.ndarray
        16 kHz mono samples (int16, or floats in -1..1).
    text : str, optional
        The transcript as written; None or blank: the free phone loop listens.
    lang : str
        BCP 47 tag (:func:`lipsync.phonetics.g2p.resolve`).
    quiet, path, jobs
        As for :func:`lipsync.speech.align.align_samples`.

    Returns
    -------
    lipsync.speech.align.Alignment
        ``words`` as written in the transcript; ``phones`` in IPA. Without a transcript,
        no words and the loop's phones.

    Raises
    ------
    lipsync.errors.InputError
        An unknown ``lang``, the optional espeak-ng extra missing, or a transcript none of
        whose words can be read in the language.

    Warns
    -----
    UnreadWordsWarning
        Words the language cannot read (left out, named).
    lipsync.speech.align.AlignmentWarning
        The transcript does not fit the audio (as for English).

    Examples
    --------
    >>> from lipsync.phonetics.g2p import espeak_available
    >>> if espeak_available():
    ...     al = align_language(np.zeros(16000, np.int16), None, "es")
    ...     print(al.words.labels(), al.recognised)
    ... else:
    ...     print([], True)
    [] True
    """
    from ..phonetics.g2p import _voices, languages, resolve, transcribe
    from . import align as A
    from .text import shown_words

    code = resolve(lang)
    pcm = A._as_pcm(pcm)
    words = transcribe(text, code) if text is not None and text.strip() else []
    unread = [w.text for w in words if not (w.read and w.phones)]
    read = [w for w in words if w.read and w.phones]
    if words and not read:
        raise InputError(f"none of the transcript's words can be read as {languages()[code]} (--lang {lang}): "
                         f"{shown_words(unread)}", path=path)
    if unread:
        warnings.warn(f"{path or 'transcript'}: {len(unread)} word(s) cannot be read as {languages()[code]} and "
                      f"were left out: {shown_words(unread)}", UnreadWordsWarning, stacklevel=3)
    plans: Dict[str, Tuple[str, Tuple[str, ...], List[int]]] = {}
    names: List[str] = []
    for w in read:
        per_phone = [_units(p, code) for p in w.phones]
        flat = tuple(u for us in per_phone for u in us)
        name = _name(w.text, flat)
        A._CUSTOM[name] = flat
        plans[name] = (w.text, w.phones, [_speech_units(us) for us in per_phone])
        names.append(name)

    def shown(n: str) -> str:
        return plans[n][0] if n in plans else n

    token = A._WIDE.set(True)
    pause = A._PAUSE_PROB.set(PAUSE_PROB.get(_voices()[code][0], A.PAUSE_PROB))
    try:
        al = _align_with_edges(A, pcm, tuple(names), quiet=quiet, path=path, jobs=jobs, shown=shown)
    finally:
        A._PAUSE_PROB.reset(pause)
        A._WIDE.reset(token)
    out = _in_ipa(al, plans, unread)
    voiced = _voiced_frames(pcm)
    # words too, so that each phone stays inside its word (their edges are the same times)
    return replace(out, words=_close_voiced_pauses(out.words, voiced), phones=_close_voiced_pauses(out.phones, voiced))


#: A pause between two aligned phones at most this long (seconds) ...
VOICED_PAUSE_MAX_S = 0.3
#: ... through which the voice goes on (at least this share of its 10 ms frames voiced, by
#: :class:`~lipsync.speech.voice.VoiceGate`) is not a pause: the aligner put its optional
#: silence on a quiet voiced sound (the murmur of an m, a weak final ŋ), so the phones on
#: either side meet in its middle. Measured with the transcript on the ``languages`` bench
#: (84 espeak-ng sentences, 20 languages): mean frame agreement with the truth's mouth
#: shapes 0.804 -> 0.817 (languages at 0.75 or more: 15 -> 17; bilabials shown closed 0.957
#: -> 0.969); at 0.2 s 0.813, at 0.1 s 0.807; a 0.5 or 0.8 share 0.814 and 0.807. Without
#: the transcript (the phone loop's voiced pauses that are not closures,
#: :data:`~lipsync.speech.align.LOOP_CLOSURE_QUIETER_DB`) 0.494 -> 0.509 (languages at 0.50
#: or more: 12 -> 13). On the six real recordings no frame changed, with or without the
#: transcript (their pauses are unvoiced: breath and silence). English never comes here.
VOICED_PAUSE_SHARE = 0.3


def _voiced_frames(pcm: np.ndarray) -> np.ndarray:
    """Per 10 ms frame of 16 kHz ``pcm``: voiced (:class:`~lipsync.speech.voice.VoiceGate`)."""
    from .voice import VoiceGate

    gate = VoiceGate()
    gate.feed(pcm)
    return np.asarray(gate.voiced, bool)


def _close_voiced_pauses(phones: Timeline, voiced: np.ndarray) -> Timeline:
    """``phones`` (or words) with each short voiced pause between two of them shared by them
    (:data:`VOICED_PAUSE_MAX_S`); ``voiced``: :func:`_voiced_frames`."""
    from .voice import FRAME_S

    out: List[Segment] = []
    for seg in phones:
        if out:
            a, b = int(round(out[-1].end / FRAME_S)), int(round(seg.start / FRAME_S))
            if 0 < seg.start - out[-1].end <= VOICED_PAUSE_MAX_S + 1e-9 and b > a and a < len(voiced) \
                    and voiced[a:b].mean() >= VOICED_PAUSE_SHARE:
                mid = round((out[-1].end + seg.start) / 2, 6)
                out[-1] = Segment(out[-1].start, mid, out[-1].label)
                seg = Segment(mid, seg.end, seg.label)
        out.append(seg)
    return Timeline(tuple(out), kind=phones.kind, path=phones.path, stated_end=phones.stated_end)


#: Silence put before and after the speech for a second try when a transcript does not fit
#: (words left out, or the phone loop used instead), its times taken off after: speech
#: that starts or ends at the very edge of the audio (synthesised speech, a clip cut tight)
#: can leave the search no path through its first or last word. A held-out Finnish
#: sentence, "Menemme bussilla mummolaan maanantaina.", starts with m at 0 ms: 3 of 4 words
#: left out, confidence 0.24; with 0.1 s of silence each side 0.88, with 0.2 s 0.98, and the
#: same with 0.3 s. Only a second try: put around every sentence, it moved the tuning
#: half's mean (docs/languages.md, "Held-out sentences") from 0.830 to 0.828 (French 0.836
#: -> 0.810, Vietnamese 0.762 -> 0.838), and a rule is chosen there.
EDGE_PAD_S = 0.2


def _align_with_edges(A, pcm: np.ndarray, names: Tuple[str, ...], *, quiet: bool, path, jobs, shown):
    """``A._align_pcm`` of the transcript ``names``; when it does not fit, again with
    :data:`EDGE_PAD_S` of silence each side, the better fit of the two kept."""
    def run(samples):
        with warnings.catch_warnings(record=True) as said:  # shown once the try is chosen
            warnings.simplefilter("always")
            got = A._align_pcm(samples, names, quiet=quiet, path=path, jobs=jobs, recogniser="loop", shown=shown)
        return got, said

    al, said = run(pcm)
    if names and EDGE_PAD_S > 0 and (al.skipped or al.recognised):
        pad = np.zeros(int(round(EDGE_PAD_S * A.SAMPLE_RATE)), pcm.dtype)
        again, said_again = run(np.concatenate([pad, pcm, pad]))
        if (again.confidence or 0.0) > (al.confidence or 0.0):
            al, said = _unpadded(again, len(pad) / A.SAMPLE_RATE, len(pcm) / A.SAMPLE_RATE), said_again
    for w in said:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return al


def _unpadded(al, pad: float, duration: float):
    """``al`` of audio with ``pad`` seconds of silence before it, as times of the audio
    alone (``duration`` long): segments moved back by ``pad`` and cut at its ends."""
    from dataclasses import replace

    from .align import _timeline

    def back(tl):
        segs = [Segment(max(round(s.start - pad, 6), 0.0), min(round(s.end - pad, 6), duration), s.label) for s in tl]
        return _timeline([s for s in segs if s.end > s.start], duration, tl.path)

    return replace(al, words=back(al.words), phones=back(al.phones), duration=duration)


def _in_ipa(al, plans, unread: Sequence[str]):
    """The alignment with the transcript's own words and their IPA phones (loop phones in IPA)."""
    from dataclasses import replace

    from .align import _NON_SPEECH_PHONES, _timeline

    phones = list(al.phones)
    out_words: List[Segment] = []
    out_phones: List[Segment] = []
    i = 0
    for w in al.words:
        inside = []
        while i < len(phones) and phones[i].start < w.end - 1e-9:
            if phones[i].end > w.start + 1e-9:
                inside.append(phones[i])
            else:
                out_phones.append(Segment(phones[i].start, phones[i].end, _ipa_of_unit(phones[i].label)))
            i += 1
        plan = plans.get(w.label)
        if plan is None:  # a loop phone (no words without a transcript)
            out_phones += [Segment(p.start, p.end, _ipa_of_unit(p.label)) for p in inside]
            continue
        text, ipa, counts = plan
        out_words.append(Segment(w.start, w.end, text))
        if len(inside) == sum(counts):
            k, last, silent = 0, w.start, None
            for seg, n in zip(ipa, counts):
                part = inside[k:k + n]
                k += n
                if n == 0:  # aligned as silence (LANGUAGE_UNITS): the gap it leaves is its time
                    silent = seg
                    continue
                if part:
                    if silent is not None and part[0].start - last > 1e-9:
                        out_phones.append(Segment(last, part[0].start, silent))
                    silent = None
                    out_phones.append(Segment(part[0].start, part[-1].end, seg))
                    last = part[-1].end
            if silent is not None and w.end - last > 1e-9:
                out_phones.append(Segment(last, w.end, silent))
        else:  # the phone pass gave another count: each unit in IPA
            out_phones += [Segment(p.start, p.end, _ipa_of_unit(p.label)) for p in inside
                           if p.label not in _NON_SPEECH_PHONES]
    out_phones += [Segment(p.start, p.end, _ipa_of_unit(p.label)) for p in phones[i:]]
    path = al.words.path
    return replace(al, words=_timeline(out_words, al.duration, path), phones=_timeline(out_phones, al.duration, path),
                   transcript=tuple(plans[n][0] if n in plans else n for n in al.transcript if n),
                   skipped=tuple(unread) + tuple(plans[n][0] if n in plans else n for n in al.skipped))
