"""``lipsync serve``: rendering and live talking heads over HTTP and WebSocket (Starlette + uvicorn).

Routes (all but the page and its static files need the session token, see
:mod:`lipsync.web`, whose :class:`~lipsync.web.Guard` also refuses foreign Host and Origin
headers and bounds request bodies):

* ``GET /`` -- the demo page: plays ``samples/hello.wav`` and draws the live head on a canvas;
* ``GET /mic`` -- the microphone page: streams the microphone (AudioWorklet, 16-bit PCM) and
  shows the frames in step with the audio delayed by the look-ahead;
* ``POST /api/render?name=FILE[&text=...][&format=NAME][&fps=N][&lang=CODE]`` -- the body is a timeline
  or audio file; answers ``202 {"job": ID, ...}``; ``GET /api/jobs/ID`` reports state and
  progress, ``GET /api/jobs/ID/video`` gives the mp4;
* ``WS /ws/live`` -- a live session (:mod:`.protocol`): push events and the clock, get frames;
* ``GET /api/status`` -- sessions, frames sent, errors answered, threads (for monitoring);
* ``GET /api/demo`` -- the demo's events (the phones of ``samples/hello.phn``).

Examples
--------
>>> from starlette.testclient import TestClient
>>> from lipsync.web import Session
>>> server = LiveServer(ServeConfig(), session=Session.open())
>>> client = TestClient(server.app, base_url=server.session.origin)
>>> client.get("/api/status").status_code, client.get(server.session.url("/api/status")).json()["sessions"]
(403, 0)
>>> server.close()
"""

from __future__ import annotations

import asyncio
import os
import shutil
import tempfile
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from ..errors import InputError, check_number
from ..motion.frames import DEFAULT_FPS
from .jobs import DEFAULT_JOB_TIMEOUT_S, DEFAULT_MAX_CLIP_S

STATIC = Path(__file__).resolve().parent / "static"
SAMPLES = Path(__file__).resolve().parents[2] / "samples"

#: Live sessions at once. Each costs a frame schedule and two small buffers; rendering is
#: shared (one renderer per core), so more sessions only lower each one's frame rate.
DEFAULT_MAX_SESSIONS = 16
#: A session with no message for this long is closed: a client that vanished without
#: closing its socket must not hold a session slot for ever.
DEFAULT_IDLE_TIMEOUT_S = 60.0
#: Largest upload: a minute of 16-bit 48 kHz stereo WAV is ~11 MB; timelines are tiny.
DEFAULT_MAX_UPLOAD = 16 << 20
#: Largest WebSocket message: a push of MAX_EVENTS_PER_MESSAGE events is well under this.
WS_MAX_MESSAGE = 256 << 10
#: JPEG quality of live frames: 80 keeps flat drawn colours clean at ~20-40 kB per 512x512 frame.
DEFAULT_QUALITY = 80
#: Upper bounds of the numeric options, each far beyond use and below harm: sessions (each
#: holds a schedule and buffers), a day of idleness, uploads held in memory while read
#: (2 GB), renderer threads.
MAX_SESSIONS_LIMIT = 10_000
MAX_IDLE_TIMEOUT_S = 86400.0
MAX_UPLOAD_LIMIT = 2 << 30
MAX_WORKERS = 256
#: ... and a render job's clip length and running time (a day each).
MAX_CLIP_LIMIT_S = 86400.0
MAX_JOB_TIMEOUT_S = 86400.0


