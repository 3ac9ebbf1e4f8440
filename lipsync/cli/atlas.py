"""``lipsync atlas [BANK] -o ATLAS.png [TIMELINE ...]``: a sprite atlas for game engines.

BANK is a folder or a shipped subject's name (default: the toon; ``--bank`` says the same
when the first positional should be a timeline).

Every viseme and ``--inbetweens`` in-betweens of each transition, rendered by the renderer
``render`` uses, in one RGBA texture, with ``ATLAS.json`` saying where each cell is and
which pair and alpha it holds (and ``ATLAS.base.png``, the part of the frame that never
changes). The pairs are those the given timelines use (read, mapped and planned as
``render`` does them: the boundaries of the sequencer's plan, and with the dominance timing
the pairs its frames blend) or, with ``--pairs all`` or no timeline, every pair of the bank.
``lipsync cues TIMELINE --format atlas --atlas ATLAS.json --fps F`` then gives the cell of
every frame. ``--player`` puts the example players beside the atlas (the page, the Godot 3 script).
"""

from __future__ import annotations

import argparse
import sys

from ..morphing.render import METHODS
from ._common import add_jobs_option, add_quiet_option, add_store_option, add_timeline_options


def add_parser(sub) -> None:
    from ..atlas.layout import DEFAULT_MAX_SIZE, DEFAULT_PADDING

    p = sub.add_parser("atlas", help="render a sprite atlas (visemes and in-betweens) for game engines",
                       description="Render every viseme and N in-betweens of each transition into one RGBA "
                                   "texture ATLAS.png, described by ATLAS.json (cell rectangles, pair, alpha). "
                                   "`lipsync cues INPUT --format atlas --atlas ATLAS.json --fps F` gives the "
                                   "cell of every frame.")
    p.add_argument("bank", metavar="BANK", nargs="?", default=None,
                   help="bank folder or shipped subject (toon, grid-s1); default: the toon")
    p.add_argument("--bank", dest="bank_option", default=None, metavar="DIR_OR_NAME",
                   help="the bank, as an option (then every positional is a timeline)")
    p.add_argument("timelines", metavar="TIMELINE", nargs="*",
                   help="timelines whose transitions the atlas holds (any format `lipsync render` reads)")
    p.add_argument("-o", "--output", required=True, metavar="ATLAS.png",
                   help="the texture; ATLAS.json (and ATLAS.base.png) go beside it")
    p.add_argument("--inbetweens", "-n", type=int, default=3, metavar="N",
                   help="in-betweens per transition, at alpha k/(N+1) (default: 3)")
    p.add_argument("--pairs", choices=("used", "all"), default=None,
                   help="transitions: those the TIMELINEs use, or every pair of visemes "
                        "(default: used when TIMELINEs are given, else all)")
    p.add_argument("--method", choices=METHODS.names(), default="flow", help="in-between method (default: flow)")
    p.add_argument("--max-size", type=int, default=DEFAULT_MAX_SIZE, metavar="PX",
                   help=f"largest texture side; above it the command fails naming a --scale that fits "
                        f"(default: {DEFAULT_MAX_SIZE})")
    p.add_argument("--scale", type=float, default=1.0, metavar="S",
                   help="texture pixels per frame pixel, in (0, 1] (default: 1)")
    p.add_argument("--padding", type=int, default=DEFAULT_PADDING, metavar="PX",
                   help=f"pixels around each cell repeating its edge (default: {DEFAULT_PADDING})")
    p.add_argument("--no-crop", dest="crop", action="store_false",
                   help="cells are whole frames (default: only the region that changes, plus ATLAS.base.png)")
    p.add_argument("--player", action="store_true",
                   help="also write the example players beside the atlas: player.html and player.js (a web "
                        "page), lipsync_player.gd (Godot 3)")
    add_store_option(p)
    add_jobs_option(p)
    add_quiet_option(p)
    add_timeline_options(p)
    p.set_defaults(func=run, extra_positionals="timelines")


