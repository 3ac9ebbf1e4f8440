"""The ``lipsync edit-timeline`` server: the page, the recording, the edited timeline, frames and saves.

API (every ``/api/`` call needs the session token, as the query parameter ``token`` or the
header ``X-Lipsync-Token``; see :mod:`lipsync.web`):

``GET /api/timeline``
    ``{"words": [{"start", "end", "label"}], "phones": [...], "visemes": [...]}``: seconds
    (float; words and phones on whole frames at the editor's fps, visemes as the map splits
    them); silence is a gap (no segment).
``PUT /api/timeline`` with the same JSON
    Validated (:meth:`lipsync.timing_editor.model.TimingDoc.from_json`) and snapped to the
    frame grid → 200 with the timeline as stored; bad input → 400 ``{"error": reason}`` and
    the timeline unchanged. ``visemes`` left out or null: derived from the phones by the map.
``GET /api/frame?t=SECONDS``
    PNG of the bank's frame at that time for the edited viseme tier, the frame
    ``lipsync render`` shows at the same fps (RGBA for a transparent bank).
``POST /api/save?format=textgrid|pgo|rhubarb-tsv|rhubarb-json|moho``
    Writes OUT (``-o``; OUT with that format's extension beside it when OUT's extension is
    another's) atomically; an existing file there is kept as ``NAME.bak`` first →
    ``{"path": ...}``. 400 for an unknown format or a timeline the format cannot hold.
``POST /api/render``
    Renders the edited timeline with the audio to OUT's ``.mp4`` → ``{"path": ...}``.
``POST /api/retype`` with ``{"index": i, "label": "word"}``
    Word ``i`` retyped: its phones from the lexicon or ``--lang``'s letters-to-sounds,
    spread over the word → the new timeline (400 as for PUT).
``GET /api/info``
    ``{duration, fps, visemes, rest, audio, out, lang, version}``.
``GET /api/peaks``
    ``{rate, min, max}``: the waveform's extremes per 1/rate s, scaled to -127..127.
``GET /api/audio``
    The recording as 16 kHz mono WAV (what the page plays).
"""

from __future__ import annotations

import io
import json
import math
import os
import shutil
import threading
import wave
from pathlib import Path
from typing import Optional

import numpy as np

from ..errors import InputError
from ..web import Guard, Session
from .model import MAX_AUDIO_S, SAVE_FORMATS, Context, TimingDoc, load_doc, retype, save_text

STATIC = Path(__file__).resolve().parent / "static"
#: A timeline of an hour's phones as JSON is ~6 MB; 16 MiB bounds a request with room to spare.
MAX_BODY = 16 << 20
#: Waveform extremes per second sent to the page: 200 (5 ms) is finer than a pixel at the
#: closest zoom the page offers (1 px = 2 ms is not useful for lip sync; 5 ms is a tenth of a
#: phone) and an hour is 720 000 pairs, ~5 MB of JSON.
PEAK_RATE = 200
#: Frames kept rendered for the current timeline version (a 512x512 PNG is ~100 kB; the page
#: caches its own copies too).
FRAME_CACHE = 256
SAMPLE_RATE = 16000


