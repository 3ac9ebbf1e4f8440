"""``lipsync render``: a timeline file to an mp4 (with the speech audio) or a PNG sequence."""

from __future__ import annotations

import argparse
import sys
import time

from .encode import ENCODERS
from .render import METHODS
from .timeline_cli import add_timeline_options

#: 25 fps is PAL video's rate and enough for lips (Rhubarb needs >= 24 for hard cuts;
#: morphs look smooth well below that, so lower rates are allowed).
DEFAULT_FPS = 25.0
#: crf 18 is visually lossless for drawn faces; "veryfast" keeps encoding well ahead of
#: real time on two cores at 512x512 (the flat colours compress well at any preset).
DEFAULT_CRF = 18
DEFAULT_PRESET = "veryfast"


def add_parser(sub) -> None:
    p = sub.add_parser("render", help="render a timeline to an mp4 (or PNG frames)",
                       description="Read a phoneme or viseme timeline, map it to visemes, sequence it and "
                                   "render every frame by morphing along the cached flows.")
    p.add_argument("timeline", metavar="TIMELINE", help="timeline file (.phn, .TextGrid, Gentle .json, "
                                                        "Rhubarb .tsv/.json/.xml, Moho .dat, Audacity .txt)")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output .mp4, or a folder for PNG frames")
    p.add_argument("--bank", default=None, metavar="DIR", help="viseme bank folder (default: the shipped toon)")
    p.add_argument("--audio", default=None, metavar="FILE", help="speech audio to mux (wav, flac, mp3, ...)")
    p.add_argument("--fps", type=float, default=DEFAULT_FPS, metavar="N", help="frames per second (default: 25)")
    p.add_argument("--method", choices=METHODS.names(), default="flow",
                   help="in-between method (default: flow)")
    p.add_argument("--format", choices=ENCODERS.names(), default=None,
                   help="output format (default: from OUT: a folder or no extension -> png, .mp4 -> mp4)")
    p.add_argument("--crf", type=int, default=DEFAULT_CRF, help=f"H.264 quality, lower is better (default: {DEFAULT_CRF})")
    p.add_argument("--preset", default=DEFAULT_PRESET, help=f"x264 speed preset (default: {DEFAULT_PRESET})")
    p.add_argument("--store", default=None, metavar="DIR", help="flow store folder (default: BANK/.lipsync)")
    p.add_argument("--jobs", "-j", type=int, default=None, help="processes for preprocessing (default: all cores)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bars or summary")
    add_timeline_options(p)
    p.set_defaults(func=run)


#: Frames rendered ahead of the encoder. A few are enough to keep both busy; each is one
#: frame of memory (0.8 MB at 512x512), so memory stays flat however long the clip.
QUEUE_FRAMES = 8


def write_overlapped(frames, write) -> None:
    """Feed ``frames`` to ``write`` from a second thread, so rendering overlaps encoding.

    Writing blocks while ffmpeg encodes; OpenCV, numpy and the pipe write all release the
    GIL, so the renderer keeps working meanwhile. Frames are copied into a ring of
    :data:`QUEUE_FRAMES` buffers (the renderer reuses its own). An error in the writer
    stops the renderer and is re-raised here; an error in the renderer stops the writer.
    """
    import queue
    import threading

    import numpy as np

    q: "queue.Queue" = queue.Queue(maxsize=QUEUE_FRAMES - 2)
    free: "queue.Queue" = queue.Queue()
    failure: list = []
    stop = threading.Event()

    def consume():
        try:
            while True:
                buf = q.get()
                if buf is None:
                    return
                write(buf)
                free.put(buf)
        except BaseException as exc:  # handed to the main thread
            failure.append(exc)
            stop.set()

    worker = threading.Thread(target=consume, name="lipsync-encode", daemon=True)
    worker.start()

    def hand_over(item) -> bool:
        # put, but give up if the writer has died (its queue would never drain)
        while worker.is_alive():
            try:
                q.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    made = 0
    try:
        for frame in frames:
            if stop.is_set():
                break
            buf = None
            while buf is None and not stop.is_set():
                try:
                    buf = free.get(timeout=0.1) if made >= QUEUE_FRAMES else free.get_nowait()
                except queue.Empty:
                    if made < QUEUE_FRAMES:
                        buf = np.empty_like(frame)
                        made += 1
            if buf is None or not hand_over(np.copyto(buf, frame) or buf):
                break
    finally:
        hand_over(None)
        worker.join()
    if failure:
        raise failure[0]


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from ._data import default_bank_dir
    from .animator import Animator
    from .bank import Bank
    from .encode import format_for, open_writer
    from .errors import InputError
    from .preprocess import preprocess
    from .store import FlowStore

    t0 = time.perf_counter()
    if not 0 <= args.crf <= 51:
        raise InputError(f"--crf must be 0..51, got {args.crf}")
    out_format = args.format or format_for(args.output)  # an unknown extension fails before any work
    bank = Bank.load(args.bank or default_bank_dir())
    store = FlowStore.for_bank(bank, args.store)
    anim = Animator(bank, args.timeline, fps=args.fps, map=args.map, method=args.method, timing=args.timing,
                    store=store, timeline_options=args)
    if args.method in ("flow", "splat"):
        preprocess(bank, store=store, jobs=args.jobs, quiet=args.quiet, normalised=anim.renderer.nb)
    h, w = anim.renderer.shape
    t1 = time.perf_counter()
    with open_writer(args.output, fps=args.fps, size=(w, h), format=out_format, audio=args.audio,
                     crf=args.crf, preset=args.preset, quiet=True) as writer:
        frames = tqdm(anim.frames(copy=False), total=len(anim), desc="render", unit="frame",
                      disable=args.quiet, leave=False)
        write_overlapped(frames, writer.write)
    t2 = time.perf_counter()
    if not args.quiet:
        seconds = len(anim) / args.fps
        print(f"wrote {args.output}: {len(anim)} frames ({seconds:.2f} s at {args.fps:g} fps), "
              f"{w}x{h}, {args.method}; rendered and encoded in {t2 - t1:.2f} s "
              f"({seconds / max(t2 - t1, 1e-9):.1f}x real time), total {t2 - t0:.2f} s", file=sys.stderr)
    return 0
