"""``lipsync render``: a timeline file to a video (with the speech audio), an animation or a PNG sequence."""

from __future__ import annotations

import argparse
import sys

from ..pipeline.clip import DEFAULT_CRF, DEFAULT_FPS, DEFAULT_PRESET
from ..encode import ENCODERS
from ..morphing.render import METHODS
from ._common import (add_bank_option, add_jobs_option, add_quiet_option, add_shapes_option, add_store_option,
                      add_timeline_options)
from ._live import add_live_options, lookahead_seconds


def add_parser(sub) -> None:
    p = sub.add_parser("render", help="render a timeline to a video (mp4, webm, mov), an animation or PNG frames",
                       description="Read a phoneme or viseme timeline, map it to visemes, sequence it and "
                                   "render every frame by morphing along the cached flows.")
    p.add_argument("timeline", metavar="TIMELINE", help="timeline file (.phn, .TextGrid, Gentle .json, "
                                                        "Rhubarb .tsv/.json/.xml, Moho .dat, Papagayo .pgo, "
                                                        "Audacity .txt), "
                                                        "or speech audio (.wav, .mp3, ...: aligned, then "
                                                        "muxed; --text gives its transcript)")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="output .mp4, .webm (VP9 + alpha), .mov (ProRes 4444 + alpha), .webp, .gif, or a folder for "
                        "PNG frames (RGBA for a transparent bank)")
    add_bank_option(p)
    p.add_argument("--audio", default=None, metavar="FILE", help="speech audio to mux (wav, flac, mp3, ...)")
    p.add_argument("--fps", type=float, default=DEFAULT_FPS, metavar="N",
                   help=f"frames per second (default: {DEFAULT_FPS:g})")
    p.add_argument("--method", choices=METHODS.names(), default="flow",
                   help="in-between method (default: flow)")
    p.add_argument("--format", choices=ENCODERS.names(), default=None,
                   help="output format (default: from OUT's extension; a folder -> png)")
    g = p.add_argument_group("transparency and composite")
    g.add_argument("--background", default=None, metavar="COLOR|IMAGE",
                   help="flatten transparency onto a colour (white, #rrggbb, r,g,b) or an image; without it a "
                        "transparent bank keeps its alpha where the format has one and is flattened onto white "
                        "(or the body) in mp4")
    g.add_argument("--over", default=None, metavar="IMAGE",
                   help="draw the mouth on this body image (the whole character talking; overrides bank.yaml's "
                        "composite: image)")
    g.add_argument("--at", default=None, metavar="X,Y", help="body pixel where the mouth image's centre goes")
    g.add_argument("--scale", type=float, default=None, metavar="S", help="mouth size on the body (default: 1)")
    g.add_argument("--mouth-only", action="store_true", help="ignore bank.yaml's composite: render the mouth alone")
    g.add_argument("--still", action="store_true",
                   help="a bank made from video: show its still pictures instead of compositing the mouth onto "
                        "its idle plate (the speaker's own video: blinks, head motion)")
    g.add_argument("--plate-start", type=float, default=None, metavar="SECONDS",
                   help="a bank made from video: where on its idle plate the clip starts (default: a place "
                        "derived from the input, so clips of a series do not blink in unison)")
    p.add_argument("--crf", type=int, default=DEFAULT_CRF, help=f"H.264 quality, lower is better (default: {DEFAULT_CRF})")
    p.add_argument("--preset", default=DEFAULT_PRESET,
                   help=f"x264 speed preset: x264's (ultrafast ... veryslow) or talking-head (default: {DEFAULT_PRESET})")
    add_shapes_option(p)
    add_store_option(p)
    add_jobs_option(p)
    add_quiet_option(p)
    add_timeline_options(p)
    add_live_options(p)
    from ._samples import add_samples_option

    add_samples_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .._data import default_bank_dir
    from ..banks.bank import Bank
    from ..pipeline.clip import composite_from_options, load_background, render_clip
    from ..errors import InputError

    from ..encode.mp4 import check_preset

    check_preset(args.preset)  # before loading anything
    if args.mouth_only and (args.over or args.at or args.scale is not None):
        raise InputError("--mouth-only renders the mouth alone: it cannot be combined with --over/--at/--scale")
    background = load_background(args.background) if args.background is not None else None
    bank = Bank.load(args.bank or default_bank_dir())
    composite = False if args.mouth_only else \
        composite_from_options(bank.composite, over=args.over, at=args.at, scale=args.scale)
    lookahead = lookahead_seconds(args)      # --lookahead without --live is refused here
    live = (True if lookahead is None else lookahead) if args.live else None
    if args.live and args.text is not None:
        raise InputError("--live hears the audio alone, as a live session does: leave out --text")
    if args.live and args.shapes != "all":
        raise InputError("--live shows what a live session shows: --shapes applies to timelines, not to --live")
    timeline, audio = args.timeline, args.audio
    if args.shapes != "all":  # the track read and mapped here, its G and H replaced
        from ..readers.audio import is_audio_input
        from ._common import shaped_timeline

        if audio is None and is_audio_input(args.timeline, args.timeline_format):
            audio = args.timeline
        timeline, _ = shaped_timeline(args, rest=bank.rest, viseme_names=bank.names)
    report = render_clip(timeline, args.output, bank=bank, audio=audio, fps=args.fps, live=live,
                         map=args.map, method=args.method, timing=args.timing, format=args.format,
                         crf=args.crf, preset=args.preset, store=args.store, jobs=args.jobs,
                         quiet=args.quiet, timeline_options=args, background=background, composite=composite,
                         still=args.still, plate_start=_plate_start(args.plate_start),
                         samples=args.samples)
    if not args.quiet:
        print(report.summary(), file=sys.stderr)
    return 0


def _plate_start(value):
    """``--plate-start``: a finite number of seconds, 0 or more (exit 2 otherwise)."""
    import math

    from ..errors import InputError

    if value is not None and not (math.isfinite(value) and value >= 0):
        raise InputError(f"--plate-start must be a number of seconds, 0 or more (got {value})")
    return value
