"""``lipsync timeline FILE``: show the viseme track (and with --frames the frame schedule).

Output is tab-separated, for checking a timeline and for feeding other tools:

* the viseme track: ``start  end  viseme`` per segment (seconds, 3 decimals);
* with ``--frames``: ``frame  time  from  to  alpha`` per output frame.

Options shared with ``lipsync render`` come from :func:`add_timeline_options`;
:func:`load_viseme_timeline` does the reading, mapping and checking for both commands.
``--format`` is left to ``render`` (its output format), so the input format option is
``--timeline-format``. A Moho ``.dat`` file counts in frames of its own frame rate, given
with ``--moho-fps`` (default 24), which is kept apart from ``--fps`` because the file's rate
and the output rate are independent (a 24 fps Papagayo export rendered at 30 fps).
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import Iterable, Optional, Tuple

from .phonemes import DEFAULT_MAP, MAPS, PhonemeMap, bank_viseme_timeline, load_map
from .sequencer import FPS_RANGE, describe, plan_segments, sequence
from .timeline import READERS, Timeline, read_timeline
from .timing import CURVES, DEFAULT_CURVE

DEFAULT_FPS = 24.0
DEFAULT_MOHO_FPS = 24.0


def add_timeline_options(parser: argparse.ArgumentParser) -> None:
    """Add --timeline-format, --tier, --sample-rate, --moho-fps, --map and --timing to ``parser``."""
    group = parser.add_argument_group("timeline input")
    group.add_argument("--timeline-format", choices=READERS.names(), default=None, metavar="NAME",
                       help="input timeline format (default: from the extension, then the content); "
                            f"one of: {', '.join(READERS.names())}")
    group.add_argument("--tier", default=None, metavar="NAME",
                       help="TextGrid tier to read (default: phones)")
    group.add_argument("--sample-rate", type=float, default=16000, metavar="N",
                       help="samples per second of TIMIT .phn times (default: 16000)")
    group.add_argument("--moho-fps", type=float, default=DEFAULT_MOHO_FPS, metavar="N",
                       help="frame rate a Moho .dat file was written at (default: 24)")
    group.add_argument("--map", default=DEFAULT_MAP, metavar="NAME_OR_FILE",
                       help=f"phoneme-to-viseme map: a shipped name ({', '.join(MAPS.names())}) "
                            f"or a YAML file (default: {DEFAULT_MAP})")
    group.add_argument("--timing", choices=CURVES.names(), default=DEFAULT_CURVE, metavar="NAME",
                       help=f"timing curve of transitions: {', '.join(CURVES.names())} "
                            f"(default: {DEFAULT_CURVE})")


def load_viseme_timeline(args: argparse.Namespace, *, rest: Optional[str] = None,
                         viseme_names: Optional[Iterable[str]] = None) -> Tuple[Timeline, PhonemeMap]:
    """Read ``args.timeline``, map it to visemes and check the map against a bank.

    Parameters
    ----------
    args : argparse.Namespace
        With ``timeline`` (the file) and the options of :func:`add_timeline_options`.
    rest : str, optional
        The bank's rest viseme, shown for silence (default: the map's silence viseme).
    viseme_names : iterable of str, optional
        The bank's viseme names. When given, the map's visemes are matched to them (through
        the map's aliases where needed, e.g. Preston Blair names) and a map viseme the bank
        lacks is a MapError.

    Returns
    -------
    (Timeline, PhonemeMap)
        The viseme timeline in the bank's viseme names, and the map renamed to them (its
        ``closures`` are what :func:`lipsync.sequencer.sequence` wants).

    Examples
    --------
    >>> import argparse, os, tempfile
    >>> p = os.path.join(tempfile.mkdtemp(), "a.phn")
    >>> _ = open(p, "w").write("0 1600 h#\\n1600 3200 m\\n3200 6400 aa\\n")
    >>> parser = argparse.ArgumentParser()
    >>> _ = parser.add_argument("timeline")
    >>> add_timeline_options(parser)
    >>> tl, pmap = load_viseme_timeline(parser.parse_args([p]), rest="X")
    >>> tl.labels(), pmap.closures
    (['X', 'A', 'D'], ['A'])
    """
    pmap = load_map(getattr(args, "map", None) or DEFAULT_MAP)
    timeline = read_timeline(args.timeline, getattr(args, "timeline_format", None),
                             tier=getattr(args, "tier", None),
                             sample_rate=getattr(args, "sample_rate", 16000),
                             fps=getattr(args, "moho_fps", DEFAULT_MOHO_FPS))
    map_arg = str(getattr(args, "map", None) or "")
    return bank_viseme_timeline(timeline, pmap, viseme_names, rest=rest,
                                map_path=map_arg if os.path.isfile(map_arg) else None)



def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``lipsync timeline``."""
    parser = subparsers.add_parser(
        "timeline", help="print the viseme track of a timeline file (and the frame schedule)",
        description="Print the viseme track of a timeline file and, with --frames, the frame "
                    "schedule (tab-separated).")
    parser.add_argument("timeline", metavar="FILE", help="phoneme or viseme timeline file")
    add_timeline_options(parser)
    parser.add_argument("--fps", type=float, default=DEFAULT_FPS, metavar="N",
                        help=f"output frame rate for --frames, {FPS_RANGE[0]:g} to {FPS_RANGE[1]:g} (default: 24)")
    parser.add_argument("--frames", action="store_true",
                        help="also print the frame schedule: frame, time, from, to, alpha")
    parser.set_defaults(func=run)
    return parser


def run(args: argparse.Namespace) -> int:
    """Print the viseme track (and the frame schedule); returns the exit code."""
    from .sequencer import check_fps

    fps = check_fps(args.fps)
    timeline, pmap = load_viseme_timeline(args)
    rest = pmap.silence
    out = sys.stdout
    out.write(f"# {timeline.path}: {timeline.duration:.3f} s, map {pmap.name}; viseme track after the "
              "sequencer's rules (gaps to rest, merges, short pauses held, flickers dropped)\n")
    for start, end, viseme in plan_segments(timeline, rest=rest, closures=pmap.closures):
        out.write(f"{start:.3f}\t{end:.3f}\t{viseme}\n")
    if args.frames:
        specs = sequence(timeline, fps=fps, rest=rest, timing=args.timing, closures=pmap.closures)
        out.write(f"# {len(specs)} frames at {fps:g} fps, timing {args.timing}: frame, time, from, to, alpha\n")
        if specs:
            out.write(describe(specs, fps) + "\n")
    return 0
