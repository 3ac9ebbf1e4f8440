"""``make bench`` / ``python -m lipsync.bench``: every speed figure, measured side by side.

Each figure lives in a module of this package beside the part it measures and registers
itself in :data:`FIGURES`; ``main`` runs them all (or ``--only NAME``), prints one table per
figure and writes ``bench/results.json``. Timings are the median of repeated runs after a
warm-up. Nothing here is asserted: the test suite checks correctness, this prints numbers.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import json
import os
import statistics
import sys
import tempfile
import time
import tracemalloc
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, List

import numpy as np

from ..registry import Registry

#: name -> function(ctx: Context, rows: list) appending one dict per measured row (each with
#: a "figure" key). Registered by the modules in _FIGURE_MODULES, in this order.
FIGURES: "Registry[Callable[[Context, List[dict]], None]]" = Registry("benchmark figure")

# Figure modules, run in this order; a module not written yet is skipped.
_FIGURE_MODULES = ["render", "align", "live", "batch", "editor", "face", "videobank", "alpha", "coarticulation", "ceiling",
                   "atlas", "inbetween", "languages", "dub", "timing_editor", "sequencer", "translation",
                   "plate_time", "samples", "live_samples", "live_samples_cost"]


@dataclass(frozen=True)
class Context:
    """What every figure may use.

    Attributes
    ----------
    quick : bool
        Fewer repeats (a smoke run).
    tmp : Path
        A scratch folder removed after the run.
    mfa : Path
        The folder with the MFA conformance files (acoustic_corpus.TextGrid/.wav/.lab).
    """

    quick: bool
    tmp: Path
    mfa: Path


def median_ms(fn: Callable[[], object], repeat: int, warmup: int = 1, clock: Callable[[], float] = time.perf_counter
              ) -> float:
    """Median ms of ``fn`` over ``repeat`` runs; ``clock=time.thread_time`` counts this
    thread's CPU time instead of wall time (steadier when other work shares the cores)."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        t = clock()
        fn()
        times.append(clock() - t)
    return statistics.median(times) * 1e3


def peak_mb(fn: Callable[[], object]) -> float:
    gc.collect()
    tracemalloc.start()
    try:
        result = fn()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # the returned map itself (H x W x 2 float32) is output, not working memory
    out = getattr(result, "nbytes", 0)
    return max(0.0, (peak - out) / 1e6)


def _table(rows: List[dict]) -> str:
    lines = []
    # Every figure present, in the order they ran.
    for fig in dict.fromkeys(r["figure"] for r in rows):
        sel = [r for r in rows if r["figure"] == fig]
        # the union of the rows' columns: a figure's rows need not all measure the same things
        keys = list(dict.fromkeys(k for r in sel for k in r if k != "figure"))
        widths = [max(len(k), *(len(str(r.get(k, ""))) for r in sel)) for k in keys]
        lines.append(f"\n## {fig}")
        lines.append("  ".join(k.ljust(w) for k, w in zip(keys, widths)))
        for r in sel:
            lines.append("  ".join(str(r.get(k, "")).ljust(w) for k, w in zip(keys, widths)))
    return "\n".join(lines)


def _conformance_dir() -> Path:
    # $LIPSYNC_CONFORMANCE, else the shared folder beside the checkout or a level up (a
    # worktree sits one level deeper than the main checkout), else the tests' copies
    root = Path(__file__).resolve().parents[2]
    candidates = [Path(os.environ["LIPSYNC_CONFORMANCE"]) / "mfa"] if os.environ.get("LIPSYNC_CONFORMANCE") else []
    candidates += [up / "shared" / "conformance" / "mfa" for up in (root.parent, root.parent.parent)]
    for c in candidates:
        if (c / "acoustic_corpus.wav").is_file():
            return c
    return root / "tests" / "data" / "conformance" / "mfa"


def main(argv=None) -> int:
    for name in _FIGURE_MODULES:
        try:
            importlib.import_module(f".{name}", __name__)
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
    parser = argparse.ArgumentParser(prog="python -m lipsync.bench", description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats (a smoke run)")
    parser.add_argument("--only", action="append", choices=FIGURES.names(), metavar="NAME",
                        help=f"run only these figures (repeatable): {', '.join(FIGURES.names())}")
    parser.add_argument("--json", default="bench/results.json", help="where to write the results")
    args = parser.parse_args(argv)

    rows: List[dict] = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        ctx = Context(quick=args.quick, tmp=Path(tmp), mfa=_conformance_dir())
        for name, figure in FIGURES.items():
            if args.only and name not in args.only:
                continue
            print(f"{name} ...", file=sys.stderr)
            figure(ctx, rows)
    meta = {"cpu_count": os.cpu_count(), "seconds": round(time.perf_counter() - t0, 1),
            "python": sys.version.split()[0], "numpy": np.__version__}
    print(_table(rows))
    print(f"\n(total {meta['seconds']} s on {meta['cpu_count']} cores)")
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp_out = out.with_suffix(".json.tmp")
    tmp_out.write_text(json.dumps({"meta": meta, "results": rows}, indent=2) + "\n")
    os.replace(tmp_out, out)
    print(f"wrote {out}")
    return 0
