"""``lipsync morph`` (one frame, or a strip like the paper's figures 8-9) and ``lipsync preview``."""

from __future__ import annotations

import argparse

import numpy as np

from .render import METHODS

#: Width of one tile in strips and sheets: large enough to judge lip contours, small
#: enough that a 9-column strip stays under ~2000 px wide.
STRIP_TILE = 220
SHEET_TILE = 320


def add_parser(sub) -> None:
    m = sub.add_parser("morph", help="render one in-between frame, or a strip of them",
                       description="Morph between two visemes of a bank: one frame with --alpha, or with "
                                   "--frames N a strip of forward warps, blends and backward warps.")
    m.add_argument("bank", help="bank folder")
    m.add_argument("from_viseme", metavar="FROM")
    m.add_argument("to_viseme", metavar="TO")
    g = m.add_mutually_exclusive_group(required=True)
    g.add_argument("--alpha", type=float, help="position between FROM (0) and TO (1)")
    g.add_argument("--frames", type=int, help="draw a strip of N frames from alpha 0 to 1")
    m.add_argument("-o", "--output", required=True, metavar="OUT.png")
    m.add_argument("--method", choices=METHODS.names(), default="flow")
    m.add_argument("--store", default=None, metavar="DIR", help="flow store folder (default: BANK/.lipsync)")
    m.set_defaults(func=run_morph)

    p = sub.add_parser("preview", help="draw every viseme with its control lines (check line placement)")
    p.add_argument("bank", help="bank folder")
    p.add_argument("-o", "--output", required=True, metavar="SHEET.png")
    p.add_argument("--normalised", action="store_true", help="show the images and lines after symmetric "
                                                             "normalisation")
    p.set_defaults(func=run_preview)


def _check_png(path: str) -> None:
    from .errors import InputError

    if not path.lower().endswith(".png"):
        raise InputError(f"output must be a .png file, got {path!r}")


def run_morph(args: argparse.Namespace) -> int:
    from .bank import Bank
    from .errors import InputError
    from .preview import save_png, strip
    from .render import Renderer
    from .store import FlowStore

    _check_png(args.output)
    bank = Bank.load(args.bank)
    renderer = Renderer(bank, method=args.method, store=FlowStore.for_bank(bank, args.store))
    if args.alpha is not None:
        if not 0.0 <= args.alpha <= 1.0:
            raise InputError(f"--alpha must be between 0 and 1, got {args.alpha}")
        save_png(args.output, renderer.render(args.from_viseme, args.to_viseme, args.alpha))
        return 0
    if not 2 <= args.frames <= 64:
        raise InputError(f"--frames must be 2..64, got {args.frames}")
    alphas = np.linspace(0.0, 1.0, args.frames)
    cols = [renderer.parts(args.from_viseme, args.to_viseme, float(a)) for a in alphas]
    rows = [[c[0] for c in cols], [c[2] for c in cols], [c[1] for c in cols]]
    sheet = strip(rows, row_labels=[f"{args.from_viseme} warped", "blend", f"{args.to_viseme} warped"],
                  column_labels=[f"alpha {a:.2f}" for a in alphas], tile=STRIP_TILE)
    save_png(args.output, sheet)
    return 0


def run_preview(args: argparse.Namespace) -> int:
    from .bank import Bank
    from .normalise import normalise
    from .preview import preview_sheet, save_png

    _check_png(args.output)
    bank = Bank.load(args.bank)
    if args.normalised:
        nb = normalise(bank)
        images, lines = nb.images, nb.lines
    else:
        images, lines = bank.images, bank.lines
    named = {v: {n: lines[v][i] for i, n in enumerate(bank.line_names)} for v in bank.names}
    save_png(args.output, preview_sheet({v: images[v] for v in bank.names}, named, tile=SHEET_TILE))
    return 0
