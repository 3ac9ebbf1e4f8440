"""One live WebSocket session: events or audio in, frames out as they fall due on the client's
clock (events) or as the audio reaches them (audio: binary messages, :mod:`.protocol`).

Two tasks per session: the reader parses client messages (:mod:`.protocol`) and feeds the
session's :class:`lipsync.LiveAnimator`; the sender waits for the next frame to fall due on
the extrapolated client clock, renders and encodes it on the server's shared thread pool
(OpenCV releases the GIL) and sends it. A sender that falls behind skips to the frame due
now rather than queueing old ones: the browser shows the head in sync, at a lower rate.
"""

from __future__ import annotations

import asyncio
import secrets
import time
from typing import Optional

import cv2
import numpy as np

from ..morphing.alpha import flatten
from ..errors import InputError
from ..live import LiveAnimator
from . import protocol

#: Longest playback time a session may reach: an hour of speech, far beyond any utterance,
#: bounds the frame schedule the session keeps (25 fps x 3600 s FrameSpecs, ~10 MB).
MAX_SESSION_TIME_S = 3600.0
#: An audio session's sender sends every frame the audio made due, in order, unless it is more
#: than this many behind (a loaded server): then it skips to the newest, as the clock-driven
#: sender does, rather than show the head late.
AUDIO_SKIP_FRAMES = 5


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
        # audio (binary messages): the stream's rate, look-ahead, and the frames it made due
        self.audio_rate: Optional[int] = None
        self.audio_lookahead: Optional[float] = None
        # a place of its own on a real subject's idle plate, so that two sessions (two heads
        # on one page) do not blink in unison; config's plate_start chooses it
        plate = server.plate
        self.plate_start = 0.0 if plate is None else secrets.randbelow(len(plate)) / plate.fps
        self.audio_started: Optional[float] = None   # monotonic time of the first audio
        self.audio_s = 0.0                           # seconds of audio received
        self.due = -1                                # newest frame the audio made due
        self.specs = False
        # the end of the audio ({"type": "end"}): the first frame it made due, the stream's
        # frame count, and whether the client has been told
        self.end_from: Optional[int] = None
        self.end_frames: Optional[int] = None
        self.end_sent = False

    # ------------------------------------------------------------------ lifecycle
    def _animator(self) -> LiveAnimator:
        if self.live is None:
            s = self.server
            self.live = LiveAnimator(s.bank, fps=self.fps, map=s.pmap, timing=s.config.timing,
                                     renderer=s.pool, prepare=False, audio_lookahead=self.audio_lookahead,
                                     plate_start=self.plate_start, samples=s.config.samples)
            h, w = self.live.shape
            c = self.live.renderer.channels  # 4 for a bank with transparency
            self._frame = np.empty((h, w, c), np.uint8)
            self._bgr = np.empty((h, w, c), np.uint8)
        return self.live

    async def run(self) -> None:
        live = self._animator()
        h, w = live.shape
        await self.ws.send_json({"type": "ready", "fps": self.fps, "width": w, "height": h,
                                 "lookahead": live.lookahead, "audio_lookahead": live.audio_lookahead,
                                 "audio_rates": list(protocol.AUDIO_RATES), "formats": list(protocol.FORMATS)})
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
            await self._release(self.live)
            self.live = None

    async def _release(self, live: Optional[LiveAnimator]) -> None:
        """Free an animator's recogniser and return its memory to the system (issue 38: a
        closed session's ~30 MB stayed with the server)."""
        if live is None:
            return
        try:
            await asyncio.get_running_loop().run_in_executor(self.server.executor, live.close)
        except RuntimeError:  # the server is shutting down: its pool takes no more work
            live.close()

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
            try:
                if text is None:
                    await self._audio(message.get("bytes") or b"")
                    continue
                await self._handle(protocol.parse(text))
            except InputError as exc:
                await self._error(str(exc))
            except WebSocketDisconnect:
                return

    async def _audio(self, data: bytes) -> None:
        """A binary message: audio samples, checked (:func:`protocol.audio_samples`), fed on
        the server's pool (the recogniser's CPU work stays off the event loop)."""
        pcm = protocol.audio_samples(data, self.audio_rate)
        now = time.monotonic()
        if self.audio_started is None:
            self.audio_started = now
        seconds = len(pcm) / self.audio_rate
        if self.audio_s + seconds > MAX_SESSION_TIME_S:
            raise protocol.ProtocolError(f"audio: a session streams at most {MAX_SESSION_TIME_S:g} s")
        ahead = self.audio_s + seconds - (now - self.audio_started)
        if ahead > protocol.MAX_AUDIO_AHEAD_S:
            raise protocol.ProtocolError(f"audio: {ahead:.1f} s ahead of real time (at most "
                                         f"{protocol.MAX_AUDIO_AHEAD_S:g} s); the chunk was dropped")
        live = self._animator()
        self.audio_s += seconds
        due = await asyncio.get_running_loop().run_in_executor(self.server.executor, live.feed_audio,
                                                                pcm, self.audio_rate)
        if due:
            self.due = max(self.due, due[-1])
            self.wake.set()

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
            started = self.live is not None and (self.live.horizon > 0 or self.audio_started is not None)
            prepare = renew = False
            if msg.audio_rate is not None and msg.audio_rate != self.audio_rate:
                if self.audio_started is not None:
                    raise protocol.ProtocolError("config: audio_rate can only be set before the first audio")
                self.audio_rate = msg.audio_rate
                prepare = renew = True     # a recogniser made for another rate is replaced
            if msg.lookahead is not None and msg.lookahead != self._animator().audio_lookahead:
                if started:
                    raise protocol.ProtocolError("config: lookahead can only change before the first push or audio")
                self.audio_lookahead, renew = msg.lookahead, True
            if msg.fps is not None and msg.fps != self.fps:
                if started:
                    raise protocol.ProtocolError("config: fps can only change before the first push")
                self.fps, renew = msg.fps, True
            if msg.plate_start is not None and msg.plate_start != self.plate_start:
                if started:
                    raise protocol.ProtocolError("config: plate_start can only change before the first push or audio")
                self.plate_start, renew = msg.plate_start, True
            if renew:
                old, self.live = self.live, None
                await self._release(old)
                self._animator()
            if prepare or (renew and self.audio_rate is not None):
                # load the recogniser now (~0.5 s), not when the first audio is due
                await asyncio.get_running_loop().run_in_executor(
                    self.server.executor, self.live.feed_audio, np.zeros(0, np.int16), self.audio_rate)
            self.format = msg.format or self.format
            self.quality = msg.quality or self.quality
            if msg.specs is not None:
                self.specs = msg.specs
            reply = {"type": "config", "fps": self.fps, "format": self.format, "quality": self.quality}
            if self.audio_rate is not None or msg.lookahead is not None or msg.specs is not None:
                reply.update(audio_rate=self.audio_rate, audio_lookahead=self.live.audio_lookahead, specs=self.specs)
            await self.ws.send_json(reply)
        elif isinstance(msg, protocol.Stop):
            self.clock_t = None
        elif isinstance(msg, protocol.Ping):
            await self.ws.send_json({"type": "pong"})
        elif isinstance(msg, protocol.End):
            await self._end()

    async def _end(self) -> None:
        """``{"type": "end"}``: the audio has ended; the frames of its last look-ahead fall due
        (the sender sends every one, then ``{"type": "end", "frames": N}``)."""
        if self.audio_started is None or self.live is None:
            raise protocol.ProtocolError("end: no audio has been streamed in this session (end closes an "
                                         "audio stream)")
        if self.end_frames is not None:
            raise protocol.ProtocolError("end: the audio has already ended")
        live = self.live
        due = await asyncio.get_running_loop().run_in_executor(self.server.executor, live.finish_audio)
        self.end_from = due[0] if due else self.due + 1
        self.end_frames = live.frames_total
        if due:
            self.due = max(self.due, due[-1])
        self.wake.set()

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

    async def _send_frame(self, live: LiveAnimator, n: int) -> bool:
        data = await asyncio.get_running_loop().run_in_executor(self.server.executor, self._encode, live, n,
                                                                self.format, self.quality)
        if self.closed or live is not self.live:
            return False
        if self.specs:
            spec = live.spec(n)
            await self.ws.send_json({"type": "spec", "n": n, "from": spec.from_viseme, "to": spec.to_viseme,
                                     "alpha": round(float(spec.alpha), 6), "cue": live.cue(n)})
        await self.ws.send_bytes(data)
        self.last_sent = n
        self.frames_sent += 1
        self.server.stats["frames"] += 1
        return True

    async def _send_frames(self) -> None:
        while not self.closed:
            if self.audio_started is not None and self.live is not None:
                # audio is the clock: every frame it made due, in order; one that fell more
                # than AUDIO_SKIP_FRAMES behind skips to the newest (the head stays in sync)
                live = self.live
                if self.last_sent < self.due:
                    n = self.last_sent + 1
                    if self.due - self.last_sent > AUDIO_SKIP_FRAMES:
                        # behind: skip to the newest, but never past the end's frames (the
                        # last sound's, which the client asked for with "end")
                        n = self.due if self.end_from is None else max(n, self.end_from)
                    await self._send_frame(live, n)
                    continue
                if self.end_frames is not None and not self.end_sent and live is self.live:
                    self.end_sent = True
                    await self.ws.send_json({"type": "end", "frames": self.end_frames})
                    continue
                self.wake.clear()
                await self.wake.wait()
                continue
            t = self._now()
            live = self.live
            if t is None or live is None or t > MAX_SESSION_TIME_S:
                self.wake.clear()
                await self.wake.wait()
                continue
            n = live.index(t)
            if n != self.last_sent:
                await self._send_frame(live, n)
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