def _bank_and_timelines(args: argparse.Namespace) -> None:
    """Settle ``args.bank``: the first positional is the bank unless it is a timeline file
    (``lipsync atlas -o A.png speech.TextGrid`` uses the toon), then ``--bank``, then the toon."""
    import os

    from .._data import DEFAULT_BANK_NAME
    from ..errors import InputError

    first = args.bank
    if first is not None and os.path.isfile(first) and os.path.basename(first) != "bank.yaml":
        args.timelines.insert(0, first)
        first = None
    if first is not None and args.bank_option is not None:
        raise InputError(f"two banks given: {first!r} and --bank {args.bank_option!r}")
    args.bank = first or args.bank_option or DEFAULT_BANK_NAME


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ..atlas.build import build_atlas, pairs_in_plan, pairs_in_specs, write_atlas
    from ..banks.bank import Bank
    from ..motion.coarticulation import resolve_timing, viseme_classes
    from ..errors import InputError
    from ..motion.sequencer import FPS_RANGE, plan_segments, sequence
    from ..motion.timing import is_model
    from ._common import check_png, load_viseme_timeline

    check_png(args.output)
    _bank_and_timelines(args)
    if Path(args.output).is_dir():
        raise InputError("is a folder; give a file name for the atlas", path=args.output)
    mode = args.pairs or ("used" if args.timelines else "all")
    if mode == "used" and not args.timelines:
        raise InputError("--pairs used needs timelines: lipsync atlas BANK -o ATLAS.png TIMELINE [TIMELINE ...]")
    if mode == "all" and args.timelines:
        raise InputError("--pairs all takes no timelines (they would only choose pairs)")
    bank = Bank.load(args.bank)
    pairs = "all"
    if mode == "used":
        pairs = []
        timing = resolve_timing(args.timing, bank)
        for path in args.timelines:
            one = argparse.Namespace(**{**vars(args), "timeline": path})
            timeline, pmap = load_viseme_timeline(one, rest=bank.rest, viseme_names=bank.names)
            plan = plan_segments(timeline, rest=bank.rest, closures=pmap.closures)
            found = pairs_in_plan(plan, bank.names)
            if is_model(timing) or not (isinstance(timing, str) or callable(timing)):
                # the dominance model blends the two heaviest sounds, not only neighbours:
                # its pairs are those its frames show, sampled at the highest frame rate
                specs = sequence(timeline, fps=FPS_RANGE[1], rest=bank.rest, timing=timing,
                                 closures=pmap.closures, classes=viseme_classes(pmap, bank.rest))
                found += pairs_in_specs(specs, bank.names)
            pairs += [p for p in found if p not in pairs]
    built = build_atlas(bank, pairs=pairs, inbetweens=args.inbetweens, method=args.method, store=args.store,
                        scale=args.scale, max_size=args.max_size, padding=args.padding, crop=args.crop,
                        jobs=args.jobs, quiet=args.quiet)
    atlas = write_atlas(built, args.output)
    if args.player:
        from ..atlas import player_files
        from .._files import atomic_write_bytes

        for src in player_files():
            data = src.read_bytes()
            atomic_write_bytes(Path(args.output).with_name(src.name), lambda fh, d=data: fh.write(d))
    if not args.quiet:
        n_pairs = len({(c.from_viseme, c.to_viseme) for c in atlas.cells if c.viseme is None})
        w, h = atlas.image_size
        rw, rh = atlas.region[2:]
        print(f"lipsync: wrote {args.output} ({w} x {h} px: {len(atlas.visemes)} visemes and {n_pairs} "
              f"transitions x {atlas.inbetweens} in-betweens, {len(atlas.cells)} cells of {rw} x {rh} frame px"
              f"{'' if atlas.scale == 1 else f' at scale {atlas.scale:g}'}) and {atlas.path}"
              f"{' (+ ' + atlas.base + ')' if atlas.base else ''}", file=sys.stderr)
    return 0