class TimingEditor:
    """State of one ``lipsync edit-timeline`` run: the recording, the doc, the renderer.

    Parameters
    ----------
    audio : path-like
        The recording (any format ffmpeg reads, at most :data:`MAX_AUDIO_S` long).
    text : str, optional
        Its transcript (or a file holding it): the words are aligned.
    timeline : path-like, optional
        A timeline file to start from (TextGrid, .pgo, Rhubarb, any reader).
    lang : str, optional
        Language of the speech (BCP 47; default English).
    bank : path-like or Bank, optional
        The subject shown (default: the shipped toon).
    fps : float
        The frame grid and the preview's frame rate.
    out : path-like, optional
        Where saves go: OUT itself when its extension is the saved format's, else OUT with
        that extension; a folder gets ``NAME.edited.EXT`` in it (default: beside the audio).

    Examples
    --------
    >>> import os, tempfile
    >>> from lipsync._data import default_bank_dir
    >>> samples = os.path.join(os.path.dirname(default_bank_dir()), "..", "samples")
    >>> ed = TimingEditor(os.path.join(samples, "hello.wav"), timeline=os.path.join(samples, "hello.TextGrid"),
    ...                   out=tempfile.mkdtemp())
    >>> [w["label"] for w in ed.get()["words"]][:2], ed.frame(1.0).shape
    (['hello', 'i'], (512, 512, 3))
    >>> os.path.basename(ed.save("pgo"))
    'hello.edited.pgo'
    """

    def __init__(self, audio, *, text: Optional[str] = None, timeline=None, lang: Optional[str] = None,
                 bank=None, fps: float = 25.0, out=None, store=None, quiet: bool = True, map=None):
        from .._data import default_bank_dir
        from ..banks.bank import Bank
        from ..morphing.store import FlowStore
        from ..phonetics.phonemes import DEFAULT_MAP, load_map

        if text is not None and timeline is not None:
            raise InputError("give --text or --timeline, not both")
        self.audio = os.fspath(audio)
        self.pcm = load_pcm(self.audio)
        duration = len(self.pcm) / SAMPLE_RATE
        self.bank = bank if isinstance(bank, Bank) else Bank.load(bank or default_bank_dir())
        self.store = store if isinstance(store, FlowStore) else FlowStore.for_bank(self.bank, store)
        self.map = load_map(map or DEFAULT_MAP)
        self.context = Context(duration=duration, fps=float(fps), visemes=tuple(self.bank.names),
                               rest=self.bank.rest, pmap=self.map, lang=lang)
        self.inputs = {os.path.realpath(self.audio)}
        if timeline is not None:
            self.inputs.add(os.path.realpath(os.fspath(timeline)))
            self.doc = load_doc(duration, context=self.context, timeline=os.fspath(timeline))
        else:
            from ..speech.align import align

            self.alignment = align(self.pcm, text, quiet=quiet, lang=lang)
            self.doc = load_doc(duration, context=self.context, alignment=self.alignment)
        # OUT: where saves go (OUT.TextGrid, ...); a folder gets the audio's name in it
        folder = os.path.dirname(os.path.abspath(self.audio)) if out is None else os.fspath(out)
        self.out = os.path.join(folder, Path(self.audio).stem + ".edited") \
            if out is None or os.path.isdir(folder) else os.fspath(out)
        self.version = 1
        self._lock = threading.RLock()
        self._anim = None  # (version, Animator, Compositor)
        self._frames = {}  # (version, index) -> PNG bytes

    # ---------------------------------------------------------------- state
    def get(self) -> dict:
        with self._lock:
            return self.doc.to_json()

    def put(self, obj) -> dict:
        doc = TimingDoc.from_json(obj, context=self.context)  # InputError: nothing changes
        return self._set(doc)

    def retype(self, index, label) -> dict:
        if isinstance(index, bool) or not isinstance(index, int) or not isinstance(label, str):
            raise InputError('expected {"index": WORD_NUMBER, "label": "text"}')
        with self._lock:
            doc = retype(self.doc, index, label)
            return self._set(doc)

    def _set(self, doc: TimingDoc) -> dict:
        with self._lock:
            self.doc = doc
            self.version += 1
            self._frames.clear()
            return doc.to_json()

    def info(self) -> dict:
        c = self.context
        return {"duration": c.duration, "fps": c.fps, "visemes": list(c.visemes), "rest": c.rest,
                "audio": os.path.basename(self.audio), "out": self.out, "lang": c.lang, "version": self.version,
                "frames": self.frame_count(), "shape": list(self.bank.shape[:2])}

    def frame_count(self) -> int:
        """Frames ``lipsync render`` makes of the edited timeline at the editor's fps."""
        return len(self.animator()[1])

    # ---------------------------------------------------------------- frames
    def animator(self):
        """The Animator and compositor of the current version, as ``lipsync render`` builds them."""
        from ..composite import Compositor
        from ..pipeline.animator import Animator

        with self._lock:
            if self._anim is None or self._anim[0] != self.version:
                bank = self.bank
                # PNG output keeps alpha: the compositor lipsync render uses for a PNG folder
                comp = Compositor((bank.shape[0], bank.shape[1]), bank.channels, composite=bank.composite or None,
                                  background=None, alpha_out=True)
                anim = Animator(bank, self.doc.visemes, fps=self.context.fps, map=self.map, store=self.store,
                                still=not comp.passthrough)
                anim.renderer.frame_threads = 1
                self._anim = (self.version, anim, comp)
            return self._anim

    def frame_index(self, t: float) -> int:
        """The frame shown at ``t`` (as :meth:`lipsync.Animator.frame_at` picks it)."""
        n = self.frame_count()
        pos = t * self.context.fps
        return 0 if pos <= 0 else n - 1 if pos >= n else min(int(math.floor(pos + 1e-9)), n - 1)

    def frame(self, t: float) -> np.ndarray:
        """The RGB(A) frame at ``t`` seconds."""
        with self._lock:
            _, anim, comp = self.animator()
            i = min(self.frame_index(t), len(anim) - 1)
        # outside the lock: frames render in parallel (the animator is thread-safe, as
        # lipsync render's frame threads use it), so two requests use two cores
        frame = anim.frame(i)
        if comp.passthrough:
            return frame
        buf = np.empty(comp.shape + (comp.channels,), np.uint8)
        comp.apply(frame, buf)
        return buf

    def frame_png(self, t: float) -> bytes:
        """PNG of :meth:`frame` (cached per timeline version)."""
        import cv2

        with self._lock:
            key = (self.version, self.frame_index(t))
            png = self._frames.get(key)
        if png is not None:
            return png
        frame = self.frame(t)
        to_bgr = cv2.COLOR_RGBA2BGRA if frame.shape[2] == 4 else cv2.COLOR_RGB2BGR
        # Encoding is most of a request (a toon frame: render ~9 ms, PNG ~40 ms on this busy
        # 2-core machine). Level 1 with run-length matching was the fastest of levels 0-3 and
        # zlib's strategies measured (39 ms and 117 kB against 47 ms/124 kB for plain level 1,
        # 59 ms/107 kB for the default level 3); level 0 writes 790 kB for 26 ms.
        ok, buf = cv2.imencode(".png", cv2.cvtColor(frame, to_bgr),
                               [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE])
        png = buf.tobytes()
        with self._lock:
            if key[0] == self.version:
                if len(self._frames) >= FRAME_CACHE:
                    self._frames.pop(next(iter(self._frames)))
                self._frames[key] = png
        return png

    # ---------------------------------------------------------------- saving
    def target(self, ext: str) -> str:
        """OUT for a format of extension ``ext``: OUT itself when its extension is ``ext``."""
        base, own = os.path.splitext(self.out)
        return self.out if own.lower() == ext.lower() else (base if own.lower() in _KNOWN_EXTS else self.out) + ext

    def save(self, format: str) -> str:
        """Write the doc as ``format`` beside OUT atomically, the previous file kept as ``.bak``."""
        if format not in SAVE_FORMATS:
            raise InputError(f"unknown format {format!r} (valid: {', '.join(SAVE_FORMATS)})")
        path = self.target(SAVE_FORMATS[format][0])
        if os.path.realpath(path) in self.inputs:
            raise InputError(f"{path} is an input of this session: saving there would replace it "
                             f"(start with -o OTHER to save elsewhere)")
        with self._lock:
            doc = self.doc
        # Papagayo finds the sound relative to the project; Rhubarb's metadata names it in full
        sound = os.path.relpath(os.path.abspath(self.audio), os.path.dirname(os.path.abspath(path))) \
            if format == "pgo" else os.path.abspath(self.audio)
        return replace_keeping_backup(path, lambda tmp: save_text(doc, format, tmp, sound_file=sound))

    def render(self) -> str:
        """Render the edited timeline with the audio to OUT's ``.mp4`` (atomic, as ``lipsync render``)."""
        from ..pipeline.clip import render_clip

        path = self.target(".mp4")
        if os.path.realpath(path) in self.inputs:
            raise InputError(f"{path} is an input of this session: rendering there would replace it")
        with self._lock:
            visemes = self.doc.visemes
        return replace_keeping_backup(path, lambda tmp: render_clip(visemes, tmp, bank=self.bank, audio=self.audio,
                                                                     fps=self.context.fps, map=self.map,
                                                                     store=self.store, quiet=True, format="mp4"))

    def peaks(self) -> dict:
        step = SAMPLE_RATE // PEAK_RATE
        n = len(self.pcm) // step
        blocks = self.pcm[: n * step].reshape(n, step) if n else np.zeros((0, step), np.int16)
        lo = (blocks.min(axis=1).astype(np.int32) * 127) // 32768
        hi = (blocks.max(axis=1).astype(np.int32) * 127) // 32767
        return {"rate": PEAK_RATE, "min": lo.tolist(), "max": hi.tolist()}

    def wav(self) -> bytes:
        buf = io.BytesIO()
        with wave.open(buf, "wb") as w:
            w.setnchannels(1)
            w.setsampwidth(2)
            w.setframerate(SAMPLE_RATE)
            w.writeframes(self.pcm.astype("<i2").tobytes())
        return buf.getvalue()