@dataclass(frozen=True)
class ServeConfig:
    """Everything ``lipsync serve`` is configured with (one frozen value, keyword-only).

    Examples
    --------
    >>> ServeConfig(max_sessions=2).max_sessions
    2
    """

    bank: Optional[str] = None
    store: Optional[str] = None
    map: Optional[str] = None
    timing: Optional[str] = None     # None: the bank's timing (bank.yaml), else the default curve
    method: str = "flow"
    fps: float = DEFAULT_FPS
    quality: int = DEFAULT_QUALITY
    max_sessions: int = DEFAULT_MAX_SESSIONS
    idle_timeout: float = DEFAULT_IDLE_TIMEOUT_S
    max_upload: int = DEFAULT_MAX_UPLOAD
    workers: Optional[int] = None
    quiet: bool = True
    max_clip_seconds: float = DEFAULT_MAX_CLIP_S
    job_timeout: float = DEFAULT_JOB_TIMEOUT_S
    samples: Optional[str] = None    # live sessions: a bank's mouth samples (None: bank.yaml), "on", "off"

    def __post_init__(self) -> None:
        # Every number checked here, once, for the CLI and the library alike: a NaN timeout
        # closed every session after its first message, a NaN upload limit was a traceback.
        from .protocol import FPS_CHOICES

        check_number(self.max_sessions, "--max-sessions", 1, MAX_SESSIONS_LIMIT, integer=True)
        check_number(self.idle_timeout, "--idle-timeout", 0, MAX_IDLE_TIMEOUT_S, lo_open=True)
        check_number(self.max_upload, "--max-upload", 1024, MAX_UPLOAD_LIMIT, integer=True)
        check_number(self.quality, "--quality", 10, 100, integer=True)
        check_number(self.max_clip_seconds, "--max-clip-seconds", 0, MAX_CLIP_LIMIT_S, lo_open=True)
        check_number(self.job_timeout, "--job-timeout", 0, MAX_JOB_TIMEOUT_S, lo_open=True)
        if self.workers is not None:
            check_number(self.workers, "--workers", 1, MAX_WORKERS, integer=True)
        if self.fps not in FPS_CHOICES:
            raise InputError(f"--fps must be one of {', '.join(map(str, FPS_CHOICES))}, got {self.fps!r}")


