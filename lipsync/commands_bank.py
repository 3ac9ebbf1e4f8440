"""``lipsync preprocess`` and ``lipsync check``: work on a viseme bank."""

from __future__ import annotations

import argparse

from .bank import Bank
from .store import FlowStore


def add_parser(sub) -> None:
    p = sub.add_parser("preprocess", help="compute and cache the flows between every pair of visemes",
                       description="Compute the Beier-Neely flow of every viseme pair that the flow "
                                   "store lacks (in parallel), then print a summary.")
    p.add_argument("bank", help="bank folder (with bank.yaml)")
    p.add_argument("--jobs", "-j", type=int, default=None, help="worker processes (default: all cores)")
    p.add_argument("--store", default=None, help="flow store folder (default: BANK/.lipsync)")
    p.add_argument("--prune", action="store_true",
                   help="remove store entries the bank no longer uses (a store of this bank only)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    p.set_defaults(func=run_preprocess)

    c = sub.add_parser("check", help="validate a bank and summarise it, computing nothing")
    c.add_argument("bank", help="bank folder (with bank.yaml)")
    c.add_argument("--store", default=None, help="flow store folder to report on (default: BANK/.lipsync)")
    c.set_defaults(func=run_check)


def run_preprocess(args: argparse.Namespace) -> int:
    from .errors import InputError
    from .preprocess import preprocess

    if args.jobs is not None and args.jobs < 1:
        raise InputError(f"--jobs must be at least 1, got {args.jobs}")
    bank = Bank.load(args.bank)
    report = preprocess(bank, store=FlowStore.for_bank(bank, args.store), jobs=args.jobs, quiet=args.quiet,
                        prune=args.prune)
    print(f"{bank.name}: {report.summary()}")
    return 0


def run_check(args: argparse.Namespace) -> int:
    from .normalise import bank_axis, symmetric_lines
    from .preprocess import all_pairs

    bank = Bank.load(args.bank)
    h, w = bank.shape
    print(f"{bank.yaml_path}: OK")
    print(f"  name {bank.name!r}, {len(bank.names)} visemes ({', '.join(bank.names)}), rest {bank.rest!r}")
    print(f"  images {w}x{h}, {len(bank.line_names)} control lines, warp a={bank.warp.a} b={bank.warp.b} "
          f"p={bank.warp.p}")
    if bank.symmetry:
        axis = bank_axis(bank)
        worst = max(float(abs(symmetric_lines(bank.lines[v], bank.line_names, axis) - bank.lines[v]).max())
                    for v in bank.names)
        print(f"  symmetry on: axis x = {axis}, lines move by at most {worst:.2f} px when normalised")
    store = FlowStore.for_bank(bank, args.store)
    pairs = all_pairs(bank.names)
    axis = bank_axis(bank) if bank.symmetry else None
    present = sum(store.pair_path(store.pair_key(bank, a, b, axis)).exists() for a, b in pairs)
    print(f"  flow store {store.root}: {present} of {len(pairs)} pairs present")
    return 0
