"""Translation dubbing (``dub_translation``): an English GRID video re-voiced in Spanish.

``lipsync dub bbwm5s.mpg --audio SPANISH --text SPANISH.txt --lang es -o OUT`` as a child
process, no ``--bank`` (the bank made from the video's own English speech, ``--video-lang``
left at English), a fresh cache: its exit code, then on the output's decoded frames the
face mesh's lip opening (:func:`lipsync.face.measure.lip_opening`) around every p, b and m of
the Spanish speech (their times from aligning it with ``--lang es``): the mouth counts as
closed there when some frame within ±60 ms of the phone is at most :func:`closed_below`.

**What "closed" is** (independent of the dub): the real speaker's own lips. Over GRID s1's
held-out sentences other than the dubbed one (their sound aligned with their transcripts),
the smallest lip opening within ±60 ms of each real P, B and M; the threshold is the 90th
percentile of those: as closed as his lips are at nine in ten of his real closures.

Beside it, measured the same way in the same run: the real clips themselves (about 90 %
by construction), an English dub of the same video (another GRID sentence's sound), and how
often the Spanish dub's mouth is "closed" in the middle frame of its open vowels (a, e, o) by
the same threshold (the measure's false alarms).
"""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path
from typing import List, Sequence

import numpy as np

from . import FIGURES, Context
from . import grid

#: The video dubbed (English, GRID s1) and the English sentence of the reference dub.
VIDEO, ENGLISH = "bbwm5s", "prap6p"
#: Either side of a phone in which a closed frame counts (the issue's ±60 ms).
WINDOW_S = 0.06
#: Real closures measured for the threshold (held-out sentences, never the dubbed video).
REFERENCE_CLIPS = 12
#: The threshold is this percentile of the real speaker's closure minima.
CLOSED_PERCENTILE = 90
#: Spanish's closures (IPA labels of the aligner with --lang es) and its open vowels.
CLOSURES_ES, OPEN_ES = ("p", "b", "m"), ("a", "e", "o")
CLOSURES_EN = ("P", "B", "M")


def spanish() -> tuple:
    """``(audio, transcript file)`` of the Spanish sentence (shared/languages or tests/data)."""
    here = Path(__file__).resolve().parents[2] / "tests" / "data" / "languages"
    a = here / "mls-es-13697_11991_000000.opus"
    return a, a.with_suffix(".txt")


def openings(video: Path) -> np.ndarray:
    """Lip opening per decoded frame of ``video`` (NaN where no face)."""
    from ..face import measure as M
    from ..face.track import track_video

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tr = track_video(video)
    o = M.lip_opening(tr.points)
    o[~tr.found] = np.nan
    return o


def window_minima(opening: np.ndarray, phones, labels: Sequence[str], fps: float) -> np.ndarray:
    """The smallest opening within :data:`WINDOW_S` of each phone labelled one of ``labels``."""
    out = []
    for s in phones:
        if s.label.rstrip("012") in labels:
            a = max(0, int(np.floor((s.start - WINDOW_S) * fps)))
            b = min(len(opening), int(np.ceil((s.end + WINDOW_S) * fps)) + 1)
            if b > a:
                out.append(float(np.nanmin(opening[a:b])))
    return np.array(out)


def closed_below(clips: Sequence[str]) -> tuple:
    """``(threshold, minima)``: :data:`CLOSED_PERCENTILE` of the real speaker's closure minima."""
    from ..speech.align import align

    minima = []
    for c in clips:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            phones = align(grid.video(c), grid.transcript(c)).phones
        minima.append(window_minima(openings(grid.video(c)), phones, CLOSURES_EN, 25.0))
    m = np.concatenate(minima)
    return float(np.percentile(m, CLOSED_PERCENTILE)), m


def _dub(video: Path, audio: Path, text, out: Path, cache: Path, lang=None) -> int:
    cmd = [sys.executable, "-m", "lipsync", "dub", str(video), "--audio", str(audio), "-o", str(out),
           "--cache", str(cache), "-q"]
    if text is not None:
        cmd += ["--text", str(text)]
    if lang:
        cmd += ["--lang", lang]
    return subprocess.run(cmd, capture_output=True, text=True).returncode


@FIGURES.decorator("dub_translation")
def translation_figures(ctx: Context, rows: List[dict]) -> None:
    from ..speech.align import align

    reference = [c for c in grid.held_out() if c not in (VIDEO, ENGLISH)][:REFERENCE_CLIPS]
    threshold, real = closed_below(reference)
    rows.append({"figure": "dub_translation", "what": f"real speaker, {len(reference)} held-out sentences",
                 "closures": len(real), "closed %": round(100 * float(np.mean(real <= threshold)), 1),
                 "closed below": round(threshold, 4)})
    audio, text = spanish()
    out = ctx.tmp / "es-dub.mp4"
    code = _dub(grid.video(VIDEO), audio, text, out, ctx.tmp / "cache-es", lang="es")
    row = {"figure": "dub_translation", "what": f"{VIDEO} dubbed in Spanish (--lang es, no bank)", "exit": code}
    if code == 0:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            phones = align(audio, text.read_text(encoding="utf-8"), lang="es").phones
        o = openings(out)
        closures = window_minima(o, phones, CLOSURES_ES, 25.0)
        vowels = np.array([o[min(len(o) - 1, int(round((s.start + s.end) / 2 * 25.0)))]
                           for s in phones if s.label in OPEN_ES])  # the vowel's middle frame
        row.update({"closures": len(closures), "closed %": round(100 * float(np.mean(closures <= threshold)), 1),
                    "open vowels called closed %": round(100 * float(np.mean(vowels <= threshold)), 1)})
    rows.append(row)
    out = ctx.tmp / "en-dub.mp4"
    code = _dub(grid.video(VIDEO), grid.video(ENGLISH), grid.transcript(ENGLISH), out, ctx.tmp / "cache-en")
    row = {"figure": "dub_translation", "what": f"{VIDEO} dubbed with {ENGLISH} (English)", "exit": code}
    if code == 0:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            phones = align(grid.video(ENGLISH), grid.transcript(ENGLISH)).phones
        closures = window_minima(openings(out), phones, CLOSURES_EN, 25.0)
        row.update({"closures": len(closures), "closed %": round(100 * float(np.mean(closures <= threshold)), 1)})
    rows.append(row)
