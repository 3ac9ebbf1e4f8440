"""``lipsync check BANK``: validate a bank and summarise it, computing nothing."""

from __future__ import annotations

import argparse

from ..banks.bank import Bank
from ..morphing.store import FlowStore
from ._common import add_store_option


def add_parser(sub) -> None:
    c = sub.add_parser("check", help="validate a bank and summarise it, computing nothing")
    c.add_argument("bank", help="bank folder (with bank.yaml), or a shipped subject's name (toon, grid-s1)")
    add_store_option(c)
    c.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..morphing.normalise import bank_axis, symmetric_lines
    from ..morphing.preprocess import all_pairs

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
    print("  flows refined by optical flow (refine: true)" if bank.refine else
          "  flows from the control lines alone (refine: false)")
    store = FlowStore.for_bank(bank, args.store)
    pairs = all_pairs(bank.names)
    axis = bank_axis(bank) if bank.symmetry else None
    # Present means usable: each entry is read and its checksum checked (a damaged one is a
    # miss for render and preprocess, so it is not counted; each gets a warning naming it).
    present = damaged = 0
    for a, b in pairs:
        key = store.pair_key(bank, a, b, axis)
        if store.pair_path(key).exists():
            if store.load_pair(key, bank.shape) is not None:
                present += 1
            else:
                damaged += 1
    extra = f", {damaged} damaged (lipsync preprocess recomputes them)" if damaged else ""
    print(f"  flow store {store.root}: {present} of {len(pairs)} pairs present{extra}")
    if bank.samples is not None:  # read and validated whole: a broken file exits 2 naming it
        from ..samples import load_samples
        from dataclasses import replace

        s = load_samples(replace(bank, samples=replace(bank.samples, enabled=True)))
        print(f"  samples: {len(s)} mouth samples from {len(s.clips)} clip(s), {s.crops.shape[2]}x{s.crops.shape[1]} "
              f"crops, {int(s.run.max()) + 1} runs{'' if bank.samples.enabled else ' (switched off)'}"
              f"{', audio lip model' if 'lip_weights' in s.table else ''}")
    return 0
