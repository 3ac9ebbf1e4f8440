"""Alignment figures (registered in :data:`lipsync.bench.FIGURES` as ``align``).

On the MFA corpus recording (``ctx.mfa/acoustic_corpus.wav``, 26.7 s of real speech):

1. speed as a multiple of real time, with the .lab transcript and without (recognition
   first), wall clock and CPU (this process and its workers), median of repeats; with the
   transcript also whether the fit check's phone loop was asked (``loop_asked``), and the
   speed with it asked whatever the words' own scores: beside the phone pass, in one
   process (``jobs_1``), and with the loop of one-phone words it had before, in the same run;
2. accuracy against MFA's own ``phones`` tier: share of MFA's phones matched (difflib's
   matching blocks of the labels), mean absolute boundary error of matched phones, and the share of
   10 ms frames showing the same Rhubarb mouth shape (both mapped with english-to-rhubarb);
3. the espeak-ng samples against the synthesiser's own phone times (mean and median signed
   boundary error: pocketsphinx's bias);
4. linear growth: the recording repeated 2 and 6 times (53 s, 160 s) aligned with its
   transcript: CPU seconds per second of audio of the longer against the shorter.

On the GRID sentences of speaker s1 (``../shared/grid-s1``, 40 real 3 s sentences with
GRID's own word alignments; without it, the few copied into tests/data), rows of figure
``align-grid`` (issue 20):

5. each sentence with its own transcript: sentences whose words came back as the
   transcript (no warning), lowest confidence, speed; word boundary error against GRID's
   ``.align`` (every start and end of a non-silence word, 10 ms frames against GRID's
   times) split by where the boundary is: between two words, or at a pause (a GRID
   ``sil``/``sp`` beside it: there the two aligners' silence models decide, with breaths,
   lip noise and the silent closure of a stop on either side; see :func:`grid_boundaries`);
   and where the sentence starts with "lay" or "set" after a pause, both aligners' start
   against the sound itself (:func:`sound_onset`: L's voicing, S's frication), signed
   (negative: before the sound) and absolute;
6. each sentence with other sentences' transcripts (the 7th, 13th and 20th next in name
   order: 3 each), with its letter left out, and with a word added: how many are reported
   (an AlignmentWarning), how many of those with a confidence below 0.5, and the
   confidences.
"""

from __future__ import annotations

import contextlib
import os
import re
import resource
import statistics
import time
import warnings
from pathlib import Path
from typing import List, Optional

import numpy as np

from . import FIGURES, Context

_SILENCE = {"", "SIL", "SP", "SPN"}


def _phones(tl):
    out = []
    for s in tl:
        label = re.sub(r"[0-2]$", "", s.label).upper()
        if label not in _SILENCE:
            out.append((s.start, s.end, label))
    return out


def _matches(a, b):
    # difflib's matching blocks: a different matcher from the test's LCS, so the two cross-check
    import difflib

    sm = difflib.SequenceMatcher(None, a, b, autojunk=False)
    return [(blk.a + k, blk.b + k) for blk in sm.get_matching_blocks() for k in range(blk.size)]


def boundary_stats(ours, ref):
    """(share of ``ref``'s phones matched, mean |error| s, median signed error s)."""
    a, b = _phones(ours), _phones(ref)
    err = []
    pairs = _matches([x[2] for x in a], [x[2] for x in b])
    for i, j in pairs:
        err += [a[i][0] - b[j][0], a[i][1] - b[j][1]]
    err = np.array(err) if err else np.zeros(1)
    return len(pairs) / max(1, len(b)), float(np.abs(err).mean()), float(np.median(err))


def frame_agreement(ours, ref, duration):
    """Share of 10 ms frames whose Rhubarb mouth shape (english-to-rhubarb map) is the same."""
    from ..phonetics.phonemes import load_map, map_timeline

    pmap = load_map("english-to-rhubarb")
    centres = (np.arange(int(round(duration * 100))) + 0.5) / 100

    def shapes(tl):
        out = np.full(len(centres), pmap.silence, dtype=object)
        for s in map_timeline(tl, pmap):
            out[(centres >= s.start) & (centres < s.end)] = s.label
        return out

    return float(np.mean(shapes(ours) == shapes(ref)))


