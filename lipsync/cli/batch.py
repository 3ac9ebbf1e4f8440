"""``lipsync batch``: render every clip of a manifest on a local process cluster or a dask cluster."""

from __future__ import annotations

import argparse
import sys

from . import EXIT_FAILURE, EXIT_OK
from ._common import add_quiet_option


def add_parser(sub) -> None:
    from ..batch.manifest import FIELDS

    fields = "; ".join(f"{k}: {v}" for k, v in FIELDS.items())
    p = sub.add_parser("batch", help="render many clips listed in a manifest, on local processes or a dask cluster",
                       description="Render every clip of MANIFEST (CSV with a header, or JSON lines) into OUTDIR "
                                   "on a dask.distributed cluster. Clips whose output is current are skipped; "
                                   "a failing clip is recorded in the report and the others go on. "
                                   f"Fields: {fields}. Relative paths are relative to the manifest.")
    p.add_argument("manifest", metavar="MANIFEST", help="clips to render (.csv with a header, or .jsonl)")
    p.add_argument("-o", "--output", required=True, metavar="OUTDIR", help="folder for the videos")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None, metavar="N",
                       help="worker processes of a local cluster on 127.0.0.1 (default: one per core)")
    where.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                       help="a running dask.distributed scheduler; its workers need only lipsync installed")
    p.add_argument("--report", default=None, metavar="FILE",
                   help="per-clip report, .json or .csv (default: OUTDIR/lipsync-batch-report.json)")
    p.add_argument("--cache", default=None, metavar="DIR",
                   help="folder on the workers for unpacked banks and flows (default: ~/.cache/lipsync/batch)")
    add_quiet_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..batch import run_batch

    report = run_batch(args.manifest, args.output, workers=args.workers, scheduler=args.scheduler,
                       report=args.report, cache=args.cache, quiet=args.quiet)
    if not args.quiet:
        for c in report.clips:
            if c.status == "failed":
                print(f"lipsync batch: failed: {c.output} (line {c.line}): {c.error}", file=sys.stderr)
        print(report.summary(), file=sys.stderr)
    return EXIT_FAILURE if report.failed else EXIT_OK