_KNOWN_EXTS = {ext.lower() for ext, _ in SAVE_FORMATS.values()} | {".mp4"}


def load_pcm(path: str) -> np.ndarray:
    """16 kHz mono int16 samples of ``path``: InputError naming it when it is not audio,
    silent-empty, or longer than :data:`MAX_AUDIO_S`."""
    from ..speech.audio import load_audio

    # AudioError (an InputError naming the file) for a missing file or one that is not audio;
    # a 10-hour file is decoded no further than the bound (measured: refused after 9 s)
    pcm = load_audio(path, max_seconds=MAX_AUDIO_S + 1.0)
    if len(pcm) > MAX_AUDIO_S * SAMPLE_RATE:
        raise InputError(f"the recording is longer than the editor's limit of {MAX_AUDIO_S / 3600:g} hour "
                         f"(split it, or edit its timeline file directly)", path=path)
    if len(pcm) < SAMPLE_RATE // 100:
        raise InputError("the recording holds no sound (under 10 ms of audio)", path=path)
    return pcm


def replace_keeping_backup(path: str, produce) -> str:
    """Run ``produce(tmp)`` to write a complete file, then keep ``path``'s old content as
    ``path.bak`` and rename the new one into place: a failure leaves ``path`` as it was.

    Examples
    --------
    >>> import os, tempfile
    >>> p = os.path.join(tempfile.mkdtemp(), "a.txt")
    >>> _ = replace_keeping_backup(p, lambda tmp: open(tmp, "w").write("one"))
    >>> _ = replace_keeping_backup(p, lambda tmp: open(tmp, "w").write("two"))
    >>> open(p).read(), open(p + ".bak").read(), sorted(os.listdir(os.path.dirname(p)))
    ('two', 'one', ['a.txt', 'a.txt.bak'])
    """
    from .._files import partial_name, remove_stale_partials

    folder = os.path.dirname(os.path.abspath(path)) or "."
    os.makedirs(folder, exist_ok=True)
    remove_stale_partials(path)
    ext = os.path.splitext(path)[1]
    tmp = os.path.join(folder, partial_name(path) + "-" + os.urandom(4).hex() + ext)
    try:
        produce(tmp)
        if os.path.exists(path):
            bak = path + ".bak"
            shutil.copy2(path, bak + ".tmp")
            os.replace(bak + ".tmp", bak)
        os.replace(tmp, path)
    finally:
        for leftover in (tmp, path + ".bak.tmp"):
            if os.path.exists(leftover):
                os.unlink(leftover)
    return path


