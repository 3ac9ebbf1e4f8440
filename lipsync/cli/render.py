"""``lipsync render``: a timeline file to an mp4 (with the speech audio) or a PNG sequence."""

from __future__ import annotations

import argparse
import sys

from ..clip import DEFAULT_CRF, DEFAULT_FPS, DEFAULT_PRESET
from ..encode import ENCODERS
from ..render import METHODS
from ._common import add_bank_option, add_jobs_option, add_quiet_option, add_store_option, add_timeline_options


def add_parser(sub) -> None:
    p = sub.add_parser("render", help="render a timeline to an mp4 (or PNG frames)",
                       description="Read a phoneme or viseme timeline, map it to visemes, sequence it and "
                                   "render every frame by morphing along the cached flows.")
    p.add_argument("timeline", metavar="TIMELINE", help="timeline file (.phn, .TextGrid, Gentle .json, "
                                                        "Rhubarb .tsv/.json/.xml, Moho .dat, Audacity .txt), "
                                                        "or speech audio (.wav, .mp3, ...: aligned, then "
                                                        "muxed; --text gives its transcript)")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output .mp4, or a folder for PNG frames")
    add_bank_option(p)
    p.add_argument("--audio", default=None, metavar="FILE", help="speech audio to mux (wav, flac, mp3, ...)")
    p.add_argument("--fps", type=float, default=DEFAULT_FPS, metavar="N", help=f"frames per second (default: {DEFAULT_FPS:g})")
    p.add_argument("--method", choices=METHODS.names(), default="flow",
                   help="in-between method (default: flow)")
    p.add_argument("--format", choices=ENCODERS.names(), default=None,
                   help="output format (default: from OUT: a folder or no extension -> png, .mp4 -> mp4)")
    p.add_argument("--crf", type=int, default=DEFAULT_CRF, help=f"H.264 quality, lower is better (default: {DEFAULT_CRF})")
    p.add_argument("--preset", default=DEFAULT_PRESET,
                   help=f"x264 speed preset: x264's (ultrafast ... veryslow) or talking-head (default: {DEFAULT_PRESET})")
    add_store_option(p)
    add_jobs_option(p)
    add_quiet_option(p)
    add_timeline_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..clip import render_clip

    report = render_clip(args.timeline, args.output, bank=args.bank, audio=args.audio, fps=args.fps,
                         map=args.map, method=args.method, timing=args.timing, format=args.format,
                         crf=args.crf, preset=args.preset, store=args.store, jobs=args.jobs,
                         quiet=args.quiet, timeline_options=args)
    if not args.quiet:
        print(report.summary(), file=sys.stderr)
    return 0
