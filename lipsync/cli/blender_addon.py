"""``lipsync blender-addon -o lipsync_blender.zip``: the Blender add-on, ready to install."""

from __future__ import annotations

import argparse
import sys

from ._common import add_quiet_option


def add_parser(sub) -> None:
    p = sub.add_parser("blender-addon", help="write the Blender add-on zip (import renders, key cues)",
                       description="Write the lipsync add-on for Blender (3.4 and later) as a zip to install "
                                   "in Edit > Preferences > Add-ons > Install: it imports a lipsync render "
                                   "(PNG frames or atlas + frames.json) lined up with the scene's frames, with "
                                   "the speech, and keys mouth cues onto a property, shape keys or poses. "
                                   "See docs/blender.md.")
    p.add_argument("-o", "--output", default="lipsync_blender.zip", metavar="ZIP",
                   help="the zip to write (default: lipsync_blender.zip)")
    add_quiet_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ..blender import addon_files, write_addon_zip
    from ..errors import InputError

    if not args.output.lower().endswith(".zip"):
        raise InputError("Blender installs add-ons from a .zip: name the output ZIP.zip", path=args.output)
    if Path(args.output).is_dir():
        raise InputError("is a folder; give a file name for the zip", path=args.output)
    out = write_addon_zip(args.output)
    if not args.quiet:
        print(f"lipsync: wrote {out} ({len(addon_files())} files); install it in Blender: Edit > Preferences > "
              f"Add-ons > Install", file=sys.stderr)
    return 0
