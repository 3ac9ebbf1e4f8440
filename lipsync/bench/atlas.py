"""Sprite-atlas figure (issue 18), registered in :data:`lipsync.bench.FIGURES`:

``atlas``: per timeline and number of in-betweens N, the cells and texture size, the time
to render the atlas (wall and CPU, flows cached), and how far playing it is from lipsync's
own frames: the mean absolute difference over the atlas' region between the cell
frames.json names and ``Animator``'s frame, over the morph frames at 25 fps (N = 0 is hard
cuts to the nearer viseme). Measured side by side in one run; nothing is asserted here
(``tests/test_atlas*.py`` check correctness).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import List

import numpy as np

from . import FIGURES, Context

ROOT = Path(__file__).resolve().parents[2]


def bench_atlas(rows: List[dict], quick: bool) -> None:
    from .._data import default_bank_dir
    from ..pipeline.animator import Animator
    from ..atlas.build import build_atlas, pairs_in_plan
    from ..atlas.frames import quantise
    from ..banks.bank import Bank
    from ..motion.sequencer import plan_segments

    bank = Bank.load(default_bank_dir())
    for name in ("hello",) if quick else ("hello", "balloons"):
        anim = Animator(bank, ROOT / "samples" / f"{name}.phn", fps=25)
        plan = plan_segments(anim.visemes, rest=bank.rest, closures=["A"])
        pairs = pairs_in_plan(plan, bank.names)
        truth = {n: anim.frame(n).astype(np.int16) for n, s in enumerate(anim.specs) if not s.is_still}
        build_atlas(bank, pairs=pairs[:1], inbetweens=0)  # warm-up: normalised images, flows mapped
        for n_between in (0, 1, 3) if quick else (0, 1, 3, 7):
            t0, c0 = time.perf_counter(), time.process_time()
            built = build_atlas(bank, pairs=pairs, inbetweens=n_between)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            cells, _ = quantise(built.atlas, anim.specs)
            rx, ry, rw, rh = built.atlas.region
            errors = []
            for n, frame in truth.items():
                c = built.atlas.cells[cells[n]]
                drawn = anim.renderer.render(c.from_viseme, c.to_viseme, c.alpha).astype(np.int16)
                errors.append(float(np.abs(drawn - frame)[ry:ry + rh, rx:rx + rw].mean()))
            h, w = built.texture.shape[:2]
            rows.append({"figure": "atlas", "timeline": name, "pairs": len(pairs), "inbetweens": n_between,
                         "cells": len(built.atlas.cells), "texture": f"{w}x{h}", "region": f"{rw}x{rh}",
                         "build_wall_s": round(wall, 2), "build_cpu_s": round(cpu, 2),
                         "morph_frames": len(errors), "mean_abs_error": round(float(np.mean(errors)), 2),
                         "max_abs_error": round(float(np.max(errors)), 2)})


@FIGURES.decorator("atlas")
def _atlas(ctx: Context, rows: List[dict]) -> None:
    bench_atlas(rows, ctx.quick)
