"""Speed figure of ``lipsync batch`` (registered in :data:`lipsync.bench.FIGURES` as ``batch``).

A manifest of short dialogue lines (seeded random Rhubarb cues, 3-5 s each, the default
subject at 512x512) rendered three ways side by side, flows already in the workers' cache:

* ``render_clip`` in a loop in this process (no dask: the floor the batch is measured against);
* ``lipsync batch`` on a LocalCluster of 1 worker process, then of 2.

Per row: seconds of video, cluster start-up, wall time of the batch, seconds of video per
wall second (without and with start-up), the speed-up over 1 worker, CPU seconds per
second of video (workers and their ffmpeg children: the number that extrapolates, since
wall times on a shared machine follow its load, printed beside them). A second table
(``batch_bytes``) gives what moves per bank and per clip, for docs/scaling.md.
"""

from __future__ import annotations

import csv
import time
from pathlib import Path
from typing import List

import numpy as np

from . import FIGURES, Context

#: Rhubarb's nine shapes; dialogue changes shape every 60-300 ms.
_SHAPES = "ABCDEFGHX"


def write_clips(folder: Path, n: int, seed: int = 0) -> Path:
    """``n`` seeded Rhubarb TSV clips of 3-5 s and a CSV manifest of them; returns the manifest."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for i in range(n):
        length = rng.uniform(3.0, 5.0)
        t, lines = 0.0, ["0.00\tX"]
        t = rng.uniform(0.1, 0.3)
        while t < length - 0.3:
            lines.append(f"{t:.2f}\t{_SHAPES[rng.integers(0, len(_SHAPES))]}")
            t += rng.uniform(0.06, 0.3)
        lines.append(f"{t:.2f}\tX")
        lines.append(f"{length:.2f}\tX")
        (folder / f"line{i:03d}.tsv").write_text("\n".join(lines) + "\n")
        rows.append({"input": f"line{i:03d}.tsv", "output": f"line{i:03d}.mp4"})
    manifest = folder / "clips.csv"
    with open(manifest, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=["input", "output"])
        w.writeheader()
        w.writerows(rows)
    return manifest


def _cpu_seconds() -> float:
    """CPU seconds of this process and its finished children (ffmpeg), user + system."""
    import resource

    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime


def bench_batch(rows: List[dict], tmp: Path, quick: bool) -> None:
    import os

    from .._data import default_bank_dir
    from ..banks.bank import Bank
    from ..batch import connect, pack_bank, read_manifest, run_batch
    from ..pipeline.clip import render_clip
    from ..morphing.preprocess import preprocess
    from ..morphing.store import FlowStore

    n = 4 if quick else 12
    manifest = write_clips(tmp / "batch-clips", n)
    cache = tmp / "batch-cache"
    jobs = read_manifest(manifest)

    # Cold: a fresh worker cache, so the bank is unpacked and its flows computed on the
    # cluster (once, pairs spread over the workers). Later rows are steady state, the case
    # of a studio whose banks were used before.
    t = time.perf_counter()
    run_batch(manifest, tmp / "batch-out-cold", workers=2, cache=str(cache), quiet=True)
    cold = time.perf_counter() - t

    # In-process floor: the same clips through render_clip, flows cached, no dask.
    bank = Bank.load(default_bank_dir())
    store = FlowStore(tmp / "batch-local-store")
    preprocess(bank, store=store, quiet=True)
    (tmp / "batch-local").mkdir()
    cpu, t = _cpu_seconds(), time.perf_counter()
    video = 0.0
    for job in jobs:
        report = render_clip(job.input, tmp / "batch-local" / job.output, bank=bank, store=store, quiet=True, jobs=1)
        video += report.duration
    wall, cpu = time.perf_counter() - t, _cpu_seconds() - cpu
    rows.append({"figure": "batch", "how": "render_clip loop, no dask", "workers": "-", "clips": n,
                 "video_s": round(video, 1), "startup_s": 0.0, "wall_s": round(wall, 2),
                 "video_s_per_wall_s": round(video / wall, 2), "with_startup": round(video / wall, 2),
                 "speedup_vs_1": "", "cpu_s_per_video_s": round(cpu / video, 3),
                 "load_avg": round(os.getloadavg()[0], 1)})

    def worker_cpu():
        import psutil

        t = psutil.Process().cpu_times()
        return t.user + t.system + t.children_user + t.children_system

    base = None
    for workers in (1, 2):
        t = time.perf_counter()
        with connect(workers=workers) as (client, _):
            client.run(lambda: __import__("lipsync.pipeline.clip"))
            startup = time.perf_counter() - t
            cpu0 = sum(client.run(worker_cpu).values())
            r = run_batch(manifest, tmp / f"batch-out-{workers}", scheduler=client.scheduler.address,
                          cache=str(cache), quiet=True)
            cpu = sum(client.run(worker_cpu).values()) - cpu0
        assert r.done == n, r.summary()
        tput = r.video_seconds / r.wall_seconds
        base = base or tput
        rows.append({"figure": "batch", "how": "lipsync batch, LocalCluster", "workers": workers, "clips": n,
                     "video_s": round(r.video_seconds, 1), "startup_s": round(startup, 2),
                     "wall_s": round(r.wall_seconds, 2), "video_s_per_wall_s": round(tput, 2),
                     "with_startup": round(r.video_seconds / (r.wall_seconds + startup), 2),
                     "speedup_vs_1": round(tput / base, 2), "cpu_s_per_video_s": round(cpu / r.video_seconds, 3),
                     "load_avg": round(os.getloadavg()[0], 1)})

    pack = pack_bank(default_bank_dir())
    flows = sorted((cache / "store" / "flows").glob("*.flow"))
    outs = [p.stat().st_size for p in (tmp / "batch-out-2").glob("*.mp4")]
    ins = [j.input.stat().st_size for j in jobs]
    rows.append({"figure": "batch_bytes", "bank_pack_bytes": pack.nbytes, "flow_entries": len(flows),
                 "flow_bytes": sum(p.stat().st_size for p in flows), "cold_first_batch_s": round(cold, 1),
                 "input_bytes_per_clip": int(np.mean(ins)), "output_bytes_per_clip": int(np.mean(outs)),
                 "output_bytes_per_video_s": int(sum(outs) / max(video, 1e-9))})


@FIGURES.decorator("batch")
def _batch(ctx: Context, rows: List[dict]) -> None:
    bench_batch(rows, ctx.tmp, ctx.quick)
