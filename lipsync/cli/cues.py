"""``lipsync cues INPUT -o OUT``: the viseme track the video would show, as mouth cues.

The track is the sequencer's cleaned segment plan (:func:`lipsync.motion.sequencer.plan_segments`,
what ``lipsync timeline`` prints: gaps to rest, merges, short pauses held, flickers dropped)
of the input mapped with the same map as ``render``. It is written in a format other tools
read (:data:`lipsync.writers.WRITERS`): Rhubarb's TSV, JSON and XML, Moho switch data at
``--fps``, a Praat TextGrid, or an Audacity label track; the format comes from ``--format``
or the output's extension. ``--format atlas --atlas ATLAS.json`` writes the sprite-atlas cell
of every frame at ``--fps`` instead (the frames ``render`` would draw, each the nearest cell
of the atlas ``lipsync atlas`` made; the track keeps the atlas' viseme names). Their timing is
``--timing``, else the ``--bank``'s (its bank.yaml), else the default: give ``--bank`` for a
bank that sets its own.
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import Dict

from ..motion.frames import DEFAULT_FPS as DEFAULT_RENDER_FPS
from ..writers import DEFAULT_FPS, DEFAULT_TIER, WRITERS
from ._common import add_bank_option, add_quiet_option, add_shapes_option, add_timeline_options, shaped_timeline
from ._live import add_live_options, lookahead_seconds as _lookahead


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``lipsync cues``."""
    parser = subparsers.add_parser(
        "cues", help="write the viseme track as mouth cues (Rhubarb, Moho, TextGrid, Audacity, atlas frames)",
        description="Write the viseme track the video would show (after the sequencer's rules) as "
                    "mouth cues for other tools: Rhubarb Lip Sync TSV/JSON/XML, Moho switch data, "
                    "a Praat TextGrid or an Audacity label track.")
    parser.add_argument("timeline", metavar="INPUT", help="timeline file (any format `lipsync render` reads)")
    parser.add_argument("-o", "--output", required=True, metavar="OUT",
                        help="output file; its extension picks the format unless --format is given "
                             "(.tsv, .json, .xml, .dat, .TextGrid, .txt)")
    parser.add_argument("--format", choices=WRITERS.names(), default=None, metavar="NAME",
                        help=f"cue format: {', '.join(WRITERS.names())} (default: from OUT's extension)")
    parser.add_argument("--fps", type=float, default=None, metavar="N",
                        help=f"frame rate of Moho .dat keys (default: {DEFAULT_FPS:g}, Moho's and Rhubarb's "
                             f"default) and of atlas frames (default: {DEFAULT_RENDER_FPS:g}, as lipsync render)")
    parser.add_argument("--atlas", default=None, metavar="ATLAS.json",
                        help="for --format atlas: the atlas (from `lipsync atlas`) whose cells the frames name")
    add_live_options(parser)
    parser.add_argument("--tier-name", default=DEFAULT_TIER, metavar="NAME",
                        help=f"TextGrid tier name (default: {DEFAULT_TIER})")
    parser.add_argument("--audio", default=None, metavar="FILE",
                        help="the recording the cues go with: Rhubarb JSON/XML name it as soundFile "
                             "(default: INPUT when it is audio, else none)")
    add_bank_option(parser)
    add_shapes_option(parser)
    add_quiet_option(parser)
    add_timeline_options(parser)
    parser.set_defaults(func=run)
    return parser


def run(args: argparse.Namespace) -> int:
    """Write the cue file; returns the exit code."""
    from ..errors import InputError
    from ..phonetics.phonemes import DEFAULT_MAP, load_map
    from ..motion.sequencer import FPS_RANGE, plan_segments
    from ..writers import format_for, write_cues

    name = args.format or format_for(args.output)  # a bad name fails before any reading
    # atlas frames are the frames a player shows: render's rate; Moho keys: Moho's own
    default = DEFAULT_RENDER_FPS if WRITERS.get(name).name == "atlas" else DEFAULT_FPS
    fps = float(default if args.fps is None else args.fps)
    if not (FPS_RANGE[0] <= fps <= FPS_RANGE[1]):
        raise InputError(f"--fps {args.fps:g} is outside {FPS_RANGE[0]:g}..{FPS_RANGE[1]:g}")
    if os.path.isdir(args.output):
        raise InputError("is a folder; give a file name for the cues", path=args.output)
    _lookahead(args)  # --lookahead without --live is refused before any work
    if getattr(args, "live", False):
        return _live_cues(args, name, float(DEFAULT_RENDER_FPS if args.fps is None else args.fps))
    if WRITERS.get(name).name == "atlas":
        return _atlas_frames(args, fps)
    if args.atlas is not None:
        raise InputError("--atlas is for --format atlas only")
    sound = _sound_file(args)  # a missing --audio fails before any reading
    base = load_map(args.map or DEFAULT_MAP)  # the map's own names, whatever the bank calls them
    if args.bank is not None:
        timeline, pmap, to_map, rest = _bank_track(args, base)
    else:
        timeline, pmap = shaped_timeline(args)
        to_map, rest = {}, pmap.silence
    plan = plan_segments(timeline, rest=rest, closures=pmap.closures)
    # Back to the map's own names (A-H, X for Rhubarb) so every format names shapes alike.
    cues = [(a, b, to_map.get(v, v)) for a, b, v in plan]
    rest = to_map.get(rest, rest)
    names: Dict[str, str] = {}
    if WRITERS.get(name).name == "moho":
        # Preston Blair names where the map has them (Papagayo's and Moho's switch names).
        names = {v: aliases[0] for v, aliases in base.aliases.items() if aliases}
    write_cues(cues, args.output, name, rest=rest, fps=fps, tier=args.tier_name,
               sound_file=sound, names=names,
               closures=[to_map.get(c, c) for c in pmap.closures], duration=timeline.duration)
    if not args.quiet:
        print(f"lipsync: wrote {len(cues)} cues ({WRITERS.get(name).name}) to {args.output}", file=sys.stderr)
    return 0


