"""Figures for speech in other languages (issue 29): ``languages`` and ``languages-real``.

``languages`` -- speech with a known phoneme timeline: for each of 20 languages in 8 scripts
(Latin, Cyrillic, Greek, Devanagari, Han, Hangul, Arabic, Japanese kana), one sentence with
bilabials, spoken by espeak-ng, which reports each phoneme as it speaks it
(:func:`lipsync.phonetics.g2p.synthesise`: the truth). Per language:

* the map: the truth's phones, how many map to no viseme (a fallback: must be 0), and
  whether every bilabial stop or nasal maps to the closed mouth;
* with the transcript (``--lang``): the share of 25 fps frames whose mouth shape
  (english-to-rhubarb, the default map) is the truth's, each frame sampled at its centre
  over the whole clip (also without the one-frame shift other languages' boundaries get,
  :data:`~lipsync.speech.align.BOUNDARY_OFFSET_OTHER_S`), and the share of the truth's
  bilabial stops and nasals shown closed: a frame of the video as the renderer's sequencer
  plans it (which keeps every closure on at least one frame), within the phone widened by
  half a frame each side, shows the closed mouth (more than half way through a morph); alignment speed as a
  multiple of real time on one core (``jobs=1``, CPU time of this process);
* without the transcript (the free phone loop): the same two shares.

``languages-real`` -- the six real recordings of ``../shared/languages`` (Japanese, Spanish,
Swedish, Mandarin, French, Russian): with the transcript, whether every transcript word
came back, in order (against the words :func:`~lipsync.phonetics.g2p.transcribe` reads),
the confidence, speed on one core; the Mandarin clip's character boundaries against its
TextGrid (AISHELL-3 aligned by Charsiu: mean and median absolute error of every start and
end, share within 50 ms) and mouth shapes against the TextGrid's pinyin phones; and for
every clip the share of frames where the mouth without the transcript is the mouth with it.
"""

from __future__ import annotations

import os
import resource
import time
import warnings
import wave
from pathlib import Path
from typing import List, Optional, Sequence, Tuple

import numpy as np

from ..speech.align import BOUNDARY_OFFSET_OTHER_S
from . import FIGURES, Context

#: Output frame rate the mouth shapes are compared at (the renderer's default).
FPS = 25.0
#: A bilabial counts as shown when a frame centred within it, or within this much of it,
#: shows the closed mouth: half a frame, so a closure between two frame centres still counts
#: when either neighbouring frame shows it.
BILABIAL_SLACK_S = 0.5 / FPS

#: (BCP 47 tag, script, sentence): everyday sentences with bilabial stops and nasals,
#: written as a native speaker would (numbers as digits in one, read by espeak-ng).
SENTENCES: Tuple[Tuple[str, str, str], ...] = (
    ("fr", "Latin", "Le petit bateau bleu passe sous le pont de pierre."),
    ("es", "Latin", "Mi padre compró un barco blanco para pescar en el mar."),
    ("de", "Latin", "Mein Bruder baut ein Boot aus Papier und Pappe."),
    ("it", "Latin", "Il mio bambino mangia una mela bianca ogni mattina."),
    ("pt-BR", "Latin", "Meu pai comprou um barco muito bonito no mês passado."),
    ("sv", "Latin", "Min mamma bakar bröd med mjöl och smör på morgonen."),
    ("pl", "Latin", "Moja mama piecze pyszny chleb w piątek rano."),
    ("nl", "Latin", "Mijn broer maakt een mooie boot van papier."),
    ("tr", "Latin", "Benim babam pazartesi günü büyük bir balık aldı."),
    ("fi", "Latin", "Minun poikani pelaa palloa puistossa aamupäivällä."),
    ("id", "Latin", "Bapak membeli 3 buah mangga di pasar pagi ini."),
    ("vi", "Latin", "Mẹ tôi mua một bó hoa đẹp ở chợ buổi sáng."),
    ("ru", "Cyrillic", "Мой папа купил большую белую лодку в мае."),
    ("uk", "Cyrillic", "Мій брат пише мамі про погоду біля моря."),
    ("el", "Greek", "Ο μπαμπάς μου αγόρασε μια μεγάλη μπλε βάρκα."),
    ("hi", "Devanagari", "मेरे पापा ने बाज़ार से बहुत मीठे आम खरीदे।"),
    ("zh", "Han", "爸爸妈妈明天不买苹果，他们买面包。"),
    ("ko", "Hangul", "우리 아버지는 바다에서 배를 봤습니다."),
    ("ar", "Arabic", "ذهب أبي إلى البحر مع أمي في الصباح."),
    ("ja", "Japanese kana", "ぼくの ははは まいばん パンを たべます。"),
)

