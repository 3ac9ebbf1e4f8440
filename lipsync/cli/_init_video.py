"""``lipsync init OUTDIR --video VIDEO ...``: the video side of ``lipsync init`` (a new subject
from video of the speaker; the work is :func:`lipsync.videobank.make_bank`)."""

from __future__ import annotations

import argparse

from ._common import add_mismatch_option

#: Options of the photo side that mean nothing for a video, with their defaults.
_PHOTO_ONLY = {"template": "toon", "names": [], "face_box": None, "layout": "auto", "lines": "auto", "rest": None,
               "over": None, "at": None}


def add_video_options(p: argparse.ArgumentParser) -> None:
    """Add --video, --text, --lang, --map, --size and --quiet to the ``init`` parser."""
    from ..phonetics.phonemes import DEFAULT_MAP, MAPS
    from ._common import add_jobs_option, add_lang_option, add_quiet_option
    from ..videobank.config import DEFAULT_MAX_SIDE

    g = p.add_argument_group("a new subject from video (DIR is the bank folder to make)")
    g.add_argument("--video", nargs="+", default=None, metavar="VIDEO",
                   help="videos of the speaker talking, with sound; one frame per viseme is chosen, "
                        "stabilised, given face lines, and the flows are computed")
    g.add_argument("--text", default=None, metavar="TEXT_OR_FILE",
                   help="transcript of the video (one video only); else NAME.txt or NAME.lab beside each "
                        "video, else the words are recognised")
    add_mismatch_option(g)
    add_lang_option(g)
    g.add_argument("--map", default=DEFAULT_MAP, metavar="NAME_OR_FILE",
                   help=f"phoneme-to-viseme map whose visemes the bank gets: {', '.join(MAPS.names())} or a "
                        f"YAML file (default: {DEFAULT_MAP})")
    g.add_argument("--size", default=None, metavar="WxH",
                   help=f"size of the bank's pictures (default: the video's scale, longer side at most "
                        f"{DEFAULT_MAX_SIDE})")
    add_jobs_option(g, "the flows")
    add_quiet_option(g)


def run_video(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..videobank import VideoBankConfig, make_bank, parse_size

    for name, default in _PHOTO_ONLY.items():
        if getattr(args, name, default) != default:
            raise InputError(f"--{name.replace('_', '-')} is for a folder of images; with --video the pictures "
                             f"and their lines come from the face in the video")
    config = VideoBankConfig(map=args.map, size=parse_size(args.size) if args.size else None, force=args.force,
                             quiet=args.quiet, jobs=args.jobs, lang=args.lang)
    result = make_bank(args.folder, args.video, text=args.text, config=config)
    if not args.quiet:
        print(result.summary())
        for v, c in result.chosen.items():
            print(f"  {v:5s} {result.report['visemes'][v]['video']} at {c.time:.2f} s (frame {c.frame})")
        print(f"next: lipsync preview {args.folder} -o sheet.png   or   "
              f"lipsync render SPEECH.wav --bank {args.folder} -o out.mp4")
    return 0
