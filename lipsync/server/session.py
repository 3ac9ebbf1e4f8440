"""One live WebSocket session: events in, frames out as they fall due on the client's clock.

Two tasks per session: the reader parses client messages (:mod:`.protocol`) and feeds the
session's :class:`lipsync.LiveAnimator`; the sender waits for the next frame to fall due on
the extrapolated client clock, renders and encodes it on the server's shared thread pool
(OpenCV releases the GIL) and sends it. A sender that falls behind skips to the frame due
now rather than queueing old ones: the browser shows the head in sync, at a lower rate.
"""

from __future__ import annotations

import asyncio
import time
from typing import Optional

import cv2
import numpy as np

from ..alpha import flatten
from ..errors import InputError
from ..live import LiveAnimator
from . import protocol

#: Longest playback time a session may reach: an hour of speech, far beyond any utterance,
#: bounds the frame schedule the session keeps (25 fps x 3600 s FrameSpecs, ~10 MB).
MAX_SESSION_TIME_S = 3600.0


class LiveSession:
    """State and tasks of one WebSocket client (module docstring)."""

    def __init__(self, server, websocket):
        self.server = server
        self.ws = websocket
        cfg = server.config
        self.fps = cfg.fps
        self.format = "jpeg"
        self.quality = cfg.quality
        self.live: Optional[LiveAnimator] = None
        self.clock_t: Optional[float] = None   # client time at clock_at (monotonic)
        self.clock_at = 0.0
        self.last_sent = -1
        self.frames_sent = 0
        self.errors = 0
        self.wake = asyncio.Event()
        self.closed = False
        self._frame: Optional[np.ndarray] = None
        self._bgr: Optional[np.ndarray] = None

    # ------------------------------------------------------------------ lifecycle
    def _animator(self) -> LiveAnimator:
        if self.live is None:
            s = self.server
            self.live = LiveAnimator(s.bank, fps=self.fps, map=s.pmap, timing=s.config.timing,
                                     renderer=s.pool, prepare=False)
            h, w = self.live.shape
            c = self.live.renderer.channels  # 4 for a bank with transparency
            self._frame = np.empty((h, w, c), np.uint8)
            self._bgr = np.empty((h, w, c), np.uint8)
        return self.live

    async def run(self) -> None:
        live = self._animator()
        h, w = live.shape
        await self.ws.send_json({"type": "ready", "fps": self.fps, "width": w, "height": h,
                                 "lookahead": live.lookahead, "formats": list(protocol.FORMATS)})
        sender = asyncio.create_task(self._send_frames())
        try:
            await self._read()
        finally:
            self.closed = True
            self.wake.set()
            sender.cancel()
            try:
                await sender
            except (asyncio.CancelledError, Exception):
                pass

    # ------------------------------------------------------------------ input
    async def _read(self) -> None:
        from starlette.websockets import WebSocketDisconnect

        idle = self.server.config.idle_timeout
        while True:
            try:
                message = await asyncio.wait_for(self.ws.receive(), timeout=idle)
            except asyncio.TimeoutError:
                await self._error(f"idle for {idle:g} s; closing the session")
                await self.ws.close(code=1000)
                return
            if message["type"] == "websocket.disconnect":
                return
            text = message.get("text")
            if text is None:
                await self._error("binary messages are not accepted; send JSON text")
                continue
            try:
                await self._handle(protocol.parse(text))
            except InputError as exc:
                await self._error(str(exc))
            except WebSocketDisconnect:
                return

    async def _handle(self, msg) -> None:
        if isinstance(msg, protocol.Clock):
            if not 0.0 <= msg.t <= MAX_SESSION_TIME_S:
                raise protocol.ProtocolError(f"clock: t must be 0..{MAX_SESSION_TIME_S:g} s")
            self.clock_t, self.clock_at = msg.t, time.monotonic()
            self.wake.set()
        elif isinstance(msg, protocol.Push):
            live = self._animator()
            for i, (start, end, label, kind) in enumerate(msg.events):
                if end > MAX_SESSION_TIME_S:
                    raise protocol.ProtocolError(f"push: events must end by {MAX_SESSION_TIME_S:g} s")
                try:
                    live.push(start, end, label, kind=kind)
                except InputError as exc:
                    where = f"event {i}: " if len(msg.events) > 1 else ""
                    raise protocol.ProtocolError(f"push: {where}{exc}") from None
            self.wake.set()
        elif isinstance(msg, protocol.Config):
            if msg.fps is not None and msg.fps != self.fps:
                if self.live is not None and self.live.horizon > 0:
                    raise protocol.ProtocolError("config: fps can only change before the first push")
                self.fps, self.live = msg.fps, None
                self._animator()
            self.format = msg.format or self.format
            self.quality = msg.quality or self.quality
            await self.ws.send_json({"type": "config", "fps": self.fps, "format": self.format,
                                     "quality": self.quality})
        elif isinstance(msg, protocol.Stop):
            self.clock_t = None
        elif isinstance(msg, protocol.Ping):
            await self.ws.send_json({"type": "pong"})

    async def _error(self, text: str) -> None:
        self.errors += 1
        self.server.stats["errors"] += 1
        await self.ws.send_json({"type": "error", "error": text[:300]})

    # ------------------------------------------------------------------ output
    def _now(self) -> Optional[float]:
        if self.clock_t is None:
            return None
        return self.clock_t + (time.monotonic() - self.clock_at)

    def _encode(self, live: LiveAnimator, n: int, fmt: str, quality: int) -> bytes:
        # runs on the server's pool: render, convert, encode; all release the GIL
        final = live.is_final(n / live.fps)
        live.frame(n, out=self._frame)
        rgba = self._frame.shape[2] == 4
        cv2.cvtColor(self._frame, cv2.COLOR_RGBA2BGRA if rgba else cv2.COLOR_RGB2BGR, dst=self._bgr)
        if fmt == "webp":  # WebP keeps the alpha of a transparent bank
            ok, buf = cv2.imencode(".webp", self._bgr, [cv2.IMWRITE_WEBP_QUALITY, quality])
        else:
            # JPEG has no alpha: a transparent bank's frames are shown on white
            bgr = flatten(self._bgr, (255, 255, 255)) if rgba else self._bgr
            ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, quality])
        if not ok:  # pragma: no cover - OpenCV encodes any uint8 image
            raise RuntimeError(f"could not encode frame {n} as {fmt}")
        return protocol.pack_frame(n, n / live.fps, final, buf.tobytes())

    async def _send_frames(self) -> None:
        loop = asyncio.get_running_loop()
        while not self.closed:
            t = self._now()
            live = self.live
            if t is None or live is None or t > MAX_SESSION_TIME_S:
                self.wake.clear()
                await self.wake.wait()
                continue
            n = live.index(t)
            if n != self.last_sent:
                data = await loop.run_in_executor(self.server.executor, self._encode, live, n,
                                                  self.format, self.quality)
                if self.closed or live is not self.live:
                    continue
                await self.ws.send_bytes(data)
                self.last_sent = n
                self.frames_sent += 1
                self.server.stats["frames"] += 1
                continue
            # sleep until the next frame falls due, or a new clock / push arrives
            t = self._now()
            if t is None:
                continue
            delay = max(0.0, (n + 1) / live.fps - t)
            self.wake.clear()
            try:
                await asyncio.wait_for(self.wake.wait(), timeout=delay + 0.001)
            except asyncio.TimeoutError:
                pass