#: The real recordings (folder, language) in ``../shared/languages``.
REAL = (("ja_commonvoice", "ja"), ("es_mls", "es"), ("sv_nst", "sv"), ("zh_aishell3", "zh"),
        ("fr_fleurs", "fr"), ("ru_css10", "ru"))


def _cpu() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    return own.ru_utime + own.ru_stime


def _pmap():
    from ..phonemes import DEFAULT_MAP, load_map

    return load_map(DEFAULT_MAP)


def frames(tl, pmap, duration: float) -> np.ndarray:
    """The mouth shape of each 25 fps frame (sampled at the frame's centre; silence: rest)."""
    from ..phonemes import map_timeline

    centres = (np.arange(int(round(duration * FPS))) + 0.5) / FPS
    out = np.full(len(centres), pmap.silence, dtype=object)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # counted apart: the map figure's fallbacks
        mapped = map_timeline(tl, pmap, notation="ipa") if len(tl) else []
    for s in mapped:
        out[(centres >= s.start) & (centres < s.end)] = s.label
    return out


def shown(tl, pmap, duration: float) -> np.ndarray:
    """The viseme each 25 fps frame of the video shows most (of the two it morphs between,
    the one with the larger weight), as the renderer's sequencer plans it: it keeps every
    closure on at least one frame, however short (``closures`` of the map)."""
    from ..phonemes import map_timeline
    from ..sequencer import sequence

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mapped = map_timeline(tl, pmap, notation="ipa") if len(tl) else tl
    specs = sequence(mapped.replace(stated_end=duration) if len(tl) else mapped, fps=FPS, rest=pmap.silence,
                     closures=pmap.closures, duration=duration)
    return np.array([f.from_viseme if f.alpha < 0.5 else f.to_viseme for f in specs], dtype=object)


def is_bilabial(label: str) -> bool:
    """A bilabial stop or nasal (the lips close), by the phonetics room's features."""
    from ..phonetics import parse

    ph = parse(label)
    if ph is None or not ph.parts:
        return False
    f = ph.parts[0].features
    return f.place == "bilabial" and f.manner in ("stop", "nasal")


def bilabials_closed(truth, shown: np.ndarray, closed: Sequence[str]) -> Optional[float]:
    """Share of the truth's lip closures (runs of touching bilabial stops and nasals, as in
    "um barco": one closure) during which a frame of the video (:func:`shown`: frame n
    shows time n / fps), widened by :data:`BILABIAL_SLACK_S` each side, shows the closed
    mouth (more than half way through a morph towards or away from it)."""
    times = np.arange(len(shown)) / FPS
    runs: List[List[float]] = []
    for s in truth:
        if is_bilabial(s.label):
            if runs and abs(runs[-1][1] - s.start) < 1e-6:
                runs[-1][1] = s.end
            else:
                runs.append([s.start, s.end])
    hits = [bool(np.isin(shown[(times >= a - BILABIAL_SLACK_S) & (times < b + BILABIAL_SLACK_S)], list(closed)).any())
            for a, b in runs]
    return float(np.mean(hits)) if hits else None


def _write_wav(path: Path, pcm: np.ndarray, rate: int) -> None:
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(np.ascontiguousarray(pcm, np.int16).tobytes())