#: The page's Content-Security-Policy: lipsync.web's, plus media from this origin and blobs
#: (the page plays the recording from a blob, which seeks without Range requests).
CSP = ("default-src 'self'; img-src 'self' data: blob:; media-src 'self' blob:; style-src 'self'; "
       "script-src 'self'; connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'self'")


def _bad(message: str, status: int = 400):
    from starlette.responses import JSONResponse

    return JSONResponse({"error": message}, status_code=status)


async def _body_json(request):
    """(payload, None) or (None, a 400 response)."""
    try:
        return json.loads(await request.body()), None
    except (ValueError, RecursionError):
        return None, _bad("the request body must be JSON")


class _Api:
    """The request handlers over one :class:`TimingEditor` (module docstring: the API)."""

    def __init__(self, editor: TimingEditor):
        self.editor = editor
        self._peaks: Optional[bytes] = None
        self._wav: Optional[bytes] = None

    async def _call(self, fn, *args):
        """``fn(*args)`` in a worker thread as JSON; InputError -> 400, OSError -> 500."""
        from starlette.concurrency import run_in_threadpool
        from starlette.responses import JSONResponse

        try:
            return JSONResponse(await run_in_threadpool(fn, *args))
        except InputError as exc:
            return _bad(str(exc))
        except OSError as exc:
            return _bad(f"cannot write: {exc}", 500)

    async def index(self, request):
        from starlette.responses import FileResponse

        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    async def timeline(self, request):
        from starlette.responses import JSONResponse

        if request.method == "GET":
            return JSONResponse(self.editor.get())
        obj, err = await _body_json(request)
        return err or await self._call(self.editor.put, obj)

    async def retype(self, request):
        obj, err = await _body_json(request)
        if err:
            return err
        if not isinstance(obj, dict):
            return _bad('expected {"index": WORD_NUMBER, "label": "text"}')
        return await self._call(self.editor.retype, obj.get("index"), obj.get("label"))

    async def frame(self, request):
        from starlette.concurrency import run_in_threadpool
        from starlette.responses import Response

        try:
            t = float(request.query_params.get("t"))
        except (TypeError, ValueError):
            return _bad("t must be a time in seconds, e.g. /api/frame?t=1.25")
        if not math.isfinite(t) or t < 0 or t > self.editor.context.duration:
            return _bad(f"t must be within 0..{self.editor.context.duration:g} s")
        png = await run_in_threadpool(self.editor.frame_png, t)
        return Response(png, media_type="image/png",
                        headers={"Cache-Control": "no-store", "X-Lipsync-Version": str(self.editor.version),
                                 "X-Lipsync-Frame": str(self.editor.frame_index(t))})

    async def save(self, request):
        fmt = request.query_params.get("format", "")
        if fmt not in SAVE_FORMATS:
            return _bad(f"format must be one of {', '.join(SAVE_FORMATS)}")
        return await self._call(lambda: {"path": self.editor.save(fmt)})

    async def render(self, request):
        return await self._call(lambda: {"path": self.editor.render()})

    def info(self, request):
        from starlette.responses import JSONResponse

        return JSONResponse(self.editor.info())

    def peaks(self, request):
        from starlette.responses import Response

        if self._peaks is None:  # made once: the recording does not change
            self._peaks = json.dumps(self.editor.peaks()).encode()
        return Response(self._peaks, media_type="application/json")

    def audio(self, request):
        from starlette.responses import Response

        if self._wav is None:
            self._wav = self.editor.wav()
        return Response(self._wav, media_type="audio/wav")


