"""``lipsync preprocess BANK``: compute and cache the flows between every pair of visemes."""

from __future__ import annotations

import argparse

from ..banks.bank import Bank
from ..morphing.store import FlowStore
from ._common import add_jobs_option, add_quiet_option, add_store_option


def add_parser(sub) -> None:
    p = sub.add_parser("preprocess", help="compute and cache the flows between every pair of visemes",
                       description="Compute the Beier-Neely flow of every viseme pair that the flow "
                                   "store lacks (in parallel), then print a summary.")
    p.add_argument("bank", help="bank folder (with bank.yaml), or a shipped subject's name (toon, grid-s1)")
    add_jobs_option(p, "computing flows")
    add_store_option(p)
    p.add_argument("--prune", action="store_true",
                   help="remove store entries the bank no longer uses (a store of this bank only)")
    add_quiet_option(p)
    p.set_defaults(func=run)



def run(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..morphing.preprocess import preprocess

    if args.jobs is not None and args.jobs < 1:
        raise InputError(f"--jobs must be at least 1, got {args.jobs}")
    bank = Bank.load(args.bank)
    report = preprocess(bank, store=FlowStore.for_bank(bank, args.store), jobs=args.jobs, quiet=args.quiet,
                        prune=args.prune)
    print(f"{bank.name}: {report.summary()}")
    return 0
