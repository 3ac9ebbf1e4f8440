"""``lipsync preview BANK``: every viseme with its control lines and their names, on one sheet."""

from __future__ import annotations

import argparse

from ._common import check_png

#: Width of one tile of the sheet: large enough to read line names at 512x512.
SHEET_TILE = 320


def add_parser(sub) -> None:
    p = sub.add_parser("preview", help="draw every viseme with its control lines (check line placement)")
    p.add_argument("bank", help="bank folder, or a shipped subject's name (toon, grid-s1)")
    p.add_argument("-o", "--output", required=True, metavar="SHEET.png")
    p.add_argument("--normalised", action="store_true", help="show the images and lines after symmetric "
                                                             "normalisation")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..banks.bank import Bank
    from ..morphing.normalise import normalise
    from ..encode.preview import feature_lines, preview_sheet, save_png

    check_png(args.output)
    bank = Bank.load(args.bank)
    if args.normalised:
        nb = normalise(bank)
        images, lines = nb.images, nb.lines
    else:
        images, lines = bank.images, bank.lines
    # Curves (segments name#i) are drawn as one chain each.
    named = {v: feature_lines(bank.line_names, lines[v]) for v in bank.names}
    save_png(args.output, preview_sheet({v: images[v] for v in bank.names}, named, tile=SHEET_TILE))
    return 0
