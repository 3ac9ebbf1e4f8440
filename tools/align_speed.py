"""Alignment speed of any checkout of lipsync, to compare versions in one sitting.

``make bench`` measures the code it runs; a figure for an older version can only come from
that version. Run this once per checkout, alternating, on an otherwise idle machine, and
compare the medians (issue 20 compared the version before its fit check with today's)::

    git worktree add /tmp/before20 a2fc988      # the last commit before issue 20
    for i in 1 2 3; do
        python tools/align_speed.py /tmp/before20
        python tools/align_speed.py .
    done

Each run aligns the MFA corpus recording (26.7 s, ``tests/data/conformance/mfa``) with its transcript
9 times with ``jobs`` processes (default 2) after one warm-up, and prints the median and
best speed as a multiple of real time, wall clock and CPU (this process and its workers).
"""

from __future__ import annotations

import argparse
import importlib
import resource
import statistics
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def _cpu() -> float:
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("checkout", type=Path, help="root of the lipsync checkout to time")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=9)
    args = parser.parse_args(argv)
    sys.path.insert(0, str(args.checkout.resolve()))
    align = importlib.import_module("lipsync.speech.align")
    audio = importlib.import_module("lipsync.speech.audio")
    if not Path(align.__file__).resolve().is_relative_to(args.checkout.resolve()):
        parser.error(f"lipsync was imported from {align.__file__}, not from {args.checkout}")
    data = HERE / "tests" / "data" / "conformance" / "mfa"
    pcm = audio.load_audio(data / "acoustic_corpus.wav")
    text = (data / "acoustic_corpus.lab").read_text()
    seconds = len(pcm) / audio.SAMPLE_RATE
    walls, cpus = [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # "yknow" is not in the dictionary
        align.align_samples(pcm, text, jobs=args.jobs)
        for _ in range(args.repeat):
            w, c = time.perf_counter(), _cpu()
            align.align_samples(pcm, text, jobs=args.jobs)
            walls.append(time.perf_counter() - w)
            cpus.append(_cpu() - c)
    print(f"{args.checkout}: {seconds / statistics.median(walls):.1f}x real time wall (best "
          f"{seconds / min(walls):.1f}x), {seconds / statistics.median(cpus):.1f}x per CPU second")
    return 0


if __name__ == "__main__":
    sys.exit(main())
