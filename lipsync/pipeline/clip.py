r"""One clip end to end: a timeline (or audio) and a bank in, a video, animation or PNG frames out.

The stages in order (DESIGN.md), shared by ``lipsync render``, ``lipsync batch`` and
``lipsync serve`` so that every entry point makes the same file from the same inputs::

    Bank.load -> FlowStore -> Animator (read, map, sequence) -> preprocess (missing flows)
    -> Renderer frames -> Compositor (body, background) -> open_writer (ffmpeg)
    -> OUT (renamed into place when complete)

Examples
--------
>>> import os, tempfile
>>> from lipsync.pipeline.clip import render_clip
>>> d = tempfile.mkdtemp()
>>> tl = os.path.join(d, "a.tsv")
>>> _ = open(tl, "w").write("0.00\tX\n0.20\tD\n0.60\tX\n")
>>> report = render_clip(tl, os.path.join(d, "frames"), format="png", quiet=True)
>>> report.frames, sorted(os.listdir(os.path.join(d, "frames")))[:2]
(15, ['frame_000000.png', 'frame_000001.png'])
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from typing import Optional, Union

from ..motion.frames import DEFAULT_FPS  # noqa: F401  (the one default frame rate; clip.DEFAULT_FPS kept)  # noqa: F401  (the one default frame rate; clip.DEFAULT_FPS kept)

PathLike = Union[str, "os.PathLike[str]"]

#: crf 18 is visually lossless for drawn faces.
DEFAULT_CRF = 18
#: "talking-head" (lipsync.encode.X264_PRESETS: ultrafast's analysis plus CABAC, B-frames
#: and the macroblock tree) replaced "veryfast" once frames reached ffmpeg as yuv420p and
#: encoding became half of the CPU time. `lipsync render` of the 26.7 s benchmark clip,
#: flows cached, 2 cores, best of 3 (wall s / CPU s / MB, with the 192 kb/s AAC track):
#:
#: ==============  ==================  ==================  ==================
#: clip            veryfast            ultrafast           talking-head
#: ==============  ==================  ==================  ==================
#: face 512x512    2.48 / 4.00 / 0.46  2.22 / 3.41 / 1.45  2.17 / 3.39 / 0.52
#: face 1280x720   6.50 / 11.4 / 0.94  5.53 / 9.47 / 5.77  5.10 / 8.81 / 0.81
#: ==============  ==================  ==================  ==================
#:
#: With a renderer three times faster (emulated: every third frame rendered, the others
#: copied) encoding dominates: 512x512 0.98 -> 0.73 s, 1280x720 3.39 -> 2.36 s to render
#: and encode.
DEFAULT_PRESET = "talking-head"
#: x264 threads inside `lipsync render` on a machine of this many cores or fewer: one.
#: The render threads already fill the cores, and x264's frame threads add lookahead and
#: synchronisation work: 2 cores, talking-head, emulated 3x renderer: 1 thread 0.73 s /
#: 2.36 s (512x512 / 1280x720) against 0.76 / 2.50 with x264's default (3 threads) and
#: 0.78 / 2.56 with 2. Not measured on more cores, where x264 keeps its own default.
SINGLE_ENCODER_THREAD_CORES = 2


@dataclass(frozen=True)
class ClipReport:
    """What :func:`render_clip` made.

    Attributes
    ----------
    output : str
        The file or folder written.
    frames : int
        Frames rendered.
    fps : float
        Frame rate.
    size : (int, int)
        Width and height.
    method : str
        Renderer method.
    seconds_setup, seconds_render : float
        Wall time loading and sequencing (and computing missing flows), then rendering and
        encoding.
    """

    output: str
    frames: int
    fps: float
    size: tuple
    method: str
    seconds_setup: float
    seconds_render: float

    @property
    def duration(self) -> float:
        """Seconds of video."""
        return self.frames / self.fps

    def summary(self) -> str:
        """One line for people: frames, size, method, speed."""
        w, h = self.size
        rt = self.duration / max(self.seconds_render, 1e-9)
        return (f"wrote {self.output}: {self.frames} frames ({self.duration:.2f} s at {self.fps:g} fps), "
                f"{w}x{h}, {self.method}; rendered and encoded in {self.seconds_render:.2f} s "
                f"({rt:.1f}x real time), total {self.seconds_setup + self.seconds_render:.2f} s")


# Overlap with ffmpeg, on 2 cores (both busy, so total CPU decides). With an emulated 3x
# faster frame kernel, a 1 MB pipe buffer instead of Linux's 64 KB, 1, 2 or 3 render
# threads and dropping +faststart (the moov rewrite of a <1 MB file) all stayed within
# run-to-run noise (+-0.05 s at 512x512, +-0.1 s at 1280x720). With the real compiled
# kernel, writing a held frame again instead of rendering it (half the frames of speech)
# and converting to yuv420p on the render threads took render + encode of the 26.7 s
# drawn-face clip from 2.55-2.61 to 2.31 s at 1280x720 (0.79 to 0.75 s at 512x512).
#: Frames rendered ahead of the encoder. A few are enough to keep both busy; each is one
#: frame of memory (0.8 MB at 512x512), so memory stays flat however long the clip.
QUEUE_FRAMES = 8


def render_parallel(render_into, n: int, shape, write, *, threads: Optional[int] = None, progress=None,
                    prepare=None, same_as_previous=None, initial=None) -> None:
    """Render frames ``0..n-1`` on worker threads and ``write`` them in order from this one.

    ``render_into(i, buf)`` fills ``buf`` (a ``shape`` uint8 array) with frame i; it must be
    safe to call from several threads (the renderer's kernels release the GIL, so threads
    render in parallel). At most :data:`QUEUE_FRAMES` frames are in flight, each in its own
    buffer, so memory stays flat; writing (a pipe to ffmpeg, which encodes on its own
    threads) overlaps rendering. An error on either side stops both and is raised here.

    ``prepare(buf, previous)``, if given, runs on the worker right after the frame is
    rendered and turns it into what ``write`` receives (a writer's
    :meth:`~lipsync.encode.Writer.prepare`: colour conversion, compression), so that work
    is parallel too; ``previous`` is that slot's last result, to reuse as its buffer.
    ``same_as_previous(i)``, if given, tells that frame i equals frame i - 1: it is not
    rendered again, the previous result is written again (a held mouth shape costs only
    the write). ``progress(done)``, if given, is called after each frame is written.
    ``initial``, if given, is what every buffer holds before its first frame (a composite's
    canvas: frames then only write the mouth's rectangle).
    """
    from concurrent.futures import ThreadPoolExecutor

    import numpy as np

    threads = max(1, int(threads or os.cpu_count() or 1))
    depth = max(QUEUE_FRAMES, 2 * threads)
    # frames that need rendering: the first, and every one that differs from its predecessor
    fresh = [i for i in range(n) if i == 0 or same_as_previous is None or not same_as_previous(i)]
    free = [[np.empty(shape, np.uint8) if initial is None else initial.copy(), None]
            for _ in range(min(depth + 1, len(fresh)))]
    pending = {}

    def job(i, slot):
        render_into(i, slot[0])
        if prepare is not None:
            slot[1] = prepare(slot[0], slot[1])
        return slot

    with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="lipsync-render") as ex:
        try:
            nxt = 0          # next entry of `fresh` to submit
            current = None   # the slot of the last frame written: kept while it repeats
            for i in range(n):
                # `current` is out of `free` while it may repeat; with two or more slots a frame
                # still to render always finds one (everything before it has been written)
                while nxt < len(fresh) and free:
                    pending[fresh[nxt]] = ex.submit(job, fresh[nxt], free.pop())
                    nxt += 1
                if i in pending:
                    if current is not None:
                        free.append(current)
                    current = pending.pop(i).result()
                write(current[0] if prepare is None else current[1])
                if progress is not None:
                    progress(i + 1)
        finally:
            for fut in pending.values():
                fut.cancel()


def render_clip(timeline, output: PathLike, *, bank=None, audio: Optional[PathLike] = None,
                fps: float = DEFAULT_FPS, map=None, method: str = "flow", timing=None,
                format: Optional[str] = None, crf: int = DEFAULT_CRF, preset: str = DEFAULT_PRESET,
                store=None, jobs: Optional[int] = None, quiet: bool = False,
                timeline_options=None, progress=None, background=None, composite=None,
                lang: Optional[str] = None, live=None, still: bool = False,
                plate_start: Optional[float] = None, samples=None) -> ClipReport:
    """Render one clip to ``output`` (a video, an animation, or a folder of numbered PNGs).

    Parameters
    ----------
    timeline : Timeline or path-like
        Any timeline the readers understand (see :func:`lipsync.read_timeline`).
    output : path-like
        The video (.mp4, .webm, .mov, ...), animation (.webp, .gif) or PNG folder; written
        under a temporary name and renamed when complete, so a failure or Ctrl-C leaves
        nothing there.
    bank : Bank or path-like, optional
        The subject (default: the shipped toon).
    audio : path-like, optional
        Speech to mux (formats with a sound track: mp4, webm, mov). Default: ``timeline``
        itself when it is an audio file.
    fps, map, method, timing
        As for :class:`lipsync.Animator`.
    format : str, optional
        A :data:`lipsync.encode.ENCODERS` name (default: from ``output``).
    crf, preset
        x264 quality, and speed preset (x264's, or one of
        :data:`lipsync.encode.X264_PRESETS`).
    store : FlowStore or path-like, optional
        Flow store (default: the bank's own). Missing flows are computed first.
    jobs : int, optional
        Processes for computing missing flows.
    quiet : bool
        No progress bars.
    timeline_options : object, optional
        Reader options (attributes ``timeline_format``, ``tier``, ``sample_rate``,
        ``moho_fps``, ``text``, ``lang``) when ``timeline`` is a path.
    progress : callable, optional
        ``progress(done, total)`` after each frame is rendered (``lipsync serve`` reports
        job progress with it).
    background : str, colour tuple or image, optional
        Flatten transparency onto this (``--background``: a colour or an image file).
        Formats without alpha (mp4) are flattened anyway, onto the body or white.
    composite : lipsync.composite.Composite or False, optional
        The body the mouth is drawn on (default: the bank's ``composite:``); False renders
        the mouth alone.
    lang : str, optional
        Language of audio input and its transcript (BCP 47; default English): see
        :func:`lipsync.speech.align.align`. Overrides ``timeline_options.lang``.
    live : float or True, optional
        Render what a live session fed the audio in real time shows
        (:func:`lipsync.pipeline.liveclip.live_specs`; ``timeline`` must be audio): the audio
        look-ahead in seconds, or True for the default.
    still : bool
        Render the bank's still pictures even when it has an idle plate (bank.yaml
        ``plate:``, banks made from video): by default each frame's lower face is
        composited onto the plate frame due at that time (:mod:`lipsync.composite.plate`),
        so the speaker blinks and moves.
    plate_start : float, optional
        Seconds into the idle plate where the clip starts (default: derived from the
        timeline, :class:`lipsync.Animator`'s ``plate_start``; with ``live``, 0, where a
        :class:`lipsync.LiveAnimator` starts by default).
    samples : {None, "on", "off"} or bool
        A bank with mouth samples shows a selected real sample per frame on its plate
        (:mod:`lipsync.pipeline.samplepath`); ``"off"``: one picture per viseme morphed, as
        before; None: bank.yaml's ``samples:`` says.

    Returns
    -------
    ClipReport
    """
    from tqdm import tqdm

    from .._data import default_bank_dir
    from .animator import Animator
    from ..banks.bank import Bank
    from ..composite import Compositor
    from ..encode import ENCODERS, format_for, open_writer
    from ..encode.mp4 import check_preset
    from ..errors import InputError
    from ..morphing.preprocess import all_pairs, preprocess
    from ..morphing.store import FlowStore
    from .._files import refuse_output_over_input

    refuse_output_over_input([output], [p for p in (timeline, audio, getattr(timeline_options, "text", None))
                                        if isinstance(p, (str, os.PathLike))])
    t0 = time.perf_counter()
    if lang is not None:
        import types

        given = vars(timeline_options) if timeline_options is not None else {}
        timeline_options = types.SimpleNamespace(**{**given, "lang": lang})
    if not 0 <= crf <= 51:
        raise InputError(f"--crf must be 0..51, got {crf}")
    check_preset(preset)  # before any work, whatever the format (ffmpeg said so only after it)
    out_format = format or format_for(output)  # an unknown extension fails before any work
    alpha_out = bool(ENCODERS.get(out_format).alpha)
    if isinstance(background, str):
        background = load_background(background)
    if not isinstance(bank, Bank):
        bank = Bank.load(bank or default_bank_dir())
    if composite is None:
        composite = bank.composite
    compositor = Compositor((bank.shape[0], bank.shape[1]), bank.channels, composite=composite or None,
                            background=background, alpha_out=alpha_out)
    if compositor.flattened:
        import warnings

        warnings.warn(f"{output}: {out_format} has no alpha channel; the bank's transparency is flattened onto "
                      f"{'the body' if composite else 'white'} (--background COLOR|IMAGE picks another; "
                      f"webm, mov, png, webp and gif keep alpha)", stacklevel=2)
    if not isinstance(store, FlowStore):
        store = FlowStore.for_bank(bank, store)
    if audio is None and out_format != "png" and not hasattr(timeline, "segments"):
        from ..readers.audio import is_audio_input

        if is_audio_input(timeline, getattr(timeline_options, "timeline_format", None)):
            audio = timeline  # speech in: its own sound is the soundtrack
    if live is not None:
        from .liveclip import LiveClip

        anim = LiveClip(bank, timeline, fps=fps, lookahead=None if live is True else live, map=map,
                        method=method, timing=timing, store=store, quiet=quiet,
                        still=still or not compositor.passthrough, plate_start=plate_start or 0.0,
                        samples=samples)
    else:
        # the idle plate (a bank made from video) only where the frame is the bank's picture itself
        anim = Animator(bank, timeline, fps=fps, map=map, method=method, timing=timing, store=store,
                        timeline_options=timeline_options, still=still or not compositor.passthrough,
                        plate_start=plate_start, samples=samples, audio=audio)
    n = len(anim)
    if n == 0:  # a video needs a frame; a timeline of no length has none to show (README: Rendering)
        where = getattr(timeline, "path", None) if hasattr(timeline, "segments") else os.fspath(timeline)
        raise InputError("the timeline lasts 0 s: there is no frame to render (a video needs at least one)",
                         path=where)
    if method in ("flow", "splat"):
        # Only when an entry is missing: checking all of them (a CRC pass over every pair)
        # would cost more than rendering a short clip. A damaged entry is still caught --
        # when the renderer maps it -- and recomputed there with a warning.
        nb = anim.renderer.nb
        if any(not store.pair_path(store.pair_key(bank, a, b, nb.axis)).exists() for a, b in all_pairs(bank.names)):
            preprocess(bank, store=store, jobs=jobs, quiet=quiet, normalised=nb)
    h, w = compositor.shape
    t1 = time.perf_counter()
    # beier-neely keeps whole-frame scratch in the renderer: one thread; the rest are thread-safe
    threads = 1 if anim.renderer.method == "beier-neely" else None
    anim.renderer.frame_threads = 1  # whole frames run in parallel instead
    encoder_threads = 1 if (os.cpu_count() or 1) <= SINGLE_ENCODER_THREAD_CORES else None
    if compositor.passthrough:
        render_into = lambda i, buf: anim.frame(i, out=buf)  # noqa: E731 - straight into the buffer
    else:
        import threading

        import numpy as np

        scratch = threading.local()  # each render thread its own mouth frame

        def render_into(i, buf):
            mouth = getattr(scratch, "frame", None)
            if mouth is None:
                mouth = scratch.frame = np.empty(anim.renderer.shape + (anim.renderer.channels,), np.uint8)
            compositor.apply(anim.frame(i, out=mouth), buf)
    with open_writer(output, fps=fps, size=(w, h), format=out_format, audio=audio,
                     crf=crf, preset=preset, quiet=True, frames=n or None,
                     threads=encoder_threads, channels=compositor.channels) as writer:
        with tqdm(total=n, desc="render", unit="frame", disable=quiet, leave=False) as bar:
            def on_frame(done: int) -> None:
                bar.update(1)
                if progress is not None:
                    progress(done, n)

            render_parallel(render_into, n, (h, w, compositor.channels), writer.write_prepared,
                            threads=threads, progress=on_frame, prepare=writer.prepare,
                            same_as_previous=anim.same_as_previous, initial=compositor.initial)
    t2 = time.perf_counter()
    return ClipReport(output=str(output), frames=len(anim), fps=float(fps), size=(w, h), method=method,
                      seconds_setup=t1 - t0, seconds_render=t2 - t1)


def write_video(frames, output: PathLike, *, fps: Optional[float] = None, audio: Optional[PathLike] = None,
                format: Optional[str] = None, crf: int = DEFAULT_CRF, preset: str = DEFAULT_PRESET,
                background=(255, 255, 255), quiet: bool = True) -> str:
    r"""Write frames to a video, an animation or a folder of PNGs, in one call.

    The frames' size and channels come from the first frame. The file is written under a
    temporary name and renamed when complete: an exception (or Ctrl-C) while the frames are
    produced leaves nothing at ``output``.

    Parameters
    ----------
    frames : Animator or iterable of numpy.ndarray
        An :class:`lipsync.Animator` (its frames, at its frame rate), or ``uint8`` frames
        ``(H, W, 3)`` RGB or ``(H, W, 4)`` RGBA, all of one size.
    output : path-like
        ``.mp4`` (also ``.m4v``, ``.mkv``), ``.webm``, ``.mov``, ``.webp``, ``.gif``, or a
        folder (``"frames/"``) for numbered PNGs; see :data:`lipsync.encode.ENCODERS`.
    fps : float, optional
        Frames per second (default: the Animator's, else 25).
    audio : path-like, optional
        Sound to mux (mp4, webm, mov), padded or cut to the video's length.
    format : str, optional
        An encoder name, when ``output``'s extension does not say it.
    crf, preset
        x264 quality and speed (mp4), as for :func:`render_clip`.
    background : colour, optional
        RGBA frames written to a format without alpha (mp4) are flattened onto this
        ``(r, g, b)`` (default white).
    quiet : bool
        No progress counter (the default).

    Returns
    -------
    str
        ``output``.

    Raises
    ------
    ValueError
        No frames, or frames that are not ``uint8`` ``(H, W, 3|4)`` of one size.

    Examples
    --------
    >>> import os, tempfile
    >>> from lipsync import Animator, read_timeline, write_video
    >>> d = tempfile.mkdtemp()
    >>> tl = os.path.join(d, "a.tsv")
    >>> _ = open(tl, "w").write("0.00\tX\n0.20\tD\n0.60\tX\n")
    >>> anim = Animator("toon", read_timeline(tl), fps=25)
    >>> out = write_video(anim, os.path.join(d, "hello.mp4"))
    >>> os.path.getsize(out) > 1000
    True
    """
    import numpy as np

    from ..encode import format_for, has_alpha, open_writer

    if hasattr(frames, "frames") and hasattr(frames, "specs"):  # an Animator
        fps = frames.fps if fps is None else fps
        count = len(frames)
        frames = frames.frames(copy=False)
    else:
        count = len(frames) if hasattr(frames, "__len__") else None
        fps = DEFAULT_FPS if fps is None else fps
    it = iter(frames)
    first = next(it, None)
    if first is None:
        raise ValueError(f"{output}: no frames to write")
    first = np.asarray(first)
    if first.dtype != np.uint8 or first.ndim != 3 or first.shape[2] not in (3, 4):
        raise ValueError(f"{output}: frames must be uint8 arrays (H, W, 3) or (H, W, 4), "
                         f"got {first.dtype} {first.shape}")
    h, w, channels = first.shape
    name = format or format_for(output)
    flatten = channels == 4 and not has_alpha(name)
    if flatten:
        from ..morphing.alpha import flatten as flatten_onto

    def frames_out():
        yield first
        yield from it

    with open_writer(output, fps=fps, size=(w, h), format=name, audio=audio, crf=crf, preset=preset,
                     quiet=quiet, total=count, frames=count, channels=3 if flatten else channels) as writer:
        for frame in frames_out():
            writer.write(flatten_onto(frame, background) if flatten else frame)
    return os.fspath(output)


# --------------------------------------------------------------------------- options

def load_background(spec: str):
    """``--background``: a colour (``white``, ``#rrggbb``, ``r,g,b``) or an image file.

    Examples
    --------
    >>> load_background("#00ff00")
    (0, 255, 0)
    """
    from ..morphing.alpha import parse_colour
    from ..errors import InputError

    colour = parse_colour(spec)
    if colour is not None:
        return colour
    if not os.path.isfile(spec):
        raise InputError("--background is neither a colour (a name, #rrggbb or r,g,b) nor an image file",
                         path=spec)
    from pathlib import Path

    from ..banks.bank import read_image

    return read_image(Path(spec))


def composite_from_options(bank_composite, *, over=None, at=None, scale: Optional[float] = None):
    """The composite ``lipsync render --over IMAGE --at X,Y --scale S`` asks for: each option
    replaces that part of the bank's own ``composite:`` (if it has one).

    Examples
    --------
    >>> import numpy as np
    >>> from lipsync.composite import Composite
    >>> body = np.zeros((50, 50, 3), np.uint8)
    >>> composite_from_options(Composite(body, (10.0, 10.0)), at="20,30").at
    (20.0, 30.0)
    >>> composite_from_options(None) is None
    True
    """
    from pathlib import Path

    from ..composite import Composite, check_placement, parse_at
    from ..errors import InputError

    if over is None and at is None and scale is None:
        return bank_composite
    if over is None and bank_composite is None:
        raise InputError("--at and --scale place the mouth on a body: give the body image with --over IMAGE "
                         "(or a composite: block in bank.yaml)")
    xy = parse_at(at) if isinstance(at, str) else at
    if over is not None:
        from ..banks.bank import read_image

        path = Path(over)
        if not path.is_file():
            raise InputError("--over: body image not found", path=path)
        image = read_image(path)
        if xy is None:
            if bank_composite is None:
                raise InputError("--over needs --at X,Y: the body pixel where the mouth's centre goes", path=path)
            xy = bank_composite.at
        c = Composite(image, (float(xy[0]), float(xy[1])), 1.0 if scale is None and bank_composite is None
                      else (scale if scale is not None else bank_composite.scale), path)
    else:
        c = bank_composite.replace(at=None if xy is None else (float(xy[0]), float(xy[1])), scale=scale)
    problem = check_placement(c.image.shape, c.at, c.scale)
    if problem:
        raise InputError(f"--over/--at/--scale: {problem}", path=c.path)
    return c
