"""``lipsync init DIR``: a starting bank.yaml for a folder of viseme images."""

from __future__ import annotations

import argparse


def add_parser(sub) -> None:
    from ..banks.init import LAYOUTS, LINE_SOURCES, SPRITE_MAX_SIDE, TEMPLATES

    p = sub.add_parser("init", help="write a starting bank.yaml for a folder of viseme images")
    p.add_argument("folder", metavar="DIR", help="folder with one image per viseme (PNG/JPEG)")
    p.add_argument("--template", default="toon", metavar="NAME_OR_BANK",
                   help=f"bank whose control lines to start from: {', '.join(TEMPLATES.names())} or a bank "
                        f"folder (default: toon)")
    p.add_argument("--names", action="append", default=[], metavar="FILE=VISEME[,...]",
                   help="viseme names of files whose names are not Rhubarb, Preston Blair or Oculus names")
    p.add_argument("--face-box", default=None, metavar="X,Y,W,H",
                   help="where the face is in the images (default: the template scaled to the whole image)")
    p.add_argument("--layout", choices=LAYOUTS, default="auto",
                   help=f"face: whole faces; mouth: mouth-only sprites (template mouth lines only); auto: "
                        f"mouth for images up to {SPRITE_MAX_SIDE} px without --face-box (default)")
    p.add_argument("--lines", choices=LINE_SOURCES, default="auto",
                   help="face: place lines from each image's face (face mesh); template: start from the "
                        "template's lines; auto: face when a face is found, else template (default)")
    p.add_argument("--rest", default=None, metavar="VISEME", help="the rest viseme (default: X, rest or sil)")
    p.add_argument("--force", action="store_true", help="replace an existing bank.yaml")
    from ._init_video import add_video_options

    add_video_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.video:
        from ._init_video import run_video

        return run_video(args)
    from ..banks.init import init_bank, parse_face_box
    from ..banks.names import parse_names_option

    result = init_bank(args.folder, template=args.template, names=parse_names_option(args.names),
                       face_box=parse_face_box(args.face_box) if args.face_box else None,
                       layout=args.layout, rest=args.rest, force=args.force, lines=args.lines)
    w, h = result.size
    print(f"wrote {result.yaml_path}: {len(result.visemes)} visemes "
          f"({', '.join(result.visemes)}) from {result.system or '--names'} names, rest {result.rest!r}, "
          f"{w}x{h}, {result.layout} layout")
    for v, image in result.visemes.items():
        print(f"  {v:6s} {image}: lines from {result.lines.get(v, 'template')}")
    faced = all(src == "face" for src in result.lines.values())
    print(f"next: lipsync edit {args.folder}   "
          + ("(check the lines on your images)" if faced else "(place the lines on your images)"))
    return 0
