"""``lipsync timeline FILE``: show the viseme track (and with --frames the frame schedule).

Output is tab-separated, for checking a timeline and for feeding other tools:

* the viseme track: ``start  end  viseme`` per segment (seconds, 3 decimals);
* with ``--frames``: ``frame  time  from  to  alpha`` per output frame.
"""

from __future__ import annotations

import argparse
import sys

from ..motion.frames import DEFAULT_FPS
from ..motion.sequencer import FPS_RANGE, describe, plan_segments, sequence
from ._common import add_timeline_options, load_viseme_timeline


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``lipsync timeline``."""
    parser = subparsers.add_parser(
        "timeline", help="print the viseme track of a timeline file (and the frame schedule)",
        description="Print the viseme track of a timeline file and, with --frames, the frame "
                    "schedule (tab-separated).")
    parser.add_argument("timeline", metavar="FILE", help="phoneme or viseme timeline file")
    add_timeline_options(parser)
    parser.add_argument("--fps", type=float, default=DEFAULT_FPS, metavar="N",
                        help=f"output frame rate for --frames, {FPS_RANGE[0]:g} to {FPS_RANGE[1]:g} "
                             f"(default: {DEFAULT_FPS:g}, as lipsync render)")
    parser.add_argument("--frames", action="store_true",
                        help="also print the frame schedule: frame, time, from, to, alpha")
    parser.set_defaults(func=run)
    return parser


def run(args: argparse.Namespace) -> int:
    """Print the viseme track (and the frame schedule); returns the exit code."""
    from ..motion.coarticulation import viseme_classes
    from ..motion.sequencer import check_fps
    from ..motion.timing import DEFAULT_CURVE

    fps = check_fps(args.fps)
    timeline, pmap = load_viseme_timeline(args)
    rest = pmap.silence
    out = sys.stdout
    out.write(f"# {timeline.path}: {timeline.duration:.3f} s, map {pmap.name}; viseme track after the "
              "sequencer's rules (gaps to rest, merges, short pauses held, flickers dropped)\n")
    for start, end, viseme in plan_segments(timeline, rest=rest, closures=pmap.closures):
        out.write(f"{start:.3f}\t{end:.3f}\t{viseme}\n")
    if args.frames:
        timing = args.timing or DEFAULT_CURVE   # no bank here: nothing else to take it from
        specs = sequence(timeline, fps=fps, rest=rest, timing=timing, closures=pmap.closures,
                         classes=viseme_classes(pmap, rest))
        out.write(f"# {len(specs)} frames at {fps:g} fps, timing {timing}: frame, time, from, to, alpha\n")
        if specs:
            out.write(describe(specs, fps) + "\n")
    return 0
