"""Face figures (``face``): landmark tracking speed and accuracy on real footage.

1. Speed, one core: decoding a video (the bundled ffmpeg), detection alone, one mesh
   inference, and tracking every frame of GRID's 360×288 clips (:data:`lipsync.bench.grid.BANK_CLIPS`,
   30 s) in frames per second of this thread's CPU time and of wall time; the same at
   1280×720 (the clips scaled up 2.5× and pillarboxed, written to an H.264 file, so decoding
   is real too).
2. Accuracy against an independent model: dlib's 68-point shape predictor, when dlib and
   its model are installed (``pip install dlib-bin face_recognition_models``: every fifth frame
   of all 40 clips), else the stored reference of the test clips
   (``tests/data/grid-s1/dlib68.json``). Mean and 95th percentile distance of the 20 lip
   points over the inter-ocular distance (dlib's outer eye corners), and the correlation of
   the two models' lip openings.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import List

import numpy as np

from . import FIGURES, Context, median_ms
from . import grid

#: dlib's lip points and the mesh points at the same places (as in tests/test_face.py).
DLIB_TO_MESH = {48: 61, 49: 40, 50: 37, 51: 0, 52: 267, 53: 270, 54: 291, 55: 321, 56: 314, 57: 17,
                58: 84, 59: 91, 60: 78, 61: 81, 62: 13, 63: 311, 64: 308, 65: 402, 66: 14, 67: 178}


def _speed(name: str, videos: List[Path], rows: List[dict], ctx: Context) -> None:
    from ..face.landmarks import FaceMesh, Roi
    from ..face.track import track_frames
    from ..face.video import probe_video, read_video

    mesh = FaceMesh()
    t0, c0 = time.perf_counter(), time.thread_time()
    clips = [list(read_video(v)) for v in videos]
    decode_wall, decode_cpu = time.perf_counter() - t0, time.thread_time() - c0
    n = sum(len(c) for c in clips)
    frame = clips[0][len(clips[0]) // 2]
    pts = mesh.find(frame)
    roi = Roi.from_landmarks(pts)
    reps = 20 if ctx.quick else 100
    det_ms = median_ms(lambda: mesh.detect(frame), reps, clock=time.thread_time)
    mesh_ms = median_ms(lambda: mesh.landmarks_in(frame, roi), reps, clock=time.thread_time)
    t0, c0 = time.perf_counter(), time.thread_time()
    for c, v in zip(clips, videos):
        track_frames(c, fps=probe_video(v).fps, mesh=mesh)
    wall, cpu = time.perf_counter() - t0, time.thread_time() - c0
    w, h = probe_video(videos[0]).size
    rows.append({"figure": "face", "case": f"speed {name} ({w}x{h}, {n} frames)",
                 "track_fps_cpu": round(n / cpu), "track_fps_wall": round(n / wall),
                 "detect_ms": round(det_ms, 2), "mesh_ms": round(mesh_ms, 2),
                 "decode_fps_wall": round(n / decode_wall), "decode_cpu_s_this_thread": round(decode_cpu, 2)})


def _upscaled(videos: List[Path], tmp: Path) -> List[Path]:
    """The clips at 1280×720: 2.5× (900×720) pillarboxed, H.264 at high quality."""
    import cv2
    import imageio_ffmpeg

    from ..face.video import read_video

    out = []
    for v in videos:
        p = tmp / f"{v.stem}-720p.mp4"
        gen = imageio_ffmpeg.write_frames(str(p), (1280, 720), fps=25, codec="libx264", pix_fmt_out="yuv420p",
                                          output_params=["-crf", "16", "-preset", "veryfast"], macro_block_size=1)
        gen.send(None)
        for f in read_video(v):
            big = cv2.resize(f, (900, 720), interpolation=cv2.INTER_CUBIC)
            gen.send(np.ascontiguousarray(cv2.copyMakeBorder(big, 0, 0, 190, 190, cv2.BORDER_CONSTANT, value=0)))
        gen.close()
        out.append(p)
    return out


def _reference(ctx: Context):
    """(source description, {clip: (frames, points)})."""
    try:
        import dlib  # noqa: F401
        import face_recognition_models  # noqa: F401
    except ImportError:
        path = Path(__file__).resolve().parents[2] / "tests" / "data" / "grid-s1" / "dlib68.json"
        data = json.loads(path.read_text())["videos"]
        return (f"stored dlib reference, {len(data)} test clips",
                {Path(k).stem: (v["frames"], v["points"]) for k, v in data.items()})
    import importlib.util
    import sys

    tool = Path(__file__).resolve().parents[2] / "tools" / "dlib_reference.py"
    spec = importlib.util.spec_from_file_location("dlib_reference", tool)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["dlib_reference"] = mod
    spec.loader.exec_module(mod)
    names = grid.clips()[:8] if ctx.quick else grid.clips()
    every = 5
    data = mod.reference([grid.video(c) for c in names], every)
    return (f"dlib 68-point predictor run now, every {every}th frame of {len(names)} clips",
            {Path(k).stem: (v["frames"], v["points"]) for k, v in data.items()})


def _accuracy(ctx: Context, rows: List[dict]) -> None:
    source, ref = _reference(ctx)
    errs, ours, theirs = [], [], []
    for clip, (frames, points) in ref.items():
        tr = grid.track(clip) if (grid.grid_dir() / f"{clip}.mpg").is_file() else None
        if tr is None:
            continue
        for f, p in zip(frames, points):
            if not tr.found[f]:
                continue
            p = np.asarray(p, float)
            m = tr.points[f, :, :2]
            iod = np.linalg.norm(p[36] - p[45])
            errs += [np.linalg.norm(p[d] - m[i]) / iod for d, i in DLIB_TO_MESH.items()]
            ours.append(np.linalg.norm(m[13] - m[14]) / iod)
            theirs.append(np.linalg.norm(p[62] - p[66]) / iod)
    rows.append({"figure": "face", "case": f"lips vs {source} ({len(ours)} frames)",
                 "lip_err_mean_iod": round(float(np.mean(errs)), 4),
                 "lip_err_p95_iod": round(float(np.percentile(errs, 95)), 4),
                 "opening_corr": round(float(np.corrcoef(ours, theirs)[0, 1]), 3)})


@FIGURES.decorator("face")
def face_figures(ctx: Context, rows: List[dict]) -> None:
    videos = [grid.video(c) for c in (grid.BANK_CLIPS[:3] if ctx.quick else grid.BANK_CLIPS)
              if grid.video(c).is_file()] or [grid.video(c) for c in grid.clips()]
    _speed("GRID", videos, rows, ctx)
    _speed("GRID scaled up", _upscaled(videos[:3], ctx.tmp), rows, ctx)
    _accuracy(ctx, rows)
