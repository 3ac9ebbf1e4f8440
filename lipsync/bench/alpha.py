"""Speed figures of transparency (issue 18), registered in :data:`lipsync.bench.FIGURES`:

1. ``alpha_frame``: ms per frame of an RGBA bank against the same bank opaque (RGB), side
   by side in one run, per method and frame kernel, on one core (wall and CPU time); the
   goal is RGBA <= 1.2x RGB for the flow method;
2. ``alpha_encode``: encoding the same RGBA frames to WebM (VP9 + alpha), MOV (ProRes
   4444), a PNG sequence, animated WebP and GIF, against H.264 mp4 of the flattened frames:
   wall and CPU seconds (ours plus ffmpeg's) and megabytes.
"""

from __future__ import annotations

import resource
import time
from pathlib import Path
from typing import Dict, List

import cv2
import numpy as np

from . import FIGURES, Context


def rgba_twin(src: Path, dst: Path) -> Path:
    """A copy of bank ``src`` whose images get a soft elliptical alpha mask (a sprite cut
    out of its background): the same pixels and lines, RGBA."""
    import shutil

    shutil.copytree(src, dst, ignore=shutil.ignore_patterns(".lipsync", "store"))
    for p in sorted(dst.glob("*.png")):
        bgr = cv2.imread(str(p), cv2.IMREAD_COLOR)
        h, w = bgr.shape[:2]
        ys, xs = np.mgrid[0:h, 0:w]
        r = np.hypot((xs - w / 2) / (0.42 * w), (ys - h / 2) / (0.46 * h))
        # opaque inside, a 6 % soft edge, transparent outside
        alpha = np.clip((1.0 - r) / 0.06 + 0.5, 0, 1) * 255
        cv2.imwrite(str(p), np.dstack([bgr, np.rint(alpha).astype(np.uint8)]))
    return dst


def _cpu() -> float:
    """This process's CPU seconds and its finished children's (ffmpeg)."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def bench_alpha_frames(rows: List[dict], banks: Dict[str, Path], tmp: Path, quick: bool) -> None:
    from ..banks.bank import Bank
    from ..morphing.preprocess import preprocess
    from ..morphing.render import Renderer, available_kernels
    from ..morphing.store import FlowStore

    pairs = [("X", "D"), ("A", "C"), ("B", "F"), ("E", "H")]
    alphas = np.linspace(0.1, 0.9, 3 if quick else 7)
    for label, path in banks.items():
        twin = tmp / f"rgba-{label}"
        if not twin.exists():
            rgba_twin(path, twin)
        pair_of = {"rgb": Bank.load(path), "rgba": Bank.load(twin)}
        assert pair_of["rgb"].channels == 3 and pair_of["rgba"].channels == 4
        for bank in pair_of.values():
            preprocess(bank, store=FlowStore.for_bank(bank), quiet=True)
        variants = [("flow", k) for k in available_kernels()] + [("splat", None), ("dissolve", None),
                                                                  ("beier-neely", None)]
        for method, kernel in variants:
            if quick and method in ("splat", "beier-neely"):
                continue
            renderers = {}
            for kind, bank in pair_of.items():
                r = Renderer(bank, method=method, kernel=kernel)
                r.frame_threads = 1  # one core: the kernel's own cost
                renderers[kind] = r
            run_alphas = alphas[:2] if method == "beier-neely" else alphas

            def frames(r):
                for a, b in pairs:
                    for al in run_alphas:
                        r.render(a, b, float(al))

            for r in renderers.values():
                frames(r)  # warm-up: pair states, packed images
            n = len(pairs) * len(run_alphas)
            wall = {k: [] for k in renderers}
            cpu = {k: [] for k in renderers}
            repeats = 1 if method == "beier-neely" else (3 if quick else 7)
            for _ in range(repeats):
                for kind, r in renderers.items():  # interleaved: both see the same machine load
                    t0, c0 = time.perf_counter(), time.thread_time()
                    frames(r)
                    wall[kind].append((time.perf_counter() - t0) * 1e3 / n)
                    cpu[kind].append((time.thread_time() - c0) * 1e3 / n)
            med = {k: float(np.median(v)) for k, v in wall.items()}
            cmed = {k: float(np.median(v)) for k, v in cpu.items()}
            rows.append({"figure": "alpha_frame", "size": label, "method": method, "kernel": kernel or "",
                         "rgb_ms": round(med["rgb"], 3), "rgba_ms": round(med["rgba"], 3),
                         "rgba_over_rgb": round(med["rgba"] / med["rgb"], 2),
                         "cpu_rgb_ms": round(cmed["rgb"], 3), "cpu_rgba_ms": round(cmed["rgba"], 3),
                         "cpu_rgba_over_rgb": round(cmed["rgba"] / cmed["rgb"], 2)})


def bench_alpha_encode(rows: List[dict], banks: Dict[str, Path], tmp: Path, quick: bool) -> None:
    from ..morphing.alpha import flatten
    from ..banks.bank import Bank
    from ..encode import open_writer
    from ..morphing.render import Renderer

    label = "512x512"
    twin = tmp / f"rgba-{label}"
    if not twin.exists():
        rgba_twin(banks[label], twin)
    bank = Bank.load(twin)
    r = Renderer(bank)
    seq = [("X", "D"), ("D", "B"), ("B", "F"), ("F", "X")]
    steps = 6 if quick else 25  # 4 s of 25 fps video
    frames = [r.render(a, b, float(t)).copy() for a, b in seq for t in np.linspace(0, 1, steps, endpoint=False)]
    h, w = frames[0].shape[:2]
    opaque = [flatten(f, (255, 255, 255)) for f in frames]
    outputs = [("mp4", "clip.mp4", opaque), ("webm", "clip.webm", frames), ("mov", "clip.mov", frames),
               ("png", "frames", frames), ("webp", "clip.webp", frames), ("gif", "clip.gif", frames)]
    from ..encode import ENCODERS

    base = None
    for fmt, name, data in outputs:
        if fmt not in ENCODERS:
            continue
        out = tmp / f"enc-{name}"
        times = []
        for _ in range(1 if quick else 3):
            t0, c0 = time.perf_counter(), _cpu()
            with open_writer(out, fps=25, size=(w, h), format=fmt, quiet=True, frames=len(data),
                             channels=data[0].shape[2]) as wr:
                for f in data:
                    wr.write(f)
            times.append((time.perf_counter() - t0, _cpu() - c0))
        wall, cpu = (float(np.median([t[i] for t in times])) for i in (0, 1))
        size = sum(p.stat().st_size for p in out.iterdir()) if out.is_dir() else out.stat().st_size
        if base is None:
            base = (wall, cpu)
        rows.append({"figure": "alpha_encode", "format": fmt, "frames": len(data), "size": f"{w}x{h}",
                     "wall_s": round(wall, 2), "cpu_s": round(cpu, 2), "MB": round(size / 1e6, 2),
                     "wall_over_mp4": round(wall / base[0], 2), "cpu_over_mp4": round(cpu / base[1], 2),
                     "fps_wall": round(len(data) / wall, 1)})


@FIGURES.decorator("alpha_frame")
def _alpha_frame(ctx: Context, rows: List[dict]) -> None:
    from .render import _toon_banks

    bench_alpha_frames(rows, _toon_banks(ctx), ctx.tmp, ctx.quick)


@FIGURES.decorator("alpha_encode")
def _alpha_encode(ctx: Context, rows: List[dict]) -> None:
    from .render import _toon_banks

    bench_alpha_encode(rows, _toon_banks(ctx), ctx.tmp, ctx.quick)