def make_app(editor: TimingEditor, session: Session, *, max_body: int = MAX_BODY):
    """The Starlette app of the page and the API, wrapped in :class:`lipsync.web.Guard`.

    Examples
    --------
    >>> from starlette.testclient import TestClient
    >>> from lipsync._data import default_bank_dir
    >>> import os
    >>> wav = os.path.join(os.path.dirname(default_bank_dir()), "..", "samples", "hello.wav")
    >>> ed = TimingEditor(wav, text="Hello, I am a talking head made by lipsync.")
    >>> s = Session.open()
    >>> c = TestClient(make_app(ed, s), base_url=s.origin)
    >>> [w["label"] for w in c.get(s.url("/api/timeline")).json()["words"]][:3]
    ['hello', 'i', 'am']
    >>> s.close()
    """
    from starlette.applications import Starlette
    from starlette.routing import Mount, Route
    from starlette.staticfiles import StaticFiles

    api = _Api(editor)
    routes = [
        Route("/", api.index),
        Route("/index.html", api.index),
        Route("/api/timeline", api.timeline, methods=["GET", "PUT"]),
        Route("/api/retype", api.retype, methods=["POST"]),
        Route("/api/frame", api.frame),
        Route("/api/save", api.save, methods=["POST"]),
        Route("/api/render", api.render, methods=["POST"]),
        Route("/api/info", api.info),
        Route("/api/peaks", api.peaks),
        Route("/api/audio", api.audio),
        Mount("/static", app=StaticFiles(directory=STATIC)),
    ]
    return Guard(Starlette(routes=routes), session=session, max_body=max_body, csp=CSP)