def _timeline(segments, duration: float):
    from ..timeline import PHONEME, Segment, Timeline

    return Timeline(tuple(Segment(a, b, l) for a, b, l in segments), kind=PHONEME, stated_end=duration)


def _aligned(pcm, text, lang):
    """(alignment, CPU seconds) on one core, warnings kept."""
    from ..speech.align import align

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        c = _cpu()
        al = align(pcm, text, lang=lang, jobs=1)
        cpu = _cpu() - c
    return al, cpu, [str(w.message) for w in caught]


def _synthetic(ctx: Context, rows: List[dict]) -> None:
    from ..phonetics.g2p import espeak_available, synthesise
    from ..speech.audio import load_audio

    if not espeak_available():
        rows.append({"figure": "languages", "language": "(espeakng-loader not installed: pip install 'lipsync[lang]')"})
        return
    pmap = _pmap()
    closed = pmap.closures
    for lang, script, text in SENTENCES[:4] if ctx.quick else SENTENCES:
        pcm22, phonemes = synthesise(text, lang)
        wav = ctx.tmp / f"synth-{lang}.wav"
        _write_wav(wav, pcm22, 22050)
        pcm = load_audio(wav)
        duration = len(pcm) / 16000
        truth = _timeline(phonemes, duration)
        fallbacks = sorted({s.label for s in truth if pmap.targets(s.label, notation="ipa") is None})
        bil_map = [pmap.targets(s.label, notation="ipa") == list(closed) for s in truth if is_bilabial(s.label)]
        truth_frames = frames(truth, pmap, duration)
        row = {"figure": "languages", "language": lang, "script": script, "seconds": round(duration, 1),
               "phones": len(truth), "fallbacks": len(fallbacks) and ",".join(fallbacks),
               "bilabials_map_closed": f"{sum(bil_map)}/{len(bil_map)}",
               "truth_bilabials_seen": _r(bilabials_closed(truth, shown(truth, pmap, duration), closed))}
        _align(pcm[:8000], text, lang)  # loads the decoder and the language's voice first
        for case, transcript in (("text", text), ("no_text", None)):
            al, cpu, said = _aligned(pcm, transcript, lang)
            ours = frames(al.phones, pmap, duration)
            row[f"{case}_frames_agree"] = _r(float(np.mean(ours == truth_frames)))
            if transcript is not None:  # without the one-frame shift other languages get
                back = frames(_shifted(al.phones, -BOUNDARY_OFFSET_OTHER_S, duration), pmap, duration)
                row["text_frames_agree_unshifted"] = _r(float(np.mean(back == truth_frames)))
            row[f"{case}_bilabials_closed"] = _r(bilabials_closed(truth, shown(al.phones, pmap, duration), closed))
            row[f"{case}_x_real_time_cpu"] = round(duration / max(cpu, 1e-9), 1)
            if transcript is not None:
                row["confidence"] = _r(al.confidence)
                row["warnings"] = len(said)
        rows.append(row)


def _shifted(tl, dt: float, duration: float):
    return _timeline([(max(s.start + dt, 0.0), min(s.end + dt, duration), s.label) for s in tl
                      if s.end + dt > 0 and s.start + dt < duration], duration)


def _align(pcm, text, lang):
    from ..speech.align import align

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return align(pcm, text, lang=lang, jobs=1)


def _r(x: Optional[float], nd: int = 3):
    return None if x is None else round(float(x), nd)


def languages_dir() -> Optional[Path]:
    """``../shared/languages`` beside the checkout (or a level up), or $LIPSYNC_LANGUAGES."""
    if os.environ.get("LIPSYNC_LANGUAGES"):
        return Path(os.environ["LIPSYNC_LANGUAGES"])
    root = Path(__file__).resolve().parents[2]
    for up in (root.parent, root.parent.parent):
        if (up / "shared" / "languages" / "SOURCE.md").is_file():
            return up / "shared" / "languages"
    return None


