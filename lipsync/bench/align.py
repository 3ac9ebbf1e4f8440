"""Alignment figures (registered in :data:`lipsync.bench.FIGURES` as ``align``).

On the MFA corpus recording (``ctx.mfa/acoustic_corpus.wav``, 26.7 s of real speech):

1. speed as a multiple of real time, with the .lab transcript and without (recognition
   first), wall clock and CPU (this process and its workers), median of repeats;
2. accuracy against MFA's own ``phones`` tier: share of MFA's phones matched (difflib's
   matching blocks of the labels), mean absolute boundary error of matched phones, and the share of
   10 ms frames showing the same Rhubarb mouth shape (both mapped with english-to-rhubarb);
3. the espeak-ng samples against the synthesiser's own phone times (mean and median signed
   boundary error: pocketsphinx's bias);
4. linear growth: the recording repeated 2 and 6 times (53 s, 160 s) aligned with its
   transcript: CPU seconds per second of audio of the longer against the shorter.
"""

from __future__ import annotations

import os
import re
import resource
import statistics
import time
import warnings
from pathlib import Path
from typing import List

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
    from ..phonemes import load_map, map_timeline

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


@FIGURES.decorator("align")
def _align(ctx: Context, rows: List[dict]) -> None:
    from ..speech.align import align_samples
    from ..speech.audio import load_audio
    from ..timeline import Segment, Timeline
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
            al, wall, cpu = _timed(lambda: align_samples(pcm, transcript, quiet=True, jobs=os.cpu_count()), repeat)
            matched, mae, bias = boundary_stats(al.phones, ref)
            rows.append({"figure": "align", "case": f"MFA corpus {seconds:.1f} s, {name}",
                         "x_real_time_wall": round(seconds / wall, 1), "x_real_time_cpu": round(seconds / cpu, 1),
                         "phones_matched_%": round(100 * matched, 1), "mean_abs_boundary_ms": round(1000 * mae, 1),
                         "median_signed_ms": round(1000 * bias, 1),
                         "same_mouth_shape_frames_%": round(100 * frame_agreement(al.phones, ref, ref.duration), 1)})
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