def _sound_file(args: argparse.Namespace) -> str:
    """Rhubarb's ``soundFile``: the recording (``--audio``, or INPUT when it is audio), as an
    absolute path; empty when there is none (a timeline is not a sound file)."""
    from ..readers.audio import is_audio_input

    if args.audio is not None:
        if not os.path.isfile(args.audio):
            from ..errors import InputError

            raise InputError("no such audio file", path=args.audio)
        return os.path.abspath(args.audio)
    if is_audio_input(args.timeline, args.timeline_format):
        return os.path.abspath(args.timeline)
    return ""


def _atlas_frames(args: argparse.Namespace, fps: float) -> int:
    """frames.json: the timeline in the atlas' viseme names, sequenced as ``render`` does,
    each frame the nearest cell of the atlas."""
    from ..atlas.schema import load_atlas
    from ..motion.coarticulation import resolve_timing, viseme_classes
    from ..errors import InputError
    from ..motion.sequencer import plan_segments
    from ..writers import write_cues

    if args.atlas is None:
        raise InputError("--format atlas needs --atlas ATLAS.json (write one with `lipsync atlas BANK -o ATLAS.png`)")
    atlas = load_atlas(args.atlas)
    bank = None
    if args.bank is not None:
        from ..banks.bank import Bank

        bank = Bank.load(args.bank)
        if tuple(bank.names) != atlas.visemes or bank.rest != atlas.rest:
            raise InputError(f"the bank's visemes ({', '.join(bank.names)}; rest {bank.rest}) are not the "
                             f"atlas' ({', '.join(atlas.visemes)}; rest {atlas.rest})", path=args.atlas)
    # the atlas names the bank's visemes and rest: the track is matched to them as to a bank
    timeline, pmap = shaped_timeline(args, rest=atlas.rest, viseme_names=atlas.visemes)
    plan = plan_segments(timeline, rest=atlas.rest, closures=pmap.closures)
    # the timing render would use: --timing, else the bank's (bank.yaml), else the default
    timing = resolve_timing(args.timing, bank)
    write_cues(plan, args.output, "atlas", rest=atlas.rest, fps=fps, closures=pmap.closures,
               duration=timeline.duration, timing=timing, timeline=timeline,
               classes=viseme_classes(pmap, atlas.rest), atlas=atlas)
    if not args.quiet:
        from ..motion.sequencer import frame_count

        print(f"lipsync: wrote {frame_count(timeline.duration, fps)} frames of {atlas.path} at {fps:g} fps "
              f"to {args.output}", file=sys.stderr)
    return 0


def _bank_track(args: argparse.Namespace, base):
    """The track in the bank's names (checked against it), bank name -> map name, the bank's rest."""
    from ..banks.bank import Bank
    from ..phonetics.phonemes import resolve_visemes

    bank = Bank.load(args.bank)
    timeline, pmap = shaped_timeline(args, rest=bank.rest, viseme_names=bank.names)
    names, _ = resolve_visemes(base, bank.names)
    return timeline, pmap, {b: m for m, b in names.items()}, bank.rest


def _live_cues(args: argparse.Namespace, name: str, fps: float) -> int:
    """``--live``: the mouth shapes a live session fed the audio in real time shows, frame by frame."""
    from .._data import default_bank_dir
    from ..banks.bank import Bank
    from ..errors import InputError
    from ..pipeline.liveclip import live_cues, live_shapes
    from ..phonetics.phonemes import DEFAULT_MAP, load_map, resolve_visemes

    if WRITERS.get(name).name == "atlas" or args.atlas is not None:
        raise InputError("--live writes mouth cues; --format atlas is for timelines")
    bank = Bank.load(args.bank or default_bank_dir())
    base = load_map(args.map or DEFAULT_MAP)
    # each frame's shape as the session fixed it (the planned segment, as offline cues are:
    # not the nearer viseme of a blend, which a timing model makes lag the sound)
    shapes = live_shapes(args.timeline, bank, fps=fps, lookahead=_lookahead(args), map=args.map,
                         timing=args.timing, quiet=args.quiet)
    names, _ = resolve_visemes(base, bank.names)
    to_map = {b: m for m, b in names.items()}
    cues = [(a, b, to_map.get(v, v)) for a, b, v in live_cues(shapes, fps)]
    write_names: Dict[str, str] = {}
    if WRITERS.get(name).name == "moho":
        write_names = {v: aliases[0] for v, aliases in base.aliases.items() if aliases}
    from ..writers import write_cues

    write_cues(cues, args.output, name, rest=to_map.get(bank.rest, bank.rest), fps=fps, tier=args.tier_name,
               sound_file=os.path.abspath(args.timeline), names=write_names,
               closures=[to_map.get(c, c) for c in base.closures], duration=len(shapes) / fps)
    if not args.quiet:
        print(f"lipsync: wrote {len(cues)} live cues ({WRITERS.get(name).name}) to {args.output}", file=sys.stderr)
    return 0
