"""``lipsync languages``: every ``--lang`` code, with its language's name, one a line."""

from __future__ import annotations

import argparse


def add_parser(sub) -> None:
    p = sub.add_parser("languages", help="list the --lang codes (espeak-ng's languages; English needs no code)",
                       description="List every language code --lang takes, with its name, one a line. "
                                   "English (en, en-US, en-GB, ...) is always available; the others need the "
                                   "optional espeak-ng extra (pip install 'lipsync[lang]').")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..phonetics.g2p import languages

    for code, name in languages().items():   # LanguageUnavailableError (exit 2) without the extra
        print(f"{code}\t{name}")
    return 0