def _cpu() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def _timed(fn, repeat: int):
    walls, cpus, result = [], [], None
    for _ in range(repeat):
        w, c = time.perf_counter(), _cpu()
        result = fn()
        walls.append(time.perf_counter() - w)
        cpus.append(_cpu() - c)
    return result, statistics.median(walls), statistics.median(cpus)


#: The phones of the fit check's loop as issue 20 first built it (:func:`_word_loop_scores`).
_WORD_LOOP_PHONES = ("AA AE AH AO AW AY B CH D DH EH ER EY F G HH IH IY JH K L M N NG OW OY P R S SH "
                     "T TH UH UW V W Y Z ZH").split()


def _word_loop_scores(pcm):
    """The fit check's phone loop as issue 20's first two rounds built it: a grammar of 39
    one-phone words (cross-word triphones), each following any other with probability 0.05.
    Run beside today's context-independent loop for the speed figure."""
    from ..speech import align as A

    d = A._aligner()
    if d.lookup_word("ph_aa") is None:
        for p in _WORD_LOOP_PHONES:
            d.add_word(f"ph_{p.lower()}", p, False)
        arcs = [(0, 0, 0.05, f"ph_{p.lower()}") for p in _WORD_LOOP_PHONES]
        d.add_fsg("word-loop", d.create_fsg("word-loop", 0, 0, arcs))
    try:
        d.activate_search("word-loop")
        A._decode(d, pcm)
        return A._search_frame_scores(d, len(pcm) // A._SAMPLES_PER_FRAME + 2)[0] if d.hyp() else None
    except RuntimeError:
        return None


@contextlib.contextmanager
def _loop_asks():
    """A list that gets one item per alignment that asked the fit check's phone loop."""
    from ..speech import align as A

    asked: list = []
    original = A._PhoneLoop.start

    def start(loop):
        if not getattr(loop, "_bench_counted", False):
            loop._bench_counted = True
            asked.append(1)
        return original(loop)

    A._PhoneLoop.start = start
    try:
        yield asked
    finally:
        A._PhoneLoop.start = original


def _fit_check_speed(pcm, transcript, seconds, repeat) -> dict:
    """Speed with the fit check's phone loop asked whatever the words' own scores (as it is
    for transcripts they leave in doubt, :data:`~lipsync.speech.align.FIT_WITHOUT_LOOP`):
    today's loop beside the phone pass (wall and CPU), in this process only (``jobs=1``),
    and the loop of one-phone words it had before, side by side (issue 20)."""
    from ..speech import align as A

    def run(jobs):
        return lambda: A.align_samples(pcm, transcript, quiet=True, jobs=jobs)

    saved, current = A.FIT_WITHOUT_LOOP, A._phone_loop_scores
    A.FIT_WITHOUT_LOOP = float("inf")
    try:
        _, wall, cpu = _timed(run(os.cpu_count()), repeat)
        _, wall1, _ = _timed(run(1), repeat)
        A._phone_loop_scores = _word_loop_scores
        _, old_wall, old_cpu = _timed(run(os.cpu_count()), repeat)
    finally:
        A.FIT_WITHOUT_LOOP, A._phone_loop_scores = saved, current
    return {"loop_asked_x_real_time_wall": round(seconds / wall, 1),
            "loop_asked_x_real_time_cpu": round(seconds / cpu, 1),
            "loop_asked_x_real_time_wall_jobs_1": round(seconds / wall1, 1),
            "word_loop_asked_x_real_time_wall": round(seconds / old_wall, 1),
            "word_loop_asked_x_real_time_cpu": round(seconds / old_cpu, 1)}


@FIGURES.decorator("align")
def _align(ctx: Context, rows: List[dict]) -> None:
    from ..speech.align import align_samples
    from ..speech.audio import load_audio
    from ..motion.timeline import Segment, Timeline
    from ..readers import read_timeline

    wav, lab, grid = (ctx.mfa / f"acoustic_corpus.{ext}" for ext in ("wav", "lab", "TextGrid"))
    pcm = load_audio(wav)
    seconds = len(pcm) / 16000
    text = lab.read_text()
    ref = read_timeline(grid)
    repeat = 1 if ctx.quick else 3
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "yknow" is not in CMUdict
        # model loading (about 0.5 s per decoder) is not alignment speed
        align_samples(pcm[:48000], text, quiet=True)
        align_samples(pcm[:48000], None, quiet=True)
        for name, transcript in (("with transcript", text), ("without transcript", None)):
            with _loop_asks() as asked:
                al, wall, cpu = _timed(lambda: align_samples(pcm, transcript, quiet=True, jobs=os.cpu_count()),
                                       repeat)
            matched, mae, bias = boundary_stats(al.phones, ref)
            rows.append({"figure": "align", "case": f"MFA corpus {seconds:.1f} s, {name}",
                         "x_real_time_wall": round(seconds / wall, 1), "x_real_time_cpu": round(seconds / cpu, 1),
                         "phones_matched_%": round(100 * matched, 1), "mean_abs_boundary_ms": round(1000 * mae, 1),
                         "median_signed_ms": round(1000 * bias, 1),
                         "same_mouth_shape_frames_%": round(100 * frame_agreement(al.phones, ref, ref.duration), 1)})
            if transcript is not None:
                rows[-1]["loop_asked"] = "yes" if asked else "no"
                rows[-1].update(_fit_check_speed(pcm, transcript, seconds, repeat))
        samples = Path(__file__).resolve().parents[2] / "samples"
        for name in ("hello", "balloons"):
            if not (samples / f"{name}.wav").is_file():
                continue
            truth = read_timeline(samples / f"{name}.TextGrid")
            al, wall, cpu = _timed(lambda: align_samples(load_audio(samples / f"{name}.wav"),
                                                         (samples / f"{name}.lab").read_text()), 1)
            matched, mae, bias = boundary_stats(al.phones, truth)
            rows.append({"figure": "align", "case": f"espeak sample {name} ({truth.duration:.1f} s), with transcript",
                         "x_real_time_wall": round(truth.duration / wall, 1),
                         "x_real_time_cpu": round(truth.duration / cpu, 1),
                         "phones_matched_%": round(100 * matched, 1), "mean_abs_boundary_ms": round(1000 * mae, 1),
                         "median_signed_ms": round(1000 * bias, 1),
                         "same_mouth_shape_frames_%": round(100 * frame_agreement(al.phones, truth, truth.duration), 1)})
        if not ctx.quick:
            # Linear growth: CPU per second of audio for 2 and 6 copies of the recording (both
            # long enough to be cut into chunks), and the peak memory of the longer one.
            per_s = {}
            for copies in (2, 6):
                long_pcm = np.tile(pcm, copies)
                long_ref = Timeline(tuple(Segment(s.start + k * seconds, s.end + k * seconds, s.label)
                                          for k in range(copies) for s in ref), stated_end=copies * seconds)
                al, wall, cpu = _timed(lambda: align_samples(long_pcm, " ".join([text] * copies), quiet=True), 1)
                per_s[copies] = cpu / (copies * seconds)
                rows.append({"figure": "align", "case": f"MFA corpus x{copies} ({copies * seconds:.0f} s), with transcript",
                             "x_real_time_wall": round(copies * seconds / wall, 1),
                             "x_real_time_cpu": round(copies * seconds / cpu, 1),
                             "cpu_per_audio_s_vs_x2": round(per_s[copies] / per_s[2], 2),
                             "same_mouth_shape_frames_%": round(100 * frame_agreement(al.phones, long_ref,
                                                                                      copies * seconds), 1)})


# --- GRID (issue 20) ------------------------------------------------------------------------

#: GRID's time unit (1/25000 s) and its silence labels.
_GRID_TICKS = 25000
_GRID_SILENCE = ("sil", "sp")


def _grid_dir() -> List[Path]:
    """Folders holding GRID sentences (``NAME.align`` beside ``NAME.mpg``/``.flac``): the
    shared 40 when found ($LIPSYNC_GRID, or ``shared/grid-s1`` beside the checkout or a
    level up), else the tests' copies."""
    root = Path(__file__).resolve().parents[2]
    candidates = [Path(os.environ["LIPSYNC_GRID"])] if os.environ.get("LIPSYNC_GRID") else []
    candidates += [up / "shared" / "grid-s1" for up in (root.parent, root.parent.parent)]
    for c in candidates:
        if len(list(c.glob("*.align"))) >= 20:
            return [c]
    return [root / "tests" / "data" / "grid-s1", root / "tests" / "data" / "grid-s1-audio"]


def read_grid_align(path) -> List[tuple]:
    """(start s, end s, label) rows of a GRID ``.align`` file (``sil``/``sp`` kept)."""
    rows = []
    for line in Path(path).read_text().splitlines():
        f = line.split()
        if len(f) == 3:
            rows.append((int(f[0]) / _GRID_TICKS, int(f[1]) / _GRID_TICKS, f[2]))
    return rows


def grid_boundaries(words, rows) -> List[tuple]:
    """(our time - GRID's time in s, "between" or "pause") for every start and end of GRID's words.

    ``words`` is our words timeline (its labels must be GRID's words); a boundary is
    "between" when GRID has the neighbouring word right there (no ``sil``/``sp`` row beside
    it), else "pause". GRID's word times come from an HMM aligner like ours; where a word
    meets silence they say as much about each aligner's silence model as about the word.
    """
    ref = [(i, r) for i, r in enumerate(rows) if r[2] not in _GRID_SILENCE]
    out = []
    for seg, (i, (start, end, _)) in zip(words, ref):
        before = "between" if i > 0 and rows[i - 1][2] not in _GRID_SILENCE else "pause"
        after = "between" if i + 1 < len(rows) and rows[i + 1][2] not in _GRID_SILENCE else "pause"
        out += [(seg.start - start, before), (seg.end - end, after)]
    return out


def _grid_align(pcm, text):
    """(alignment, AlignmentWarnings) of one sentence."""
    from ..speech.align import AlignmentWarning, align_samples

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        al = align_samples(pcm, text, quiet=True)
    return al, [w for w in caught if issubclass(w.category, AlignmentWarning)]


#: The band whose energy starts each sentence-initial GRID word that follows a pause and
#: has no lip closure to time it by: "lay" begins voiced (its L: the voice's fundamental
#: and L's low first formant, under 400 Hz), "set" with its S's frication (4-8 kHz).
#: Breaths and lip noise before speech have little energy in either band.
SOUND_ONSET_BANDS = {"lay": (80, 400), "set": (4000, 8000)}
#: The onset is where the band rises this many dB above its level before speech (the 20th
#: percentile of the first 0.3 s) and stays there for ONSET_FRAMES frames of 10 ms.
ONSET_RISE_DB = 20.0
ONSET_FRAMES = 3


def sound_onset(pcm, lo: float, hi: float) -> Optional[float]:
    """Seconds at which the energy between ``lo`` and ``hi`` Hz first rises for good
    (:data:`ONSET_RISE_DB`, :data:`ONSET_FRAMES`) after the first 0.1 s, or None."""
    x = np.asarray(pcm, dtype=np.float64) / 32768.0
    n = (len(x) - 400) // 160 + 1
    if n < 30:
        return None
    frames = np.lib.stride_tricks.sliding_window_view(x, 400)[::160][:n] * np.hanning(400)
    spectrum = np.abs(np.fft.rfft(frames, axis=1)) ** 2
    f = np.fft.rfftfreq(400, 1 / 16000)
    db = 10 * np.log10(spectrum[:, (f >= lo) & (f < hi)].sum(axis=1) + 1e-12)
    up = db > np.percentile(db[:30], 20) + ONSET_RISE_DB
    for i in range(10, n - ONSET_FRAMES):
        if up[i: i + ONSET_FRAMES].all():
            return i * 0.01
    return None


@FIGURES.decorator("align-grid")
def _align_grid(ctx: Context, rows: List[dict]) -> None:
    from ..speech.audio import load_audio

    sentences = []
    for folder in _grid_dir():
        for align_path in sorted(folder.glob("*.align")):
            audio = next((align_path.with_suffix(e) for e in (".mpg", ".flac", ".wav")
                          if align_path.with_suffix(e).is_file()), None)
            if audio is not None:
                ref = read_grid_align(align_path)
                words = [w for _, _, w in ref if w not in _GRID_SILENCE]
                sentences.append((align_path.stem, load_audio(audio), ref, words))
    if not sentences:
        return
    n = len(sentences)
    _grid_align(sentences[0][1], " ".join(sentences[0][3]))  # model loading is not alignment speed
    # 5. own transcripts
    same, confidences, errors, audio_s = 0, [], [], 0.0
    cpu0, wall0 = _cpu(), time.perf_counter()
    with _loop_asks() as asked:
        results = [_grid_align(pcm, " ".join(words)) for _, pcm, _, words in sentences]
    cpu, wall = _cpu() - cpu0, time.perf_counter() - wall0
    for (name, pcm, ref, words), (al, warned) in zip(sentences, results):
        audio_s += len(pcm) / 16000
        confidences.append(al.confidence)
        if al.words.labels() == words and not al.recognised and not warned:
            same += 1
            errors += grid_boundaries(al.words, ref)
    row = {"figure": "align-grid", "case": f"GRID s1, {n} sentences, own transcripts",
           "transcript_words_back": f"{same}/{n}", "lowest_confidence": round(min(confidences), 2),
           "loop_asked": f"{len(asked)}/{n}",
           "x_real_time_wall": round(audio_s / wall, 1), "x_real_time_cpu": round(audio_s / cpu, 1)}
    for where in ("between", "pause", None):
        e = np.abs([x for x, w in errors if where in (None, w)])
        if len(e):
            key = where or "all"
            row[f"{key}_n"] = len(e)
            row[f"{key}_mean_ms"] = round(1000 * float(e.mean()), 1)
            row[f"{key}_p90_ms"] = round(1000 * float(np.percentile(e, 90)), 1)
    rows.append(row)
    # 5b. who is right at a pause: sentence-initial "lay" and "set" against the sound itself
    onsets = {}
    for (name, pcm, ref, words), (al, warned) in zip(sentences, results):
        if words and words[0] in SOUND_ONSET_BANDS and al.words.labels() == words:
            onset = sound_onset(pcm, *SOUND_ONSET_BANDS[words[0]])
            first = next(r for r in ref if r[2] not in _GRID_SILENCE)
            if onset is not None:
                onsets.setdefault(words[0], []).append((al.words[0].start - onset, first[0] - onset))
    for word, pairs in sorted(onsets.items()):
        ours, theirs = (np.array(x) for x in zip(*pairs))
        lo, hi = SOUND_ONSET_BANDS[word]
        rows.append({"figure": "align-grid",
                     "case": f'GRID s1, start of a first "{word}" against its sound ({lo}-{hi} Hz onset)',
                     "n": len(pairs), "ours_median_ms": round(1000 * float(np.median(ours))),
                     "ours_mean_abs_ms": round(1000 * float(np.abs(ours).mean())),
                     "grid_median_ms": round(1000 * float(np.median(theirs))),
                     "grid_mean_abs_ms": round(1000 * float(np.abs(theirs).mean()))})
    # 6. transcripts that do not fit: another sentence's, the letter left out, a word added
    cases = {"another sentence's transcript (3 each)": [], "its letter left out": [], "a word added": []}
    for i, (name, pcm, ref, words) in enumerate(sentences):
        for k in (7, 13, 20):
            other = sentences[(i + k) % n][3]
            if other != words:
                shared = sum(a == b for a, b in zip(other, words))
                cases["another sentence's transcript (3 each)"].append((pcm, other, shared))
        cases["its letter left out"].append((pcm, words[:3] + words[4:], len(words) - 1))
        cases["a word added"].append((pcm, words[:2] + ["again"] + words[2:], len(words)))
    for case, items in cases.items():
        if ctx.quick:
            items = items[::4]
        got = [(_grid_align(pcm, " ".join(t)), shared) for pcm, t, shared in items]
        warned = [bool(w) for (_, w), _ in got]
        low = [bool(w) and al.confidence < 0.5 for (al, w), _ in got]
        conf = np.array([al.confidence for (al, _), _ in got])
        row = {"figure": "align-grid", "case": f"GRID s1, {case}",
               "warned": f"{sum(warned)}/{len(warned)}", "warned_below_0.5": f"{sum(low)}/{len(low)}",
               "confidence_median": round(float(np.median(conf)), 2),
               "confidence_max": round(float(conf.max()), 2)}
        if case.startswith("another"):
            few = [lo for lo, (_, shared) in zip(low, got) if shared <= 2]
            row["below_0.5_sharing_le_2_words"] = f"{sum(few)}/{len(few)}"
        rows.append(row)
