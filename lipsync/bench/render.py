"""Speed figures of the renderer (registered in :data:`lipsync.bench.FIGURES`):

1. one Beier-Neely field (30 random lines) at 512x512 and 1280x720: ms and peak extra
   memory of :func:`lipsync.morphing.warp.beier_neely_map` against a naive full-broadcast numpy
   version of the same formulas; the speed-up from symmetric halving;
2. ms per frame of each render method on the default subject at 512x512 and scaled to
   1280x720; beier-neely / flow; flow against a plain memory copy of the bytes a flow
   frame reads and writes (two images and two flows in, one frame out);
3. ``lipsync render`` end to end (render + H.264/AAC encode) of the 26.7 s MFA recording
   as a multiple of real time, flows cached, at 512x512 and 1280x720;
4. flow store bytes per field pixel;
5. whole-frame motion (a drawn face, 30 lines on its features, no anchors, b = 2) at
   512x512 and 1280x720: flow frame against the classic Beier-Neely frame and against a
   memory copy of the same bytes, on one core; first-frame latency of an untouched pair;
   ``lipsync render`` of the MFA recording; store bytes per field pixel;
6. x264 presets: wall time and file size of the same ``lipsync render``.

"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
import time
import sys
from pathlib import Path
from typing import Dict, List

import numpy as np

from .._data import default_bank_dir
from . import FIGURES, Context, median_ms, peak_mb


def naive_beier_neely_map(shape, dst, src, a=1.0, b=2.0, p=0.5) -> np.ndarray:
    """DESIGN.md's formulas broadcast over (lines, H, W) at once: the obvious numpy version."""
    h, w = shape
    dst = np.asarray(dst, np.float64)[:, :, :, None, None]
    src = np.asarray(src, np.float64)[:, :, :, None, None]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    P, Q, Ps, Qs = dst[:, 0], dst[:, 1], src[:, 0], src[:, 1]
    e, es = Q - P, Qs - Ps
    dx, dy = xs - P[:, 0], ys - P[:, 1]
    len2 = e[:, 0] ** 2 + e[:, 1] ** 2
    length = np.sqrt(len2)
    u = (dx * e[:, 0] + dy * e[:, 1]) / len2
    v = (dx * -e[:, 1] + dy * e[:, 0]) / length
    lens = np.sqrt(es[:, 0] ** 2 + es[:, 1] ** 2)
    xp = Ps[:, 0] + u * es[:, 0] + v * -es[:, 1] / lens
    yp = Ps[:, 1] + u * es[:, 1] + v * es[:, 0] / lens
    dist = np.where(u < 0, np.hypot(dx, dy), np.where(u > 1, np.hypot(xs - Q[:, 0], ys - Q[:, 1]), np.abs(v)))
    weight = (length ** p / (a + dist)) ** b
    wsum = weight.sum(axis=0)
    out = np.empty((h, w, 2), np.float32)
    out[..., 0] = xs + (weight * (xp - xs)).sum(axis=0) / wsum
    out[..., 1] = ys + (weight * (yp - ys)).sum(axis=0) / wsum
    return out