class LiveServer:
    """The app of ``lipsync serve`` and what it owns: bank, renderers, threads, temp folder.

    ``app`` is the guarded ASGI app; :meth:`close` releases everything (the job folder
    included). Build it with a :class:`lipsync.web.Session` (bound socket and token).
    """

    def __init__(self, config: ServeConfig, *, session):
        from .._data import default_bank_dir
        from ..banks.bank import Bank
        from ..live import RendererPool
        from ..phonetics.phonemes import DEFAULT_MAP, load_map
        from ..morphing.preprocess import preprocess
        from ..morphing.store import FlowStore
        from ..web import Guard
        from .jobs import Jobs

        self.config = config
        self.session = session
        self.bank = Bank.load(config.bank or default_bank_dir())
        self.store = FlowStore.for_bank(self.bank, config.store)
        self.pmap = load_map(config.map or DEFAULT_MAP)
        workers = max(1, config.workers or os.cpu_count() or 1)
        self.pool = RendererPool(self.bank, method=config.method, store=self.store, size=workers)
        if self.pool.method in ("flow", "splat"):
            # every flow now, so that no live frame waits seconds for a missing one
            preprocess(self.bank, store=self.store, quiet=config.quiet, normalised=self.pool.nb)
        from ..live.pool import shared_plate

        # the idle plate of a bank made from video, decoded once: every session composites
        # onto it (held here, so sessions coming and going do not decode it again)
        self.plate = shared_plate(self.bank)
        from ..live.samples import samples_wanted, shared_samples
        from ..phonetics.phonemes import check_map_against

        # ... and its mouth samples, decoded and made ready for selection once (sessions
        # share them; each keeps only its own path)
        samples_wanted(config.samples)
        self.samples = None if self.plate is None else shared_samples(
            self.bank, config.samples, self.pmap.renamed(check_map_against(self.pmap, self.bank.names)), self.store)
        self.executor = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="lipsync-live")
        self.tmp = Path(tempfile.mkdtemp(prefix="lipsync-serve-"))
        self.jobs = Jobs(self.tmp, bank=self.bank, store=self.store, fps=config.fps, map=config.map,
                         timing=config.timing, method=config.method, max_clip_seconds=config.max_clip_seconds,
                         job_timeout=config.job_timeout, samples=config.samples)
        self.sessions: set = set()
        self.stats = {"frames": 0, "errors": 0, "sessions_total": 0, "refused_sessions": 0}
        self.app = Guard(self._routes(), session=session, max_body=config.max_upload,
                         public=("/", "/index.html", "/mic", "/favicon.ico", "/static/"))
        self._closed = False

    # ------------------------------------------------------------------ app
    def _routes(self):
        from starlette.applications import Starlette
        from starlette.responses import FileResponse, JSONResponse, Response
        from starlette.routing import Mount, Route, WebSocketRoute
        from starlette.staticfiles import StaticFiles

        from ..motion.sequencer import check_fps
        from .jobs import Busy

        async def page(request):
            return FileResponse(STATIC / "index.html", media_type="text/html")

        async def mic(request):
            return FileResponse(STATIC / "mic.html", media_type="text/html")

        async def status(request):
            return JSONResponse({"sessions": len(self.sessions), "max_sessions": self.config.max_sessions,
                                 "threads": threading.active_count(), **self.stats})

        async def demo(request):
            events = await asyncio.get_running_loop().run_in_executor(None, _demo_events)
            if events is None:
                return JSONResponse({"error": "samples/hello.phn is not installed"}, status_code=404)
            return JSONResponse({"audio": "/demo/hello.wav", "events": events, "fps": self.config.fps})

        async def demo_audio(request):
            wav = SAMPLES / "hello.wav"
            if not wav.is_file():
                return JSONResponse({"error": "samples/hello.wav is not installed"}, status_code=404)
            return FileResponse(wav, media_type="audio/wav")

        async def render(request):
            q = request.query_params
            body = await request.body()
            try:
                # as `lipsync render --fps` checks it (fps=0 once rendered at the default 25)
                fps = check_fps(q["fps"]) if "fps" in q else None
                job = self.jobs.submit(body, q.get("name", ""), text=q.get("text"),
                                       timeline_format=q.get("format"), fps=fps, lang=q.get("lang"))
            except (InputError, ValueError) as exc:
                return JSONResponse({"error": str(exc)}, status_code=400)
            except Busy as exc:
                return JSONResponse({"error": str(exc)}, status_code=503)
            return JSONResponse(job.as_json(), status_code=202)

        async def job_state(request):
            job = self.jobs.get(request.path_params["job"])
            if job is None:
                return JSONResponse({"error": "no such job"}, status_code=404)
            return JSONResponse(job.as_json())

        async def job_video(request):
            job = self.jobs.get(request.path_params["job"])
            path = self.jobs.video(job) if job is not None else None
            if path is None:
                return JSONResponse({"error": "no such finished job"}, status_code=404)
            return FileResponse(path, media_type="video/mp4", filename=Path(job.name).stem + ".mp4")

        async def favicon(request):
            return Response(status_code=204)

        return Starlette(routes=[
            Route("/", page), Route("/index.html", page), Route("/mic", mic), Route("/favicon.ico", favicon),
            Mount("/static", app=StaticFiles(directory=STATIC), name="static"),
            Route("/api/status", status), Route("/api/demo", demo), Route("/demo/hello.wav", demo_audio),
            Route("/api/render", render, methods=["POST"]),
            Route("/api/jobs/{job:str}", job_state), Route("/api/jobs/{job:str}/video", job_video),
            WebSocketRoute("/ws/live", self._live),
        ])

    async def _live(self, websocket) -> None:
        from .session import LiveSession

        await websocket.accept()
        if len(self.sessions) >= self.config.max_sessions:
            self.stats["refused_sessions"] += 1
            await websocket.send_json({"type": "error", "error": f"the server has {len(self.sessions)} live "
                                       f"sessions, its limit; try again later"})
            await websocket.close(code=1013)
            return
        session = LiveSession(self, websocket)
        self.sessions.add(session)
        self.stats["sessions_total"] += 1
        try:
            await session.run()
        finally:
            self.sessions.discard(session)

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        """Stop the job and frame threads and remove the server's temporary folder."""
        if self._closed:
            return
        self._closed = True
        self.jobs.close()
        self.executor.shutdown(wait=True, cancel_futures=True)
        shutil.rmtree(self.tmp, ignore_errors=True)


def _demo_events():
    phn = SAMPLES / "hello.phn"
    if not phn.is_file():
        return None
    from ..readers import read_timeline

    return [{"start": round(s.start, 6), "end": round(s.end, 6), "label": s.label, "kind": "phoneme"}
            for s in read_timeline(phn)]


def serve(config: ServeConfig, *, host: str = "127.0.0.1", port: int = 8765) -> None:
    """Run ``lipsync serve`` until Ctrl-C (prints the page's URL with its token)."""
    from ..web import Session, run

    session = Session.open(host, port)
    server = LiveServer(config, session=session)
    try:
        run(server.app, session, announce="lipsync serve: open", ws_max_size=WS_MAX_MESSAGE)
    finally:
        server.close()
        session.close()


__all__ = ["ServeConfig", "LiveServer", "serve"]
