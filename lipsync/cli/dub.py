"""``lipsync dub``: re-voice a video of a speaker with new speech (the video's frames kept, its lower face replaced)."""

from __future__ import annotations

import argparse
import sys

from ..pipeline.clip import DEFAULT_CRF, DEFAULT_PRESET
from ._common import (TIMING_HELP, add_jobs_option, add_mismatch_option, add_quiet_option, add_store_option,
                      lang_code)


def add_parser(sub) -> None:
    from ..phonetics.phonemes import DEFAULT_MAP
    from ..motion.timing import timing_names

    p = sub.add_parser("dub", help="re-voice a video: its own frames, the lower face driven by new speech",
                       description="Keep VIDEO's frames (head motion, blinks, background) and replace the "
                                   "speaker's lower face by their mouth morphed to SPEECH; the output carries "
                                   "SPEECH and lasts as long as it (when the speech is longer the video goes on "
                                   "where its frames match, never mid-blink). Without --bank a bank is made from VIDEO (lipsync init "
                                   "--video) and cached.")
    p.add_argument("video", metavar="VIDEO", help="video of the speaker facing the camera (any format ffmpeg reads)")
    p.add_argument("--audio", required=True, metavar="SPEECH",
                   help="the new speech (wav, mp3, flac, or a video's sound)")
    p.add_argument("--text", default=None, metavar="TEXT_OR_FILE",
                   help="SPEECH's transcript, or a text file holding it (default: the words are recognised)")
    p.add_argument("--bank", default=None, metavar="DIR",
                   help="the speaker's bank (default: one made from VIDEO, cached)")
    p.add_argument("--video-text", default=None, metavar="TEXT_OR_FILE",
                   help="what is said in VIDEO, for making its bank (default: VIDEO's NAME.txt/NAME.lab, else "
                        "recognised)")
    p.add_argument("-o", "--output", default=None, metavar="OUT",
                   help="output .mp4 (default: VIDEO's name with -dub.mp4 beside it)")
    p.add_argument("--map", default=DEFAULT_MAP, metavar="NAME_OR_FILE",
                   help=f"phoneme-to-viseme map (default: {DEFAULT_MAP})")
    p.add_argument("--timing", choices=timing_names(), default=None, metavar="NAME", help=TIMING_HELP)
    p.add_argument("--crf", type=int, default=DEFAULT_CRF,
                   help=f"H.264 quality, lower is better (default: {DEFAULT_CRF})")
    p.add_argument("--preset", default=DEFAULT_PRESET,
                   help=f"x264 speed preset: x264's (ultrafast ... veryslow) or talking-head "
                        f"(default: {DEFAULT_PRESET})")
    p.add_argument("--cache", default=None, metavar="DIR",
                   help="cache of face tracks and banks made from videos (default: ~/.cache/lipsync/dub)")
    p.add_argument("--lang", type=lang_code, default=None, metavar="CODE",
                   help="language of the new speech (SPEECH, --text) as a BCP 47 tag (es, fr, pt-BR, zh, ...); "
                        "default English. Other languages need the optional espeak-ng extra "
                        "(pip install 'lipsync[lang]')")
    p.add_argument("--video-lang", type=lang_code, default=None, metavar="CODE",
                   help="language of what is said in VIDEO, for making its bank (default English; when its "
                        "words cannot be recognised the bank is made from the phones heard, or the lips alone)")
    p.add_argument("--plate-start", type=float, default=None, metavar="SECONDS",
                   help="where in VIDEO the output starts (default 0)")
    add_mismatch_option(p)
    add_store_option(p)
    add_jobs_option(p)
    add_quiet_option(p)
    from ._samples import add_samples_option

    add_samples_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import os

    from ..pipeline.dubbing import dub
    from ..encode.mp4 import check_preset

    check_preset(args.preset)  # before loading anything
    out = args.output or os.path.splitext(args.video)[0] + "-dub.mp4"
    report = dub(args.video, args.audio, out, text=args.text, bank=args.bank, video_text=args.video_text,
                 map=args.map, timing=args.timing, crf=args.crf, preset=args.preset, store=args.store,
                 jobs=args.jobs, quiet=args.quiet, cache=args.cache, lang=args.lang, video_lang=args.video_lang,
                 plate_start=args.plate_start, samples=args.samples)
    if not args.quiet:
        print(report.summary(), file=sys.stderr)
    return 0