def _random_symmetric_lines(shape, n, rng):
    """``n`` lines mirror-symmetric about the image's centre column (pairs plus one on the axis)."""
    h, w = shape
    axis = (w - 1) / 2
    half = rng.uniform([0.1 * w, 0.1 * h], [0.48 * w, 0.9 * h], size=((n - 1) // 2, 2, 2))
    mirror = half.copy()
    mirror[..., 0] = 2 * axis - mirror[..., 0]
    lines = [half, mirror]
    if n % 2:
        lines.append(np.array([[[axis, 0.2 * h], [axis, 0.8 * h]]]))
    out = np.concatenate(lines)
    names = [f"l{i}_l" for i in range(len(half))] + [f"l{i}_r" for i in range(len(half))] + ["mid"] * (n % 2)
    return out, names, axis


def bench_field(rows: List[dict], quick: bool) -> None:
    from ..banks.bank import WarpParams
    from ..morphing.flows import flow_field
    from ..morphing.warp import beier_neely_displacement, beier_neely_map

    rng = np.random.default_rng(0)
    for shape in ((512, 512), (720, 1280)):
        dst, names, axis = _random_symmetric_lines(shape, 30, rng)
        src = dst + rng.normal(0, 3, dst.shape)
        src_sym = dst.copy()
        src_sym[: len(dst) // 2, :, 1] += 3.0  # symmetric motion: move each pair the same way
        src_sym[len(dst) // 2 : 2 * (len(dst) // 2), :, 1] += 3.0
        rep = 3 if quick else 7
        ms = median_ms(lambda: beier_neely_map(shape, dst_lines=dst, src_lines=src), rep)
        # the compiled field's portable path and numba's copy (installs without the extension)
        plain_ms = median_ms(lambda: beier_neely_displacement(shape, dst_lines=dst, src_lines=src, kernel="plain"), rep)
        numba_ms = median_ms(lambda: beier_neely_displacement(shape, dst_lines=dst, src_lines=src, kernel="numba"), rep)
        mem = peak_mb(lambda: beier_neely_map(shape, dst_lines=dst, src_lines=src))
        naive_ms = median_ms(lambda: naive_beier_neely_map(shape, dst, src), 1 if quick else 3, warmup=0)
        naive_mem = peak_mb(lambda: naive_beier_neely_map(shape, dst, src))
        w = WarpParams()
        full_ms = median_ms(lambda: flow_field(shape, dst, src_sym, w), rep)
        half_ms = median_ms(lambda: flow_field(shape, dst, src_sym, w, axis=axis), rep)
        px = shape[0] * shape[1]
        rows.append({
            "figure": "beier_neely_field", "size": f"{shape[1]}x{shape[0]}", "lines": 30,
            "ms": round(ms, 1), "ns_per_pixel_line": round(ms * 1e6 / px / 30, 2), "peak_mb": round(mem, 1),
            "plain_path_ms": round(plain_ms, 1), "numba_ms": round(numba_ms, 1),
            "naive_ms": round(naive_ms, 1), "naive_peak_mb": round(naive_mem, 1),
            "speedup_vs_naive": round(naive_ms / ms, 1), "memory_ratio": round(mem / naive_mem, 4),
            "symmetric_full_ms": round(full_ms, 1), "symmetric_half_ms": round(half_ms, 1),
            "halving_speedup": round(full_ms / half_ms, 2),
        })


def _scaled_bank(src_dir: Path, out_dir: Path, size) -> Path:
    """The default subject placed on a ``size`` = (W, H) canvas (scaled to its height)."""
    import cv2
    import yaml

    spec = yaml.safe_load((src_dir / "bank.yaml").read_text())
    W, H = size
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, v in spec["visemes"].items():
        img = cv2.imread(str(src_dir / v["image"]))
        s = H / img.shape[0]
        img = cv2.resize(img, (round(img.shape[1] * s), H), interpolation=cv2.INTER_CUBIC)
        pad = (W - img.shape[1]) // 2
        img = cv2.copyMakeBorder(img, 0, 0, pad, W - img.shape[1] - pad, cv2.BORDER_REPLICATE)
        cv2.imwrite(str(out_dir / v["image"]), img)
        # pixel centres: x' = (x + 0.5) * s - 0.5 + pad keeps the mirror axis on the centre
        v["lines"] = {n: [[(x + 0.5) * s - 0.5 + pad, (y + 0.5) * s - 0.5] for x, y in line]
                      for n, line in v["lines"].items()}
        # the wider canvas needs its own frame anchors, as the subject has at its edges
        v["lines"]["canvas_side_l"] = [[4.0, 0.05 * H], [4.0, 0.95 * H]]
        v["lines"]["canvas_side_r"] = [[W - 5.0, 0.05 * H], [W - 5.0, 0.95 * H]]
    (out_dir / "bank.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
    return out_dir


#: Mouth half-width, half-height and jaw drop (in face heights) of the bench face per
#: Rhubarb shape: X rest, A closed (M B P), B slightly open, C open, D wide open, E rounded,
#: F puckered (OO), G teeth on lip (F V), H tongue (L).
FACE_MOUTHS = {"X": (0.085, 0.008, 0.0), "A": (0.080, 0.004, 0.0), "B": (0.095, 0.020, 0.01),
               "C": (0.100, 0.040, 0.025), "D": (0.105, 0.065, 0.045), "E": (0.075, 0.045, 0.03),
               "F": (0.050, 0.035, 0.02), "G": (0.090, 0.015, 0.005), "H": (0.095, 0.045, 0.035)}


def face_bank(folder: Path, size) -> Path:
    """A drawn face with 30 control lines on its features only (no anchors), b = 2.

    Whole-frame motion: without lines at the frame's edges, Beier-Neely weights (1/dist^2)
    let the moving mouth and jaw drag every pixel, as on a photo subject whose lines sit on
    the features. Nine visemes (Rhubarb's shapes), mirror-symmetric about the centre column.
    """
    import cv2
    import yaml

    W, H = size
    cx, s = (W - 1) / 2.0, 0.8 * H            # axis, face height
    top = 0.1 * H
    folder.mkdir(parents=True, exist_ok=True)

    def P(x, y):  # face coordinates (x from the axis, y from the top, in face heights) -> pixels
        return [cx + x * s, top + y * s]

    def mirror(name, p, q):
        (x0, y0), (x1, y1) = p, q
        return {f"{name}_l": [P(-x0, y0), P(-x1, y1)], f"{name}_r": [P(x0, y0), P(x1, y1)]}

    visemes = {}
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    for name, (mw, mh, jaw) in FACE_MOUTHS.items():
        img = np.empty((H, W, 3), np.float32)
        img[:] = (np.linspace(90, 160, H)[:, None, None] * np.array([0.6, 0.8, 1.0]))  # backdrop (RGB)
        # texture, so any misplaced pixel shows (static: it moves only where the warp says)
        img += (12 * np.sin(xx / 7.0) * np.cos(yy / 9.0))[..., None]
        mouth_y = 0.74 + jaw / 2
        chin_y = 0.98 + jaw
        layers = []
        head = (((xx - cx) / (0.36 * s)) ** 2 + ((yy - top - 0.5 * s) / (0.5 * s)) ** 2) <= 1
        jawmask = (((xx - cx) / (0.32 * s)) ** 2 + ((yy - top - 0.62 * s) / ((chin_y - 0.62) * s)) ** 2) <= 1
        layers.append((head | jawmask, (225, 180, 150)))
        for sx in (-1, 1):
            ex = cx + sx * 0.14 * s
            layers.append(((((xx - ex) / (0.06 * s)) ** 2 + ((yy - top - 0.38 * s) / (0.025 * s)) ** 2) <= 1,
                           (250, 250, 250)))
            layers.append((((xx - ex) ** 2 + (yy - top - 0.38 * s) ** 2) <= (0.018 * s) ** 2, (60, 40, 30)))
            layers.append(((np.abs(xx - ex) <= 0.07 * s) & (np.abs(yy - top - 0.30 * s) <= 0.008 * s),
                           (90, 60, 40)))
        layers.append(((np.abs(xx - cx) <= 0.02 * s + (yy - top - 0.42 * s) * 0.15)
                       & (yy >= top + 0.42 * s) & (yy <= top + 0.6 * s), (200, 150, 125)))
        lips = (((xx - cx) / ((mw + 0.012) * s)) ** 2 + ((yy - top - mouth_y * s) / ((mh + 0.012) * s)) ** 2) <= 1
        inner = (((xx - cx) / (mw * s)) ** 2 + ((yy - top - mouth_y * s) / (mh * s)) ** 2) <= 1
        layers.append((lips, (170, 70, 80)))
        layers.append((inner, (70, 20, 30)))
        layers.append((inner & (yy <= top + (mouth_y - mh + 0.02) * s), (240, 240, 235)))  # teeth
        for mask, colour in layers:
            # soft edges: blur the mask a little so shapes are anti-aliased
            m = cv2.GaussianBlur(mask.astype(np.float32), (0, 0), 0.7)[..., None]
            img = img * (1 - m) + m * np.array(colour, np.float32)
        img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        cv2.imwrite(str(folder / f"{name}.png"), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
        lines = {"brow_mid": [P(-0.05, 0.28), P(0.05, 0.28)], "nose_bridge": [P(0, 0.40), P(0, 0.58)],
                 "nose_base": [P(-0.05, 0.61), P(0.05, 0.61)], "mouth_width": [P(-mw, mouth_y), P(mw, mouth_y)],
                 "mouth_height": [P(0, mouth_y - mh - 0.012), P(0, mouth_y + mh + 0.012)],
                 "chin": [P(-0.08, chin_y - 0.01), P(0.08, chin_y - 0.01)],
                 "forehead": [P(-0.1, 0.08), P(0.1, 0.08)], "philtrum": [P(0, 0.63), P(0, mouth_y - mh - 0.02)]}
        lines.update(mirror("brow", (0.08, 0.30), (0.2, 0.29)))
        lines.update(mirror("eye_top", (0.09, 0.375), (0.19, 0.375)))
        lines.update(mirror("eye_bottom", (0.09, 0.39), (0.19, 0.39)))
        lines.update(mirror("nostril", (0.03, 0.6), (0.055, 0.57)))
        k = np.sqrt(0.5)
        lines.update(mirror("upper_lip", (mw + 0.012, mouth_y), (k * mw, mouth_y - k * mh - 0.012)))
        lines.update(mirror("lower_lip", (mw + 0.012, mouth_y), (k * mw, mouth_y + k * mh + 0.012)))
        lines.update(mirror("jaw", (0.30, 0.75), (0.12, chin_y - 0.03)))
        lines.update(mirror("cheek", (0.33, 0.45), (0.31, 0.65)))
        lines.update(mirror("temple", (0.33, 0.15), (0.35, 0.35)))
        lines.update(mirror("ear", (0.37, 0.4), (0.37, 0.55)))
        lines.update(mirror("crown", (0.1, 0.02), (0.28, 0.08)))
        assert len(lines) == 30
        visemes[name] = {"image": f"{name}.png",
                         "lines": {n: [[float(v) for v in p], [float(v) for v in q]] for n, (p, q) in lines.items()}}
    spec = {"name": f"face{W}x{H}", "rest": "X", "warp": {"a": 1.0, "b": 2.0, "p": 0.5}, "symmetry": True,
            "visemes": visemes}
    (folder / "bank.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
    return folder


def bench_methods(rows: List[dict], banks: Dict[str, Path], quick: bool) -> None:
    from ..banks.bank import Bank
    from ..morphing.preprocess import preprocess
    from ..morphing.render import METHODS, Renderer
    from ..morphing.store import FlowStore

    pairs = [("X", "D"), ("A", "C"), ("B", "F"), ("E", "H")]
    for label, path in banks.items():
        bank = Bank.load(path)
        store = FlowStore.for_bank(bank)
        preprocess(bank, store=store, quiet=True)
        row = {"figure": "frame", "size": label, "lines": len(bank.line_names)}
        for method in METHODS.names() + ["flow-numba"]:
            # flow-numba: the flow method on the portable kernel, beside the compiled one
            kernel = "numba" if method == "flow-numba" else None
            r = Renderer(bank, method=method.replace("-numba", ""), store=store, kernel=kernel)
            alphas = np.linspace(0.1, 0.9, 3 if (quick or method == "beier-neely") else 9)

            def frames():
                for a, b in pairs:
                    for al in alphas:
                        r.render(a, b, float(al))

            frames()  # warm-up: pair states and buffers
            n = len(pairs) * len(alphas)
            row[f"{method}_ms"] = round(median_ms(frames, 1 if method == "beier-neely" else 3, warmup=0) / n, 3)
        # the bytes one flow frame reads and writes: two images and two flows in, one frame out
        img = bank.images[bank.names[0]]
        flows = store.get_pair(bank, "X", "D")
        f16 = [np.zeros(img.shape[:2] + (2,), np.float16) for _ in flows]
        srcs = [img, img.copy()] + f16
        dsts = [np.empty_like(s) for s in srcs]
        out = np.empty_like(img)

        def copy_bytes():
            for s, d in zip(srcs, dsts):
                np.copyto(d, s)
            np.copyto(out, img)

        row["memcpy_ms"] = round(median_ms(copy_bytes, 50), 3)
        row["beier_neely_over_flow"] = round(row["beier-neely_ms"] / row["flow_ms"], 1)
        row["flow_over_memcpy"] = round(row["flow_ms"] / row["memcpy_ms"], 1)
        row["numba_over_flow"] = round(row["flow-numba_ms"] / row["flow_ms"], 2)
        rows.append(row)


def bench_end_to_end(rows: List[dict], banks: Dict[str, Path], timeline: Path, audio: Path) -> None:
    import wave

    with wave.open(str(audio)) as wf:
        seconds = wf.getnframes() / wf.getframerate()
    for label, path in banks.items():
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "out.mp4"
            cmd = [sys.executable, "-m", "lipsync", "render", str(timeline), "--audio", str(audio), "--bank",
                   str(path), "-o", str(out), "--quiet"]
            subprocess.run(cmd, check=True)  # warm: flows cached, files in the page cache
            before = _children_cpu()
            t = time.perf_counter()
            subprocess.run(cmd, check=True)
            wall = time.perf_counter() - t
            cpu = _children_cpu() - before
        # CPU seconds (lipsync and its ffmpeg) tell the cost when other work shares the
        # cores and the wall time does not
        rows.append({"figure": "end_to_end", "size": label, "audio_s": round(seconds, 2), "wall_s": round(wall, 2),
                     "x_real_time": round(seconds / wall, 1), "cpu_s": round(cpu, 2),
                     "audio_s_per_cpu_s": round(seconds / cpu, 1)})


def _children_cpu() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _own_and_children_cpu() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime + _children_cpu()


def bench_store(rows: List[dict], banks: Dict[str, Path]) -> None:
    from ..banks.bank import Bank
    from ..morphing.preprocess import all_pairs
    from ..morphing.store import FlowStore

    for label, path in banks.items():
        bank = Bank.load(path)
        store = FlowStore.for_bank(bank)
        flows = sorted((store.root / "flows").glob("*.flow"))
        n_fields = 2 * len(all_pairs(bank.names))
        total = sum(p.stat().st_size for p in flows)
        h, w = bank.shape
        rows.append({"figure": "store", "size": label, "entries": len(flows),
                     "bytes": total, "bytes_per_field_pixel": round(total / (n_fields * h * w), 3),
                     "float32_full_bytes_per_field_pixel": 8})


def _toon_banks(ctx: Context) -> Dict[str, Path]:
    """The default subject at 512x512 and scaled to 1280x720, made once per run."""
    banks = {"512x512": ctx.tmp / "toon512", "1280x720": ctx.tmp / "toon720"}
    if not banks["512x512"].exists():
        shutil.copytree(default_bank_dir(), banks["512x512"], ignore=shutil.ignore_patterns(".lipsync"))
        _scaled_bank(default_bank_dir(), banks["1280x720"], (1280, 720))
    return banks


@FIGURES.decorator("beier_neely_field")
def _field(ctx: Context, rows: List[dict]) -> None:
    bench_field(rows, ctx.quick)


@FIGURES.decorator("frame")
def _frame(ctx: Context, rows: List[dict]) -> None:
    bench_methods(rows, _toon_banks(ctx), ctx.quick)


@FIGURES.decorator("end_to_end")
def _end_to_end(ctx: Context, rows: List[dict]) -> None:
    audio = ctx.mfa / "acoustic_corpus.wav"
    if audio.exists():
        bench_end_to_end(rows, _toon_banks(ctx), ctx.mfa / "acoustic_corpus.TextGrid", audio)


@FIGURES.decorator("store")
def _store(ctx: Context, rows: List[dict]) -> None:
    bench_store(rows, _toon_banks(ctx))


# --------------------------------------------------------------------------- whole-frame motion

def _face_banks(ctx: Context) -> Dict[str, Path]:
    """The drawn face (30 lines on the features, no anchors) at 512x512 and 1280x720."""
    banks = {"512x512": ctx.tmp / "face512", "1280x720": ctx.tmp / "face720"}
    for label, size in (("512x512", (512, 512)), ("1280x720", (1280, 720))):
        if not banks[label].exists():
            face_bank(banks[label], size)
    return banks


def _preprocessed(path: Path):
    from ..banks.bank import Bank
    from ..morphing.preprocess import preprocess
    from ..morphing.store import FlowStore

    bank = Bank.load(path)
    store = FlowStore.for_bank(bank)
    t = time.perf_counter()
    report = preprocess(bank, store=store, quiet=True)
    return bank, store, (time.perf_counter() - t) if report.computed else None


def bench_whole_frame(rows: List[dict], banks: Dict[str, Path], quick: bool) -> None:
    """Flow frame vs classic Beier-Neely frame vs memory copy, one core, whole-frame motion."""
    import cv2

    from ..morphing.render import Renderer, available_kernels

    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)  # one core: the classic warp's cv2.remap would otherwise use both
    try:
        pairs = [("X", "D"), ("A", "C"), ("B", "F"), ("E", "H")]
        for label, path in banks.items():
            bank, store, prep_s = _preprocessed(path)
            out = np.empty(bank.shape + (3,), np.uint8)
            alphas = np.linspace(0.1, 0.9, 9)
            n_frames = len(pairs) * len(alphas)
            kernel_ms = {}
            for kernel in available_kernels():  # the default (fastest) first
                flow = Renderer(bank, store=store, kernel=kernel)
                flow.frame_threads = 1  # one core
                for a, b in pairs:  # warm-up: pair states, compiled kernels
                    flow.render(a, b, 0.5, out=out)

                def flow_frames(flow=flow):
                    for a, b in pairs:
                        for al in alphas:
                            flow.render(a, b, float(al), out=out)

                kernel_ms[kernel] = median_ms(flow_frames, 3 if quick else 7, warmup=0) / n_frames
                if kernel == available_kernels()[0]:
                    flow_ms = kernel_ms[kernel]
                    flow_cpu = median_ms(flow_frames, 3 if quick else 7, warmup=0, clock=time.thread_time) / n_frames
                    default = flow
            flow = default
            classic = Renderer(bank, method="beier-neely", store=store)
            bn_ms = median_ms(lambda: classic.render("X", "D", 0.4), 1 if quick else 3)
            bn_cpu = median_ms(lambda: classic.render("X", "D", 0.4), 1 if quick else 3, clock=time.thread_time)
            # the same bytes as a flow frame: two images and two float16 flows in, a frame out
            # (round one's definition), and the bytes this renderer really reads (two images,
            # four int16 tables per side on the coarse grid) and writes
            img = bank.images["X"]
            pair = flow._pair("X", "D")
            tables = [np.array(pair.inv_a.data), np.array(pair.inv_b.data)]
            f16 = [np.zeros(img.shape[:2] + (2,), np.float16) for _ in range(2)]
            srcs_round1 = [img, img.copy()] + f16
            srcs_now = [img, img.copy()] + tables
            copy = {}
            for name, srcs in (("round1", srcs_round1), ("now", srcs_now)):
                dsts = [np.empty_like(s) for s in srcs]
                frame = np.empty_like(img)

                def copy_bytes(srcs=srcs, dsts=dsts, frame=frame):
                    for s, d in zip(srcs, dsts):
                        np.copyto(d, s)
                    np.copyto(frame, img)

                copy[name] = median_ms(copy_bytes, 50)
                copy[name + "_cpu"] = median_ms(lambda: [copy_bytes() for _ in range(20)], 10,
                                                clock=time.thread_time) / 20
            # first frame of a pair nobody touched yet: load (map + CRC) and render
            first = []
            for a, b in (("C", "G"), ("D", "F"), ("G", "H"), ("B", "E"), ("A", "H")):
                fresh = Renderer(bank, store=store)
                fresh.frame_threads = 1
                fresh.render("X", "X", 0.0, out=out)
                t = time.perf_counter()
                fresh.render(a, b, 0.5, out=out)
                first.append((time.perf_counter() - t) * 1e3)
            roi = pair.roi
            rows.append({
                "figure": "whole_frame", "size": label, "lines": len(bank.line_names),
                "kernel": available_kernels()[0],
                "numba_kernel_ms": round(kernel_ms["numba"], 3),
                "numba_over_kernel": round(kernel_ms["numba"] / flow_ms, 2),
                # the 8-lane path, what CPUs without AVX-512 run (identical frames)
                "avx2_kernel_ms": round(kernel_ms["avx2"], 3) if "avx2" in kernel_ms else None,
                "moving_fraction": round((roi.y1 - roi.y0) * (roi.x1 - roi.x0) / (bank.shape[0] * bank.shape[1]), 2),
                "flow_ms": round(flow_ms, 3), "fps_one_core": round(1000.0 / flow_ms, 1),
                "beier_neely_ms": round(bn_ms, 1), "beier_neely_over_flow": round(bn_ms / flow_ms, 1),
                "memcpy_ms": round(copy["round1"], 3), "flow_over_memcpy": round(flow_ms / copy["round1"], 1),
                "memcpy_read_bytes_ms": round(copy["now"], 3),
                "flow_over_memcpy_read_bytes": round(flow_ms / copy["now"], 1),
                "cpu_flow_ms": round(flow_cpu, 3), "cpu_beier_neely_ms": round(bn_cpu, 1),
                "cpu_beier_neely_over_flow": round(bn_cpu / flow_cpu, 1),
                "cpu_memcpy_ms": round(copy["round1_cpu"], 3),
                "cpu_flow_over_memcpy": round(flow_cpu / copy["round1_cpu"], 1),
                "cpu_fps_one_core": round(1000.0 / flow_cpu, 1),
                "first_frame_ms": round(float(np.median(first)), 2),
                "preprocess_s": None if prep_s is None else round(prep_s, 1),
            })
    finally:
        cv2.setNumThreads(threads)


def bench_presets(rows: List[dict], banks: Dict[str, Path], timeline: Path, audio: Path, quick: bool) -> None:
    """x264 presets for ``lipsync render``: wall time and file size, same clip, flows cached."""
    from ..pipeline.clip import render_clip

    for label, path in banks.items():
        _preprocessed(path)
        for preset in ("talking-head", "ultrafast", "superfast", "veryfast"):
            with tempfile.TemporaryDirectory() as tmp:
                out = Path(tmp) / "out.mp4"
                walls, cpus = [], []
                for _ in range(1 if quick else 2):
                    c = _own_and_children_cpu()
                    t = time.perf_counter()
                    report = render_clip(timeline, out, bank=path, audio=audio, preset=preset, quiet=True)
                    walls.append(time.perf_counter() - t)
                    cpus.append(_own_and_children_cpu() - c)
                rows.append({"figure": "preset", "size": label, "preset": preset,
                             "wall_s": round(min(walls), 2), "x_real_time": round(report.duration / min(walls), 1),
                             "cpu_s": round(min(cpus), 2),
                             "mb": round(out.stat().st_size / 1e6, 2),
                             "kbit_s": round(out.stat().st_size * 8 / 1e3 / report.duration)})


@FIGURES.decorator("whole_frame")
def _whole_frame(ctx: Context, rows: List[dict]) -> None:
    bench_whole_frame(rows, _face_banks(ctx), ctx.quick)


@FIGURES.decorator("whole_frame_end_to_end")
def _whole_frame_end_to_end(ctx: Context, rows: List[dict]) -> None:
    audio = ctx.mfa / "acoustic_corpus.wav"
    if audio.exists():
        banks = _face_banks(ctx)
        for path in banks.values():
            _preprocessed(path)
        before = len(rows)
        bench_end_to_end(rows, banks, ctx.mfa / "acoustic_corpus.TextGrid", audio)
        for r in rows[before:]:
            r["figure"] = "whole_frame_end_to_end"


@FIGURES.decorator("whole_frame_store")
def _whole_frame_store(ctx: Context, rows: List[dict]) -> None:
    banks = _face_banks(ctx)
    for path in banks.values():
        _preprocessed(path)
    before = len(rows)
    bench_store(rows, banks)
    for r in rows[before:]:
        r["figure"] = "whole_frame_store"


@FIGURES.decorator("preset")
def _preset(ctx: Context, rows: List[dict]) -> None:
    audio = ctx.mfa / "acoustic_corpus.wav"
    if audio.exists():
        bench_presets(rows, _face_banks(ctx), ctx.mfa / "acoustic_corpus.TextGrid", audio, ctx.quick)
