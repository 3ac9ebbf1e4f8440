"""``lipsync align``: speech (and optionally its transcript) to a words + phones TextGrid, offline."""

from __future__ import annotations

import argparse

from ._common import add_mismatch_option
import sys


def add_parser(sub) -> None:
    from ..speech.export import ALIGNMENT_FORMATS
    from ._common import add_lang_option

    p = sub.add_parser("align", help="align speech audio to words and phones (TextGrid or JSON)",
                       description="Find the words and phones of a recording and when each is spoken, with "
                                   "pocketsphinx, offline. With --text the transcript is aligned; without it "
                                   "the words are recognised first. Long recordings are split at pauses. With "
                                   "--lang (other than English) the phones tier is IPA.")
    p.add_argument("audio", metavar="AUDIO", help="speech audio: any file ffmpeg reads (wav, flac, mp3, m4a, ogg, ...)")
    p.add_argument("--text", default=None, metavar="TEXT_OR_FILE",
                   help="the transcript, or a UTF-8 text file holding it (default: recognise the words)")
    add_mismatch_option(p)
    add_lang_option(p)
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="output file (.TextGrid: Praat long form with tiers words and phones; .json)")
    p.add_argument("--format", choices=ALIGNMENT_FORMATS.names(), default=None,
                   help="output format (default: from OUT's extension, else textgrid)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar or summary")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import time

    from ..speech.align import align
    from ..speech.export import write_alignment

    import os

    from ..errors import InputError

    folder = os.path.dirname(os.path.abspath(args.output))
    if not os.path.isdir(folder):  # before the work, not after it
        raise InputError("the output's folder does not exist", path=args.output)
    t0 = time.perf_counter()
    alignment = align(args.audio, args.text, quiet=args.quiet, lang=args.lang)
    write_alignment(alignment, args.output, args.format)
    if not args.quiet:
        dt = time.perf_counter() - t0
        how = "recognised and aligned" if alignment.recognised else "aligned"
        if alignment.confidence is not None:
            how += f" (transcript confidence {alignment.confidence:.2f})"
        print(f"wrote {args.output}: {len(alignment.words)} words, {len(alignment.phones)} phones {how} in "
              f"{alignment.duration:.2f} s of audio ({alignment.duration / max(dt, 1e-9):.1f}x real time)",
              file=sys.stderr)
    return 0
