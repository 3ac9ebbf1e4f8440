"""The live WebSocket protocol: client messages parsed and checked, frame messages packed.

Client -> server, text frames holding one JSON object each:

* ``{"type": "config", "fps": 25, "format": "jpeg"|"webp", "quality": 80}`` (optional,
  before anything else is pushed); for audio also ``"audio_rate": 48000`` (Hz, before the
  first audio), ``"lookahead": 200`` (ms, the audio look-ahead, before the first audio) and
  ``"specs": true`` (a ``{"type": "spec", "n", "from", "to", "alpha", "cue"}`` text message
  before each frame: what it shows, for checking, and its mouth shape as a cue,
  :meth:`lipsync.LiveAnimator.cue`); ``"plate_start": 1.5`` (seconds into a real subject's
  idle plate where the session starts, before anything is pushed; by default each session
  starts at a place of its own, so two heads on one page do not blink in unison);
* binary frames: audio, 16-bit little-endian PCM mono at ``audio_rate`` (at most
  :data:`MAX_AUDIO_MESSAGE_S` per message, in real time: at most
  :data:`MAX_AUDIO_AHEAD_S` ahead of the wall clock since the first). Audio is the session's
  clock: each frame is sent as soon as the audio reaches its time plus the look-ahead, so a
  client shows it with its sound delayed by the look-ahead (``ready`` and ``config`` say how
  much: ``audio_lookahead``). Events pushed in an audio session win where both exist;
* ``{"type": "push", "start": 0.1, "end": 0.25, "label": "AA", "kind": "phoneme"}``
  (``kind`` optional: ``viseme``, ``phoneme`` or ``word``), or
  ``{"type": "push", "events": [{"start": .., "end": .., "label": ..}, ...]}``;
* ``{"type": "clock", "t": 1.25}`` -- the client's playback time now; the server
  extrapolates it in real time until the next clock message;
* ``{"type": "stop"}`` -- playback paused: no frames until the next clock message;
* ``{"type": "end"}`` -- an audio session's stream has ended (no other field): its last
  phones are decided and every frame still to come is sent, in order, up to the end of the
  audio (the last look-ahead's frames, which no later audio would make due), then
  ``{"type": "end", "frames": N}`` (N: the stream's frame count, ``ceil(seconds * fps)``,
  as an offline render of the same audio has). Audio after it is refused; events may still
  be pushed. An ``end`` with fields, before any audio, or a second one is answered with an
  error (the session carries on);
* ``{"type": "ping"}`` -- answered with ``{"type": "pong"}``.

Server -> client: text ``{"type": "ready", ...}`` once, ``{"type": "error", "error": ...}``
for a message it could not use (the session carries on), ``{"type": "end", ...}`` after the
last frame of an ended audio stream, and binary frames: a 16-byte
header (``<IId``: frame number, flags -- bit 0 set when the frame is final --, its time in
seconds) followed by the JPEG or WebP image.

Examples
--------
>>> parse('{"type": "clock", "t": 1.5}')
Clock(t=1.5)
>>> parse('{"type": "push", "start": 0, "end": 0.2, "label": "M"}')
Push(events=((0.0, 0.2, 'M', None),))
>>> parse('{"type": "end"}')
End()
>>> parse('{"type": "push", "start": 0}')
Traceback (most recent call last):
...
lipsync.server.protocol.ProtocolError: push: 'end' must be a number
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass
from typing import Optional, Tuple, Union

from ..errors import InputError

HEADER = struct.Struct("<IId")
FLAG_FINAL = 1

#: Events in one push message: a long utterance's phones (about 15 a second) fit many
#: times over, and one message cannot make the server plan minutes of frames at once.
MAX_EVENTS_PER_MESSAGE = 2000
#: Longest label: words and phone names are short; this bounds what is kept and echoed.
MAX_LABEL_CHARS = 64
#: Audio sample rates a session may stream (telephone to studio rates).
AUDIO_RATES = (8000, 11025, 12000, 16000, 22050, 24000, 32000, 44100, 48000, 88200, 96000)
#: Longest audio in one binary message: browsers send 3-20 ms, a file streamer maybe 100 ms;
#: a second (192 kB at 96 kHz, under the WebSocket's message limit) bounds what one message
#: makes the server decode at once.
MAX_AUDIO_MESSAGE_S = 1.0
#: Audio may run ahead of the wall clock (since the session's first audio) by this much:
#: network jitter and a client's buffering, not a file pushed at full speed (that is
#: ``lipsync render --live``'s job), so one session costs at most its real-time share of CPU.
MAX_AUDIO_AHEAD_S = 2.0
#: The audio look-ahead a session may ask for, ms.
LOOKAHEAD_MS_RANGE = (0, 1000)
#: ``plate_start``'s bound: the plate timeline wraps a start to the plate's length anyway; a
#: bound keeps a client's number a number of seconds, not 1e300.
MAX_PLATE_START_S = 3600.0
#: The frame rates and image formats a session may ask for.
FPS_CHOICES = (10, 12, 15, 20, 24, 25, 30, 50, 60)
FORMATS = ("jpeg", "webp")


class ProtocolError(InputError):
    """A client message that cannot be used (answered with an error message)."""


@dataclass(frozen=True)
class Config:
    fps: Optional[float] = None
    format: Optional[str] = None
    quality: Optional[int] = None
    audio_rate: Optional[int] = None
    lookahead: Optional[float] = None     # seconds
    specs: Optional[bool] = None
    plate_start: Optional[float] = None   # seconds


@dataclass(frozen=True)
class Push:
    events: Tuple[Tuple[float, float, str, Optional[str]], ...]


@dataclass(frozen=True)
class Clock:
    t: float


@dataclass(frozen=True)
class Stop:
    pass


@dataclass(frozen=True)
class Ping:
    pass


@dataclass(frozen=True)
class End:
    """The audio stream has ended (module docstring)."""


Message = Union[Config, Push, Clock, Stop, Ping, End]


def _number(obj: dict, key: str, what: str) -> float:
    value = obj.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ProtocolError(f"{what}: {key!r} must be a number")
    return float(value)


def _event(obj, what: str) -> Tuple[float, float, str, Optional[str]]:
    if not isinstance(obj, dict):
        raise ProtocolError(f"{what}: an event must be an object with start, end and label")
    start, end = _number(obj, "start", what), _number(obj, "end", what)
    label = obj.get("label")
    if not isinstance(label, str) or len(label) > MAX_LABEL_CHARS:
        raise ProtocolError(f"{what}: 'label' must be text of at most {MAX_LABEL_CHARS} characters")
    kind = obj.get("kind")
    if kind is not None and not isinstance(kind, str):
        raise ProtocolError(f"{what}: 'kind' must be viseme, phoneme or word")
    return start, end, label, kind


def parse(text: str) -> Message:
    """One client message (module docstring), or :class:`ProtocolError` saying what is wrong."""
    try:
        obj = json.loads(text)
    except (ValueError, RecursionError):
        raise ProtocolError("not a JSON message") from None
    if not isinstance(obj, dict):
        raise ProtocolError("a message must be a JSON object with a 'type'")
    kind = obj.get("type")
    if kind == "clock":
        return Clock(_number(obj, "t", "clock"))
    if kind == "push":
        if "events" in obj:
            events = obj["events"]
            if not isinstance(events, list) or not 0 < len(events) <= MAX_EVENTS_PER_MESSAGE:
                raise ProtocolError(f"push: 'events' must be a list of 1 to {MAX_EVENTS_PER_MESSAGE} events")
            return Push(tuple(_event(e, f"push event {i}") for i, e in enumerate(events)))
        return Push((_event(obj, "push"),))
    if kind == "config":
        fps = obj.get("fps")
        if fps is not None and fps not in FPS_CHOICES:
            raise ProtocolError(f"config: fps must be one of {', '.join(map(str, FPS_CHOICES))}")
        fmt = obj.get("format")
        if fmt is not None and fmt not in FORMATS:
            raise ProtocolError(f"config: format must be one of {', '.join(FORMATS)}")
        quality = obj.get("quality")
        if quality is not None and (isinstance(quality, bool) or not isinstance(quality, int)
                                    or not 10 <= quality <= 100):
            raise ProtocolError("config: quality must be an integer 10..100")
        rate = obj.get("audio_rate")
        if rate is not None and (isinstance(rate, bool) or rate not in AUDIO_RATES):
            raise ProtocolError(f"config: audio_rate must be one of {', '.join(map(str, AUDIO_RATES))}")
        look = obj.get("lookahead")
        if look is not None and (isinstance(look, bool) or not isinstance(look, (int, float))
                                 or not LOOKAHEAD_MS_RANGE[0] <= look <= LOOKAHEAD_MS_RANGE[1]):
            raise ProtocolError(f"config: lookahead must be {LOOKAHEAD_MS_RANGE[0]}..{LOOKAHEAD_MS_RANGE[1]} ms")
        specs = obj.get("specs")
        if specs is not None and not isinstance(specs, bool):
            raise ProtocolError("config: specs must be true or false")
        start = obj.get("plate_start")
        if start is not None and (isinstance(start, bool) or not isinstance(start, (int, float))
                                  or not 0 <= start <= MAX_PLATE_START_S):
            raise ProtocolError(f"config: plate_start must be 0..{MAX_PLATE_START_S:g} s")
        return Config(None if fps is None else float(fps), fmt, quality, None if rate is None else int(rate),
                      None if look is None else float(look) / 1000.0, specs,
                      None if start is None else float(start))
    if kind == "stop":
        return Stop()
    if kind == "ping":
        return Ping()
    if kind == "end":
        extra = sorted(k for k in obj if k != "type")
        if extra:
            # a field here is a client that means something end does not do (a time, a
            # count): say so rather than end a stream differently from what it asked
            raise ProtocolError(f"end: takes no fields, got {', '.join(repr(k[:20]) for k in extra[:3])}")
        return End()
    raise ProtocolError(f"unknown message type {str(kind)[:20]!r}; valid: config, push, clock, stop, end, ping")


def audio_samples(data: bytes, rate: Optional[int]):
    """A binary audio message as ``int16`` samples, or :class:`ProtocolError` saying what is wrong.

    Examples
    --------
    >>> audio_samples(b"\\x01\\x00\\xff\\xff", 16000).tolist()
    [1, -1]
    >>> audio_samples(b"\\x01", 16000)
    Traceback (most recent call last):
    ...
    lipsync.server.protocol.ProtocolError: audio: 1 bytes is not whole 16-bit samples
    """
    import numpy as np

    if rate is None:
        raise ProtocolError('audio: send {"type": "config", "audio_rate": HZ} before the first audio')
    if len(data) % 2:
        raise ProtocolError(f"audio: {len(data)} bytes is not whole 16-bit samples")
    if len(data) > 2 * rate * MAX_AUDIO_MESSAGE_S:
        raise ProtocolError(f"audio: {len(data) // 2} samples in one message, over {MAX_AUDIO_MESSAGE_S:g} s "
                            f"at {rate} Hz")
    return np.frombuffer(data, "<i2").astype(np.int16)


def pack_frame(n: int, t: float, final: bool, image: bytes) -> bytes:
    """A frame message: the header (module docstring) and the encoded image.

    Examples
    --------
    >>> msg = pack_frame(7, 0.28, True, b"JPEG")
    >>> HEADER.unpack(msg[:HEADER.size]), msg[HEADER.size:]
    ((7, 1, 0.28), b'JPEG')
    """
    return HEADER.pack(n, FLAG_FINAL if final else 0, t) + image