def _read_words_tier(path: Path) -> List[Tuple[float, float, str]]:
    from ..readers import read_timeline

    tl = read_timeline(path, tier="words")
    return [(s.start, s.end, s.label) for s in tl if s.label not in ("", "[SIL]", "sil", "sp")]


def _real(ctx: Context, rows: List[dict]) -> None:
    from ..phonetics.g2p import espeak_available, transcribe
    from ..readers import read_timeline
    from ..speech.audio import load_audio

    root = languages_dir()
    if root is None or not espeak_available():
        rows.append({"figure": "languages-real", "clip": "(../shared/languages or the lang extra missing)"})
        return
    pmap = _pmap()
    for folder, lang in REAL:
        d = root / folder
        audio = next(p for p in sorted(d.iterdir()) if p.suffix in (".wav", ".mp3", ".ogg", ".opus"))
        text = (d / (audio.stem + ".txt")).read_text(encoding="utf-8")
        pcm = load_audio(audio)
        duration = len(pcm) / 16000
        _align(pcm[:8000], text, lang)
        al, cpu, said = _aligned(pcm, text, lang)
        expected = [w.text for w in transcribe(text, lang) if w.read and w.phones]
        got = al.words.labels()
        free, _, _ = _aligned(pcm, None, lang)
        with_text, without = frames(al.phones, pmap, duration), frames(free.phones, pmap, duration)
        row = {"figure": "languages-real", "clip": f"{folder} ({lang})", "seconds": round(duration, 1),
               "words": len(expected), "all_words_in_order": "yes" if got == expected else f"no ({len(got)} back)",
               "confidence": _r(al.confidence), "warnings": len(said),
               "x_real_time_cpu": round(duration / max(cpu, 1e-9), 1),
               "no_text_mouth_agrees_with_text": _r(float(np.mean(with_text == without)))}
        grids = list(d.glob("*.TextGrid"))
        if grids:
            ref = _read_words_tier(grids[0])
            ours = [(s.start, s.end, s.label) for s in al.words]
            if [w for *_, w in ref] == [w for *_, w in ours]:
                err = np.abs(np.array([[a[0] - b[0], a[1] - b[1]] for a, b in zip(ours, ref)]).ravel())
                back = np.abs(np.array([[a[0] - BOUNDARY_OFFSET_OTHER_S - b[0], a[1] - BOUNDARY_OFFSET_OTHER_S - b[1]]
                                        for a, b in zip(ours, ref)]).ravel())
                row["words_vs_textgrid_mean_ms_unshifted"] = round(1000 * float(back.mean()), 1)
                row.update({"words_vs_textgrid_mean_ms": round(1000 * float(err.mean()), 1),
                            "words_vs_textgrid_median_ms": round(1000 * float(np.median(err)), 1),
                            "words_vs_textgrid_within_50ms": _r(float(np.mean(err <= 0.05)))})
            else:
                row["words_vs_textgrid"] = "characters differ"
            phones = read_timeline(grids[0], tier="phones")
            ref_frames = frames_notation(phones, pmap, duration)
            row["text_mouth_vs_textgrid_phones"] = _r(float(np.mean(with_text == ref_frames)))
            row["no_text_mouth_vs_textgrid_phones"] = _r(float(np.mean(without == ref_frames)))
        rows.append(row)


def frames_notation(tl, pmap, duration: float) -> np.ndarray:
    """As :func:`frames` for a timeline in any notation (detected: the TextGrid's pinyin)."""
    from ..phonemes import map_timeline
    from ..timeline import Timeline

    centres = (np.arange(int(round(duration * FPS))) + 0.5) / FPS
    out = np.full(len(centres), pmap.silence, dtype=object)
    speech = Timeline(tuple(s for s in tl if s.label not in ("[SIL]", "sil", "sp", "")), kind=tl.kind,
                      stated_end=duration)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for s in map_timeline(speech, pmap):
            out[(centres >= s.start) & (centres < s.end)] = s.label
    return out


FIGURES.register("languages", _synthetic)
FIGURES.register("languages-real", _real)
