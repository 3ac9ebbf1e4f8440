"""``lipsync morph BANK FROM TO``: one in-between frame, or a strip like the paper's figures 8-9."""

from __future__ import annotations

import argparse

import numpy as np

from ..morphing.render import METHODS
from ._common import add_store_option, check_png

#: Width of one tile in strips and sheets: large enough to judge lip contours, small
#: enough that a 9-column strip stays under ~2000 px wide.
STRIP_TILE = 220


def add_parser(sub) -> None:
    m = sub.add_parser("morph", help="render one in-between frame, or a strip of them",
                       description="Morph between two visemes of a bank: one frame with --alpha, or with "
                                   "--frames N a strip of forward warps, blends and backward warps.")
    m.add_argument("bank", help="bank folder, or a shipped subject's name (toon, grid-s1)")
    m.add_argument("from_viseme", metavar="FROM")
    m.add_argument("to_viseme", metavar="TO")
    g = m.add_mutually_exclusive_group(required=True)
    g.add_argument("--alpha", type=float, help="position between FROM (0) and TO (1)")
    g.add_argument("--frames", type=int, help="draw a strip of N frames from alpha 0 to 1")
    m.add_argument("-o", "--output", required=True, metavar="OUT.png")
    m.add_argument("--method", choices=METHODS.names(), default="flow")
    add_store_option(m)
    m.set_defaults(func=run)



def run(args: argparse.Namespace) -> int:
    from ..banks.bank import Bank
    from ..errors import InputError
    from ..encode.preview import save_png, strip
    from ..morphing.render import Renderer
    from ..morphing.store import FlowStore

    check_png(args.output)
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
