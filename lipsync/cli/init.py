"""``lipsync init DIR``: a starting bank.yaml for a folder of viseme images."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub) -> None:
    from ..videobank.photos import LAYOUTS, LINE_SOURCES, SPRITE_MAX_SIDE, TEMPLATES

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
    p.add_argument("--keep-photos", action="store_true",
                   help="use the photos as they are; by default photos of one face become one face: the rest "
                        "image everywhere but the lower face, each photo's mouth, jaw and chin pasted in "
                        "(written to DIR/one-face/; the photos are never changed)")
    g = p.add_argument_group("mouth sprites on a character")
    g.add_argument("--over", default=None, metavar="BODY",
                   help="the character image the mouth sprites go on (copied into DIR if elsewhere): writes "
                        "bank.yaml's composite: block, so lipsync render shows the whole character talking")
    g.add_argument("--at", default=None, metavar="X,Y", help="body pixel where the mouth image's centre goes")
    g.add_argument("--scale", type=float, default=1.0, metavar="S", help="mouth size on the body (default: 1)")
    p.add_argument("--force", action="store_true", help="replace an existing bank.yaml")
    from ._init_video import add_video_options

    add_video_options(p)
    p.set_defaults(func=run)


def _body_in_folder(folder: Path, body: Path):
    """``(name, copy)``: the body image's name inside the bank folder, copying it there when
    it is elsewhere (bank.yaml may only name files inside its folder); ``copy`` is the
    copy made, or None."""
    import filecmp
    import shutil

    from ..errors import InputError

    if not body.is_file():
        raise InputError("--over: body image not found", path=body)
    folder_real = folder.resolve()
    real = body.resolve()
    if not folder.is_dir():
        raise InputError("not a folder (give the folder that holds the viseme images)", path=folder)
    if folder_real in real.parents:
        return real.relative_to(folder_real).as_posix(), None
    target = folder / body.name
    if target.exists() and not filecmp.cmp(target, body, shallow=False):
        raise InputError(f"--over: {target} exists and is another image; move the body into the folder yourself",
                         path=body)
    if target.exists():
        return body.name, None
    shutil.copyfile(body, target)
    return body.name, target


def run(args: argparse.Namespace) -> int:
    if args.video:
        from ._init_video import run_video

        return run_video(args)
    from ..videobank.photos import init_bank, parse_face_box
    from ..banks.names import parse_names_option
    from ..composite import parse_at
    from ..errors import InputError

    composite, copied = None, None
    if args.over is not None:
        if args.at is None:
            raise InputError("--over needs --at X,Y: the body pixel where the mouth image's centre goes")
        at = list(parse_at(args.at))
        name, copied = _body_in_folder(Path(args.folder), Path(args.over))
        composite = {"image": name, "at": at, "scale": args.scale}
    elif args.at is not None:
        raise InputError("--at places the mouth on a body: give the body image with --over BODY")
    try:
        result = init_bank(args.folder, template=args.template, names=parse_names_option(args.names),
                           face_box=parse_face_box(args.face_box) if args.face_box else None,
                           layout=args.layout, rest=args.rest, force=args.force, lines=args.lines,
                           composite=composite, keep_photos=args.keep_photos)
    except BaseException:
        if copied is not None:  # nothing half-done: the copy goes with the failed bank
            copied.unlink(missing_ok=True)
        raise
    if copied is not None:
        print(f"copied {args.over} to {copied}")
    w, h = result.size
    print(f"wrote {result.yaml_path}: {len(result.visemes)} visemes "
          f"({', '.join(result.visemes)}) from {result.system or '--names'} names, rest {result.rest!r}, "
          f"{w}x{h}, {result.layout} layout")
    for v, image in result.visemes.items():
        print(f"  {v:6s} {image}: lines from {result.lines.get(v, 'template')}")
    if result.one_face:
        print(f"  one face: the pictures are {result.visemes[result.rest]} outside the lower face, in "
              f"{Path(args.folder) / 'one-face'} (--keep-photos uses the photos as they are)")
    if composite:
        x, y = composite["at"]
        print(f"  composite: the mouth goes on {composite['image']} at ({x:g}, {y:g}), scale {args.scale:g}: "
              f"lipsync render shows the whole character")
    elif result.layout == "mouth":
        print("  mouth sprites: to render them on your character, add to bank.yaml\n"
              "    composite: {image: body.png, at: [X, Y], scale: 1}\n"
              f"  (the body image in this folder; X, Y: where the mouth's centre goes), or run: "
              f"lipsync init {args.folder} --over BODY.png --at X,Y --force")
    faced = all(src == "face" for src in result.lines.values())
    print(f"next: lipsync edit {args.folder}   "
          + ("(check the lines on your images)" if faced else "(place the lines on your images)"))
    return 0
