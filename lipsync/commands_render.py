"""``lipsync render``: a timeline file to an mp4 (with the speech audio) or a PNG sequence."""

from __future__ import annotations

import argparse
import sys
import time

from .encode import ENCODERS
from .render import METHODS
from .timeline_cli import add_timeline_options

#: 25 fps is PAL video's rate and enough for lips (Rhubarb needs >= 24 for hard cuts;
#: morphs look smooth well below that, so lower rates are allowed).
DEFAULT_FPS = 25.0
#: crf 18 is visually lossless for drawn faces; "veryfast" keeps encoding well ahead of
#: real time on two cores at 512x512 (the flat colours compress well at any preset).
DEFAULT_CRF = 18
DEFAULT_PRESET = "veryfast"


def add_parser(sub) -> None:
    p = sub.add_parser("render", help="render a timeline to an mp4 (or PNG frames)",
                       description="Read a phoneme or viseme timeline, map it to visemes, sequence it and "
                                   "render every frame by morphing along the cached flows.")
    p.add_argument("timeline", metavar="TIMELINE", help="timeline file (.phn, .TextGrid, Gentle .json, "
                                                        "Rhubarb .tsv/.json/.xml, Moho .dat, Audacity .txt)")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output .mp4, or a folder for PNG frames")
    p.add_argument("--bank", default=None, metavar="DIR", help="viseme bank folder (default: the shipped toon)")
    p.add_argument("--audio", default=None, metavar="FILE", help="speech audio to mux (wav, flac, mp3, ...)")
    p.add_argument("--fps", type=float, default=DEFAULT_FPS, metavar="N", help="frames per second (default: 25)")
    p.add_argument("--method", choices=METHODS.names(), default="flow",
                   help="in-between method (default: flow)")
    p.add_argument("--format", choices=ENCODERS.names(), default=None,
                   help="output format (default: from OUT: a folder or no extension -> png, .mp4 -> mp4)")
    p.add_argument("--crf", type=int, default=DEFAULT_CRF, help=f"H.264 quality, lower is better (default: {DEFAULT_CRF})")
    p.add_argument("--preset", default=DEFAULT_PRESET, help=f"x264 speed preset (default: {DEFAULT_PRESET})")
    p.add_argument("--store", default=None, metavar="DIR", help="flow store folder (default: BANK/.lipsync)")
    p.add_argument("--jobs", "-j", type=int, default=None, help="processes for preprocessing (default: all cores)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bars or summary")
    add_timeline_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from ._data import default_bank_dir
    from .animator import Animator
    from .bank import Bank
    from .encode import format_for, open_writer
    from .errors import InputError
    from .preprocess import preprocess
    from .store import FlowStore

    t0 = time.perf_counter()
    if not 0 <= args.crf <= 51:
        raise InputError(f"--crf must be 0..51, got {args.crf}")
    out_format = args.format or format_for(args.output)  # an unknown extension fails before any work
    bank = Bank.load(args.bank or default_bank_dir())
    store = FlowStore.for_bank(bank, args.store)
    anim = Animator(bank, args.timeline, fps=args.fps, map=args.map, method=args.method, timing=args.timing,
                    store=store, timeline_options=args)
    if args.method in ("flow", "splat"):
        preprocess(bank, store=store, jobs=args.jobs, quiet=args.quiet, normalised=anim.renderer.nb)
    h, w = anim.renderer.shape
    t1 = time.perf_counter()
    with open_writer(args.output, fps=args.fps, size=(w, h), format=out_format, audio=args.audio,
                     crf=args.crf, preset=args.preset, quiet=True) as writer:
        for frame in tqdm(anim.frames(copy=False), total=len(anim), desc="render", unit="frame",
                          disable=args.quiet, leave=False):
            writer.write(frame)
    t2 = time.perf_counter()
    if not args.quiet:
        seconds = len(anim) / args.fps
        print(f"wrote {args.output}: {len(anim)} frames ({seconds:.2f} s at {args.fps:g} fps), "
              f"{w}x{h}, {args.method}; rendered and encoded in {t2 - t1:.2f} s "
              f"({seconds / max(t2 - t1, 1e-9):.1f}x real time), total {t2 - t0:.2f} s", file=sys.stderr)
    return 0
